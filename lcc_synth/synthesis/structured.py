"""Structured H2 gains: each CAV may only use the states of a chosen set of vehicles.

One CAV: :func:`structured_h2` (convex restriction, then :func:`polish`). A platoon or ring
(a row pattern per CAV): :func:`initial_gain`, then :func:`descend` (also the robust
multi-model objective).

Two stages, both keeping the pattern exactly (forbidden entries are structural zeros, never
small numbers):

1. :func:`~lcc_synth.synthesis.lmi.convex_restriction` -- sparsity invariance. With
   ``X = blkdiag(X_P, X_N)`` (a full block on the states of the heard vehicles, a banded PSD
   block on the others) and ``Z`` zero
   outside the heard states, ``g = Z X^-1`` has the pattern. The zeros are built into the
   variables (cvxpy variables only exist for the free entries), and the Lyapunov LMI, whose
   sparsity is then banded, is split by chordal decomposition into small PSD cones over the
   cliques of its sparsity graph, so the SDP grows linearly with the string length. It gives a
   feasible structured gain and an upper bound on its H2 norm (loose for long strings: the
   band of ``X_N`` limits how far the certificate couples the vehicles).
2. :func:`polish` -- descent on the TRUE closed-loop H2 cost ``J(g)`` restricted to the pattern.
   Each step factorises the closed loop once (real Schur form) and solves the two Gramians'
   Lyapunov equations with it (:mod:`~lcc_synth.synthesis.lyapunov`). With at most
   ``NEWTON_MAX_FREE`` free entries the direction is Newton's, from the exact Hessian
   (``h2_hessian``, two more triangular solves per free entry; eigenvalues made positive
   far from the minimum); otherwise, or when it does not descend, the Anderson-Moore step (the
   minimiser of ``J`` for frozen Gramians on the pattern), then the projected gradient
   ``2 (R g + B' P) L``; an Armijo line search only accepts stabilising gains. Measured on
   CF-LCC with the pattern CAV + HDVs 1, 2 (2 cores, shared): 202 states 118 first-order
   steps in 22 s became 13 Newton steps in 2.4 s, 402 states 12 steps in about 25 s, the same
   H2 to 10 digits. Constrained polishing (``accept``, the string-aware design) keeps the
   first-order directions; it also polishes an open platoon's gain rows (a row pattern per
   CAV; ``R = r I`` decouples the Anderson-Moore step by row), so the string-aware design of
   a platoon is the one-CAV method with several inputs.

Always rank results by :func:`~lcc_synth.synthesis.h2.h2_norm` of the gain, never by the bound.

Platoons and rings -- structured multi-input H2: a cheap stabilising start (with ``method =
"lmi"`` also the convex restriction above, a block of ``X`` per set of states heard by the
same CAVs: :func:`structured_start`), then descent on the TRUE H2 norm with every CAV's row
pattern kept exactly (robust multi-model objectives included).

Polishing method
----------------
1. **Start** (:func:`initial_gain`): the full-information Riccati gain
   (:func:`~lcc_synth.synthesis.h2.platoon_riccati`) truncated to the pattern. On the
   ring the gain is defined modulo the conserved direction ``c``, so each row is first shifted
   by the multiple of ``c`` that minimises the dropped part (least squares), then truncated.
   When that does not stabilise, a penalty continuation: minimise
   ``J(K) + gamma |K off the pattern|^2`` from the Riccati gain for growing ``gamma`` until
   the truncated minimiser stabilises.
2. **Descent** (:func:`descend`): with at most :data:`DESCENT_NEWTON_MAX_FREE` free entries Newton
   steps from the exact Hessian (eigenvalues made positive), else BFGS on the free entries;
   an Armijo line search accepts only stabilising gains (an unstable trial costs ``inf``).
   Entries off the pattern are never touched: they stay exactly zero.

Why not the published sparsity-invariance LMI: its SDP on the 40 (80) ring states takes about
28 s at N = 20 and fails at N = 40 (the issue's figures); the start here costs one CARE (79
states: about 30 ms) and every Newton step ``2 k`` Lyapunov solves sharing one Schur form
(``k`` = free entries, 22 for one CAV with R = 5). Measured figures: ``benchmarks/
bench_synthesis_ring.py``.

Robust objectives (:func:`robust_objective`): over plants ``p_1..p_M`` (sampled HDV
parameters), ``"mean"`` minimises ``(1/M) sum_i h_i`` with ``h_i = sqrt(J_i)`` the true H2 norm
on member ``i``; ``"worst"`` minimises the smooth maximum ``t log((1/M) sum_i exp(h_i / t))``
(between ``max h_i - t log M`` and ``max h_i``) for a decreasing temperature ``t`` (5%, 1%,
0.2% of the mean), each stage warm-started; its gradient and Hessian are exact (softmax weights
times the members' derivatives plus the ``1/t`` covariance term). A trial gain unstable on any
member costs ``inf``, so every accepted gain is stable on every member.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.resources import progress, single_thread_blas
from lcc_synth.synthesis.h2 import (
    STABILITY_TOL,
    H2Plant,
    PlatoonPlant,
    SynthesisError,
    closed_loop_matrix,
    h2_cost,
    max_real_eig,
    platoon_cost,
    platoon_gradient,
    platoon_hessian,
    platoon_riccati,
    riccati_gain,
)
from lcc_synth.synthesis.lmi import (  # noqa: F401 (convex_restriction: its old home)
    LMIResult,
    convex_restriction,
    restriction_start,
)

__all__ = [
    "pattern_mask",
    "pattern_vehicles",
    "PolishResult",
    "NEWTON_MAX_FREE",
    "h2_hessian",
    "polish",
    "StructuredResult",
    "structured_h2",
    "DESCENT_NEWTON_MAX_FREE",
    "h2_objective",
    "robust_objective",
    "DescentResult",
    "descend",
    "initial_gain",
    "structured_start",
    "ROBUST_TEMPERATURES",
]


def pattern_mask(plant: H2Plant, vehicles: Iterable[int]) -> np.ndarray:
    """Boolean mask on the design states: True on the states of ``vehicles`` and the CAV."""
    vehicles = set(int(v) for v in vehicles) | {0}
    model = plant.model
    for v in vehicles:
        if v not in model.vehicles:
            raise ConfigError(
                "synthesis.pattern",
                f"vehicle {v} is not in the {model.kind} string (allowed {-model.m}..{model.n})",
            )
    return np.array([v in vehicles for v in plant.vehicle_of_state()])


def pattern_vehicles(plant: H2Plant, mask: np.ndarray) -> list[int]:
    """Vehicles whose states the mask allows (the CAV included)."""
    return sorted(set(int(v) for v in plant.vehicle_of_state()[np.asarray(mask, bool)]))


# --------------------------------------------------------------------------------------------
# Polishing on the true H2 cost
# --------------------------------------------------------------------------------------------


@dataclass
class PolishResult:
    """Outcome of :func:`polish`."""

    g: np.ndarray
    J: float
    iterations: int
    grad_norm: float
    converged: bool
    history: list[float] = field(default_factory=list)


#: Largest number of free gain entries for which :func:`polish` takes Newton steps (each
#: Hessian column costs two Lyapunov solves with the current closed loop's Schur form).
NEWTON_MAX_FREE = 24


def h2_hessian(plant: H2Plant, g, L, P, S, mask) -> np.ndarray:
    """Exact Hessian of the true H2 cost ``J`` on the free entries of the pattern ``mask``.

    With ``A_K = A + B g`` and the Gramians ``L``, ``P`` of :func:`h2_cost`, the gradient is
    ``G = 2 (r g + B' P) L``. Along a direction ``d`` the Gramians move by ``L'``, ``P'``:
    ``A_K L' + L' A_K' + B d L + L d' B' = 0`` and
    ``A_K' P' + P' A_K + d' B' P + P B d + r (d' g + g' d) = 0``, and
    ``G' = 2 (r d + B' P') L + 2 (r g + B' P) L'``. Column ``i`` is ``G'`` along the unit
    direction of the ``i``-th free entry: ``2k`` Lyapunov solves that reuse the Schur form
    ``S`` of ``A_K`` (:class:`~lcc_synth.synthesis.lyapunov.ClosedLoopSchur`).
    """
    idx = np.flatnonzero(mask)
    b = plant.B[:, 0]
    g = np.asarray(g, float).ravel()
    row = plant.r * g + b @ P
    Hs = np.empty((idx.size, idx.size))
    Pb = P @ b
    for c, j in enumerate(idx):
        d = np.zeros(g.size)
        d[j] = 1.0  # the unit direction of free entry j
        BdL = np.outer(b, L[j])  # B d L
        dL = S.solve(BdL + BdL.T)
        BdP = np.outer(Pb, d)  # P B d
        rg = plant.r * np.outer(d, g)  # r d' g
        dP = S.solve(BdP + BdP.T + rg + rg.T, transpose=True)
        dG = 2.0 * ((plant.r * d + b @ dP) @ L + row @ dL)
        Hs[:, c] = dG[idx]
    return 0.5 * (Hs + Hs.T)


def _newton_direction(plant: H2Plant, g, L, P, S, mask, grad) -> np.ndarray | None:
    """Newton step on the free entries (``None`` when the pattern has too many of them).

    Where the Hessian is not positive definite (far from the minimum) its eigenvalues are
    replaced by their absolute values, floored at ``1e-8`` of the largest: the step is then
    always a descent direction and reduces to Newton's near a strict minimum.
    """
    idx = np.flatnonzero(mask)
    if S is None or idx.size > NEWTON_MAX_FREE:
        return None
    lam, V = np.linalg.eigh(h2_hessian(plant, g, L, P, S, mask))
    lam = np.abs(lam)
    if not (np.all(np.isfinite(lam)) and lam.max() > 0):
        return None
    lam = np.maximum(lam, 1e-8 * lam.max())
    d = np.zeros_like(g)
    d[idx] = -V @ ((V.T @ grad[idx]) / lam)
    return d if np.all(np.isfinite(d)) else None


def _am_direction(plant: H2Plant | PlatoonPlant, g, L, P, mask) -> np.ndarray:
    """Anderson-Moore step: ``g* = argmin over the pattern of tr((Q + g'Rg) L)`` with the cross
    term ``2 B'P L`` frozen, i.e. ``R g*_P L_PP = -(B' P L)_P`` (several inputs: row by row,
    ``R = r I``); returns ``g* - g`` (a row whose system is singular: no step)."""
    rows = np.atleast_2d(mask)
    G = np.atleast_2d(g)
    BPL = plant.B.T @ P @ L
    D = np.zeros_like(G)
    for k in range(rows.shape[0]):
        idx = np.flatnonzero(rows[k])
        rhs = -BPL[k, idx]
        try:
            gp = np.linalg.solve(plant.r * L[np.ix_(idx, idx)].T, rhs)
        except np.linalg.LinAlgError:
            continue
        D[k, idx] = gp - G[k, idx]
    return D.reshape(np.shape(g))


@single_thread_blas
def polish(
    plant: H2Plant | PlatoonPlant,
    g0: np.ndarray,
    mask: np.ndarray,
    tol: float = 1e-7,
    max_iter: int = 500,
    accept: Callable[[np.ndarray], bool] | None = None,
    max_rejected: int = 10,
) -> PolishResult:
    """Minimise the true H2 cost over gains with the pattern ``mask``, from stabilising ``g0``.

    One CAV: ``g0`` and ``mask`` on the design states. An open platoon (``PlatoonPlant``, not a
    ring): ``n_cav x nx``, a row per CAV; the directions are the first-order ones.

    Parameters
    ----------
    tol : float
        Stop when the projected gradient's norm is below ``tol * max(1, J)`` or the relative
        decrease of ``J`` over a step is below ``tol**2``.
    accept : callable, optional
        Extra feasibility test on a trial gain (e.g. string stability); a step is accepted only
        when it holds (feasible-direction descent). ``g0`` must satisfy it.
    max_rejected : int
        Per direction, give up after this many Armijo-acceptable steps that ``accept`` refused
        (the direction points out of the feasible set; the next direction is tried).

    Raises
    ------
    SynthesisError
        ``g0`` does not stabilise the plant (or fails ``accept``).
    """
    if plant.conserved is not None:  # a ring
        raise SynthesisError("polish works on the full state: a ring's gain is descended on its "
                             "invariant hyperplane (descend)")  # fmt: skip
    mask = np.asarray(mask, bool)
    g = np.where(mask, np.asarray(g0, dtype=float).reshape(mask.shape), 0.0)
    n_in = plant.B.shape[1]
    J, L, P, S = plant.polish_cost(g)
    if not math.isfinite(J):
        raise SynthesisError("polishing needs a stabilising initial gain")
    if accept is not None and not accept(g):
        raise SynthesisError("polishing: the initial gain violates the required constraint")
    hist = [J]
    gn = math.inf
    converged = False
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007
        if it == 1 or it % 25 == 0:
            progress(f"synthesis: polish iteration {it}/{max_iter}, H2^2 = {J:.6g}")
        grad = 2.0 * (plant.r * g.reshape(n_in, -1) + plant.B.T @ P) @ L
        grad = np.where(mask, grad.reshape(mask.shape), 0.0)
        gn = float(np.linalg.norm(grad))
        if gn <= tol * max(1.0, J):
            converged = True
            break
        step_found = False
        one = accept is None and n_in == 1  # Newton: one CAV, unconstrained
        newton = _newton_direction(plant, g, L, P, S, mask, grad) if one else None
        directions = [_am_direction(plant, g, L, P, mask), -grad]
        for d in ([newton] if newton is not None else []) + directions:
            slope = float(grad.ravel() @ d.ravel())
            if not slope < 0:
                continue
            t = 1.0
            rejected = 0  # steps refused by `accept` (each costs a global check)
            for _ in range(40):
                trial = g + t * d
                Jt, Lt, Pt, St = plant.polish_cost(trial)
                if Jt <= J + 1e-4 * t * slope:
                    if accept is None or accept(trial):
                        step_found = True
                        break
                    rejected += 1
                    if rejected > max_rejected:
                        break
                t *= 0.5
            if step_found:
                break
        if not step_found:
            converged = True  # no descent possible at machine precision
            break
        rel = (J - Jt) / max(J, 1e-300)
        g, J, L, P, S = trial, Jt, Lt, Pt, St
        hist.append(J)
        if rel < tol**2:
            converged = True
            break
    return PolishResult(g, J, it, gn, converged, hist)


# --------------------------------------------------------------------------------------------
# The whole structured design
# --------------------------------------------------------------------------------------------


@dataclass
class StructuredResult:
    """A structured gain with everything a report needs."""

    g: np.ndarray
    mask: np.ndarray
    h2: float
    h2_restriction: float
    h2_lmi_bound: float
    lmi: LMIResult | None
    polish: PolishResult | None
    start: str
    timings: dict[str, float]


def _initial_gain(plant: H2Plant, mask: np.ndarray) -> tuple[np.ndarray, str]:
    """A stabilising gain on the pattern without an SDP: the Riccati gain truncated to the
    pattern when it stabilises, else a CAV-only damping gain found by a small scan."""
    g_full, _ = riccati_gain(plant)
    g = np.where(mask, g_full, 0.0)
    if max_real_eig(closed_loop_matrix(plant, g)) < -STABILITY_TOL:
        return g, "truncated_riccati"
    cav = plant.vehicle_of_state() == 0
    for kv in (-0.25, -0.5, -1.0, -2.0):
        for ks in (0.0, 0.1, 0.5):
            g = np.zeros(plant.nx)
            for j in np.flatnonzero(cav):
                nm = plant.state_names[j]
                g[j] = kv if nm.startswith("v_") else (ks if nm.startswith("s_") else -ks)
            if max_real_eig(closed_loop_matrix(plant, g)) < -STABILITY_TOL:
                return g, "cav_damping"
    raise SynthesisError("no stabilising initial gain found for this pattern")


@single_thread_blas
def structured_h2(
    plant: H2Plant,
    vehicles: Iterable[int],
    method: str = "lmi",
    tol: float = 1e-7,
    max_iter: int = 500,
    band: int = 4,
) -> StructuredResult:
    """Structured H2 design on the pattern "CAV + ``vehicles``".

    Parameters
    ----------
    method : {"lmi", "direct"}
        ``"lmi"``: convex restriction (bound + feasible gain), then polishing from the better
        of that gain and the truncated Riccati gain. ``"direct"``: no SDP, polish from the
        truncated Riccati gain (or a CAV damping gain): the fast path for long strings.
    band : int
        Coupling range (vehicles) of the non-heard block of X in the convex restriction.
    """
    mask = pattern_mask(plant, vehicles)
    timings = {}
    lmi = None
    starts = []
    if method == "lmi":
        t0 = time.perf_counter()
        progress(f"synthesis: LMI solve (convex restriction, {plant.nx} states, Clarabel)")
        lmi, J_lmi = restriction_start(plant, mask, band)
        timings["lmi"] = time.perf_counter() - t0
        starts.append((J_lmi, lmi.g, "convex_restriction"))
    elif method != "direct":
        raise ConfigError("synthesis.method", f"must be 'lmi' or 'direct', got {method!r}")
    t0 = time.perf_counter()
    try:
        g_init, name = _initial_gain(plant, mask)
        starts.append((h2_cost(plant, g_init)[0], g_init, name))
    except SynthesisError:
        if not starts:
            raise
    J0, g0, start = min(starts, key=lambda s: s[0])
    pol = polish(plant, g0, mask, tol=tol, max_iter=max_iter)
    timings["polish"] = time.perf_counter() - t0
    h2_restr = math.sqrt(starts[0][0]) if lmi is not None else math.nan
    return StructuredResult(
        g=pol.g,
        mask=mask,
        h2=math.sqrt(pol.J),
        h2_restriction=h2_restr,
        h2_lmi_bound=lmi.bound if lmi is not None else math.nan,
        lmi=lmi,
        polish=pol,
        start=start,
        timings=timings,
    )


#: Largest number of free entries for Newton steps (each Hessian column: two Lyapunov solves).
DESCENT_NEWTON_MAX_FREE = 160

#: ``"worst"``: the smooth-max temperatures, as fractions of the members' mean H2.
ROBUST_TEMPERATURES = (0.05, 0.01, 0.002)

#: An objective: ``fun(K, order)`` -> ``(f, grad, hess)``; ``order`` 0: value only, 1: with the
#: gradient (``n_cav x nx``), 2: also ``hess(free)``, the Hessian on the free entries.
Objective = Callable[[np.ndarray, int], tuple[float, np.ndarray | None, Callable | None]]


def h2_objective(plant: PlatoonPlant, penalty: np.ndarray | None = None) -> Objective:
    """The squared true H2 norm ``J(K)`` of ``plant`` (plus ``sum(penalty * K**2)``)."""

    def fun(K, order):
        ev = platoon_cost(plant, K)
        if not ev.stable:
            return math.inf, None, None
        f = ev.J
        grad = hess = None
        if order >= 1:
            grad = platoon_gradient(plant, ev)
        if penalty is not None:
            f += float(np.sum(penalty * K**2))
            if grad is not None:
                grad = grad + 2.0 * penalty * K
        if order >= 2:
            def hess(free):
                H = platoon_hessian(plant, ev, free)
                if penalty is not None:
                    H[np.diag_indices_from(H)] += 2.0 * penalty.ravel()[free]
                return H
        return f, grad, hess

    return fun


def robust_objective(
    plants: Sequence[PlatoonPlant], objective: str = "mean", temperature: float = 0.0
) -> Objective:
    """Mean (or smooth worst, at ``temperature`` > 0) true H2 norm over ``plants``
    (see the module docstring)."""
    M = len(plants)

    def fun(K, order):
        evs = [platoon_cost(p, K) for p in plants]
        if not all(e.stable for e in evs):
            return math.inf, None, None
        h = np.sqrt([e.J for e in evs])
        if objective == "mean":
            w = np.full(M, 1.0 / M)
            f = float(h.mean())
        else:
            z = (h - h.max()) / temperature
            w = np.exp(z) / np.exp(z).sum()
            f = float(h.max() + temperature * math.log(np.exp(z).mean()))
        if order == 0:
            return f, None, None
        gJ = [platoon_gradient(p, e) for p, e in zip(plants, evs, strict=True)]
        gh = [g / (2.0 * hi) for g, hi in zip(gJ, h, strict=True)]
        grad = sum(wi * g for wi, g in zip(w, gh, strict=True))
        hess = None
        if order >= 2:
            def hess(free):
                H = np.zeros((free.size, free.size))
                for wi, p, e, g, hi in zip(w, plants, evs, gh, h, strict=True):
                    gf = g.ravel()[free]
                    Hj = platoon_hessian(p, e, free)
                    H += wi * (Hj / (2.0 * hi) - np.outer(gf, gf) / hi)
                if objective != "mean":
                    G = np.array([g.ravel()[free] for g in gh])
                    mean = w @ G
                    H += ((G * w[:, None]).T @ G - np.outer(mean, mean)) / temperature
                return H

        return f, grad, hess

    return fun


@dataclass
class DescentResult:
    """Outcome of :func:`descend`."""

    K: np.ndarray
    f: float
    iterations: int
    grad_norm: float
    converged: bool
    method: str
    history: list[float] = field(default_factory=list)


def _newton(H: np.ndarray, g: np.ndarray) -> np.ndarray | None:
    lam, U = np.linalg.eigh(H)
    lam = np.abs(lam)
    if not (np.all(np.isfinite(lam)) and lam.max() > 0):
        return None
    lam = np.maximum(lam, 1e-8 * lam.max())
    d = -U @ ((U.T @ g) / lam)
    return d if np.all(np.isfinite(d)) else None


@single_thread_blas
def descend(
    fun: Objective,
    K0: np.ndarray,
    mask: np.ndarray,
    tol: float = 1e-7,
    max_iter: int = 500,
    label: str = "polish",
) -> DescentResult:
    """Minimise ``fun`` over gains with the pattern ``mask`` (``n_cav x nx`` booleans) from
    ``K0`` (which must make ``fun`` finite: stabilising).

    Stops when the gradient's norm on the free entries is below ``tol * max(1, f)``, the
    relative decrease over a step below ``tol**2``, or no step decreases ``f``.

    Raises
    ------
    SynthesisError
        ``K0`` does not stabilise.
    """
    mask = np.asarray(mask, bool)
    free = np.flatnonzero(mask.ravel())
    K = np.where(mask, np.asarray(K0, float), 0.0)
    newton_ok = free.size <= DESCENT_NEWTON_MAX_FREE
    f, grad, hess = fun(K, 2 if newton_ok else 1)
    if not math.isfinite(f):
        raise SynthesisError(f"{label}: the initial gain does not stabilise the plant")
    hist = [f]
    Hinv = None  # BFGS inverse Hessian on the free entries
    gn = math.inf
    converged = False
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007
        if it == 1 or it % 25 == 0:
            progress(f"synthesis: {label} iteration {it}/{max_iter}, objective {f:.8g}")
        g = grad.ravel()[free]
        gn = float(np.linalg.norm(g))
        if gn <= tol * max(1.0, abs(f)):
            converged = True
            break
        dirs = []
        if newton_ok:
            d = _newton(hess(free), g)
            if d is not None:
                dirs.append(d)
        else:
            if Hinv is None:
                Hinv = np.eye(free.size) * (1.0 / max(gn, 1e-300))
            dirs.append(-Hinv @ g)
        dirs.append(-g / max(gn, 1e-300))
        step = None
        for d in dirs:
            slope = float(g @ d)
            if not slope < 0:
                continue
            t = 1.0
            for _ in range(50):
                trial = K.copy()
                trial.ravel()[free] += t * d
                ft = fun(trial, 0)[0]
                if ft <= f + 1e-4 * t * slope:
                    step = (trial, ft, t * d)
                    break
                t *= 0.5
            if step is not None:
                break
        if step is None:
            converged = True  # no descent possible at machine precision
            break
        trial, ft, s = step
        ft, gt, ht = fun(trial, 2 if newton_ok else 1)
        if not newton_ok:
            y = gt.ravel()[free] - g
            sy = float(s @ y)
            if sy > 1e-12 * np.linalg.norm(s) * np.linalg.norm(y):
                rho = 1.0 / sy
                I = np.eye(free.size)
                Hinv = (I - rho * np.outer(s, y)) @ Hinv @ (I - rho * np.outer(y, s)) + rho * (
                    np.outer(s, s)
                )
        rel = (f - ft) / max(abs(f), 1e-300)
        K, f, grad, hess = trial, ft, gt, ht
        hist.append(f)
        if rel < tol**2:
            converged = True
            break
    return DescentResult(K, f, it, gn, converged, "newton" if newton_ok else "bfgs", hist)


def _shift_modulo_c(plant: PlatoonPlant, K: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Ring: add to each row the multiple of ``c`` that minimises its part off the pattern
    (the closed loop is unchanged); open platoon: ``K``."""
    c = plant.conserved
    if c is None:
        return K
    K = K.copy()
    for k in range(K.shape[0]):
        off = ~mask[k]
        cc = float(c[off] @ c[off])
        if cc > 0:
            K[k] -= (float(c[off] @ K[k, off]) / cc) * c
    return K


def structured_start(
    plant: PlatoonPlant,
    mask: np.ndarray,
    K_ric: np.ndarray | None = None,
    method: str = "direct",
    band: int = 4,
) -> tuple[np.ndarray, str, LMIResult | None]:
    """The start of a platoon's / ring's polish, as :func:`structured_h2` starts one CAV's:
    ``method = "direct"`` :func:`initial_gain`; ``"lmi"`` also the convex restriction
    (:func:`restriction_start`), and the start is the one of lower true H2 (the restriction's
    when :func:`initial_gain` finds none).

    Returns
    -------
    K0 : numpy.ndarray
        The start (``n_cav x nx``, zero off the patterns).
    how : str
        ``"convex_restriction"``, ``"truncated_riccati"`` or ``"penalty_continuation"``.
    lmi : LMIResult or None
        The restriction (its gain, bound and solver figures); ``None`` for ``"direct"``.

    Raises
    ------
    SynthesisError
        The restriction fails (``"lmi"``), or no stabilising start was found.
    """
    mask = np.asarray(mask, bool)
    starts = []
    lmi = None
    if method == "lmi":
        progress(f"synthesis: LMI solve (convex restriction, {plant.nx} states, Clarabel)")
        lmi, J_lmi = restriction_start(plant, mask, band)
        starts.append((J_lmi, lmi.g, "convex_restriction"))
    elif method != "direct":
        raise ConfigError("synthesis.method", f"must be 'lmi' or 'direct', got {method!r}")
    try:
        K0, how = initial_gain(plant, mask, K_ric)
        starts.append((platoon_cost(plant, K0).J, K0, how))
    except SynthesisError:
        if not starts:
            raise
    _, K0, how = min(starts, key=lambda s: s[0])
    return np.where(mask, K0, 0.0), how, lmi


def initial_gain(
    plant: PlatoonPlant, mask: np.ndarray, K_ric: np.ndarray | None = None
) -> tuple[np.ndarray, str]:
    """A stabilising gain with the pattern ``mask`` and how it was found
    (``"truncated_riccati"`` or ``"penalty_continuation"``; see the module docstring).

    Raises
    ------
    SynthesisError
        No stabilising gain of the pattern was found.
    """
    mask = np.asarray(mask, bool)
    if K_ric is None:
        K_ric = platoon_riccati(plant)[0]
    Ks = _shift_modulo_c(plant, K_ric, mask)
    K = np.where(mask, Ks, 0.0)
    if platoon_cost(plant, K).stable:
        return K, "truncated_riccati"
    J_ric = platoon_cost(plant, K_ric).J
    Kc = K_ric
    allm = np.ones_like(mask)
    for gamma in J_ric * np.logspace(-3, 6, 19):
        pen = np.where(mask, 0.0, gamma)
        Kc = descend(h2_objective(plant, pen), Kc, allm, tol=1e-6, max_iter=50,
                     label="penalty continuation").K  # fmt: skip
        K = np.where(mask, _shift_modulo_c(plant, Kc, mask), 0.0)
        if platoon_cost(plant, K).stable:
            return K, "penalty_continuation"
    raise SynthesisError("no stabilising gain found for this pattern (truncated Riccati and "
                         "the penalty continuation both fail)")  # fmt: skip
