"""SIGINT (Ctrl-C) and SIGTERM at a random moment of ``calibrate --out F.toml`` and
``simulate --export DIR``: the command stops within the hang bound, exits ``128 + signum``
with one line on stderr, and leaves no partial output: no ``F.toml`` (it is written, atomically,
only after the fits) and, in ``DIR``, only complete files (every one reads back with the full
run: every sample of every vehicle) and no temporary file.

The moment is drawn at random (the delay is in every assertion message); the signal helper is
:func:`test_fail_signals._interrupt` (the one of ``run``, ``simulate`` and ``synthesize``).
"""

from __future__ import annotations

import signal

import pytest
from cli_subprocess import PROBLEMS, REPO
from test_fail_signals import _interrupt

from lcc_synth.simulation.export import read_trajectories

LANE2 = REPO / "problems" / "data" / "ngsim_i80" / "i80_lane2.csv"


def _one_line(err: str, sig: int, delay: float) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, (delay, err)
    assert lines[0].endswith(f": interrupted by {signal.Signals(sig).name}"), (delay, err)


# slow (CI runs it): a signal at a random moment of a >= 8 s calibration; the default suite
# checks the same clean stop on simulate (test_fail_signals.test_simulate)
@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_calibrate_out(tmp_path, sig):
    # the whole calibration of lane 2 (4 followers + pooled, 5 starts) takes >= 8 s here
    _, out, err, delay, _ = _interrupt(
        ["calibrate", LANE2, "--out", "F.toml", "-q"], tmp_path, sig, (2.5, 7.0)
    )
    _one_line(err, sig, delay)
    assert out == "", delay  # no report of a calibration that did not finish
    assert sorted(p.name for p in tmp_path.iterdir()) == [], delay  # no F.toml, no temp file


# slow (CI runs it): the same stop of simulate is test_fail_signals.test_simulate (default);
# the export's own failure paths are test_fail_export's (default)
@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_simulate_export(tmp_path, sig):
    _, _, err, delay, _ = _interrupt(
        ["simulate", PROBLEMS / "mpc_head_brake.toml", "--seeds", "4", "--no-record",
         "--export", "traj", "-q"], tmp_path, sig, (2.5, 8.0),
    )  # fmt: skip
    _one_line(err, sig, delay)
    out = tmp_path / "traj"
    names = sorted(p.name for p in out.iterdir()) if out.exists() else []
    assert all(n.endswith(".csv") and not n.startswith(".") for n in names), (delay, names)
    for n in names:  # every file written is whole: 60 s / 0.01 s = 6000 samples x 12 vehicles
        tr = read_trajectories(out / n)
        assert tr.grid("velocity").shape == (6000, 12), (delay, n)
        assert tr.grid("t")[-1, 0] == pytest.approx(59.99, abs=1e-9), (delay, n)
