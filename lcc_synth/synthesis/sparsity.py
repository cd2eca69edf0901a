"""Sparsity-promoting H2 design: which vehicles should each CAV listen to?

One CAV: the group-sparsity ADMM Pareto sweep (:func:`sparsity_sweep`); a platoon or ring: the
greedy per-CAV communication-range front (:func:`range_pareto`, below).

One CAV, method: the ADMM of Lin, Fardad & Jovanovic (IEEE TAC 2013) with a *group* penalty,
one group per vehicle other than the CAV (its two gains), for

    minimise  J(F) + gamma * sum_i w_i ||F_i||_2        (J = true squared H2 cost)

* F-step: ``min J(F) + rho/2 ||F - U||^2`` by Anderson-Moore / gradient descent with an Armijo
  search that keeps the closed loop stable (two Lyapunov equations per step);
* G-step: block soft-thresholding ``G_i = max(0, 1 - gamma w_i / (rho ||V_i||)) V_i``;
* dual update ``Lambda += rho (F - G)``.

Group weights ``w_i`` are uniform or reweighted by the unstructured optimum
(``w_i = 1 / (||F*_i|| + eps)``, normalised to mean 1). The penalty ``gamma`` is swept upward
with warm starts; every distinct identified pattern is then *re-polished* on the true H2 cost
(:func:`~lcc_synth.synthesis.structured.polish`), starting from the best of the ADMM gain, the
truncated Riccati gain and the polished gain of any pattern it contains (so a larger pattern
never scores worse than one of its subsets). The Pareto front is the set of non-dominated
``(vehicles heard, H2)`` points.

Platoons and rings, how far must each CAV hear? (:func:`range_pareto`). Method: greedy
forward selection of every CAV's own communication range. All CAVs start at
range 0 (decentralised: each CAV hears itself only; the start of
:func:`~lcc_synth.synthesis.structured.initial_gain`, then polished). Each step tries
widening one CAV's range by one vehicle on each side, polishes every candidate on the true H2
from the current gain (feasible: the pattern only grows, so the start is stabilising and the
true H2 never increases), and keeps the candidate with the lowest H2. It stops when every CAV
hears every vehicle (the last point is then the full-information optimum). The chosen design
is the point with the fewest heard vehicles whose H2 is within ``(1 + max_loss)`` of the
Riccati optimum. Greedy: the front is an upper bound on the exact one (which would need every
combination of ranges), and exact for a single CAV (the ranges are then nested).

Cost: ``sum_k Rmax_k`` steps of ``n_cav`` polishes each, warm-started (one CAV on the
20-vehicle ring: 10 points in about 0.3 s; see ``benchmarks/bench_synthesis_ring.py``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.resources import progress, single_thread_blas
from lcc_synth.synthesis.h2 import (
    H2Plant,
    PlatoonPlant,
    SynthesisError,
    h2_cost,
    pattern_rows,
    riccati_gain,
)
from lcc_synth.synthesis.structured import descend, h2_objective, initial_gain, pattern_mask, polish

__all__ = [
    "ParetoPoint",
    "SparsityResult",
    "admm_group",
    "sparsity_sweep",
    "full_range",
    "range_patterns",
    "range_pareto",
]


@dataclass
class ParetoPoint:
    """One identified pattern after re-polishing."""

    vehicles: list[int]  # heard vehicles other than the CAV
    gamma: float  # smallest penalty that produced the pattern
    h2: float  # true H2 norm of the polished gain
    g: np.ndarray
    on_front: bool = False

    @property
    def count(self) -> int:
        return len(self.vehicles)


@dataclass
class SparsityResult:
    """All patterns found by the sweep and the Pareto front."""

    points: list[ParetoPoint]
    h2_full: float  # unstructured optimum (every vehicle heard)
    gammas: list[float]
    weights: dict[int, float]
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def front(self) -> list[ParetoPoint]:
        return sorted((p for p in self.points if p.on_front), key=lambda p: p.count)


def _groups(plant: H2Plant) -> dict[int, np.ndarray]:
    veh = plant.vehicle_of_state()
    return {int(v): np.flatnonzero(veh == v) for v in dict.fromkeys(veh)}


def _f_step(plant, F, U, rho, iters=2, tol=1e-9):
    """``min J(F) + rho/2 ||F - U||^2`` from stabilising ``F`` (AM direction + Armijo)."""
    J, L, P = h2_cost(plant, F)
    f = J + 0.5 * rho * float(np.sum((F - U) ** 2))
    R = plant.r
    for _ in range(iters):
        grad = (2.0 * (R * F.reshape(1, -1) + plant.B.T @ P) @ L).ravel() + rho * (F - U)
        if np.linalg.norm(grad) <= tol * max(1.0, f):
            break
        lhs = 2.0 * R * L + rho * np.eye(plant.nx)
        rhs = rho * U - 2.0 * (plant.B.T @ P @ L).ravel()
        d_am = np.linalg.solve(lhs.T, rhs) - F
        moved = False
        for d in (d_am, -grad):
            slope = float(grad @ d)
            if not slope < 0:
                continue
            t = 1.0
            for _ in range(40):
                trial = F + t * d
                Jt, Lt, Pt = h2_cost(plant, trial)
                ft = Jt + 0.5 * rho * float(np.sum((trial - U) ** 2))
                if ft <= f + 1e-4 * t * slope:
                    moved = True
                    break
                t *= 0.5
            if moved:
                break
        if not moved:
            break
        rel = (f - ft) / max(abs(f), 1e-300)
        F, J, L, P, f = trial, Jt, Lt, Pt, ft
        if rel < 1e-12:
            break
    return F


def admm_group(
    plant: H2Plant,
    gamma: float,
    F0: np.ndarray,
    weights: dict[int, float],
    rho: float = 10.0,
    max_iter: int = 200,
    tol: float = 1e-3,
) -> np.ndarray:
    """Group-sparse gain ``G`` (exact zeros on dropped vehicles) for penalty ``gamma``."""
    groups = _groups(plant)
    F = np.asarray(F0, float).copy()
    G = F.copy()
    Lam = np.zeros_like(F)
    for _ in range(max_iter):
        F = _f_step(plant, F, G - Lam / rho, rho)
        V = F + Lam / rho
        G_old = G
        G = V.copy()
        for v, idx in groups.items():
            if v == 0:
                continue
            nv = float(np.linalg.norm(V[idx]))
            a = gamma * weights[v] / rho
            G[idx] = 0.0 if nv <= a else (1.0 - a / nv) * V[idx]
        Lam = Lam + rho * (F - G)
        scale = max(1.0, float(np.linalg.norm(F)))
        if (
            np.linalg.norm(F - G) <= tol * scale
            and np.linalg.norm(G - G_old) <= tol * scale
        ):
            break
    return G


@single_thread_blas
def sparsity_sweep(
    plant: H2Plant,
    gammas: list[float] | None = None,
    reweight: bool = True,
    rho: float = 10.0,
    n_gamma: int = 12,
    refine: int = 12,
) -> SparsityResult:
    """Sweep the group penalty and return the patterns found and their Pareto front.

    Parameters
    ----------
    gammas : list of float, optional
        Penalties (>= 0) in increasing order; default ``n_gamma`` values log-spaced over
        ``[1e-3, 10] * J*`` (``J*`` the unstructured optimal squared H2 cost).
    reweight : bool
        Group weights from the unstructured optimum (else uniform).
    rho : float
        ADMM penalty parameter.
    refine : int
        At most this many extra penalties, each the geometric mean of two neighbouring
        penalties whose patterns differ by more than one vehicle (fills gaps in the front).
    """
    t0 = time.perf_counter()
    g_opt, _ = riccati_gain(plant)
    J_opt, _, _ = h2_cost(plant, g_opt)
    groups = _groups(plant)
    if reweight:
        w = {v: 1.0 / (float(np.linalg.norm(g_opt[idx])) + 1e-3) for v, idx in groups.items()}
    else:
        w = {v: 1.0 for v in groups}
    others = [v for v in groups if v != 0]
    mean = float(np.mean([w[v] for v in others])) if others else 1.0
    w = {v: x / mean for v, x in w.items()}
    if gammas is None:
        gammas = list(J_opt * np.logspace(-3, 1, n_gamma))
    gammas = [float(x) for x in gammas]
    if any(not (math.isfinite(x) and x >= 0) for x in gammas):
        raise ConfigError("sparsity.gammas", "must be finite numbers >= 0")
    gammas = sorted(gammas)
    found: dict[tuple[int, ...], tuple[float, np.ndarray]] = {}
    runs: list[tuple[float, tuple[int, ...], np.ndarray]] = []

    def run(gamma: float, F0: np.ndarray) -> tuple[np.ndarray, tuple[int, ...]]:
        G = admm_group(plant, gamma, F0, w, rho=rho)
        heard = tuple(v for v in others if np.any(G[groups[v]] != 0))
        runs.append((gamma, heard, G))
        if heard not in found or gamma < found[heard][0]:
            found[heard] = (gamma, G)
        return G, heard

    def stabilising(G: np.ndarray) -> bool:
        return math.isfinite(h2_cost(plant, G)[0])

    F = g_opt.copy()
    for i, gamma in enumerate(gammas, 1):
        progress(f"synthesis: sparsity sweep, penalty {i}/{len(gammas)} (gamma = {gamma:.3g})")
        G, heard = run(gamma, F)
        if stabilising(G):
            F = G  # warm start along the sweep (G has the exact zeros)
        if not heard:
            break  # larger penalties keep the CAV-only pattern
    # refinement: bisect (geometrically) between penalties whose patterns differ by more than
    # one vehicle, warm-started from the smaller penalty's gain
    for _ in range(int(refine)):
        rs = sorted(runs, key=lambda r: r[0])
        gaps = [
            (a, b)
            for a, b in zip(rs, rs[1:], strict=False)
            if len(a[1]) - len(b[1]) > 1 and b[0] > 1.01 * a[0]
        ]
        if not gaps:
            break
        a, b = min(gaps, key=lambda ab: len(ab[1][1]))  # sparse end of the front first
        gm = math.sqrt(a[0] * b[0]) if a[0] > 0 else b[0] / 10.0
        run(gm, a[2] if stabilising(a[2]) else g_opt)
    # every sweep ends at the CAV-only and all-vehicles patterns for a complete front
    found.setdefault((), (math.inf, np.zeros(plant.nx)))
    found.setdefault(tuple(others), (0.0, g_opt))
    t_admm = time.perf_counter() - t0
    polished: dict[tuple[int, ...], ParetoPoint] = {}
    g_opt_J = J_opt
    for i, heard in enumerate(sorted(found, key=len), 1):
        progress(f"synthesis: sparsity sweep, polishing pattern {i}/{len(found)}")
        gamma, G = found[heard]
        mask = pattern_mask(plant, heard)
        starts = []
        for cand in [G, np.where(mask, g_opt, 0.0)] + [
            p.g for h, p in polished.items() if set(h) <= set(heard)
        ]:
            J, _, _ = h2_cost(plant, np.where(mask, cand, 0.0))
            if math.isfinite(J):
                starts.append((J, cand))
        if not starts:
            try:
                from lcc_synth.synthesis.structured import _initial_gain

                g_init, _ = _initial_gain(plant, mask)
                starts.append((h2_cost(plant, g_init)[0], g_init))
            except SynthesisError:
                continue
        _, g0 = min(starts, key=lambda s: s[0])
        pol = polish(plant, g0, mask)
        if set(heard) == set(others):
            pol_J = min(pol.J, g_opt_J)
            g_use = pol.g if pol.J <= g_opt_J else g_opt
        else:
            pol_J, g_use = pol.J, pol.g
        polished[heard] = ParetoPoint(list(heard), gamma, math.sqrt(pol_J), g_use)
    points = list(polished.values())
    best = math.inf
    for p in sorted(points, key=lambda p: (p.count, p.h2)):
        if p.h2 < best * (1 - 1e-12):
            p.on_front = True
            best = p.h2
    return SparsityResult(
        points=sorted(points, key=lambda p: (p.count, p.h2)),
        h2_full=math.sqrt(J_opt),
        gammas=gammas,
        weights=w,
        timings={"admm": t_admm, "total": time.perf_counter() - t0},
    )


def full_range(plant: PlatoonPlant, cav: int) -> int:
    """The smallest communication range with which CAV ``cav`` hears every vehicle."""
    p = plant.model.platoon
    return p.size // 2 if p.ring else max(cav - 1, p.size - cav)


def range_patterns(plant: PlatoonPlant, ranges: dict[int, int]) -> dict[int, tuple[int, ...]]:
    """Each CAV's heard positions for its own range (as
    :func:`~lcc_synth.synthesis.config.comm_range_pattern`, per CAV)."""
    p = plant.model.platoon
    N = p.size
    out = {}
    for i, R in ranges.items():
        if p.ring:
            out[i] = tuple(sorted({(i - 1 + d) % N + 1 for d in range(-R, R + 1)}))
        else:
            out[i] = tuple(j for j in range(i - R, i + R + 1) if 1 <= j <= N)
    return out


def range_pareto(
    plant: PlatoonPlant, h2_star: float, max_loss: float = 0.01, tol: float = 1e-7,
    max_iter: int = 500,
) -> tuple[list[dict], np.ndarray, dict[int, tuple[int, ...]]]:
    """The greedy per-CAV range front (module docstring).

    Returns
    -------
    points : list of dict
        ``ranges`` (``{"u_i": R}``), ``heard`` (vehicles heard, summed over the CAVs), ``h2``,
        ``loss`` (``h2 / h2_star - 1``), ``chosen``.
    K : numpy.ndarray
        The chosen point's gain.
    patterns : dict
        The chosen point's patterns.
    """
    cavs = plant.model.cavs
    ranges = {i: 0 for i in cavs}
    rmax = {i: full_range(plant, i) for i in cavs}
    mask = pattern_rows(plant, range_patterns(plant, ranges))
    K0, _ = initial_gain(plant, mask)
    res = descend(h2_objective(plant), K0, mask, tol, max_iter, "sparsity R = 0")
    front = [(dict(ranges), mask, res.K, res.f)]
    while any(ranges[i] < rmax[i] for i in cavs):
        best = None
        for i in cavs:
            if ranges[i] >= rmax[i]:
                continue
            trial = {**ranges, i: ranges[i] + 1}
            m = pattern_rows(plant, range_patterns(plant, trial))
            r = descend(h2_objective(plant), front[-1][2], m, tol, max_iter,
                        f"sparsity {trial}")  # fmt: skip
            if best is None or r.f < best[3]:
                best = (trial, m, r.K, r.f)
        ranges = best[0]
        front.append(best)
        progress(f"synthesis: sparsity ranges {ranges}, H2 {math.sqrt(best[3]):.6g}")
    points = []
    for rg, m, _, J in front:
        h = math.sqrt(J)
        heard = int(m.sum()) // 2
        points.append({"ranges": {f"u_{i}": R for i, R in rg.items()}, "heard": heard,
                       "h2": h, "loss": h / h2_star - 1.0, "chosen": False})  # fmt: skip
    ok = [k for k, p in enumerate(points) if p["h2"] <= (1.0 + max_loss) * h2_star]
    pick = min(ok, key=lambda k: (points[k]["heard"], points[k]["h2"])) if ok else len(points) - 1
    points[pick]["chosen"] = True
    return points, front[pick][2], range_patterns(plant, front[pick][0])
