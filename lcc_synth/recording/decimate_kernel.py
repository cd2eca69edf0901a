"""Compiled loops (numba) of :mod:`lcc_synth.recording.decimate`: the piecewise-linear
simplification of :func:`~lcc_synth.recording.decimate.linear_rows` and the frame skipping of
:func:`~lcc_synth.recording.decimate.frame_rows` (one pass over ``T x k`` samples each; in
Python they took about 1 s per 10,000-row entity, here about a millisecond)."""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["frame_keep", "linear_keep", "strips_keep"]


@numba.njit(cache=True, error_model="numpy")
def linear_keep(x, v, tol, keep):  # pragma: no cover - compiled
    """Mark in ``keep`` (``(T,)`` bool, anchors already set) the rows of a greedy
    piecewise-linear approximation of every column of ``v`` (``(T, k)``, NaN = no value) over
    the increasing abscissae ``x`` (``(T,)``) that stays within ``tol`` of every sample.

    From anchor ``a`` the candidate end ``b`` grows while the chord ``a -> b`` of every series
    has a slope inside the interval allowed by the samples in between: sample ``i`` allows
    ``[(v_i - v_a - tol) / (x_i - x_a), (v_i - v_a + tol) / (x_i - x_a)]``. When it does not,
    ``b - 1``
    is kept and becomes the anchor. A row already marked (forced, extremes, NaN edges) always
    becomes an anchor, so a segment never crosses a change of which series are finite; a
    series without a value at the anchor is skipped for that segment.
    """
    T, k = v.shape
    lo = np.full(k, -np.inf)
    hi = np.full(k, np.inf)
    a = 0
    b = 1
    while b < T:
        if b - a >= 2:
            i = b - 1  # the newest sample between a and b
            d = x[i] - x[a]
            for j in range(k):
                va = v[a, j]
                if va != va:
                    continue
                dv = v[i, j] - va
                lj = (dv - tol) / d
                hj = (dv + tol) / d
                if lj > lo[j]:
                    lo[j] = lj
                if hj < hi[j]:
                    hi[j] = hj
            d = x[b] - x[a]
            ok = True
            for j in range(k):
                va = v[a, j]
                if va != va:
                    continue
                s = (v[b, j] - va) / d
                if not (s >= lo[j] and s <= hi[j]):
                    ok = False
                    break
            if not ok:
                a = b - 1
                keep[a] = True
                lo[:] = -np.inf
                hi[:] = np.inf
                continue  # b again, from the new anchor
        if keep[b]:
            a = b
            lo[:] = -np.inf
            hi[:] = np.inf
        b += 1
    return keep


@numba.njit(cache=True, error_model="numpy")
def strips_keep(x, y, tol, keep):  # pragma: no cover - compiled
    """:func:`linear_keep` of every strip ``y[s]`` (``(S, H)``, over the abscissae ``x``) on its
    own, into ``keep[s]`` (``(S, H)`` bool, anchors already set)."""
    S, H = y.shape
    for s in range(S):
        linear_keep(x, y[s].reshape((H, 1)), tol, keep[s])
    return keep


@numba.njit(cache=True, error_model="numpy")
def frame_keep(v, tol, grid, keep):  # pragma: no cover - compiled
    """Mark in ``keep`` the ``grid`` rows of ``v`` (``(T, k)``) where some coordinate moved by
    more than ``tol`` since the last kept row (or became / stopped being NaN); rows already
    marked in ``keep`` are kept and become the reference."""
    T, k = v.shape
    a = 0
    for r in range(1, T):
        if keep[r]:
            a = r
            continue
        if not grid[r]:
            continue
        moved = False
        for j in range(k):
            x = v[r, j]
            y = v[a, j]
            if (x != x) != (y != y):
                moved = True
                break
            if x == x and abs(x - y) > tol:
                moved = True
                break
        if moved:
            keep[r] = True
            a = r
    return keep
