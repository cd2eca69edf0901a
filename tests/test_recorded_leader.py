"""A recorded leader as a perturbation (``type = "trajectory"``) and ``[scenario] initial =
"data"``: the head has the file's speed at every sample time, the platoon starts from the
file's first sample, bad entries are one error naming the field; and the problem file that
``lcc-synth calibrate --out`` writes simulates, agreeing with the calibration's own platoon
replay (a second integrator)."""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

import lcc_synth as lcc
from lcc_synth.calibration.fit import calibrate
from lcc_synth.calibration.problem import write_problem
from lcc_synth.errors import ConfigError
from lcc_synth.schema.trajectories import read_trajectory

ROOT = Path(__file__).resolve().parents[1]
LANE2 = ROOT / "problems" / "data" / "ngsim_i80" / "i80_lane2.csv"

PROBLEM = """
[hdv]
model = "ovm"
[system]
kind = "platoon"
size = 4
cavs = [4]
v_star = 8.0
vehicle_length = 5.0
[scenario]
dt = 0.01
duration = {duration}
a_min = -9.0
a_max = 9.0
cav_aeb = false
initial = "{initial}"
{extra}
[[scenario.perturbations]]
type = "trajectory"
vehicle = {vehicle}
file = "{file}"
column = "{column}"
interpolation = "{interpolation}"
start = {start}
[metrics]
window = [0.0, 10.0]
vehicles = "all"
[controllers.replay]
type = "hdv"
"""


def _problem(tmp_path: Path, **keys) -> Path:
    shutil.copy(LANE2, tmp_path / "lane2.csv")
    values = {"duration": 12.0, "initial": "data", "vehicle": '"head"', "file": "lane2.csv",
              "column": "v0", "interpolation": "linear", "start": 0.0, "extra": "",
              **keys}  # fmt: skip
    path = tmp_path / "p.toml"
    path.write_text(PROBLEM.format(**values))
    return path


def _scenario(path: Path):
    return lcc.load_problem(path).scenario


def _run(path: Path):
    objs = lcc.load_problem(path)
    return lcc.simulate(objs.scenario, objs.controllers["replay"])


@pytest.mark.parametrize("interpolation", ["linear", "previous"])
def test_head_has_the_recorded_speed_at_every_sample_time(tmp_path, interpolation):
    tr = read_trajectory(LANE2)
    res = _run(_problem(tmp_path, interpolation=interpolation))
    k = np.rint(tr.t / 0.01).astype(int)
    k = k[k < res.t.size]
    assert np.allclose(res.t[k], tr.t[: k.size])
    assert np.abs(res.velocity[0, k, 0] - tr.v[0, : k.size]).max() < 1e-9
    half = k[:-1] + 5  # half-way between two samples
    mid = res.velocity[0, half, 0]
    if interpolation == "linear":
        expected = 0.5 * (tr.v[0, : k.size - 1] + tr.v[0, 1 : k.size])
    else:
        expected = tr.v[0, : k.size - 1]
    assert np.abs(mid - expected).max() < 1e-9


@pytest.mark.sumo
def test_sumo_replays_the_recorded_leader_from_the_first_sample(tmp_path):
    """The same entry in SUMO (``backend = "sumo"``): the head, commanded by ``setSpeed``,
    has the file's speed at every sample time, and the platoon departs from the file's first
    sample (speeds, and spacings as headway - vehicle length)."""
    tr = read_trajectory(LANE2)
    path = _problem(tmp_path, extra='backend = "sumo"')
    path.write_text(path.read_text().replace('model = "ovm"', 'model = "idm"'))
    res = _run(path)
    assert res.velocity[0, 0] == pytest.approx(tr.v[:, 0], abs=1e-9)
    assert res.spacing[0, 0, 1:] == pytest.approx(tr.headway[1:, 0] - 5.0, abs=1e-9)
    k = np.rint(tr.t / 0.01).astype(int)
    k = k[k < res.t.size]
    assert np.abs(res.velocity[0, k, 0] - tr.v[0, : k.size]).max() < 1e-9


def test_platoon_starts_from_the_first_sample(tmp_path):
    tr = read_trajectory(LANE2)
    res = _run(_problem(tmp_path))
    assert res.velocity[0, 0] == pytest.approx(tr.v[:, 0], abs=1e-12)
    assert res.spacing[0, 0, 1:] == pytest.approx(tr.headway[1:, 0] - 5.0, abs=1e-12)


def test_a_later_start_cruises_at_the_first_recorded_speed_until_then(tmp_path):
    tr = read_trajectory(LANE2)
    res = _run(_problem(tmp_path, start=2.0))
    assert np.all(res.velocity[0, res.t <= 2.0, 0] == tr.v[0, 0])
    k = 200 + np.rint(tr.t / 0.01).astype(int)
    k = k[k < res.t.size]
    assert np.abs(res.velocity[0, k, 0] - tr.v[0, : k.size]).max() < 1e-9


BAD = {
    "file missing": ({"file": "nope.csv"}, "scenario.perturbations[0].file: ",
                     "nope.csv: no such trajectory file"),
    "column missing": ({"column": "v9"}, "scenario.perturbations[0].column: ",
                       "lane2.csv has no column 'v9'; columns: v0, headway0, a0"),
    "not a speed": ({"column": "headway1"},
                    "scenario.perturbations[0].column: must be a speed column v<k> (m/s)"),
    "wrong vehicle": ({"vehicle": "1"}, "scenario.perturbations[0].vehicle: a recorded "
                      'trajectory drives the head vehicle of an open road: must be "head"'),
    "head speed differs": ({"initial": "equilibrium"},
                           "scenario.perturbations[0].column: the head starts at 8 m/s but the "
                           'recording starts at 3.3345 m/s: set [scenario] initial = "data"'),
    "bad interpolation": ({"interpolation": "cubic"},
                          "scenario.perturbations[0].interpolation: must be one of"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_entry_is_one_error_naming_the_field(tmp_path, case):
    keys, expected, *more = BAD[case]
    path = _problem(tmp_path, **keys)
    with pytest.raises(ConfigError) as exc:
        _scenario(path)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{path}: {expected}"), msg
    assert all(m in msg for m in more), msg


def test_initial_data_needs_a_recording_of_the_whole_string(tmp_path):
    path = _problem(tmp_path)
    text = path.read_text().replace("size = 4\ncavs = [4]", "size = 3\ncavs = [3]")
    path.write_text(text)
    with pytest.raises(ConfigError, match=r"scenario.initial: .*lane2.csv holds 5 vehicles; "
                       r"the string has 4"):
        _scenario(path)
    text = path.read_text()
    block = text[text.index("[[scenario.perturbations]]"):text.index("[metrics]")]
    path.write_text(text.replace(block, "").replace("size = 3\ncavs = [3]", "size = 4\ncavs = [4]"))
    with pytest.raises(ConfigError, match=r'scenario.initial: "data" takes the initial state '
                       r'from a recording: add a \[\[scenario.perturbations\]\] entry'):
        _scenario(path)


@pytest.mark.slow
def test_calibrated_problem_simulates_as_the_calibrations_platoon_replay(tmp_path):
    """The written problem in the built-in simulator (Euler, dt = 0.01 s) against the
    calibration's platoon replay (held accelerations at the recorded 0.1 s): every follower's
    spacing RMSE agrees to 0.15 m (measured 0.06 m at most)."""
    tr = read_trajectory(LANE2)
    cal = calibrate(tr, "ovm", starts=1)
    path = write_problem(tmp_path / "sub" / "lane2.toml", cal, tr)
    rel = tomllib.loads(path.read_text())["scenario"]["perturbations"][0]["file"]
    assert not Path(rel).is_absolute() and (path.parent / rel).resolve() == LANE2.resolve()
    res = _run_named(path)
    k = np.rint(tr.t / 0.01).astype(int)
    assert k[-1] == res.t.size - 1
    head = res.velocity[0, k, 0]
    assert np.abs(head - tr.v[0]).max() < 1e-9
    for f in cal.followers:
        i = f.index
        rmse = np.sqrt(np.mean((res.spacing[0, k[1:], i] - (tr.headway[i, 1:] - 5.0)) ** 2))
        assert rmse == pytest.approx(f.platoon_rmse_spacing, abs=0.15), i
    assert not res.collided.any()


def _run_named(path: Path):
    objs = lcc.load_problem(path)
    [name] = objs.controllers
    return lcc.simulate(objs.scenario, objs.controllers[name])


def test_shipped_calibrated_lane2_problem_simulates():
    """problems/ngsim_lane2_calibrated.toml (written by ``lcc-synth calibrate --out``): the
    head replays lane 2's front vehicle, the followers start from the data, nobody collides."""
    tr = read_trajectory(LANE2)
    res = _run_named(ROOT / "problems" / "ngsim_lane2_calibrated.toml")
    k = np.rint(tr.t / 0.01).astype(int)
    assert np.abs(res.velocity[0, k, 0] - tr.v[0]).max() < 1e-9
    assert res.velocity[0, 0] == pytest.approx(tr.v[:, 0], abs=1e-12)
    assert not res.collided.any()
