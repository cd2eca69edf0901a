"""Issue 28, rows 6, 12 and 2: ``lcc-synth sweep`` checks where it writes and what it will
cost before the work, and a disk that fills while it writes is one line.

* An ``--out`` that cannot be written (a read-only mount: as root, mode bits stop nothing) is
  exit 2 before any simulation: no cluster started (no scratch directory), no results
  directory.
* ``--count 10000000`` (the schema's largest count) is exit 2 at once, one line naming
  ``--count``, when its estimate does not fit: on a small file system always (the disk), and
  here also on the memory when the machine has less than the estimate needs.
* A disk that fills while the sweep runs: a warning for the partial files, then one line
  naming ``samples.csv`` (exit 1) after the summary table is printed.

The file systems are ``tmpfs`` mounts (root only): a test skips with the reason when ``mount``
is not permitted.
"""

from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path

import pytest
from cli_subprocess import PROBLEMS, cli_env, one_line_error, run_cli, start_cli, tmpfs, wait_for

PROBLEM = PROBLEMS / "sweep_robustness.toml"
SMALL = ["--controllers", "all_hdv,paper", "--count", "12", "--batch-size", "2", "--workers",
         "2", "--no-record", "--no-progress"]  # fmt: skip


def _env(tmp: Path) -> dict:
    (tmp / "tmp").mkdir(exist_ok=True)
    return cli_env(TMPDIR=str(tmp / "tmp"))


def test_unwritable_out_is_exit_2_before_any_simulation(tmp_path):
    with tmpfs(tmp_path / "ro", "ro,size=1m") as ro:
        t0 = time.monotonic()
        proc = run_cli(["sweep", PROBLEM, *SMALL, "--out", ro / "results"], cwd=tmp_path,
                       env=_env(tmp_path))  # fmt: skip
        took = time.monotonic() - t0
        assert proc.returncode == 2 and one_line_error(proc.stderr), proc.stderr
        assert "--out" in proc.stderr and "Read-only file system" in proc.stderr
        assert os.listdir(ro) == []
    assert os.listdir(tmp_path / "tmp") == []  # no cluster was started
    assert "scenarios" not in proc.stderr and proc.stdout == ""
    assert took < 30, took  # imports only: no cluster, no simulation


def test_a_results_directory_that_is_a_file_is_exit_2(tmp_path):
    (tmp_path / "results").write_text("not a directory")
    proc = run_cli(["sweep", PROBLEM, *SMALL, "--out", tmp_path / "results"], cwd=tmp_path,
                   env=_env(tmp_path))  # fmt: skip
    assert proc.returncode == 2 and one_line_error(proc.stderr), proc.stderr
    assert "--out" in proc.stderr and os.listdir(tmp_path / "tmp") == []


def test_a_count_too_large_for_the_disk_is_refused_naming_count(tmp_path):
    with tmpfs(tmp_path / "small", "size=64m") as small:
        t0 = time.monotonic()
        proc = run_cli(["sweep", PROBLEM, "--count", "10000000", "--controllers", "all_hdv",
                        "--no-record", "--out", small], cwd=tmp_path, env=_env(tmp_path))
        assert proc.returncode == 2 and one_line_error(proc.stderr), proc.stderr
        assert "error: --count:" in proc.stderr and "free" in proc.stderr
        assert os.listdir(small) == []
    assert time.monotonic() - t0 < 30 and os.listdir(tmp_path / "tmp") == []


def test_ten_million_scenarios_are_refused_when_the_estimate_does_not_fit(tmp_path):
    """The largest count the schema allows, every controller and the recording: refused at
    once on a machine without the memory (or disk) its estimate needs (this one: 20.5 GiB
    estimated for 23 GiB available, of which a run may plan on 80 %)."""
    from lcc_synth.experiments.sweep import load_sweep
    from lcc_synth.experiments.sweep_estimate import estimate_sweep
    from lcc_synth.outputs import SPACE_FLOOR, SPACE_MARGIN, free_bytes
    from lcc_synth.resources import MEMORY_FRACTION, available_memory

    est = estimate_sweep(load_sweep(PROBLEM, count=10_000_000), 2, record=True)
    memory = est.memory > MEMORY_FRACTION * available_memory()
    disk = est.disk * SPACE_MARGIN + SPACE_FLOOR > free_bytes(tmp_path)
    if not (memory or disk):
        pytest.skip("this machine has the memory and disk for the estimate: the refusal on a "
                    "small file system is tested above")  # fmt: skip
    t0 = time.monotonic()
    proc = run_cli(["sweep", PROBLEM, "--count", "10000000", "--out", tmp_path / "out"],
                   cwd=tmp_path, env=_env(tmp_path))  # fmt: skip
    assert proc.returncode == 2 and one_line_error(proc.stderr), proc.stderr
    assert "error: --count:" in proc.stderr
    assert ("memory" if memory else "free") in proc.stderr
    if memory:
        assert "--no-record" in proc.stderr  # what else can be done
    assert not (tmp_path / "out").exists() and os.listdir(tmp_path / "tmp") == []
    assert time.monotonic() - t0 < 30


def _fill(directory: Path) -> None:
    """Write a file in ``directory`` until its file system is full."""
    block = b"\0" * (1 << 16)
    with contextlib.suppress(OSError), open(directory / "filler", "wb") as fh:
        while True:
            fh.write(block)
            fh.flush()


@pytest.mark.slow  # a disk that fills under run's results: tests/test_fail_disk_full.py
def test_a_disk_that_fills_is_one_line_after_the_summary(tmp_path):
    """The estimate fits (the check passes); the test fills the file system once the results
    directory exists (before the cluster has started): the partial writes warn, the final
    ``samples.csv`` is one line naming it (exit 1), after the summary table."""
    with tmpfs(tmp_path / "disk", "size=4m") as disk:
        proc = start_cli(["sweep", PROBLEM, *SMALL, "--out", disk], cwd=tmp_path,
                         env=_env(tmp_path))  # fmt: skip
        try:
            assert wait_for(lambda: any(p.is_dir() for p in disk.iterdir()), timeout=60)
            _fill(disk)
            stdout, stderr = proc.communicate(timeout=300)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
        (run,) = [p for p in disk.iterdir() if p.is_dir()]
        assert proc.returncode == 1, stderr
        assert one_line_error(stderr), stderr
        last = stderr.rstrip().splitlines()[-1]
        assert last == (f"lcc-synth sweep: error: cannot write {run / 'samples.csv'}: "
                        "No space left on device")  # fmt: skip
        assert "warning: the partial results were not written" in stderr
        assert "all_hdv " in stdout and "paper " in stdout and "mean [p5, p95]" in stdout
        assert "results:" not in stdout
        assert [p.name for p in run.iterdir()] == []  # no half file, no temporary file
    assert os.listdir(tmp_path / "tmp") == []
