"""One MPC for every layout: the feature matrix of :mod:`lcc_synth.mpc` on a one-CAV string, a
two-CAV platoon and a ring, through the one entry point (:func:`lcc_synth.mpc.build_mpc`), and
the joint MPC's actuator-lag prediction against independent truths (the lagged ODE integrated
by scipy; the single-CAV MPC with the same lag on a platoon with one CAV)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from lcc_synth.controllers.base import ControlContext, Observation
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.spec import load_spec
from lcc_synth.models.hdv import OVM, linear_coefficients
from lcc_synth.models.platoon import Platoon
from lcc_synth.mpc import JointMPCController, MPCController, build_mpc
from lcc_synth.mpc.controller import OneCAVLayout
from lcc_synth.mpc.joint import StringLayout
from lcc_synth.mpc.joint_prediction import linearize_joint
from lcc_synth.mpc.settings import MPCSettings, Prediction
from lcc_synth.problem import System
from lcc_synth.simulation.engine import simulate

HDV = OVM()

_BRAKE = """
[[scenario.perturbations]]
type = "brake"
vehicle = "head"
start = 0.5
duration = 1.0
decel = -3.0
"""
_PROBLEMS = {
    "one_cav": '[system]\nkind = "lcc"\nm = 1\nn = 2\nv_star = 15.0\n',
    "platoon": '[system]\nkind = "platoon"\nsize = 5\ncavs = [2, 4]\nv_star = 15.0\n',
    "ring": '[system]\nkind = "ring"\nsize = 6\ncavs = [6]\nv_star = 15.0\n',
}


def _spec(tmp_path: Path, layout: str):
    brake = _BRAKE if layout != "ring" else _BRAKE.replace('"head"', "1")
    text = (_PROBLEMS[layout] + '\n[scenario]\ndt = 0.02\nduration = 4.0\ncav_lag = 0.2\n'
            + '[metrics]\nwindow = [0.0, 4.0]\n'
            + brake + '\n[controllers.hdv]\ntype = "hdv"\n')  # fmt: skip
    path = tmp_path / f"{layout}.toml"
    path.write_text(text)
    return load_spec(path)


# option -> build_mpc keyword arguments (the keys of a type = "mpc" table)
OPTIONS = {
    "default": {},
    "cav_lag": {"prediction": {"cav_lag": 0.2}},
    "comfort": {"constraints": {"jerk_scale": 1.0}},
    "daqp": {"solver": {"method": "daqp"}},
    "relinearize": {"prediction": {"relinearize": True, "relinearize_threshold": 0.4}},
    "head_accel": {"prediction": {"head": "accel"}},
    "fixed_equilibrium": {"prediction": {"equilibrium": "fixed"}},
    "delay": {"prediction": {"delay": 0.3}},
    "equilibrium_spacing": {"constraints": {"spacing": "equilibrium"}},
}
#: (option, layout) -> the key a ConfigError names (the rest of the matrix works)
REFUSED = {
    "n_model": ({"n_model": 1}, "n_model"),
    "behind": ({"constraints": {"behind": [1]}}, "constraints.behind"),
}


@pytest.mark.parametrize("layout", ["one_cav", "platoon", "ring"])
@pytest.mark.parametrize("option", list(OPTIONS))
def test_every_option_runs_on_every_layout(tmp_path, layout, option):
    """A short closed-loop run (4 s, a brake, the CAVs' actuators lagged 0.2 s) per option and
    layout through ``build_mpc``: every sample is solved by the QP (status 0), the commands stay
    in the limits, and no emergency braking or collision happens."""
    spec = _spec(tmp_path, layout)
    ctrl = build_mpc(spec.system, horizon=30, **OPTIONS[option])
    # one class for every layout; the layout picks the prediction model
    assert type(ctrl) is MPCController and JointMPCController is MPCController
    assert isinstance(ctrl.layout, OneCAVLayout if layout == "one_cav" else StringLayout)
    res = simulate(spec.scenario, ctrl)
    h = ctrl.history()
    assert h["status"].size > 0 and (h["status"] == 0).all()
    assert np.all(h["u"] >= -5.0 - 1e-12) and np.all(h["u"] <= 2.0 + 1e-12)
    assert not res.aeb_active.any()
    assert ctrl.stats()["errors"] == 0


@pytest.mark.parametrize("layout", ["platoon", "ring"])
@pytest.mark.parametrize("option", list(REFUSED))
def test_missing_combinations_are_one_config_error_naming_the_key(tmp_path, layout, option):
    """What the joint MPC does not implement is refused by its key, with the layout named;
    the same keys work on one CAV."""
    table, key = REFUSED[option]
    spec = _spec(tmp_path, layout)
    with pytest.raises(ConfigError) as err:
        build_mpc(spec.system, horizon=10, **table)
    assert err.value.field == f"controllers.mpc.{key}"
    assert "platoon or ring" in err.value.message
    build_mpc(_spec(tmp_path, "one_cav").system, horizon=10, **table)  # works on one CAV


# ------------------------------------------------------------------ the lagged joint prediction


def _hand_ode(pl: Platoon, tau: float):
    """The linearised platoon with each CAV's first-order actuator lag, written out row by
    row (eq. 8 and ``da/dt = (u - a) / tau``); state ``(s_1, v_1, .., s_N, v_N, a_c..)``."""
    N, cavs = pl.size, list(pl.cavs)
    coef = [linear_coefficients(h, pl.v_star, warn=False) for h in pl.hdv]

    def f(t, z, u, d):
        s, v, a = z[0:2 * N:2], z[1:2 * N:2], z[2 * N:]
        dz = np.empty_like(z)
        for i in range(N):
            ahead = (v[N - 1] if pl.ring else d) if i == 0 else v[i - 1]
            dz[2 * i] = ahead - v[i]
            if i + 1 in cavs:
                dz[2 * i + 1] = a[cavs.index(i + 1)]
            else:
                c = coef[i]
                dz[2 * i + 1] = c.alpha1 * s[i] - c.alpha2 * v[i] + c.alpha3 * ahead
        dz[2 * N:] = (u - a) / tau
        return dz

    return f


@pytest.mark.parametrize("ring", [False, True])
def test_joint_lag_prediction_is_the_lagged_ode(ring):
    """The joint MPC's prediction with ``prediction.cav_lag`` (ZOH of the lagged model) equals
    the hand-written lagged ODE integrated by scipy (DOP853, rtol 1e-12) with the inputs held
    over each sample, to 1e-9 of the response over 20 samples (measured: about 1e-12)."""
    tau, Ts = 0.3, 0.1
    models = tuple(OVM(alpha=0.5 + 0.05 * i, beta=0.8 + 0.03 * i) for i in range(6))
    pl = Platoon(models, (6,) if ring else (2, 5), 15.0, ring=ring)
    settings = MPCSettings(sample_time=Ts, horizon=20, prediction=Prediction(cav_lag=tau))
    lin = linearize_joint(pl, pl.v_star, settings)
    nu = len(pl.cavs)
    assert lin.Ad.shape == (12 + nu, 12 + nu) and lin.Bd.shape == (12 + nu, nu)
    rng = np.random.default_rng(3)
    x0 = rng.normal(0.0, 0.5, 12 + nu)
    d = np.zeros(20) if ring else rng.normal(0.0, 0.5, 20)
    U = rng.normal(0.0, 1.0, (20, nu))
    X = lin.predict(x0, d, U)
    f = _hand_ode(pl, tau)
    z = x0.copy()
    err = 0.0
    for k in range(20):
        sol = solve_ivp(f, (0.0, Ts), z, method="DOP853", rtol=1e-12, atol=1e-12,
                        args=(U[k], d[k]))  # fmt: skip
        z = sol.y[:, -1]
        err = max(err, float(np.abs(z - X[k + 1]).max()))
    assert err <= 1e-9 * np.abs(X).max(), err


@pytest.mark.parametrize(("m", "n"), [(0, 3), (2, 2)])
@pytest.mark.parametrize("prediction", [{"cav_lag": 0.3}, {"delay": 0.4},
                                        {"delay": [0.45, 0.2, 0.0, 0.3]}])
def test_one_cav_joint_mpc_predicts_lag_and_delays_as_the_single_cav_mpc(m, n, prediction):
    """A platoon with one CAV and ``prediction.cav_lag`` or ``prediction.delay`` (one delay,
    or one per HDV front to tail): the joint QP's data equal the single-CAV MPC's (1e-12
    relative; the single-CAV delay model is checked against the delay differential equation
    in ``tests/test_mpc_delay.py``, the lag against the simulator in
    ``tests/test_actuator_lag.py``) and so do their commands on a run of observations with a
    measured CAV acceleration, the delay register filling up (1e-6 m/s^2, measured 0.0)."""
    size = m + n + 1
    if isinstance(prediction.get("delay"), list):
        prediction = {"delay": tuple(prediction["delay"][: m + n])}
    settings = MPCSettings(horizon=30, prediction=Prediction(**prediction))
    pl = Platoon(tuple([HDV] * size), (m + 1,), 15.0)
    joint = JointMPCController("mpc", settings, System("platoon", m, n, 15.0, HDV, pl))
    single = MPCController("mpc", settings, System("lcc", m, n, 15.0, HDV))
    qj = joint.formulation.matrices(joint._lin0)
    qs = single.formulation.matrices(single._lin0)
    assert joint._lin0.Ad.shape == single._lin0.Ad.shape
    assert joint._lin0.Ad.shape[0] > 2 * size  # the lag state or the delay register
    for a, b in ((qj.P, qs.P), (qj.A, qs.A)):
        assert a.shape == b.shape and abs(a - b).max() <= 1e-12 * abs(b).max()
    for a, b in ((qj.Qp, qs.Qp), (qj.Gp, qs.Gp)):
        assert np.allclose(a, b, rtol=0, atol=1e-12 * abs(b).max())
    s_star = HDV.equilibrium_spacing(15.0)
    ctx = ControlContext(m, n, 1, 0.1, np.full(1, 15.0), np.full(1, s_star), -5.0, 2.0, HDV)
    try:
        jctx = replace(ctx, cavs=(m + 1,))
    except TypeError:  # no layout fields on the context: the joint MPC reads the defaults
        jctx = ctx
    joint.reset(jctx)
    single.reset(ctx)
    rng = np.random.default_rng(5)
    diffs = []
    for k in range(40):
        s = np.concatenate([[np.nan], s_star + rng.normal(0.0, 2.0, size)])
        v = 15.0 + rng.normal(0.0, 1.0, size + 1)
        obs = Observation(0.1 * k, s[None], v[None], np.zeros((1, size + 1)),
                          cav_acceleration=np.array([[rng.normal(0.0, 1.0)]]))  # fmt: skip
        diffs.append(abs(joint(obs)[0] - single(obs)[0]))
    assert (joint.history()["status"] == 0).all() and (single.history()["status"] == 0).all()
    assert max(diffs) <= 1e-6, max(diffs)


# slow: the ring (CI runs it; the two-CAV platoon checks the same prediction by default)
@pytest.mark.parametrize(("ring", "tau"), [(False, 0.4),
                                          pytest.param(True, 0.45, marks=pytest.mark.slow)])
def test_joint_delay_prediction_follows_the_delay_differential_equation(ring, tau):
    """The joint MPC's delayed prediction (``prediction.delay``, :mod:`lcc_synth.mpc.delay`'s
    discretisation over the platoon's HDV rows; on the ring position 1 reacts to vehicle N)
    against the delay differential equation integrated by Heun's method at 0.1 ms (the HDVs'
    velocity rows see the state ``tau`` old), from a state held as the history, two CAVs /
    one AV pushed +1 m/s^2 for 2 s, the head 0.5 m/s slower for 3 s: largest error over 10 s
    within 1 % of the largest response (measured 0.16 % and 0.36 %; the single-CAV model's
    measured accuracy is 0.95 % at 0.4 s, ``tests/test_mpc_delay.py``)."""
    models = tuple(OVM(alpha=0.5 + 0.05 * i, beta=0.8 + 0.03 * i) for i in range(6))
    cavs = (6,) if ring else (2, 5)
    pl = Platoon(models, cavs, 15.0, ring=ring)
    Ts, K = 0.1, 100
    lin = linearize_joint(pl, 15.0, MPCSettings(sample_time=Ts, horizon=K,
                                                 prediction=Prediction(delay=tau)))
    model, dm = lin.model, lin.delay
    A, B, H, nx = model.A, model.B, model.H[:, 0], model.nx
    rng = np.random.default_rng(1)
    x0 = rng.normal(0.0, 0.5, nx)
    if ring:  # on the invariant hyperplane (the controller projects the measured state)
        x0[0::2] -= x0[0::2].mean()
    U = np.zeros((K, len(cavs)))
    U[:20] = 1.0
    d = np.zeros(K) if ring else np.where(np.arange(K) < 30, -0.5, 0.0)
    z0 = np.concatenate([x0] + [np.append(x0, d[0])[dm.columns]] * dm.depth)
    X = lin.predict(z0, d, U)[:, :nx]
    rows = [2 * i - 1 for i in range(1, 7) if i not in cavs]  # the HDVs' velocity rows
    A_del, H_del = np.zeros_like(A), np.zeros(nx)
    A_del[rows], H_del[rows] = A[rows], H[rows]
    h = 1e-4
    lag, sub = int(round(tau / h)), int(round(Ts / h))
    xs, ds = [x0.copy()] * (lag + 1), [d[0]] * (lag + 1)  # the past, oldest first
    x, ref = x0.copy(), [x0.copy()]

    def f(x, x_old, u, dk, d_old):
        return (A - A_del) @ x + A_del @ x_old + B @ u + (H - H_del) * dk + H_del * d_old

    for k in range(K):
        for j in range(sub):
            k1 = f(x, xs[-1 - lag], U[k], d[k], ds[-1 - lag])
            k2 = f(x + h * k1, xs[-lag], U[k], d[k], ds[-lag])
            x = x + 0.5 * h * (k1 + k2)
            xs.append(x.copy())
            ds.append(d[k] if j < sub - 1 or k + 1 == K else d[k + 1])
            if len(xs) > lag + 2:
                xs.pop(0)
                ds.pop(0)
        ref.append(x.copy())
    ref = np.array(ref)
    err = np.abs(ref - X).max() / np.abs(ref).max()
    assert err <= 0.01, err


@pytest.mark.parametrize("layout", ["one_cav", "platoon", "ring"])
def test_lag_with_delays_is_one_config_error_on_every_layout(tmp_path, layout):
    """The actuator lag and HDV delays in one prediction are not written for any layout: one
    ConfigError naming ``prediction.cav_lag``."""
    with pytest.raises(ConfigError) as err:
        build_mpc(_spec(tmp_path, layout).system, horizon=10,
                  prediction={"cav_lag": 0.2, "delay": 0.3})  # fmt: skip
    assert err.value.field == "controllers.mpc.prediction.cav_lag"


# ------------------------------------------------------------------ solvers and comfort rows


def _qp_data(tmp_path, layout, spacing_rows: bool):
    """One QP of the MPC with the ISO comfort rows on (``jerk_scale = 0.9``, ``J`` = 2.5 m/s^3
    given here), every CAV 8 m too close and 2 m/s faster than its predecessor, its past
    commands accelerating (1.5 -> 1.0 m/s^2, each further CAV 0.3 m/s^2 less): the plan wants
    to brake and the comfort rows hold it back; ``spacing_rows`` asks 2 m more than the
    predicted spacing error allows, so the soft spacing rows take slack."""
    spec = _spec(tmp_path, layout)
    ctrl = build_mpc(spec.system, horizon=20, constraints={"jerk_scale": 0.9})
    lin, form = ctrl._lin0, ctrl.formulation
    qp = form.matrices(lin)
    nx, nu, N, W = lin.Ad.shape[0], form.nu, form.N, form.W
    rng = np.random.default_rng(3)
    x0 = rng.normal(0.0, 0.5, nx)
    names = list(lin.model.state_names)
    cavs = spec.system.platoon.cavs if spec.system.platoon is not None else (0,)
    for c in cavs:
        x0[names.index(f"s_{c}")] = -8.0
        x0[names.index(f"v_{c}")] = 2.0
    if layout == "ring":  # on the invariant hyperplane: the spacing errors sum to zero
        x0[0::2] -= x0[0::2].mean()
    d = np.zeros(N) if layout == "ring" else np.full(N, 1.0)
    past = np.column_stack([np.linspace(1.5, 1.0, W) - 0.3 * j for j in range(nu)])
    p = form.param(x0, d, past[0], past)
    fb = np.full((len(form.families), N), -2.0 if spacing_rows else -np.inf)
    q, lo, hi = form.bounds(qp, p, -5.0, 2.0, fb, np.full(nu, 2.5))
    return ctrl, qp, q, lo, hi, past


@pytest.mark.parametrize("layout", ["one_cav", "platoon", "ring"])
@pytest.mark.parametrize("spacing_rows", [False, True], ids=["comfort", "comfort_and_spacing"])
def test_daqp_and_osqp_give_the_exact_qp_solution_on_every_layout(tmp_path, layout,
                                                                  spacing_rows):
    """``solver.method = "daqp"`` and the default OSQP on one QP of each layout with active
    rows, against a second exact solver (qpOASES, a primal active-set method via CasADi):
    the whole input plan within 1e-6 m/s^2, OSQP's tolerance (measured: DAQP 2e-13, OSQP
    after its polish 7e-15)."""
    from lcc_synth.mpc.active_set import DAQPSolver
    from lcc_synth.mpc.solver import OSQPSolver, solve_exact

    ctrl, qp, q, lo, hi, _ = _qp_data(tmp_path, layout, spacing_rows)
    form = ctrl.formulation
    NU, FN = form.n_input, len(form.families) * form.N
    z = solve_exact(qp, q, lo, hi, "qpoases")
    Az = qp.A.toarray() @ z
    tol = 1e-7 * (1.0 + np.abs(Az))
    active = (np.abs(Az - lo) < tol) | (np.abs(Az - hi) < tol)
    assert active[form.jerk_rows].any()  # the comparison is on a constrained QP
    assert active[NU:NU + FN].any() == spacing_rows
    for cls in (DAQPSolver, OSQPSolver):
        res = cls(qp, q, lo, hi, ctrl.settings.solver).solve(q, lo, hi)
        assert res.ok and res.status == "solved", cls.__name__
        assert np.abs(res.z[:NU] - z[:NU]).max() <= 1e-6, cls.__name__


@pytest.mark.parametrize("layout", ["one_cav", "platoon", "ring"])
def test_comfort_rows_bound_the_first_move_by_the_iso_window_on_every_layout(tmp_path, layout):
    """The comfort rows mean ``|a_k - a_{k-W}| <= J W Ts``: with the CAVs braking into a
    1 s window of past commands, each CAV's first move is exactly the oldest past command
    minus ``J W Ts`` (the closed form), the whole plan keeps the windowed bound computed
    here from the plan and the past commands, and without the rows every CAV brakes harder at
    once, beyond that bound (the rows are what held it)."""
    from lcc_synth.mpc.active_set import DAQPSolver

    ctrl, qp, q, lo, hi, past = _qp_data(tmp_path, layout, False)
    form = ctrl.formulation
    N, nu, W, J = form.N, form.nu, form.W, 2.5
    assert W * ctrl.settings.sample_time == pytest.approx(form.window) == pytest.approx(1.0)
    res = DAQPSolver(qp, q, lo, hi, ctrl.settings.solver).solve(q, lo, hi)
    U = res.z[: form.n_input].reshape(N, nu)
    np.testing.assert_allclose(U[0], past[W - 1] - J * form.window, rtol=0, atol=1e-9)
    seq = np.vstack([past[::-1], U])  # oldest first
    assert np.abs(seq[W:] - seq[:-W]).max() <= J * form.window + 1e-9
    lo2, hi2 = lo.copy(), hi.copy()
    lo2[form.jerk_rows], hi2[form.jerk_rows] = -np.inf, np.inf
    free = DAQPSolver(qp, q, lo2, hi2, ctrl.settings.solver).solve(q, lo2, hi2)
    assert np.all(free.z[:nu] < U[0] - 0.5) and np.all(free.z[:nu] >= -5.0 - 1e-9)


def _per_row_dde(A, B, H, row_delay, x0, U, d, Ts, h):
    """The delay differential equation of the linearised string, each row ``r`` reading the
    state ``row_delay[r]`` seconds old (0: undelayed), integrated by Heun's method at step
    ``h`` (the delays multiples of ``h``) with the inputs held over each sample and the
    history held at ``x0``; returns the states at the samples."""
    nx = A.shape[0]
    lags = np.rint(np.asarray(row_delay) / h).astype(int)
    groups = []
    A_now, H_now = A.copy(), H.copy()
    for lag in sorted(set(lags[lags > 0])):
        rows = lags == lag
        Ag, Hg = np.where(rows[:, None], A, 0.0), np.where(rows, H, 0.0)
        A_now[rows], H_now[rows] = 0.0, 0.0
        groups.append((lag, Ag, Hg))
    depth = int(lags.max())
    xs, ds = [x0.copy()] * (depth + 1), [d[0]] * (depth + 1)  # the past, oldest first
    sub = int(round(Ts / h))

    def f(x, back, u, dk):
        out = A_now @ x + B @ u + H_now * dk
        for lag, Ag, Hg in groups:
            out += Ag @ xs[back - 1 - lag] + Hg * ds[back - 1 - lag]
        return out

    x, ref = x0.copy(), [x0.copy()]
    for k in range(len(U)):
        for j in range(sub):
            k1 = f(x, 0, U[k], d[k])
            k2 = f(x + h * k1, 1, U[k], d[k])
            x = x + 0.5 * h * (k1 + k2)
            xs.append(x.copy())
            ds.append(d[k] if j < sub - 1 or k + 1 == len(U) else d[k + 1])
            if len(xs) > depth + 2:
                xs.pop(0)
                ds.pop(0)
        ref.append(x.copy())
    assert np.all(np.abs(lags * h - np.asarray(row_delay)) < 1e-12)
    return np.array(ref).reshape(-1, nx)


# slow: the ring (CI runs it; the two-CAV platoon checks the same prediction by default)
@pytest.mark.parametrize("ring", [False, pytest.param(True, marks=pytest.mark.slow)],
                         ids=["two_cav", "ring"])
def test_joint_prediction_with_a_delay_per_hdv_follows_the_delay_differential_equation(ring):
    """``prediction.delay`` with one delay per HDV, front to tail (one of them 0), on the
    two-CAV platoon and the ring: the joint prediction against the delay differential
    equation with each HDV's velocity row reading the state its own delay old (Heun at
    0.2 ms, converged: 0.1 ms changes the error by 2e-6), the run of
    ``test_joint_delay_prediction_follows_the_delay_differential_equation``: within 1 % of
    the largest response (measured 0.16 % and 0.03 %). The same delays in the reverse order
    miss it by more than 5 times that (measured 1.7 % on both: each delay reaches the HDV it
    is given for)."""
    models = tuple(OVM(alpha=0.5 + 0.05 * i, beta=0.8 + 0.03 * i) for i in range(6))
    cavs = (6,) if ring else (2, 5)
    hdvs = [i for i in range(1, 7) if i not in cavs]
    taus = (0.45, 0.2, 0.0, 0.3, 0.35)[: len(hdvs)]
    pl = Platoon(models, cavs, 15.0, ring=ring)
    Ts, K = 0.1, 100

    def prediction(delays):
        lin = linearize_joint(pl, 15.0, MPCSettings(sample_time=Ts, horizon=K,
                                                     prediction=Prediction(delay=delays)))
        dm = lin.delay
        z0 = np.concatenate([x0] + [np.append(x0, d[0])[dm.columns]] * dm.depth)
        return lin.model, lin.predict(z0, d, U)[:, : lin.model.nx]

    rng = np.random.default_rng(1)
    x0 = rng.normal(0.0, 0.5, 12)
    if ring:  # on the invariant hyperplane (the controller projects the measured state)
        x0[0::2] -= x0[0::2].mean()
    U = np.zeros((K, len(cavs)))
    U[:20] = 1.0
    d = np.zeros(K) if ring else np.where(np.arange(K) < 30, -0.5, 0.0)
    model, X = prediction(taus)
    row_delay = np.zeros(model.nx)
    for i, tau in zip(hdvs, taus, strict=True):
        row_delay[model.index(f"v_{i}")] = tau
    ref = _per_row_dde(model.A, model.B, model.H[:, 0], row_delay, x0, U, d, Ts, 2e-4)
    err = np.abs(ref - X).max() / np.abs(ref).max()
    assert err <= 0.01, err
    _, X_rev = prediction(taus[::-1])
    assert np.abs(ref - X_rev).max() / np.abs(ref).max() > 5 * err
