"""Linearised LCC models (eqs. 9, 11, 12, 14) against the block formulas written out by hand,
the proofs of Corollary 1 and Theorem 2, transfer functions and discretisation."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import OVM, LinearCoefficients
from lcc_synth.models.linear import (
    build_model,
    ccc,
    cf_lcc,
    discretize,
    fd_lcc,
    general_lcc,
    model_from_hdv,
)

PAPER = OVM().linear_coefficients(15.0)
# Heterogeneous string for m = n = 2: vehicles -2, -1, 1, 2 (and the CAV's own law).
C_M2 = LinearCoefficients(0.7, 1.6, 0.8)
C_M1 = LinearCoefficients(0.9, 1.3, 0.5)
C_P1 = LinearCoefficients(1.1, 2.0, 1.2)
C_P2 = LinearCoefficients(0.6, 1.45, 0.95)
HET = [C_M2, C_M1, C_P1, C_P2]


def test_general_lcc_m2_n2_matches_eq9_written_out():
    """State x = (s_-2, v_-2, s_-1, v_-1, s_0, v_0, s_1, v_1, s_2, v_2)."""
    model = general_lcc(2, 2, HET)
    a, b, c, d = C_M2, C_M1, C_P1, C_P2
    A = np.array(
        [
            # s_-2 = v_h - v_-2 ; v_-2 = a1 s_-2 - a2 v_-2 + a3 v_h
            [0, -1, 0, 0, 0, 0, 0, 0, 0, 0],
            [a.alpha1, -a.alpha2, 0, 0, 0, 0, 0, 0, 0, 0],
            # s_-1 = v_-2 - v_-1 ; v_-1 = a1 s_-1 - a2 v_-1 + a3 v_-2
            [0, 1, 0, -1, 0, 0, 0, 0, 0, 0],
            [0, b.alpha3, b.alpha1, -b.alpha2, 0, 0, 0, 0, 0, 0],
            # s_0 = v_-1 - v_0 ; v_0 = u
            [0, 0, 0, 1, 0, -1, 0, 0, 0, 0],
            [0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
            # s_1 = v_0 - v_1 ; v_1 = a1 s_1 - a2 v_1 + a3 v_0
            [0, 0, 0, 0, 0, 1, 0, -1, 0, 0],
            [0, 0, 0, 0, 0, c.alpha3, c.alpha1, -c.alpha2, 0, 0],
            # s_2 = v_1 - v_2 ; v_2 = a1 s_2 - a2 v_2 + a3 v_1
            [0, 0, 0, 0, 0, 0, 0, 1, 0, -1],
            [0, 0, 0, 0, 0, 0, 0, d.alpha3, d.alpha1, -d.alpha2],
        ],
        dtype=float,
    )
    np.testing.assert_array_equal(model.A, A)
    np.testing.assert_array_equal(model.B[:, 0], [0, 0, 0, 0, 0, 1, 0, 0, 0, 0])
    np.testing.assert_array_equal(model.H[:, 0], [1, a.alpha3, 0, 0, 0, 0, 0, 0, 0, 0])
    assert model.state_names == (
        "s_-2", "v_-2", "s_-1", "v_-1", "s_0", "v_0", "s_1", "v_1", "s_2", "v_2",
    )  # fmt: skip
    assert model.vehicles == (-2, -1, 0, 1, 2)
    assert model.coefficients[1] == C_P1 and model.coefficients[-2] == C_M2


def test_fd_lcc_matches_eq12_and_cf_lcc_is_its_state_feedback():
    """Proof of Corollary 1: A_c = A_f - B_1 K_1 with K_1 = [-a1, a2, 0, ..., 0]."""
    n = 4
    fd, cf = fd_lcc(n, PAPER), cf_lcc(n, PAPER)
    a1, a2, a3 = PAPER.as_tuple()
    assert fd.state_names[:3] == ("-p_0", "v_0", "s_1")
    np.testing.assert_array_equal(fd.A[:2, :2], [[0, -1], [0, 0]])  # S_1
    np.testing.assert_array_equal(fd.A[2:4, 0:2], [[0, 1], [0, a3]])  # P_2
    np.testing.assert_array_equal(fd.A[2:4, 2:4], [[0, -1], [a1, -a2]])  # P_1
    assert not fd.H.any()
    K1 = np.zeros((1, fd.nx))
    K1[0, :2] = [-a1, a2]
    np.testing.assert_array_equal(cf.A, fd.A - fd.B @ K1)
    np.testing.assert_array_equal(cf.B, fd.B)
    np.testing.assert_array_equal(cf.H[:, 0], np.r_[1.0, a3, np.zeros(2 * n)])


def test_ccc_is_general_lcc_with_n0_and_matches_eq14():
    m = 3
    c, g = ccc(m, PAPER), general_lcc(m, 0, PAPER)
    for name in ("A", "B", "H"):
        np.testing.assert_array_equal(getattr(c, name), getattr(g, name))
    np.testing.assert_array_equal(c.A[-2:, -4:], [[0, 1, 0, -1], [0, 0, 0, 0]])  # S_2, S_1
    np.testing.assert_array_equal(c.B[:, 0], np.r_[np.zeros(2 * m + 1), 1.0])
    assert c.kind == "ccc" and c.n == 0


@pytest.mark.parametrize(("m", "n"), [(1, 1), (2, 3), (5, 4)])
def test_theorem2_transformation_gives_block_triangular_form(m, n):
    """T^-1 = [[0, I_{2n+2}], [I_{2m}, 0]]: T^-1 A T = [[A_f, A_12], [0, A_22]]."""
    rng = np.random.default_rng(m * 10 + n)
    coefs = [
        LinearCoefficients(rng.uniform(0.3, 2), a2 := rng.uniform(1.0, 2.5), rng.uniform(0.2, a2))
        for _ in range(m + n)
    ]
    model = general_lcc(m, n, coefs)
    nf, na = 2 * n + 2, 2 * m
    Tinv = np.zeros((nf + na, nf + na))
    Tinv[:nf, na:] = np.eye(nf)
    Tinv[nf:, :na] = np.eye(na)
    T = np.linalg.inv(Tinv)
    At = Tinv @ model.A @ T
    Af = fd_lcc(n, coefs[m:]).A
    np.testing.assert_array_equal(At[:nf, :nf], Af)
    assert not At[nf:, :nf].any()
    A12 = np.zeros((nf, na))
    A12[:2, -2:] = [[0, 1], [0, 0]]  # S_2: the CAV's spacing sees v_-1
    np.testing.assert_array_equal(At[:nf, nf:], A12)
    # A_22 is the chain of the vehicles ahead: P_1 on the diagonal, P_2 below.
    A22 = At[nf:, nf:]
    for j, c in enumerate(coefs[:m]):
        np.testing.assert_array_equal(A22[2 * j : 2 * j + 2, 2 * j : 2 * j + 2], [
            [0, -1], [c.alpha1, -c.alpha2]])  # fmt: skip
        if j:
            np.testing.assert_array_equal(A22[2 * j : 2 * j + 2, 2 * j - 2 : 2 * j], [
                [0, 1], [0, c.alpha3]])  # fmt: skip
    Bt = Tinv @ model.B
    np.testing.assert_array_equal(Bt[:, 0], np.r_[0.0, 1.0, np.zeros(nf + na - 2)])
    Ht = Tinv @ model.H
    np.testing.assert_array_equal(Ht[nf : nf + 2, 0], [1.0, coefs[0].alpha3])
    assert not Ht[:nf].any()


def test_to_statespace_equals_resolvent_formula():
    model = general_lcc(2, 2, HET)
    outs = ["v_2", "s_0", "v_-1"]
    sys = model.to_statespace(outs)
    C = model.output_matrix(outs)
    BH = np.hstack([model.B, model.H])
    for w in (0.05, 0.7, 3.0):
        G = sys(1j * w)
        R = C @ np.linalg.solve(1j * w * np.eye(model.nx) - model.A, BH)
        np.testing.assert_allclose(G, R, rtol=1e-12, atol=1e-14)
    assert list(sys.input_labels) == ["u", "v_h"]
    assert list(sys.output_labels) == outs


def test_hdv_chain_transfer_function_of_section_iv():
    """Head -> v_-2 of the general model is phi/gamma = (a3 s + a1)/(s^2 + a2 s + a1)."""
    model = general_lcc(2, 0, PAPER)
    sys = model.to_statespace(["v_-2"])
    a1, a2, a3 = PAPER.as_tuple()
    for w in (0.1, 1.0, 5.0):
        s = 1j * w
        assert complex(sys(s)[0, 1]) == pytest.approx((a3 * s + a1) / (s * s + a2 * s + a1))


def test_discretize_against_euler_and_scipy():
    model = general_lcc(1, 2, PAPER)
    BH = np.hstack([model.B, model.H])
    Ts = 0.1
    Ad, Bd = discretize(model.A, BH, Ts)
    ref = scipy.signal.cont2discrete((model.A, BH, np.eye(model.nx), 0), Ts, method="zoh")
    np.testing.assert_allclose(Ad, ref[0], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(Bd, ref[1], rtol=1e-12, atol=1e-14)
    # Fine explicit Euler with the input held constant (2^20 steps): error O(h).
    nx, nu = BH.shape
    M = np.zeros((nx + nu, nx + nu))
    M[:nx, :nx], M[:nx, nx:] = model.A, BH
    steps = 2**20
    Phi = np.linalg.matrix_power(np.eye(nx + nu) + M * (Ts / steps), steps)
    np.testing.assert_allclose(Ad, Phi[:nx, :nx], atol=1e-7)
    np.testing.assert_allclose(Bd, Phi[:nx, nx:], atol=1e-7)
    with pytest.raises(ConfigError, match="sample_time"):
        discretize(model.A, BH, 0.0)


def test_model_from_hdv_heterogeneous_uses_each_vehicle():
    hdvs = [OVM(alpha=0.5), OVM(beta=1.0), OVM(alpha=0.8, beta=0.7)]
    model = model_from_hdv("lcc", 1, 2, hdvs, 15.0)
    for i, h in zip((-1, 1, 2), hdvs, strict=True):
        assert model.coefficients[i] == h.linear_coefficients(15.0)
    assert model.coefficients[0] == hdvs[1].linear_coefficients(15.0)  # CAV law: first behind


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: build_model("acc", 0, 2, PAPER), "kind"),
        (lambda: build_model("cf_lcc", 1, 2, PAPER), "m"),
        (lambda: build_model("fd_lcc", 1, 2, PAPER), "m"),
        (lambda: build_model("ccc", 2, 1, PAPER), "n"),
        (lambda: build_model("fd_lcc", 0, 0, PAPER), "n"),
        (lambda: build_model("lcc", -1, 2, PAPER), "m"),
        (lambda: build_model("lcc", 1, 2, [PAPER, PAPER]), "hdv"),
        (lambda: general_lcc(1, 1, PAPER).index("v_7"), "state"),
        (lambda: general_lcc(1, 1, PAPER).block(3), "vehicle"),
    ],
)
def test_model_errors_name_the_field(call, field):
    with pytest.raises(ConfigError) as err:
        call()
    assert err.value.field == field


def test_output_matrix_and_blocks():
    model = general_lcc(1, 2, PAPER)
    C = model.output_matrix(["s_0", "v_2"])
    assert C.shape == (2, model.nx) and C[0, 2] == 1 and C[1, 7] == 1 and C.sum() == 2
    assert model.block(0) == slice(2, 4) and model.block(-1) == slice(0, 2)
    assert model.tail_velocity_index == model.nx - 1
