"""The joint MPC of every CAV of a platoon or ring (lcc_synth.mpc.joint) against independent
truth: the single-CAV MPC (one CAV), an independent dense QP solved by cvxpy + Clarabel
(state variables, no condensation; the ring's on its invariant hyperplane), each CAV's limits
and absolute spacing bound, the per-CAV fallback chain, and a closed ring loop that damps a
perturbation which grows with every vehicle an HDV."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from lcc_synth.controllers.base import ControlContext, Observation
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.controller_tables import controller_from_table
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import OVM, linear_coefficients
from lcc_synth.models.platoon import Platoon, platoon_model
from lcc_synth.mpc import JointMPCController, MPCController
from lcc_synth.mpc.joint_prediction import joint_state_weights
from lcc_synth.mpc.settings import Constraints, MPCSettings, Prediction, SolverSettings, Weights
from lcc_synth.problem import System, system_from

HDV = OVM()
DEEPLCC = {  # the DeeP-LCC paper's platoon: positions 1..8, CAVs 3 and 6 (nominal there)
    "alpha": [0.45, 0.75, 0.6, 0.70, 0.50, 0.6, 0.40, 0.80],
    "beta": [0.60, 0.95, 0.9, 0.95, 0.75, 0.9, 0.80, 1.00],
    "s_go": [38.0, 31.0, 35.0, 33.0, 37.0, 35.0, 39.0, 34.0],
}


def _deeplcc(cavs=(3, 6)):
    hdv = tuple(OVM(alpha=a, beta=b, s_go=g) for a, b, g in zip(*DEEPLCC.values(), strict=True))
    pl = Platoon(hdv, cavs, 15.0)
    return System("platoon", cavs[0] - 1, 8 - cavs[0], 15.0, HDV, pl)


def _ring(size=20, cav=20, hdv=HDV):
    pl = Platoon(tuple([hdv] * size), (cav,), 15.0, ring=True)
    return System("ring", cav - 1, size - cav, 15.0, hdv, pl)


@dataclass(frozen=True)
class _Ctx(ControlContext):
    """The simulator session's ControlContext fields, until they land on main."""

    cavs: tuple[int, ...] = ()
    ring: bool = False
    circumference: float = math.nan


def _ctx(system, batch=1, a_min=-5.0, a_max=2.0):
    pl = system.platoon
    cols = tuple(c - 1 if pl.ring else c for c in pl.cavs)
    args = (cols[0] - 1, system.n, batch, 0.1, np.full(batch, pl.v_star),
            np.full(batch, float(pl.equilibrium_spacings[0])), a_min, a_max, system.hdv)
    kw = {"cavs": cols, "ring": pl.ring, "circumference": pl.length}
    try:
        return ControlContext(*args, **kw)
    except TypeError:  # the fields are not on main yet
        return _Ctx(*args, **kw)


def _obs(t, s, v):
    """Observation from absolute spacings / velocities ``(n_columns,)`` (one batch member)."""
    return Observation(t, np.asarray(s, float)[None], np.asarray(v, float)[None],
                       np.zeros((1, len(s))))


def _euler(system, ctrl, s0, v0, head, T, dt=0.05, linear=False, noise=None):
    """Own Euler loop of the platoon (open: column 0 is the head with velocity ``head(t)``;
    ring: vehicle 1 follows vehicle N) with the CAVs driven by ``ctrl`` at its sample time
    (zero-order hold). ``linear``: the linearised HDV rows (eq. 8) instead of the OVM.
    Returns times, spacings, velocities ``(T, N)`` of positions 1..N and commands."""
    pl = system.platoon
    N = pl.size
    model = platoon_model(pl, warn=False)
    s, v = np.array(s0, float), np.array(v0, float)
    cav = np.array(pl.cavs) - 1
    hold = int(round(ctrl.sample_time / dt)) if ctrl is not None else 1
    u = np.zeros(len(cav))
    out_s, out_v, out_u, ts = [], [], [], []
    s_eq = pl.equilibrium_spacings
    for k in range(int(round(T / dt))):
        t = k * dt
        vh = head(t) if not pl.ring else math.nan
        v_ahead = np.roll(v, 1) if pl.ring else np.concatenate([[vh], v[:-1]])
        if ctrl is not None and k % hold == 0:
            cols_s = s if pl.ring else np.concatenate([[np.nan], s])
            cols_v = v if pl.ring else np.concatenate([[vh], v])
            u = np.asarray(ctrl(_obs(t, cols_s, cols_v)), float).reshape(-1)
        if linear:
            c = model.coefficients
            a = np.array([c[i].alpha1 * (s[i] - s_eq[i]) - c[i].alpha2 * (v[i] - pl.v_star)
                          + c[i].alpha3 * (v_ahead[i] - pl.v_star) for i in range(N)])
        else:
            a = np.array([pl.hdv[i].accel(s[i], v_ahead[i] - v[i], v[i]) for i in range(N)])
            a = np.clip(a, -5.0, 2.0)
        if noise is not None:
            a = a + noise(k)
        if ctrl is not None:
            a[cav] = u
        ts.append(t)
        out_s.append(s.copy())
        out_v.append(v.copy())
        out_u.append(u.copy())
        s = s + dt * (v_ahead - v)
        v = v + dt * a
    return np.array(ts), np.array(out_s), np.array(out_v), np.array(out_u)


def _brake(t):
    return 15.0 - 5.0 * min(max(t - 1.0, 0.0), 1.5)  # -5 m/s^2 for 1.5 s, then 7.5 m/s


# ------------------------------------------------------------------ one CAV: the single-CAV MPC


@pytest.mark.parametrize(("m", "n"), [(0, 3), (2, 2)])
def test_one_cav_joint_mpc_first_move_is_the_single_cav_mpcs(m, n):
    """Homogeneous platoon, one CAV at position m+1: the same QP as the paper's LCC MPC (the
    same matrices to round-off), so OSQP's answers agree far below its tolerance; both are
    checked through a braking run in which the spacing bound and comfort rows become active.

    Tolerance: the two QPs' data agree to 1e-12 relative (asserted); OSQP runs the same
    iterations on them and, when polishing succeeds (asserted), returns the KKT point of the
    identified active set, solved with iterative refinement: the first moves then agree to
    ~1e-10 and 1e-6 m/s^2 is a bound with margin, not a fitted value."""
    size = m + n + 1
    pl = Platoon(tuple([HDV] * size), (m + 1,), 15.0)
    sys_p = System("platoon", m, n, 15.0, HDV, pl)
    settings = MPCSettings(horizon=30)
    joint = JointMPCController("mpc", settings, sys_p)
    single = MPCController("mpc", settings, System("lcc", m, n, 15.0, HDV))
    qj = joint.formulation.matrices(joint._lin0)
    qs = single.formulation.matrices(single._lin0)
    for a, b in ((qj.P, qs.P), (qj.A, qs.A)):
        assert a.shape == b.shape
        assert abs(a - b).max() <= 1e-12 * abs(b).max()
    assert np.allclose(qj.Qp, qs.Qp, rtol=0, atol=1e-12 * abs(qs.Qp).max())
    assert np.allclose(qj.Gp, qs.Gp, rtol=0, atol=1e-12 * abs(qs.Gp).max())
    ctx = _ctx(sys_p)
    single.reset(ControlContext(m, n, 1, 0.1, np.full(1, 15.0),
                                np.full(1, HDV.equilibrium_spacing(15.0)), -5.0, 2.0, HDV))
    s_star = HDV.equilibrium_spacing(15.0)
    s0 = np.full(size, s_star)
    s0[m] = 9.0  # the CAV starts close behind its predecessor
    joint.reset(ctx)
    _, S, V, U = _euler(sys_p, joint, s0, np.full(size, 15.0), _brake, 8.0, dt=0.1)
    joint.reset(ctx)
    diffs = []
    for k in range(S.shape[0]):
        obs = _obs(0.1 * k, np.concatenate([[np.nan], S[k]]),
                   np.concatenate([[_brake(0.1 * k)], V[k]]))
        a, b = joint(obs), single(obs)
        assert a.shape == (1,)
        diffs.append(abs(a[0] - b[0]))
    hj, hs = joint.history(), single.history()
    assert (hj["status"] == 0).all() and (hs["status"] == 0).all()
    assert max(diffs) <= 1e-6, max(diffs)  # measured: 0.0 on all 80 samples
    sj = joint.stats()
    assert set(sj["polish"]) == {"success"} == set(single.stats()["polish"])
    # a constrained run: spacing slack used, comfort rows yielding, the braking limit reached
    assert sj["slack_steps"] > 0 and sj["jerk_relaxed"] > 0 and U.min() == -5.0


# ------------------------------------------------------------------ independent dense QP (cvxpy)


def _dense_qp(settings, Ad, Bd, Hd, Q, P, x0, d, u_prev, past, fams, a_lo, a_hi, jerk, x_dir,
              T=None):
    """The MPC's QP written with state variables (no condensation) and solved by Clarabel.

    ``fams``: list of ``(s_row, v_row, bound (N,))`` on ``x = T xi``; ``past``: ``(W, nu)``
    newest first. Returns the optimal inputs ``(N, nu)``."""
    import cvxpy as cp

    N = settings.horizon
    w, c = settings.weights, settings.constraints
    nxi, nu = Ad.shape[0], Bd.shape[1]
    T = np.eye(nxi) if T is None else T
    X = cp.Variable((N + 1, nxi))
    U = cp.Variable((N, nu))
    E = cp.Variable((N, max(1, len(fams))))
    cons = [X[0] == x0, E >= 0, U >= np.tile(a_lo, (N, 1)), U <= np.tile(a_hi, (N, 1))]
    cost = 0
    for k in range(N):
        cons.append(X[k + 1] == Ad @ X[k] + Bd @ U[k] + Hd * d[k])
    for k in range(1, N + 1):
        r = X[k] - x_dir * d[min(k, N - 1)]
        cost += cp.quad_form(r, Q if k < N else P, assume_PSD=True)
    cost += w.input * cp.sum_squares(U)
    if w.jerk > 0:
        cost += w.jerk * cp.sum_squares(cp.vstack([U[0] - u_prev, U[1:] - U[:-1]]))
    for f, (si, vi, b) in enumerate(fams):
        xs = X[1:] @ T[si]
        xv = X[1:] @ T[vi]
        cons.append(xs - c.t_gap * xv + E[:, f] >= b)
    cost += w.slack * cp.sum(E) + w.slack_quadratic * cp.sum_squares(E)
    Wc = int(round(c.jerk_window / settings.sample_time)) if c.jerk_scale > 0 else 0
    if Wc and np.all(np.isfinite(jerk)):
        ext = cp.vstack([past[:Wc][::-1], U])  # a_{-W} .. a_{N-1}
        diff = ext[Wc:] - ext[:-Wc]
        lim = np.tile(np.asarray(jerk) * Wc * settings.sample_time, (N, 1))
        cons += [diff <= lim, diff >= -lim]
    prob = cp.Problem(cp.Minimize(cost), cons)
    prob.solve(solver=cp.CLARABEL)
    assert prob.status == "optimal", prob.status
    return np.asarray(U.value)


def _closing_in_run(system, settings, T=6.0):
    ctrl = JointMPCController("mpc", settings, system)
    ctrl.reset(_ctx(system))
    pl = system.platoon
    s0 = pl.equilibrium_spacings.copy()
    s0[np.array(pl.cavs) - 1] = 9.0 if not pl.ring else s0[np.array(pl.cavs) - 1]
    return ctrl, _euler(system, ctrl, s0, np.full(pl.size, 15.0), _brake, T)


def test_two_cav_first_moves_match_a_dense_clarabel_qp_on_constrained_steps():
    system = _deeplcc()
    settings = MPCSettings(horizon=25, weights=Weights(jerk=0.3, spacing_cav=0.8),
                           constraints=Constraints(jerk_scale=0.0, a_min=-4.0))
    ctrl, (ts, S, V, U) = _closing_in_run(system, settings)
    h = ctrl.history()
    lin = ctrl._lin0
    model = lin.model
    pl = system.platoon
    Q = np.diag(joint_state_weights(model, settings))
    c = settings.constraints
    checked = 0
    for k in range(h["u"].shape[1]):
        constrained = h["slack"][0, k] > 1e-6 or np.any(np.abs(h["u"][0, k] + 4.0) < 1e-9) \
            or k in (3, 12)
        if not constrained:
            continue
        x0, d, v_eq = h["x0"][0, k], h["d"][0, k], h["v_eq"][0, k]
        s_ref = np.array([m.equilibrium_spacing(v_eq) for m in pl.hdv])
        fams = [(2 * i - 2, 2 * i - 1, np.full(settings.horizon, c.s_min + c.margin
                 + c.t_gap * v_eq - s_ref[i - 1])) for i in pl.cavs]  # fmt: skip
        u_prev = h["u"][0, k - 1] if k else np.zeros(2)
        Ud = _dense_qp(settings, lin.Ad, lin.Bd, lin.Hd, Q, lin.P, x0, d, u_prev, None, fams,
                       np.full(2, -4.0), np.full(2, 2.0), np.inf, lin.x_dir)
        assert np.abs(h["u"][0, k] - Ud[0]).max() <= 1e-3, (k, h["u"][0, k], Ud[0])
        checked += 1
    assert checked >= 5 and ctrl.stats()["slack_steps"] > 0


def test_comfort_rows_and_past_commands_match_the_dense_qp():
    """Formulation level, the ISO comfort rows on: a hard-braking step whose first moves are
    limited by |u_k - u_{k-W}| <= J W Ts with past commands given."""
    system = _deeplcc()
    settings = MPCSettings(horizon=20, constraints=Constraints(jerk_scale=0.9))
    ctrl = JointMPCController("mpc", settings, system)
    lin = ctrl._lin0
    form = ctrl.formulation
    qp = form.matrices(lin)
    rng = np.random.default_rng(3)
    x0 = rng.normal(0, 1.0, lin.model.nx)
    d = np.full(settings.horizon, 3.0)  # the head is faster: both CAVs want to accelerate
    past = np.column_stack([np.linspace(-3.0, -2.0, form.W), np.linspace(-2.5, -1.5, form.W)])
    p = form.param(x0, d, past[0], past)
    jerk = np.array([2.5, 3.0])
    fb = np.full((2, settings.horizon), -np.inf)
    qv, lo, hi = form.bounds(qp, p, -5.0, 2.0, fb, jerk)
    from lcc_synth.mpc.solver import OSQPSolver

    res = OSQPSolver(qp, qv, lo, hi, settings.solver).solve(qv, lo, hi)
    assert res.ok
    Ud = _dense_qp(settings, lin.Ad, lin.Bd, lin.Hd, np.diag(joint_state_weights(lin.model,
                   settings)), lin.P, x0, d, past[0], past, [], np.full(2, -5.0),
                   np.full(2, 2.0), jerk, lin.x_dir)  # fmt: skip
    Uo = res.z[: form.n_input].reshape(settings.horizon, 2)
    assert np.abs(Uo - Ud).max() <= 1e-3
    # the comfort rows bind: without them the first moves differ
    lo2, hi2 = lo.copy(), hi.copy()
    lo2[form.jerk_rows], hi2[form.jerk_rows] = -np.inf, np.inf
    free = OSQPSolver(qp, qv, lo2, hi2, settings.solver).solve(qv, lo2, hi2)
    assert np.all(free.z[:2] > Uo[0] + 0.5)


# ------------------------------------------------------------------ limits, spacing bound


def test_each_cav_acceleration_limits_hold_and_bind():
    system = _deeplcc()
    settings = MPCSettings(horizon=30, constraints=Constraints(a_min=-3.0, a_max=1.5,
                                                               jerk_scale=0.0))
    ctrl, (ts, S, V, U) = _closing_in_run(system, settings, T=10.0)
    assert U.shape[1] == 2
    assert U.min() >= -3.0 - 1e-12 and U.max() <= 1.5 + 1e-12
    assert np.isclose(U[:, 0].min(), -3.0, atol=1e-6) and np.isclose(U[:, 1].min(), -3.0,
                                                                      atol=1e-6)  # fmt: skip
    plans = ctrl.history()["plan"][0]
    assert plans.min() >= -3.0 - 1e-6 and plans.max() <= 1.5 + 1e-6


def test_absolute_soft_spacing_bound_is_active_when_a_cav_closes_in():
    """CAV 6 starts 9 m behind vehicle 5 (bound at 15 m/s: 5 + 0.8 * 15 = 17 m): the plan
    re-opens the gap within the bound's slack, and the plan without the bound does not."""
    system = _deeplcc()
    on = MPCSettings(horizon=30, constraints=Constraints(jerk_scale=0.0))
    off = MPCSettings(horizon=30, constraints=Constraints(jerk_scale=0.0, spacing_ahead=False))
    pl = system.platoon
    s0 = pl.equilibrium_spacings.copy()
    s0[5] = 9.0
    out = {}
    for name, st in (("on", on), ("off", off)):
        ctrl = JointMPCController("mpc", st, system)
        ctrl.reset(_ctx(system))
        s = np.concatenate([[np.nan], s0])
        v = np.full(9, 15.0)
        ctrl(_obs(0.0, s, v))
        h = ctrl.history()
        X = h["predicted_states"][0, 0]
        v_eq = h["v_eq"][0, 0]
        s6 = X[:, 10] + pl.hdv[5].equilibrium_spacing(v_eq)
        v6 = X[:, 11] + v_eq
        out[name] = (s6 - (5.0 + 0.1 + 0.8 * v6), h["slack"][0, 0], h["plan"][0, 0][:, 1])
    margin_on, slack_on, plan_on = out["on"]
    margin_off, _, plan_off = out["off"]
    assert slack_on > 1e-3  # violated at the start: the soft bound is used
    # predicted violation = the slack (exact l1 penalty: no more than needed)
    assert -margin_on[1:].min() <= slack_on + 1e-6
    # CAV 6 brakes at its limit for longer to re-open the gap: less predicted violation
    assert plan_on[:10].sum() < plan_off[:10].sum() - 5.0
    assert np.maximum(-margin_on, 0).sum() < 0.8 * np.maximum(-margin_off, 0).sum()
    assert margin_on[10] > margin_off[10] + 1.0


# ------------------------------------------------------------------ fallback per CAV


def test_fallback_per_cav_on_solver_failure():
    system = _deeplcc()
    pl = system.platoon
    settings = MPCSettings(horizon=20, solver=SolverSettings(max_iter=1))
    ctrl = JointMPCController("mpc", settings, system)
    ctrl.reset(_ctx(system))
    s = np.concatenate([[np.nan], pl.equilibrium_spacings + np.linspace(-2, 2, 8)])
    v = np.concatenate([[14.0], 15.0 + np.linspace(1, -1, 8)])
    u = ctrl(_obs(0.0, s, v))[0]
    st = ctrl.stats()
    reason = "maximum iterations reached"
    assert st["qp_failures"] == {reason: 1}
    for i in (3, 6):  # no plan yet: each CAV's HDV law, eq. (8) by hand
        pc = st["per_cav"][f"u_{i}"]
        assert pc["fallback_static"] == 1 and pc["reasons"] == {reason: 1}
    v_eq = v[1]  # the reference: the first vehicle of the platoon (moving average, 1 sample)
    for k, i in enumerate(pl.cavs):
        c = linear_coefficients(pl.hdv[i - 1], 15.0)
        law = (c.alpha1 * (s[i] - pl.hdv[i - 1].equilibrium_spacing(v_eq))
               - c.alpha2 * (v[i] - v_eq) + c.alpha3 * (v[i - 1] - v_eq))
        assert u[k] == pytest.approx(np.clip(law, -5, 2), abs=1e-12)
    # after a solved step a failure applies the previous plan's shifted move, per CAV
    ok = JointMPCController("mpc", MPCSettings(horizon=20), system)
    ok.reset(_ctx(system))
    ok(_obs(0.0, s, v))
    plan = ok.history()["plan"][0, 0]
    for mem in ok._members:
        mem.solver.force_failure = True
    u2 = ok(_obs(0.1, s, v))[0]
    assert np.array_equal(u2, np.clip(plan[1], -5, 2))
    assert ok.stats()["per_cav"]["u_6"]["fallback_shifted"] == 1
    assert ok.history()["status"][0, 1].tolist() == [1, 1]


def test_each_cav_falls_back_on_its_own_row():
    """A lost measurement (NaN) that only CAV 6's fallback row reads: CAV 3 applies its static
    row, CAV 6 holds its last command; the reasons are reported per CAV."""
    system = _deeplcc()
    pl = system.platoon
    model = platoon_model(pl, warn=False)
    K = np.zeros((2, model.nx))
    K[0, model.index("v_3")] = -0.4
    K[1, model.index("v_8")] = -0.3
    ctrl = JointMPCController("mpc", MPCSettings(horizon=20), system,
                                Gains.on(model, K, "replace"), "test")
    ctrl.reset(_ctx(system))
    s = np.concatenate([[np.nan], pl.equilibrium_spacings])
    v = np.full(9, 15.0)
    v[3] = 16.0
    v[8] = np.nan
    u = ctrl(_obs(0.0, s, v))[0]
    pc = ctrl.stats()["per_cav"]
    assert pc["u_3"]["fallback_static"] == 1 and pc["u_6"]["fallback_hold"] == 1
    assert pc["u_3"]["reasons"] == {"nonfinite_state": 1} == pc["u_6"]["reasons"]
    v_eq = v[1]
    assert u[0] == pytest.approx(-0.4 * (16.0 - v_eq)) and u[1] == 0.0


# ------------------------------------------------------------------ ring


def test_ring_qp_equals_the_qp_on_the_invariant_hyperplane():
    """The ring's spacing errors at a mean speed away from the ring velocity do not sum to
    zero; the controller's answer must be that of the QP written on the invariant hyperplane
    (reduced coordinates xi = V'x, well-posed), where that offset does not exist. Unequal
    spacing weights make a left-over offset bias the answer (checked: it would)."""
    system = _ring()
    pl = system.platoon
    settings = MPCSettings(horizon=30, weights=Weights(spacing_cav=2.0),
                           constraints=Constraints(jerk_scale=0.0))
    ctrl = JointMPCController("mpc", settings, system)
    ctrl.reset(_ctx(system))
    rng = np.random.default_rng(7)
    s = pl.equilibrium_spacings + rng.normal(0, 1.0, pl.size)
    s *= pl.length / s.sum()  # a ring: the spacings fill the circumference
    v = 14.2 + rng.normal(0, 0.5, pl.size)  # mean speed below the ring velocity (15)
    u = ctrl(_obs(0.0, s, v))
    h = ctrl.history()
    v_eq = h["v_eq"][0, 0]
    assert v_eq == pytest.approx(v.mean())
    s_eq = np.array([m.equilibrium_spacing(v_eq) for m in pl.hdv])
    assert abs(pl.length - s_eq.sum()) > 5.0  # a real offset
    x_raw = np.empty(2 * pl.size)
    x_raw[0::2], x_raw[1::2] = s - s_eq, v - v_eq
    lin = ctrl._lin0
    V = lin.model.invariant_basis()
    Q = np.diag(joint_state_weights(lin.model, settings))
    P_r = V.T @ lin.P @ V
    c = settings.constraints
    delta = (pl.length - s_eq.sum()) / pl.size
    b = c.s_min + c.margin + c.t_gap * v_eq - (s_eq[-1] + delta)
    fams = [(2 * pl.size - 2, 2 * pl.size - 1, np.full(30, b))]
    Ud = _dense_qp(settings, V.T @ lin.Ad @ V, V.T @ lin.Bd, np.zeros(V.shape[1]),
                   V.T @ Q @ V, P_r, V.T @ x_raw, np.zeros(30), np.zeros(1), None, fams,
                   np.full(1, -5.0), np.full(1, 2.0), np.inf, np.zeros(V.shape[1]), T=V)
    assert abs(u[0] - Ud[0, 0]) <= 1e-3
    assert abs(h["x0"][0, 0][0::2].sum()) <= 1e-9 * pl.length
    # without the projection the offset would move the first input
    form = ctrl.formulation
    qp = form.matrices(lin)
    p = form.param(x_raw, np.zeros(30), np.zeros(1))
    qv, lo, hi = form.bounds(qp, p, -5.0, 2.0, np.full((1, 30), b), np.inf)
    from lcc_synth.mpc.solver import solve_exact

    biased = solve_exact(qp, qv, lo, hi)[0]
    assert abs(biased - Ud[0, 0]) > 0.05


def test_ring_mpc_damps_a_perturbation_that_grows_with_all_hdvs():
    """Default OVM (alpha 0.6, beta 0.9, s_go 35) on a 20-vehicle ring at 15 m/s: the all-HDV
    ring is linearly unstable (eigenvalue with positive real part on the invariant
    hyperplane). Own Euler loop of the linear ring: with all HDVs a 1 m/s velocity
    perturbation grows; with the MPC on vehicle 20 it decays."""
    system = _ring()
    pl = system.platoon
    hdv_ring = platoon_model(Platoon(pl.hdv, (), 15.0, ring=True), warn=False)
    V = hdv_ring.invariant_basis()
    growth = np.linalg.eigvals(V.T @ hdv_ring.A @ V).real.max()
    assert growth > 1e-2
    s0 = pl.equilibrium_spacings.copy()
    v0 = np.full(pl.size, 15.0)
    v0[4] -= 1.0
    _, _, Vh, _ = _euler(System("ring", 19, 0, 15.0, HDV, Platoon(pl.hdv, (), 15.0, ring=True)),
                         None, s0, v0, None, 180.0, dt=0.05, linear=True)
    ctrl = JointMPCController("mpc", MPCSettings(horizon=40), system)
    ctrl.reset(_ctx(system))
    _, Sm, Vm, Um = _euler(system, ctrl, s0, v0, None, 120.0, dt=0.05, linear=True)
    spread = lambda V_: np.abs(V_ - V_.mean(axis=1, keepdims=True)).max(axis=1)  # noqa: E731
    tail = slice(-int(10 / 0.05), None)
    # measured: all HDVs 0.95 -> 13.5 m/s over 180 s; MPC 0.95 -> 2e-7 m/s over 120 s
    assert spread(Vh)[tail].max() > 10.0 * spread(Vh)[:20].max()  # grows with all HDVs
    assert spread(Vm)[tail].max() < 1e-3 * spread(Vm)[:20].max()  # damped by the MPC
    st = ctrl.stats()
    assert st["fallbacks"] == 0 and st["qp_failures"] == {}
    assert np.allclose(Sm.sum(axis=1), pl.length, rtol=1e-12)  # the ring is a ring


# ------------------------------------------------------------------ problem files, registry


def _problem(kind, extra=""):
    import tomllib

    if kind == "ring":
        text = f'[system]\nkind = "ring"\nsize = 6\ncavs = [6]\nv_star = 15.0\n{extra}'
    else:
        text = f'[system]\nkind = "platoon"\nsize = 5\ncavs = [2, 4]\nv_star = 15.0\n{extra}'
    return system_from(tomllib.loads(text))


@pytest.mark.parametrize("kind", ["platoon", "ring"])
def test_registry_builds_the_joint_mpc_for_platoon_kinds(kind):
    system = _problem(kind)
    ctrl = controller_from_table("mpc", {"type": "mpc", "horizon": 10}, system)
    assert isinstance(ctrl, JointMPCController)
    desc = ctrl.describe()
    assert desc["joint"] and desc["cavs"] == list(system.platoon.cavs)
    ctrl.reset(_ctx(system))
    pl = system.platoon
    s = pl.equilibrium_spacings if pl.ring else np.concatenate([[np.nan],
                                                                pl.equilibrium_spacings])
    v = np.full(s.size, 15.0)
    u = ctrl(_obs(0.0, s, v))
    assert u.shape == ((1,) if ctrl.n_cav == 1 else (1, ctrl.n_cav))
    assert np.abs(u).max() <= 1e-6  # at the equilibrium nothing to do


@pytest.mark.parametrize(
    ("table", "field"),
    [({"n_model": 2}, "controllers.mpc.n_model"),
     ({"constraints": {"behind": [1]}}, "controllers.mpc.constraints.behind"),
     ({"weights": {"position": 1.0}}, "controllers.mpc.weights.position"),
     ({"fallback": {"gains": {"u_3": {"v_1": 1.0}}}}, "controllers.mpc.fallback.gains.u_3")],
)
def test_bad_platoon_mpc_keys_are_config_errors(table, field):
    with pytest.raises(ConfigError) as err:
        controller_from_table("mpc", {"type": "mpc", **table}, _problem("platoon"))
    assert err.value.field == field


def test_scenario_layout_mismatch_is_a_config_error():
    system = _deeplcc()
    ctrl = JointMPCController("mpc", MPCSettings(horizon=10), system)
    with pytest.raises(ConfigError, match="CAV columns"):
        ctrl.reset(_ctx(_deeplcc(cavs=(3, 7))))


def test_batch_members_are_independent_and_relinearisation_runs():
    """Two batch members equal two single-member runs bit for bit (one OSQP workspace each),
    also with re-linearisation on while the head brakes from 15 to 7.5 m/s."""
    system = _deeplcc()
    pl = system.platoon
    settings = MPCSettings(horizon=20, prediction=Prediction(relinearize=True,
                                                            equilibrium_window=1.0))
    s0 = np.concatenate([[np.nan], pl.equilibrium_spacings])
    runs = []
    for shift in (0.0, 1.5):
        ctrl = JointMPCController("mpc", settings, system)
        ctrl.reset(_ctx(system))
        out = []
        for k in range(60):
            v = np.full(9, _brake(0.1 * k) + shift)
            out.append(ctrl(_obs(0.1 * k, s0, v))[0])
        runs.append(np.array(out))
        assert ctrl.stats()["relinearizations"] >= 1
    both = JointMPCController("mpc", settings, system)
    both.reset(_ctx(system, batch=2))
    for k in range(60):
        v = np.stack([np.full(9, _brake(0.1 * k) + sh) for sh in (0.0, 1.5)])
        s = np.stack([s0, s0])
        u = both(Observation(0.1 * k, s, v, np.zeros_like(s)))
        assert u.shape == (2, 2)
        assert np.array_equal(u[0], runs[0][k]) and np.array_equal(u[1], runs[1][k])
    h = both.history()
    assert h["u"].shape == (2, 60, 2) and h["plan"].shape == (2, 60, 20, 2)
    assert h["predicted_states"].shape == (2, 60, 21, 16)


def test_fallback_gains_file_in_platoon_form(tmp_path):
    import json

    from lcc_synth.mpc import mpc_controller_from_table

    system = _problem("platoon")
    K = np.zeros((2, 10))
    K[0, 2], K[0, 3], K[1, 7] = 0.2, -0.5, -0.6  # the gains file's K is required (issue 28)
    gains = {"kind": "platoon", "size": 5, "cavs": [2, 4], "ring": False, "semantics": "replace",
             "state_names": [f"{q}_{i}" for i in range(1, 6) for q in "sv"], "K": K.tolist(),
             "gains": {"u_2": {"v_2": -0.5, "s_2": 0.2}, "u_4": {"v_4": -0.6}}, "h2_true": None}
    (tmp_path / "g.json").write_text(json.dumps(gains))
    ctrl = mpc_controller_from_table(
        "mpc", {"type": "mpc", "horizon": 10, "fallback_gains_file": "g.json",
                "solver": {"max_iter": 1}},
        system, source=str(tmp_path / "problem.toml"))
    assert ctrl.describe()["fallback"]["gains"] == gains["gains"]
    ctrl.reset(_ctx(system))
    pl = system.platoon
    s = np.concatenate([[np.nan], pl.equilibrium_spacings + 1.0])
    v = np.full(6, 15.0)
    v[4] = 16.0  # position 4 (a CAV) 1 m/s fast
    u = ctrl(_obs(0.0, s, v))[0]  # the QP fails (max_iter = 1): the file's rows
    assert u == pytest.approx([0.2 * 1.0, -0.6 * 1.0], abs=1e-12)
    (tmp_path / "bad.json").write_text(json.dumps(dict(gains, kind="ring")))
    with pytest.raises(ConfigError) as err:
        mpc_controller_from_table("mpc", {"type": "mpc", "fallback_gains_file": "bad.json"},
                                  system, source=str(tmp_path / "problem.toml"))
    assert err.value.field == "controllers.mpc.fallback_gains_file"
