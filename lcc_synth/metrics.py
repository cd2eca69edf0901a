"""Performance and safety metrics of simulation results (Section V-B and beyond).

Every function takes a :class:`~lcc_synth.simulation.results.SimResult` and returns one value per
scenario of the batch (``(batch,)``) or per scenario and vehicle (``(batch, n_vehicles)``,
columns head..tail).

Window: AAVE and fuel use the samples whose time lies in the CLOSED interval ``window``
(default 20-40 s: 2001 samples at dt = 0.01), integrated by the rectangle rule (sum x dt), as
the paper's reference computation does. The window must lie in the simulated time
``[t_start, t_start + duration]`` (:func:`check_window`): AAVE divides by the window's length,
so a window past the end would divide by time that was never simulated.

Failed runs: a scenario with a collision has NaN AAVE and fuel (its run stopped at the
collision; whatever it burnt until then is no efficiency to compare), whenever the collision
happened.

Comfort: the CAV's jerk ``da/dt`` of its applied acceleration, as an RMS of the step-to-step
finite differences (:func:`rms_jerk`) and as ISO 15622's "average over 1 s" (:func:`jerk_1s`):
``j1(t) = (a(t) - a(t - 1 s)) / 1 s``, judged against ISO 15622's limit at the CAV's speed
(:func:`iso15622_jerk_limit`) outside emergency braking.

Vehicle sets: ``"cav_and_behind"`` (the paper's "sum over i = 0..10": CAV and the HDVs behind),
``"first_cav_and_behind"`` (the DeeP-LCC paper's: the first CAV of a mixed platoon and every
vehicle behind it, CAVs included; for one CAV the same as ``"cav_and_behind"``), ``"all"``
(head included), ``"hdvs"`` (every HDV), or explicit paper indices / ``"head"`` (a platoon or
ring: positions ``1..N``). On a ring there is no head and every vehicle is behind every CAV
(the road closes): ``"cav_and_behind"`` and ``"first_cav_and_behind"`` are every vehicle, as
is ``"all"``.

Several CAVs: the command, jerk and emergency-braking metrics cover every CAV — ``max|u|``
over all of them, the RMS jerk of the worst CAV, the 1 s jerk's worst case, margin and time
over the limit over every CAV (times summed over the CAVs), AEB samples summed.

Safety verdict: a run is *unsafe* (:func:`unsafe_reasons`) when the CAV's emergency braking
acted, or a vehicle behind the head came closer than :data:`UNSAFE_MIN_SPACING` (2 m) to the
one ahead or within :data:`UNSAFE_MIN_TTC` (1 s) of hitting it; every table ranks unsafe runs
after the safe ones (:mod:`lcc_synth.experiments.tables`).

Wave metrics (the Sugiyama ring benchmark, Stern et al. 2018), over the window and vehicle set:
``velocity_std`` the standard deviation of the pooled speeds, every vehicle of the set at every
recorded sample of the window (one population, ``ddof = 0``: ``sqrt(mean (v - mean v)^2)``),
``mean_speed`` their mean, ``braking_events`` the number of downward crossings of
``BRAKING_THRESHOLD = -1`` m/s² by a vehicle's recorded acceleration (a pair of consecutive
samples in the window with ``a_{k-1} >= -1 > a_k``), summed over the vehicles. NaN (the
counts: as computed until the stop) for a scenario with a collision, as AAVE.

Followers' velocity standard deviation (:func:`follower_velocity_std`, the design for measured
drivers, ``problems/ngsim_lane2_design.toml``): ``velocity_std`` of a fixed vehicle set, the
HDVs behind the first CAV (CAVs excluded; on a ring every HDV), whatever ``[metrics]
vehicles`` says: how much of the leader's stop-and-go the CAV passes on to the human drivers
it leads. NaN when no HDV drives behind a CAV, as for a collision.

Fuel of the DeeP-LCC paper (Wang et al. 2023, the platoon brake test): the same Bowyer rate
(:func:`bowyer_fuel_rate`) on accelerations first smoothed by a centred moving average of
``accel_smoothing = 9`` recorded samples (:func:`smooth_acceleration`; the window shrinks at
the ends of the run, as MATLAB's ``movmean``), over the window 0-40 s and the vehicle set
``"first_cav_and_behind"``.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.records import Record
from lcc_synth.problem import System
from lcc_synth.schema import declared
from lcc_synth.simulation.perturbations import vehicle_column

__all__ = [
    "VEHICLE_SETS",
    "MetricsConfig",
    "metrics_from",
    "vehicle_columns",
    "PHASE_PREFIX",
    "window_mask",
    "check_window",
    "bowyer_fuel_rate",
    "smooth_acceleration",
    "aave",
    "fuel",
    "min_spacing",
    "min_time_to_collision",
    "max_abs_velocity_error",
    "max_abs_command",
    "rms_jerk",
    "JERK_WINDOW",
    "iso15622_jerk_limit",
    "jerk_1s",
    "max_jerk_1s",
    "jerk_limit_margin",
    "jerk_limit_violation_time",
    "aeb_activations",
    "collisions",
    "METRIC_DISPLAY",
    "DISPLAY_LIMIT",
    "format_metric",
    "UNSAFE_MIN_SPACING",
    "UNSAFE_MIN_TTC",
    "UNSAFE_RULE",
    "unsafe_reasons",
    "sweep_safety_rank",
    "BRAKING_THRESHOLD",
    "velocity_std",
    "follower_columns",
    "follower_velocity_std",
    "mean_speed",
    "braking_events",
    "WAVE_METRICS",
    "wave_metrics",
    "summary",
    "per_scenario",
    "concatenate",
    "aggregate",
]

VEHICLE_SETS = ("cav_and_behind", "first_cav_and_behind", "all", "hdvs")

#: Averaging window (s) of ISO 15622's jerk limit.
JERK_WINDOW = 1.0
#: ISO 15622's limit on the 1 s average jerk: (speed m/s, limit m/s^3) at both ends.
_ISO_JERK = ((5.0, 20.0), (5.0, 2.5))


@dataclass(frozen=True, repr=False)
class MetricsConfig(Record):
    """Window and vehicle set of AAVE and fuel, an optional baseline controller name, and the
    moving-average length (recorded samples, odd; 1: none) of the accelerations in the fuel."""

    window: tuple[float, float] = (20.0, 40.0)
    vehicles: str | tuple[int | str, ...] = "cav_and_behind"
    baseline: str | None = None
    accel_smoothing: int = 1
    phases: tuple[tuple[str, tuple[float, float]], ...] = ()

    def __post_init__(self) -> None:
        t0, t1 = self.window
        if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
            raise ConfigError("metrics.window", f"must be [t0, t1] with t1 > t0, got {self.window}")
        for name, (p0, p1) in self.phases:
            if not (np.isfinite(p0) and np.isfinite(p1) and p1 > p0):
                raise ConfigError(f"metrics.phases.{name}", f"must be [t0, t1], t1 > t0: {p0, p1}")
        if isinstance(self.vehicles, str) and self.vehicles not in VEHICLE_SETS:
            raise ConfigError(
                "metrics.vehicles",
                f"must be one of {list(VEHICLE_SETS)} or a list of indices, got {self.vehicles!r}",
            )
        k = self.accel_smoothing
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1 or k % 2 == 0:
            raise ConfigError(
                "metrics.accel_smoothing", f"must be an odd integer >= 1 (1: none), got {k!r}"
            )

    def toml_table(self) -> dict[str, Any]:
        """The ``[metrics]`` table (what :func:`metrics_from` reads)."""
        vehicles = self.vehicles if isinstance(self.vehicles, str) else list(self.vehicles)
        out = {"window": [float(t) for t in self.window], "vehicles": vehicles,
               "baseline": self.baseline}  # fmt: skip
        if self.accel_smoothing != 1:
            out["accel_smoothing"] = int(self.accel_smoothing)
        if self.phases:
            out["phases"] = {name: [float(t) for t in w] for name, w in self.phases}
        return out


def _layout(result) -> tuple[int, bool] | None:
    """``(N, ring)`` of a platoon or ring result (vehicles named by position), else None."""
    sc = getattr(result, "scenario", None)
    return None if sc is None else sc.layout


def vehicle_columns(result, vehicles: str | Sequence[int | str] = "cav_and_behind") -> np.ndarray:
    """Array columns of a vehicle set (see the module docstring)."""
    nv, cav = result.n_vehicles, result.cav
    ring = bool(getattr(result, "ring", False))
    cavs = tuple(getattr(result, "cavs", None) or (cav,))
    if isinstance(vehicles, str):
        if vehicles in ("cav_and_behind", "first_cav_and_behind"):
            return np.arange(nv) if ring else np.arange(cavs[0], nv)
        if vehicles == "all":
            return np.arange(nv)
        if vehicles == "hdvs":
            return np.array([j for j in range(0 if ring else 1, nv) if j not in cavs])
        if vehicles == "head":
            return np.array([0])
        raise ConfigError("metrics.vehicles", f"must be one of {list(VEHICLE_SETS)}")
    cols = [
        vehicle_column(v, result.m, result.n, "metrics.vehicles", _layout(result))
        for v in vehicles
    ]
    if not cols:
        raise ConfigError("metrics.vehicles", "must name at least one vehicle")
    return np.array(cols)


def check_window(
    window: tuple[float, float], start: float, end: float, dt: float, field: str = "metrics.window"
) -> None:
    """Raise :class:`ConfigError` unless ``start <= window[0]`` and ``window[1] <= end``
    (tolerance 1e-6 dt): ``[start, end]`` is the simulated time, ``t_start`` to
    ``t_start + steps dt`` (the last sample stands for the step that ends there)."""
    eps = 1e-6 * dt
    t0, t1 = window
    if t0 < start - eps or t1 > end + eps:
        raise ConfigError(
            field,
            f"[{t0:g}, {t1:g}] leaves the simulated time [{start:g}, {end:g}] s (t_start to "
            f"t_start + duration): AAVE would divide by time that was never simulated; "
            f"choose {start:g} <= t0 < t1 <= {end:g} or a longer duration",
        )


def window_mask(result, window: tuple[float, float] = (20.0, 40.0)) -> np.ndarray:
    """Samples with ``window[0] <= t <= window[1]`` (tolerance 1e-6 dt for round-off); a
    window outside the recorded run is a :class:`ConfigError` (:func:`check_window`)."""
    eps = 1e-6 * result.sim_dt
    check_window(window, result.t[0], result.t[-1] + result.dt, result.sim_dt)
    mask = (result.t >= window[0] - eps) & (result.t <= window[1] + eps)
    if not mask.any():
        raise ConfigError(
            "metrics.window",
            f"{list(window)} holds no sample of the run ({result.t[0]:g} to {result.t[-1]:g} s)",
        )
    return mask


def bowyer_fuel_rate(v, a):
    """Instantaneous fuel rate (mL/s) of Bowyer et al. (1985) as printed in Section V-B.

    ``R = 0.333 + 0.00108 v^2 + 1.2 a``; ``f = 0.444 + 0.090 R v + [0.054 a^2 v]_{a>0}`` when
    ``R > 0``, else ``0.444``. ``v`` in m/s, ``a`` in m/s^2; broadcasts.
    """
    v = np.asarray(v, dtype=float)
    a = np.asarray(a, dtype=float)
    R = 0.333 + 0.00108 * v**2 + 1.2 * a
    f = 0.444 + 0.090 * R * v + np.where(a > 0, 0.054 * a**2 * v, 0.0)
    return np.where(R > 0, f, 0.444)


def smooth_acceleration(a: np.ndarray, length: int) -> np.ndarray:
    """Centred moving average of ``length`` (odd) samples along axis 1 of ``a``
    (``(batch, T, ...)``); near the ends the window shrinks to the samples that exist
    (MATLAB's ``movmean``). ``length = 1`` returns ``a``."""
    a = np.asarray(a, dtype=float)
    if length <= 1:
        return a
    h = length // 2
    T = a.shape[1]
    c = np.cumsum(np.concatenate([np.zeros_like(a[:, :1]), a], axis=1), axis=1)
    hi = np.minimum(np.arange(T) + h + 1, T)
    lo = np.maximum(np.arange(T) - h, 0)
    shape = (1, T) + (1,) * (a.ndim - 2)
    return (c[:, hi] - c[:, lo]) / (hi - lo).reshape(shape)


def _slice(result, arr, window, vehicles):
    mask = window_mask(result, window)
    cols = vehicle_columns(result, vehicles)
    return arr[:, mask][:, :, cols], mask, cols


def aave(result, window=(20.0, 40.0), vehicles="cav_and_behind") -> np.ndarray:
    """Average absolute velocity error (m/s): ``sum_i int |v_i - v*| dt / (t1 - t0) / count``.

    ``window`` ``(t0, t1)`` (s) defaults to Table II's (20, 40); the flat API's ``lcc.aave`` and
    ``lcc.metrics`` require it. NaN for a scenario with a collision (see the module docstring).
    """
    v, _, cols = _slice(result, result.velocity, window, vehicles)
    err = np.abs(v - result.v_star[:, None, None])
    out = err.sum(axis=(1, 2)) * result.dt / (window[1] - window[0]) / len(cols)
    return np.where(result.collided.any(axis=1), np.nan, out)


def fuel(
    result, window=(20.0, 40.0), vehicles="cav_and_behind", accel_smoothing: int = 1
) -> np.ndarray:
    """Total fuel (mL) of the vehicle set over the window (Bowyer model, rectangle rule).

    ``window`` ``(t0, t1)`` (s) defaults to Table II's (20, 40); the flat API's ``lcc.fuel`` and
    ``lcc.metrics`` require it. NaN for a scenario with a collision (see the module docstring).
    ``accel_smoothing``: the accelerations are first smoothed over the whole recorded run by
    :func:`smooth_acceleration` (the DeeP-LCC paper: 9), then cut to the window.
    """
    v, mask, cols = _slice(result, result.velocity, window, vehicles)
    acc = result.acceleration
    if accel_smoothing > 1:
        acc = smooth_acceleration(acc[:, :, cols], accel_smoothing)
        cols = slice(None)
    a = acc[:, mask][:, :, cols]
    out = bowyer_fuel_rate(v, a).sum(axis=(1, 2)) * result.dt
    return np.where(result.collided.any(axis=1), np.nan, out)


def min_spacing(result) -> np.ndarray:
    """Minimum spacing (m) of every vehicle over the run, ``(batch, nv)``; NaN for the head
    (on a ring column 0's is its gap to the last vehicle)."""
    out = np.full((result.batch, result.n_vehicles), np.nan)
    j0 = 0 if getattr(result, "ring", False) else 1
    out[:, j0:] = np.nanmin(result.spacing[:, :, j0:], axis=1)
    return out


def min_time_to_collision(result) -> np.ndarray:
    """Minimum time to collision (s) of every vehicle, ``(batch, nv)``.

    ``TTC = s_i / (v_i - v_ahead)`` at samples where the vehicle closes in (``v_i > v_ahead``);
    ``inf`` when it never does; NaN for the head.
    """
    v = result.velocity
    j0 = 0 if getattr(result, "ring", False) else 1
    closing = (v - np.roll(v, 1, axis=2))[:, :, j0:]  # column 0 of a ring: behind the last
    s = result.spacing[:, :, j0:]
    with np.errstate(divide="ignore", invalid="ignore"):
        ttc = np.where(closing > 0, s / closing, np.inf)
    ttc = np.where(np.isnan(ttc), np.inf, ttc)
    out = np.full((result.batch, result.n_vehicles), np.nan)
    out[:, j0:] = ttc.min(axis=1)
    return out


def max_abs_velocity_error(result) -> np.ndarray:
    """``max_t |v_i - v*|`` (m/s) of every vehicle, ``(batch, nv)``."""
    return np.nanmax(np.abs(result.velocity - result.v_star[:, None, None]), axis=1)


def max_abs_command(result) -> np.ndarray:
    """``max_t |u|`` (m/s^2) of the CAV's command (before limits and emergency braking); the
    largest over every CAV when there are several."""
    u = np.asarray(result.u_cmd)
    return np.nanmax(np.abs(u).reshape(u.shape[0], -1), axis=1)


def _cav_cols(result) -> list[int]:
    return list(getattr(result, "cavs", None) or (result.cav,))


def rms_jerk(result) -> np.ndarray:
    """RMS of the CAV's jerk (m/s^3): finite differences of its applied acceleration (the
    worst CAV's when there are several)."""
    a = result.acceleration[:, :, _cav_cols(result)]
    jerk = np.diff(a, axis=1) / result.dt
    return np.max(np.sqrt(np.nanmean(jerk**2, axis=1)), axis=1)


def iso15622_jerk_limit(v):
    """ISO 15622's limit (m/s^3) on the 1 s average jerk at speed ``v`` (m/s): 5 at or below
    5 m/s, 2.5 at or above 20 m/s, linear in ``v`` between; NaN where ``v`` is. Broadcasts."""
    v = np.asarray(v, dtype=float)
    return np.where(np.isnan(v), np.nan, np.interp(v, *_ISO_JERK))


def jerk_1s(result) -> np.ndarray:
    """The CAV's 1 s average jerk (m/s^3), ``(batch, T)``, outside emergency braking.

    At recorded sample ``k`` (time ``t``), ``j1 = (a_k - a_{k-w}) / (w dt)``: the mean of
    ``da/dt`` over the window ``[t - w dt, t]`` of ``w = round(JERK_WINDOW / dt)`` samples
    (1 s at any ``dt`` dividing it), ``a`` the CAV's applied acceleration. NaN for the first
    second, after a collision, and where the window holds a sample of the CAV's emergency
    braking (AEB at ``t - 1 s .. t``: during it and for 1 s after it). Several CAVs:
    ``(batch, T, n_cav)``, each CAV with its own emergency braking.
    """
    cols = _cav_cols(result)
    a = result.acceleration[:, :, cols] if len(cols) > 1 else result.acceleration[:, :, cols[0]]
    w = max(1, int(round(JERK_WINDOW / result.dt)))
    j = np.full(a.shape, np.nan)
    j[:, w:] = (a[:, w:] - a[:, :-w]) / (w * result.dt)
    aeb = np.cumsum(result.aeb_active, axis=1)  # AEB samples up to k
    aeb[:, w + 1 :] -= aeb[:, : -w - 1].copy()  # ... in k - w .. k
    return np.where(aeb > 0, np.nan, j)


def max_jerk_1s(result) -> np.ndarray:
    """``max_t |j1(t)|`` (m/s^3) of :func:`jerk_1s`; NaN when no sample is defined."""
    j = jerk_1s(result)
    return _nanmax(np.abs(j).reshape(j.shape[0], -1))


def _jerk_margin(result) -> np.ndarray:
    """``(batch, T)`` ISO 15622 limit at the CAV's speed at ``t`` minus ``|j1(t)|``
    (``(batch, T * n_cav)`` with several CAVs)."""
    cols = _cav_cols(result)
    v = result.velocity[:, :, cols] if len(cols) > 1 else result.velocity[:, :, cols[0]]
    out = iso15622_jerk_limit(v) - np.abs(jerk_1s(result))
    return out.reshape(out.shape[0], -1)


def jerk_limit_margin(result) -> np.ndarray:
    """``min_t (limit(v_CAV(t)) - |j1(t)|)`` (m/s^3): negative where the CAV's 1 s average
    jerk exceeds ISO 15622's limit at its speed (:func:`iso15622_jerk_limit`)."""
    return -_nanmax(-_jerk_margin(result))


def jerk_limit_violation_time(result) -> np.ndarray:
    """Time (s) the CAV's 1 s average jerk spends above ISO 15622's limit at its speed:
    samples with a negative margin times ``dt`` (0 within the limit)."""
    return (_jerk_margin(result) < 0).sum(axis=1) * result.dt


def _nanmax(x: np.ndarray) -> np.ndarray:
    """``nanmax`` over axis 1; NaN (no warning) for a row without a defined value."""
    ok = ~np.isnan(x)
    return np.where(ok.any(axis=1), np.max(np.where(ok, x, -np.inf), axis=1), np.nan)


def aeb_activations(result) -> np.ndarray:
    """Number of samples where the CAV's emergency braking overrode its command (summed over
    the CAVs when there are several)."""
    a = np.asarray(result.aeb_active)
    return a.reshape(a.shape[0], -1).sum(axis=1)


def collisions(result) -> np.ndarray:
    """Number of vehicles that collided with the vehicle ahead, per scenario."""
    return result.collided.sum(axis=1)


#: How a metric is shown in every table (``run``, the recordings, ``review --summary``): key ->
#: (label with its unit, format of :func:`format_metric`). Keys not listed are shown as
#: they are.
METRIC_DISPLAY: dict[str, tuple[str, str]] = {
    "aave": ("AAVE (m/s)", ".4f"),
    "aave_std": ("AAVE std over the batch (m/s)", ".4f"),
    "fuel_ml": ("fuel (mL)", ".2f"),
    "fuel_ml_std": ("fuel std over the batch (mL)", ".2f"),
    "velocity_std": ("velocity std (m/s)", ".3f"),
    "mean_speed": ("mean speed (m/s)", ".3f"),
    "follower_velocity_std": ("followers' velocity std (m/s)", ".3f"),
    "braking_events": ("braking events", "d"),
    "min_spacing": ("min spacing (m)", ".2f"),
    "min_ttc": ("min TTC (s)", ".2f"),
    "max_abs_command": ("max |u| (m/s²)", ".3f"),
    "rms_jerk_cav": ("RMS jerk (m/s³)", ".2f"),
    "max_jerk_1s_cav": ("max 1 s jerk (m/s³)", ".2f"),
    "jerk_1s_margin_cav": ("ISO 15622 jerk margin (m/s³)", ".2f"),
    "jerk_1s_over_limit_s": ("ISO 15622 jerk", "iso"),
    "aeb_activations": ("AEB steps", "d"),
    "aeb_episodes": ("AEB episodes", "d"),
    "collisions": ("collisions", "d"),
    "wall_time_s": ("wall time (s)", ".3f"),
}
#: A fixed-point value this large is shown as ``>= 1e6`` (a time to collision of 2.7e12 s is a
#: closing speed at round-off: the vehicle is not closing in).
DISPLAY_LIMIT = 1e6


def format_metric(value: Any, fmt: str) -> str:
    """``value`` as a table shows it: ``n/a`` (None), ``nan``, ``inf``; ``fmt`` ``"d"`` an
    integer count, ``"iso"`` the time over ISO 15622's jerk limit as a verdict (``ok`` or
    ``over X s``), else a format spec (fixed-point values of magnitude
    :data:`DISPLAY_LIMIT` or more: ``>= 1e6``; a value that rounds to zero prints as zero, so
    ``6e-12`` m/s² of round-off is ``0.000``).

    >>> format_metric(2.66e12, ".2f"), format_metric(6e-12, ".3f"), format_metric(0.0, "iso")
    ('>= 1e6', '0.000', 'ok')
    """
    if value is None:
        return "n/a"
    if isinstance(value, bool):
        return str(value).lower()
    v = float(value)
    if np.isnan(v):
        return "nan"
    if np.isinf(v):
        return "inf" if v > 0 else "-inf"
    if fmt == "d":
        return str(int(v))
    if fmt == "iso":
        return "ok" if v == 0 else f"over {v:.2f} s"
    if fmt.endswith("f") and abs(v) >= DISPLAY_LIMIT:
        return f"{'>=' if v > 0 else '<= -'} 1e6".replace("- ", "-")
    text = format(v, fmt)
    return format(0.0, fmt) if float(text.rstrip("%")) == 0 else text  # no "-0.000"


#: Minimum spacing (m) below which a run is unsafe (:func:`unsafe_reasons`).
UNSAFE_MIN_SPACING = 2.0
#: Minimum time to collision (s) below which a run is unsafe (:func:`unsafe_reasons`).
UNSAFE_MIN_TTC = 1.0
#: The rule, printed once under a table that has unsafe rows.
UNSAFE_RULE = (f"(unsafe: emergency braking, a spacing under {UNSAFE_MIN_SPACING:g} m or a time "
               f"to collision under {UNSAFE_MIN_TTC:g} s; ranked after every safe run, its "
               "AAVE and fuel still shown)")  # fmt: skip


def unsafe_reasons(metrics: Mapping[str, Any]) -> list[str]:
    """Why a table row's run was unsafe (empty: it was safe): emergency braking on some step
    (``aeb_activations``), a minimum spacing under :data:`UNSAFE_MIN_SPACING` or a minimum
    time to collision under :data:`UNSAFE_MIN_TTC` (``min_spacing``, ``min_ttc``). A
    collision is unsafe too (its spacing reached 0). Missing or NaN values judge nothing (a
    controller that did not run has no metrics).

    >>> unsafe_reasons({"aeb_activations": 297, "min_spacing": 0.096, "min_ttc": 0.05})
    ['emergency braking on 297 steps', 'min spacing 0.10 m < 2 m', 'min TTC 0.05 s < 1 s']
    >>> unsafe_reasons({"aeb_activations": 0, "min_spacing": 17.1, "min_ttc": 5.85})
    []
    """
    out = []
    aeb = metrics.get("aeb_activations")
    if aeb is not None and float(aeb) > 0:  # NaN compares False
        out.append(f"emergency braking on {int(aeb)} step{'s' if int(aeb) != 1 else ''}")
    for key, limit, unit, name in (("min_spacing", UNSAFE_MIN_SPACING, "m", "min spacing"),
                                   ("min_ttc", UNSAFE_MIN_TTC, "s", "min TTC")):  # fmt: skip
        value = metrics.get(key)
        if value is not None and float(value) < limit:  # NaN compares False
            out.append(f"{name} {float(value):.2f} {unit} < {limit:g} {unit}")
    return out


def sweep_safety_rank(entry: Mapping[str, Any]) -> tuple[bool, bool, bool]:
    """Sort key of a controller's entry in a sweep summary, safety before efficiency: the
    controllers without a collided run first, then those with an unsafe one
    (``unsafe_scenarios``, judged by :func:`unsafe_reasons`), then those whose solver fell
    back (``fallbacks``); a stable sort keeps the given order within each group.

    >>> sorted(["a", "b", "c"], key=lambda c: sweep_safety_rank(
    ...     {"a": {"unsafe_scenarios": 2}, "b": {"collision_scenarios": 1}, "c": {}}[c]))
    ['c', 'a', 'b']
    """
    return (int(entry.get("collision_scenarios") or 0) > 0,
            int(entry.get("unsafe_scenarios") or 0) > 0,
            int(entry.get("fallbacks") or 0) > 0)  # fmt: skip


#: Deceleration (m/s²) below which a vehicle brakes (:func:`braking_events`).
BRAKING_THRESHOLD = -1.0


def velocity_std(result, window=(20.0, 40.0), vehicles="all") -> np.ndarray:
    """Standard deviation (m/s) of every speed of the vehicle set over the window, pooled over
    vehicles and samples (``ddof = 0``); NaN for a scenario with a collision."""
    v, _, _ = _slice(result, result.velocity, window, vehicles)
    out = v.reshape(v.shape[0], -1).std(axis=1)
    return np.where(result.collided.any(axis=1), np.nan, out)


def follower_columns(result) -> np.ndarray:
    """Array columns of the HDVs behind the first CAV (CAVs excluded; a ring: every HDV),
    ascending; empty when the first CAV is the tail."""
    nv = result.n_vehicles
    cavs = tuple(getattr(result, "cavs", None) or (result.cav,))
    first = 0 if getattr(result, "ring", False) else min(cavs) + 1
    return np.array([j for j in range(first, nv) if j not in cavs], dtype=int)


def follower_velocity_std(result, window=(20.0, 40.0)) -> np.ndarray:
    """:func:`velocity_std` (m/s, pooled, ``ddof = 0``) of the HDVs behind the first CAV
    (:func:`follower_columns`) over the window; NaN when there is none or for a scenario with
    a collision."""
    cols = follower_columns(result)
    if cols.size == 0:
        return np.full(result.batch, np.nan)
    v = result.velocity[:, window_mask(result, window)][:, :, cols]
    out = v.reshape(v.shape[0], -1).std(axis=1)
    return np.where(result.collided.any(axis=1), np.nan, out)


def mean_speed(result, window=(20.0, 40.0), vehicles="all") -> np.ndarray:
    """Mean (m/s) of every speed of the vehicle set over the window (pooled as
    :func:`velocity_std`); NaN for a scenario with a collision."""
    v, _, _ = _slice(result, result.velocity, window, vehicles)
    out = v.reshape(v.shape[0], -1).mean(axis=1)
    return np.where(result.collided.any(axis=1), np.nan, out)


def braking_events(
    result, window=(20.0, 40.0), vehicles="all", threshold: float = BRAKING_THRESHOLD
) -> np.ndarray:
    """Downward crossings of ``threshold`` (m/s²) by the recorded accelerations of the vehicle
    set in the window (``a_{k-1} >= threshold > a_k``, both samples in it), summed over the
    vehicles; an integer per scenario (NaN samples after a collision never count)."""
    a, _, _ = _slice(result, result.acceleration, window, vehicles)
    cross = (a[:, :-1] >= threshold) & (a[:, 1:] < threshold)
    return cross.sum(axis=(1, 2))


#: The wave metrics (:func:`wave_metrics`) -> label.
WAVE_METRICS = {"velocity_std": "velocity std (m/s)", "mean_speed": "mean speed (m/s)",
                "braking_events": "braking events"}  # fmt: skip


def wave_metrics(result, config: MetricsConfig | None = None) -> dict[str, np.ndarray]:
    """:data:`WAVE_METRICS` of every scenario (``(batch,)`` each) over the config's window and
    vehicle set."""
    cfg = config or MetricsConfig()
    return {"velocity_std": velocity_std(result, cfg.window, cfg.vehicles),
            "mean_speed": mean_speed(result, cfg.window, cfg.vehicles),
            "braking_events": braking_events(result, cfg.window, cfg.vehicles)}  # fmt: skip


def _stat(x: np.ndarray, fn=np.nanmean) -> float:
    """Batch statistic over the scenarios where ``x`` is defined (NaN when none is)."""
    x = np.asarray(x, dtype=float)
    if not np.isfinite(x).any():
        return float("nan")
    return float(fn(x))


def per_scenario(result, config: MetricsConfig | None = None) -> dict[str, np.ndarray]:
    """Every metric of every scenario of a result: arrays ``(batch,)`` or ``(batch, nv)``.

    Results of several batches (e.g. chunks of a large seed study) concatenate along axis 0
    before :func:`aggregate`.
    """
    cfg = config or MetricsConfig()
    with warnings.catch_warnings():  # all-NaN slices: scenarios stopped by a collision
        warnings.simplefilter("ignore", RuntimeWarning)
        return _per_scenario(result, cfg)


PHASE_PREFIX = "fuel_ml@"  #: per-phase fuel keys of :func:`per_scenario`: ``fuel_ml@NAME``


def _per_scenario(result, cfg: MetricsConfig) -> dict[str, np.ndarray]:
    k = cfg.accel_smoothing
    phases = {f"{PHASE_PREFIX}{p}": fuel(result, w, cfg.vehicles, k) for p, w in cfg.phases}
    return {
        "aave": aave(result, cfg.window, cfg.vehicles),
        "fuel_ml": fuel(result, cfg.window, cfg.vehicles, cfg.accel_smoothing),
        **phases,
        **wave_metrics(result, cfg),
        "follower_velocity_std": follower_velocity_std(result, cfg.window),
        "min_spacing": min_spacing(result),
        "min_ttc": min_time_to_collision(result),
        "max_abs_velocity_error": max_abs_velocity_error(result),
        "max_abs_command": max_abs_command(result),
        "rms_jerk_cav": rms_jerk(result),
        "max_jerk_1s_cav": max_jerk_1s(result),
        "jerk_1s_margin_cav": jerk_limit_margin(result),
        "jerk_1s_over_limit_s": jerk_limit_violation_time(result),
        "aeb_activations": aeb_activations(result),
        "collisions": collisions(result),
    }


def concatenate(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Join :func:`per_scenario` dictionaries of several batches."""
    return {k: np.concatenate([p[k] for p in parts], axis=0) for k in parts[0]}


def aggregate(per: dict[str, np.ndarray]) -> dict[str, Any]:
    """Summary of :func:`per_scenario` arrays (see :func:`summary`)."""
    a, f = per["aave"], per["fuel_ml"]
    ms, ttc, mv = per["min_spacing"], per["min_ttc"], per["max_abs_velocity_error"]
    phases = {k[len(PHASE_PREFIX):]: v for k, v in per.items() if k.startswith(PHASE_PREFIX)}
    with warnings.catch_warnings():  # all-NaN slices: scenarios stopped by a collision
        warnings.simplefilter("ignore", RuntimeWarning)
        out = {
            "aave": _stat(a),
            "aave_std": _stat(a, np.nanstd),
            "aave_all": a.tolist(),
            "fuel_ml": _stat(f),
            "fuel_ml_std": _stat(f, np.nanstd),
            "fuel_ml_all": f.tolist(),
            "velocity_std": _stat(per["velocity_std"]),
            "mean_speed": _stat(per["mean_speed"]),
            "follower_velocity_std": _stat(per["follower_velocity_std"]),
            "braking_events": int(per["braking_events"].sum()),
            "scenarios_with_collision": int((per["collisions"] > 0).sum()),
            "min_spacing": float(np.nanmin(ms)),  # the head's is NaN
            "collisions": int(per["collisions"].sum()),
            "aeb_activations": int(per["aeb_activations"].sum()),
            "max_abs_command": float(np.nanmax(per["max_abs_command"])),
            "rms_jerk_cav": _stat(per["rms_jerk_cav"]),
            "max_jerk_1s_cav": _stat(per["max_jerk_1s_cav"], np.nanmax),
            "jerk_1s_margin_cav": _stat(per["jerk_1s_margin_cav"], np.nanmin),
            "jerk_1s_over_limit_s": float(per["jerk_1s_over_limit_s"].sum()),
            "min_ttc": float(np.nanmin(ttc)),
            "per_vehicle": {
                "max_abs_velocity_error": np.nanmax(mv, axis=0).tolist(),
                "min_spacing": np.nanmin(ms, axis=0).tolist(),  # NaN for the head
                "min_ttc": np.nanmin(ttc, axis=0).tolist(),
            },
            "batch": int(a.shape[0]),
        }
    if phases:  # [metrics] phases: the fuel of each window, as fuel_ml's
        out["fuel_ml_phases"] = {name: _stat(x) for name, x in phases.items()}
    return out


def summary(result, config: MetricsConfig | None = None) -> dict[str, Any]:
    """All metrics of a result; batch statistics where a batch has several scenarios.

    Scalars are means over the batch (``*_std`` the standard deviations, ``*_all`` every
    scenario); ``min_spacing`` and ``collisions``/``aeb_activations`` are the worst case /
    totals. A scenario that collided has NaN AAVE and fuel: the means and deviations are over
    the other scenarios, and ``scenarios_with_collision`` counts them (NaN when all collided).
    ``velocity_std``, ``follower_velocity_std`` and ``mean_speed`` are means over the batch,
    ``braking_events`` the total.
    The CAV's jerk: ``rms_jerk_cav`` is the mean, ``max_jerk_1s_cav`` (:func:`max_jerk_1s`)
    the worst case, ``jerk_1s_margin_cav`` the least margin to ISO 15622's limit (negative:
    exceeded), ``jerk_1s_over_limit_s`` the total time above it (0: within the limit).
    Per-vehicle lists are ordered head..tail (head spacing is NaN). ``fuel_ml_phases``: the
    config's phases' mean fuel (mL, as ``fuel_ml``) by name.
    """
    return aggregate(per_scenario(result, config))


def metrics_from(
    data: Mapping[str, Any], system: System, controllers=(), scenario=None
) -> MetricsConfig:
    """The ``[metrics]`` table; with ``scenario`` (a
    :class:`~lcc_synth.simulation.scenario.Scenario`) the window must lie in its simulated time."""
    f = "metrics"
    mt = declared("").get(data, "metrics", "")
    table = declared("metrics")
    table.check(mt, f)
    window = tuple(table.get(mt, "window", f))
    if scenario is not None and window[1] > window[0]:  # t1 <= t0: MetricsConfig says so
        t_end = scenario.t_start + scenario.steps * scenario.dt
        check_window(window, scenario.t_start, t_end, scenario.dt, f"{f}.window")
    vehicles = table.raw(mt, "vehicles")
    if isinstance(vehicles, list):
        for v in vehicles:
            vehicle_column(v, system.m, system.n, f"{f}.vehicles", system.numbering)
        vehicles = tuple(vehicles)
    elif vehicles not in VEHICLE_SETS:
        raise ConfigError(
            f"{f}.vehicles", f"must be one of {list(VEHICLE_SETS)} or a list of vehicle indices"
        )
    baseline = table.get(mt, "baseline", f)
    if baseline is not None and controllers and baseline not in controllers:
        raise ConfigError(f"{f}.baseline", f"must name a controller, one of {list(controllers)}")
    phases, raw = [], table.get(mt, "phases", f) or {}
    for name, w in raw.items():  # each [t0, t1] (t1 > t0: MetricsConfig) inside the run
        if not (isinstance(w, list) and len(w) == 2 and all(type(t) in (int, float) for t in w)):
            raise ConfigError(f"{f}.phases.{name}", f"must be [t0, t1] (s), got {w!r}")
        if scenario is not None and w[1] > w[0]:
            t_end = scenario.t_start + scenario.steps * scenario.dt
            check_window(w, scenario.t_start, t_end, scenario.dt, f"{f}.phases.{name}")
        phases.append((str(name), (float(w[0]), float(w[1]))))
    return MetricsConfig(window, vehicles, baseline, table.get(mt, "accel_smoothing", f),
                         tuple(phases))
