"""Prescribed motions ("perturbations") of chosen vehicles, Section V.

A perturbation overrides the acceleration of one vehicle while it is active (the vehicle's own
law, the CAV's controller and its emergency braking included). Outside every active window the
head vehicle cruises (zero acceleration) and the other vehicles follow their laws.

Vehicles are named by the paper's index ``-m .. n`` (``0`` = CAV) or ``"head"``; in a mixed
platoon or on a ring (``[system] kind = "platoon" | "ring"``) by their position ``1..N``
(``"head"`` only on the open platoon): the layout ``(N, ring)`` is passed as ``platoon``.

Signs carry meaning and are checked, never reinterpreted: a ``brake``'s ``decel`` and a
``brake_profile``'s ``decel`` are braking accelerations (< 0), the profile's ``accel`` its
recovery acceleration (> 0); a ``sine``'s amplitude and an ``accel_profile``'s values are signed
accelerations of either sign, a ``speed_profile``'s values speeds (>= 0).
A ``trajectory`` replays a recorded speed (a column of a trajectory file,
:mod:`lcc_synth.schema.trajectories`) on the head vehicle: its acceleration is the recorded
speed's difference over each step, never clipped (the recording is what happened), so a head
that starts at the recorded speed has it exactly at every sample time.
Activity windows are open intervals ``start < t < end``, tested with a tolerance of
``1e-6 dt`` so that floating-point sample times (``t_start + k dt``) never flip an endpoint.

The simulator consumes :func:`overrides`: two ``(T, n_vehicles)`` tables, an acceleration
override and a speed target, NaN where nothing is prescribed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.records import Record
from lcc_synth.schema import declared
from lcc_synth.schema.readers import read_file
from lcc_synth.schema.trajectories import Trajectory, read_trajectory

__all__ = [
    "Sine",
    "Brake",
    "BrakeProfile",
    "Profile",
    "Recorded",
    "Perturbation",
    "vehicle_column",
    "overrides",
    "perturbation_from_table",
    "read_profile_csv",
    "recorded_file",
    "recorded_from_table",
]

Vehicle = int | str


def vehicle_column(
    vehicle: Vehicle, m: int, n: int, field: str = "vehicle",
    platoon: tuple[int, bool] | None = None,
) -> int:
    """Array column of ``vehicle`` ("head" or a paper index in ``[-m, n]``).

    With ``platoon = (N, ring)`` the vehicle is ``"head"`` (open platoon) or a position
    ``1..N``: column ``i`` of the open platoon, ``i - 1`` on the ring.
    """
    if platoon is not None:
        size, ring = platoon
        if vehicle == "head" and not ring:
            return 0
        allowed = f"an integer position in [1, {size}]" + ("" if ring else ' or "head"')
        if isinstance(vehicle, bool) or not isinstance(vehicle, int | np.integer) or not (
            1 <= int(vehicle) <= size
        ):
            raise ConfigError(field, f"must be {allowed}, got {vehicle!r}")
        return int(vehicle) - 1 if ring else int(vehicle)
    if vehicle == "head":
        return 0
    if isinstance(vehicle, bool) or not isinstance(vehicle, int | np.integer):
        raise ConfigError(field, f'must be "head" or an integer in [{-m}, {n}], got {vehicle!r}')
    if not -m <= int(vehicle) <= n:
        raise ConfigError(field, f'must be "head" or an integer in [{-m}, {n}], got {vehicle}')
    return int(vehicle) + m + 1


def _window(t: np.ndarray, start: float, end: float, dt: float) -> np.ndarray:
    eps = 1e-6 * dt
    return (t > start + eps) & (t < end - eps)


def _check_sign(name: str, value: float, meaning: str, example: float) -> None:
    """``value`` must have the sign of ``example`` (strictly): e.g. a deceleration < 0."""
    neg = example < 0
    if not (math.isfinite(value) and (value < 0 if neg else value > 0)):
        hint = "; use accel_time = 0 for no recovery phase" if name == "accel" else ""
        raise ConfigError(
            name,
            f"is {meaning} and must be {'< 0' if neg else '> 0'} (m/s², e.g. {example}), got "
            f"{value!r}: its sign is not reinterpreted{hint}",
        )


@dataclass(frozen=True, repr=False)
class Sine(Record):
    """``a = amplitude cos(2 pi (t - start) / period)`` for ``start < t < end``.

    Section V-A: ``Sine(0.2, 12.0, 20.0)`` on the head vehicle.
    """

    amplitude: float
    period: float
    start: float
    end: float | None = None
    vehicle: Vehicle = "head"
    target = "accel"

    def toml_table(self) -> dict[str, Any]:
        """The ``[[scenario.perturbations]]`` entry of this perturbation."""
        end = self.start + self.period if self.end is None else self.end
        return {"type": "sine", "vehicle": self.vehicle, "amplitude": self.amplitude,
                "period": self.period, "start": self.start, "end": end}  # fmt: skip

    def window(self) -> tuple[float, float, str]:
        """``(start, end, key)``: when it may act, and the key that sets the start."""
        return self.start, self.start + self.period if self.end is None else self.end, "start"

    def values(self, t: np.ndarray, dt: float) -> np.ndarray:
        end = self.start + self.period if self.end is None else self.end
        out = self.amplitude * np.cos(2.0 * np.pi / self.period * (t - self.start))
        return np.where(_window(t, self.start, end, dt), out, np.nan)


@dataclass(frozen=True, repr=False)
class Brake(Record):
    """``a = decel`` for ``start < t < start + duration`` (Section V-B: vehicle 1, -5, 1 s)."""

    vehicle: Vehicle
    start: float = 20.0
    duration: float = 1.0
    decel: float = -5.0
    target = "accel"

    def __post_init__(self) -> None:
        _check_sign("decel", self.decel, "the braking acceleration", -5.0)

    def toml_table(self) -> dict[str, Any]:
        """The ``[[scenario.perturbations]]`` entry of this perturbation."""
        return {"type": "brake", "vehicle": self.vehicle, "start": self.start,
                "duration": self.duration, "decel": self.decel}  # fmt: skip

    def window(self) -> tuple[float, float, str]:
        """``(start, end, key)``: when it may act, and the key that sets the start."""
        return self.start, self.start + self.duration, "start"

    def values(self, t: np.ndarray, dt: float) -> np.ndarray:
        active = _window(t, self.start, self.start + self.duration, dt)
        return np.where(active, self.decel, np.nan)


@dataclass(frozen=True, repr=False)
class BrakeProfile(Record):
    """Brake at ``decel`` for ``decel_time``, hold (a = 0) for ``hold_time``, accelerate at
    ``accel`` for ``accel_time``, then cruise; each phase an open window from ``start`` on."""

    start: float = 20.0
    decel: float = -5.0
    decel_time: float = 2.0
    hold_time: float = 5.0
    accel: float = 2.0
    accel_time: float = 5.0
    vehicle: Vehicle = "head"
    target = "accel"

    def __post_init__(self) -> None:
        _check_sign("decel", self.decel, "the braking acceleration", -5.0)
        _check_sign("accel", self.accel, "the recovery acceleration", 2.0)

    def toml_table(self) -> dict[str, Any]:
        """The ``[[scenario.perturbations]]`` entry of this perturbation."""
        keys = ("vehicle", "start", "decel", "decel_time", "hold_time", "accel", "accel_time")
        return {"type": "brake_profile", **{k: getattr(self, k) for k in keys}}

    def window(self) -> tuple[float, float, str]:
        """``(start, end, key)``: when it may act, and the key that sets the start."""
        return (self.start, self.start + self.decel_time + self.hold_time + self.accel_time,
                "start")  # fmt: skip

    def values(self, t: np.ndarray, dt: float) -> np.ndarray:
        t1 = self.start + self.decel_time
        t2 = t1 + self.hold_time
        t3 = t2 + self.accel_time
        out = np.full(t.shape, np.nan)
        eps = 1e-6 * dt
        # phases are contiguous: a boundary sample belongs to the later phase
        out[(t > self.start + eps) & (t < t1 - eps)] = self.decel
        out[(t >= t1 - eps) & (t < t2 - eps)] = 0.0
        out[(t >= t2 - eps) & (t < t3 - eps)] = self.accel
        return out


@dataclass(frozen=True, repr=False)
class Profile(Record):
    """Piecewise acceleration (``target="accel"``) or speed (``target="speed"``) profile.

    Active for ``times[0] <= t < times[-1]``. ``interpolation="step"`` holds ``values[i]`` on
    ``[times[i], times[i+1])``; ``"linear"`` interpolates. A speed profile is tracked as closely
    as the acceleration limits allow: ``a_k = (v(t_{k+1}) - v_k) / dt``, then clipped.
    """

    times: tuple[float, ...]
    values_: tuple[float, ...]
    target: str = "accel"
    interpolation: str = "step"
    vehicle: Vehicle = "head"

    def __post_init__(self) -> None:
        times = np.asarray(self.times, dtype=float)
        if len(self.times) < 2 or len(self.times) != len(self.values_):
            raise ConfigError(
                "times", "needs at least 2 times and as many values as times, got "
                f"{len(self.times)} times and {len(self.values_)} values"
            )
        if not np.all(np.isfinite(times)) or not np.all(np.isfinite(self.values_)):
            raise ConfigError("values", "times and values must be finite")
        if np.any(np.diff(times) <= 0):
            raise ConfigError("times", "must be strictly increasing")
        if self.target not in ("accel", "speed"):
            raise ConfigError("target", f'must be "accel" or "speed", got {self.target!r}')
        if self.interpolation not in ("step", "linear"):
            raise ConfigError(
                "interpolation", f'must be "step" or "linear", got {self.interpolation!r}'
            )
        if self.target == "speed" and min(self.values_) < 0:
            raise ConfigError("values", "speeds must be >= 0")

    def toml_table(self) -> dict[str, Any]:
        """The ``[[scenario.perturbations]]`` entry of this profile (a CSV's samples inline)."""
        return {"type": f"{self.target}_profile", "vehicle": self.vehicle,
                "times": list(self.times), "values": list(self.values_),
                "interpolation": self.interpolation}  # fmt: skip

    def _eval(self, t: np.ndarray) -> np.ndarray:
        times = np.asarray(self.times)
        vals = np.asarray(self.values_)
        if self.interpolation == "linear":
            return np.interp(t, times, vals)
        idx = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1)
        return vals[idx]

    def window(self) -> tuple[float, float, str]:
        """``(start, end, key)``: when it may act, and the key that sets the start."""
        return float(self.times[0]), float(self.times[-1]), "times"

    def values(self, t: np.ndarray, dt: float) -> np.ndarray:
        eps = 1e-6 * dt
        active = (t >= self.times[0] - eps) & (t < self.times[-1] - eps)
        # a speed profile prescribes where the vehicle should be one step later
        query = t + dt if self.target == "speed" else t
        query = np.clip(query, self.times[0], self.times[-1])
        return np.where(active, self._eval(query), np.nan)


@dataclass(frozen=True, repr=False)
class Recorded(Record):
    """The head replays a recorded speed: column ``column`` of the trajectory file ``file``,
    its first sample at simulation time ``start``.

    Between samples the speed is ``"linear"`` or held (``"previous"``). On each step
    ``[t, t + dt]`` inside the recording the head's acceleration is ``(V(t + dt) - V(t)) / dt``
    (not clipped by the limits), so from the recorded initial speed its speed is ``V`` at
    every step, hence the recording's value at every sample time a step lands on (up to
    round-off). After the recording the head cruises.
    """

    file: str
    column: str
    times: tuple[float, ...]
    speeds: tuple[float, ...]
    interpolation: str = "linear"
    start: float = 0.0
    vehicle: Vehicle = "head"
    target = "accel"

    def toml_table(self) -> dict[str, Any]:
        """The ``[[scenario.perturbations]]`` entry (the file as the problem file names it)."""
        return {"type": "trajectory", "vehicle": self.vehicle, "file": self.file,
                "column": self.column, "interpolation": self.interpolation,
                "start": self.start}  # fmt: skip

    def window(self) -> tuple[float, float, str]:
        """``(start, end, key)``: when it may act, and the key that sets the start."""
        return float(self.times[0]), float(self.times[-1]), "start"

    def speed(self, t: np.ndarray, dt: float) -> np.ndarray:
        """The recorded speed ``V(t)`` (clamped to the recording's ends)."""
        times = np.asarray(self.times)
        vals = np.asarray(self.speeds)
        if self.interpolation == "linear":
            return np.interp(t, times, vals)
        idx = np.searchsorted(times, np.asarray(t) + 1e-6 * dt, side="right") - 1
        return vals[np.clip(idx, 0, len(times) - 1)]

    def values(self, t: np.ndarray, dt: float) -> np.ndarray:
        eps = 1e-6 * dt
        active = (t >= self.times[0] - eps) & (t + dt <= self.times[-1] + eps)
        acc = (self.speed(t + dt, dt) - self.speed(t, dt)) / dt
        return np.where(active, acc, np.nan)


Perturbation = Sine | Brake | BrakeProfile | Profile | Recorded


def overrides(
    perturbations: Sequence[Perturbation], t: np.ndarray, dt: float, m: int, n: int,
    platoon: tuple[int, bool] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Acceleration overrides and speed targets, each ``(T, m + n + 2)``, NaN when free.

    Later perturbations win where several are active on the same vehicle at once.
    ``platoon``: the ``(N, ring)`` layout of a platoon or ring (see :func:`vehicle_column`).
    """
    nv = m + n + 2
    acc = np.full((len(t), nv), np.nan)
    spd = np.full((len(t), nv), np.nan)
    for i, p in enumerate(perturbations):
        col = vehicle_column(p.vehicle, m, n, f"scenario.perturbations[{i}].vehicle", platoon)
        vals = p.values(t, dt)
        on = ~np.isnan(vals)
        dest, other = (spd, acc) if p.target == "speed" else (acc, spd)
        dest[on, col] = vals[on]
        other[on, col] = np.nan
    return acc, spd


# --------------------------------------------------------------------------------------------
# Problem files
# --------------------------------------------------------------------------------------------


def read_profile_csv(
    path: Path, field: str, source: str | None = None
) -> tuple[list[float], list[float]]:
    """Two columns ``t, value`` (comma separated, optional header line), read by
    :func:`lcc_synth.schema.readers.read_file` (a missing, unreadable or binary file is a
    ConfigError naming ``field`` and the path)."""
    text = read_file(path, field, source, "CSV file")
    times: list[float] = []
    vals: list[float] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = [p.strip() for p in line.split(",")]
        try:
            t, v = float(parts[0]), float(parts[1])
        except (ValueError, IndexError):
            if lineno == 1 or not times:  # header
                continue
            raise ConfigError(field, f"{path}:{lineno}: expected 't,value', got {line!r}") from None
        if not (math.isfinite(t) and math.isfinite(v)):
            raise ConfigError(field, f"{path}:{lineno}: values must be finite")
        times.append(t)
        vals.append(v)
    return times, vals


def perturbation_from_table(
    table: Mapping[str, Any], field: str, m: int, n: int, base_dir: Path | None = None,
    platoon: tuple[int, bool] | None = None,
) -> Perturbation:
    """Build one perturbation from a ``[[scenario.perturbations]]`` entry (``platoon``: see
    :func:`vehicle_column`)."""
    if not isinstance(table, Mapping):
        raise ConfigError(field, f"must be a table, got {table!r}")
    kind = declared("scenario.perturbations").get(table, "type", field)
    P = declared(f"scenario.perturbations:{kind}")
    P.check(table, field)
    vehicle = P.raw(table, "vehicle")
    vehicle_column(vehicle, m, n, f"{field}.vehicle", platoon)
    if kind == "sine":
        period = P.get(table, "period", field)
        start = P.get(table, "start", field)
        end = P.get(table, "end", field, default=start + period, lo=start)
        amp = P.get(table, "amplitude", field)
        return Sine(amp, period, start, end, vehicle)
    try:
        if kind == "brake":
            return Brake(
                vehicle,
                P.get(table, "start", field),
                P.get(table, "duration", field),
                P.get(table, "decel", field),
            )
        if kind == "brake_profile":
            return BrakeProfile(
                P.get(table, "start", field),
                P.get(table, "decel", field),
                P.get(table, "decel_time", field),
                P.get(table, "hold_time", field),
                P.get(table, "accel", field),
                P.get(table, "accel_time", field),
                vehicle,
            )
    except ConfigError as err:
        if err.field.startswith(field):  # a reader's error already names the field
            raise
        raise ConfigError(f"{field}.{err.field}", err.message) from None
    if kind == "trajectory":
        return recorded_from_table(table, field, base_dir, platoon)
    target = "accel" if kind == "accel_profile" else "speed"
    interp = P.get(table, "interpolation", field)
    if "csv" in table:
        if "times" in table or "values" in table:
            raise ConfigError(f"{field}.csv", "give either csv or times/values, not both")
        rel = P.get(table, "csv", field)
        path = Path(rel) if base_dir is None or Path(rel).is_absolute() else base_dir / rel
        times, vals = read_profile_csv(path, f"{field}.csv")
    else:
        times = P.get(table, "times", field)
        vals = P.get(table, "values", field)
    try:
        return Profile(tuple(times), tuple(vals), target, interp, vehicle)
    except ConfigError as err:
        raise ConfigError(f"{field}.{err.field}", err.message) from None


def recorded_from_table(
    table: Mapping[str, Any], field: str, base_dir: Path | None = None,
    platoon: tuple[int, bool] | None = None,
) -> Recorded:
    """The :class:`Recorded` of a ``type = "trajectory"`` entry: the file (relative to the
    problem file) read by :func:`~lcc_synth.schema.trajectories.read_trajectory`, a speed
    column ``v<k>`` of it, on the head vehicle of an open road."""
    P = declared("scenario.perturbations:trajectory")
    vehicle = P.raw(table, "vehicle")
    if vehicle != "head" or (platoon is not None and platoon[1]):
        raise ConfigError(f"{field}.vehicle", 'a recorded trajectory drives the head vehicle '
                          f'of an open road: must be "head", got {vehicle!r}')
    traj = recorded_file(table, field, base_dir)
    column = P.get(table, "column", field)
    if not (isinstance(column, str) and column.startswith("v")):
        raise ConfigError(f"{field}.column", f"must be a speed column v<k> (m/s), got {column!r}")
    speeds = traj.column(column, f"{field}.column")
    start = P.get(table, "start", field)
    times = start + (traj.t - traj.t[0])
    return Recorded(P.get(table, "file", field), column, tuple(float(x) for x in times),
                    tuple(float(x) for x in speeds), P.get(table, "interpolation", field),
                    start, vehicle)  # fmt: skip


def recorded_file(
    table: Mapping[str, Any], field: str, base_dir: Path | None = None
) -> Trajectory:
    """The trajectory file of a ``type = "trajectory"`` entry (``file`` relative to
    ``base_dir``, the problem file's directory)."""
    rel = declared("scenario.perturbations:trajectory").get(table, "file", field)
    path = Path(rel) if base_dir is None or Path(rel).is_absolute() else base_dir / rel
    try:
        return read_trajectory(path, f"{field}.file")
    except ConfigError as err:
        if err.field.startswith(field):  # the file itself: missing, unreadable
            raise
        raise ConfigError(f"{field}.file", str(err)) from None
