"""Min/max-preserving decimation of recorded time series (what ``lcc-synth run`` records).

A simulation holds one sample every ``dt = 0.01`` s; the viewer draws a 60-70 s run in a
few hundred pixels (one plot per controller, side by side), about 0.2 s per pixel. Recording
every step made the default ``lcc-synth run`` (16 runs x 12 vehicles x 6000-7000 steps) a
40.5 MB file, 96 % of it the per-step velocity, spacing, acceleration, road, command and AEB
rows. :func:`minmax_rows` keeps, per entity (all its series share the rows):

* a grid of one row per ``bucket`` steps (0.1 s) and the last row;
* every series' global minimum and maximum (so the minimum spacing, the maximum ``|u|``... of
  the recording equal the simulated ones exactly);
* in every grid bucket and for every series, the rows of its minimum and maximum (M4, Jugel
  et al. 2014: first, last, min and max of every pixel column draw a line chart exactly),
  unless the bucket's grid rows come within ``tolerance`` (0.2 %) of the entity's whole span
  (about a pixel of a plot): a peak or a dip inside a bucket is never cut off, unlike naive
  striding, and every bucket's recorded min and max are within that tolerance of the true ones;
* the rows on both sides of every NaN gap (a collided vehicle) and the ``forced`` rows:
  :func:`event_rows` forces full rate during emergency braking (eq. 29), half a second around
  every AEB edge and collision, and the rows of the CAV's largest step and 1 s jerk.

Measured on the default ``lcc-synth run`` (``problems/showcase.toml``): the file 40.5 MB ->
8.6 MB, its 16 simulations 39.2 -> 7.2 MB (``benchmarks/bench_recording.py``). Smooth series
(velocities, spacings) keep about one row in nineteen; the noisy accelerations of the
``heterogeneous`` scenario (HDV acceleration noise, noisy V2V data) keep about two rows in
three, since most buckets hold a peak above the tolerance.
"""

from __future__ import annotations

import numpy as np

from lcc_synth.errors import ConfigError

__all__ = ["ROAD_BUCKET_S", "VIEWER_BUCKET_S", "VIEWER_TOLERANCE", "event_rows", "minmax_rows"]

#: Grid spacing (s) of the min/max-preserving decimation of the time series: about a pixel of
#: a 70 s plot a quarter of 60 % of a 1920-pixel screen wide (the default layout).
VIEWER_BUCKET_S = 0.2
#: Grid spacing (s) of the road view (points scrubbed or played back: 10 frames per second).
ROAD_BUCKET_S = 0.1
#: Deviations below this fraction of an entity's span are not kept (about a pixel).
VIEWER_TOLERANCE = 0.002


def minmax_rows(
    values: np.ndarray,
    bucket: int,
    tolerance: float = VIEWER_TOLERANCE,
    forced: np.ndarray | None = None,
) -> np.ndarray:
    """Rows of ``values`` to record so that no series loses a visible extreme.

    Parameters
    ----------
    values : numpy.ndarray
        ``(T,)`` or ``(T, k)``: ``k`` series sharing ``T`` rows (NaN = no value).
    bucket : int
        Grid spacing in rows (>= 1; 1 keeps every row).
    tolerance : float
        A bucket's interior minimum / maximum is dropped when a grid row of the bucket is
        within ``tolerance`` x the span of ``values`` (max - min over every finite sample).
    forced : numpy.ndarray, optional
        ``(T,)`` bool: rows always kept.

    Returns
    -------
    numpy.ndarray
        Sorted unique row indices (int64), always including ``0`` and ``T - 1``.
    """
    if isinstance(bucket, bool) or not isinstance(bucket, int | np.integer) or bucket < 1:
        raise ConfigError("bucket", f"must be an integer >= 1, got {bucket!r}")
    if not (np.isfinite(tolerance) and tolerance >= 0):
        raise ConfigError("tolerance", f"must be finite and >= 0, got {tolerance!r}")
    v = np.asarray(values, dtype=np.float64)
    v = v[:, None] if v.ndim == 1 else v.reshape(v.shape[0], -1)
    T = v.shape[0]
    if T == 0:
        return np.zeros(0, dtype=np.int64)
    keep = np.zeros(T, dtype=bool)
    keep[::bucket] = True
    keep[-1] = True
    if forced is not None:
        keep |= np.asarray(forced, dtype=bool).reshape(T)
    finite = np.isfinite(v)
    if bucket == 1 or T < 3 or not finite.any():
        return np.flatnonzero(keep)
    some = finite.any(axis=0)
    cols = np.flatnonzero(some)
    keep[np.nanargmin(v[:, cols], axis=0)] = True  # the global extremes, exactly
    keep[np.nanargmax(v[:, cols], axis=0)] = True
    edges = np.flatnonzero(np.diff(finite.astype(np.int8), axis=0).any(axis=1))
    keep[edges] = True  # both sides of a NaN gap
    keep[edges + 1] = True
    tol = float(tolerance) * float(np.nanmax(v) - np.nanmin(v))
    # M4 (first, last, min, max of every bucket): a bucket's interior minimum / maximum is
    # kept unless its grid rows already come within ``tol`` of it.
    grid = np.arange(0, T, bucket)
    if grid[-1] != T - 1:
        grid = np.append(grid, T - 1)
    seg = np.clip(np.searchsorted(grid, np.arange(T), side="right") - 1, 0, len(grid) - 2)
    ends = np.stack([v[grid[seg]], v[grid[seg + 1]]])  # (2, T, k) the bucket's grid rows
    with np.errstate(invalid="ignore"):
        for x, e in ((v, np.fmax(ends[0], ends[1])), (-v, -np.fmin(ends[0], ends[1]))):
            x = np.where(np.isfinite(x), x, -np.inf)
            e = np.where(np.isfinite(e), e, -np.inf)
            peak = np.maximum.reduceat(x, grid[:-1], axis=0)[seg]  # (T, k)
            keep |= ((x == peak) & (x > e + tol)).any(axis=1)
    return np.flatnonzero(keep)


def event_rows(
    t: np.ndarray,
    aeb_active: np.ndarray,
    collision_time: np.ndarray,
    cav_accel: np.ndarray,
    margin: float = 0.5,
) -> np.ndarray:
    """Rows recorded at full rate: emergency braking, ``margin`` s around its edges and
    around collisions, and the rows of the CAV's largest step jerk ``|a_k - a_(k-1)|`` and
    1 s jerk ``|a_k - a_(k-1 s)|`` (both rows of each pair).

    Parameters
    ----------
    t : numpy.ndarray
        ``(T,)`` times (s), uniformly spaced.
    aeb_active : numpy.ndarray
        ``(T,)`` bool, the CAV's emergency braking.
    collision_time : numpy.ndarray
        ``(n_vehicles,)`` collision times (NaN: none).
    cav_accel : numpy.ndarray
        ``(T,)`` the CAV's applied acceleration.
    margin : float
        Seconds of full rate around every event.

    Returns
    -------
    numpy.ndarray
        ``(T,)`` bool mask.
    """
    t = np.asarray(t, dtype=np.float64)
    T = t.size
    forced = np.zeros(T, dtype=bool)
    if T < 2:
        return forced | True
    dt = float(t[1] - t[0])
    half = max(1, int(round(margin / dt)))
    aeb = np.asarray(aeb_active, dtype=bool).reshape(T)
    forced |= aeb
    times = [t[k] for k in np.flatnonzero(np.diff(aeb.astype(np.int8)))]
    times += [float(c) for c in np.asarray(collision_time, dtype=np.float64).reshape(-1)
              if np.isfinite(c)]  # fmt: skip
    for tc in times:
        k = int(np.clip(np.searchsorted(t, tc), 0, T - 1))
        forced[max(0, k - half) : k + half + 1] = True
    a = np.asarray(cav_accel, dtype=np.float64).reshape(T)
    for lag in {1, max(1, int(round(1.0 / dt)))}:
        if T > lag:
            j = np.abs(a[lag:] - a[:-lag])
            if np.isfinite(j).any():
                k = int(np.nanargmax(j))
                forced[[k, k + lag]] = True
    return forced
