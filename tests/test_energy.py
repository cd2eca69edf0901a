"""Control energy (Section III-B): Gramian against quadrature and the Lyapunov equation, Lemma 2
against simulation, the trends of Fig. 5, and the refusal of numerically singular Gramians."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
from gramian_reference import quad_gramian
from scipy.integrate import quad_vec, solve_ivp

from lcc_synth.analysis.energy import (
    COND_LIMIT,
    NumericallySingularError,
    energy_report,
    gramian,
    min_energy,
    min_energy_input,
)
from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import OVM, LinearCoefficients
from lcc_synth.models.linear import cf_lcc, fd_lcc, general_lcc

PAPER = OVM(alpha=0.6, beta=0.9, v_max=30.0, s_st=5.0, s_go=35.0).linear_coefficients(15.0)
HET = [LinearCoefficients(0.8, 1.4, 0.7), LinearCoefficients(1.1, 1.9, 0.5)]


@pytest.mark.parametrize(
    ("model", "t"),
    [(fd_lcc(2, PAPER), 10.0), (fd_lcc(3, PAPER), 30.0), (cf_lcc(2, HET), 7.5)],
    ids=["fd2_t10", "fd3_t30", "cf_het_t7.5"],
)
def test_gramian_matches_quadrature(model, t):
    W = gramian(model.A, model.B, t)
    Wq = quad_gramian(model.A, model.B, t)
    assert np.linalg.norm(W - Wq) <= 1e-10 * np.linalg.norm(Wq)
    lam, lam_q = np.linalg.eigvalsh(W), np.linalg.eigvalsh(Wq)
    np.testing.assert_allclose(lam[0], lam_q[0], rtol=1e-6)
    np.testing.assert_allclose(W, W.T, rtol=0, atol=0)


def test_gramian_tends_to_lyapunov_solution_for_a_stable_matrix():
    """CF-LCC's A_c is Hurwitz (P1 blocks): W(t -> inf) solves A W + W A^T + B B^T = 0."""
    model = cf_lcc(3, PAPER)
    assert np.max(np.linalg.eigvals(model.A).real) < 0
    W_inf = sla.solve_continuous_lyapunov(model.A, -model.B @ model.B.T)
    W = gramian(model.A, model.B, 400.0)
    np.testing.assert_allclose(W, W_inf, rtol=1e-9, atol=1e-12 * np.abs(W_inf).max())
    # A short horizon is far from it (the test could fail).
    assert np.linalg.norm(gramian(model.A, model.B, 2.0) - W_inf) > 0.1 * np.linalg.norm(W_inf)


def test_min_energy_input_steers_to_the_target_with_the_lemma2_energy():
    model = fd_lcc(2, PAPER)
    t = 10.0
    rng = np.random.default_rng(3)
    x0 = rng.normal(size=model.nx)
    xt = rng.normal(size=model.nx)
    u = min_energy_input(model, t, x0, xt)

    def rhs(tau, x):
        return model.A @ x + model.B[:, 0] * u(tau)[0]

    sol = solve_ivp(rhs, (0.0, t), x0, method="DOP853", rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(sol.y[:, -1], xt, atol=1e-6 * max(1.0, np.abs(xt).max()))
    energy, _ = quad_vec(lambda tau: float(u(tau)[0] ** 2), 0.0, t, epsrel=1e-10)
    np.testing.assert_allclose(energy, min_energy(model, t, x0, xt), rtol=1e-7)


def test_energy_identities_of_lemma2():
    """From the origin: sum of the energies to the unit targets = tr(W^-1); the hardest unit
    target (eigenvector of lambda_min) costs 1 / lambda_min."""
    model = fd_lcc(3, PAPER)
    t = 20.0
    rep = energy_report(model, t)
    zero = np.zeros(model.nx)
    total = sum(min_energy(model, t, zero, e) for e in np.eye(model.nx))
    np.testing.assert_allclose(total, rep.trace_inv, rtol=1e-8)
    lam, V = np.linalg.eigh(gramian(model.A, model.B, t))
    np.testing.assert_allclose(min_energy(model, t, zero, V[:, 0]), 1.0 / rep.lambda_min, rtol=1e-6)
    np.testing.assert_allclose(rep.condition, lam[-1] / lam[0], rtol=1e-12)


def test_fig5_trends_energy_grows_with_n_and_falls_with_t():
    """Paper's parameters (alpha 0.6, beta 0.9, v_max 30, s_st 5, s_go 35, v* 15)."""
    lam = np.empty((3, 4))
    tr = np.empty((3, 4))
    for a, t in enumerate((10.0, 20.0, 30.0)):
        for b, n in enumerate(range(1, 5)):
            rep = energy_report(fd_lcc(n, PAPER), t)
            lam[a, b], tr[a, b] = rep.lambda_min, rep.trace_inv
    assert np.all(np.diff(lam, axis=1) < 0) and np.all(np.diff(tr, axis=1) > 0)
    assert np.all(np.diff(lam, axis=0) > 0) and np.all(np.diff(tr, axis=0) < 0)
    # Exponential in n: every extra HDV multiplies tr(W^-1) by more than 50.
    assert np.all(tr[:, 1:] / tr[:, :-1] > 50)


def test_numerically_singular_gramian_is_refused():
    with pytest.raises(NumericallySingularError, match=r"n = 6 \(14 states\)") as err:
        energy_report(fd_lcc(6, PAPER), 10.0)
    assert err.value.condition > COND_LIMIT and err.value.n == 6 and err.value.t == 10.0
    with pytest.raises(NumericallySingularError):
        min_energy(fd_lcc(6, PAPER), 10.0, np.zeros(14), np.ones(14))
    # An uncontrollable model (vehicles ahead, Theorem 2) has a singular Gramian.
    with pytest.raises(NumericallySingularError):
        energy_report(general_lcc(2, 2, PAPER), 10.0)
    # Just inside the limit it is accepted and has a positive lambda_min.
    rep = energy_report(fd_lcc(5, PAPER), 20.0)
    assert 0 < rep.lambda_min and rep.condition < COND_LIMIT


def test_bad_input_is_a_config_error():
    model = fd_lcc(2, PAPER)
    for t in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ConfigError, match="^t:"):
            gramian(model.A, model.B, t)
    with pytest.raises(ConfigError, match="^x0:"):
        min_energy(model, 10.0, np.zeros(3), np.zeros(model.nx))
    with pytest.raises(ConfigError, match="^x_target:"):
        min_energy(model, 10.0, np.zeros(model.nx), [np.nan] * model.nx)


def test_report_as_dict():
    d = energy_report(fd_lcc(2, PAPER), 10.0).as_dict()
    assert d["n"] == 2 and d["n_states"] == 6 and d["t"] == 10.0
    assert d["lambda_min"] > 0 and d["condition_limit"] == COND_LIMIT


def test_energy_vs_size_stops_at_the_first_singular_size(tmp_path):
    from lcc_synth.analysis.energy import energy_vs_size
    from lcc_synth.figures import plot_control_energy

    sweep = energy_vs_size(PAPER, horizons=(10.0, 30.0), n_max=12)
    assert [r.n for r in sweep.reports[10.0]] == [1, 2, 3, 4]
    assert sweep.singular_n(10.0) == 5 and sweep.singular_n(30.0) == 6
    assert sweep.reports[30.0][0].lambda_min == energy_report(fd_lcc(1, PAPER), 30.0).lambda_min
    short = energy_vs_size(PAPER, horizons=(30.0,), n_max=3)
    assert short.singular_n(30.0) is None and len(short.reports[30.0]) == 3
    assert sweep.as_dict()["10"]["singular_n"] == 5
    with pytest.raises(ConfigError, match="kind"):
        energy_vs_size(PAPER, kind="lcc")
    out = plot_control_energy(sweep, tmp_path / "fig5.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
