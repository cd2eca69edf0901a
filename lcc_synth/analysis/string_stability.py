"""Head-to-tail transfer function and string stability, Section IV and Appendix A.

Head-to-tail transfer function (eq. 24): ``Gamma(s) = V_t(s) / V_h(s)``, the velocity error of the
tail vehicle over the velocity error of the head vehicle, for the CAV law (eq. 23)

    u = a1 s_0 - a2 v_0 + a3 v_-1 + sum_i (mu_i s_i + k_i v_i).

Two independent computations:

* :func:`gamma_closed_form` evaluates the paper's formula ``Gamma = G (phi/gamma)^(n+m)`` with
  ``phi = a3 s + a1``, ``gamma = s^2 + a2 s + a1`` and ``H_i = mu_i (gamma/phi - 1) + k_i s``,
  generalised to per-vehicle (heterogeneous) coefficients by replacing every power of
  ``phi/gamma`` with the product of the vehicles' own ratios (Appendix A, same derivation).
  :func:`gamma_polynomials` gives the same function as an exact ratio of polynomials
  ``num/den``; ``den`` is the closed-loop characteristic polynomial.
* :func:`gamma_state_space` evaluates ``c (jw I - A_cl)^-1 h_cl`` of the closed loop
  (``feedback.closed_loop``) by a vectorised Hessenberg solve (orthogonal reduction once, then an
  O(nx^2) elimination with pivoting per frequency), never by an eigen-decomposition: identical
  vehicle blocks make ``A`` nearly defective.

String-stability verdict (eq. 25): ``|Gamma(jw)| < 1`` for all ``w > 0``. Every stabilising gain
gives ``|Gamma(0)| = 1``, so the question is decided by

1. the low-frequency expansion ``|Gamma(jw)|^2 = Gamma(0)^2 + c w^2 + O(w^4)``: ``c > 0`` means
   ``|Gamma| > 1`` just above ``w = 0``. ``c = g1^2 - g0 g2`` with ``g_k`` the Taylor
   coefficients of ``Gamma`` at 0 (computed from ``A_cl^-1`` solves). The verdict requires
   ``c_rel = c / (g1^2 + |g0 g2|) < -LOW_FREQ_TOL`` (1e-9): a point whose curvature is zero to
   round-off is on the boundary and counted as *not* string stable (conservative);
2. the global supremum over ``w > 0``: every local maximum must stay below ``1 - PEAK_TOL``
   (1e-9). The search is global: a dense logarithmic grid (``GRID_PER_DECADE`` points per decade
   over ``[min(1e-3, 0.01 min|lambda|), max(100, 100 max|lambda|)]``) to which the imaginary
   parts and moduli of all closed-loop poles are added (a lightly damped pole makes a narrow
   peak exactly there), then every local maximum of the grid is refined by a vectorised
   golden-section search (bracket = its two grid neighbours, 45 iterations, relative frequency
   resolution ~1e-9, so the peak value is exact to round-off). A second, independent method is
   the Hamiltonian level-set algorithm of Boyd & Balakrishnan (:func:`hinf_norm_hamiltonian`,
   :func:`level_crossings`), selectable with ``method="hamiltonian"``; the tests check that
   both agree.

Plant (asymptotic) stability uses the closed-loop eigenvalues computed per strongly connected
block of ``A_cl`` (a permutation to block-triangular form, exact): HDVs that the CAV does not
feed back form their own 2x2 blocks, so their eigenvalues are exact instead of being scattered
by a long Jordan chain.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np

from lcc_synth.analysis.transfer import (
    check_head,
    closed_loop_eigenvalues,
    hessenberg_solver,
    low_frequency_curvature,
    tail_output,
    transfer_response,
)
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import closed_loop
from lcc_synth.models.linear import LCCModel

__all__ = [
    "StringStabilityReport",
    "GRID_PER_DECADE",
    "LOW_FREQ_TOL",
    "PEAK_TOL",
    "hinf_norm_hamiltonian",
    "level_crossings",
    "string_stability",
    "gains_string_stability",
    "AnalysisOptions",
    "analysis_options_from",
    "GainCase",
    "cases_from",
]

GRID_PER_DECADE = 120
LOW_FREQ_TOL = 1e-9
PEAK_TOL = 1e-9
_GOLDEN_ITERS = 45


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class StringStabilityReport:
    """Closed-loop plant stability and head-to-tail string stability of one gain.

    Attributes
    ----------
    plant_stable : bool
        All closed-loop eigenvalues have negative real part.
    string_stable : bool
        ``plant_stable`` and ``|Gamma(jw)| < 1`` for every ``w > 0`` (see module docstring).
    gamma_peak : float
        ``sup_{w > 0} |Gamma(jw)|`` (for an unstable plant: the formal frequency response).
    gamma_peak_omega : float
        Where the supremum is attained (rad/s); ``0.0`` when it is the limit ``w -> 0``.
    max_real_eig : float
        Largest real part of the closed-loop eigenvalues.
    gamma_dc : float
        ``|Gamma(0)|`` (1 for every stabilising gain).
    low_freq_curvature : float
        ``c`` in ``|Gamma(jw)|^2 = Gamma(0)^2 + c w^2 + O(w^4)``; ``c > 0`` is string unstable.
    interior_peak, interior_peak_omega : float
        Largest local maximum of ``|Gamma(jw)|`` at ``w > 0`` (NaN when ``|Gamma|`` decreases
        monotonically).
    method : str
        ``"grid"`` or ``"hamiltonian"``.
    """

    plant_stable: bool
    string_stable: bool
    gamma_peak: float
    gamma_peak_omega: float
    max_real_eig: float
    gamma_dc: float
    low_freq_curvature: float
    interior_peak: float
    interior_peak_omega: float
    method: str

    def as_dict(self) -> dict:
        """JSON-ready dict (non-finite floats become ``None``)."""
        out = asdict(self)
        for key, value in out.items():
            if isinstance(value, float) and not np.isfinite(value):
                out[key] = None
        return out



# --------------------------------------------------------------------------------------------
# Global peak search: dense grid + pole frequencies + golden-section refinement
# --------------------------------------------------------------------------------------------


def _frequency_grid(eigs: np.ndarray) -> np.ndarray:
    mags = np.abs(eigs)
    mags = mags[mags > 1e-12]
    lo = min(1e-3, 0.01 * mags.min()) if mags.size else 1e-3
    hi = max(1e2, 100.0 * mags.max()) if mags.size else 1e2
    count = int(np.ceil(GRID_PER_DECADE * np.log10(hi / lo))) + 1
    grid = np.logspace(np.log10(lo), np.log10(hi), count)
    poles = np.concatenate([np.abs(eigs.imag), mags])
    poles = poles[(poles > lo) & (poles < hi)]
    return np.unique(np.concatenate([grid, poles]))


def _golden_max(f, lo: np.ndarray, hi: np.ndarray):
    """Vectorised golden-section maximisation on ``log w`` brackets ``[lo, hi]``."""
    a, b = np.log(lo), np.log(hi)
    r = (np.sqrt(5.0) - 1.0) / 2.0
    x1 = b - r * (b - a)
    x2 = a + r * (b - a)
    f1, f2 = f(np.exp(x1)), f(np.exp(x2))
    for _ in range(_GOLDEN_ITERS):
        left = f1 >= f2  # maximum in [a, x2]
        a_new = np.where(left, a, x1)
        b_new = np.where(left, x2, b)
        # the kept interior point becomes the new x2 (left) or x1 (right)
        keep_x = np.where(left, x1, x2)
        keep_f = np.where(left, f1, f2)
        new_x = np.where(left, b_new - r * (b_new - a_new), a_new + r * (b_new - a_new))
        new_f = f(np.exp(new_x))
        x1 = np.where(left, new_x, keep_x)
        f1 = np.where(left, new_f, keep_f)
        x2 = np.where(left, keep_x, new_x)
        f2 = np.where(left, keep_f, new_f)
        a, b = a_new, b_new
    xb = np.where(f1 >= f2, x1, x2)
    return np.exp(xb), np.maximum(f1, f2)


def _interior_peaks(mag_fn, eigs: np.ndarray, rising_at_zero: bool):
    """All local maxima of ``|Gamma(jw)|`` for ``w > 0``: ``(omegas, values)``.

    ``rising_at_zero`` (low-frequency curvature >= 0): a maximum below the lowest grid
    frequency is searched too; otherwise a decrease at the low end is the ``w -> 0`` limit."""
    w = _frequency_grid(eigs)
    g = mag_fn(w)
    g = np.where(np.isfinite(g), g, np.inf)
    inner = np.nonzero((g[1:-1] >= g[:-2]) & (g[1:-1] >= g[2:]))[0] + 1
    lo = list(w[inner - 1])
    hi = list(w[inner + 1])
    if rising_at_zero and g[0] > g[1]:  # the maximum lies below the lowest grid frequency
        lo.insert(0, w[0] * 1e-3)
        hi.insert(0, w[1])
    if g[-1] > g[-2]:
        lo.append(w[-2])
        hi.append(w[-1] * 1e3)
    if not lo:
        return np.empty(0), np.empty(0)
    om, val = _golden_max(mag_fn, np.array(lo), np.array(hi))
    # a bracket whose grid value beats the refined one (non-unimodal bracket): keep the grid
    grid_best = np.array([g[i] for i in inner]) if len(inner) else np.empty(0)
    if grid_best.size:
        off = 1 if (rising_at_zero and g[0] > g[1]) else 0
        sl = slice(off, off + len(inner))
        better = grid_best > val[sl]
        val[sl] = np.where(better, grid_best, val[sl])
        om[sl] = np.where(better, w[inner], om[sl])
    return om, val


# --------------------------------------------------------------------------------------------
# Hamiltonian level-set method (Boyd & Balakrishnan 1990), the independent check
# --------------------------------------------------------------------------------------------


def level_crossings(
    A: np.ndarray, b: np.ndarray, c: np.ndarray, level: float, rtol: float = 1e-7
) -> np.ndarray:
    """Frequencies ``w >= 0`` with ``|c (jw I - A)^-1 b| = level``: the imaginary-axis
    eigenvalues ``jw`` of the Hamiltonian ``[[A, b b^T/level], [-c^T c/level, -A^T]]``.

    An eigenvalue counts as imaginary when ``|Re| <= rtol * max(1, |lambda|)``.
    """
    A = np.asarray(A, float)
    b = np.asarray(b, float).reshape(-1, 1)
    c = np.asarray(c, float).reshape(1, -1)
    Hm = np.block([[A, b @ b.T / level], [-c.T @ c / level, -A.T]])
    ev = np.linalg.eigvals(Hm)
    on_axis = np.abs(ev.real) <= rtol * np.maximum(1.0, np.abs(ev))
    return np.sort(np.unique(np.round(np.abs(ev[on_axis].imag), 12)))


def hinf_norm_hamiltonian(
    A: np.ndarray, b: np.ndarray, c: np.ndarray, tol: float = 1e-9, max_iter: int = 100
) -> tuple[float, float]:
    """``(sup_w |G(jw)|, argmax)`` of a stable SISO ``G = c (sI - A)^-1 b`` by the
    quadratically convergent level-set iteration of Boyd & Balakrishnan."""
    eigs = np.linalg.eigvals(A)
    cand = np.concatenate([[0.0], np.abs(eigs.imag), np.abs(eigs)])
    vals = np.abs(transfer_response(A, b, c, 1j * cand))
    i = int(np.argmax(vals))
    lb, w_best = float(vals[i]), float(cand[i])
    for _ in range(max_iter):
        level = (1.0 + 2.0 * tol) * lb
        ws = level_crossings(A, b, c, level)
        if ws.size < 2:
            return lb, w_best
        mids = 0.5 * (ws[:-1] + ws[1:])
        mv = np.abs(transfer_response(A, b, c, 1j * mids))
        j = int(np.argmax(mv))
        if mv[j] <= lb:
            return lb, w_best
        lb, w_best = float(mv[j]), float(mids[j])
    return lb, w_best


# --------------------------------------------------------------------------------------------
# Verdict
# --------------------------------------------------------------------------------------------


def string_stability(
    model: LCCModel, K: np.ndarray, kh: float = 0.0, method: str = "grid"
) -> StringStabilityReport:
    """Plant and head-to-tail string stability of the closed loop ``input = K x + kh v_h``.

    Parameters
    ----------
    model : LCCModel
        Any kind with a head vehicle (not ``fd_lcc``).
    K, kh : array_like, float
        Feedback on the model's input, as :func:`lcc_synth.models.feedback.input_feedback` returns.
    method : {"grid", "hamiltonian"}
        Global search of ``sup |Gamma(jw)|``: dense grid + pole frequencies + golden-section
        refinement, or Boyd-Balakrishnan level sets (see the module docstring). The
        Hamiltonian method reports ``interior_peak`` only when it is the global supremum, and
        an unstable plant's formal response is always searched on the grid.
    """
    check_head(model)
    if method not in ("grid", "hamiltonian"):
        raise ConfigError("method", f"must be 'grid' or 'hamiltonian', got {method!r}")
    Acl, Hcl = closed_loop(model, K, kh)
    c = tail_output(model)
    h = Hcl.reshape(-1)
    eigs = closed_loop_eigenvalues(Acl)
    max_re = float(eigs.real.max())
    plant_stable = bool(max_re < 0.0)
    singular = np.any(np.abs(eigs) < 1e-12)
    g0, curv, crel = float("nan"), float("nan"), float("nan")
    if not singular:
        with np.errstate(all="ignore"):
            try:
                g0, curv, crel = low_frequency_curvature(Acl, h, c)
            except (np.linalg.LinAlgError, ValueError):
                pass
        if not (np.isfinite(g0) and np.isfinite(curv)):
            g0, curv, crel = float("nan"), float("nan"), float("nan")

    solver = hessenberg_solver(Acl, h, c)

    def mag(w):
        return np.abs(solver(1j * np.asarray(w, float)))

    if method == "hamiltonian" and plant_stable:
        peak, peak_w = hinf_norm_hamiltonian(Acl, h, c)
        crossings = level_crossings(Acl, h, c, abs(g0))
        crossings = crossings[crossings > 1e-6 * max(1.0, np.abs(eigs).max())]
        dc = abs(g0)
        interior = peak if peak_w > 0 and peak > dc else float("nan")
        interior_w = peak_w if np.isfinite(interior) else float("nan")
        string_stable = bool(crel < -LOW_FREQ_TOL and crossings.size == 0)
        gamma_peak = max(peak, dc)
        gamma_peak_w = peak_w if peak > dc * (1 + PEAK_TOL) else 0.0
    else:
        om, val = _interior_peaks(mag, eigs, rising_at_zero=not crel < 0)
        dc = abs(g0) if np.isfinite(g0) else float(mag(np.array([1e-9]))[0])
        if val.size:
            j = int(np.argmax(val))
            interior, interior_w = float(val[j]), float(om[j])
        else:
            interior, interior_w = float("nan"), float("nan")
        string_stable = bool(
            plant_stable
            and crel < -LOW_FREQ_TOL
            and (not val.size or interior < 1.0 - PEAK_TOL)
        )
        if np.isfinite(interior) and interior > dc:
            gamma_peak, gamma_peak_w = interior, interior_w
        else:
            gamma_peak, gamma_peak_w = dc, 0.0
    string_stable = bool(string_stable and plant_stable)
    return StringStabilityReport(
        plant_stable=plant_stable,
        string_stable=string_stable,
        gamma_peak=float(gamma_peak),
        gamma_peak_omega=float(gamma_peak_w),
        max_real_eig=max_re,
        gamma_dc=float(dc),
        low_freq_curvature=float(curv),
        interior_peak=float(interior),
        interior_peak_omega=float(interior_w),
        method=method,
    )


def gains_string_stability(model: LCCModel, gains, method: str = "grid") -> StringStabilityReport:
    """:func:`string_stability` of :class:`~lcc_synth.models.feedback.StaticGains` on ``model``."""
    from lcc_synth.models.feedback import input_feedback

    K, kh = input_feedback(model, gains)
    return string_stability(model, K, kh, method=method)


# --------------------------------------------------------------------------------------------
# Problem files: [cases.NAME] and [analysis]
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class AnalysisOptions:
    """The ``[analysis]`` table: observability outputs, peak-search method, plot grid."""

    outputs: tuple[str, ...] | None = None
    method: str = "grid"
    omega_min: float = 1e-3
    omega_max: float = 10.0
    points: int = 400

    def omega(self) -> np.ndarray:
        """Logarithmic frequency grid for plotted responses (Fig. 9)."""
        return np.logspace(np.log10(self.omega_min), np.log10(self.omega_max), self.points)


def analysis_options_from(data: Mapping, source: str | None = None) -> AnalysisOptions:
    """Parse the optional ``[analysis]`` table (see :func:`cases_from`)."""
    from lcc_synth.problem import check_keys, get_int, get_number, get_str, get_table

    try:
        t = get_table(data, "analysis", "analysis")
        check_keys(t, ["outputs", "method", "omega_min", "omega_max", "points"], "analysis")
        outputs = None
        if "outputs" in t:
            raw = t["outputs"]
            if not isinstance(raw, list) or not raw or not all(isinstance(x, str) for x in raw):
                raise ConfigError(
                    "analysis.outputs", f"must be a non-empty list of state names, got {raw!r}"
                )
            outputs = tuple(raw)
        method = get_str(t, "method", "analysis", "grid", choices=["grid", "hamiltonian"])
        lo = get_number(t, "omega_min", "analysis", 1e-3, lo=0.0, lo_open=True)
        hi = get_number(t, "omega_max", "analysis", 10.0, lo=lo, lo_open=True)
        points = get_int(t, "points", "analysis", 400, lo=2, hi=100_000)
        return AnalysisOptions(outputs, method, lo, hi, points)
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None


@dataclass(frozen=True)
class GainCase:
    """One ``[cases.NAME]`` table: a named static gain (eq. 23) to analyse."""

    name: str
    gains: object  # StaticGains
    label: str


def cases_from(data: Mapping, model: LCCModel, source: str | None = None) -> dict[str, GainCase]:
    """Parse ``[cases.NAME]`` tables into :class:`GainCase` (in file order).

    Each table: ``semantics = "added" | "replace"`` (default ``"added"``), ``gains = { s_-2 =
    1.0, v_-2 = -1.0, ... }`` (state name -> gain, missing states 0) and an optional ``label``.
    Errors name ``cases.NAME.<field>`` and the file.
    """
    from lcc_synth.models.feedback import StaticGains
    from lcc_synth.problem import check_keys, get_str, get_table

    out = {}
    try:
        cases = get_table(data, "cases", "cases")
        for name, table in cases.items():
            field = f"cases.{name}"
            if not isinstance(table, dict):
                raise ConfigError(field, f"must be a table, got {table!r}")
            check_keys(table, ["semantics", "gains", "label"], field)
            semantics = get_str(table, "semantics", field, "added", choices=["added", "replace"])
            raw = get_table(table, "gains", f"{field}.gains")
            label = get_str(table, "label", field, name)
            try:
                gains = StaticGains(raw, semantics)
                gains.check(model)
            except ConfigError as err:
                raise ConfigError(f"{field}.{err.field}", err.message) from None
            out[name] = GainCase(name, gains, label)
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None
    return out
