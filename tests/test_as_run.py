"""The loop as it runs (lcc_synth.analysis.as_run) against the simulator and an independent
frequency-domain construction.

Tolerances of the simulator comparisons (measured, see lcc_synth.experiments.string_as_run):

* Euler integration at dt = 0.01 s: the relative error of the measured ratio is first order in
  dt (it halves at dt = 0.005: 9e-5, 4e-4, 3.8e-3 at w = 0.05, 0.1, 0.3 rad/s become 5e-5,
  2e-4, 1.7e-3; the same for every controller, fixed or estimated, sampled or not: it is the
  HDVs' integration). Bound used: 0.6 % at 0.3 rad/s, 0.1 % below.
* amplitude extraction: least squares (multisine) over one period of the slowest frequency
  after 150 s; the transient left is
  e^-10 of its start (slowest pole -0.068 1/s), below 1e-5;
* nonlinearity: the ratios at head amplitudes 0.1 and 0.02 m/s differ by < 1e-5.
Richardson extrapolation (2 r(dt/2) - r(dt)) removes the Euler term: it then matches the
sampled loop to 1e-4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla

from lcc_synth.analysis.as_run import (
    NotRepresentable,
    as_run_loop,
    as_run_report,
    equilibrium_slope,
    law_loop,
    law_of_gains,
    tustin,
)
from lcc_synth.analysis.as_run_h2 import as_run_h2
from lcc_synth.controllers.registry import build_controller
from lcc_synth.controllers.static import LinearLaw
from lcc_synth.experiments.string_as_run import controller_loop, gamma_curves, measured_ratio
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import cf_lcc, discretize, model_from_hdv
from lcc_synth.problem import System

PAPER = {"s_0": 0.1, "v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}
H2 = {"s_0": 0.282924, "v_0": -2.633268, "s_1": -1.400903, "v_1": -0.009594,
      "s_2": -1.246173, "v_2": 0.080802}  # fmt: skip
OMEGA = np.array([0.05, 0.1, 0.3])


def _system(n=10):
    hdv = OVM(alpha=0.6, beta=0.9, s_st=5.0, s_go=35.0, v_max=30.0)
    return System(kind="cf_lcc", m=0, n=n, v_star=15.0, hdv=hdv)


def _table(gains, **extra):
    return {"type": "static", "semantics": "replace", "gains": gains, **extra}


# ------------------------------------------------------------------ against the simulator


CASES = [
    ("paper", PAPER, {}),
    ("paper", PAPER, {"equilibrium": "estimated"}),
    ("h2", H2, {"equilibrium": "estimated"}),
    ("h2", H2, {"sample_time": 0.1}),
    ("h2", H2, {"sample_time": 0.1, "equilibrium": "estimated"}),
    ("paper", PAPER, {"sample_time": 0.1, "equilibrium": "estimated", "equilibrium_tau": 2.0}),
]


@pytest.mark.parametrize("latency", [0.0, 0.1])
@pytest.mark.parametrize("name,gains,extra", CASES)
def test_as_run_gamma_equals_the_simulated_amplitude_ratio(name, gains, extra, latency):
    system = _system()
    ctrl = build_controller(name, _table(gains, **extra), system)
    loop = controller_loop(ctrl, system, 0.01, latency)
    analysed = np.abs(loop.response(OMEGA))
    measured = measured_ratio(ctrl, system, OMEGA, 0.01, latency)
    tol = np.array([1e-3, 1e-3, 6e-3])
    assert np.all(np.abs(measured / analysed - 1) < tol), (measured, analysed)
    if extra.get("equilibrium") == "estimated":  # the estimator is what makes it amplify
        assert analysed[1] > 1.0


def test_richardson_extrapolated_ratio_matches_the_sampled_loop_tightly():
    system = _system()
    ctrl = build_controller("h2", _table(H2, sample_time=0.1, equilibrium="estimated"), system)
    r1 = measured_ratio(ctrl, system, OMEGA, 0.01, 0.1)
    r2 = measured_ratio(ctrl, system, OMEGA, 0.005, 0.1)
    analysed = np.abs(controller_loop(ctrl, system, 0.005, 0.1).response(OMEGA))
    assert np.all(np.abs((2 * r2 - r1) / analysed - 1) < 1e-4)


def test_gamma_curves_analyse_what_runs_and_measure_the_rest():
    system = _system(4)
    ctrls = {
        "fixed": build_controller("fixed", _table(PAPER), system),
        "est": build_controller("est", _table(PAPER, equilibrium="estimated"), system),
    }

    class NotLinear:  # the protocol without linear_law: measured
        name, sample_time = "nl", None

        def __init__(self):
            self.inner = ctrls["est"]

        def reset(self, ctx):
            self.inner.reset(ctx)

        def __call__(self, obs):
            return self.inner(obs)

        def describe(self):
            return {}

        def stats(self):
            return {}

    ctrls["nl"] = NotLinear()
    omega = np.logspace(-2, 0, 50)
    curves = gamma_curves(ctrls, system, omega, measure_omega=(0.1, 0.3))
    assert curves["fixed"][1].verdict == "string_stable"
    assert curves["est"][1].verdict == "string_unstable"
    rep = curves["nl"][1]
    assert rep.verdict == "not_linear" and rep.as_dict()["linear"] is False
    ref = np.abs(controller_loop(ctrls["est"], system).response(rep.omega))
    assert np.allclose(rep.ratio, ref, rtol=5e-3)


# ------------------------------------------------------- independent frequency-domain check


@dataclass(frozen=True)
class FilteredLaw(LinearLaw):
    """A law with the measurement filter another change adds to LinearLaw."""

    measurement_filter: float = 0.0


def _reference(model, law, T, latency, tau, tf, omega):
    """Gamma(e^{jwT}) by a direct solve of the loop's equations in the frequency domain: the
    head is e^{jwkT} (first-order hold into the plant), every received value is delayed by
    z^-d and filtered by (1-a) / (z - a) (the law reads the filter's state), the estimate is
    (1-b) / (z - b) of the filtered velocity ahead."""
    from lcc_synth.analysis.as_run import _physical_plant

    A0, B0, H0, names, own = _physical_plant(model, 0.0)
    nx = A0.shape[0]
    Ad, Bd = discretize(A0, B0, T)
    Hd = discretize(A0, H0, T)[1][:, 0]
    M3 = np.zeros((nx + 2, nx + 2))
    M3[:nx, :nx], M3[:nx, nx], M3[nx, nx + 1] = A0, H0[:, 0], 1.0
    Lam = sla.expm(M3 * T)[:nx, nx + 1] / T
    K = np.asarray(law.K)
    d = round(latency / T)
    a = math.exp(-T / tf) if tf else 0.0
    b = math.exp(-T / tau) if tau else None
    out = []
    for w in omega:
        z = np.exp(1j * w * T)
        F = ((1 - a) / (z - a) if tf else 1.0) * z**-d  # received: delayed then filtered
        # x_k = X V: (z I - Ad) X = Bd U + (Hd + (Ad - I) Lam) ... with the FOH written on x
        # directly: x_{k+1} = Ad x_k + Bd u_k + (Hd - Lam') v_k + Lam' v_{k+1}, Lam' = Lam
        Kown = np.where(own, K, 0.0)
        Krec = np.where(own, 0.0, K)
        # u = Kown x + F (Krec x + kh v) - e W,  W = (1-b)/(z-b) * F * y,  y = v (m = 0)
        Wv = (1 - b) / (z - b) * F if b is not None else 0.0
        lhs = z * np.eye(nx) - Ad - Bd @ (Kown + F * Krec).reshape(1, -1)
        rhs = (Hd - Lam) + z * Lam + Bd[:, 0] * (F * law.kh - law.e * Wv)
        X = np.linalg.solve(lhs, rhs)
        out.append(X[nx - 1])
    return np.array(out)


@pytest.mark.parametrize("latency,tau,tf", [(0.0, None, 0.0), (0.2, 1.0, 0.0), (0.1, 1.0, 0.5),
                                            (0.0, None, 0.3)])
def test_sampled_loop_equals_the_frequency_domain_reference(latency, tau, tf):
    system = _system(4)
    model = system.linear_model(warn=False)
    law = law_of_gains(model, Gains.named(PAPER, "replace"))
    T = 0.1
    loop = as_run_loop(model, law, T, latency, tau, tf)
    omega = np.array([0.03, 0.2, 1.0, 5.0])
    ref = _reference(model, law, T, latency, tau, tf, omega)
    assert np.allclose(loop.response(omega), ref, rtol=1e-9, atol=1e-12)


def test_measurement_filter_read_from_the_law():
    system = _system(4)
    ctrl = build_controller("p", _table(PAPER, equilibrium="estimated"), system)
    from lcc_synth.experiments.string_as_run import _context

    base = ctrl.linear_law(_context(system, 0.01))
    kw = {k: getattr(base, k) for k in base.__dataclass_fields__ if k != "measurement_filter"}
    filtered = FilteredLaw(**kw, measurement_filter=0.5)
    model = ctrl.model
    plain = law_loop(model, base, 0.01)
    loop = law_loop(model, filtered, 0.01)
    assert loop.settings["measurement_filter"] == 0.5
    assert any(s.startswith("f[") for s in loop.states)
    omega = np.array([0.05, 0.3, 1.0])
    law = law_of_gains(model, Gains.named(PAPER, "replace"))
    ref = _reference(model, law, 0.01, 0.0, 1.0, 0.5, omega)
    assert np.allclose(loop.response(omega), ref, rtol=1e-8)
    assert not np.allclose(loop.response(omega), plain.response(omega), rtol=1e-3)
    # a vanishing filter is one sample of delay (the law reads the state before the update)
    tiny = law_loop(model, FilteredLaw(**kw, measurement_filter=1e-9), 0.01)
    delayed = law_loop(model, base, 0.01, latency=0.01)
    assert np.allclose(tiny.response(omega), delayed.response(omega), rtol=1e-12)
    # against the simulator, also at a 0.1 s sample time, where a one-sample difference in the
    # filter's convention would show (a 0.1 s delay: 3 % of phase at 0.3 rad/s)
    for extra in ({}, {"sample_time": 0.1}):
        ctrl_f = build_controller(
            "p", _table(PAPER, equilibrium="estimated", measurement_filter=0.5, **extra), system
        )
        analysed = np.abs(controller_loop(ctrl_f, system).response(OMEGA))
        measured = measured_ratio(ctrl_f, system, OMEGA)
        assert np.all(np.abs(measured / analysed - 1) < np.array([1e-3, 1e-3, 6e-3])), extra


# ------------------------------------------------------------------- verdict and H2 norm


def test_continuous_limit_and_fixed_equilibrium_reduce_to_the_bare_gain():
    from lcc_synth.analysis.string_stability import gains_string_stability
    from lcc_synth.analysis.transfer import gamma_state_space
    from lcc_synth.models.feedback import input_feedback

    model = cf_lcc(6, model_from_hdv("cf_lcc", 0, 6, OVM(), 15.0).coefficients[1])
    gains = Gains.named(PAPER, "replace")
    loop = as_run_loop(model, law_of_gains(model, gains))
    K, kh = input_feedback(model, gains)
    w = np.logspace(-2, 1, 30)
    assert np.allclose(loop.response(w), gamma_state_space(model, K, kh, w), rtol=1e-10)
    bare = gains_string_stability(model, gains)
    rep = as_run_report(loop)
    assert rep.verdict == bare.verdict and math.isclose(rep.margin, bare.margin, rel_tol=1e-8)
    # a sampled loop tends to it as T -> 0
    fine = as_run_report(as_run_loop(model, law_of_gains(model, gains), 1e-3))
    assert fine.verdict == bare.verdict and abs(fine.margin - bare.margin) < 1e-2 * bare.margin


def test_tustin_image_preserves_the_frequency_response():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6)) * 0.3
    A /= 1.2 * np.max(np.abs(np.linalg.eigvals(A)))
    b, c = rng.normal(size=6), rng.normal(size=6)
    T = 0.2
    Ac, bc, cc, dc = tustin(A, b, c, T)
    w = np.array([0.1, 1.0, 10.0])
    z = np.exp(1j * w * T)
    nu = 2 / T * np.tan(w * T / 2)
    gd = [c @ np.linalg.solve(zz * np.eye(6) - A, b) for zz in z]
    gc = [dc + cc @ np.linalg.solve(1j * n * np.eye(6) - Ac, bc) for n in nu]
    assert np.allclose(gd, gc, rtol=1e-10)


def test_sampled_verdict_peak_is_the_discrete_supremum():
    system = _system(10)
    model = system.linear_model(warn=False)
    loop = as_run_loop(model, law_of_gains(model, Gains.named(H2, "replace")), 0.1, 0.1, 1.0)
    rep = as_run_report(loop)
    w = np.linspace(1e-3, math.pi / 0.1, 200001)
    mag = np.abs(loop.response(w))
    assert rep.verdict == "string_unstable"
    assert math.isclose(rep.gamma_peak, mag.max(), rel_tol=1e-6)
    assert abs(rep.gamma_peak_omega - w[np.argmax(mag)]) < 1e-3
    # a gain pushing the CAV towards the vehicle ahead: unstable, also when sampled
    bad = as_run_report(as_run_loop(model, law_of_gains(model, Gains.named(
        {**H2, "s_0": -0.5}, "replace")), 0.1, 0.1, 1.0))
    assert bad.verdict == "plant_unstable" and bad.string.max_real_eig > 0


def test_fractional_latency_is_not_representable():
    model = _system(4).linear_model(warn=False)
    law = law_of_gains(model, Gains.named(PAPER, "replace"))
    with pytest.raises(NotRepresentable, match="not a multiple"):
        as_run_loop(model, law, 0.1, 0.15)
    with pytest.raises(NotRepresentable, match="sample time"):
        as_run_loop(model, law, None, 0.1)


def test_as_run_h2_continuous_equals_the_design_h2_and_sampled_tends_to_it():
    from lcc_synth.synthesis.h2 import Weights, h2_norm, make_plant

    model = _system(4).linear_model(warn=False)
    plant = make_plant(model, "replace", Weights(q_s=0.1, q_v=1.0, q_a=3.0, r=1.0))
    gains = Gains.named(PAPER, "replace")
    from lcc_synth.synthesis.design import design_gain_of

    g = design_gain_of(plant, gains)
    ref = h2_norm(plant, g)
    law = law_of_gains(model, gains)
    cont = as_run_h2(as_run_loop(model, law), plant.Bw, plant.Q, plant.r)
    assert math.isclose(cont, ref, rel_tol=1e-9)
    for T, tol in ((1e-3, 2e-3), (1e-2, 2e-2)):
        samp = as_run_h2(as_run_loop(model, law, T), plant.Bw, plant.Q, plant.r)
        assert abs(samp / ref - 1) < tol
    # the estimate reads only the head: acceleration noise alone never moves it (CF-LCC)
    est = as_run_loop(model, law, None, 0.0, 1.0)
    assert math.isclose(as_run_h2(est, plant.Bw, plant.Q, plant.r), cont, rel_tol=1e-9)
    # with noise on the head velocity it does, and a sampled law reading it has no H2 norm
    assert as_run_h2(est, plant.Bw, plant.Q, plant.r, head=1.0) > as_run_h2(
        as_run_loop(model, law), plant.Bw, plant.Q, plant.r, head=1.0)
    assert as_run_h2(as_run_loop(model, law, 0.1, 0.0, 1.0), plant.Bw, plant.Q, plant.r,
                     head=1.0) is None


def test_equilibrium_slope_is_that_of_the_nominal_model():
    hdv = OVM()
    model = model_from_hdv("cf_lcc", 0, 3, hdv, 12.0)
    h = 1e-5
    num = (hdv.equilibrium_spacing(12.0 + h) - hdv.equilibrium_spacing(12.0 - h)) / (2 * h)
    assert math.isclose(equilibrium_slope(model), num, rel_tol=1e-6)


# ------------------------------------------------------------------------- design as run


def _plant(kind="lcc", m=2, n=2, semantics="added", head=1.0):
    from lcc_synth.synthesis.h2 import Weights, make_plant

    model = model_from_hdv(kind, m, n, OVM(), 15.0, warn=False)
    return make_plant(model, semantics, Weights(q_s=0.1, q_v=1.0, q_a=3.0, r=1.0, head=head))


def test_output_cost_and_gradient():
    from lcc_synth.synthesis.as_run import AsRunSettings, _augmented, _directions, output_cost
    from lcc_synth.synthesis.h2 import h2_cost
    from lcc_synth.synthesis.structured import pattern_mask, structured_h2

    plant = _plant()
    res = structured_h2(plant, [1, 2], "direct")
    fixed = _augmented(plant, AsRunSettings())
    assert math.isclose(output_cost(fixed, plant.r, res.g)[0], h2_cost(plant, res.g)[0],
                        rel_tol=1e-12)
    aug = _augmented(plant, AsRunSettings(equilibrium_tau=1.0))
    J, L, P = output_cost(aug, plant.r, res.g)
    mask = pattern_mask(plant, [1, 2])
    grad, _ = _directions(aug, plant.r, res.g, L, P, mask)
    k = int(np.flatnonzero(mask)[0])
    e = np.zeros(plant.nx)
    e[k] = 1e-6
    fd = (output_cost(aug, plant.r, res.g + e)[0] - output_cost(aug, plant.r, res.g - e)[0]) / 2e-6
    assert math.isclose(grad[k], fd, rel_tol=1e-5)
    # with the vehicles ahead (m = 2) the estimate sees their noise: the cost differs
    assert not math.isclose(J, h2_cost(plant, res.g)[0], rel_tol=1e-6)


def test_as_run_design_keeps_the_as_run_margin_and_lowers_the_cost():
    from lcc_synth.synthesis.as_run import AsRunSettings, as_run_check, as_run_design
    from lcc_synth.synthesis.structured import pattern_mask, structured_h2

    plant = _plant()
    mask = pattern_mask(plant, [1, 2])
    g0 = structured_h2(plant, [1, 2], "direct", max_iter=5).g  # not converged: room to descend
    st = AsRunSettings(sample_time=0.1, latency=0.1, margin=1e-2, polish_steps=30)
    assert as_run_check(plant, g0, st).margin > st.margin
    g, info = as_run_design(plant, mask, g0, st)
    assert info["polished"] and info["string_stable"]
    rep = as_run_check(plant, g, st)
    assert rep.string_stable and rep.margin >= st.margin
    assert info["h2_after"] <= info["h2_before"]
    assert np.all(g[~mask] == 0.0)


def test_as_run_design_reports_an_unstable_loop_it_cannot_fix():
    from lcc_synth.experiments.comparison import synthesize_table

    system = _system(4)
    table = {"type": "h2", "design": "structured", "semantics": "replace", "pattern": [1, 2],
             "method": "direct", "weights": {"q_s": 0.1, "q_a": 3.0},
             "equilibrium": "estimated", "equilibrium_tau": 1.0, "as_run": True}
    static, rep = synthesize_table("h2", table, system, "t")
    assert static["equilibrium"] == "estimated"
    assert rep.as_run["settings"]["equilibrium_tau"] == 1.0
    assert rep.as_run["after"]["verdict"] == "string_unstable" and not rep.as_run["string_stable"]
    assert any("NOT string stable" in n for n in rep.notes)
    ctrl = build_controller("h2", static, system)
    assert math.isclose(as_run_report(controller_loop(ctrl, system)).gamma_peak,
                        rep.as_run["after"]["gamma_peak"], rel_tol=1e-9)


def test_as_run_table_is_checked():
    from lcc_synth.problem import Problem
    from lcc_synth.synthesis.config import spec_from_problem

    def spec(ar, design="structured"):
        data = {"hdv": {"model": "ovm"}, "system": {"kind": "cf_lcc", "m": 0, "n": 3},
                "synthesis": {"design": design, "as_run": ar}}
        return spec_from_problem(Problem(Path("x.toml"), data))

    assert spec(True).as_run.equilibrium_tau is None
    assert spec({"equilibrium": "estimated", "equilibrium_tau": 2.0}).as_run.equilibrium_tau == 2
    from lcc_synth.errors import ConfigError

    with pytest.raises(ConfigError, match="equilibrium_tau"):
        spec({"equilibrium_tau": 2.0})
    with pytest.raises(ConfigError, match="as_run"):
        spec(True, design="full_state")
    with pytest.raises(ConfigError, match="unknown|not allowed|bogus"):
        spec({"bogus": 1})


# ------------------------------------------------- a QP controller measured with its exact QP


@pytest.mark.parametrize("table", [
    {"type": "mpc", "sample_time": 0.1},
    {"type": "deep_lcc", "data": {"T": 600}},
])  # fmt: skip
def test_measuring_with_the_exact_qp_gives_the_polished_osqp_ratios(table, monkeypatch):
    """A QP controller's measured ratio with its QP solved by DAQP (``exact_qp``, what
    ``lcc-synth run`` measures) equals the ratio with the controller's own polished OSQP; an
    OSQP that does not polish is measured as it is."""
    from lcc_synth.experiments.controller_tables import controller_from_table as build
    from lcc_synth.mpc.active_set import DAQPSolver, exact_qp

    system = _system(4)
    ctrl = build("qp", table, system)
    w = np.array([0.3, 1.0])
    own = measured_ratio(ctrl, system, w, 0.01, 0.1, settle=10.0, exact=False)
    assert ctrl.describe()["qp"]["solver"].startswith("osqp ")
    calls = []
    solve = DAQPSolver.solve
    monkeypatch.setattr(DAQPSolver, "solve", lambda *a, **k: calls.append(1) or solve(*a, **k))
    exact = measured_ratio(ctrl, system, w, 0.01, 0.1, settle=10.0)
    assert len(calls) > 300  # DAQP solved every sample
    assert np.all(np.abs(exact / own - 1.0) < 1e-9), (exact, own)
    assert 0.2 < own.min() and own.max() < 1.5  # a real measurement, not a constant
    with exact_qp() as swaps:
        measured_ratio(ctrl, system, w[1:], 0.01, 0.0, settle=1.0, exact=False)
    assert swaps and set(swaps) == {"osqp -> daqp"}
    no_polish = build("np", {**table, "solver": {"polish": False}}, system)
    with exact_qp() as swaps:
        measured_ratio(no_polish, system, w[1:], 0.01, 0.0, settle=1.0, exact=False)
    assert swaps == []


def test_deep_lcc_runs_the_solver_method_it_is_given():
    """``[controllers.NAME.solver] method = "daqp"`` on DeeP-LCC runs DAQP (it used to be
    read and ignored: OSQP ran); its commands equal OSQP's polished ones."""
    from dataclasses import replace

    from lcc_synth.experiments.controller_tables import controller_from_table
    from lcc_synth.simulation.engine import simulate
    from lcc_synth.simulation.perturbations import Brake
    from lcc_synth.simulation.scenario import Scenario

    system = _system(4)
    sc = Scenario(m=0, n=4, hdv=system.hdv, v_star=15.0, dt=0.01, duration=30.0,
                  perturbations=(Brake(vehicle=0, start=20.0, duration=1.0, decel=-3.0),))
    runs = {}
    for method in ("osqp", "daqp"):
        ctrl = controller_from_table(method, {"type": "deep_lcc", "data": {"T": 600},
                                         "solver": {"method": method}}, system)
        assert ctrl.describe()["qp"]["solver"].startswith(f"{method} ")
        runs[method] = simulate(replace(sc), ctrl).velocity[0]
    assert np.max(np.abs(runs["daqp"] - runs["osqp"])) < 1e-8
    assert np.ptp(runs["osqp"][:, 1]) > 1.0  # the brake moved the CAV
