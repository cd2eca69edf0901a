"""CAV actuator lag ``da/dt = (u - a) / tau``: the linear model, the string-stability effect,
the lag-aware design, the simulator (against the linear model and the discrete lag), bad input.

Independent truths: the lagged loop's transfer function solved directly per frequency from
the lag-free closed loop (the lag as the factor ``1 / (tau s + 1)`` on the CAV's velocity row,
no augmented matrix), a dense frequency grid of ``|Gamma|`` on both sides of the critical lag,
the simulator's small-signal ratio (Richardson-extrapolated in ``dt``) and the Euler recursion
of the lag recomputed from the simulator's recorded commands.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lcc_synth import api
from lcc_synth.analysis.lag_string import critical_lag, gamma_lag, lag_string_stability
from lcc_synth.analysis.string_stability import string_stability
from lcc_synth.cli.main import main
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.string_as_run import measured_ratio
from lcc_synth.models.feedback import Gains, closed_loop, input_feedback
from lcc_synth.models.lag import pad_gain, with_actuator_lag
from lcc_synth.problem import load_problem
from lcc_synth.simulation.engine import simulate
from lcc_synth.simulation.perturbations import Brake
from lcc_synth.simulation.scenario import Scenario
from lcc_synth.synthesis.config import spec_from_problem
from lcc_synth.synthesis.design import synthesize

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"
#: Table II's CF-LCC gains (problems/paper_table2.toml), the CAV's whole command
TABLE2_CF = {"s_0": 0.1, "v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}
#: Table I's case D on the Section V-A string (m = n = 2), added to the HDV law
CASE_D = {"s_-2": 1.0, "v_-2": -1.0, "s_-1": 1.0, "v_-1": -1.0, "s_1": -1.0, "v_1": -1.0,
          "s_2": -1.0, "v_2": -1.0}  # fmt: skip
W = np.geomspace(1e-3, 20.0, 6000)


def _table2():
    model = api.model("cf_lcc", 0, 10)
    K, kh = input_feedback(model, Gains.named(TABLE2_CF, "replace"))
    return model, K, kh


def _case_d():
    model = api.model("lcc", 2, 2)
    K, kh = input_feedback(model, Gains.named(CASE_D, "added"))
    return model, K, kh


def _gamma_direct(model, K, kh, tau, omega, k_a=0.0):
    """Head-to-tail Gamma of the lagged loop from the lag-free closed loop: the CAV's velocity
    row r of ``dx = A_cl x + h v_h`` becomes ``s v_0 = (A_cl[r] x + h[r] v_h) / (tau s + 1)``;
    one dense solve per frequency (``k_a``: the command also feeds back ``a_0``, so the factor
    is ``1 / (tau s + 1 - k_a)``)."""
    Acl, Hcl = closed_loop(model, K, kh)
    h = Hcl.ravel()
    r = model.index("v_0")
    out = []
    for w in omega:
        s = 1j * w
        lag = 1.0 / (tau * s + 1.0 - k_a)
        M = s * np.eye(model.nx) - Acl
        M[r] = s * np.eye(model.nx)[r] - lag * Acl[r]
        rhs = h.astype(complex)
        rhs[r] = lag * h[r]
        out.append(np.linalg.solve(M, rhs)[model.tail_velocity_index])
    return np.array(out)


# ------------------------------------------------------------------------------ linear model
def test_lagged_model_matches_direct_solution():
    for model, K, kh in (_table2(), _case_d()):
        for tau in (0.1, 0.45, 2.0):
            w = np.geomspace(1e-3, 10.0, 50)
            ref = _gamma_direct(model, K, kh, tau, w)
            got = gamma_lag(model, K, kh, tau, w)
            np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-13)
            ref = _gamma_direct(model, K, kh, tau, w, k_a=-0.4)
            got = gamma_lag(model, K, kh, tau, w, k_a=-0.4)
            np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-13)


def test_lag_structure_and_limits():
    model, K, kh = _table2()
    lag = with_actuator_lag(model.A, model.B, model.H, [model.index("v_0")], 0.3,
                            model.state_names)  # fmt: skip
    assert lag.state_names[-1] == "a_0" and lag.nx == model.nx + 1
    r = model.index("v_0")
    assert lag.A[r].tolist() == [0.0] * model.nx + [1.0]  # dv_0 = a_0
    assert lag.A[-1, -1] == pytest.approx(-1 / 0.3)
    assert pad_gain(lag, K).shape == (1, model.nx + 1) and pad_gain(lag, K)[0, -1] == 0.0
    # Gamma(0) = 1 stays; tau -> 0 recovers the lag-free loop
    assert abs(gamma_lag(model, K, kh, 0.3, [0.0])[0]) == pytest.approx(1.0, abs=1e-12)
    w = np.geomspace(1e-3, 10.0, 30)
    np.testing.assert_allclose(
        gamma_lag(model, K, kh, 1e-7, w), gamma_lag(model, K, kh, 0.0, w), rtol=1e-5
    )
    # tau = 0 is the lag-free verdict itself
    a, b = lag_string_stability(model, K, kh, 0.0), string_stability(model, K, kh)
    assert (a.verdict, a.margin) == (b.verdict, b.margin)


# ----------------------------------------------------------------------- the known effect
@pytest.mark.parametrize(
    "case, expect", [(_table2, (2.19, 2.20)), (_case_d, (0.44, 0.45))], ids=["table2", "caseD"]
)
def test_string_stable_gain_loses_it_at_the_critical_lag(case, expect):
    model, K, kh = case()
    assert lag_string_stability(model, K, kh, 0.0).string_stable
    cr = critical_lag(model, K, kh)
    assert expect[0] < cr.tau < expect[1]
    assert cr.verdict_lo == "string_stable" and cr.verdict_hi == "string_unstable"
    assert cr.hi - cr.lo <= 1e-6 * cr.hi
    # both sides, against an independent dense grid of |Gamma| (direct solution)
    below, above = 0.99 * cr.tau, 1.01 * cr.tau
    assert lag_string_stability(model, K, kh, below).string_stable
    assert not lag_string_stability(model, K, kh, above).string_stable
    assert np.abs(_gamma_direct(model, K, kh, below, W)).max() <= 1.0 + 1e-9
    assert np.abs(_gamma_direct(model, K, kh, above, W)).max() > 1.0 + 1e-3
    # every scanned lag below is string stable too (the loss is not a blip)
    for t in np.linspace(0.05, 0.95, 7) * cr.tau:
        assert lag_string_stability(model, K, kh, t).string_stable


def test_design_with_the_lag_keeps_string_stability():
    """On the Section V-A string (m = n = 2) case D loses string stability at 0.445 s and the
    lag-free string_stable design of problems/synth_string_stable_m2n2.toml at 1.071 s; the
    same design made with cav_lag = 1.5 s is string stable with that lag."""
    tau = 1.5
    model, K, kh = _case_d()
    assert not lag_string_stability(model, K, kh, tau).string_stable
    spec = spec_from_problem(load_problem(PROBLEMS / "synth_string_stable_m2n2.toml"))
    rep0 = synthesize(spec)
    K0 = np.array(rep0.input_K)
    assert lag_string_stability(model, K0, rep0.input_kh, 0.0).string_stable
    assert 1.07 < critical_lag(model, K0, rep0.input_kh).tau < 1.08
    assert not lag_string_stability(model, K0, rep0.input_kh, tau).string_stable
    rep = synthesize(replace(spec, cav_lag=tau))
    Kd, khd = np.array(rep.input_K), rep.input_kh
    r = lag_string_stability(model, Kd, khd, tau)
    assert r.string_stable and r.margin > 1e-2
    assert rep.check.string_verdict == "string_stable"
    assert rep.check.string_margin == pytest.approx(r.margin, rel=1e-12)
    assert np.abs(_gamma_direct(model, Kd, khd, tau, W)).max() <= 1.0 + 1e-9
    assert rep.baseline["string_verdict"] != "string_stable"  # case D with the lag
    assert any("actuator lag" in n for n in rep.notes)
    assert critical_lag(model, Kd, khd).tau > tau
    # the price: a larger H2 norm than the lag-free design (checked on its own plant)
    assert rep.check.h2 > rep0.check.h2


def test_structured_design_with_lag():
    spec = spec_from_problem(load_problem(PROBLEMS / "synth_cf_lcc_pattern.toml"))
    rep = synthesize(replace(spec, cav_lag=0.3))
    assert rep.pattern == [0, 1, 2]
    assert set(rep.gains) == set(spec.system.linear_model(warn=False).state_names)
    model = spec.system.linear_model(warn=False)
    r = lag_string_stability(model, np.array(rep.input_K), rep.input_kh, 0.3)
    assert rep.check.string_verdict == r.verdict == "string_stable"


# ----------------------------------------------------------------------------- simulator
@pytest.mark.slow  # the lag model: test_lagged_model_matches_direct_solution; the simulator's
# lag: test_simulator_lag_recursion_limits_and_braking
def test_simulator_small_signal_matches_the_lag_model():
    """Tail/head amplitude ratio of a small multisine in the nonlinear simulator (Euler at dt,
    first order in dt: Richardson over dt = 2 ms and 1 ms) against |Gamma| of the lag model."""
    system = api.system("cf_lcc", 0, 10)
    model, K, kh = _table2()
    ctrl = api.static_controller(system, Gains.named(TABLE2_CF, "replace"))
    w = [0.1, 0.3, 1.0]
    for tau in (0.3, 2.5):
        r2 = measured_ratio(ctrl, system, w, dt=0.002, cav_lag=tau)
        r1 = measured_ratio(ctrl, system, w, dt=0.001, cav_lag=tau)
        lin = np.abs(gamma_lag(model, K, kh, tau, w))
        np.testing.assert_allclose(2 * r1 - r2, lin, rtol=1e-3)
        free = np.abs(gamma_lag(model, K, kh, 0.0, w))
        assert np.max(np.abs(lin / free - 1)) > 0.15  # the lag's effect is far above 1e-3
    # tau = 2.5 s > the critical 2.19 s: the simulator amplifies at 0.3 rad/s
    assert 2 * r1[1] - r2[1] > 1.01


def _brake_run(tau, **kw):
    system = api.system("cf_lcc", 0, 10)
    ctrl = api.static_controller(system, Gains.named(TABLE2_CF, "replace"))
    sc = Scenario(m=0, n=10, v_star=15.0, duration=40.0, cav_lag=tau,
                  perturbations=(Brake(vehicle="head", start=10.0, duration=2.0, decel=-5.0),),
                  **kw)  # fmt: skip
    return simulate(sc, ctrl)


def test_simulator_lag_recursion_limits_and_braking():
    """The CAV's applied acceleration is the Euler lag of its clipped command, and emergency
    braking commands a_min through the same actuator (it does not jump)."""
    tau, dt = 0.5, 0.01
    res = _brake_run(tau, a_max=0.5)
    a = res.acceleration[0, :, 1]
    u = res.u_cmd[0]
    cmd = np.where(res.aeb_active[0], -5.0, np.clip(u, -5.0, 0.5))
    pred = a[:-1] + (dt / tau) * (cmd[:-1] - a[:-1])
    np.testing.assert_array_equal(a[1:], pred)  # the kernel's arithmetic, bit for bit
    assert a[0] == 0.0
    assert np.any(u > 0.5)  # the limit acted on the command
    assert np.any(res.aeb_active[0])  # and so did emergency braking ...
    k = int(np.argmax(res.aeb_active[0]))
    assert a[k + 1] > -5.0 + 1.0  # ... through the lag: no jump to a_min
    # without lag the same brake applies the clipped command itself
    res0 = _brake_run(0.0, a_max=0.5)
    a0 = res0.acceleration[0, :, 1]
    cmd0 = np.where(res0.aeb_active[0], -5.0, np.clip(res0.u_cmd[0], -5.0, 0.5))
    np.testing.assert_array_equal(a0, cmd0)
    assert not np.array_equal(a, a0)


@pytest.mark.parametrize("problem", [
    # slow: the ring's several CAVs, each with its lag, check the same path faster
    pytest.param("platoon_deeplcc_brake.toml", marks=pytest.mark.slow),
    "ring_stop_and_go.toml",
])  # fmt: skip
def test_several_cavs_each_with_its_lag(problem):
    """A platoon (CAVs at positions 3, 6, lags 0.2 / 0.5 s) and the ring (its CAV at position
    20, the last column): each CAV's applied acceleration is the Euler lag of its own clipped
    (or braking) command with its own tau."""
    from lcc_synth.experiments.spec import load_spec

    spec = load_spec(PROBLEMS / problem)
    n_cav = len(spec.scenario.cav_columns)
    taus = (0.2, 0.5)[:n_cav]
    sc = replace(spec.scenario, cav_lag=taus, accel_noise_uniform=0.0, duration=60.0,
                 record_every=1)
    name = [k for k in spec.controllers if k != "all_hdv"][0]
    res = simulate(sc, spec.controllers[name])
    u = res.u_cmd.reshape(1, -1, n_cav)[0]
    aeb = res.aeb_active.reshape(1, -1, n_cav)[0]
    for c, (col, tau) in enumerate(zip(sc.cav_columns, taus, strict=True)):
        a = res.acceleration[0, :, col]
        cmd = np.where(aeb[:, c], sc.a_min, np.clip(u[:, c], sc.a_min, sc.a_max))
        ok = np.isfinite(a[1:])
        pred = a[:-1] + (sc.dt / tau) * (cmd[:-1] - a[:-1])
        assert ok.sum() > 1000
        np.testing.assert_array_equal(a[1:][ok], pred[ok])
    free = simulate(replace(sc, cav_lag=0.0), spec.controllers[name])
    assert not np.array_equal(free.velocity, res.velocity, equal_nan=True)


def test_lag_per_cav_and_table_form():
    sc = Scenario(m=0, n=10, cav_lag=(0.2,))
    assert sc.lags() == (0.2,)
    assert Scenario(m=0, n=10, cav_lag=0.2).toml_table()["cav_lag"] == 0.2
    assert "cav_lag" not in Scenario(m=0, n=10).toml_table()
    with pytest.raises(ConfigError, match="one per CAV"):
        Scenario(m=0, n=10, cav_lag=(0.2, 0.3))


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("tau, what", [(-0.2, ">= 0"), (0.005, ">= dt"), (float("nan"), "")])
def test_bad_lag_is_a_named_error(tau, what):
    with pytest.raises(ConfigError) as err:
        Scenario(m=0, n=10, cav_lag=tau)
    assert err.value.field == "scenario.cav_lag" and what in err.value.message


def test_bad_lag_elsewhere():
    model, K, kh = _table2()
    with pytest.raises(ConfigError) as err:
        lag_string_stability(model, K, kh, -0.1)
    assert err.value.field == "cav_lag"
    with pytest.raises(ConfigError) as err:
        with_actuator_lag(model.A, model.B, model.H, [1], 0.0)
    assert err.value.field == "cav_lag"
    with pytest.raises(ConfigError) as err:
        Scenario(m=0, n=10, cav_lag=0.005, backend="sumo")  # checked in SUMO too
    assert err.value.field == "scenario.cav_lag"


def test_cli_negative_lag_exits_2(tmp_path, capsys):
    text = (PROBLEMS / "paper_table2.toml").read_text()
    bad = tmp_path / "bad_lag.toml"
    bad.write_text(text.replace("t_start = 0.01\n", "t_start = 0.01\ncav_lag = -0.2\n", 1))
    assert main(["simulate", str(bad), "--no-record"]) == 2
    assert "scenario.cav_lag" in capsys.readouterr().err
    syn = tmp_path / "bad_syn.toml"
    syn.write_text((PROBLEMS / "synth_cf_lcc_pattern.toml").read_text().replace(
        "[synthesis]\n", "[synthesis]\ncav_lag = -1.0\n", 1))  # fmt: skip
    assert main(["synthesize", str(syn)]) == 2
    assert "synthesis.cav_lag" in capsys.readouterr().err


# ----------------------------------------------------------------------------------- MPC
def _mpc(system, lag, name="mpc"):
    from lcc_synth.mpc.build import mpc_controller_from_table

    return mpc_controller_from_table(name, {"type": "mpc", "prediction": {"cav_lag": lag}},
                                     system)  # fmt: skip


def test_mpc_lag_prediction_model():
    """The lagged prediction is the exact ZOH discretisation: it matches a fine Euler run of
    the continuous lagged model over one sample; with cav_lag = 0 the matrices are today's."""
    from lcc_synth.mpc.formulation import linearize
    from lcc_synth.mpc.lag import LagPrediction
    from lcc_synth.mpc.settings import MPCSettings, Prediction

    system = api.system("cf_lcc", 0, 4)
    base = MPCSettings()
    lin0 = linearize("cf_lcc", 0, 4, system.hdv, 15.0, base)
    assert lin0.delay is None and lin0.Ad.shape == (10, 10)
    lin = linearize("cf_lcc", 0, 4, system.hdv, 15.0,
                    replace(base, prediction=Prediction(cav_lag=0.4)))  # fmt: skip
    assert isinstance(lin.delay, LagPrediction) and lin.Ad.shape == (11, 11)
    lag = with_actuator_lag(lin.model.A, lin.model.B, lin.model.H, [1], 0.4)
    rng = np.random.default_rng(1)
    z, u, d = rng.normal(size=11), 0.7, -0.3
    h = 1e-5
    zz = z.copy()
    for _ in range(int(round(base.sample_time / h))):
        zz = zz + h * (lag.A @ zz + lag.B[:, 0] * u + lag.H[:, 0] * d)
    pred = lin.Ad @ z + lin.Bd * u + lin.Hd * d
    np.testing.assert_allclose(pred, zz, rtol=0, atol=1e-5 * np.abs(zz).max())
    # general LCC (the command is the CAV's whole input): the lag row is decoupled,
    # a_{k+1} = exp(-Ts / tau) a_k + (1 - exp(-Ts / tau)) u_k
    lcc = linearize("lcc", 0, 4, system.hdv, 15.0,
                    replace(base, prediction=Prediction(cav_lag=0.4)))  # fmt: skip
    e = np.exp(-0.1 / 0.4)
    assert lcc.Ad[-1, -1] == pytest.approx(e, rel=1e-12)
    assert np.all(lcc.Ad[-1, :-1] == 0.0) and lcc.Hd[-1] == 0.0
    assert lcc.Bd[-1] == pytest.approx(1.0 - e, rel=1e-12)


def test_mpc_with_lag_keeps_its_safety_margin():
    """Head brake (problems/mpc_head_brake.toml) with a 0.3 s actuator lag in the simulator:
    the lag-free prediction uses up the MPC's 0.1 m constraint margin on the safe spacing
    s_0 >= 5 + 0.8 v_0; the lag-aware prediction keeps it, as the MPC does without lag."""
    from lcc_synth.experiments.spec import load_spec

    spec = load_spec(PROBLEMS / "mpc_head_brake.toml")
    sc = replace(spec.scenario, cav_lag=0.3)
    worst = {}
    for name, lag, scen in (("free", 0.0, sc), ("lag", 0.3, sc), ("nolag", 0.0, spec.scenario)):
        ctrl = _mpc(spec.system, lag, name)
        r = simulate(scen, ctrl)
        assert not r.collided.any() and ctrl.stats()["fallbacks"] == 0
        worst[name] = float(np.max(5.0 + 0.8 * r.velocity[0, :, 1] - r.spacing[0, :, 1]))
    assert worst["free"] > -0.05  # the margin (0.1 m) is gone
    assert worst["lag"] < -0.09 and worst["nolag"] < -0.09


def test_mpc_bad_lag():
    system = api.system("cf_lcc", 0, 4)
    with pytest.raises(ConfigError) as err:
        _mpc(system, -0.3)
    assert err.value.field == "controllers.mpc.prediction.cav_lag"


def test_ring_column_zero_cav_lag_and_override():
    """The ring's column 0 as the CAV (its own code path): the lag recursion holds except while
    a perturbation overrides its acceleration, which then sets the lag state itself."""
    from lcc_synth.experiments.spec import load_spec

    spec = load_spec(PROBLEMS / "ring_stop_and_go.toml")
    base = spec.scenario
    sc = replace(base, cavs=(0,), m=-1, n=base.n_vehicles - 1, cav_lag=0.3, record_every=1,
                 duration=30.0)  # fmt: skip
    assert sc.perturbations[0].vehicle == 1  # position 1 = column 0: the CAV itself
    r = simulate(sc, spec.controllers["all_hdv"])
    a, u, aeb = r.acceleration[0, :, 0], r.u_cmd[0], r.aeb_active[0]
    cmd = np.where(aeb, sc.a_min, np.clip(u, sc.a_min, sc.a_max))
    pred = a[:-1] + (sc.dt / 0.3) * (cmd[:-1] - a[:-1])
    t = r.t[1:]
    brake = sc.perturbations[0]
    on = (t > brake.start - 1e-9) & (t < brake.start + brake.duration + 1e-9)
    np.testing.assert_array_equal(a[1:][~on & (t > brake.start + brake.duration + 0.02)],
                                  pred[~on & (t > brake.start + brake.duration + 0.02)])
    np.testing.assert_array_equal(a[1:][t < brake.start], pred[t < brake.start])
    inside = (t > brake.start + 0.02) & (t < brake.start + brake.duration - 0.02)
    assert np.all(a[1:][inside] == brake.decel)
    # after the override the lag starts from the overridden acceleration (continuous)
    k = int(np.flatnonzero(r.t > brake.start + brake.duration + 0.02)[0])
    assert a[k] < 0.5 * brake.decel  # -0.76: not the stale state from before the brake (~0)


def test_platoon_lag_against_the_cascade_product():
    """An open platoon (DeeP-LCC layout, CAVs 3 and 6 with local laws, lags 0.3 / 0.6 s) is a
    cascade: with the lag a CAV's T_c = (k_p s + k_s) / (tau s^3 + s^2 - k_v s + k_s), HDVs as
    eq. (8); the state space of the lagged loop must equal the product."""
    from lcc_synth.analysis.transfer import local_cav_laws, phi_gamma
    from lcc_synth.experiments.spec import load_spec

    model = load_spec(PROBLEMS / "platoon_deeplcc_brake.toml").system.linear_model(warn=False)
    table = {"u_3": {"s_3": 0.5, "v_3": -1.2, "v_2": 0.9}, "u_6": {"s_6": 0.4, "v_6": -1.5,
             "v_5": 1.1}}  # fmt: skip
    K, kh = Gains.from_table(table, model, "replace").input_feedback(model)
    laws, taus = local_cav_laws(model, K, kh), {3: 0.3, 6: 0.6}
    w = np.logspace(-3, 2, 300)
    s = 1j * w
    prod = np.ones_like(s)
    for i in range(1, model.platoon.size + 1):
        if i in laws:
            k_s, k_v, k_p = laws[i]
            prod *= (k_p * s + k_s) / (taus[i] * s**3 + s**2 - k_v * s + k_s)
        else:
            num, den = phi_gamma(model.coefficients[i - 1])
            prod *= np.polyval(num, s) / np.polyval(den, s)
    ss = gamma_lag(model, K, kh, (0.3, 0.6), w)
    assert np.max(np.abs(ss / prod - 1)) < 1e-10
    r = lag_string_stability(model, K, kh, (0.3, 0.6))
    r0 = string_stability(model, K, kh)
    assert r.gamma_peak > r0.gamma_peak  # the lag amplifies more
