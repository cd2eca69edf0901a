"""Controllability / observability against Theorems 1-4 and Corollaries 1-5 of the paper.

Truth comes from the theorems themselves (valid alphas), from exact rational arithmetic
(``fractions.Fraction``) on small systems, and from the explicit left eigenvector of the proof of
Theorem 1 when eq. (13) is violated.
"""

from __future__ import annotations

import json
from fractions import Fraction

import numpy as np
import pytest
from exact_rank import rational_rank

from lcc_synth.analysis.controllability import (
    controllability_report,
    default_outputs,
    observability_report,
)
from lcc_synth.analysis.staircase import kalman_decomposition, structural_split
from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import OVM, LinearCoefficients
from lcc_synth.models.linear import ccc, cf_lcc, fd_lcc, general_lcc

PAPER = OVM().linear_coefficients(15.0)
# Rational alphas on the boundary of eq. (13): alpha1 = alpha2 alpha3 - alpha3^2 = 27/50.
A2, A3 = Fraction(3, 2), Fraction(9, 10)
A1 = A2 * A3 - A3 * A3
VIOLATING = LinearCoefficients(float(A1), float(A2), float(A3))


def _random_coef(rng: np.random.Generator) -> LinearCoefficients:
    """Valid alphas: alpha1 > 0, alpha2 > alpha3 > 0 and |eq. 13| >= 0.05."""
    while True:
        a3 = rng.uniform(0.1, 2.0)
        a2 = a3 + rng.uniform(0.1, 2.0)
        a1 = rng.uniform(0.05, 3.0)
        c = LinearCoefficients(a1, a2, a3)
        if abs(c.controllability_margin) >= 0.05:
            return c


def _coefs(rng, count: int, heterogeneous: bool):
    if heterogeneous:
        return [_random_coef(rng) for _ in range(count)]
    return _random_coef(rng)


CASES = [(seed, het) for seed in range(12) for het in (False, True)]


# --------------------------------------------------------------------------------------------
# Controllability: Theorem 1, Corollary 1, Theorem 2, Corollary 2
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("seed", "het"), CASES)
def test_fd_and_cf_lcc_are_controllable(seed, het):
    """Theorem 1 and Corollary 1 for n = 1..15, homogeneous and heterogeneous."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 16)) if seed else 15
    coefs = _coefs(rng, n, het)
    for model in (fd_lcc(n, coefs), cf_lcc(n, coefs)):
        rep = controllability_report(model)
        assert rep.controllable and rep.rank == model.nx == 2 * n + 2
        assert rep.vehicles_in_subspace == list(range(0, n + 1))
        assert rep.vehicles_outside == [] and rep.vehicles_partial == []
        assert rep.decision_margin > 10


@pytest.mark.parametrize(("seed", "het"), CASES)
def test_general_lcc_theorem2(seed, het):
    """Vehicles ahead uncontrollable, CAV and vehicles behind controllable (m <= 5, n <= 15)."""
    rng = np.random.default_rng(100 + seed)
    m, n = (5, 15) if seed == 0 else (int(rng.integers(1, 6)), int(rng.integers(0, 16)))
    model = general_lcc(m, n, _coefs(rng, m + n, het))
    rep = controllability_report(model)
    assert not rep.controllable
    assert rep.rank == 2 * n + 2
    assert rep.vehicles_outside == list(range(-m, 0))
    assert rep.vehicles_in_subspace == list(range(0, n + 1))
    assert rep.vehicles_partial == []
    # The subspace is exactly the coordinate subspace of the CAV and the vehicles behind.
    P = rep.basis @ rep.basis.T
    expected = np.zeros(model.nx)
    expected[2 * m :] = 1.0
    np.testing.assert_allclose(P, np.diag(expected), atol=1e-12)
    assert rep.contains_state(model, "v_0") and not rep.contains_state(model, f"v_{-m}")


@pytest.mark.parametrize("m", [1, 2, 5])
def test_ccc_only_the_cav_is_controllable(m):
    """Corollary 2."""
    rep = controllability_report(ccc(m, PAPER))
    assert not rep.controllable and rep.rank == 2
    assert rep.vehicles_in_subspace == [0]
    assert rep.vehicles_outside == list(range(-m, 0))


# --------------------------------------------------------------------------------------------
# Observability: Theorems 3 and 4, Corollaries 3, 4, 5
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("seed", "het"), CASES)
def test_fd_cf_observability_theorem3(seed, het):
    """With v_k measured, vehicles 1..k are observable and k+1..n unobservable."""
    rng = np.random.default_rng(200 + seed)
    n = int(rng.integers(1, 16))
    coefs = _coefs(rng, n, het)
    for k in sorted({1, int(rng.integers(1, n + 1)), n}):
        fd = observability_report(fd_lcc(n, coefs), [f"v_{k}"])
        # FD-LCC: -p_0 drives nothing, so the CAV is only partly observable (v_0 yes, -p_0 no).
        assert fd.vehicles_in_subspace == list(range(1, k + 1))
        assert fd.vehicles_partial == [0]
        assert fd.vehicles_outside == list(range(k + 1, n + 1))
        assert fd.rank == 2 * k + 1 and not fd.observable
        cf = observability_report(cf_lcc(n, coefs), [f"v_{k}"])
        assert cf.vehicles_in_subspace == list(range(0, k + 1))
        assert cf.vehicles_outside == list(range(k + 1, n + 1))
        assert cf.observable == (k == n)  # Corollary 3 for CF-LCC


@pytest.mark.parametrize(("seed", "het"), CASES)
def test_general_lcc_observability_theorem4(seed, het):
    """Output C^(k) = (s_0, v_0, v_k): vehicles -m..k observable, k+1..n not; k = n: all."""
    rng = np.random.default_rng(300 + seed)
    m, n = (5, 15) if seed == 0 else (int(rng.integers(1, 6)), int(rng.integers(1, 16)))
    model = general_lcc(m, n, _coefs(rng, m + n, het))
    for k in sorted({1, int(rng.integers(1, n + 1)), n}):
        rep = observability_report(model, default_outputs(model, k))
        assert rep.outputs == ["s_0", "v_0", f"v_{k}"]
        assert rep.vehicles_in_subspace == list(range(-m, k + 1))
        assert rep.vehicles_outside == list(range(k + 1, n + 1))
        assert rep.rank == 2 * (m + k + 1)
        assert rep.observable == (k == n)  # Corollary 4


@pytest.mark.parametrize(("m", "het"), [(1, False), (3, True), (5, False), (5, True)])
def test_ccc_observable_from_own_states(m, het):
    """Corollary 5."""
    rng = np.random.default_rng(m)
    model = ccc(m, _coefs(rng, m, het))
    rep = observability_report(model, default_outputs(model))
    assert rep.outputs == ["s_0", "v_0"]
    assert rep.observable and rep.vehicles_in_subspace == list(range(-m, 1))


# --------------------------------------------------------------------------------------------
# Eq. (13) violated: checked against exact rational arithmetic
# --------------------------------------------------------------------------------------------


def _exact_fd_lcc(n: int, a1: Fraction, a2: Fraction, a3: Fraction):
    """A_f, B_1 of eq. (12) written out entry by entry in exact rationals."""
    nx = 2 * n + 2
    A = [[Fraction(0)] * nx for _ in range(nx)]
    A[0][1] = Fraction(-1)  # d(-p_0)/dt = -v_0
    for i in range(1, n + 1):
        s, v = 2 * i, 2 * i + 1
        A[s][v - 2] = Fraction(1)  # ds_i = v_{i-1} - v_i
        A[s][v] = Fraction(-1)
        A[v][s] = a1  # dv_i = a1 s_i - a2 v_i + a3 v_{i-1}
        A[v][v] = -a2
        A[v][v - 2] = a3
    B = [Fraction(0)] * nx
    B[1] = Fraction(1)
    return A, B


def _exact_kalman_rank(A, B) -> int:
    nx = len(B)
    cols, v = [], list(B)
    for _ in range(nx):
        cols.append(v)
        v = [sum(A[i][j] * v[j] for j in range(nx)) for i in range(nx)]
    return rational_rank([list(r) for r in zip(*cols, strict=True)])


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_violating_eq13_is_uncontrollable_exactly(n):
    """alpha1 = alpha2 alpha3 - alpha3^2: the exact rank is n + 2 and ours agrees."""
    A, B = _exact_fd_lcc(n, A1, A2, A3)
    exact = _exact_kalman_rank(A, B)
    assert exact == n + 2  # one cancelled mode per HDV (pole-zero cancellation at -a1/a3)
    # Sanity of the exact construction: valid alphas are controllable (Theorem 1).
    A_ok, _ = _exact_fd_lcc(n, A1 + Fraction(1, 10), A2, A3)
    assert _exact_kalman_rank(A_ok, B) == 2 * n + 2
    np.testing.assert_array_equal(np.array(A, dtype=float), fd_lcc(n, VIOLATING).A)
    rep = controllability_report(fd_lcc(n, VIOLATING))
    assert not rep.controllable and rep.rank == exact
    assert rep.decision_margin > 10
    # The CAV's own states stay controllable; the HDVs are only partly reachable.
    assert rep.vehicles_in_subspace == [0] and rep.vehicles_partial == list(range(1, n + 1))


@pytest.mark.parametrize("n", [1, 5, 15])
def test_violating_eq13_left_eigenvector_from_the_proof(n):
    """Case 2 of the proof of Theorem 1: lambda = -a1/a3 = -(a2 - a3) and the vector rho with
    rho_1 = (1, lambda/a1), all other blocks zero, satisfies rho^T (lambda I - A_f) = 0 and
    rho^T B_1 = 0 exactly; rho must be orthogonal to our controllable subspace."""
    lam = -A1 / A3
    assert lam == -(A2 - A3)
    A, B = _exact_fd_lcc(n, A1, A2, A3)
    nx = 2 * n + 2
    rho = [Fraction(0)] * nx
    rho[2], rho[3] = Fraction(1), lam / A1
    left = [lam * rho[j] - sum(rho[i] * A[i][j] for i in range(nx)) for j in range(nx)]
    assert all(x == 0 for x in left) and sum(r * b for r, b in zip(rho, B, strict=True)) == 0
    rep = controllability_report(fd_lcc(n, VIOLATING))
    r = np.array(rho, dtype=float)
    assert np.linalg.norm(rep.basis.T @ r) < 1e-10 * np.linalg.norm(r)
    assert rep.rank == n + 2


def test_violation_in_one_vehicle_of_a_heterogeneous_string():
    """Only vehicle 3 violates eq. (13): exactly one mode is lost."""
    rng = np.random.default_rng(7)
    coefs = [_random_coef(rng) for _ in range(6)]
    coefs[2] = VIOLATING
    rep = controllability_report(fd_lcc(6, coefs))
    assert rep.rank == 2 * 6 + 2 - 1


# --------------------------------------------------------------------------------------------
# The decomposition itself, and why the textbook tests are not used
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "model",
    [general_lcc(3, 4, PAPER), fd_lcc(6, VIOLATING), ccc(2, PAPER), cf_lcc(10, PAPER)],
    ids=["lcc", "fd_violating", "ccc", "cf"],
)
def test_kalman_decomposition_form(model):
    dec = kalman_decomposition(model.A, model.B)
    T, nc = dec.T, dec.n_c
    np.testing.assert_allclose(T.T @ T, np.eye(model.nx), atol=1e-13)
    At, Bt = T.T @ model.A @ T, T.T @ model.B
    scale = np.linalg.norm(model.A)
    assert np.max(np.abs(At[nc:, :nc]), initial=0.0) < 1e-13 * scale
    assert np.max(np.abs(Bt[nc:]), initial=0.0) < 1e-13
    assert sum(dec.steps) == nc
    # The controllable part is itself controllable: its staircase keeps every direction.
    assert kalman_decomposition(At[:nc, :nc], Bt[:nc]).n_c == nc


def test_structural_split_finds_vehicles_ahead():
    model = general_lcc(2, 3, PAPER)
    reach, unreach = structural_split(model.A, model.B)
    assert list(unreach) == [0, 1, 2, 3] and list(reach) == list(range(4, model.nx))


def _naive_pbh_uncontrollable_modes(A, B) -> int:
    """Sum over the computed eigenvalues of the rank deficiency of [lambda I - A, B]."""
    nx = A.shape[0]
    return sum(
        nx - np.linalg.matrix_rank(np.hstack([lam * np.eye(nx) - A, B]))
        for lam in np.linalg.eigvals(A)
    )


def _naive_kalman_rank(A, B) -> int:
    cols = [B]
    for _ in range(A.shape[0] - 1):
        cols.append(A @ cols[-1])
    return int(np.linalg.matrix_rank(np.hstack(cols)))


def test_naive_methods_fail_where_the_staircase_succeeds():
    """Documents why the method matters (truth: Theorem 1 and exact rational rank).

    1. The Kalman-matrix rank calls FD-LCC with n = 15 (paper's alphas) uncontrollable,
       contradicting Theorem 1: its columns span ~20 orders of magnitude.
    2. PBH at computed eigenvalues counts the uncontrollable modes wrongly: the repeated
       eigenvalues come out scattered, so each copy is counted (FD-LCC violating eq. 13 with
       n = 4: exact uncontrollable dimension 4, PBH count much larger).
    """
    fd = fd_lcc(15, PAPER)
    assert _naive_kalman_rank(fd.A, fd.B) < fd.nx  # wrong
    assert controllability_report(fd).controllable  # right

    n = 4
    A, B = _exact_fd_lcc(n, A1, A2, A3)
    exact_unc = 2 * n + 2 - _exact_kalman_rank(A, B)
    bad = fd_lcc(n, VIOLATING)
    assert _naive_pbh_uncontrollable_modes(bad.A, bad.B) > exact_unc  # wrong
    assert bad.nx - controllability_report(bad).rank == exact_unc  # right


# --------------------------------------------------------------------------------------------
# API details
# --------------------------------------------------------------------------------------------


def test_reports_as_dict_are_json():
    model = general_lcc(2, 3, PAPER)
    c = controllability_report(model).as_dict()
    o = observability_report(model, default_outputs(model, 2)).as_dict()
    json.dumps(c)
    json.dumps(o)
    assert "basis" not in c and c["controllable"] is False and c["rank"] == 8
    assert c["vehicles_outside"] == [-2, -1]
    assert o["outputs"] == ["s_0", "v_0", "v_2"] and o["vehicles_outside"] == [3]


def test_default_outputs_and_errors():
    assert default_outputs(fd_lcc(3, PAPER)) == ["v_3"]
    assert default_outputs(general_lcc(1, 3, PAPER), 2) == ["s_0", "v_0", "v_2"]
    with pytest.raises(ConfigError, match="k"):
        default_outputs(fd_lcc(3, PAPER), 4)
    with pytest.raises(ConfigError, match="outputs"):
        observability_report(fd_lcc(3, PAPER), [])
    with pytest.raises(ConfigError, match="unknown state"):
        observability_report(fd_lcc(3, PAPER), ["v_9"])


def test_uncontrollable_modes_are_those_of_the_vehicles_ahead():
    """A_22 is block triangular with the P_1 of each vehicle ahead on its diagonal, so the
    uncontrollable modes are the roots of s^2 + alpha2 s + alpha1 of those vehicles."""
    coefs = [LinearCoefficients(0.7, 1.6, 0.8), LinearCoefficients(2.0, 1.3, 0.5), PAPER, PAPER]
    rep = controllability_report(general_lcc(2, 2, coefs))
    expected = np.concatenate([np.roots([1.0, c.alpha2, c.alpha1]) for c in coefs[:2]])
    got = rep.uncontrollable_eigenvalues
    assert got.size == 4
    for lam in expected:
        assert np.min(np.abs(got - lam)) < 1e-10
    assert rep.stabilizable and rep.uncontrollable_max_real < 0
    assert rep.as_dict()["stabilizable"] is True
    full = controllability_report(fd_lcc(3, PAPER))
    assert full.uncontrollable_eigenvalues.size == 0 and full.uncontrollable_max_real is None


def test_violating_eq13_loses_the_cancelled_mode():
    """The lost modes sit at the cancelled pole-zero pair lambda = -(alpha2 - alpha3)."""
    rep = controllability_report(fd_lcc(3, VIOLATING))
    lam = rep.uncontrollable_eigenvalues
    assert lam.size == 3
    # A triple eigenvalue in a Jordan chain scatters by about eps^(1/3) ~ 6e-6.
    np.testing.assert_allclose(lam, -float(A2 - A3), atol=1e-4)
    assert rep.stabilizable


@pytest.mark.parametrize(("m", "n"), [(1, 1), (2, 3), (3, 2)])
def test_structural_split_and_plain_staircase_agree_on_small_systems(m, n):
    model = general_lcc(m, n, PAPER)
    with_split = kalman_decomposition(model.A, model.B)
    plain = kalman_decomposition(model.A, model.B, structural=False)
    assert with_split.n_structural == 2 * m and plain.n_structural == 0
    assert plain.n_c == with_split.n_c == 2 * n + 2
    Q1, Q2 = with_split.T[:, : with_split.n_c], plain.T[:, : plain.n_c]
    np.testing.assert_allclose(Q1 @ Q1.T, Q2 @ Q2.T, atol=1e-12)


def _exactify(M: np.ndarray) -> list[list[Fraction]]:
    """Replace every float entry of an LCC matrix built from VIOLATING by its exact rational."""
    table = {float(q): q for q in (A1, A2, A3, -A1, -A2, -A3, Fraction(1), Fraction(-1))}
    table[0.0] = Fraction(0)
    return [[table[float(x)] for x in row] for row in M]


def _exact_observability_rank(A, C) -> int:
    rows, nx = [list(r) for r in C], len(A)
    block = [list(r) for r in C]
    for _ in range(nx - 1):
        block = [[sum(r[k] * A[k][j] for k in range(nx)) for j in range(nx)] for r in block]
        rows.extend(block)
    return rational_rank(rows)


@pytest.mark.parametrize(
    ("model", "outputs"),
    [
        (fd_lcc(3, VIOLATING), ["v_3"]),
        (cf_lcc(3, VIOLATING), ["v_3"]),
        (general_lcc(2, 2, VIOLATING), ["s_0", "v_0", "v_2"]),
    ],
    ids=["fd", "cf", "lcc"],
)
def test_violating_eq13_observability_matchesrational_rank(model, outputs):
    """Theorems 3/4 assume eq. (13); when it fails the pole-zero cancellations of the HDVs also
    hide modes from v_k. Truth: the exact rank of the observability matrix."""
    A = _exactify(model.A)
    C = _exactify(model.output_matrix(outputs))
    exact = _exact_observability_rank(A, C)
    rep = observability_report(model, outputs)
    assert exact < model.nx and rep.rank == exact and not rep.observable
    assert rep.decision_margin > 10
    # And controllability of the general model against the exact Kalman rank.
    B = [row[0] for row in _exactify(model.B)]
    assert controllability_report(model).rank == _exact_kalman_rank(A, B)
