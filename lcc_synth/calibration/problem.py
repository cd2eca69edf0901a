"""The problem file of a calibrated platoon (``lcc-synth calibrate --out FILE.toml``).

The recorded platoon becomes ``[system] kind = "platoon"`` with ``size`` = the followers,
every follower's calibrated values in ``[system.hdv_values]`` (``[hdv]`` holds the pooled
fit), the head replaying the recorded front vehicle (``type = "trajectory"``, the data file
named relative to the problem file) and every vehicle starting from the recording's first
sample (``[scenario] initial = "data"``). The simulator needs one CAV slot: the tail's, driven
by ``type = "hdv"``, i.e. by its own calibrated law, so the run is the all-HDV platoon replay.

Simulation settings: ``dt = 0.01 s`` (a divisor of the recording's period, so that the head
lands on every recorded sample), the run as long as the recording, acceleration limits wide
enough not to act (``[-9, 9] m/s²``: the fits have no limits), no emergency braking, metrics
over the whole run and every vehicle. ``v_star`` (the linearisation point, not the initial
state) is the recording's mean follower speed, kept below every calibrated free speed.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import tomli_w

from lcc_synth.calibration.fit import Calibration
from lcc_synth.calibration.replay import PARAMS
from lcc_synth.errors import ConfigError
from lcc_synth.outputs import write_text
from lcc_synth.schema.trajectories import Trajectory

__all__ = ["SIM_DT", "problem_table", "write_problem"]

#: Integration step of the written problem (s).
SIM_DT = 0.01


def _free_speed(model: str, params: dict[str, float]) -> float:
    return params["v_max"] if model == "ovm" else params["v0"]


def problem_table(cal: Calibration, traj: Trajectory, data_file: str, name: str) -> dict:
    """The TOML document (as a dict) of the calibrated platoon named ``name``; ``data_file``
    is the trajectory file as the problem file names it (relative to the problem file)."""
    ratio = traj.dt / SIM_DT
    if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
        raise ConfigError("--out", f"the recording's period {traj.dt:g} s is not a multiple of "
                          f"the simulation step {SIM_DT} s")  # fmt: skip
    names = PARAMS[cal.model]
    F = len(cal.followers)
    fits = [f.fit.params for f in cal.followers]
    cap = min(_free_speed(cal.model, p) for p in [*fits, cal.pooled.params])
    v_star = min(float(np.mean(traj.v[1:])), 0.9 * cap)
    v_star = math.floor(v_star * 100) / 100
    duration = round(float(traj.t[-1] - traj.t[0]) + SIM_DT, 6)
    rmse = ", ".join(f"{f.index}: {f.fit.rmse_spacing:.2f} m / {f.fit.rmse_velocity:.2f} m/s"
                     for f in cal.followers)  # fmt: skip
    flat = sorted({k for f in cal.followers for k, ok in f.fit.identified.items() if not ok})
    description = (
        f"Calibrated {cal.model.upper()} platoon of {Path(traj.path).name} (lcc-synth "
        f"calibrate, {cal.starts} starts, seed {cal.seed}, vehicle length {cal.length:g} m). "
        f"The head replays the recorded front vehicle (v0); followers 1..{F} start from the "
        "first recorded sample and drive with their own calibrated values (position i = file "
        "vehicle i). Pairwise replay RMSE (spacing / speed) per follower: "
        f"{rmse}. Parameters the data did not identify: "
        f"{', '.join(flat) if flat else 'none'}. The tail's slot is a CAV driven by its own "
        "law (controllers.replay, type = hdv): the run is the all-HDV replay."
    )
    return {
        "name": name,
        "description": description,
        "hdv": {"model": cal.model, **{k: round(cal.pooled.params[k], 6) for k in names}},
        "system": {
            "kind": "platoon", "size": F, "cavs": [F], "v_star": v_star,
            "vehicle_length": cal.length,
            "hdv_values": {k: [round(p[k], 6) for p in fits] for k in names},
        },
        "scenario": {
            "dt": SIM_DT, "duration": duration, "a_min": -9.0, "a_max": 9.0,
            "cav_aeb": False, "hdv_aeb": False, "initial": "data",
            "perturbations": [{"type": "trajectory", "vehicle": "head", "file": data_file,
                               "column": "v0", "interpolation": "linear", "start": 0.0}],
        },
        "metrics": {"window": [0.0, round(duration - SIM_DT, 6)], "vehicles": "all"},
        "controllers": {"replay": {"type": "hdv"}},
    }  # fmt: skip


def write_problem(path: str | Path, cal: Calibration, traj: Trajectory,
                  overwrite: bool = False) -> Path:
    """Write the problem file of ``cal`` atomically (:func:`lcc_synth.outputs.write_text`);
    the data file is named relative to it. Returns the name used."""
    path = Path(path)
    rel = os.path.relpath(Path(traj.path).resolve(), path.resolve().parent)
    text = tomli_w.dumps(problem_table(cal, traj, Path(rel).as_posix(), path.stem))
    return write_text(path, text, overwrite)
