"""The loop as it runs on an open platoon (several CAVs): lcc_synth.analysis.as_run against the
plain platoon analysis, the one-CAV loop and the simulator.

Truths:

* the continuous loop with a fixed equilibrium, no latency and no filter is the closed loop of
  the gains: its ``Gamma`` is :func:`gamma_state_space`'s and its verdict, peak and margin are
  :func:`gains_string_stability`'s (the plain platoon analysis);
* a platoon with one CAV has the paper's ``kind = "lcc"`` matrices bit for bit (renumbered),
  so its loop is the one-CAV loop, entry for entry;
* the simulator (explicit Euler at ``dt``, the controller sampled every ``sample_time``, V2V
  values ``latency`` old and filtered): the measured tail/head amplitude ratio's relative error
  is first order in ``dt`` (measured on the two-CAV platoon below at dt = 0.01 s: at most
  5.3e-5, 2.1e-4, 2.2e-3 at 0.05, 0.1, 0.3 rad/s over CASES, halved at dt = 0.005 s; the same
  as the one-CAV string of tests/test_as_run.py, whose bounds are used); Richardson
  extrapolation ``2 r(dt/2) - r(dt)`` removes the Euler term and matches the sampled loop to
  7.2e-5 (bound 3e-4).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import lcc_synth as lcc
from lcc_synth.analysis.as_run import as_run_loop, as_run_report, law_of_gains
from lcc_synth.analysis.string_stability import gains_string_stability
from lcc_synth.analysis.transfer import gamma_state_space
from lcc_synth.controllers.static import HDVController, StaticGainController
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.string_as_run import controller_loop, gamma_curves, measured_ratio
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import OVM

HDV = OVM(alpha=0.6, beta=0.9, s_st=5.0, s_go=35.0, v_max=30.0)
OMEGA = np.array([0.05, 0.1, 0.3])
#: Two CAVs, the first right behind the head (its HDV law reads the head's velocity, received
#: over V2V), each HDV with its own alpha; each CAV reads HDVs (received) and the other CAV
#: (exact: every CAV's own values are exact to every CAV).
TABLE = {
    "u_1": {"s_1": 0.1, "v_1": -0.2, "s_2": -0.2, "v_2": 0.05, "v_4": 0.05},
    "u_4": {"v_1": 0.1, "s_3": 0.1, "v_3": 0.2, "s_4": 0.1, "v_4": -0.4, "s_5": -0.2,
            "v_5": 0.05, "v_6": 0.1},
}  # fmt: skip


def _platoon():
    return lcc.system(size=6, cavs=[1, 4], v_star=15.0, hdv=HDV,
                      hdv_values={"alpha": [0.6, 0.5, 0.7, 0.6, 0.8, 0.55]})  # fmt: skip


def _gains(model, semantics="added"):
    return Gains.from_table(TABLE, model, semantics)


# --------------------------------------------------------------------- the plain analysis


@pytest.mark.parametrize("semantics", ["added", "replace"])
def test_continuous_loop_is_the_plain_platoon_string_stability(semantics):
    model = _platoon().linear_model(warn=False)
    gains = _gains(model, semantics)
    loop = as_run_loop(model, law_of_gains(model, gains))
    K, kh = gains.input_feedback(model)
    w = np.logspace(-2, 1, 30)
    assert np.allclose(loop.response(w), gamma_state_space(model, K, kh, w), rtol=1e-10)
    bare, rep = gains_string_stability(model, gains), as_run_report(loop)
    assert rep.verdict == bare.verdict
    assert math.isclose(rep.gamma_peak, bare.gamma_peak, rel_tol=1e-10)
    assert math.isclose(rep.margin, bare.margin, rel_tol=1e-8)
    # the sampled loop tends to it as T -> 0 (the hold's delay T/2 moves the margin by O(T))
    fine = as_run_report(as_run_loop(model, law_of_gains(model, gains), 1e-3))
    assert fine.verdict == bare.verdict and abs(fine.margin - bare.margin) < 1e-2 * abs(bare.margin)


# ------------------------------------------------------------------------ one CAV: the same


@pytest.mark.parametrize("semantics", ["added", "replace"])
def test_a_one_cav_platoon_is_the_one_cav_loop(semantics):
    """kind = "lcc", m = 2, n = 3 and the platoon of 6 with its CAV at 3: the same matrices,
    so the same loop (states renumbered: s_-2 .. v_3 are s_1 .. v_6) entry for entry."""
    one = lcc.system("lcc", 2, 3, 15.0, HDV)
    pl = lcc.system(size=6, cavs=[3], v_star=15.0, hdv=HDV)
    m1, mp = one.linear_model(warn=False), pl.linear_model(warn=False)
    paper = {"s_-1": 0.2, "v_-2": 0.1, "s_0": 0.1, "v_0": -0.5, "s_1": -0.2, "v_1": 0.05,
             "s_2": -0.1, "v_2": 0.05}  # fmt: skip
    renamed = {f"{nm[0]}_{int(nm[2:]) + 3}": g for nm, g in paper.items()}
    g1 = Gains.named(paper, semantics)
    gp = Gains.from_table({"u_3": renamed}, mp, semantics)
    for args in [(None,), (0.1,), (0.1, 0.2), (0.1, 0.2, None, 0.3), (0.1, 0.1, None, 0.3, 0.2)]:
        a = as_run_loop(m1, law_of_gains(m1, g1), *args)
        b = as_run_loop(mp, law_of_gains(mp, gp), *args)
        for x, y in [(a.A, b.A), (a.h, b.h), (a.c, b.c), (a.u_row, b.u_row[0])]:
            assert np.max(np.abs(x - y), initial=0.0) <= 1e-12, args
        assert abs(a.d - b.d) <= 1e-12 and a.settings == b.settings
        ra, rb = as_run_report(a), as_run_report(b)
        assert ra.verdict == rb.verdict and abs(ra.gamma_peak - rb.gamma_peak) <= 1e-12
    # the simulator's law of either controller (law_of_linear): the same loop again
    ca = StaticGainController("g", g1, m1, sample_time=0.1, measurement_filter=0.3)
    cb = StaticGainController("g", gp, mp, sample_time=0.1, measurement_filter=0.3)
    la, lb = controller_loop(ca, one, 0.01, 0.1), controller_loop(cb, pl, 0.01, 0.1)
    assert np.max(np.abs(la.A - lb.A)) <= 1e-12 and np.max(np.abs(la.h - lb.h)) <= 1e-12
    # what differs: a platoon's controllers run with a fixed equilibrium (StaticGainController)
    with pytest.raises(ConfigError) as info:
        as_run_loop(mp, law_of_gains(mp, gp), 0.1, 0.0, 1.0)
    assert info.value.field == "equilibrium_tau" and "fixed" in info.value.message


def test_as_run_h2_of_a_platoon_loop():
    """Continuous: the dual Lyapunov equation of the closed loop (the cost-to-go ``P``,
    ``J = tr(Bw' P Bw)``) with each CAV's gain without its HDV law weighted; sampled: tends to
    it as T -> 0 (the hold's O(T) error)."""
    import scipy.linalg as sla

    from lcc_synth.analysis.as_run_h2 import as_run_h2

    model = _platoon().linear_model(warn=False)
    gains = _gains(model)
    Q = np.diag(np.tile([0.5, 1.0], 6))
    Bw = np.zeros((model.nx, 6))
    Bw[1::2] = np.eye(6)  # acceleration noise on every vehicle
    cont = as_run_h2(as_run_loop(model, law_of_gains(model, gains)), Bw, Q, 1.0)
    K, kh = gains.input_feedback(model)
    Kg = gains.matrix(model)  # the gain alone ("added" to each CAV's HDV law)
    Acl = model.A + model.B @ K
    P = sla.solve_continuous_lyapunov(Acl.T, -(Q + Kg.T @ Kg))
    assert math.isclose(cont, math.sqrt(np.trace(Bw.T @ P @ Bw)), rel_tol=1e-9)
    errs = [abs(as_run_h2(as_run_loop(model, law_of_gains(model, gains), T), Bw, Q, 1.0)
                / cont - 1) for T in (0.02, 0.01)]  # fmt: skip
    assert errs[1] < errs[0] < 0.05 and errs[1] < 0.7 * errs[0]


# ----------------------------------------------------------------------- against the simulator


CASES = [
    ({}, 0.0),
    ({"sample_time": 0.1}, 0.1),
    ({"sample_time": 0.1, "measurement_filter": 0.3}, 0.2),
]


@pytest.mark.parametrize("extra,latency", CASES)
def test_sampled_platoon_loop_equals_the_simulated_amplitude_ratio(extra, latency):
    system = _platoon()
    model = system.linear_model(warn=False)
    ctrl = StaticGainController("g", _gains(model), model, **extra)
    analysed = np.abs(controller_loop(ctrl, system, 0.01, latency).response(OMEGA))
    r1 = measured_ratio(ctrl, system, OMEGA, 0.01, latency)
    assert np.all(np.abs(r1 / analysed - 1) < [1e-3, 1e-3, 6e-3]), (r1, analysed)
    r2 = measured_ratio(ctrl, system, OMEGA, 0.005, latency)
    fine = np.abs(controller_loop(ctrl, system, 0.005, latency).response(OMEGA))
    assert np.all(np.abs((2 * r2 - r1) / fine - 1) < 3e-4), (r1, r2, fine)
    assert analysed.max() > 1.0  # these gains amplify: the comparison is not of ones


def test_cavs_driving_as_hdvs_on_a_platoon_and_the_ring_refusal():
    system = _platoon()
    ctrl = HDVController("hdv", sample_time=0.1)
    curves = gamma_curves({"hdv": ctrl}, system, OMEGA, 0.01, 0.1, measure_omega=None)
    analysed, rep = curves["hdv"]
    assert rep.verdict in ("string_stable", "string_unstable")
    measured = measured_ratio(ctrl, system, OMEGA, 0.01, 0.1)
    assert np.all(np.abs(measured / analysed - 1) < [1e-3, 1e-3, 6e-3]), (measured, analysed)
    ring = lcc.ring(8, cavs=[8], v_star=15.0, hdv=HDV)
    rmodel = ring.linear_model(warn=False)
    gains = Gains.from_table({"u_8": {"v_8": -0.3, "s_7": 0.1}}, rmodel, "added")
    with pytest.raises(ConfigError) as info:
        as_run_loop(rmodel, law_of_gains(rmodel, gains), 0.1)
    assert info.value.field == "system.kind" and "no head vehicle" in info.value.message
    with pytest.raises(ConfigError, match="no head vehicle"):
        controller_loop(StaticGainController("g", gains, rmodel), ring)
    assert gamma_curves({"g": StaticGainController("g", gains, rmodel)}, ring, OMEGA) == {}


# ------------------------------------------------------------------------------ lcc-synth run


def test_run_analyses_the_platoon_layout_as_run(tmp_path, capsys):
    """``lcc-synth run`` on the showcase's two-CAV platoon: every linear controller's loop as
    run (both CAVs sampled every 0.05 s, the scenario's step), the same report as the analysis
    of the gain it wrote (gains file) and of the CAVs' HDV law ("added" zero gain)."""
    import json
    from pathlib import Path

    from lcc_synth.cli.main import main
    from lcc_synth.experiments.comparison import load_suite
    from lcc_synth.synthesis.gains_file import read_gains

    showcase = Path(__file__).resolve().parents[1] / "problems" / "showcase.toml"
    assert main(["run", str(showcase), "--scenarios", "platoon_brake", "--controllers",
                 "all_hdv,h2", "--json", "--no-record", "--no-figures", "-q",
                 "--out", str(tmp_path)]) == 0  # fmt: skip
    ss = json.loads(capsys.readouterr().out)["string_stability"]
    assert set(ss) == {"platoon8"} and set(ss["platoon8"]) == {"all_hdv", "h2"}
    [gains_file] = tmp_path.glob("*/gains_platoon8_h2.json")
    system = load_suite(showcase, ["platoon_brake"], ["h2"]).layouts["platoon8"]
    model = system.linear_model(warn=False)
    gains, _ = read_gains(gains_file, model=model)
    for name, g in [("h2", gains), ("all_hdv", Gains.zero(model, "added"))]:
        rep = as_run_report(as_run_loop(model, law_of_gains(model, g), 0.05)).as_dict()
        got = ss["platoon8"][name]
        assert got["verdict"] == rep["verdict"] and got["as_run"]["sample_time"] == 0.05
        assert math.isclose(got["gamma_peak"], rep["gamma_peak"], rel_tol=1e-9)
        assert math.isclose(got["margin"], rep["margin"], rel_tol=1e-6)
    assert ss["platoon8"]["all_hdv"]["verdict"] == "string_unstable"
    assert ss["platoon8"]["h2"]["verdict"] == "string_stable"
