"""Head-to-tail string stability (Section IV, Definition 1, eq. 25), decided without rounding.

The paper's condition is ``|Gamma(jw)| < 1`` for all ``w > 0``, where ``Gamma(s) = c (sI -
A_cl)^-1 h`` is the head-to-tail transfer function (:mod:`lcc_synth.analysis.transfer`). Every
stabilising gain has ``Gamma(0) = g0 = 1``, so the question is asked at the level of the
supremum itself: ``|Gamma|^2 - g0^2`` has an exact double zero at ``w = 0``, and a test that
evaluates it there (a level crossing of the Hamiltonian at ``|Gamma(0)|``, a grid point against
``1 - 1e-9``) decides on rounding noise. This module removes that double zero structurally.

Decision function
-----------------
With the Taylor remainders (exact identities, each a transfer function of the same loop)

    Gamma1(s) = (Gamma(s) - g0) / s       = c (sI - A)^-1 A^-1 h,
    Gamma2(s) = (Gamma1(s) - Gamma1(0)) / s = c (sI - A)^-1 A^-2 h,

one has, for every ``w``, ``|Gamma(jw)|^2 - g0^2 = w^2 Q(w)`` with

    Q(w) = |Gamma1(jw)|^2 - 2 g0 Re Gamma2(jw),      Q(0) = c,

``c`` the low-frequency curvature of ``|Gamma|^2 = g0^2 + c w^2 + O(w^4)``. String stability is
exactly ``Q(w) < 0`` for all ``w >= 0``: no zero to remove, no limit to take. The verdict uses the
relative form ``q(w) = Q / S``, ``S = |Gamma1|^2 + 2 |g0 Re Gamma2|`` (the sum of the absolute
values of its two terms, so ``|q| <= 1``; ``q -> -1/3`` as ``w -> inf``). ``q`` is a function of
the transfer function only: it does not change under a change of state coordinates, of units
(``Gamma1`` scales with time, ``Gamma2`` with time squared), or of the realisation.

Verdict and tolerance band
--------------------------
``margin = -max_{w >= 0} q(w)``. With the band

    tau = BAND_FACTOR * eps * max(1, max|lambda| / min|lambda|)       (BAND_FACTOR = 1e4)

over the closed-loop eigenvalues (a coordinate-free spread of the loop's time scales; on the
paper's models tau = 2e-11 to 3e-10), the report says ``"string_stable"`` when ``margin > tau``,
``"string_unstable"`` when ``margin < -tau`` and ``"boundary"`` in between: a case too close to
call is never settled by a coin flip. ``"plant_unstable"`` is a loop with an eigenvalue of real
part above ``tau * max|lambda|`` (below it in magnitude: ``"boundary"`` too).
``string_stable`` (bool) is true only for the first verdict. The band covers the rounding error
of ``q`` with a wide margin where it matters. Measured against an exact rational / 50-digit
reference (``tests/exact_reference.py``; ``python benchmarks/bench_string_exactness.py``) on
674 gains of the paper's models and 6740 transformed copies (permutations, diagonal scalings,
orthogonal and similarity transforms, 1e-12 gain perturbations), under the Haswell and SkylakeX
BLAS kernels: ``|q - q_exact|`` is at most 15 ``eps kappa`` (1.5e-3 ``tau``) at ``w = 0`` and
12 ``eps kappa`` (1.2e-3 ``tau``) wherever ``|q| < 1e-2``; it reaches ~``tau`` only on the
plateau ``q ~ 1`` far from any verdict. Every decided verdict was right (124 gains inside the
band were reported ``"boundary"``: exactly those whose exact margin is inside it); the previous
check was wrong on 81 (grid) and 86 (Hamiltonian) of the 674 and its Hamiltonian flipped on 213
of the transformed copies.

Two independent searches of ``max q`` (``method``), the same band for both:

* ``"grid"``: ``w = 0`` exactly (``q(0) = c / S(0)`` from three solves with ``A_cl``) plus a dense
  logarithmic grid (``GRID_PER_DECADE`` points per decade over ``[min(1e-3, 0.01 min|lambda|),
  max(100, 100 max|lambda|)]``) with the imaginary parts and moduli of all closed-loop poles
  added (a lightly damped pole makes a narrow peak there); points closer than
  ``transfer.MERGE_RTOL`` (1e-7) relative are merged, so repeated poles that differ by an ulp
  do not make zero-width brackets. Every local maximum is refined by a vectorised
  golden-section search on ``log w`` whose bracket runs between the neighbours that are
  *strictly* lower (so it contains the maximiser even on a flat stretch).
* ``"hamiltonian"``: the level set ``|Gamma(jw)| = g0`` is the set of imaginary eigenvalues
  ``jw`` of the Hamiltonian ``[[A, h h^T / g0], [-c^T c / g0, -A^T]]`` (Boyd & Balakrishnan).
  Its double eigenvalue at 0 is deflated exactly: the Jordan chain ``v0 = [-A^-1 h; -A^-T
  c^T]``, ``v1 = [-A^-2 h; (c A^-2 h / g0) A^-T c^T + A^-2T c^T]`` (``H v0 = 0``, ``H v1 =
  v0``) spans an invariant subspace, and the eigenvalues of the Hamiltonian restricted to its
  orthogonal complement are the remaining ones. Their imaginary parts (every eigenvalue within
  45 degrees of the axis: an eigenvalue near ``jw*`` is also what a near-tangency ``q(w*) ~ 0``
  leaves) are the candidate frequencies; ``q`` is evaluated there, at the midpoints between them
  and refined between neighbours.

Outside the band the two methods give the same verdict. ``gamma_peak`` (``sup_{w > 0}
|Gamma(jw)|``, the limit ``g0`` at ``w -> 0`` for a string-stable gain) is found by the same grid
for ``"grid"`` and by the Boyd-Balakrishnan level-set iteration (:func:`hinf_norm_hamiltonian`)
for ``"hamiltonian"``; they agree to 1e-9 relative. The loop is first balanced by an exact diagonal
similarity (``scipy.linalg.matrix_balance``, powers of 2), so states in badly chosen units
(``T = diag(10^±3)``, ``cond(A) ~ 1e11``) give the same peak to 1e-12 instead of 3e-9.

The loop need not come from an LCC model: :func:`loop_string_stability` takes any stable SISO
``(A_cl, h, c)``, e.g. a loop with an estimator or sampling in it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import scipy.linalg as sla

from lcc_synth.analysis.controllability import reduce_conserved
from lcc_synth.analysis.transfer import (
    closed_loop_eigenvalues,
    golden_max,
    hamiltonian_matrix,
    head_to_tail_loop,
    hessenberg_solver,
    hinf_norm_hamiltonian,
    merge_frequencies,
)
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import closed_loop
from lcc_synth.models.records import Record

__all__ = [
    "StringStabilityReport",
    "VERDICTS",
    "GRID_PER_DECADE",
    "BAND_FACTOR",
    "string_band",
    "plant_verdict",
    "plant_stability",
    "decision_function",
    "deflated_hamiltonian_eigenvalues",
    "loop_string_stability",
    "string_stability",
    "gains_string_stability",
    "verdict_text",
]

VERDICTS = ("string_stable", "string_unstable", "plant_unstable", "boundary")
GRID_PER_DECADE = 120
BAND_FACTOR = 1e4
_EPS = float(np.finfo(float).eps)


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, repr=False)
class StringStabilityReport(Record):
    """Closed-loop plant stability and head-to-tail string stability of one loop.

    Attributes
    ----------
    plant_stable : bool
        All closed-loop eigenvalues have real part below ``-band * max|lambda|``.
    string_stable : bool
        ``verdict == "string_stable"``: ``|Gamma(jw)| < 1`` for every ``w > 0`` with a margin
        outside the band.
    verdict : str
        ``"string_stable"``, ``"string_unstable"``, ``"plant_unstable"`` or ``"boundary"``
        (too close to call at this precision; see the module docstring).
    margin : float
        ``-max_{w >= 0} q(w)`` (relative, in ``[-1, 1]``): positive for string stable. NaN for an
        unstable plant.
    margin_omega : float
        Where ``q`` is largest (rad/s; 0 when it is the low-frequency curvature).
    band : float
        The tolerance ``tau`` the verdict used.
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
    verdict: str = "string_unstable"
    margin: float = float("nan")
    margin_omega: float = float("nan")
    band: float = float("nan")

    @property
    def boundary(self) -> bool:
        """True when the verdict is too close to call (inside the band)."""
        return self.verdict == "boundary"

    def as_dict(self) -> dict:
        """JSON-ready dict (non-finite floats become ``None``)."""
        out = asdict(self)
        for key, value in out.items():
            if isinstance(value, float) and not np.isfinite(value):
                out[key] = None
        return out


# --------------------------------------------------------------------------------------------
# The decision function q(w) and the band
# --------------------------------------------------------------------------------------------


def string_band(eigs: np.ndarray) -> float:
    """The relative tolerance ``tau = BAND_FACTOR * eps * max(1, max|lambda| / min|lambda|)``.

    Coordinate- and unit-free: eigenvalues do not change under similarity transforms, and a
    change of time unit scales all of them alike. Infinite when an eigenvalue is 0.
    """
    mags = np.abs(np.asarray(eigs, dtype=complex))
    if mags.size == 0:
        return BAND_FACTOR * _EPS
    lo = float(mags.min())
    if lo == 0.0:
        return float("inf")
    return BAND_FACTOR * _EPS * max(1.0, float(mags.max()) / lo)


def plant_verdict(eigs: np.ndarray) -> tuple[str, float]:
    """``(verdict, max Re lambda)`` of a loop with eigenvalues ``eigs``: ``"plant_stable"`` /
    ``"plant_unstable"`` when the largest real part is below / above ``-+ tau max|lambda|``
    (:func:`string_band` of the eigenvalues that are not numerically 0), ``"boundary"`` in
    between: too close to call at this precision.

    An eigenvalue numerically 0 (``|lambda| <= BAND_FACTOR eps max|lambda|``: an exact 0, or
    the round-off a change of coordinates leaves of it) is on the imaginary axis: the loop is
    then ``"boundary"``, unless another eigenvalue is clearly in the right half-plane
    (``"plant_unstable"``, which a 0 eigenvalue cannot make stable)."""
    eigs = np.asarray(eigs, dtype=complex)
    max_re = float(eigs.real.max())
    scale = float(np.abs(eigs).max()) if eigs.size else 1.0
    tiny = np.abs(eigs) <= BAND_FACTOR * _EPS * scale
    band = string_band(eigs[~tiny])
    if max_re > band * scale:
        return "plant_unstable", max_re
    if tiny.any() or abs(max_re) <= band * scale:
        return "boundary", max_re
    return "plant_stable", max_re


def plant_stability(model, K, kh=0.0) -> tuple[str, float]:
    """:func:`plant_verdict` of the closed loop ``input = K x + kh v_h`` on the space that
    matters: the whole state of an open layout, the invariant hyperplane of a ring (its
    conserved total spacing left out, :func:`~lcc_synth.analysis.controllability.
    reduce_conserved`). Any layout, a head vehicle or not."""
    Acl, _ = closed_loop(model, K, kh)
    if model.ring:
        Acl = reduce_conserved(Acl, model.B, model.conserved)[0]
    return plant_verdict(closed_loop_eigenvalues(Acl))


@dataclass(frozen=True)
class _Decision:
    """``q(w)`` of one loop plus what the searches reuse."""

    g0: float
    curvature: float
    q0: float
    evaluate: object  # w -> (q, |Gamma|)
    lu: tuple
    b1: np.ndarray
    b2: np.ndarray


def _decision(A: np.ndarray, h: np.ndarray, c: np.ndarray, d: float = 0.0) -> _Decision:
    lu = sla.lu_factor(A)
    b1 = sla.lu_solve(lu, h)
    b2 = sla.lu_solve(lu, b1)
    b3 = sla.lu_solve(lu, b2)
    g0 = d - float(c @ b1)  # Gamma1, Gamma2 do not depend on the feed-through d
    G1_0 = -float(c @ b2)
    G2_0 = -float(c @ b3)
    curv = G1_0 * G1_0 - 2.0 * g0 * G2_0
    S0 = G1_0 * G1_0 + 2.0 * abs(g0 * G2_0)
    q0 = curv / S0 if S0 > 0 else 0.0
    solver = hessenberg_solver(A, np.column_stack([h, b1, b2]), c)

    def evaluate(w):
        w = np.asarray(w, dtype=float)
        y = solver(1j * w)
        G, G1, G2 = y[..., 0] + d, y[..., 1], y[..., 2]
        a = G1.real * G1.real + G1.imag * G1.imag
        b = 2.0 * g0 * G2.real
        S = a + np.abs(b)
        with np.errstate(divide="ignore", invalid="ignore"):
            q = np.where(S > 0, (a - b) / S, 0.0)
        q = np.where(w == 0.0, q0, q)
        return np.where(np.isfinite(q), q, np.inf), np.abs(G)

    return _Decision(g0, curv, q0, evaluate, lu, b1, b2)


def decision_function(A: np.ndarray, h: np.ndarray, c: np.ndarray):
    """``(q, g0, c)``: the relative decision function ``q(w)`` (a callable on frequencies,
    ``q(0)`` exact), ``Gamma(0)`` and the low-frequency curvature of the stable loop
    ``Gamma = c (sI - A)^-1 h`` (see the module docstring)."""
    A, (scale, _) = sla.matrix_balance(np.asarray(A, dtype=float), permute=False, separate=True)
    h = np.asarray(h, float).reshape(-1) / scale
    c = np.asarray(c, float).reshape(-1) * scale
    d = _decision(A, h, c)
    return (lambda w: d.evaluate(w)[0]), d.g0, d.curvature


# --------------------------------------------------------------------------------------------
# Grid search: dense grid + pole frequencies + golden-section refinement
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
    return merge_frequencies(np.concatenate([grid, poles]))


def _local_maxima(f, w: np.ndarray, g: np.ndarray, lowest: float | None):
    """Refined local maxima of ``f`` sampled as ``g`` on the sorted grid ``w`` (``w[0]`` may be
    0, an endpoint never refined). Brackets run between the nearest neighbours that are strictly
    lower, so a flat stretch cannot hide the maximiser outside its bracket; a maximum at the
    upper end is searched up to ``1e3 w[-1]``; ``lowest`` is the left end used when the left
    neighbour is ``w = 0``. Returns ``(omegas, values)``, the better of grid and refined."""
    n = w.size
    if n < 2:
        return np.empty(0), np.empty(0)
    peak = np.zeros(n, dtype=bool)
    peak[1:-1] = (g[1:-1] >= g[:-2]) & (g[1:-1] >= g[2:])
    peak[-1] = g[-1] > g[-2]
    peak[1:] &= ~(peak[:-1] & (g[1:] == g[:-1]))  # one index per plateau
    idx = np.nonzero(peak)[0]
    if not idx.size:
        return np.empty(0), np.empty(0)
    lo_b, hi_b = [], []
    for i in idx:
        j = i - 1
        while j > 0 and g[j] >= g[i]:
            j -= 1
        k = i + 1
        while k < n and g[k] >= g[i]:
            k += 1
        left = w[j] if w[j] > 0 else (lowest if lowest else w[i] * 1e-6)
        right = w[k] if k < n else w[-1] * 1e3
        lo_b.append(left)
        hi_b.append(right)
    om, val = golden_max(f, np.array(lo_b), np.array(hi_b))
    grid_better = g[idx] > val
    om = np.where(grid_better, w[idx], om)
    val = np.where(grid_better, g[idx], val)
    return om, val


def _grid_search(dec: _Decision, eigs: np.ndarray):
    """``(max q, its w, [(omega, |Gamma|) of the interior peaks])`` by the grid method."""
    w = _frequency_grid(eigs)
    q, mag = dec.evaluate(w)
    # decision function: w = 0 is part of the domain
    wq = np.concatenate([[0.0], w])
    gq = np.concatenate([[dec.q0], q])
    om, val = _local_maxima(lambda x: dec.evaluate(x)[0], wq, gq, lowest=w[0] * 1e-3)
    cand_w = np.concatenate([[0.0], om])
    cand_q = np.concatenate([[dec.q0], val])
    j = int(np.argmax(cand_q))
    # |Gamma|: interior local maxima (the limit at 0 is g0)
    mag = np.where(np.isfinite(mag), mag, np.inf)
    pw, pv = _local_maxima(
        lambda x: dec.evaluate(x)[1], w, mag, lowest=None
    )
    if dec.q0 >= 0 and mag.size > 1 and mag[0] > mag[1]:  # rising at 0: peak below the grid
        w2, v2 = golden_max(lambda x: dec.evaluate(x)[1], np.array([w[0] * 1e-3]), w[1:2])
        pw, pv = np.concatenate([w2, pw]), np.concatenate([v2, pv])
    return float(cand_q[j]), float(cand_w[j]), pw, pv


# --------------------------------------------------------------------------------------------
# Hamiltonian level-set method (Boyd & Balakrishnan 1990), the independent search
# --------------------------------------------------------------------------------------------


def deflated_hamiltonian_eigenvalues(
    A: np.ndarray, h: np.ndarray, c: np.ndarray
) -> np.ndarray:
    """Eigenvalues of the Hamiltonian at the level ``g0 = Gamma(0)``, without the exact double
    eigenvalue at 0 (deflated through its Jordan chain, see the module docstring)."""
    A = np.asarray(A, float)
    h = np.asarray(h, float).reshape(-1)
    c = np.asarray(c, float).reshape(-1)
    return _deflated_eigs(A, h, c, _decision(A, h, c))


def _deflated_eigs(A, h, c, dec: _Decision) -> np.ndarray:
    g0 = dec.g0
    At_c = sla.lu_solve(dec.lu, c, trans=1)
    At2_c = sla.lu_solve(dec.lu, At_c, trans=1)
    m2 = float(c @ dec.b2)
    v0 = np.concatenate([-dec.b1, -At_c])
    v1 = np.concatenate([-dec.b2, (m2 / g0) * At_c + At2_c])
    V = np.column_stack([v0 / np.linalg.norm(v0), v1 / np.linalg.norm(v1)])
    Z = np.linalg.qr(V, mode="complete")[0][:, 2:]
    Hm = hamiltonian_matrix(A, h, c, g0)
    return np.linalg.eigvals(Z.T @ Hm @ Z)


def _hamiltonian_search(A, h, c, dec: _Decision):
    """``(max q, its w)`` from the candidate frequencies of the deflated Hamiltonian."""
    ev = _deflated_eigs(A, h, c, dec)
    near = np.abs(ev.real) <= np.abs(ev.imag)
    cand = merge_frequencies(np.abs(ev[near].imag))
    cand = cand[cand > 0]
    if cand.size == 0:
        return dec.q0, 0.0
    mids = np.sqrt(cand[:-1] * cand[1:])
    pts = merge_frequencies(np.concatenate([cand, mids, [cand[0] * 0.5, cand[-1] * 2.0]]))
    wq = np.concatenate([[0.0], pts])
    gq = np.concatenate([[dec.q0], dec.evaluate(pts)[0]])
    om, val = _local_maxima(lambda x: dec.evaluate(x)[0], wq, gq, lowest=pts[0] * 1e-3)
    all_w = np.concatenate([[0.0], om])
    all_q = np.concatenate([[dec.q0], val])
    j = int(np.argmax(all_q))
    return float(all_q[j]), float(all_w[j])


# --------------------------------------------------------------------------------------------
# Verdict
# --------------------------------------------------------------------------------------------


def loop_string_stability(
    A: np.ndarray, h: np.ndarray, c: np.ndarray, method: str = "grid", d: float = 0.0
) -> StringStabilityReport:
    """Plant and string stability of the SISO loop ``Gamma(s) = d + c (sI - A)^-1 h``.

    Parameters
    ----------
    A : array_like, (nx, nx)
        Closed-loop state matrix (any realisation: the verdict does not depend on it).
    h, c : array_like, (nx,)
        Input column of the head velocity error and the tail velocity output row.
    method : {"grid", "hamiltonian"}
        How ``max q`` and ``sup |Gamma|`` are searched (module docstring); the band and the
        decision function are the same for both.
    d : float
        Feed-through (default 0). The Taylor remainders ``Gamma1``, ``Gamma2`` do not depend on
        it (``Gamma(s) - Gamma(0) = s c (sI - A)^-1 A^-1 h`` for every ``d``), only
        ``g0 = d - c A^-1 h`` and ``|Gamma|`` do: the decision function and the band are
        unchanged. A Tustin image of a sampled loop has ``d != 0``
        (:mod:`lcc_synth.analysis.as_run`). Only ``method = "grid"`` supports ``d != 0``.
    """
    if method not in ("grid", "hamiltonian"):
        raise ConfigError("method", f"must be 'grid' or 'hamiltonian', got {method!r}")
    d = float(d)
    if d != 0.0 and method != "grid":
        raise ConfigError("method", "a loop with a feed-through d != 0 needs method = 'grid'")
    A = np.asarray(A, dtype=float)
    h = np.asarray(h, dtype=float).reshape(-1)
    c = np.asarray(c, dtype=float).reshape(-1)
    if A.ndim != 2 or A.shape[0] != A.shape[1] or h.size != A.shape[0] or c.size != A.shape[0]:
        raise ConfigError(
            "loop", f"needs A (nx, nx), h (nx,), c (nx,); got {A.shape}, {h.shape}, {c.shape}"
        )
    # exact diagonal balancing (powers of 2): a change of units of the states costs no accuracy
    A, (scale, _) = sla.matrix_balance(A, permute=False, separate=True)
    h, c = h / scale, c * scale
    eigs = closed_loop_eigenvalues(A)
    band = string_band(eigs)
    plant, max_re = plant_verdict(eigs)
    plant_boundary = plant == "boundary"
    plant_stable = plant == "plant_stable"
    nan = float("nan")

    dec = None
    if np.isfinite(band):
        with np.errstate(all="ignore"):
            try:
                dec = _decision(A, h, c, d)
            except (np.linalg.LinAlgError, ValueError):
                dec = None
        if dec is not None and not (np.isfinite(dec.g0) and np.isfinite(dec.curvature)):
            dec = None

    if dec is None:  # an eigenvalue at 0: no DC gain, the formal response on the grid only
        solver = hessenberg_solver(A, h, c)
        w = _frequency_grid(eigs)
        mag = np.abs(solver(1j * w) + d)
        mag = np.where(np.isfinite(mag), mag, np.inf)
        pw, pv = _local_maxima(lambda x: np.abs(solver(1j * x) + d), w, mag, lowest=None)
        j = int(np.argmax(pv)) if pv.size else -1
        peak = float(pv[j]) if j >= 0 else float(mag[0])
        peak_w = float(pw[j]) if j >= 0 else float(w[0])
        return StringStabilityReport(
            plant_stable=plant_stable, string_stable=False, gamma_peak=peak,
            gamma_peak_omega=peak_w, max_real_eig=max_re, gamma_dc=nan,
            low_freq_curvature=nan, interior_peak=peak if j >= 0 else nan,
            interior_peak_omega=peak_w if j >= 0 else nan, method=method,
            verdict="boundary" if plant_boundary else "plant_unstable", band=band,
        )

    dc = abs(dec.g0)
    qmax, qmax_w, pw, pv = _grid_search(dec, eigs) if (
        method == "grid" or not plant_stable
    ) else (None, None, None, None)
    if method == "hamiltonian" and plant_stable:
        qmax, qmax_w = _hamiltonian_search(A, h, c, dec)
        peak, peak_w = hinf_norm_hamiltonian(A, h, c)
        interior = peak if peak_w > 0 and peak > dc else nan
        interior_w = peak_w if np.isfinite(interior) else nan
    else:
        if pv.size:
            j = int(np.argmax(pv))
            interior, interior_w = float(pv[j]), float(pw[j])
        else:
            interior, interior_w = nan, nan
    if np.isfinite(interior) and interior > dc:
        gamma_peak, gamma_peak_w = interior, interior_w
    else:
        gamma_peak, gamma_peak_w = dc, 0.0

    margin = -qmax
    if plant_boundary:
        verdict = "boundary"
    elif not plant_stable:
        verdict = "plant_unstable"
    elif margin > band:
        verdict = "string_stable"
    elif margin < -band:
        verdict = "string_unstable"
    else:
        verdict = "boundary"
    return StringStabilityReport(
        plant_stable=plant_stable,
        string_stable=verdict == "string_stable",
        gamma_peak=float(gamma_peak),
        gamma_peak_omega=float(gamma_peak_w),
        max_real_eig=max_re,
        gamma_dc=float(dc),
        low_freq_curvature=float(dec.curvature),
        interior_peak=float(interior),
        interior_peak_omega=float(interior_w),
        method=method,
        verdict=verdict,
        margin=float(margin) if plant_stable or plant_boundary else nan,
        margin_omega=float(qmax_w) if plant_stable or plant_boundary else nan,
        band=float(band),
    )


def string_stability(model, K, kh=0.0, method: str = "grid") -> StringStabilityReport:
    """Plant and head-to-tail string stability of the closed loop ``input = K x + kh v_h``.

    Definition 1 and eq. (25) on any layout with a head vehicle: the paper's one-CAV models
    (eqs. 9, 11, 14) and open platoons with several CAVs (``Gamma = V_N / V_h``, the last
    vehicle's velocity error over the head's). FD-LCC (eq. 12) and the ring have no head
    vehicle: ConfigError naming ``system.kind``.

    Parameters
    ----------
    model : LCCModel or PlatoonModel
        Any layout with a head vehicle.
    K, kh : array_like, float
        Feedback on the model's input: one CAV, ``nx`` entries and a number
        (:func:`lcc_synth.models.feedback.input_feedback`); several CAVs, one row and one
        entry per CAV (:meth:`lcc_synth.models.feedback.Gains.input_feedback`).
    method : {"grid", "hamiltonian"}
        See :func:`loop_string_stability`.

    Returns
    -------
    StringStabilityReport
        The exact verdict of :func:`loop_string_stability` (``"boundary"`` when too close to
        call at this precision).
    """
    if method not in ("grid", "hamiltonian"):
        raise ConfigError("method", f"must be 'grid' or 'hamiltonian', got {method!r}")
    Acl, h, c = head_to_tail_loop(model, K, kh)
    return loop_string_stability(Acl, h, c, method=method)


_VERDICT_TEXT = {
    "string_stable": "string stable",
    "string_unstable": "NOT string stable",
    "plant_unstable": "plant unstable",
    "boundary": "boundary (too close to call)",
    "not_linear": "not linear: measured in the simulator",
}


def verdict_text(verdict: str | None) -> str:
    """Words for a :attr:`StringStabilityReport.verdict` (``"n/a"`` for ``None``)."""
    return _VERDICT_TEXT.get(verdict, "n/a") if verdict is not None else "n/a"


def gains_string_stability(model, gains, method: str = "grid") -> StringStabilityReport:
    """:func:`string_stability` of a gains object on ``model``: anything with
    ``input_feedback(model) -> (K, kh)``, i.e. a :class:`~lcc_synth.models.feedback.Gains` of
    the model's layout (one CAV or several)."""
    K, kh = gains.input_feedback(model)
    return string_stability(model, K, kh, method=method)
