"""Issue 28, row 3: two runs in the same second.

``lcc-synth simulate problems/paper_table2.toml & lcc-synth simulate ... & wait`` used to write
the same ``logs/<name>-<stamp>.rrd`` from both processes (both exit 0, the file fails
``rerun rrd verify``). Default names are now taken exclusively when a finished file is
published (``os.link``: ``NAME-2.rrd`` when NAME is taken), so each run keeps its own whole
file, and results directories are created with ``mkdir`` (exclusive).
"""

from __future__ import annotations

import re

import pytest
from cli_subprocess import PROBLEMS, rrd_verifies, start_cli

from lcc_synth.outputs import new_directory, publish, temporary_path


@pytest.mark.slow  # CI runs it; by default: two exports at once (test_fail_export)
def test_two_simulations_at_once_keep_two_whole_recordings(tmp_path):
    procs = [start_cli(["simulate", PROBLEMS / "paper_table2.toml", "--json"], cwd=tmp_path)
             for _ in range(2)]  # fmt: skip
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (_, err) in zip(procs, outs, strict=True):
        assert p.returncode == 0, err
    files = sorted((tmp_path / "logs").glob("*.rrd"))
    assert len(files) == 2, files  # never one file shared by the two processes
    named = sorted(re.search(r"recording: (\S+)", err).group(1) for _, err in outs)
    assert named == sorted(str(f.relative_to(tmp_path)) for f in files)  # each says its own
    for f in files:
        assert rrd_verifies(f), f
    stems = sorted((f.stem for f in files), key=len)
    if stems[0].split("-")[1] == stems[1].split("-")[1]:  # the same second: -2 appended
        assert stems[1] == stems[0] + "-2"
    assert not list((tmp_path / "logs").glob(".*part*"))


def test_publish_never_replaces_and_numbers_the_next_free_name(tmp_path):
    """The primitive under it, in-process: a name that exists is never replaced."""
    target = tmp_path / "x.rrd"
    target.write_text("the user's file")
    names = []
    for k in range(3):
        tmp = temporary_path(target)
        tmp.write_text(f"run {k}")
        names.append(publish(tmp, target))
    assert target.read_text() == "the user's file"
    assert [n.name for n in names] == ["x-2.rrd", "x-3.rrd", "x-4.rrd"]
    assert [n.read_text() for n in names] == ["run 0", "run 1", "run 2"]
    tmp = temporary_path(target)
    tmp.write_text("replaced")
    assert publish(tmp, target, overwrite=True) == target and target.read_text() == "replaced"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x-2.rrd", "x-3.rrd", "x-4.rrd",
                                                          "x.rrd"]  # no temporary file left
    a = new_directory(tmp_path / "res", "p", "20260101T000000Z")
    b = new_directory(tmp_path / "res", "p", "20260101T000000Z")
    assert a != b and a.is_dir() and b.name == a.name + "-2"
