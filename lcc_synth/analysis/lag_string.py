"""Head-to-tail string stability with the CAVs' actuator lag, and the critical lag of a gain.

The lagged loop (:func:`lcc_synth.models.lag.with_actuator_lag` on any layout with a head
vehicle: the paper's one-CAV models, the lag fed by the CAV's velocity row ``v_0``, or an open
platoon, one lag state per CAV fed by its ``v_c``) is a SISO loop ``Gamma(s) = c (sI -
A_cl)^-1 h`` like the lag-free one, so the verdict is the exact one of
:func:`lcc_synth.analysis.string_stability.loop_string_stability` (decision function without
the double zero at ``w = 0``, band from the closed-loop eigenvalues). The lag multiplies the
CAV's command path by ``1 / (tau s + 1)``: ``Gamma(0) = 1`` stays, the phase lag grows with
``w tau``, and a gain that is string stable without lag loses it at a large enough ``tau``
(the known effect of CACC work: the lag eats the time gap's margin).

:func:`critical_lag` finds the smallest lag at which a gain stops being string stable: a scan
of ``tau`` over a geometric grid (``SCAN`` points from ``tau_lo`` to ``tau_max``) for the first
lag whose verdict is not ``"string_stable"``, then bisection between it and the previous
(string stable) grid point on the exact verdicts, down to ``rtol`` relative. A lag whose
verdict is ``"boundary"`` counts as not string stable. About 50 verdicts per gain (measured
2.9 s for Table II's string, 0.8 s for m = n = 2, on a loaded 2-core machine).

Measured critical lags (``tests/test_actuator_lag.py``, ``docs/guide/lag.md``): Table II's
CF-LCC gain 2.194 s (beyond it an interior peak near 0.40 rad/s); Table I's case D (m = n = 2)
0.445 s (a resonance at 1.84 rad/s, the plant itself unstable by 0.6 s); the showcase's
structured H2 gain 1.583 s; the lag-free ``string_stable`` design of
``problems/synth_string_stable_m2n2.toml`` 1.071 s.
Checked against a direct per-frequency solution of the lag-free loop with the factor
``1 / (tau s + 1)`` on the CAV's velocity row (agreement 1e-10) and a dense ``|Gamma|`` grid on
both sides of each critical lag. An open platoon whose CAVs have local laws is a cascade: with
the lag a CAV's ``T_c = (k_p s + k_s) / (tau s^3 + s^2 - k_v s + k_s)``, and the lagged loop's
``Gamma`` equals that product to 1e-10 (DeeP-LCC platoon, lags 0.3 / 0.6 s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lcc_synth.analysis.string_stability import StringStabilityReport, loop_string_stability
from lcc_synth.analysis.transfer import head_to_tail_loop, transfer_response
from lcc_synth.errors import ConfigError
from lcc_synth.models.lag import LaggedModel, check_lag, with_actuator_lag
from lcc_synth.models.records import Record

__all__ = [
    "lagged_lcc",
    "lag_string_stability",
    "gamma_lag",
    "CriticalLag",
    "critical_lag",
    "SCAN",
]

#: Grid points of the scan that brackets the critical lag.
SCAN = 40


def lagged_lcc(model, tau) -> LaggedModel:
    """``model`` with the lag ``tau`` (> 0; one value, or one per CAV) on every CAV's
    acceleration (states ``a_<c>``, fed by each CAV's velocity row ``v_<c>``)."""
    rows = [model.index(f"v_{c}") for c in model.cavs]
    return with_actuator_lag(model.A, model.B, model.H, rows, tau, model.state_names)


def _loop(model, K, kh, tau, k_a):
    """``(A, h, c)`` of the head-to-tail loop with the lag (``tau = 0``: without)."""
    A, h, c = head_to_tail_loop(model, K, kh)  # checks the head, K and kh
    if np.ndim(tau) == 0:
        tau = check_lag(tau)
    if np.ndim(tau) == 0 and tau == 0.0:
        if np.any(np.asarray(k_a, dtype=float) != 0.0):
            raise ConfigError("k_a", "an acceleration feedback needs a lag tau > 0")
        return A, h, c
    lag = lagged_lcc(model, tau)
    nu = model.B.shape[1]
    K = np.asarray(K, dtype=float).reshape(nu, -1)
    k_a = np.broadcast_to(np.asarray(k_a, dtype=float), (nu,))
    Acl, Hcl = lag.closed_loop(np.hstack([K, np.diag(k_a)]), kh)
    return Acl, Hcl.ravel(), np.concatenate([c, np.zeros(nu)])


def lag_string_stability(
    model, K, kh=0.0, tau=0.0, k_a=0.0, method: str = "grid",
) -> StringStabilityReport:  # fmt: skip
    """String stability of ``input = K x + kh v_h (+ k_a a_c)`` with the actuator lag ``tau``.

    Parameters
    ----------
    model : LCCModel or PlatoonModel
        Any layout with a head vehicle (one CAV or several).
    K, kh : array_like, float
        Feedback on the model's input, as for
        :func:`~lcc_synth.analysis.string_stability.string_stability`.
    tau : float or sequence of float
        Actuator lag (s, >= 0), one for every CAV or one per CAV (each > 0); 0 is
        :func:`~lcc_synth.analysis.string_stability.string_stability`.
    k_a : float or sequence of float
        Feedback of each CAV's own (measured) acceleration ``a_c`` (needs ``tau > 0``).
    method : {"grid", "hamiltonian"}
        See :func:`~lcc_synth.analysis.string_stability.loop_string_stability`.
    """
    A, h, c = _loop(model, K, kh, tau, k_a)
    return loop_string_stability(A, h, c, method=method)


def gamma_lag(model, K, kh, tau, omega, k_a=0.0) -> np.ndarray:
    """``Gamma(j omega)`` (head velocity to tail velocity) of the lagged loop (any layout with a
    head vehicle; arguments as :func:`lag_string_stability`)."""
    A, h, c = _loop(model, K, kh, tau, k_a)
    return transfer_response(A, h, c, 1j * np.asarray(omega, dtype=float))


@dataclass(frozen=True, repr=False)
class CriticalLag(Record):
    """The smallest actuator lag at which a gain stops being string stable.

    Attributes
    ----------
    tau : float
        The critical lag (s): midpoint of the final bracket; ``inf`` when the gain is string
        stable up to ``tau_max``, 0 when it is not string stable without lag.
    lo, hi : float
        The final bracket: string stable at ``lo``, not at ``hi``.
    verdict_lo, verdict_hi : str
        The verdicts at ``lo`` and ``hi``.
    margin_lo : float
        The string margin at ``lo``.
    evaluations : int
        Verdicts computed.
    """

    tau: float
    lo: float
    hi: float
    verdict_lo: str
    verdict_hi: str
    margin_lo: float
    evaluations: int


def critical_lag(
    model, K, kh=0.0, tau_max: float = 5.0, tau_lo: float = 1e-3,
    rtol: float = 1e-6, k_a: float = 0.0,
) -> CriticalLag:  # fmt: skip
    """Scan and bisect the lag at which ``u = K x + kh v_h`` loses string stability.

    Parameters
    ----------
    model : LCCModel or PlatoonModel
        Any layout with a head vehicle; every CAV gets the same lag.
    K, kh : array_like, float
        Feedback on the model's input.
    tau_max, tau_lo : float
        The scanned range (s, ``0 < tau_lo < tau_max``).
    rtol : float
        Relative width of the final bracket.
    k_a : float
        Acceleration feedback (see :func:`lag_string_stability`).

    Returns
    -------
    CriticalLag
    """
    tau_lo = check_lag(tau_lo, "tau_lo", allow_zero=False)
    tau_max = check_lag(tau_max, "tau_max", allow_zero=False)
    if not tau_lo < tau_max:
        raise ConfigError("tau_max", f"must be > tau_lo = {tau_lo}, got {tau_max}")
    n = 0

    def rep(t):
        nonlocal n
        n += 1
        return lag_string_stability(model, K, kh, t, k_a if t > 0 else 0.0)

    r0 = rep(0.0) if k_a == 0.0 else rep(tau_lo)
    if not r0.string_stable:
        return CriticalLag(0.0, 0.0, 0.0, r0.verdict, r0.verdict, r0.margin, n)
    lo, r_lo, hi, r_hi = 0.0, r0, None, None
    for t in np.geomspace(tau_lo, tau_max, SCAN):
        r = rep(float(t))
        if not r.string_stable:
            hi, r_hi = float(t), r
            break
        lo, r_lo = float(t), r
    if hi is None:
        return CriticalLag(float("inf"), lo, float("inf"), r_lo.verdict, "n/a", r_lo.margin, n)
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        r = rep(mid)
        if r.string_stable:
            lo, r_lo = mid, r
        else:
            hi, r_hi = mid, r
    return CriticalLag(0.5 * (lo + hi), lo, hi, r_lo.verdict, r_hi.verdict, r_lo.margin, n)
