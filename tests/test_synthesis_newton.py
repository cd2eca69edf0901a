"""Newton polishing of structured H2 gains: the shared-Schur Lyapunov solves against scipy, the
exact Hessian against finite differences of the gradient, and the Newton optimum against the
first-order (Anderson-Moore / gradient) descent."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as sla

from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import model_from_hdv
from lcc_synth.synthesis import structured
from lcc_synth.synthesis.h2 import (
    Weights,
    closed_loop_matrix,
    h2_cost,
    h2_cost_schur,
    make_plant,
    riccati_gain,
)
from lcc_synth.synthesis.lyapunov import closed_loop_schur
from lcc_synth.synthesis.structured import h2_hessian, pattern_mask, polish

HDV = OVM(alpha=0.6, beta=0.9, s_st=5.0, s_go=35.0, v_max=30.0)
W = Weights(q_s=0.1, q_v=1.0, q_a=3.0, r=1.0, accel=1.0)


def _plant(kind="cf_lcc", m=0, n=10, semantics="replace"):
    return make_plant(model_from_hdv(kind, m, n, HDV, 15.0), semantics, W)


CASES = [
    ("cf_lcc", 0, 10, "replace", [1, 2]),
    ("cf_lcc", 0, 6, "added", [1]),
    ("lcc", 2, 3, "replace", [-1, 1, 2]),
]


@pytest.mark.parametrize("transpose", [False, True])
def test_shared_schur_solves_match_scipy(transpose):
    rng = np.random.default_rng(3)
    for n in (5, 22, 60):
        A = rng.standard_normal((n, n))
        A -= (np.max(np.linalg.eigvals(A).real) + 0.5) * np.eye(n)
        C = rng.standard_normal((n, n))
        C = C @ C.T
        S = closed_loop_schur(A)
        X = S.solve(C, transpose=transpose)
        Aop = A.T if transpose else A
        ref = sla.solve_continuous_lyapunov(Aop, -C)
        assert np.max(np.abs(X - ref)) <= 1e-10 * np.max(np.abs(ref))
        # residual of the equation itself, relative to its terms
        res = Aop @ X + X @ Aop.T + C
        assert np.max(np.abs(res)) <= 1e-11 * np.max(np.abs(C)) * n
        assert math.isclose(S.max_real_eig, np.max(np.linalg.eigvals(A).real), rel_tol=1e-9)


def test_h2_cost_equals_the_lyapunov_definition():
    p = _plant()
    g = np.where(pattern_mask(p, [1, 2]), riccati_gain(p)[0], 0.0)
    J, L, P = h2_cost(p, g)
    AK = closed_loop_matrix(p, g)
    Lref = sla.solve_continuous_lyapunov(AK, -p.Bw @ p.Bw.T)
    Pref = sla.solve_continuous_lyapunov(AK.T, -(p.Q + p.r * np.outer(g, g)))
    assert np.allclose(L, Lref, rtol=1e-10, atol=1e-12 * np.abs(Lref).max())
    assert np.allclose(P, Pref, rtol=1e-10, atol=1e-12 * np.abs(Pref).max())
    # the two trace formulas of J agree (independent Gramians)
    assert math.isclose(J, float(np.trace(p.Bw.T @ P @ p.Bw)), rel_tol=1e-10)


def _grad(p, g):
    J, L, P, _ = h2_cost_schur(p, g)
    return (2.0 * (p.r * g.reshape(1, -1) + p.B.T @ P) @ L).ravel()


@pytest.mark.parametrize("kind,m,n,semantics,heard", CASES)
def test_hessian_matches_finite_differences(kind, m, n, semantics, heard):
    p = _plant(kind, m, n, semantics)
    mask = pattern_mask(p, heard)
    idx = np.flatnonzero(mask)
    g = np.where(mask, riccati_gain(p)[0], 0.0)
    J, L, P, S = h2_cost_schur(p, g)
    assert math.isfinite(J)
    H = h2_hessian(p, g, L, P, S, mask)
    h = 1e-6 * max(1.0, np.abs(g).max())
    Hfd = np.empty_like(H)
    for c, j in enumerate(idx):
        e = np.zeros_like(g)
        e[j] = h
        Hfd[:, c] = (_grad(p, g + e)[idx] - _grad(p, g - e)[idx]) / (2 * h)
    assert np.max(np.abs(H - Hfd)) <= 1e-6 * np.max(np.abs(Hfd))
    assert np.allclose(H, H.T)


@pytest.mark.parametrize("kind,m,n,semantics,heard", CASES)
def test_newton_reaches_the_first_order_optimum(kind, m, n, semantics, heard, monkeypatch):
    p = _plant(kind, m, n, semantics)
    mask = pattern_mask(p, heard)
    g0 = np.where(mask, riccati_gain(p)[0], 0.0)
    if not math.isfinite(h2_cost(p, g0)[0]):
        g0, _ = structured._initial_gain(p, mask)
    newton = polish(p, g0, mask, tol=1e-9)
    monkeypatch.setattr(structured, "NEWTON_MAX_FREE", 0)
    first_order = polish(p, g0, mask, tol=1e-9, max_iter=5000)
    assert np.all(newton.g[~mask] == 0.0)  # the pattern is kept exactly
    assert math.isclose(newton.J, first_order.J, rel_tol=1e-9)
    assert newton.J <= first_order.J * (1 + 1e-12)
    grad = np.where(mask, _grad(p, newton.g), 0.0)
    assert np.linalg.norm(grad) <= 1e-9 * max(1.0, newton.J)
    # Newton converges in far fewer steps than the first-order descent (quadratic vs linear)
    assert newton.iterations < first_order.iterations


def test_newton_direction_descends_where_the_hessian_is_indefinite():
    p = _plant(n=40)
    mask = pattern_mask(p, [1, 2])
    g, _ = structured._initial_gain(p, mask)
    J, L, P, S = h2_cost_schur(p, g)
    grad = np.where(mask, _grad(p, g), 0.0)
    lam = np.linalg.eigvalsh(h2_hessian(p, g, L, P, S, mask))
    d = structured._newton_direction(p, g, L, P, S, mask, grad)
    assert d is not None and np.all(d[~mask] == 0.0)
    assert float(grad @ d) < 0
    if lam.min() > 0:  # positive definite here: the plain Newton step
        idx = np.flatnonzero(mask)
        H = h2_hessian(p, g, L, P, S, mask)
        assert np.allclose(d[idx], -np.linalg.solve(H, grad[idx]), rtol=1e-8)


def test_riccati_solution_is_reused_per_plant_and_returned_as_copies(monkeypatch):
    from lcc_synth.synthesis import h2

    p = _plant()
    calls = []
    solve = h2._riccati
    monkeypatch.setattr(h2, "_riccati", lambda plant: calls.append(plant) or solve(plant))
    g1, P1 = h2.riccati_gain(p)
    g1[:] = 0.0  # the caller's copy: must not reach the cache
    g2, P2 = h2.riccati_gain(p)
    assert len(calls) == 1 and np.any(g2 != 0.0)
    # the CARE itself: A'P + PA - P B r^-1 B' P + Q = 0
    res = p.A.T @ P2 + P2 @ p.A - P2 @ p.B @ p.B.T @ P2 / p.r + p.Q
    assert np.max(np.abs(res)) <= 1e-9 * np.max(np.abs(P2))
    h2.riccati_gain(_plant())  # another plant: solved again
    assert len(calls) == 2
