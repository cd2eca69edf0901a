"""The MPC in the nonlinear simulator (problem files under problems/)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lcc_synth.experiments.spec import load_spec
from lcc_synth.metrics import summary
from lcc_synth.mpc.report import bound_margin, safety_summary
from lcc_synth.simulation.engine import simulate

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"


def test_head_brake_spacing_bound_holds_without_emergency_braking():
    spec = load_spec(PROBLEMS / "mpc_head_brake.toml")
    mpc = simulate(spec.scenario, spec.controllers["mpc"])
    assert not mpc.collided.any()
    assert not mpc.aeb_active.any()
    # the absolute bound s0 >= 5 m + 0.8 s * v0 at every 0.01 s step, not only at samples
    assert bound_margin(mpc).min() >= 0.0
    st = mpc.controller_stats
    assert st["fallbacks"] == 0 and st["qp_failures"] == {} and st["violation_steps"] == 0
    assert st["solves"] == 600
    # the CAV really had to brake: the head went 15 -> 5 m/s at -5 m/s^2
    assert mpc.u_cmd.min() < -4.0
    # control experiment: the paper's static CF-LCC gain in the same scenario runs into the
    # emergency brake and comes within a metre of the head vehicle
    paper = simulate(spec.scenario, spec.controllers["cf_lcc_paper"])
    assert paper.aeb_active.any()
    assert bound_margin(paper).min() < -5.0
    safe = safety_summary(paper)
    assert safe["bound_violation_steps"] > 100 and safe["max_bound_violation_m"] > 5.0
    safe = safety_summary(mpc)
    assert safe["bound_violation_steps"] == 0 and safe["fallbacks"] == 0
    # and the MPC smooths the string better than the CAV driving as an HDV
    hdv = simulate(spec.scenario, spec.controllers["all_hdv"])
    assert summary(mpc, spec.metrics)["aave"] < summary(hdv, spec.metrics)["aave"]


def test_heterogeneous_noisy_lossy_head_brake():
    spec = load_spec(PROBLEMS / "mpc_head_brake_hetero.toml")
    sc = replace(spec.scenario, batch=2)
    res = simulate(sc, spec.controllers["mpc"])
    assert res.scenario.v2v.loss_rate == pytest.approx(0.2)
    assert not res.collided.any()
    assert not res.aeb_active.any()
    assert bound_margin(res).min() >= 0.0
    st = res.controller_stats
    assert st["fallbacks"] == 0 and st["errors"] == 0
    assert st["solves"] == 2 * 600


def test_table2_fd_mpc_beats_looking_ahead():
    spec = load_spec(PROBLEMS / "mpc_table2_fd.toml")
    sc = replace(spec.scenario, duration=45.0)
    mpc = simulate(sc, spec.controllers["mpc"])
    hdv = simulate(sc, spec.controllers["all_hdv"])
    a_mpc = summary(mpc, spec.metrics)["aave"]
    a_hdv = summary(hdv, spec.metrics)["aave"]
    assert a_hdv == pytest.approx(0.89, abs=0.005)  # Table II, looking ahead
    assert a_mpc < 0.8 * a_hdv
    assert not mpc.aeb_active.any() and not mpc.collided.any()
    assert np.all(np.isfinite(mpc.u_cmd))
