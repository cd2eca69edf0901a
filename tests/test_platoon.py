"""Mixed platoons and the ring road (lcc_synth.models.platoon) against independent truth:
the paper's single-CAV models entry for entry, the ring's conservation law, the exact ZOH."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import IDM, OVM, linear_coefficients
from lcc_synth.models.linear import ccc, general_lcc
from lcc_synth.models.platoon import Platoon, platoon_model, ring_velocity
from lcc_synth.problem import system_from

DEEPLCC = {  # the DeeP-LCC paper's platoon: positions 1..8, CAVs 3 and 6 (nominal there)
    "alpha": [0.45, 0.75, 0.6, 0.70, 0.50, 0.6, 0.40, 0.80],
    "beta": [0.60, 0.95, 0.9, 0.95, 0.75, 0.9, 0.80, 1.00],
    "s_go": [38.0, 31.0, 35.0, 33.0, 37.0, 35.0, 39.0, 34.0],
}


@pytest.mark.parametrize(("m", "n"), [(0, 4), (2, 3), (3, 0), (1, 1)])
def test_one_cav_platoon_is_the_papers_general_lcc_bit_for_bit(m, n):
    rng = np.random.default_rng(m * 10 + n)
    models = [OVM(alpha=a, beta=b) for a, b in rng.uniform(0.3, 1.0, (m + n + 1, 2))]
    P = platoon_model(Platoon(tuple(models), (m + 1,), 15.0))
    coefs = [linear_coefficients(h, 15.0) for h in models]
    build = ccc if n == 0 else general_lcc
    args = (m, coefs[:m]) if n == 0 else (m, n, coefs[:m] + coefs[m + 1 :])
    G = build(*args, coefs[m])
    assert np.array_equal(P.A, G.A) and np.array_equal(P.B, G.B) and np.array_equal(P.H, G.H)
    # the same layout attributes: vehicle i of the paper's string is position i + m + 1
    assert G.cavs == (0,) and P.cavs == (m + 1,) and G.ring is False and P.ring is False
    assert [i + m + 1 for i in G.vehicles] == list(P.vehicles) and P.kind == "platoon"
    assert G.vehicle_coefficients == P.vehicle_coefficients == tuple(coefs)
    assert G.conserved is None is P.conserved and G.conserved_mode is None is P.conserved_mode
    for i in G.vehicles:
        assert G.block(i) == P.block(i + m + 1)
    # m, n as the [system] tables say them: a platoon's n counts the first CAV
    assert (G.m, G.n) == (m, n) and (P.m, P.n) == (m, n + 1)


@pytest.mark.parametrize(("cavs", "ring", "m", "n"),
                         [((3, 6), False, 2, 6), ((8,), True, 7, 1), ((), True, 8, 0)])
def test_platoon_layout_attributes_match_the_system_table(cavs, ring, m, n):
    """``kind``, ``m``, ``n`` of the model are those of the problem file's ``[system]``."""
    table = {"system": {"kind": "ring" if ring else "platoon", "size": 8, "cavs": list(cavs)}}
    system = system_from(table)
    model = system.linear_model(warn=False)
    assert (model.kind, model.m, model.n) == (system.kind, system.m, system.n) == (
        "ring" if ring else "platoon", m, n)
    assert model.vehicles == tuple(range(1, 9)) and model.vehicle_coefficients == model.coefficients


def test_two_cav_rows_are_eq_9_and_hdv_rows_eq_8_at_their_own_equilibrium():
    hdv = tuple(OVM(alpha=a, beta=b, s_go=g) for a, b, g in zip(*DEEPLCC.values(), strict=True))
    M = platoon_model(Platoon(hdv, (3, 6), 15.0))
    assert M.B.shape == (16, 2) and M.input_names == ("u_3", "u_6")
    assert M.B[M.index("v_3"), 0] == 1 and M.B[M.index("v_6"), 1] == 1 and M.B.sum() == 2
    for i in (1, 2, 4, 5, 7, 8):
        h = hdv[i - 1]
        # OVM eq. (8) by hand at the vehicle's own s*: a1 = alpha V'(s*), a2 = alpha + beta
        s = h.equilibrium_spacing(15.0)
        w = h.s_go - h.s_st
        dV = 0.5 * h.v_max * np.pi / w * np.sin(np.pi * (s - h.s_st) / w)
        row = M.A[M.index(f"v_{i}")]
        assert row[M.index(f"s_{i}")] == pytest.approx(h.alpha * dV, rel=1e-12)
        assert row[M.index(f"v_{i}")] == pytest.approx(-(h.alpha + h.beta), rel=1e-12)
        if i > 1:
            assert row[M.index(f"v_{i - 1}")] == pytest.approx(h.beta, rel=1e-12)
        assert M.A[M.index(f"s_{i}"), M.index(f"v_{i}")] == -1
    for i in (3, 6):
        assert not M.A[M.index(f"v_{i}")].any()  # dv_i = u_i
        assert M.A[M.index(f"s_{i}"), M.index(f"v_{i - 1}")] == 1
    assert M.H[M.index("s_1"), 0] == 1 and M.H[M.index("v_1"), 0] == pytest.approx(0.60)
    # each HDV at its own equilibrium: s_go 38 -> larger spacing than s_go 31
    eq = M.platoon.equilibrium_spacings
    assert eq[0] == pytest.approx(5 + 33 / 2) and eq[1] == pytest.approx(5 + 26 / 2)


def test_ring_conserves_total_spacing_and_the_invariant_basis_is_exact():
    M = platoon_model(Platoon((OVM(),) * 20, (20,), 15.0, ring=True))
    c = M.conserved
    assert np.abs(c @ M.A).max() == 0 and np.abs(c @ M.B).max() == 0
    assert M.A[M.index("s_1"), M.index("v_20")] == 1 and not M.H.any()
    ev = np.linalg.eigvals(M.A)
    assert np.min(np.abs(ev)) < 1e-12  # the conserved mode
    V = M.invariant_basis()
    assert V.shape == (40, 39)
    assert np.abs(V.T @ V - np.eye(39)).max() < 1e-15 and np.abs(c @ V).max() < 1e-15
    Ar = V.T @ M.A @ V
    assert np.abs(M.A @ V - V @ Ar).max() < 1e-14
    assert M.conserved_mode.startswith("total spacing")
    # no controller, a random start: x(t) = expm(A t) x0 keeps the total spacing to round-off
    x0 = np.random.default_rng(0).normal(size=40)
    xt = sla.expm(M.A * 30.0) @ x0
    assert abs(xt[0::2].sum() - x0[0::2].sum()) < 1e-11 * np.abs(x0).sum()


def test_ring_circumference_sets_the_equilibrium_velocity():
    # Sugiyama: 22 OVM cars on 230 m; by hand v = v_max / 2 (1 - cos(pi (s - s_st) / (s_go - s_st)))
    v = ring_velocity((OVM(),) * 22, 230.0)
    s = 230.0 / 22
    assert v == pytest.approx(15 * (1 - np.cos(np.pi * (s - 5) / 30)), rel=1e-10)
    P = Platoon((OVM(),) * 22, (), None, ring=True, circumference=230.0)
    assert P.v_star == pytest.approx(v) and P.length == 230.0
    idm = Platoon((IDM(),) * 5, (), None, ring=True, circumference=150.0)
    assert idm.equilibrium_spacings.sum() == pytest.approx(150.0, rel=1e-9)


def test_discretisation_is_the_exact_zoh_and_statespace_has_every_input():
    hdv = tuple(OVM(alpha=a) for a in DEEPLCC["alpha"])
    M = platoon_model(Platoon(hdv, (3, 6), 15.0))
    Ad, Bd, Hd = M.discretize(0.1)
    assert np.allclose(Ad, sla.expm(M.A * 0.1), rtol=0, atol=1e-14)
    # ZOH input: integral_0^T expm(A t) dt B, by a fine composite Simpson rule
    ts = np.linspace(0, 0.1, 201)
    Es = np.array([sla.expm(M.A * t) for t in ts])
    w = np.ones(201)
    w[1:-1:2] = 4
    w[2:-1:2] = 2
    integral = np.tensordot(w, Es, axes=1) * (0.1 / 600)
    assert np.allclose(Bd, integral @ M.B, atol=1e-12)
    assert np.allclose(Hd, integral @ M.H, atol=1e-12)
    ss = M.to_statespace()
    assert ss.ninputs == 3 and ss.noutputs == 16
    ring = platoon_model(Platoon((OVM(),) * 6, (6,), 15.0, ring=True)).to_statespace(["v_1"])
    assert ring.ninputs == 1 and ring.noutputs == 1


@pytest.mark.parametrize(
    ("system", "field"),
    [
        ({"kind": "platoon", "size": 8, "cavs": [9]}, "system.cavs"),
        ({"kind": "platoon", "size": 8, "cavs": [0]}, "system.cavs"),
        ({"kind": "platoon", "size": 8, "cavs": [3, 3]}, "system.cavs"),
        ({"kind": "platoon", "size": 8, "cavs": "3"}, "system.cavs"),
        ({"kind": "platoon", "cavs": [3]}, "system.size"),
        ({"kind": "ring", "size": 10, "circumference": 40.0}, "system.circumference"),
        ({"kind": "ring", "size": 10, "circumference": 200.0, "v_star": 15.0},
         "system.circumference"),
        ({"kind": "platoon", "size": 4, "circumference": 200.0}, "system.circumference"),
        ({"kind": "platoon", "size": 4, "m": 1}, "system.m"),
        ({"kind": "lcc", "m": 1, "n": 1, "cavs": [1]}, "system.cavs"),
        ({"kind": "platoon", "size": 2, "hdv_values": {"alpha": [0.6]}}, "system.hdv_values"),
        ({"kind": "platoon", "size": 2, "hdv_values": {"alpha": [0.6, -1.0]}}, "system.hdv_values"),
        ({"kind": "platoon", "size": 2, "hdv_values": {"v0": [1.0, 2.0]}}, "system.hdv_values"),
    ],
)
def test_bad_platoon_input_names_the_field(system, field):
    with pytest.raises(ConfigError) as err:
        system_from({"system": system})
    assert err.value.field.startswith(field), err.value


def test_added_semantics_with_zero_gain_is_the_all_hdv_platoon():
    """A CAV that keeps its HDV law and adds nothing is an HDV: the closed loop equals the
    all-HDV platoon's model, entry for entry (open and ring)."""
    from lcc_synth.models.feedback import Gains

    hdv = tuple(OVM(alpha=a, beta=b, s_go=g) for a, b, g in zip(*DEEPLCC.values(), strict=True))
    for ring in (False, True):
        M = platoon_model(Platoon(hdv, (1, 3, 6), 15.0, ring=ring))
        H0 = platoon_model(Platoon(hdv, (), 15.0, ring=ring))
        g = Gains.zero(M, "added")
        A, Hc = g.closed_loop(M)
        assert np.allclose(A, H0.A, rtol=0, atol=1e-15) and np.allclose(Hc, H0.H, atol=1e-15)
        back = Gains.from_table(Gains.on(M, np.eye(3, 16)).as_table(), M)
        assert np.array_equal(back.K, np.eye(3, 16))
    with pytest.raises(ConfigError, match="u_4"):
        Gains.from_table({"u_4": {"s_1": 1.0}}, M)


def _ring_roots(c, N: int) -> np.ndarray:
    """Every eigenvalue of a homogeneous all-HDV ring, independently of the state space: the
    travelling-wave modes x_i ~ z^i of eq. (8) give, for each k, the quadratic
    lambda^2 + a2 lambda + a1 = (a3 lambda + a1) w_k with w_k = exp(2 pi i k / N)."""
    roots = []
    for k in range(N):
        w = np.exp(2j * np.pi * k / N)
        roots.extend(np.roots([1.0, c.alpha2 - c.alpha3 * w, c.alpha1 * (1 - w)]))
    return np.array(roots)


@pytest.mark.parametrize(
    ("hdv", "N", "circumference"),
    [
        (OVM(), 20, None),  # the synthesis files' ring at v* = 15
        # Sugiyama: 22 IDM cars (v0 30, T 1, s0 2, a 1, b 1.5, delta 4) of length 5 m on 230 m:
        # in gap coordinates, a ring of 230 - 22 * 5 = 120 m of point vehicles
        (IDM(v0=30.0, T=1.0, s0=2.0, a=1.0, b=1.5, delta=4.0), 22, 230.0 - 22 * 5.0),
    ],
)
def test_all_hdv_ring_is_string_unstable_and_its_wave_grows(hdv, N, circumference):
    """The known condition (the paper's HDV string stability, a2^2 - a3^2 - 2 a1 >= 0) fails,
    and the ring's state space has a growing mode: the same eigenvalues as the travelling-wave
    polynomial, apart from the conserved mode at 0."""
    v_star = None if circumference else 15.0
    P = Platoon((hdv,) * N, (), v_star, ring=True, circumference=circumference)
    M = platoon_model(P)
    c = M.coefficients[0]
    assert c.alpha2**2 - c.alpha3**2 - 2 * c.alpha1 < 0
    ev = np.linalg.eigvals(M.A)
    ref = _ring_roots(c, N)
    assert np.max(ev.real) > 1e-3 and np.max(ev.real) == pytest.approx(np.max(ref.real), rel=1e-8)
    # every eigenvalue is a root of the wave polynomial (two roots per k, 2N states)
    d = np.abs(ev[:, None] - ref[None, :]).min(axis=1)
    assert d.max() < 1e-8 * max(1.0, np.abs(ref).max())
