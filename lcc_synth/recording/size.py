"""How big a recording will be, before the work is done (``--max-recording-size``).

Estimation method
-----------------
A simulation recording is the sum of its entities (:mod:`lcc_synth.recording.simulation`).
Per recorded run (one controller on one scenario): five time series (velocity, spacing,
acceleration: one series per vehicle; the CAV command and the AEB flag: one per CAV), the
road view (a point per vehicle and frame), the run's documents and, for a predictive
controller (MPC, DeeP-LCC), its solve times, status and plans (line strips). Per recording:
the layout (blueprint, a fixed cost per view, sent when the recording opens and again when
the command finishes) and the scenario's documents. A time-series entity costs
``rows x (ROW_BYTES + series x VALUE_BYTES)``, the road ``frames x (ROW_BYTES + vehicles x
POINT_BYTES)``, a plan ``ROW_BYTES + strips x STRIP_BYTES + points x POINT_BYTES``, plus
``RUN_BYTES`` per run (its static styles and documents: about 2 kB of Arrow schema per
chunk). Only the number of rows depends on the mode:

* exact (``--record-every N``): every N-th sample, every controller step, at most about 200
  plans per run: known in advance. ``VALUE_BYTES`` is the incompressible 8 bytes of a
  float64 (LZ4 compresses the repeated values of a cruise), so the estimate is an upper
  bound.
* ``minmax`` (:mod:`lcc_synth.recording.decimate`): the rows depend on the signal, so each
  entity gets a bound per simulated second: a smooth series ``SMOOTH_ROWS_PER_S``, a
  noise-dominated one (the accelerations and commands of a scenario with acceleration or V2V
  noise) the M4 bound ``1 + 2 k`` rows per :data:`~lcc_synth.recording.decimate.NOISY_BUCKET_S`
  for ``k`` series, the road ``ROAD_FRAMES_PER_S`` (a ring, always moving: every
  :data:`~lcc_synth.recording.decimate.ROAD_BUCKET_S`), a flag ``FLAG_ROWS`` per run, the MPC
  solve times ``1 + 2 k`` rows per second, plans every
  :data:`~lcc_synth.recording.decimate.MPC_PLAN_S` with ``STRIP_POINTS`` points per strip.
  Not counted: full rate during emergency braking (eq. 29) and around collisions, which no
  estimate made before the run can know: a run that brakes on AEB for a long time records
  more than the estimate.

Measured figures (``benchmarks/bench_recording_size.py``, rerun-sdk 0.41)
-------------------------------------------------------------------------
Per unit, from the Arrow size (LZ4) of every chunk by entity of exact recordings of
``paper_table2``, ``paper_appendix_c`` and the ring: a row 14.2-15.3 B (an all-zero flag at
full rate: time stamp, row id, offsets), a float64 value 2.5-7.9 B above it (a ring's cruise
.. a transient), a road point 3.0-8.0 B, the static part of a run 28-33 kB, a view of the
layout 11.3-11.7 kB; the file is the Arrow data within 1 %. Rows per simulated second with
``minmax`` (the default run's 24 runs, ``paper_table2``, ``paper_appendix_c``,
``mpc_head_brake``): velocities and spacings 0.3-5.7 (13 with the chattering emergency braking
of ``mpc_head_brake``, at full rate), the noisy accelerations of ``heterogeneous`` 17.5-19.2
(12 series: bound 25), road frames 1.0-3.8 (the ring 5), plans 0.1-2 with about 5 points per
strip (the command's 12). The estimate against the file of the real command (``lcc-synth
simulate`` / ``run``): exact 1.06-1.54 x (table2, appendix C with 3 seeds, the MPC, noisy
HDVs, the ring), ``minmax`` 1.07-1.9 x for those, 2.4 x for the default ``lcc-synth run``
(6.6 MB) and 3.7 x for the 300 s ring (a long cruise keeps few rows). The tests
(``tests/test_fail_estimates.py``) hold it to at least the real size less
:data:`ESTIMATE_MARGIN` (10 %) and at most :data:`ESTIMATE_FACTOR` (4) times it.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from lcc_synth.errors import ConfigError
from lcc_synth.recording.decimate import (
    MPC_PLAN_S,
    MPC_TIMING_BUCKET_S,
    NOISY_BUCKET_S,
    ROAD_BUCKET_S,
)
from lcc_synth.resources import format_size

__all__ = [
    "DEFAULT_LIMIT",
    "ESTIMATE_FACTOR",
    "ESTIMATE_MARGIN",
    "MPCShape",
    "RecordingEstimate",
    "RunShape",
    "estimate_recording_bytes",
    "estimate_simulation_recording",
    "estimate_suite_recording",
    "format_size",
    "mpc_shape",
    "parse_size",
    "run_shape",
    "simulation_views",
]

#: Default ``--max-recording-size`` (bytes): 1 GB.
DEFAULT_LIMIT = 10**9
#: The estimate is never below the real size by more than this fraction (outside AEB).
ESTIMATE_MARGIN = 0.10
#: ... and at most this many times the real size (tests/test_fail_estimates.py).
ESTIMATE_FACTOR = 4.0

#: Bytes of one recorded row of an entity besides its values (time, row id, offsets).
ROW_BYTES = 16.0
#: Bytes of one recorded float64 value (incompressible: an upper bound).
VALUE_BYTES = 8.0
#: Bytes of one recorded point (road, plans: two float32).
POINT_BYTES = 8.0
#: Bytes of one line strip besides its points (offsets).
STRIP_BYTES = 4.0
#: Fixed bytes of a recorded run: static styles and documents (about 11 chunks).
RUN_BYTES = 24_000.0
#: ... and of a predictive controller's history entities (5 chunks).
MPC_RUN_BYTES = 12_000.0
#: Fixed bytes of a recording: properties, status, the scenario's comparison table.
RECORDING_BYTES = 20_000.0
#: Bytes of one view of the layout (blueprint), its container share included.
VIEW_BYTES = 12_000.0

#: minmax: rows per simulated second of a smooth time series (measured at most 5.7).
SMOOTH_ROWS_PER_S = 6.0
#: minmax: road frames per simulated second on an open road (measured at most 3.8).
ROAD_FRAMES_PER_S = 4.0
#: minmax: rows of a flag (AEB, MPC status) per run: its ends and a few edges.
FLAG_ROWS = 8.0
#: minmax: points per plan strip (measured about 5; the command's plan about 12).
STRIP_POINTS = 8.0

_UNITS = {
    "": 1, "b": 1, "k": 10**3, "kb": 10**3, "m": 10**6, "mb": 10**6, "g": 10**9, "gb": 10**9,
    "t": 10**12, "tb": 10**12, "p": 10**15, "pb": 10**15, "kib": 2**10, "mib": 2**20,
    "gib": 2**30, "tib": 2**40, "pib": 2**50,
}  # fmt: skip


def parse_size(text: str, field: str = "--max-recording-size") -> int:
    """``"1GB"``, ``"500 MB"``, ``"2.5GiB"`` or a number of bytes as bytes (decimal units kB,
    MB, GB, TB, PB = powers of 1000; KiB, MiB, GiB, TiB, PiB = powers of 1024).

    Raises
    ------
    ConfigError
        For ``field``: not a size, or not positive.
    """
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([A-Za-z]*)\s*", str(text))
    unit = m.group(2).lower() if m else ""
    if m is None or unit not in _UNITS:
        raise ConfigError(
            field, f"expected a size such as 500MB, 2GB or 1.5GiB (units B, kB, MB, GB, TB, "
            f"PB, KiB, MiB, GiB, TiB, PiB), got {text!r}",
        )  # fmt: skip
    value = float(m.group(1)) * _UNITS[unit]
    if not (math.isfinite(value) and value >= 1):
        raise ConfigError(field, f"must be at least 1 byte, got {text!r}")
    return int(value)


@dataclass(frozen=True)
class MPCShape:
    """What a predictive controller's history adds to a recorded run.

    Attributes
    ----------
    steps : int
        Controller steps of the run.
    horizon : int
        Prediction steps ``N`` (a plan of the command has ``N`` points, a predicted state
        ``N + 1``).
    vehicles : int
        Vehicles of the predicted velocity and spacing strips (0: none are recorded).
    cavs : int
        Command plans per step (a joint MPC: one per CAV).
    """

    steps: int
    horizon: int
    vehicles: int
    cavs: int = 1


@dataclass(frozen=True)
class RunShape:
    """What one recorded simulation run is made of.

    Attributes
    ----------
    seconds : float
        Simulated duration.
    samples : int
        Samples of the result (the scenario's steps, or every ``record_every``-th).
    vehicles : int
        Vehicles (series of velocity and acceleration; road points).
    cavs : int
        CAVs (series of the command and the AEB flag).
    ring : bool
        A ring road (the spacing of every vehicle; the road view always moves).
    noisy : bool
        Acceleration or V2V noise: the accelerations and the command are noise-dominated.
    mpc : MPCShape, optional
        The controller's history, when it has one.
    count : int
        How many such runs (controllers x recorded seeds).
    """

    seconds: float
    samples: int
    vehicles: int
    cavs: int = 1
    ring: bool = False
    noisy: bool = False
    mpc: MPCShape | None = None
    count: int = 1


@dataclass(frozen=True)
class RecordingEstimate:
    """An upper estimate of a recording's size (see the module docstring).

    Attributes
    ----------
    bytes : float
        Estimated size of the file.
    runs : int
        Recorded runs.
    views : int
        Views of its layout.
    decimate : int or str
        ``"minmax"`` or the stride.
    what : str
        What it counts, e.g. ``"200 draws x 3 controllers recorded, minmax"``.
    """

    bytes: float
    runs: int
    views: int
    decimate: int | str
    what: str

    def __str__(self) -> str:
        return f"~{format_size(self.bytes)}"


def _series_rows(seconds: float, samples: int, series: int, noisy: bool) -> float:
    """minmax rows of one time series entity (bounded by the samples)."""
    if noisy:
        rate = (1 + 2 * series) / NOISY_BUCKET_S
    else:
        rate = SMOOTH_ROWS_PER_S
    return min(float(samples), rate * seconds + 2 * series + 2)


def _run_bytes(run: RunShape, decimate: int | str) -> float:
    """Upper estimate of one run's bytes (without the layout)."""
    nv, nc, T = run.vehicles, run.cavs, max(1, run.samples)
    spacing = nv if run.ring else nv - 1
    minmax = decimate == "minmax"
    total = RUN_BYTES
    signals = ((nv, run.noisy), (spacing, False), (nv, False), (nc, run.noisy))  # a, s, v, u
    if minmax:
        for k, noisy in signals:
            total += _series_rows(run.seconds, T, k, noisy) * (ROW_BYTES + k * VALUE_BYTES)
        total += min(T, FLAG_ROWS) * (ROW_BYTES + nc * VALUE_BYTES)
        frames = (1.0 / ROAD_BUCKET_S if run.ring else ROAD_FRAMES_PER_S) * run.seconds + 2
        total += min(T, frames) * (ROW_BYTES + nv * POINT_BYTES)
    else:
        rows = (T - 1) // int(decimate) + 1 + (1 if (T - 1) % int(decimate) else 0)
        values = nv + spacing + nv + 2 * nc
        total += rows * (6 * ROW_BYTES + values * VALUE_BYTES + nv * POINT_BYTES)
    if run.mpc is not None:
        total += _mpc_bytes(run.mpc, run.seconds, minmax)
    return total


def _mpc_bytes(mpc: MPCShape, seconds: float, minmax: bool) -> float:
    """Upper estimate of a predictive controller's history entities."""
    S, N = max(1, mpc.steps), mpc.horizon
    timing_k, status_k = 2, mpc.cavs + 1
    total = MPC_RUN_BYTES
    if minmax:
        timing = min(S, (1 + 2 * timing_k) * seconds / MPC_TIMING_BUCKET_S + 2)
        total += timing * (ROW_BYTES + timing_k * VALUE_BYTES)
        total += min(S, FLAG_ROWS) * (ROW_BYTES + status_k * VALUE_BYTES)
        plans = min(S, seconds / MPC_PLAN_S + 2)
        u_points = min(N, STRIP_POINTS * 1.5)
        x_points = min(N + 1, STRIP_POINTS)
    else:
        total += S * (2 * ROW_BYTES + (timing_k + status_k) * VALUE_BYTES)
        every = max(1, S // 200)
        plans = (S - 1) // every + 1
        u_points, x_points = N, N + 1
    per_plan = ROW_BYTES + mpc.cavs * (STRIP_BYTES + u_points * POINT_BYTES)
    total += plans * per_plan
    if mpc.vehicles:
        per_plan = ROW_BYTES + mpc.vehicles * (STRIP_BYTES + x_points * POINT_BYTES)
        total += 2 * plans * per_plan  # predicted velocity and spacing
    return total


def simulation_views(controllers: int, mpc: int = 0) -> int:
    """Views of :func:`~lcc_synth.recording.layout.simulation_blueprint`: velocity, spacing,
    acceleration, road and description per controller, the command, the comparison, the
    status and the events, and two per MPC."""
    return 5 * controllers + 4 + 2 * mpc


def estimate_recording_bytes(
    runs: Sequence[RunShape],
    decimate: int | str = "minmax",
    views: int = 0,
    blueprints: int = 1,
    what: str = "",
) -> RecordingEstimate:
    """Upper estimate of a simulation recording holding ``runs`` (see the module docstring).

    Parameters
    ----------
    runs : sequence of RunShape
        The recorded runs (each ``count`` times).
    decimate : int or "minmax"
        The recording's ``--record-every``.
    views : int
        Views of its layout (:func:`simulation_views`).
    blueprints : int
        How many times the layout is written (the CLI's recorder: twice).
    what : str
        What the estimate counts (for messages).

    Returns
    -------
    RecordingEstimate
    """
    if decimate != "minmax" and (
        isinstance(decimate, bool) or not isinstance(decimate, int) or decimate < 1
    ):
        raise ConfigError("decimate", f"must be an integer >= 1 or 'minmax', got {decimate!r}")
    total = RECORDING_BYTES + views * VIEW_BYTES * blueprints
    count = 0
    for run in runs:
        total += run.count * _run_bytes(run, decimate)
        count += run.count
    mode = "minmax" if decimate == "minmax" else f"every {decimate} step(s)"
    return RecordingEstimate(float(total), count, views, decimate, what or f"{count} runs, {mode}")


def _noisy(scenario: Any) -> bool:
    """Does ``scenario`` put noise on accelerations or V2V data?"""
    v2v = getattr(scenario, "v2v", None)
    noise = [getattr(scenario, "hdv_accel_noise", 0.0), getattr(scenario, "accel_noise_uniform",
             0.0)] + [getattr(v2v, k, 0.0) for k in ("spacing_noise", "velocity_noise",
                                                      "position_noise")]  # fmt: skip
    return any(float(x) > 0 for x in noise)


def mpc_shape(controller: Any, scenario: Any) -> MPCShape | None:
    """The :class:`MPCShape` of a built controller with a ``history()`` (MPC, DeeP-LCC), else
    ``None``: its horizon (``settings.horizon``) and sample time on ``scenario``."""
    if not callable(getattr(controller, "history", None)):
        return None
    settings = getattr(controller, "settings", None)
    horizon = int(getattr(settings, "horizon", 50) or 50)
    ts = getattr(controller, "sample_time", None)
    return _shape(scenario, horizon, ts, "deep" not in type(controller).__name__.lower())


def _shape(scenario: Any, horizon: int, sample_time: float | None, states: bool) -> MPCShape:
    ts = float(sample_time) if sample_time else float(scenario.dt)
    steps = max(1, math.ceil(float(scenario.duration) / ts))
    nc = len(tuple(scenario.cav_columns))
    return MPCShape(steps, horizon, int(scenario.n_vehicles) if states else 0, nc)


def run_shape(scenario: Any, mpc: MPCShape | None = None, count: int = 1) -> RunShape:
    """The :class:`RunShape` of a run of ``scenario`` (a
    :class:`~lcc_synth.simulation.scenario.Scenario`)."""
    samples = (int(scenario.steps) - 1) // int(scenario.record_every) + 1
    return RunShape(
        seconds=float(scenario.duration), samples=samples, vehicles=int(scenario.n_vehicles),
        cavs=len(tuple(scenario.cav_columns)), ring=bool(scenario.ring),
        noisy=_noisy(scenario), mpc=mpc, count=int(count),
    )  # fmt: skip


def estimate_simulation_recording(
    scenario: Any,
    controllers: Mapping[str, Any],
    seeds: int,
    decimate: int | str = "minmax",
) -> RecordingEstimate:
    """The recording of ``lcc-synth simulate``: every controller on ``seeds`` recorded
    scenarios of ``scenario`` (one layout tab per seed when there are several; the layout
    written twice, as :class:`~lcc_synth.recording.cli.SimulationRecorder` does)."""
    runs, mpc = [], 0
    for ctrl in controllers.values():
        shape = mpc_shape(ctrl, scenario)
        mpc += shape is not None
        runs.append(run_shape(scenario, shape, count=seeds))
    views = simulation_views(len(controllers), mpc) * max(1, seeds)
    mode = "minmax" if decimate == "minmax" else f"every {decimate} step(s)"
    what = (f"{seeds} draws x {len(controllers)} controllers recorded, {mode}" if seeds > 1
            else f"{len(controllers)} controllers, {mode}")  # fmt: skip
    return estimate_recording_bytes(runs, decimate, views, blueprints=2, what=what)


def estimate_suite_recording(
    scenarios: Sequence[tuple[Any, Sequence[Mapping[str, Any]]]],
    controllers: int,
    documents: int = 0,
    decimate: int | str = "minmax",
) -> RecordingEstimate:
    """The recording of ``lcc-synth run``: each scenario with the controllers that run in it.

    Parameters
    ----------
    scenarios : sequence of (Scenario, sequence of mapping)
        Each scenario and the tables of the controllers that run in it, merged for its layout
        (:func:`lcc_synth.experiments.suite_size.suite_recording_estimate` builds them); the
        predictive ones (``type = "mpc"`` or ``"deep_lcc"``) with their history.
    controllers : int
        Controllers of the suite (every scenario tab has a view per controller).
    documents : int
        |Gamma| curves and gains recorded besides (counted as the documents of a run each,
        with two views).
    decimate : int or "minmax"
        The recording's ``--record-every``.

    Returns
    -------
    RecordingEstimate
        The layout written once.
    """
    runs, views, n = [], 0, 0
    for scenario, tables in scenarios:
        for table in tables:
            kind = str(table.get("type", ""))
            shape = None
            if kind in ("mpc", "deep_lcc"):
                horizon, ts = _table_horizon(kind, table)
                shape = _shape(scenario, horizon, ts, kind == "mpc")
            runs.append(run_shape(scenario, shape))
            n += 1
        views += simulation_views(int(controllers))
    runs.append(RunShape(0.0, 1, 1, count=int(documents)))
    views += 2 * int(documents)
    mode = "minmax" if decimate == "minmax" else f"every {decimate} step(s)"
    what = f"{len(scenarios)} scenarios, {n} runs, {mode}"
    return estimate_recording_bytes(runs, decimate, views, blueprints=1, what=what)


def _table_horizon(kind: str, table: Mapping[str, Any]) -> tuple[int, float]:
    """``(horizon, sample_time)`` of a controller table (the settings' defaults)."""
    if kind == "mpc":
        from lcc_synth.mpc.settings import MPCSettings

        d = MPCSettings()
        return int(table.get("horizon", d.horizon)), float(table.get("sample_time",
                                                                       d.sample_time))
    from lcc_synth.deeplcc.settings import DeePLCCSettings

    d = DeePLCCSettings()
    data = table.get("data") if isinstance(table.get("data"), Mapping) else {}
    return int(table.get("horizon", d.horizon)), float(data.get("dt", d.sample_time))
