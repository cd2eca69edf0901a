"""Head-to-tail transfer function and string stability (Section IV, Appendix A, Table I)."""

from __future__ import annotations

import numpy as np
import pytest

from lcc_synth.analysis.string_stability import string_stability
from lcc_synth.analysis.transfer import (
    closed_form_gains,
    closed_loop_eigenvalues,
    gamma_closed_form,
    gamma_polynomials,
    gamma_state_space,
    hinf_norm_hamiltonian,
    level_crossings,
    transfer_response,
)
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains, closed_loop, input_feedback
from lcc_synth.models.hdv import OVM, LinearCoefficients
from lcc_synth.models.linear import build_model, fd_lcc, general_lcc

PAPER = OVM().linear_coefficients(15.0)  # alpha=0.6, beta=0.9, v_max=30, s_st=5, s_go=35
TABLE_I = {
    "hdv_only": {},
    "case_a": {"s_-2": 1, "v_-2": -1},
    "case_b": {"s_-2": 1, "v_-2": -1, "s_-1": 1, "v_-1": -1},
    "case_c": {"s_-2": 1, "v_-2": -1, "s_-1": 1, "v_-1": -1, "s_1": -1, "v_1": -1},
    "case_d": {
        "s_-2": 1, "v_-2": -1, "s_-1": 1, "v_-1": -1, "s_1": -1, "v_1": -1, "s_2": -1, "v_2": -1,
    },
}
OMEGA = np.logspace(-3, 1.5, 300)


def random_coefs(rng) -> LinearCoefficients:
    """alpha1 > 0, alpha2 > alpha3 > 0, eq. (13) away from zero."""
    while True:
        a3 = rng.uniform(0.1, 2.0)
        a2 = a3 + rng.uniform(0.1, 2.0)
        a1 = rng.uniform(0.05, 3.0)
        c = LinearCoefficients(a1, a2, a3)
        if abs(c.controllability_margin) > 0.05:
            return c


def random_model(rng, kind="lcc"):
    m = 0 if kind == "cf_lcc" else int(rng.integers(0 if kind == "lcc" else 1, 4))
    n = 0 if kind == "ccc" else int(rng.integers(1, 4))
    coefs = [random_coefs(rng) for _ in range(m + n)]
    return build_model(kind, m, n, coefs, cav=random_coefs(rng))


def random_gains(rng, model, scale=2.0) -> Gains:
    names = [s for s in model.state_names]
    pick = rng.choice(names, size=int(rng.integers(1, len(names) + 1)), replace=False)
    return Gains.named({str(p): float(rng.uniform(-scale, scale)) for p in pick})


@pytest.mark.parametrize("kind", ["lcc", "cf_lcc", "ccc"])
def test_closed_form_matches_state_space_random(kind):
    rng = np.random.default_rng({"lcc": 1, "cf_lcc": 2, "ccc": 3}[kind])
    for _ in range(25):
        model = random_model(rng, kind)
        gains = random_gains(rng, model)
        K, kh = input_feedback(model, gains)
        mu, k, khx = closed_form_gains(model, K, kh)
        ss = gamma_state_space(model, K, kh, OMEGA)
        cf = gamma_closed_form(model.coefficients, mu, k, model.m, model.n, 1j * OMEGA, khx)
        num, den = gamma_polynomials(model.coefficients, mu, k, model.m, model.n, khx)
        poly = np.polyval(num, 1j * OMEGA) / np.polyval(den, 1j * OMEGA)
        scale = np.maximum(np.abs(cf), 1e-300)
        assert np.max(np.abs(ss - cf) / scale) < 1e-9
        assert np.max(np.abs(poly - cf) / scale) < 1e-9


def test_added_gains_are_the_papers_mu_k():
    """For 'added' semantics, the closed-form parameters are exactly the table's mu_i, k_i."""
    model = general_lcc(2, 2, PAPER)
    K, kh = input_feedback(model, Gains.named(TABLE_I["case_d"]))
    mu, k, khx = closed_form_gains(model, K, kh)
    assert mu == {-2: 1, -1: 1, 0: 0, 1: -1, 2: -1}
    assert k == {-2: -1, -1: -1, 0: 0, 1: -1, 2: -1}
    assert khx == 0.0


def test_denominator_is_closed_loop_characteristic_polynomial():
    rng = np.random.default_rng(7)
    for _ in range(20):
        model = random_model(rng)
        gains = random_gains(rng, model)
        K, kh = input_feedback(model, gains)
        mu, k, khx = closed_form_gains(model, K, kh)
        _, den = gamma_polynomials(model.coefficients, mu, k, model.m, model.n, khx)
        Acl, _ = closed_loop(model, K, kh)
        assert len(den) == model.nx + 1 and den[0] == 1.0
        for s in rng.normal(size=4) + 1j * rng.normal(size=4):
            det = np.linalg.det(s * np.eye(model.nx) - Acl)
            assert abs(np.polyval(den, s) - det) <= 1e-9 * max(1.0, abs(det))


def test_dc_gain_is_one_for_stabilising_gains():
    rng = np.random.default_rng(11)
    checked = 0
    while checked < 30:
        model = random_model(rng)
        K, kh = input_feedback(model, random_gains(rng, model))
        rep = string_stability(model, K, kh)
        if not rep.plant_stable:
            continue
        checked += 1
        assert rep.gamma_dc == pytest.approx(1.0, abs=1e-9)
        mu, k, khx = closed_form_gains(model, K, kh)
        g0 = gamma_closed_form(model.coefficients, mu, k, model.m, model.n, 0.0, khx)
        assert abs(g0 - 1.0) < 1e-12
        assert rep.gamma_peak >= 1.0 - 1e-12


@pytest.mark.parametrize("m,n", [(2, 2), (0, 3), (5, 15)])
def test_hdv_only_is_platoon_of_hdvs(m, n):
    """Special case 1: Gamma_1 = (phi/gamma)^(n+m+1)."""
    model = general_lcc(m, n, PAPER)
    K, kh = input_feedback(model, Gains.named({}))
    phi = PAPER.alpha3 * 1j * OMEGA + PAPER.alpha1
    gam = (1j * OMEGA) ** 2 + PAPER.alpha2 * 1j * OMEGA + PAPER.alpha1
    expected = (phi / gam) ** (n + m + 1)
    ss = gamma_state_space(model, K, kh, OMEGA)
    assert np.max(np.abs(ss - expected) / np.abs(expected)) < 1e-8
    rep = string_stability(model, K, kh)
    # every HDV is string unstable at these parameters: 2 alpha1 > alpha2^2 - alpha3^2
    assert 2 * PAPER.alpha1 > PAPER.alpha2**2 - PAPER.alpha3**2
    assert rep.plant_stable and not rep.string_stable
    assert rep.max_real_eig == pytest.approx(-0.75, abs=1e-9)  # exact despite Jordan chains
    # one HDV's peak |phi/gamma| (unimodal on [0.1, 1]) raised to the platoon length
    from scipy.optimize import minimize_scalar

    def one(w):
        return -abs((PAPER.alpha3 * 1j * w + PAPER.alpha1) / ((1j * w) ** 2
                    + PAPER.alpha2 * 1j * w + PAPER.alpha1))

    best = minimize_scalar(one, bounds=(0.1, 1.0), method="bounded", options={"xatol": 1e-10})
    assert rep.gamma_peak == pytest.approx((-best.fun) ** (n + m + 1), rel=1e-9)
    assert rep.gamma_peak_omega == pytest.approx(best.x, rel=1e-5)


def test_special_cases_ahead_and_behind():
    """Eqs. (26) and (27): looking ahead only / behind only."""
    c = PAPER
    s = 1j * OMEGA
    phi, gam = c.alpha3 * s + c.alpha1, s**2 + c.alpha2 * s + c.alpha1
    T = phi / gam
    model = general_lcc(2, 2, c)

    def H(mu, k):
        return mu * (gam / phi - 1) + k * s

    g_ahead = {"s_-2": 0.7, "v_-2": -0.4, "s_-1": -0.3, "v_-1": 0.5}
    K, kh = input_feedback(model, Gains.named(g_ahead))
    gamma2 = (phi + H(0.7, -0.4) * T ** (-1) + H(-0.3, 0.5) * T**0) / gam * T**4
    assert np.allclose(gamma_state_space(model, K, kh, OMEGA), gamma2, rtol=1e-9, atol=0)
    g_behind = {"s_1": -1.0, "v_1": -0.5, "s_2": 0.4, "v_2": -0.8}
    K, kh = input_feedback(model, Gains.named(g_behind))
    gamma3 = phi / (gam - H(-1.0, -0.5) * T - H(0.4, -0.8) * T**2) * T**4
    assert np.allclose(gamma_state_space(model, K, kh, OMEGA), gamma3, rtol=1e-9, atol=0)


def test_python_control_agrees():
    import control as ct

    model = general_lcc(2, 2, PAPER)
    gains = Gains.named(TABLE_I["case_c"])
    K, kh = input_feedback(model, gains)
    plant = model.to_statespace()
    law = ct.ss(
        [], [], [], np.concatenate([K, [kh]]).reshape(1, -1),
        inputs=[*model.state_names, "v_h"], outputs=["u"], name="law",
    )
    loop = ct.interconnect([plant, law], inplist=["v_h"], outlist=["v_2"])
    w = np.logspace(-2, 1, 50)
    ours = gamma_state_space(model, K, kh, w)
    theirs = np.array([complex(loop(1j * x)) for x in w])
    assert np.allclose(ours, theirs, rtol=1e-9, atol=0)
    tf = ct.ss2tf(loop)
    mu, k, _ = closed_form_gains(model, K, kh)
    num, den = gamma_polynomials(PAPER, mu, k, 2, 2)
    theirs_tf = np.array([complex(tf(1j * x)) for x in w])
    ours_poly = np.polyval(num, 1j * w) / np.polyval(den, 1j * w)
    assert np.allclose(ours_poly, theirs_tf, rtol=1e-7, atol=0)


def test_table_i_frequency_response():
    """Fig. 9: HDV-only string unstable; |Gamma| drops from HDV-only to case A .. case D at low
    frequencies; cases C and D (looking behind) string stable."""
    model = general_lcc(2, 2, PAPER)
    w = np.logspace(-3, 0, 200)
    mags, reps = [], {}
    for name, g in TABLE_I.items():
        K, kh = input_feedback(model, Gains.named(g))
        mags.append(np.abs(gamma_state_space(model, K, kh, w)))
        reps[name] = string_stability(model, K, kh)
    mags = np.array(mags)
    assert np.all(np.diff(mags, axis=0) < 0)  # strictly ordered at every w in (0, 1]
    assert all(r.plant_stable for r in reps.values())
    assert not reps["hdv_only"].string_stable and reps["hdv_only"].gamma_peak > 1.1
    assert not reps["case_a"].string_stable and not reps["case_b"].string_stable
    assert reps["case_c"].string_stable and reps["case_d"].string_stable
    peaks = [reps[n].gamma_peak for n in TABLE_I]
    assert peaks[0] > peaks[1] > peaks[2] > 1.0
    assert reps["case_c"].gamma_peak_omega == 0.0 and reps["case_c"].gamma_peak == 1.0


@pytest.mark.parametrize("kind", ["paper", "lcc", "cf_lcc", "ccc"])
def test_grid_search_agrees_with_hamiltonian(kind):
    rng = np.random.default_rng(5)
    model = general_lcc(2, 2, PAPER) if kind == "paper" else random_model(rng, kind)
    done = 0
    while done < (20 if kind == "paper" else 8):
        K, kh = input_feedback(model, random_gains(rng, model, 3.0))
        grid = string_stability(model, K, kh)
        if not grid.plant_stable:
            assert not grid.string_stable
            continue
        done += 1
        ham = string_stability(model, K, kh, method="hamiltonian")
        assert grid.string_stable == ham.string_stable
        assert grid.gamma_peak == pytest.approx(ham.gamma_peak, rel=1e-7)
        Acl, Hcl = closed_loop(model, K, kh)
        hinf, _ = hinf_norm_hamiltonian(Acl, Hcl, np.eye(model.nx)[-1])
        assert max(1.0, grid.gamma_peak) == pytest.approx(max(1.0, hinf), rel=1e-7)


def test_global_search_finds_second_peak_a_local_search_misses():
    """Two resonances: 0.99 at 0.62 rad/s and 1.04 at 1.32 rad/s. A local maximiser started
    next to the first concludes 'string stable'; the global search must not."""
    from scipy.optimize import minimize

    model = general_lcc(2, 2, PAPER)
    K, kh = input_feedback(model, Gains.named({"v_-1": 1.9, "v_-2": 1.5, "v_2": -2.7}))
    rep = string_stability(model, K, kh)
    assert rep.plant_stable and not rep.string_stable
    assert rep.gamma_peak == pytest.approx(1.0392157, abs=1e-6)
    assert 1.2 < rep.gamma_peak_omega < 1.4

    def neg(x):
        return -np.abs(gamma_state_space(model, K, kh, np.exp(x)))[0]

    local = minimize(neg, x0=np.log(0.5), method="Nelder-Mead")
    assert -local.fun < 1.0  # the local search sees a peak below 1 ...
    assert abs(np.exp(local.x[0]) - 0.62) < 0.05
    w = np.linspace(0.3, 2.0, 4000)  # ... and a brute-force sweep confirms the second peak
    assert np.abs(gamma_state_space(model, K, kh, w)).max() == pytest.approx(
        rep.gamma_peak, rel=1e-6
    )
    Acl, Hcl = closed_loop(model, K, kh)
    crossings = level_crossings(Acl, Hcl, np.eye(model.nx)[-1], 1.0)
    assert np.any((crossings > 1.0) & (crossings < 1.6))


def test_low_frequency_curvature_decides_near_zero():
    """|Gamma|^2 = 1 + c w^2 + ...: the report's c matches a finite difference."""
    model = general_lcc(2, 2, PAPER)
    for g in TABLE_I.values():
        K, kh = input_feedback(model, Gains.named(g))
        rep = string_stability(model, K, kh)
        w = 1e-3
        fd = (np.abs(gamma_state_space(model, K, kh, [w]))[0] ** 2 - 1.0) / w**2
        assert fd == pytest.approx(rep.low_freq_curvature, rel=1e-4)
        assert (rep.low_freq_curvature > 0) == (g in (TABLE_I["hdv_only"], TABLE_I["case_a"],
                                                      TABLE_I["case_b"]))


def test_unstable_plant_is_not_string_stable():
    model = general_lcc(2, 2, PAPER)
    K, kh = input_feedback(model, Gains.named({"s_1": 5.0, "v_1": 5.0}))
    rep = string_stability(model, K, kh)
    assert not rep.plant_stable and not rep.string_stable and rep.max_real_eig > 0
    assert rep.as_dict()["plant_stable"] is False


def test_eigenvalues_by_blocks_are_exact_for_long_strings():
    model = general_lcc(5, 15, PAPER)
    K, kh = input_feedback(model, Gains.named({"s_-3": 1.0, "v_-1": -0.5}))
    Acl, _ = closed_loop(model, K, kh)
    ev = closed_loop_eigenvalues(Acl)
    assert ev.size == model.nx
    assert np.allclose(ev.real.max(), -0.75, atol=1e-12)
    ev_full = np.linalg.eigvals(Acl)  # the scattered eigenvalues the block method avoids
    assert np.abs(ev_full.real.max() + 0.75) > 1e-6


def test_transfer_response_matches_dense_solve():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(12, 12))
    b, c = rng.normal(size=12), rng.normal(size=12)
    s = 1j * np.logspace(-2, 2, 37) + 0.1
    ref = np.array([c @ np.linalg.solve(z * np.eye(12) - A, b) for z in s])
    assert np.allclose(transfer_response(A, b, c, s), ref, rtol=1e-10, atol=1e-12)


def test_fd_lcc_has_no_head_to_tail_transfer():
    model = fd_lcc(3, PAPER)
    with pytest.raises(ConfigError, match="head"):
        string_stability(model, np.zeros(model.nx))


def test_bad_inputs():
    model = general_lcc(2, 2, PAPER)
    with pytest.raises(ConfigError, match="entries"):
        string_stability(model, np.zeros(3))
    with pytest.raises(ConfigError, match="method"):
        string_stability(model, np.zeros(model.nx), method="local")
    with pytest.raises(ConfigError, match="vehicle index"):
        gamma_closed_form(PAPER, {5: 1.0}, {}, 2, 2, 1j)
