"""The MPC's QP against independent truth: a numpy evaluation of the cost and constraints from
the prediction model, the infinite-horizon LQR (unconstrained steps), an exact active-set solver
(DAQP via CasADi) and the exactness of the l1 slack penalty."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from lcc_synth.models.hdv import OVM
from lcc_synth.mpc.formulation import Family, Formulation, linearize, state_weights
from lcc_synth.mpc.settings import Constraints, MPCSettings, Weights
from lcc_synth.mpc.solver import OSQPSolver, solve_exact

HDV = OVM()


def _setup(kind, m, n, N=30, weights=None, behind=()):
    s = MPCSettings(
        horizon=N,
        weights=weights or Weights(),
        constraints=Constraints(behind=tuple(behind)),
    )
    lin = linearize(kind, m, n, HDV, 15.0, s)
    model = lin.model
    fams = []
    b = model.block(0)
    fams.append(Family(0, b.start, b.start + 1, s.constraints.t_gap, s.constraints.s_min))
    for i in behind:
        bi = model.block(i)
        fams.append(Family(i, bi.start, bi.start + 1, 0.8, 5.0))
    form = Formulation(kind, model.nx, s, state_weights(model, s), fams)
    return s, lin, form, form.matrices(lin)


def _numpy_cost(s, lin, form, x0, d, u_prev, z, past=None):
    """The MPC cost evaluated by simulating the prediction model (independent of CasADi);
    ``past``: the applied commands before the step, newest first (comfort rows)."""
    N = s.horizon
    w = s.weights
    q = state_weights(lin.model, s)
    U, E = z[:N], z[N:]
    X = lin.predict(x0, d, U)
    a = U.copy()
    if form.kind == "cf_lcc":
        a = np.array([lin.K_law @ X[k] + lin.k_h * d[k] + U[k] for k in range(N)])
    weighted = a if w.input_on == "total" else U
    J = w.input * np.sum(weighted**2)
    if w.jerk > 0:
        J += w.jerk * np.sum(np.diff(np.concatenate([[u_prev], weighted])) ** 2)
    for k in range(1, N):
        r = X[k] - lin.x_dir * d[k]
        J += r @ (q * r)
    r = X[N] - lin.x_dir * d[N - 1]
    J += r @ lin.P @ r
    J += w.slack * E.sum() + w.slack_quadratic * E @ E
    rows = [a]
    for f, fam in enumerate(form.families):
        rows.append(X[1:, fam.s_index] - fam.t_gap * X[1:, fam.v_index] + E[f * N:(f + 1) * N])
    rows.append(E)
    W = form.W
    if W:
        past = np.full(W, u_prev) if past is None else np.asarray(past)
        ext = np.concatenate([past[:W][::-1], a])  # a_{-W} .. a_{N-1}
        rows.append(ext[W:] - ext[:-W])
    return J, np.concatenate(rows)


@pytest.mark.parametrize(
    "kind,m,n,jerk,input_on",
    [("cf_lcc", 0, 3, 0.0, "total"), ("cf_lcc", 0, 2, 0.5, "model"), ("fd_lcc", 0, 3, 0.3, "total"),
     ("lcc", 2, 2, 0.0, "total")],
)
def test_qp_matches_numpy_cost_and_constraints(kind, m, n, jerk, input_on):
    w = Weights(jerk=jerk, input_on=input_on, velocity=1.3, spacing=0.4)
    s, lin, form, qp = _setup(kind, m, n, N=12, weights=w, behind=(1,))
    rng = np.random.default_rng(1)
    Pu = qp.P.toarray()
    H = Pu + np.triu(Pu, 1).T
    for _ in range(5):
        x0 = rng.normal(size=lin.model.nx)
        d = rng.normal(size=s.horizon)
        u_prev = rng.normal()
        past = rng.normal(size=form.W)
        p = form.param(x0, d, u_prev, past)
        q, lo, hi = form.bounds(qp, p, -5.0, 2.0, np.zeros((len(form.families), s.horizon)),
                                jerk=3.0)
        J0, g0 = _numpy_cost(s, lin, form, x0, d, u_prev, np.zeros(form.nz), past)
        for _ in range(3):
            z = rng.normal(size=form.nz)
            J, g = _numpy_cost(s, lin, form, x0, d, u_prev, z, past)
            assert 0.5 * z @ H @ z + q @ z == pytest.approx(J - J0, rel=1e-9, abs=1e-8)
            # constraint rows: A z + offset reproduces the rows; l/u are shifted by the offset
            off = g0
            np.testing.assert_allclose(qp.A @ z + off, g, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(lo[: s.horizon] + off[: s.horizon], -5.0, atol=1e-9)
            r = form.jerk_rows
            np.testing.assert_allclose(hi[r] + off[r], 3.0 * form.window, atol=1e-9)


@pytest.mark.parametrize("kind,input_on", [("cf_lcc", "total"), ("cf_lcc", "model"),
                                           ("fd_lcc", "total"), ("lcc", "total")])
def test_unconstrained_first_input_is_the_lqr_gain(kind, input_on):
    """With a Riccati terminal cost, inactive constraints and d = 0, MPC = infinite-horizon LQR."""
    m = 1 if kind == "lcc" else 0
    w = Weights(input_on=input_on)
    s, lin, form, qp = _setup(kind, m, 3, N=15, weights=w)
    model = lin.model
    q = state_weights(model, s)
    keep = np.arange(model.nx)
    if kind == "fd_lcc":
        keep = keep[1:]
    A_r = lin.Ad[np.ix_(keep, keep)]
    B_r = lin.Bd[keep].reshape(-1, 1)
    K_r = lin.K_law[keep].reshape(1, -1)
    r = w.input
    if kind == "cf_lcc" and input_on == "total":
        Qx, S = np.diag(q[keep]) + r * K_r.T @ K_r, r * K_r.T
    else:
        Qx, S = np.diag(q[keep]), np.zeros((keep.size, 1))
    P = sla.solve_discrete_are(A_r, B_r, Qx, np.array([[r]]), s=S)
    K = np.linalg.solve(r + B_r.T @ P @ B_r, B_r.T @ P @ A_r + S.T)  # u = -K x
    rng = np.random.default_rng(2)
    for _ in range(5):
        x0 = 0.05 * rng.normal(size=model.nx)
        p = form.param(x0, np.zeros(s.horizon), 0.0)
        fb = np.full((len(form.families), s.horizon), -np.inf)
        qv, lo, hi = form.bounds(qp, p, -5.0, 2.0, fb)
        z = solve_exact(qp, qv, lo, hi, "daqp")
        assert z[0] == pytest.approx(float((-K @ x0[keep])[0]), abs=1e-8)


def _random_problem(rng, form, qp, s, lin, N):
    x0 = rng.normal(size=lin.model.nx) * np.tile([3.0, 2.5], lin.model.nx // 2)
    d = np.full(N, rng.normal() * 2.0)
    p = form.param(x0, d, 0.0)
    # absolute safe spacing s0 >= 5 + 0.8 v0 at v_eq = 15 (s* = 20)
    fb = np.full((len(form.families), N), 5.0 + 0.8 * 15.0 - 20.0)
    return form.bounds(qp, p, -5.0, 2.0, fb)


@pytest.mark.parametrize("kind,m,n", [("cf_lcc", 0, 10), ("fd_lcc", 0, 10), ("lcc", 2, 4)])
def test_osqp_first_input_matches_exact_solver(kind, m, n):
    """OSQP (set up once, warm-started) vs DAQP on 60 random states: the applied first input
    agrees to 1e-3 m/s^2, and most steps are constrained."""
    N = 50
    s, lin, form, qp = _setup(kind, m, n, N=N)
    rng = np.random.default_rng(3)
    q, lo, hi = _random_problem(rng, form, qp, s, lin, N)
    solver = OSQPSolver(qp, q, lo, hi, s.solver)
    constrained = 0
    for _ in range(60):
        q, lo, hi = _random_problem(rng, form, qp, s, lin, N)
        res = solver.solve(q, lo, hi)
        assert res.ok, res.status
        ze = solve_exact(qp, q, lo, hi, "daqp")
        g = qp.A @ ze
        active = np.any(np.isclose(g, lo, atol=1e-7) | np.isclose(g, hi, atol=1e-7))
        active = active or np.any(ze[N:] > 1e-7)
        constrained += bool(active)
        assert res.z[0] == pytest.approx(ze[0], abs=1e-3)
    assert constrained >= 30


def test_l1_slack_penalty_is_exact():
    """Whenever the hard-constrained QP is feasible, the soft QP uses no slack (exact penalty)."""
    N = 50
    s, lin, form, qp = _setup("cf_lcc", 0, 10, N=N)
    rng = np.random.default_rng(4)
    checked = 0
    for _ in range(40):
        q, lo, hi = _random_problem(rng, form, qp, s, lin, N)
        hard_hi = hi.copy()
        hard_hi[2 * N:3 * N] = lo[2 * N:3 * N]  # slacks fixed at 0
        try:
            solve_exact(qp, q, lo, hard_hi, "daqp")
        except RuntimeError:
            continue  # hard problem infeasible: slack is legitimately needed
        ze = solve_exact(qp, q, lo, hi, "daqp")
        assert ze[N:].max() < 1e-7
        checked += 1
    assert checked >= 20
