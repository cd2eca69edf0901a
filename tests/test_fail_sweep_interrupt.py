"""Issue 28, rows 5 and 7: an interrupted ``lcc-synth sweep`` keeps what finished and
``--resume`` completes it to the results of an uninterrupted sweep, bit for bit.

The real command runs in a subprocess (``tests/cli_subprocess.py``) on a small sweep of the
two cheap controllers of ``problems/sweep_robustness.toml`` (its scenarios draw their
settings, so each is simulated on its own), with ``TMPDIR`` inside the test's directory to see
the Dask scratch space. The signal goes to the command's process (as ``kill`` sends it) at a
random moment after the partial ``samples.csv`` appeared; the test checks the exit code
(130 / 143) within a generous bound (a failure detector: the command measures 0.1-0.5 s here),
the partial files (``"partial": true``, the finished tasks and exactly their rows), no scratch
directory and no leaked-semaphore warning left behind, then ``--resume DIR`` and compares its
``samples.csv`` (the text) and ``sweep.json`` (the summary, every count) with those of an
uninterrupted run. A ``SIGKILL`` loses at most what finished since the last periodic write:
its partial files are resumed the same way; a resume of another sweep is one line.
"""

from __future__ import annotations

import csv
import json
import os
import random
import signal
import time
from pathlib import Path

import pytest
from cli_subprocess import PROBLEMS, cli_env, one_line_error, run_cli, start_cli, wait_for

#: Slow (deselected by a plain ``pytest``, run in CI): the in-process resume is checked by
#: tests/test_sweep.py::test_an_interrupted_sweep_resumes_to_the_same_results and the signal
#: handling of a command in a subprocess by tests/test_fail_signals.py::test_simulate.
pytestmark = pytest.mark.slow

PROBLEM = PROBLEMS / "sweep_robustness.toml"
COUNT = 120
ARGS = ["--controllers", "all_hdv,paper", "--count", str(COUNT), "--batch-size", "2",
        "--workers", "2", "--no-figures", "--no-record", "--no-progress"]  # fmt: skip
#: Seconds from the signal to the exit that count as a failure (the command takes < 2 s).
EXIT_BOUND = 10.0


def _env(tmp: Path) -> dict:
    (tmp / "tmp").mkdir(exist_ok=True)
    return cli_env(TMPDIR=str(tmp / "tmp"))


def _run_dir(out: Path) -> Path:
    (run,) = out.iterdir()
    return run


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The same sweep run to the end: its samples.csv text and sweep.json."""
    tmp = tmp_path_factory.mktemp("whole")
    proc = run_cli(["sweep", PROBLEM, *ARGS, "--out", tmp / "out"], cwd=tmp, env=_env(tmp))
    assert proc.returncode == 0, proc.stderr
    run = _run_dir(tmp / "out")
    return (run / "samples.csv").read_text(), json.loads((run / "sweep.json").read_text())


def _interrupt(tmp: Path, signum: int):
    """Start the sweep, wait for its first partial samples.csv, send ``signum`` at a random
    moment after it; returns (process, stdout, stderr, seconds from the signal to the exit)."""
    out = tmp / "out"
    proc = start_cli(["sweep", PROBLEM, *ARGS, "--out", out], cwd=tmp, env=_env(tmp))
    try:
        appeared = wait_for(lambda: any(out.glob("*/samples.csv")), timeout=120)
        assert appeared, "no partial samples.csv appeared"
        time.sleep(random.uniform(0.0, 0.5))
        assert proc.poll() is None, "the sweep ended before the signal: make it longer"
        sent = time.monotonic()
        proc.send_signal(signum)
        stdout, stderr = proc.communicate(timeout=60)
        took = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    print(f"{signal.Signals(signum).name}: exit {proc.returncode} {took:.2f} s after the signal")
    return proc, stdout, stderr, took


def _check_partial(run: Path, status: str | None) -> int:
    """The partial files: marked partial, the finished tasks' rows exactly; returns how many
    scenarios finished."""
    doc = json.loads((run / "sweep.json").read_text())
    assert doc["partial"] is True
    if status is not None:
        assert doc["status"] == status
    finished = doc["done"]["finished"]
    scenarios = {i for t in finished for i in range(t["start"], t["stop"])}
    assert doc["done"]["scenarios"] == len(scenarios) and 0 < len(scenarios) < COUNT
    with open(run / "samples.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    for c in ("all_hdv", "paper"):
        assert {int(r["scenario"]) for r in rows if r["controller"] == c} >= scenarios
        assert doc["results"][c]["scenarios"] == len(scenarios)
    assert doc["provenance"]["problem"]["file"] == PROBLEM.name
    assert not (run / "distributions.png").exists()
    return len(scenarios)


def _resume_equals(tmp: Path, run: Path, uninterrupted) -> None:
    proc = run_cli(["sweep", PROBLEM, "--resume", run, "--no-figures", "--no-record",
                    "--no-progress"], cwd=tmp, env=_env(tmp))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert f"results: {run}" in proc.stdout
    text, doc = uninterrupted
    assert (run / "samples.csv").read_text() == text  # bit for bit: the same text
    got = json.loads((run / "sweep.json").read_text())
    assert "partial" not in got
    assert got["results"] == doc["results"]  # summary and every count, MPC fallbacks included
    for key in ("count", "batch_size", "tasks", "seed", "controllers"):
        assert got["sweep"][key] == doc["sweep"][key]
    assert 0 < got["sweep"]["resumed_tasks"] < got["sweep"]["tasks"]
    assert list(run.iterdir()) and not list(run.glob(".*part*"))  # no temporary file left


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_interrupted_sweep_keeps_what_finished_and_resumes_bit_for_bit(
    tmp_path, signum, uninterrupted
):
    proc, stdout, stderr, took = _interrupt(tmp_path, signum)
    name = signal.Signals(signum).name
    assert proc.returncode == 128 + signum, stderr
    assert took < EXIT_BOUND
    assert "Traceback" not in stderr and "leaked" not in stderr, stderr
    assert stderr.rstrip().splitlines()[-1] == f"lcc-synth sweep: interrupted by {name}"
    run = _run_dir(tmp_path / "out")
    assert f"--resume {run}" in stderr and "recording is written when the sweep" in stderr
    done = _check_partial(run, f"interrupted by {name}")
    assert f"kept {done} of {COUNT} scenarios" in stderr
    assert os.listdir(tmp_path / "tmp") == []  # no lcc-sweep-dask-*, no dask-scratch-space
    _resume_equals(tmp_path, run, uninterrupted)
    assert os.listdir(tmp_path / "tmp") == []


def test_a_killed_sweep_resumes_from_its_last_write_and_a_resume_checks_its_sweep(
    tmp_path, uninterrupted
):
    """``SIGKILL``: the partial files of the last periodic write (status ``running``) are
    resumed. Before that, a resume that would not continue the same sweep is one line naming
    what differs (exit 2, before any work, the partial files untouched); after it, a resume of
    the complete sweep is refused too."""
    proc, _, _, _ = _interrupt(tmp_path, signal.SIGKILL)
    assert proc.returncode == -signal.SIGKILL
    run = _run_dir(tmp_path / "out")
    _check_partial(run, "running")
    before = (run / "samples.csv").read_bytes(), (run / "sweep.json").read_bytes()

    def refused(*args, problem=PROBLEM):
        p = run_cli(["sweep", problem, "--resume", run, "--no-record", "--no-progress", *args],
                    cwd=tmp_path, env=_env(tmp_path))  # fmt: skip
        assert p.returncode == 2 and one_line_error(p.stderr), p.stderr
        return p.stderr

    assert "count differs" in refused("--count", "13")
    assert "controllers differ" in refused("--controllers", "paper")
    edited = tmp_path / "edited.toml"
    edited.write_text(PROBLEM.read_text().replace("count = 1000", "count = 999"))
    err = refused(problem=edited)
    assert "problem file" in err and "SHA-256" in err
    assert ((run / "samples.csv").read_bytes(), (run / "sweep.json").read_bytes()) == before
    _resume_equals(tmp_path, run, uninterrupted)
    assert "complete: nothing to resume" in refused()
