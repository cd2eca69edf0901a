"""Issue 28, row 4: names from a problem file used as paths.

A layout or controller named ``x/../../../victim`` in a suite file used to have
``gains_{layout}_{ctrl}.json`` written outside ``results/``, over the user's file. Every name
from a problem file now goes through :func:`lcc_synth.outputs.path_part` before it becomes
part of a path, and :func:`lcc_synth.outputs.child` refuses a name that leaves its directory.
"""

from __future__ import annotations

import pytest
from cli_subprocess import PAPER_HDV, run_cli

from lcc_synth.errors import ConfigError
from lcc_synth.outputs import child, path_part

SUITE = """
name = "../../names"
""" + PAPER_HDV + """[layouts."x/../../../victim"]
kind = "cf_lcc"
m = 0
n = 2
v_star = 15.0
[scenarios."../../../victim_s"]
layout = "x/../../../victim"
duration = 20.0
[[scenarios."../../../victim_s".perturbations]]
type = "brake"
vehicle = "head"
start = 5.0
duration = 1.0
decel = -3.0
[scenarios."../../../victim_s".metrics]
window = [5.0, 20.0]
[controllers.all_hdv]
type = "hdv"
[controllers."../../../../victim_h2"]
type = "h2"
"""


@pytest.mark.slow  # CI runs it; by default: test_fail_export's names with ".." (the same child())
def test_names_with_dot_dot_stay_inside_the_results_directory(tmp_path):
    work = tmp_path / "a" / "b" / "work"
    work.mkdir(parents=True)
    (work / "names.toml").write_text(SUITE)
    victims = {p: p.name for p in (tmp_path / "victim", tmp_path / "a" / "victim",
                                   tmp_path / "victim_h2.json", tmp_path / "a" / "victim_s.png")}
    for p, text in victims.items():
        p.write_text(text)
    before = {p for p in tmp_path.rglob("*")}
    proc = run_cli(["run", "names.toml", "--no-progress"], cwd=work)
    assert proc.returncode == 0, proc.stderr
    for p, text in victims.items():
        assert p.read_text() == text  # the user's files are untouched
    new = {p for p in tmp_path.rglob("*")} - before
    assert new and all(p.is_relative_to(work) for p in new), sorted(new)
    (run_dir,) = (work / "results").iterdir()
    names = {p.name for p in run_dir.iterdir()}
    assert "gains_x_.._.._.._victim__._.._.._.._victim_h2.json" in names
    assert not any(n.startswith(".") for n in names) and not run_dir.name.startswith(".")
    (rec,) = (work / "logs").iterdir()
    assert rec.name.startswith("_._.._names-")


def test_path_part_and_child():
    assert path_part("x/../../../victim") == "x_.._.._.._victim"
    assert path_part("..hidden") == "_.hidden" and path_part(" a b ") == "a_b"
    for bad in ("", ".", "..", "..."):
        with pytest.raises(ConfigError):
            path_part(bad)
    for bad in ("../x", "a/b", ".", ".."):
        with pytest.raises(ConfigError):
            child("/tmp/res", bad)
    assert str(child("/tmp/res", "gains_a.json")) == "/tmp/res/gains_a.json"
