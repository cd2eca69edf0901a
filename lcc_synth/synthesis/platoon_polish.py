"""Structured multi-input H2 for platoons: a cheap stabilising start, then descent on the TRUE
H2 norm with every CAV's row pattern kept exactly (robust multi-model objectives included).

Polishing method
----------------
1. **Start** (:func:`initial_gain`): the full-information Riccati gain
   (:func:`~lcc_synth.synthesis.platoon_h2.platoon_riccati`) truncated to the pattern. On the
   ring the gain is defined modulo the conserved direction ``c``, so each row is first shifted
   by the multiple of ``c`` that minimises the dropped part (least squares), then truncated.
   When that does not stabilise, a penalty continuation: minimise
   ``J(K) + gamma |K off the pattern|^2`` from the Riccati gain for growing ``gamma`` until
   the truncated minimiser stabilises.
2. **Descent** (:func:`descend`): with at most :data:`NEWTON_MAX_FREE` free entries Newton
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
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from lcc_synth.resources import progress
from lcc_synth.synthesis.h2 import SynthesisError, single_thread_blas
from lcc_synth.synthesis.platoon_h2 import (
    PlatoonPlant,
    platoon_cost,
    platoon_gradient,
    platoon_hessian,
    platoon_riccati,
)

__all__ = [
    "NEWTON_MAX_FREE",
    "h2_objective",
    "robust_objective",
    "DescentResult",
    "descend",
    "initial_gain",
    "ROBUST_TEMPERATURES",
]

#: Largest number of free entries for Newton steps (each Hessian column: two Lyapunov solves).
NEWTON_MAX_FREE = 160

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
    newton_ok = free.size <= NEWTON_MAX_FREE
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
    c = plant.model.conserved
    if c is None:
        return K
    K = K.copy()
    for k in range(K.shape[0]):
        off = ~mask[k]
        cc = float(c[off] @ c[off])
        if cc > 0:
            K[k] -= (float(c[off] @ K[k, off]) / cc) * c
    return K


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
