"""DeeP-LCC (lcc_synth.deeplcc) against independent truth: the fundamental lemma on exact
linear data, the reduced QP against the full QP in g (cvxpy + Clarabel), the persistency-of-
excitation refusal, the data cache, limits, the absolute safe spacing, the fallback chain and
the head-brake scenario in the nonlinear simulator."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest
from cli_subprocess import run_cli

from lcc_synth.controllers.base import ControlContext, Observation
from lcc_synth.deeplcc import data as D
from lcc_synth.deeplcc.build import deep_lcc_controller_from_table
from lcc_synth.deeplcc.controller import DeePLCCController
from lcc_synth.deeplcc.hankel import DataSet, hankel, predict, reduce, spacing_rows, windows
from lcc_synth.deeplcc.qp import formulate
from lcc_synth.deeplcc.settings import DeePLCCSettings
from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import OVM
from lcc_synth.models.platoon import Platoon, platoon_model
from lcc_synth.simulation.engine import simulate
from lcc_synth.simulation.scenario import Scenario

TS = 0.05


def linear_data(model, T, rng, noise=0.0, x0=None):
    """``T`` pairs ``(u_k, e_k, y_{k+1})`` of the exact ZOH model with i.i.d. U[-1, 1] inputs;
    y = every velocity error, then the CAVs' spacing errors (the DeeP-LCC output)."""
    Ad, Bd, Hd = model.discretize(TS)
    N = len(model.state_names) // 2
    names = [f"v_{i}" for i in range(1, N + 1)] + [f"s_{c}" for c in model.cavs]
    C = model.output_matrix(names)
    nc = Bd.shape[1]
    u = rng.uniform(-1, 1, (T, nc))
    e = rng.uniform(-1, 1, T)
    x = np.zeros(model.nx) if x0 is None else x0
    y = np.empty((T, C.shape[0]))
    for k in range(T):
        x = Ad @ x + Bd @ u[k] + Hd[:, 0] * e[k]
        y[k] = C @ x
    y = y + noise * rng.standard_normal(y.shape)
    return DataSet(u, e, y, TS), x


def platoon(n_veh, cavs, seed=0):
    rng = np.random.default_rng(seed)
    hdv = tuple(OVM(alpha=a, beta=b) for a, b in rng.uniform(0.4, 0.9, (n_veh, 2)))
    return platoon_model(Platoon(hdv, cavs, 15.0))


def test_hankel_is_the_block_hankel_matrix_time_major():
    w = np.arange(12.0).reshape(6, 2)
    H = hankel(w, 3)
    assert H.shape == (6, 4)
    for j in range(4):
        assert np.array_equal(H[:, j], w[j:j + 3].ravel())


@pytest.mark.parametrize(("n_veh", "cavs"), [(4, (1,)), (4, (2,)), (8, (3, 6))],
                         ids=["one_cav_behind_head", "one_cav_hdv_ahead", "two_cav"])
def test_fundamental_lemma_reproduces_the_linear_model_exactly(n_veh, cavs):
    rng = np.random.default_rng(1)
    model = platoon(n_veh, cavs)
    data, _ = linear_data(model, 600, rng)
    Tini, N = 12, 15
    win = windows(data, Tini, N)
    # an independent trajectory from a random initial state
    traj, _ = linear_data(model, Tini + N, rng, x0=rng.normal(size=model.nx))
    y_pred = predict(win, traj.u[:Tini], traj.e[:Tini], traj.y[:Tini], traj.u[Tini:],
                     traj.e[Tini:])  # fmt: skip
    err = np.linalg.norm(y_pred - traj.y[Tini:]) / np.linalg.norm(traj.y[Tini:])
    assert err < 1e-8


def test_persistency_of_excitation_refuses_short_and_periodic_data():
    rng = np.random.default_rng(2)
    model = platoon(4, (1,))
    good, _ = linear_data(model, 600, rng)
    rep = D.check_excitation(good, 12 + 15 + 8, "controllers.d.data")
    rho = rep.rows / rep.columns
    mp = (1 - np.sqrt(rho)) / (1 + np.sqrt(rho))  # Marchenko-Pastur edge ratio
    assert rep.ok and rep.rank == rep.rows and 0.5 * mp < rep.ratio < 2 * mp
    short = DataSet(good.u[:60], good.e[:60], good.y[:60], TS)
    with pytest.raises(ConfigError) as err:
        D.check_excitation(short, 35, "controllers.d.data")
    assert err.value.field == "controllers.d.data" and "T >=" in err.value.message
    k = np.arange(600)
    periodic = DataSet(np.sin(2 * np.pi * k / 8)[:, None], np.cos(2 * np.pi * k / 8),
                       good.y, TS)  # fmt: skip
    assert D.excitation(periodic.u, periodic.e, 35).rank <= 8
    with pytest.raises(ConfigError, match="not rich enough"):
        D.check_excitation(periodic, 35, "controllers.d.data")


def _full_qp_first_moves(win, q, r, lam_g, lam_y, W, b_parts, y_ini, a, b_w, slack,
                         exact_past=False):
    """The QP in g of Wang et al. (2023) solved by cvxpy + Clarabel (tight tolerances);
    ``exact_past``: ``Y_p g = y_ini`` as an equality instead of the lambda_y slack."""
    import cvxpy as cp

    u_ini, e_ini, e_f = b_parts
    K = win.Up.shape[1]
    N = win.Ef.shape[0]
    g = cp.Variable(K)
    sig = cp.Variable(W.shape[0])
    yf = win.Yf @ g
    uf = win.Uf @ g
    cost = (cp.sum_squares(cp.multiply(np.sqrt(np.tile(q, N)), yf))
            + cp.sum_squares(cp.multiply(np.sqrt(np.tile(r, N)), uf))
            + lam_g * cp.sum_squares(g)
            + (0 if exact_past else lam_y * cp.sum_squares(win.Yp @ g - y_ini))
            + slack[0] * cp.sum(sig) + slack[1] * cp.sum_squares(sig))  # fmt: skip
    cons = [win.Up @ g == u_ini, win.Ep @ g == e_ini, win.Ef @ g == e_f, uf >= a[0],
            uf <= a[1], W @ yf + sig >= b_w, sig >= 0]  # fmt: skip
    if exact_past:
        cons.append(win.Yp @ g == y_ini)
    cp.Problem(cp.Minimize(cost), cons).solve(
        solver="CLARABEL", tol_gap_abs=1e-11, tol_gap_rel=1e-11, tol_feas=1e-11
    )
    return np.asarray(uf.value), np.asarray(sig.value)


@pytest.mark.parametrize("noise, lam_g, exact_past",
                         [(0.0, 100.0, False), (1e-3, 100.0, False), (0.0, 0.0, False),
                          (1e-3, 100.0, True)],
                         ids=["exact", "noisy", "exact_lambda_g_0", "noisy_exact_past"])
def test_reduced_qp_equals_the_full_qp_in_g(noise, lam_g, exact_past):
    """Exact for noise-free data (singular Gamma) and noisy data (full rank), with the
    defaults' regularisation, unregularised on exact data (g restricted to the data's row
    space) and with the past outputs as equalities; the spacing and acceleration bounds are
    both active. (Exact data with exact past outputs repeat equality rows, which Clarabel
    cannot take; that case is checked against the model-based MPC below.)"""
    from lcc_synth.mpc.solver import solve_exact

    rng = np.random.default_rng(3)
    model = platoon(3, (1,))
    data, _ = linear_data(model, 160, rng, noise=noise)
    Tini, N = 4, 6
    win = windows(data, Tini, N)
    q, r = np.array([1.0, 1.0, 1.0, 0.5]), np.array([0.1])
    lam_y, slack = 1e4, (100.0, 1.0)
    W = spacing_rows(N, data.p, [0], 0.8)
    red = reduce(win, q, r, lam_g, lam_y, W, exact_past=exact_past)
    dqp = formulate(red, *slack)
    traj, _ = linear_data(model, Tini + 1, rng, noise=noise, x0=rng.normal(size=model.nx))
    u_ini, e_ini, y_ini = traj.u[:Tini].ravel(), traj.e[:Tini], traj.y[1:].ravel()
    e_f = np.zeros(N)
    e_f[0] = traj.e[Tini]
    a = (-0.4, 0.3)
    b_w = np.full(N, 0.6)  # demands more spacing than the string has: slack active
    c = red.Cb @ np.concatenate([u_ini, e_ini, e_f]) + red.Cy @ y_ini
    qv, lo, hi = dqp.vectors(c, a[0], a[1], b_w)
    x = solve_exact(dqp.qp, qv, lo, hi)
    u_red, sig_red = dqp.plan(x), dqp.slack(x)
    u_full, sig_full = _full_qp_first_moves(win, q, r, lam_g, lam_y, W, (u_ini, e_ini, e_f),
                                            y_ini, a, b_w, slack, exact_past)  # fmt: skip
    assert np.isclose(u_full.min(), a[0], atol=1e-6) or np.isclose(u_full.max(), a[1], atol=1e-6)
    assert sig_full.max() > 1e-3
    # Clarabel at 1e-11 and daqp (exact active set): agreement limited by H's conditioning
    assert np.max(np.abs(u_red - u_full)) < 1e-6
    assert np.max(np.abs(sig_red - sig_full)) < 1e-6
    # the controller's OSQP (eps_abs = eps_rel = 1e-6): the planned inputs are the first N
    # rows of A x, so OSQP's termination bounds their residual by eps_abs + eps_rel ||Ax||_inf
    # (about 2e-6 here); 10x that is the test's scale (measured: 2e-10 when the polish failed
    # on the degenerate active set, 1e-15 when it succeeded)
    from lcc_synth.mpc.settings import SolverSettings
    from lcc_synth.mpc.solver import OSQPSolver

    res = OSQPSolver(dqp.qp, qv, lo, hi, SolverSettings()).solve(qv, lo, hi)
    u_osqp = dqp.plan(res.z)
    tol = 10 * (1e-6 + 1e-6 * np.abs(dqp.qp.A @ res.z).max())
    assert res.ok and np.max(np.abs(u_osqp - u_red)) < tol


@pytest.mark.parametrize("noise, lam_g, exact_past",
                         [(1e-3, 100.0, False), (0.0, 0.0, False), (1e-3, 100.0, True)],
                         ids=["noisy", "exact_lambda_g_0", "noisy_exact_past"])
def test_reduce_without_the_maps_to_g_is_bit_for_bit_the_same(noise, lam_g, exact_past):
    """The controller's reduction skips the maps back to g (G, G0b, G0y): what the online QP
    uses (Gamma, Cb, Cy, B) is bit for bit that of the reduction with them; the maps, when
    asked for, satisfy the reduction's identities (module docstring): A G = 0, C G = Gamma,
    A (G0b b + G0y y_ini) = b and C (G0b b + G0y y_ini) = Cb b + Cy y_ini."""
    rng = np.random.default_rng(7)
    model = platoon(3, (1,))
    data, _ = linear_data(model, 160, rng, noise=noise)
    Tini, N = 4, 6
    win = windows(data, Tini, N)
    q, r = np.array([1.0, 1.0, 1.0, 0.5]), np.array([0.1])
    W = spacing_rows(N, data.p, [0], 0.8)
    lean = reduce(win, q, r, lam_g, 1e4, W, exact_past=exact_past)
    full = reduce(win, q, r, lam_g, 1e4, W, exact_past=exact_past, maps=True)
    for name in ("Gamma", "Cb", "Cy", "B"):
        assert np.array_equal(getattr(lean, name), getattr(full, name)), name
    assert lean.G is None and lean.G0b is None and lean.G0y is None
    A = np.vstack([win.Up, win.Ep, win.Ef] + ([win.Yp] if exact_past else []))
    C = np.vstack([win.Uf, W @ win.Yf])
    scale = np.abs(full.Gamma).max()
    assert np.abs(C @ full.G - full.Gamma).max() < 1e-8 * scale
    assert np.abs(A @ full.G).max() < 1e-8 * np.abs(A).max() * np.abs(full.G).max() * A.shape[1]
    traj, _ = linear_data(model, Tini + 1, rng, noise=noise, x0=rng.normal(size=model.nx))
    b = np.concatenate([traj.u[:Tini].ravel(), traj.e[:Tini], [traj.e[Tini]], np.zeros(N - 1)])
    y_ini = traj.y[1:].ravel()
    g0 = full.G0b @ b + full.G0y @ y_ini
    rhs = np.concatenate([b, y_ini]) if exact_past else b
    if not (exact_past and noise == 0.0):
        assert np.allclose(A @ g0, rhs, rtol=0, atol=1e-7 * np.abs(rhs).max())
    assert np.allclose(C @ g0, full.Cb @ b + full.Cy @ y_ini, rtol=0,
                       atol=1e-7 * np.abs(full.Cb @ b + full.Cy @ y_ini).max())


def _reduction_by_stacked_qr(win, q, r, lam_g, lam_y, W):
    """The reduction's ``Gamma, Cb, Cy`` (module docstring of :mod:`lcc_synth.deeplcc.hankel`)
    whitened by the Householder QR of ``sqrt(2) [B; sqrt(lambda_g) I]`` (``H = R'R``, no
    ``B'B`` or ``B B'`` formed): a second method, its round-off set by cond(R) = cond(H)^(1/2)."""
    N = win.Ef.shape[0]
    qf, rf = np.tile(q, N), np.tile(r, N)
    B = np.vstack([np.sqrt(qf)[:, None] * win.Yf, np.sqrt(rf)[:, None] * win.Uf,
                   np.sqrt(lam_y) * win.Yp])  # fmt: skip
    K = B.shape[1]
    R = np.linalg.qr(np.sqrt(2.0) * np.vstack([B, np.sqrt(lam_g) * np.eye(K)]), mode="r")
    A = np.vstack([win.Up, win.Ep, win.Ef])
    C = np.vstack([win.Uf, W @ win.Yf])
    Z = np.linalg.solve(R.T, np.hstack([A.T, C.T, -2.0 * lam_y * win.Yp.T]))
    nA, nC = A.shape[0], C.shape[0]
    QA, RA = np.linalg.qr(Z[:, :nA])
    M = Z[:, nA:nA + nC] - QA @ (QA.T @ Z[:, nA:nA + nC])
    Cb = Z[:, nA:nA + nC].T @ QA @ np.linalg.inv(RA).T
    return M.T @ M, Cb, -(M.T @ Z[:, nA + nC:])


@pytest.mark.parametrize("units, w_spacing", [(1.0, 0.5), (1e3, 0.5), (1.0, 0.0)],
                         ids=["si", "data_x1e3", "spacing_weight_0"])
def test_reduction_equals_a_stacked_qr_whitening(units, w_spacing):
    """The default path's reduction works in the m = 46 dimensions of the weighted rows B
    (Woodbury: the K = 151 dimensional Hessian is never formed or factored); it equals the
    reduction whitened by the QR of the stacked matrix to 1e-11 of each matrix's largest entry
    (measured 1.4e-15 / 6.8e-14 / 4.0e-13 on Gamma / Cb / Cy; on the sweep's 1931-column data
    1.4e-15 / 8.8e-14 / 1.6e-12, where the former Cholesky of H gave 2e-12 / 1.3e-11 /
    4.4e-11). Data in other units (every sample x 1e3, lambda_g x 1e6) give the same
    matrices: the whitened coordinates do not see the data's scale. A spacing weight of 0 (the
    schema allows it) leaves the constrained spacing rows W Y_f outside the weighted rows B:
    they are whitened as A's are, not as combinations of B's rows."""
    rng = np.random.default_rng(13)
    data, _ = linear_data(platoon(3, (1,)), 160, rng, noise=1e-3)
    scaled = DataSet(units * data.u, units * data.e, units * data.y, data.dt)
    win = windows(scaled, 4, 6)
    q, r = np.array([1.0, 1.0, 1.0, w_spacing]), np.array([0.1])
    W = spacing_rows(6, data.p, [0], 0.8)
    red = reduce(win, q, r, 100.0 * units**2, 1e4, W)
    truth = _reduction_by_stacked_qr(win, q, r, 100.0 * units**2, 1e4, W)
    for name, got, want in zip(("Gamma", "Cb", "Cy"), (red.Gamma, red.Cb, red.Cy), truth,
                               strict=True):  # fmt: skip
        assert np.abs(got - want).max() < 1e-11 * np.abs(want).max(), name
    if units != 1.0:
        base = reduce(windows(data, 4, 6), q, r, 100.0, 1e4, W)
        for name in ("Gamma", "Cb", "Cy"):
            want = getattr(base, name)
            assert np.abs(getattr(red, name) - want).max() < 1e-11 * np.abs(want).max(), name


def _mpc_first_plan(model, x_t, q, r, N, a_lim=None):
    """The model-based finite-horizon QP on DeeP-LCC's cost (future head error 0), solved by
    cvxpy + Clarabel at 1e-12: the independent truth of the fundamental-lemma tests."""
    import cvxpy as cp

    Ad, Bd, _ = model.discretize(TS)
    C = model.output_matrix(["v_1", "v_2", "v_3", "v_4", "s_1"])
    u = cp.Variable(N)
    x, cost = x_t, 0
    for k in range(N):
        x = Ad @ x + Bd[:, 0] * u[k]
        cost += cp.sum_squares(cp.multiply(np.sqrt(q), C @ x)) + r[0] * cp.square(u[k])
    cons = [] if a_lim is None else [u >= a_lim[0], u <= a_lim[1]]
    cp.Problem(cp.Minimize(cost), cons).solve(solver="CLARABEL", tol_gap_abs=1e-12,
                                              tol_gap_rel=1e-12, tol_feas=1e-12)  # fmt: skip
    return np.asarray(u.value)


def _deep_first_plan(win, traj, q, r, N, lam_g, exact_past, a_lim=(-50.0, 50.0)):
    from lcc_synth.mpc.solver import solve_exact

    W = spacing_rows(N, win.Yf.shape[0] // N, [0], 0.8)
    red = reduce(win, q, r, lam_g, 1e4, W, exact_past=exact_past)
    dqp = formulate(red, 100.0, 1.0)
    b = np.concatenate([traj.u.ravel(), traj.e, np.zeros(N)])
    c = red.Cb @ b + red.Cy @ traj.y.ravel()
    qv, lo, hi = dqp.vectors(c, a_lim[0], a_lim[1], np.full(N, -1e3))  # spacing bound inactive
    return dqp.plan(solve_exact(dqp.qp, qv, lo, hi))[:N]


@pytest.fixture(scope="module")
def lemma_case():
    """Exact linear data of a CAV and 3 HDVs, a past window from a random state, the MPC."""
    rng = np.random.default_rng(5)
    model = platoon(4, (1,))
    data, _ = linear_data(model, 800, rng)
    Tini, N = 10, 15
    traj, x_t = linear_data(model, Tini, rng, x0=0.5 * rng.normal(size=model.nx))
    q, r = np.array([1.0, 1.0, 1.0, 1.0, 0.5]), np.array([0.1])
    return model, data, windows(data, Tini, N), traj, x_t, q, r, N


# slow: the unbounded case (the same equality with the input bound active covers it)
@pytest.mark.parametrize(
    "a_lim", [pytest.param(None, marks=pytest.mark.slow), (-1.0, 1.0)],
    ids=["free", "input_bound_active"],
)  # fmt: skip
def test_noise_free_deeplcc_is_the_model_based_mpc(lemma_case, a_lim):
    """The fundamental lemma: with exact data, lambda_g = 0 and the past outputs as equalities
    (past_outputs = "exact"), DeeP-LCC's plan is the model-based finite-horizon QP's on the
    same cost, unconstrained and with the input bound active (measured 6e-13)."""
    model, data, win, traj, x_t, q, r, N = lemma_case
    u_mpc = _mpc_first_plan(model, x_t, q, r, N, a_lim)
    lim = (-50.0, 50.0) if a_lim is None else a_lim
    u_deep = _deep_first_plan(win, traj, q, r, N, 0.0, True, lim)
    if a_lim is not None:
        assert np.isclose(u_mpc.max(), a_lim[1], atol=1e-9)  # the bound binds
    assert abs(u_deep[0] - u_mpc[0]) < 1e-6
    assert np.max(np.abs(u_deep - u_mpc)) < 1e-6


@pytest.mark.slow  # noise-free DeeP-LCC equals the model-based MPC, whatever the data:
# test_noise_free_deeplcc_is_the_model_based_mpc
def test_noise_free_plan_does_not_depend_on_which_data_were_recorded(lemma_case):
    """A second, independent exact data set (other excitation, other length) describes the
    same system: the same plan (the Hankel matrices differ entirely, the answer may not)."""
    model, data, win, traj, x_t, q, r, N = lemma_case
    other, _ = linear_data(model, 500, np.random.default_rng(11))
    u1 = _deep_first_plan(win, traj, q, r, N, 0.0, True)
    u2 = _deep_first_plan(windows(other, 10, N), traj, q, r, N, 0.0, True)
    assert np.max(np.abs(u1 - u2)) < 1e-9 * max(1.0, np.abs(u1).max())


def test_regularised_first_move_converges_to_the_model_based_mpc(lemma_case):
    """With the defaults' soft past (slack) the regularisation biases the plan: the distance
    to the MPC falls as lambda_g falls, 1.5e-2, 1.1e-3, 3.0e-4 at lambda_g = 1e-2, 1e-3, 1e-4
    (O(lambda_g) plus O(1 / lambda_y) through sigma_y), and is 4.6e-4 at lambda_g = 0 (the
    lambda_y = 1e4 slack alone): the 1e-6 agreement needs both limits."""
    model, data, win, traj, x_t, q, r, N = lemma_case
    u_mpc = _mpc_first_plan(model, x_t, q, r, N)
    diff = {lg: abs(_deep_first_plan(win, traj, q, r, N, lg, False)[0] - u_mpc[0])
            for lg in (1e-2, 1e-3, 1e-4, 0.0)}  # fmt: skip
    assert diff[1e-2] > diff[1e-3] > diff[1e-4]
    assert diff[1e-4] < 1e-3 * abs(u_mpc[0]) and diff[1e-2] < 2e-2 * abs(u_mpc[0])
    assert 1e-5 < diff[0.0] < 1e-3 * abs(u_mpc[0])


def test_unregularised_form_refuses_what_the_data_cannot_decide():
    """lambda_g = 0 needs exact data: noisy data give a Hankel matrix of full row rank, so
    every future would fit the past (the unregularised QP plans u = y = 0, measured), refused
    by name, as are data without information; a tiny positive lambda_g on exact data is
    singular to working precision and refused too (the regularised path's Cholesky)."""
    rng = np.random.default_rng(5)
    exact_data, _ = linear_data(platoon(4, (1,)), 800, rng)
    q, r = np.array([1.0, 1.0, 1.0, 1.0, 0.5]), np.array([0.1])
    W = spacing_rows(15, exact_data.p, [0], 0.8)
    with pytest.raises(ConfigError) as err:
        reduce(windows(exact_data, 10, 15), q, r, 1e-9, 1e4, W)
    assert err.value.field == "weights.lambda_g"
    noisy, _ = linear_data(platoon(4, (1,)), 800, rng, noise=1e-3)
    for exact_past in (False, True):  # full row rank: every future fits the past
        with pytest.raises(ConfigError) as err:
            reduce(windows(noisy, 10, 15), q, r, 0.0, 1e4, W, exact_past=exact_past)
        assert err.value.field == "weights.lambda_g" and "noise-free" in err.value.message
    zero = DataSet(np.zeros((800, 1)), np.zeros(800), np.zeros((800, 5)), TS)
    with pytest.raises(ConfigError) as err:
        reduce(windows(zero, 10, 15), q, r, 0.0, 1e4, W)
    assert err.value.field == "weights.lambda_g" and "no information" in err.value.message


@dataclass(frozen=True)
class _Ctx(ControlContext):
    """A hand-made context with several CAVs (``cavs``, as the multi-CAV simulator gives)."""

    cavs: tuple[int, ...] = (1,)


def _controller_on_linear_data(n_veh, cavs, T=600, **kw):
    rng = np.random.default_rng(4)
    model = platoon(n_veh, cavs)
    data, _ = linear_data(model, T, rng, noise=1e-3)
    st = DeePLCCSettings(t_ini=10, horizon=20, **kw)
    return DeePLCCController("d", st, data, "platoon", OVM(), 15.0, n_veh + 1, cavs), model


def _ctx(n_veh, cavs, batch=1):
    s = OVM().equilibrium_spacing(15.0)
    return _Ctx(0, n_veh - 1, batch, TS, np.full(batch, 15.0), np.full(batch, s), -5.0, 2.0,
                OVM(), cavs=cavs)  # fmt: skip


def _obs(t, n_veh, v_head=15.0, gap=None):
    s = OVM().equilibrium_spacing(15.0) if gap is None else gap
    spacing = np.full((1, n_veh + 1), s)
    spacing[0, 0] = np.nan
    vel = np.full((1, n_veh + 1), 15.0)
    vel[0, 0] = v_head
    return Observation(t, spacing, vel, -np.cumsum(np.nan_to_num(spacing), axis=1))


def test_several_cavs_give_one_command_column_each():
    ctrl, _ = _controller_on_linear_data(8, (3, 6))
    ctrl.reset(_ctx(8, (3, 6)))
    out = ctrl(_obs(0.0, 8, v_head=14.0))
    assert out.shape == (1, 2) and np.all(np.isfinite(out))
    st = ctrl.stats()
    assert st["solves"] == 1 and st["fallbacks"] == 0


def test_a_string_other_than_the_datas_or_a_ring_is_a_named_error():
    ctrl, _ = _controller_on_linear_data(4, (1,))
    with pytest.raises(ConfigError, match="CAVs at columns"):
        ctrl.reset(_ctx(4, (2,)))

    @dataclass(frozen=True)
    class Ring(_Ctx):
        ring: bool = True

    s = OVM().equilibrium_spacing(15.0)
    ring = Ring(0, 3, 1, TS, np.full(1, 15.0), np.full(1, s), -5.0, 2.0, OVM(), cavs=(1,))
    with pytest.raises(ConfigError, match="ring"):
        ctrl.reset(ring)


RING_DEEP = """
[system]
kind = "ring"
size = 6
cavs = [6]

[controllers.deep]
type = "deep_lcc"

[scenario]
duration = 40.0

[[scenario.perturbations]]
type = "brake"
vehicle = 1
"""


def test_a_ring_is_refused_by_name_before_any_data_are_collected(tmp_path):
    """DeeP-LCC on a ring used to fail inside its data collection with an error about a
    ``'head'`` perturbation the user never wrote. Now the API and the CLI name the controller
    and the reason, before any simulation (no progress bar, nothing collected)."""
    import lcc_synth as lcc

    with pytest.raises(ConfigError, match="a ring has none") as info:
        lcc.deep_lcc(lcc.ring(6, cavs=[6]), name="deep")
    assert info.value.field == "controllers.deep"
    (tmp_path / "ring_deep.toml").write_text(RING_DEEP)
    proc = run_cli(["simulate", "ring_deep.toml", "--no-record"], tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().splitlines() == [
        "lcc-synth simulate: error: ring_deep.toml: controllers.deep: DeeP-LCC needs an open "
        'string with a head vehicle (its external input); a ring has none: use kind = "platoon" '
        "for an open string of the same vehicles"
    ]


def test_forced_failure_runs_the_shifted_plan_then_the_static_gain():
    ctrl, _ = _controller_on_linear_data(4, (1,))
    ctrl.reset(_ctx(4, (1,)))
    for k in range(3):
        ctrl(_obs(k * TS, 4, v_head=14.0))
    ctrl.force_failure = True
    N = ctrl.settings.horizon
    for k in range(3, 3 + N + 2):
        ctrl(_obs(k * TS, 4, v_head=14.0))
    h = ctrl.history()
    status = h["status"][0]
    assert list(status[:3]) == [0, 0, 0]
    assert list(status[3:3 + N - 1]) == [1] * (N - 1) and list(status[3 + N - 1:]) == [2] * 3
    # the shifted plan: the step-3 command is entry 1 of the step-2 plan
    assert h["u"][0, 3] == pytest.approx(h["plan"][0, 2, 1])
    st = ctrl.stats()
    assert st["qp_failures"] == {"forced_failure": N + 2}
    assert st["fallback_shifted"] == N - 1 and st["fallback_static"] == 3


def _brake_scenario():
    """problems/mpc_head_brake.toml's scenario at the DeeP-LCC paper's dt = 0.05 s."""
    from pathlib import Path

    from lcc_synth.experiments.spec import load_spec

    spec = load_spec(Path(__file__).resolve().parents[1] / "problems" / "mpc_head_brake.toml")
    return replace(spec.scenario, dt=TS)


def _system():
    import lcc_synth as lcc

    return lcc.system("cf_lcc", n=10, hdv=OVM(), v_star=15.0)


def test_data_cache_is_reused_and_keyed_by_what_determines_the_data(tmp_path, monkeypatch):
    sc = Scenario(m=0, n=2, dt=TS)
    st = D.DataSettings(T=300, cache_dir=str(tmp_path))
    d1, key1, cached1 = D.load_or_collect(sc, st)
    assert not cached1 and (tmp_path / f"deeplcc-{key1}.npz").is_file()

    def no_collection(*a, **k):
        raise AssertionError("collected again")

    monkeypatch.setattr(D, "collect", no_collection)
    d2, key2, cached2 = D.load_or_collect(sc, st)
    assert cached2 and key2 == key1
    assert np.array_equal(d1.u, d2.u) and np.array_equal(d1.y, d2.y)
    for other in (replace(st, seed=1), replace(st, u_amplitude=0.5), replace(st, T=301)):
        assert D.data_key(D.collection_scenario(sc, other), other, (1,)) != key1
    noisy = replace(sc, hdv_accel_noise=0.1)
    assert D.data_key(D.collection_scenario(noisy, st), st, (1,)) != key1


def test_collection_records_applied_inputs_and_the_head_excitation(tmp_path):
    sc = Scenario(m=0, n=2, dt=TS)
    st = D.DataSettings(T=300, cache=False, u_amplitude=1.0)
    d = D.collect(D.collection_scenario(sc, st), st)
    # y_{k+1} velocity of the CAV = y_k + dt u_k (Euler), head error within its amplitude
    v_cav = np.concatenate([[0.0], d.y[:, 0]])
    assert np.allclose(np.diff(v_cav), TS * d.u[:, 0], atol=1e-12)
    assert np.abs(d.e).max() <= 1.0 + 1e-12 and d.e[0] == 0.0 and np.abs(d.u).max() <= 1.0


def test_bad_settings_are_named_field_errors():
    sc = Scenario(m=0, n=2, dt=TS)
    for table, field in (
        ({"weights": {"lambda_g": -1.0}}, "controllers.d.weights.lambda_g"),
        ({"weights": {"past_outputs": "hard"}}, "controllers.d.weights.past_outputs"),
        # the nonlinear simulator's data are not noise-free: no unregularised form
        ({"weights": {"lambda_g": 0.0}, "data": {"T": 400, "cache": False}},
         "controllers.d.weights.lambda_g"),
        ({"constraints": {"a_min": 1.0}}, "controllers.d.constraints.a_min"),
        ({"data": {"T": 0}}, "controllers.d.data.T"),
        ({"horizon": 0}, "controllers.d.horizon"),
        ({"data": {"T": 100, "cache": False}}, "controllers.d.data"),  # too short: PE refusal
    ):
        with pytest.raises(ConfigError) as err:  # the data are judged when they are collected
            deep_lcc_controller_from_table("d", {"type": "deep_lcc", **table}, _system(),
                                           scenario=sc).controller()  # fmt: skip
        assert err.value.field == field, err.value


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One data cache for the n = 10 tests (their collection scenarios are the same)."""
    return tmp_path_factory.mktemp("deeplcc")


@pytest.fixture(scope="module")
def brake_runs(cache):
    """all_hdv and DeeP-LCC (tighter limits) on the head brake (n = 10, dt = 0.05)."""
    from lcc_synth.controllers.static import HDVController

    sc = _brake_scenario()
    table = {"type": "deep_lcc", "data": {"cache_dir": str(cache)}}
    ctrl = deep_lcc_controller_from_table("deep_lcc", table, _system(), scenario=sc)
    tight = deep_lcc_controller_from_table(
        "tight", {**table, "constraints": {"a_min": -3.0, "a_max": 1.0}}, _system(), scenario=sc
    )
    return {"all_hdv": simulate(sc, HDVController("all_hdv")), "deep_lcc": simulate(sc, ctrl),
            "tight": simulate(sc, tight)}  # fmt: skip


def test_head_brake_no_collision_safe_spacing_and_better_aave_than_all_hdv(brake_runs):
    from lcc_synth.metrics import MetricsConfig, summary
    from lcc_synth.mpc.report import safety_summary

    res = brake_runs["deep_lcc"]
    safe = safety_summary(res)
    assert safe["collisions"] == 0 and safe["aeb_activations"] == 0
    assert safe["bound_violation_steps"] == 0 and safe["fallbacks"] == 0
    cfg = MetricsConfig(window=(20.0, 60.0), vehicles="cav_and_behind")
    aave = {k: summary(r, cfg)["aave"] for k, r in brake_runs.items()}
    assert aave["deep_lcc"] < 0.95 * aave["all_hdv"], aave


def test_acceleration_limits_are_respected_and_reached(brake_runs):
    res = brake_runs["tight"]
    u = res.acceleration[0, :, res.cav]
    assert u.min() >= -3.0 - 1e-9 and u.max() <= 1.0 + 1e-9
    assert u.min() < -3.0 + 1e-6  # the brake needs more: the lower limit is active


@pytest.mark.slow  # CI runs it; by default: the head brake's safe spacing (the test above)
def test_absolute_spacing_bound_opens_the_gap_when_closing_in(cache):
    """s_min = 15 m demands s >= 15 + 0.8 v = 27 m at 15 m/s, more than s* = 20 m: the soft
    absolute bound is active from the start and the CAV opens the gap to it (an HDV-like CAV
    keeps 20 m); a bound relative to s* would not move it."""
    sc = Scenario(m=0, n=10, dt=TS, duration=30.0)
    table = {"type": "deep_lcc", "constraints": {"s_min": 15.0, "t_gap": 0.8, "margin": 0.0},
             "data": {"cache_dir": str(cache)}}  # fmt: skip
    ctrl = deep_lcc_controller_from_table("d", table, _system(), scenario=sc)
    res = simulate(sc, ctrl)
    st = res.controller_stats
    assert st["slack_steps"] > 0 and st["violation_steps"] > 0
    s, v = res.spacing[0, :, 1], res.velocity[0, :, 1]
    margin = s - (15.0 + 0.8 * v)
    assert margin[0] < -6.0 and abs(margin[-1]) < 0.05  # settles on the bound
    first = int(np.argmax(margin > -0.05))
    assert 0 < first and margin[first:].min() > -0.05  # once reached, it is kept


# slow: 8 s (CI runs it); the one-CAV closed-loop DeeP-LCC tests of this file stay by default
@pytest.mark.slow
def test_two_cavs_in_the_nonlinear_platoon_simulator(tmp_path):
    """problems/platoon_deeplcc_brake.toml (CAVs at 3 and 6, heterogeneous noisy HDVs) with a
    default DeeP-LCC: one command column per CAV, no collision, fuel and AAVE below all-HDV."""
    from pathlib import Path

    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.metrics import summary

    path = Path(__file__).resolve().parents[1] / "problems" / "platoon_deeplcc_brake.toml"
    spec = load_spec(path)
    table = {"type": "deep_lcc", "data": {"cache_dir": str(tmp_path)}}
    ctrl = deep_lcc_controller_from_table("deep_lcc", table, spec.system, str(path),
                                          spec.scenario)  # fmt: skip
    assert ctrl.cavs == (3, 6) and ctrl.controller().p == 8 + 2
    sc = replace(spec.scenario, duration=20.0)  # the brake and the recovery
    draws = sc.draw()
    res = simulate(sc, ctrl, draws)
    base = simulate(sc, spec.controllers["all_hdv"], draws)
    assert not res.collided.any() and res.controller_stats["errors"] == 0
    h = ctrl.history()
    assert h["u"].shape[-1] == 2 and not np.allclose(h["u"][0, :, 0], h["u"][0, :, 1])
    cfg = replace(spec.metrics, window=(0.0, 20.0))
    m, b = summary(res, cfg), summary(base, cfg)
    assert m["aave"] < 0.95 * b["aave"] and m["fuel_ml"] < 0.95 * b["fuel_ml"]


def test_the_set_up_runs_with_one_blas_thread_whatever_the_caller_has():
    """The controller's reduction is that of one BLAS thread bit for bit (a sweep's workers
    have one; ``run`` and the sweep's client had the machine's cores, which round the
    Cholesky factor and the products differently on data of the default size)."""
    from threadpoolctl import threadpool_limits

    n_veh, cavs = 10, (1,)
    rng = np.random.default_rng(8)
    model = platoon(n_veh, cavs)
    data, _ = linear_data(model, 2000, rng, noise=1e-2)  # the default T: 1931 columns
    st = DeePLCCSettings()
    with threadpool_limits(limits=2, user_api="blas"):
        ctrl = DeePLCCController("d", st, data, "platoon", OVM(), 15.0, n_veh + 1, cavs)
    w = st.weights
    q = np.concatenate([np.full(n_veh, w.velocity), np.full(1, w.spacing)])
    W = spacing_rows(st.horizon, n_veh + 1, [0], st.constraints.t_gap)
    with threadpool_limits(limits=1, user_api="blas"):
        one = reduce(windows(data, st.t_ini, st.horizon), q, np.full(1, w.input), w.lambda_g,
                     w.lambda_y, W)  # fmt: skip
    for name in ("Gamma", "Cb", "Cy", "B"):
        assert np.array_equal(getattr(ctrl.reduced, name), getattr(one, name)), name
    assert ctrl.excitation is not None
