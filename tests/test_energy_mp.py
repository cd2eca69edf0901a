"""The multiprecision Gramian (Fig. 5 beyond float64): a closed form, the float64 values where
they work, an independent algorithm at high precision (mpmath's own matrix exponential of Van
Loan's block matrix over the whole horizon) and the digits the reports state."""

from __future__ import annotations

import mpmath as mp
import numpy as np
import pytest

from lcc_synth.analysis.energy import (
    NumericallySingularError,
    energy_report,
    energy_reports_mp,
    energy_vs_size,
    gramians_mp,
)
from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import fd_lcc, general_lcc

PAPER = OVM(alpha=0.6, beta=0.9, v_max=30.0, s_st=5.0, s_go=35.0).linear_coefficients(15.0)
EPS = float(np.finfo(float).eps)


def _rel(a, b) -> float:
    return abs(a - b) / abs(b)


def test_double_integrator_gramian_matches_its_closed_form_to_55_digits():
    """x'' = u: W(t) = [[t^3/3, t^2/2], [t^2/2, t]]; three horizons (the later ones are sums
    over shared steps)."""
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    B = np.array([[0.0], [1.0]])
    ts = (1.5, 3.0, 4.5)
    for t, W in zip(ts, gramians_mp(A, B, ts, dps=60), strict=True):
        with mp.workdps(60):
            tt = mp.mpf(t)
            exact = mp.matrix([[tt**3 / 3, tt**2 / 2], [tt**2 / 2, tt]])
            assert mp.mnorm(W - exact, 1) <= mp.mpf(10) ** -55 * mp.mnorm(exact, 1)


def test_multiprecision_agrees_with_float64_within_float64s_own_error_bound():
    """n = 1..4: |mp - float64| / value <= 100 eps cond(W) (Weyl's bound on the float64 value)."""
    dbl = energy_vs_size(PAPER, horizons=(10.0, 20.0, 30.0), n_max=4)
    mpw = energy_vs_size(PAPER, horizons=(10.0, 20.0, 30.0), n_max=4, method="mp")
    for t in (10.0, 20.0, 30.0):
        for d, m in zip(dbl.reports[t], mpw.reports[t], strict=True):
            assert (d.n, d.t, m.method, d.method) == (m.n, m.t, "mp", "double")
            bound = 100 * EPS * d.condition
            assert _rel(d.lambda_min, m.lambda_min) <= bound
            assert _rel(d.trace_inv, m.trace_inv) <= bound
            np.testing.assert_allclose(d.lambda_max, m.lambda_max, rtol=1e-12)
            np.testing.assert_allclose(d.condition, m.condition, rtol=bound)
    # n = 1 is well conditioned: the two agree to 11 digits and more.
    assert _rel(dbl.reports[10.0][0].lambda_min, mpw.reports[10.0][0].lambda_min) < 1e-11


def _van_loan_reference(model, t: float, dps: int):
    """W(t) from mpmath's expm of [[-A, B B^T], [0, A^T]] t in one piece (a different algorithm:
    no series on a short step, no doubling; its cancellation is paid for by the digits)."""
    with mp.workdps(dps):
        nx = model.nx
        A = mp.matrix(model.A.tolist())
        B = mp.matrix(model.B.reshape(nx, -1).tolist())
        M = mp.zeros(2 * nx, 2 * nx)
        BBt = B * B.T
        for i in range(nx):
            for j in range(nx):
                M[i, j] = -A[i, j]
                M[i, nx + j] = BBt[i, j]
                M[nx + i, nx + j] = A[j, i]
        E = mp.expm(M * t)
        F12 = E[0:nx, nx : 2 * nx]
        F22 = E[nx : 2 * nx, nx : 2 * nx]
        W = F22.T * F12
        lam = sorted(mp.eigsy((W + W.T) / 2, eigvals_only=True))
        return lam[0], mp.fsum(1 / x for x in lam)


def test_multiprecision_matches_an_independent_method_where_float64_is_singular():
    """n = 7, t = 10 s: cond(W) 8.8e23, far beyond float64 (refused there)."""
    model = fd_lcc(7, PAPER)
    with pytest.raises(NumericallySingularError):
        energy_report(model, 10.0)
    rep = energy_reports_mp(model, (10.0,), digits=12)[0]
    lam_ref, tr_ref = _van_loan_reference(model, 10.0, dps=90)
    assert rep.condition > 1e23 and rep.digits >= 12
    assert _rel(rep.lambda_min, float(lam_ref)) < 1e-12
    assert _rel(rep.trace_inv, float(tr_ref)) < 1e-12


def test_stated_digits_are_achieved_at_a_fixed_precision():
    """At 50 working digits lambda_min keeps >= 50 - log10(cond) - 1 digits (the estimate the
    reports state), checked against 100 digits; n = 10, t = 10 s (cond 2.2e37)."""
    model = fd_lcc(10, PAPER)
    out = {}
    for dps in (50, 100):
        (W,) = gramians_mp(model.A, model.B, (10.0,), dps)
        with mp.workdps(dps):
            lam = sorted(mp.eigsy(W, eigvals_only=True))
            out[dps] = (lam[0], lam[-1] / lam[0])
    with mp.workdps(100):
        agreed = -mp.log10(abs(out[50][0] - out[100][0]) / out[100][0])
        stated = 50 - mp.log10(out[100][1]) - 1
    assert 30 < 50 - stated < 45  # the example is really ill-conditioned
    assert agreed >= stated


@pytest.mark.slow  # multiprecision against an independent method:
# test_multiprecision_matches_an_independent_method_where_float64_is_singular
def test_multiprecision_sweep_continues_the_fig5_trends_past_the_float64_limit():
    sweep = energy_vs_size(PAPER, horizons=(10.0, 30.0), n_max=10, method="mp")
    for t in (10.0, 30.0):
        reps = sweep.reports[t]
        assert [r.n for r in reps] == list(range(1, 11)) and sweep.singular_n(t) is None
        lam = np.array([r.lambda_min for r in reps])
        tr = np.array([r.trace_inv for r in reps])
        assert np.all(lam > 0) and np.all(np.diff(lam) < 0) and np.all(tr[1:] / tr[:-1] > 50)
        assert min(r.digits for r in reps) >= 10
    assert np.all(
        [a.lambda_min < b.lambda_min for a, b in zip(*sweep.reports.values(), strict=True)]
    )
    assert sweep.as_dict()["10"]["reports"][9]["method"] == "mp"


def test_uncontrollable_model_is_refused_in_multiprecision_too():
    with pytest.raises(NumericallySingularError, match="uncontrollable"):
        energy_reports_mp(general_lcc(1, 1, PAPER), (10.0,))


def test_bad_multiprecision_input_is_a_config_error():
    model = fd_lcc(2, PAPER)
    with pytest.raises(ConfigError, match="^method:"):
        energy_vs_size(PAPER, method="quad")
    with pytest.raises(ConfigError, match="^digits:"):
        energy_reports_mp(model, (10.0,), digits=0)
    with pytest.raises(ConfigError, match="^dps:"):
        gramians_mp(model.A, model.B, (10.0,), dps=10)
    with pytest.raises(ConfigError, match="^t:"):
        gramians_mp(model.A, model.B, (0.0,), dps=30)
