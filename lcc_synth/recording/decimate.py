"""Decimation of recorded simulations (``decimate="minmax"``, what every command records
unless ``--record-every N`` asks for a stride; ``--record-every 1`` is the exact recording).

A simulation holds one sample every ``dt = 0.01`` s; the viewer draws a 60-70 s run in a
few hundred pixels (one plot per controller, side by side), about 0.2 s per pixel. Each entity
keeps its own rows (all series of an entity share them), chosen so that what the viewer draws
does not visibly change:

* time series (velocity, spacing, acceleration, the CAV command): :func:`viewer_rows`, the
  fewer of :func:`linear_rows` (a piecewise-linear simplification: the line drawn through the
  kept rows passes within ``tolerance`` = 0.2 % of the entity's span, about a pixel, of every
  sample; a cruise costs two rows) and :func:`minmax_rows` (M4, Jugel et al. 2014: every
  series' minimum and maximum in every 0.2 s bucket, i.e. a pixel column drawn exactly); an
  entity where both leave more than two rows per bucket (noise-dominated: the accelerations of
  HDVs with acceleration noise, every series peaking in every bucket on a different row) keeps
  the M4 rows of every :data:`NOISY_BUCKET_S` (its band's envelope, exact per second);
* always: every series' global minimum and maximum (so the minimum spacing, the maximum
  ``|u|``... of the recording equal the simulated ones exactly), both sides of every NaN gap
  (a collided vehicle) and the ``forced`` rows of :func:`event_rows`: full rate during
  emergency braking (eq. 29), half a second around every AEB edge and collision, and the rows
  of the CAV's largest step and 1 s jerk;
* flags and status codes (``cav/aeb_active``, ``mpc/status``): their breakpoints only
  (:func:`linear_rows` with ``tolerance = 0``), which redraw them exactly;
* the road view (scrubbed, latest-at): :func:`frame_rows`, a frame every
  :data:`ROAD_BUCKET_S` unless no vehicle moved by more than the tolerance since the last one;
* MPC plans: one per :data:`MPC_PLAN_S` (:func:`plan_rows`: a plan unchanged since the last
  recorded one is skipped), each strip through the points that draw it within the tolerance
  (:func:`strip_points`: a smooth 51-point prediction keeps about 5); solve times: M4 per
  :data:`MPC_TIMING_BUCKET_S`.

Measured on the default ``lcc-synth run`` (``problems/showcase.toml``, 24 runs: six scenarios,
four to six controllers; ``rerun rrd stats`` and the Arrow size of every chunk by entity,
``benchmarks/bench_recording_size.py``): the file 19.1 MB -> 6.6 MB. Its simulations 16.3 ->
4.2 MB: the MPC plans 6.36 -> 0.44 MB (about 200 full plans per run before), the
accelerations 3.81 -> 1.31 MB (the noisy ``heterogeneous`` ones 2.68 -> 0.81 MB: two rows in
three before), the road 2.26 -> 0.87 MB (0.1 s frames with M4 peaks before), velocity and
spacing 2.52 -> 0.93 MB, the CAV command 0.46 -> 0.21 MB, the AEB flags 0.27 -> 0.10 MB, the
MPC solve times and status 0.39 -> 0.11 MB; what remains is mostly about 2 kB of Arrow schema
per chunk. The layout (blueprint) 2.47 -> 2.09 MB: time-series views no longer save the
visible time range that is Rerun's default.
"""

from __future__ import annotations

import numpy as np

from lcc_synth.errors import ConfigError

__all__ = [
    "MPC_PLAN_S",
    "MPC_TIMING_BUCKET_S",
    "NOISY_BUCKET_S",
    "ROAD_BUCKET_S",
    "VIEWER_BUCKET_S",
    "VIEWER_TOLERANCE",
    "event_rows",
    "frame_rows",
    "linear_rows",
    "minmax_rows",
    "plan_rows",
    "strip_points",
    "viewer_rows",
]

#: Grid spacing (s) of the min/max-preserving decimation of the time series: about a pixel of
#: a 70 s plot a quarter of 60 % of a 1920-pixel screen wide (the default layout).
VIEWER_BUCKET_S = 0.2
#: Grid spacing (s) of the road view (points scrubbed or played back: 5 frames per second).
ROAD_BUCKET_S = 0.2
#: Grid spacing (s) of the min/max decimation of a noise-dominated series (:func:`viewer_rows`).
NOISY_BUCKET_S = 1.0
#: Deviations below this fraction of an entity's span are not kept (about a pixel).
VIEWER_TOLERANCE = 0.002
#: Seconds between the MPC plans recorded (a plan unchanged since the last one is skipped).
MPC_PLAN_S = 0.5
#: Grid (s) of the min/max decimation of the MPC solve times (their peaks are kept).
MPC_TIMING_BUCKET_S = 1.0


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
        An extreme reached on several rows of a bucket (a command saturated at its limit)
        keeps the first and the last of them.
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
            hit = (x == peak) & (x > e + tol)
            for j in np.flatnonzero(hit.any(axis=0)):  # a plateau (a saturated command):
                rows = np.flatnonzero(hit[:, j])  # its first and last row in the bucket
                new = np.diff(seg[rows]) != 0
                keep[rows[np.r_[True, new]]] = True
                keep[rows[np.r_[new, True]]] = True
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


def _prepare(values) -> np.ndarray:
    """``values`` as a C-contiguous ``(T, k)`` float64 array, non-finite samples as NaN."""
    v = np.asarray(values, dtype=np.float64)
    v = v[:, None] if v.ndim == 1 else v.reshape(v.shape[0], -1)
    return np.ascontiguousarray(np.where(np.isfinite(v), v, np.nan))


def _anchors(v: np.ndarray, forced: np.ndarray | None) -> np.ndarray:
    """``(T,)`` bool: the rows every decimation keeps: first, last, ``forced``, each series'
    global minimum and maximum and both sides of every NaN gap."""
    T = v.shape[0]
    keep = np.zeros(T, dtype=bool)
    keep[0] = keep[-1] = True
    if forced is not None:
        keep |= np.asarray(forced, dtype=bool).reshape(T)
    finite = np.isfinite(v)
    cols = np.flatnonzero(finite.any(axis=0))
    if cols.size:
        keep[np.nanargmin(v[:, cols], axis=0)] = True
        keep[np.nanargmax(v[:, cols], axis=0)] = True
    edges = np.flatnonzero(np.diff(finite.astype(np.int8), axis=0).any(axis=1))
    keep[edges] = True
    keep[edges + 1] = True
    return keep


def _span(v: np.ndarray) -> float:
    """Max - min over every finite sample (0 without any)."""
    return float(np.nanmax(v) - np.nanmin(v)) if np.isfinite(v).any() else 0.0


def linear_rows(
    values: np.ndarray,
    tolerance: float = VIEWER_TOLERANCE,
    forced: np.ndarray | None = None,
) -> np.ndarray:
    """Rows of ``values`` whose straight lines pass within ``tolerance`` of every sample.

    A greedy piecewise-linear simplification of all series at once (the rows are shared):
    from each kept row the segment is stretched as far as the line to the next candidate row
    passes within ``tolerance x span`` of every sample in between, of every series (the
    admissible slopes are intersected sample by sample, so the work is ``O(T k)``). A plot
    drawn from the kept rows differs from the full-rate one by at most that much anywhere, at
    any zoom, and the kept rows are simulated samples. Also kept: first and last row, every
    series' global minimum and maximum, both sides of every NaN gap and ``forced``. With
    ``tolerance = 0`` a piecewise-constant or piecewise-linear signal (a flag, a status code)
    keeps only its breakpoints and is reproduced exactly.

    Parameters
    ----------
    values : numpy.ndarray
        ``(T,)`` or ``(T, k)``: ``k`` series sharing ``T`` uniformly spaced rows.
    tolerance : float
        Fraction of the span of ``values`` (max - min over every finite sample).
    forced : numpy.ndarray, optional
        ``(T,)`` bool: rows always kept.

    Returns
    -------
    numpy.ndarray
        Sorted unique row indices (int64), always including ``0`` and ``T - 1``.
    """
    if not (np.isfinite(tolerance) and tolerance >= 0):
        raise ConfigError("tolerance", f"must be finite and >= 0, got {tolerance!r}")
    v = _prepare(values)
    T = v.shape[0]
    if T == 0:
        return np.zeros(0, dtype=np.int64)
    keep = _anchors(v, forced)
    if T > 2 and np.isfinite(v).any():
        from lcc_synth.recording.decimate_kernel import linear_keep

        x = np.arange(T, dtype=np.float64)
        linear_keep(x, v, float(tolerance) * _span(v), keep)
    return np.flatnonzero(keep)


def viewer_rows(
    values: np.ndarray,
    bucket: int,
    tolerance: float = VIEWER_TOLERANCE,
    forced: np.ndarray | None = None,
    noisy_bucket: int | None = None,
) -> np.ndarray:
    """The rows a time-series entity records with ``decimate="minmax"``.

    The fewer of :func:`linear_rows` (every sample within ``tolerance`` of the drawn line:
    smooth signals, cruise phases) and :func:`minmax_rows` on ``bucket`` (every bucket's
    extremes: about a pixel column). When even the fewer leaves more than two rows per bucket
    besides ``forced`` (a noise-dominated entity, e.g. the noisy accelerations of
    heterogeneous HDVs, where every series peaks in every bucket and the series' peaks fall on
    different rows), :func:`minmax_rows` on ``noisy_bucket`` (default ``NOISY_BUCKET_S /
    VIEWER_BUCKET_S`` buckets): the noise band's envelope, every series' minimum and maximum
    of every ``noisy_bucket`` rows, exactly. All keep ``forced``, every series' global
    extremes and the NaN gaps' edges.

    Parameters
    ----------
    values, bucket, tolerance, forced
        As :func:`minmax_rows`.
    noisy_bucket : int, optional
        Grid of a noise-dominated entity, in rows (``bucket`` switches the fallback off).

    Returns
    -------
    numpy.ndarray
        Sorted unique row indices (int64).
    """
    m4 = minmax_rows(values, bucket, tolerance, forced)
    lin = linear_rows(values, tolerance, forced)
    best = lin if len(lin) <= len(m4) else m4
    T = len(np.asarray(values))
    wide = noisy_bucket or max(bucket, int(round(bucket * NOISY_BUCKET_S / VIEWER_BUCKET_S)))
    n_forced = 0 if forced is None else int(np.count_nonzero(forced))
    if wide > bucket and len(best) - n_forced > 2 * (-(-T // bucket)):
        noisy = minmax_rows(values, wide, tolerance, forced)
        if len(noisy) < len(best):
            return noisy
    return best


def frame_rows(
    points: np.ndarray, every: int, tolerance: float = VIEWER_TOLERANCE
) -> np.ndarray:
    """Frames of a scrubbed view (the road): every ``every``-th row, skipping a frame when no
    coordinate moved by more than ``tolerance`` x the span since the last kept frame (nothing
    visible changed: a cruise); first, last and both sides of every NaN gap are kept.

    Parameters
    ----------
    points : numpy.ndarray
        ``(T, k)`` coordinates (every point's x and y) per row.
    every : int
        Frame spacing in rows (>= 1).
    tolerance : float
        Fraction of the span of ``points``.

    Returns
    -------
    numpy.ndarray
        Sorted unique row indices (int64).
    """
    if isinstance(every, bool) or not isinstance(every, int | np.integer) or every < 1:
        raise ConfigError("every", f"must be an integer >= 1, got {every!r}")
    v = _prepare(points)
    T = v.shape[0]
    if T == 0:
        return np.zeros(0, dtype=np.int64)
    finite = np.isfinite(v)
    keep = np.zeros(T, dtype=bool)
    keep[0] = keep[-1] = True
    edges = np.flatnonzero(np.diff(finite.astype(np.int8), axis=0).any(axis=1))
    keep[edges] = True
    keep[edges + 1] = True
    grid = np.zeros(T, dtype=bool)
    grid[::every] = True
    from lcc_synth.recording.decimate_kernel import frame_keep

    frame_keep(v, float(tolerance) * _span(v), grid, keep)
    return np.flatnonzero(keep)


def plan_rows(plans: np.ndarray, every: int, tolerance: float = VIEWER_TOLERANCE) -> np.ndarray:
    """Which of ``K`` predicted plans to record: every ``every``-th, skipping one that differs
    from the last recorded plan by at most ``tolerance`` x the span of all plans (a cruise
    repeats the same plan); the first and the last are kept.

    Parameters
    ----------
    plans : numpy.ndarray
        ``(K, ...)`` one plan per row.
    every : int
        Candidate spacing in plans (>= 1).
    tolerance : float
        Fraction of the span of ``plans``.

    Returns
    -------
    numpy.ndarray
        Sorted unique plan indices (int64).
    """
    v = _prepare(np.asarray(plans).reshape(len(plans), -1))
    K = v.shape[0]
    if K == 0:
        return np.zeros(0, dtype=np.int64)
    keep = np.zeros(K, dtype=bool)
    keep[0] = keep[-1] = True
    grid = np.zeros(K, dtype=bool)
    grid[::every] = True
    from lcc_synth.recording.decimate_kernel import frame_keep

    frame_keep(v, float(tolerance) * _span(v), grid, keep)
    return np.flatnonzero(keep)


def strip_points(
    x: np.ndarray, strips: np.ndarray, tolerance: float = VIEWER_TOLERANCE
) -> np.ndarray:
    """``(S, H)`` bool: the points of each line strip to keep so that the strip drawn through
    them stays within ``tolerance`` x the span of all strips of every point (the
    :func:`linear_rows` simplification of each strip on its own: a smooth 5 s prediction of
    51 points needs a handful); each strip keeps its ends and its extremes, a strip with some
    NaN points keeps every point (one without any value, e.g. FD-LCC's CAV spacing: its ends).

    Parameters
    ----------
    x : numpy.ndarray
        ``(H,)`` increasing abscissae shared by the strips.
    strips : numpy.ndarray
        ``(S, H)`` ordinates.
    tolerance : float
        Fraction of the span of ``strips``.
    """
    y = np.ascontiguousarray(strips, dtype=np.float64)
    S, H = y.shape
    keep = np.zeros((S, H), dtype=bool)
    if S == 0 or H == 0:
        return keep
    keep[:, 0] = keep[:, -1] = True
    finite = np.isfinite(y)
    bad = ~finite.all(axis=1) & finite.any(axis=1)  # partly NaN: every point
    keep[bad] = True
    good = np.flatnonzero(finite.all(axis=1))  # (a strip without any value: its two ends)
    if good.size and H > 2:
        keep[good, np.argmin(y[good], axis=1)] = True
        keep[good, np.argmax(y[good], axis=1)] = True
        from lcc_synth.recording.decimate_kernel import strips_keep

        tol = float(tolerance) * _span(y[good])
        sub = np.ascontiguousarray(keep[good])
        strips_keep(np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(y[good]),
                    tol, sub)  # fmt: skip
        keep[good] = sub
    return keep
