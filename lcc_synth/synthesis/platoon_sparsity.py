"""Sparsity Pareto per CAV for platoons and the ring: how far must each CAV hear?

Method: greedy forward selection of every CAV's own communication range. All CAVs start at
range 0 (decentralised: each CAV hears itself only; the start of
:func:`~lcc_synth.synthesis.platoon_polish.initial_gain`, then polished). Each step tries
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

import numpy as np

from lcc_synth.resources import progress
from lcc_synth.synthesis.platoon_h2 import PlatoonPlant, pattern_rows
from lcc_synth.synthesis.platoon_polish import descend, h2_objective, initial_gain

__all__ = ["full_range", "range_patterns", "range_pareto"]


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
