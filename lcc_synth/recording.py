"""Rerun recordings (``.rrd``) of simulation, analysis and synthesis runs.

Every recording command writes one file, by default ``logs/<problem>-<UTC timestamp>.rrd``
(see :func:`recording_path`), with a default blueprint so that opening it in the Rerun viewer
(``lcc-synth review PATH.rrd``) immediately shows what matters.

Entity layout (stable: tests and users rely on these names)
-----------------------------------------------------------
Timeline ``time``: simulated time in seconds (a Rerun *duration* timeline, stored in ns).
``<scenario>`` is the problem name and ``<controller>`` the controller name, both reduced to the
characters ``[A-Za-z0-9_.-]`` (others become ``_``).

Simulation (:func:`record_simulation`), under ``/<scenario>/<controller>/``:

=====================  =========================================================================
``velocity``           ``Scalars``, one series per vehicle (head, HDVs ahead, CAV, HDVs behind)
``spacing``            ``Scalars``, one series per vehicle except the head vehicle
``acceleration``       ``Scalars``, one series per vehicle (applied acceleration)
``cav/u_cmd``          ``Scalars``, the CAV command before limits and emergency braking
``cav/aeb_active``     ``Scalars``, 1 while the CAV's emergency braking is active, else 0
``road``               ``Points2D``, every vehicle over time: x = position relative to the CAV
                       (m), y = ``ROAD_Y_SCALE`` x velocity error (m/s), as in the paper's Fig. 11;
                       CAV blue, HDVs grey, head vehicle yellow; labels = vehicle names
``road/equilibrium``   ``LineStrips2D`` (static), the zero-velocity-error line
``events``             ``TextLog`` on the timeline: CAV emergency braking on/off, collisions
``metrics``            ``TextDocument`` (markdown), the run's metrics table
``controller``         ``TextDocument`` (markdown), ``describe()`` and ``stats()`` of the controller
``mpc/solve_time_ms``  ``Scalars`` (MPC only): whole controller step and OSQP time per step (ms)
``mpc/status``         ``Scalars`` (MPC only): status code (0 QP, 1 shifted plan, 2 static gain,
                       3 hold) and 1 when a fallback was used
``mpc/predicted/*``    ``LineStrips2D`` (MPC only): ``u``, ``velocity``, ``spacing`` plans at
                       each recorded controller step (x = seconds ahead, y = value)
=====================  =========================================================================

``/<scenario>/metrics`` (markdown) compares every controller recorded so far and
``/<scenario>/status`` says whether the run completed or was interrupted (and by what).

Vehicle names in series and labels: ``head``, ``hdv-2``, ``hdv-1`` (ahead of the CAV), ``cav``,
``hdv1``, ``hdv2``... (behind), i.e. the paper's vehicle index; series colors as above.

Analysis (:func:`record_gamma`, :func:`record_region_map`) under ``/analysis/``:
``gamma/<case>`` (``LineStrips2D``: x = log10 omega, y = |Gamma(j omega)|, with ``gamma/unit``
the line |Gamma| = 1) and ``gamma/<case>/report`` (markdown); ``regions/<name>`` (a
``SegmentationImage`` of classes 0 = plant unstable, 1 = stable, 2 = string stable, with an
annotation context naming them) and ``regions/<name>/report`` (markdown: axes and fractions).
``/analysis/report`` holds the analysis command's whole report (:func:`record_analysis_file`).
Synthesis (:func:`record_synthesis`, :func:`record_gains`) under ``/synthesis/<name>/``:
``gains`` (``BarChart`` of the gain on every state), ``report`` (markdown: state names, gains,
true H2, LMI bound, verdicts, solver), ``pareto/front`` and ``pareto/patterns`` (sparsity
designs: x = vehicles heard, y = true H2); the |Gamma| curve of the gain as above.

Interrupted runs: :func:`open_recording` is a context manager that flushes and finalises the
file on every exit (exception, ``KeyboardInterrupt``) and records the interruption in
``/<scenario>/status``; the commands record each controller as soon as its result exists
(:class:`SimulationRecorder`), so the file holds everything finished before the interruption.

Rerun's usage analytics live in its viewer/CLI binary, not in the logging SDK (writing a file
sends nothing). Rerun 0.41 documents only ``rerun analytics disable`` (a per-user setting); its
analytics pipeline also switches itself off whenever the ``CI`` environment variable is set, so
every Rerun process started here gets ``CI=1`` in its own environment
(:func:`viewer_environment`), leaving the user's settings and our own process untouched.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import uuid
import weakref
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError

__all__ = [
    "APP_ID",
    "ROAD_Y_SCALE",
    "COLOR_CAV",
    "COLOR_HDV",
    "COLOR_HEAD",
    "add_recording_arguments",
    "recording_path",
    "recording_decimation",
    "entity_name",
    "vehicle_names",
    "vehicle_colors",
    "simulation_blueprint",
    "analysis_blueprint",
    "synthesis_blueprint",
    "open_recording",
    "record_simulation",
    "record_metrics",
    "SimulationRecorder",
    "record_mpc_history",
    "record_gamma",
    "record_region_map",
    "record_gains",
    "record_synthesis",
    "record_analysis_file",
    "record_synthesis_file",
    "gamma_grid",
    "record_text",
    "viewer_environment",
    "rerun_binary",
    "RecordingSummary",
    "EntitySummary",
    "summarize_recording",
]

APP_ID = "lcc_synth"
#: Road view: metres of screen height per m/s of velocity error (the 2D view keeps aspect 1:1).
ROAD_Y_SCALE = 10.0
COLOR_CAV = (31, 119, 180)
COLOR_HDV = (150, 150, 150)
COLOR_HEAD = (230, 180, 0)
#: Colors of controllers in overlay views (u_cmd of all controllers in one plot).
_PALETTE = [
    (31, 119, 180), (214, 39, 40), (44, 160, 44), (148, 103, 189),
    (255, 127, 14), (140, 86, 75), (227, 119, 194), (23, 190, 207),
]  # fmt: skip
_REGION_COLORS = {0: (235, 235, 235), 1: (170, 170, 170), 2: (31, 119, 180)}
_REGION_LABELS = {0: "plant unstable", 1: "stable, not string stable", 2: "string stable"}


def _rr():
    """Import rerun lazily (heavy: ~1 s); the CLI keeps ``--help`` fast."""
    import rerun as rr

    return rr


def _rrb():
    import rerun.blueprint as rrb

    return rrb


# --------------------------------------------------------------------------------------------
# CLI helpers
# --------------------------------------------------------------------------------------------


def add_recording_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--rrd PATH``, ``--no-record`` and ``--record-every N`` to a command's parser."""
    group = parser.add_argument_group("recording (Rerun .rrd, see `lcc-synth review`)")
    excl = group.add_mutually_exclusive_group()
    excl.add_argument(
        "--rrd",
        metavar="PATH",
        help="write the recording to PATH (default: logs/<problem>-<UTC timestamp>.rrd)",
    )
    excl.add_argument("--no-record", action="store_true", help="do not write a recording")
    group.add_argument(
        "--record-every",
        type=int,
        default=1,
        metavar="N",
        help="record every N-th simulation step (decimation; default 1 = every step)",
    )


def recording_path(
    args: argparse.Namespace, problem_name: str, now: datetime | None = None
) -> Path | None:
    """Where the command records: ``None`` with ``--no-record``, ``--rrd`` when given, else
    ``logs/<problem>-<UTC timestamp>.rrd`` (relative to the working directory)."""
    if getattr(args, "no_record", False):
        return None
    recording_decimation(args)  # validate early, before any work is done
    given = getattr(args, "rrd", None)
    if given:
        path = Path(given)
        if path.suffix != ".rrd":
            raise ConfigError("--rrd", f"must be a path ending in .rrd, got {given!r}")
        if path.exists() and path.is_dir():
            raise ConfigError("--rrd", f"is a directory, expected a file path: {given!r}")
        return path
    stamp = (now or datetime.now(UTC)).strftime("%Y%m%dT%H%M%SZ")
    return Path("logs") / f"{entity_name(problem_name)}-{stamp}.rrd"


def recording_decimation(args: argparse.Namespace) -> int:
    """The validated ``--record-every`` value (>= 1)."""
    every = getattr(args, "record_every", 1)
    if isinstance(every, bool) or not isinstance(every, int) or every < 1:
        raise ConfigError("--record-every", f"must be an integer >= 1, got {every!r}")
    return every


# --------------------------------------------------------------------------------------------
# Names and colors
# --------------------------------------------------------------------------------------------

_BAD = re.compile(r"[^A-Za-z0-9_.\-]")


def entity_name(name: str) -> str:
    """``name`` reduced to one safe entity-path part (``[A-Za-z0-9_.-]``, others -> ``_``)."""
    cleaned = _BAD.sub("_", str(name).strip())
    if not cleaned or set(cleaned) <= {"."}:
        raise ConfigError("name", f"cannot be used as a recording entity name: {name!r}")
    return cleaned


def vehicle_names(m: int, n: int) -> list[str]:
    """Names of the ``m + n + 2`` array columns: ``head, hdv-m..hdv-1, cav, hdv1..hdvn``."""
    return (
        ["head"]
        + [f"hdv{i}" for i in range(-m, 0)]
        + ["cav"]
        + [f"hdv{i}" for i in range(1, n + 1)]
    )


def vehicle_colors(m: int, n: int) -> np.ndarray:
    """``(m + n + 2, 3)`` uint8 colors: head yellow, HDVs grey, CAV blue (the paper's figures)."""
    colors = np.tile(np.array(COLOR_HDV, dtype=np.uint8), (m + n + 2, 1))
    colors[0] = COLOR_HEAD
    colors[m + 1] = COLOR_CAV
    return colors


# --------------------------------------------------------------------------------------------
# Blueprints
# --------------------------------------------------------------------------------------------


def simulation_blueprint(scenario: str, controllers: Sequence[str], mpc: Sequence[str] = ()):
    """Default layout of a simulation recording.

    Left: one row per quantity (velocity, spacing, acceleration), one time-series view per
    controller side by side. Right: the road view of every controller, the CAV command of all
    controllers overlaid, the comparison metrics and each controller's description; for the
    MPC controllers named in ``mpc``, tabs with their solve times / status and their predicted
    velocities.
    """
    rrb = _rrb()
    s = entity_name(scenario)
    ctrls = [entity_name(c) for c in controllers]
    if not ctrls:
        raise ConfigError("controllers", "a simulation recording needs at least one controller")

    def row(quantity: str, title: str):
        return rrb.Horizontal(
            *[
                rrb.TimeSeriesView(origin=f"/{s}/{c}/{quantity}", name=f"{c}: {title}")
                for c in ctrls
            ],
            name=title,
        )

    plots = rrb.Vertical(
        row("velocity", "velocity (m/s)"),
        row("spacing", "spacing (m)"),
        row("acceleration", "acceleration (m/s²)"),
        name="time series",
    )
    road = rrb.Vertical(
        *[
            rrb.Spatial2DView(
                origin=f"/{s}/{c}/road",
                name=f"{c}: road (x: m from CAV, y: {ROAD_Y_SCALE:g}·velocity error)",
            )
            for c in ctrls
        ],
        name="road",
    )
    u_cmd = rrb.TimeSeriesView(
        origin=f"/{s}",
        contents=[f"+ /{s}/{c}/cav/**" for c in ctrls],
        name="CAV command u_cmd (m/s²) and AEB",
    )
    tabs = [
        rrb.TextDocumentView(origin=f"/{s}/metrics", name="metrics"),
        *[
            rrb.TextDocumentView(origin=f"/{s}/{c}/controller", name=f"{c}: controller")
            for c in ctrls
        ],
        rrb.TextDocumentView(origin=f"/{s}/status", name="status"),
        rrb.TextLogView(
            origin=f"/{s}", contents=[f"+ /{s}/{c}/events" for c in ctrls], name="events"
        ),
    ]
    for c in (entity_name(x) for x in mpc):
        tabs += [
            rrb.TimeSeriesView(
                origin=f"/{s}/{c}/mpc",
                contents=[f"+ /{s}/{c}/mpc/solve_time_ms", f"+ /{s}/{c}/mpc/status"],
                name=f"{c}: MPC solve time (ms), status",
            ),
            rrb.Spatial2DView(
                origin=f"/{s}/{c}/mpc/predicted/velocity",
                name=f"{c}: predicted velocity (x: s ahead, y: m/s)",
            ),
        ]
    texts = rrb.Tabs(*tabs, name="reports")
    right = rrb.Vertical(road, u_cmd, texts, row_shares=[2, 1, 2])
    return rrb.Blueprint(rrb.Horizontal(plots, right, column_shares=[3, 2]), collapse_panels=False)


def analysis_blueprint(
    cases: Sequence[str] = (), regions: Sequence[str] = (), report: bool = False
):
    """Default layout of an analysis recording: |Gamma| curves, region maps, reports (and the
    command's whole report at ``/analysis/report`` when ``report``)."""
    rrb = _rrb()
    views = []
    if cases:
        views.append(rrb.Spatial2DView(origin="/analysis/gamma", name="|Γ(jω)| vs log10 ω"))
    for r in regions:
        views.append(
            rrb.Spatial2DView(origin=f"/analysis/regions/{entity_name(r)}", name=f"region {r}")
        )
    reports = [
        rrb.TextDocumentView(origin=f"/analysis/gamma/{entity_name(c)}/report", name=f"{c}")
        for c in cases
    ] + [
        rrb.TextDocumentView(
            origin=f"/analysis/regions/{entity_name(r)}/report", name=f"region {r}"
        )
        for r in regions
    ]
    if report:
        reports.append(rrb.TextDocumentView(origin="/analysis/report", name="report"))
    if not views:
        views.append(rrb.Spatial2DView(origin="/analysis", name="analysis"))
    parts = [rrb.Grid(*views, name="plots")]
    if reports:
        parts.append(rrb.Tabs(*reports, name="reports"))
    return rrb.Blueprint(rrb.Horizontal(*parts, column_shares=[3, 2][: len(parts)]))


def synthesis_blueprint(names: Sequence[str], gamma: bool = True, pareto: bool = False):
    """Default layout of a synthesis recording: gains bar charts, |Gamma| curves, the Pareto
    front (sparsity designs) and the reports."""
    rrb = _rrb()
    plots = [
        rrb.BarChartView(origin=f"/synthesis/{entity_name(n)}/gains", name=f"{n}: gains")
        for n in names
    ] or [rrb.BarChartView(origin="/synthesis")]
    if gamma:
        plots.append(rrb.Spatial2DView(origin="/analysis/gamma", name="|Γ(jω)| vs log10 ω"))
    if pareto:
        plots += [
            rrb.Spatial2DView(
                origin=f"/synthesis/{entity_name(n)}/pareto",
                name=f"{n}: Pareto front (vehicles heard vs true H2)",
            )
            for n in names
        ]
    reports = [
        rrb.TextDocumentView(origin=f"/synthesis/{entity_name(n)}/report", name=f"{n}: report")
        for n in names
    ] or [rrb.TextDocumentView(origin="/synthesis")]
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(*plots), rrb.Tabs(*reports), column_shares=[3, 2])
    )


# --------------------------------------------------------------------------------------------
# The recording itself
# --------------------------------------------------------------------------------------------


@contextmanager
def open_recording(
    path: str | Path, name: str, blueprint: Any = None, scenario: str | None = None
) -> Iterator[Any]:
    """Open a Rerun recording that writes to ``path``; yields the ``rerun.RecordingStream``.

    The file is flushed and finalised on every exit. On an exception (a controller raising,
    ``KeyboardInterrupt``...) ``/<scenario>/status`` records the interruption and the exception
    propagates; everything recorded before stays in a readable file.

    Parameters
    ----------
    path : path-like
        The ``.rrd`` file (its directory is created).
    name : str
        Recording name shown by the viewer (e.g. the problem name).
    blueprint : rerun.blueprint.Blueprint, optional
        The default layout saved in the file.
    scenario : str, optional
        Entity prefix of the status document (default: ``name``).
    """
    rr = _rr()
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError("--rrd", f"cannot create directory {str(path.parent)!r}: {err}") from None
    if not os.access(path.parent, os.W_OK):
        raise ConfigError("--rrd", f"directory {str(path.parent)!r} is not writable")
    status = f"/{entity_name(scenario or name)}/status"
    rec = rr.RecordingStream(APP_ID, recording_id=uuid.uuid4())
    rec.save(path, default_blueprint=blueprint)
    rec.send_recording_name(name)
    started = datetime.now(UTC).isoformat(timespec="seconds")
    record_text(rec, status, f"# Status\n\nstarted {started}: **running**\n")
    with rec:  # flush + finalise the file sink on every exit (Rerun 0.41 context manager)
        try:
            yield rec
        except GeneratorExit:  # the with-block was abandoned (interpreter exit): just finalise
            raise
        except BaseException as err:
            what = type(err).__name__ + (f": {err}" if str(err) else "")
            record_text(
                rec,
                status,
                f"# Status\n\nstarted {started}: **interrupted** by `{what}`; the recording holds "
                "everything recorded before the interruption.\n",
            )
            raise
        else:
            done = datetime.now(UTC).isoformat(timespec="seconds")
            record_text(rec, status, f"# Status\n\nstarted {started}, **complete** {done}\n")


def record_text(rec: Any, entity: str, markdown: str) -> None:
    """Log a static markdown ``TextDocument`` at ``entity`` (the latest one wins)."""
    rr = _rr()
    rec.log(entity, rr.TextDocument(markdown, media_type=rr.MediaType.MARKDOWN), static=True)


def _sample_indices(T: int, every: int) -> np.ndarray:
    idx = np.arange(0, T, every)
    if idx[-1] != T - 1:
        idx = np.append(idx, T - 1)
    return idx


def _time_column(t: np.ndarray):
    """The ``time`` timeline (seconds -> ns, rounded: Rerun's float path truncates, which puts
    e.g. 2.05 s at 2049999999 ns)."""
    rr = _rr()
    ns = np.round(np.asarray(t, dtype=np.float64) * 1e9).astype(np.int64)
    return rr.TimeColumn("time", duration=ns.astype("timedelta64[ns]"))


class _ArrowBatch:
    """A ready pyarrow array as a Rerun component batch (``as_arrow_array`` protocol)."""

    def __init__(self, array):
        self.array = array

    def as_arrow_array(self):
        return self.array


def _rows(rr: Any, descriptor: Any, flat: Any, rows: int, per_row: int):
    """``rows`` rows of ``per_row`` instances each: a component column over ``flat`` without
    copying (``Scalars.columns(...).partition(...)`` copies the data several times)."""
    offsets = np.arange(0, rows * per_row + 1, per_row, dtype=np.int32)
    return rr.ComponentColumn(descriptor, _ArrowBatch(flat), offsets=offsets)


def _send_series(rec: Any, entity: str, t: Any, values: np.ndarray, names, colors) -> None:
    """One entity with ``values.shape[1]`` scalar series (one ``send_columns`` call); ``t`` is
    the times (s) or a ready ``TimeColumn``."""
    import pyarrow as pa

    rr = _rr()
    values = np.ascontiguousarray(values, dtype=np.float64)
    rows, k = values.shape
    rec.log(
        entity,
        rr.SeriesLines(
            names=list(names), colors=np.asarray(colors, dtype=np.uint8), widths=[1.5] * k
        ),
        static=True,
    )
    flat = pa.array(values.reshape(-1), type=pa.float64())  # NaN stays NaN (a gap)
    column = _rows(rr, rr.Scalars.descriptor_scalars(), flat, rows, k)
    tcol = _time_column(t) if isinstance(t, np.ndarray) else t
    rec.send_columns(entity, indexes=[tcol], columns=[column])


def _flush_started(rec: Any) -> None:
    """Start writing what was logged without waiting (the context manager's exit waits)."""
    rec.flush(timeout_sec=0.0)


def _fmt(value: Any) -> str:
    if isinstance(value, bool) or value is None:
        return str(value)
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        v = float(value)
        if math.isnan(v):
            return "—"
        return f"{v:.6g}" if (v == 0 or 1e-3 <= abs(v) < 1e6) else f"{v:.4e}"
    return str(value)


def _cell(text: Any) -> str:
    """Text safe inside a markdown table cell."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def _jsonable(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def _is_scalar(value: Any) -> bool:
    return isinstance(value, str | bool | int | float | np.generic) or value is None


def _mapping_markdown(
    title: str, data: Mapping[str, Any], vehicles: Sequence[str] | None = None
) -> str:
    """Markdown of a (possibly nested) mapping: scalars as a table, per-vehicle lists as a
    vehicle table, anything else as JSON."""
    lines = [f"## {title}", ""]
    scalars = {k: v for k, v in data.items() if _is_scalar(v)}
    if scalars:
        lines += ["| quantity | value |", "|---|---|"]
        lines += [f"| {_cell(k)} | {_cell(_fmt(v))} |" for k, v in scalars.items()]
        lines.append("")
    rest = {k: v for k, v in data.items() if k not in scalars}
    for key, value in rest.items():
        if (
            isinstance(value, Mapping)
            and vehicles is not None
            and value
            and all(
                isinstance(v, list | tuple | np.ndarray) and len(v) == len(vehicles)
                for v in value.values()
            )
        ):
            cols = list(value)
            lines += [f"### {key} (per vehicle, head to tail)", ""]
            lines += ["| vehicle | " + " | ".join(cols) + " |", "|---|" + "---|" * len(cols)]
            for i, veh in enumerate(vehicles):
                lines.append(f"| {veh} | " + " | ".join(_fmt(value[c][i]) for c in cols) + " |")
            lines.append("")
        elif isinstance(value, Mapping) and all(_is_scalar(v) for v in value.values()) and value:
            lines += [f"### {key}", "", "| name | value |", "|---|---|"]
            lines += [f"| {k} | {_fmt(v)} |" for k, v in value.items()]
            lines.append("")
        else:
            lines += [
                f"### {key}",
                "",
                "```json",
                json.dumps(_jsonable(value), indent=1),
                "```",
                "",
            ]
    return "\n".join(lines)


@dataclass
class _RunFacts:
    """What the metrics document of a recorded run always shows (from the result itself)."""

    vehicles: list[str]
    events: str
    row: dict[str, Any]


@dataclass
class _RecState:
    """Per-recording state: comparison rows per scenario, run facts, colors handed out."""

    rows: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    runs: dict[tuple[str, str], _RunFacts] = field(default_factory=dict)
    colors: dict[str, tuple[int, int, int]] = field(default_factory=dict)

    def color(self, key: str) -> tuple[int, int, int]:
        if key not in self.colors:
            self.colors[key] = _PALETTE[len(self.colors) % len(_PALETTE)]
        return self.colors[key]


_STATES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _state(rec: Any) -> _RecState:
    try:
        return _STATES.setdefault(rec, _RecState())
    except TypeError:  # not weak-referenceable (a test double): no shared state
        return _RecState()


def _comparison_markdown(scenario: str, rows: Mapping[str, Mapping[str, Any]]) -> str:
    ctrls = list(rows)
    keys: list[str] = []
    for row in rows.values():
        keys += [k for k, v in row.items() if _is_scalar(v) and k not in keys]
    lines = [f"# {scenario}: metrics", ""]
    lines += ["| metric | " + " | ".join(ctrls) + " |", "|---|" + "---|" * len(ctrls)]
    for k in keys:
        lines.append(f"| {k} | " + " | ".join(_fmt(rows[c].get(k, "")) for c in ctrls) + " |")
    return "\n".join(lines) + "\n"


def _record_events(rec, entity, t, aeb_on, collided, ctime, names, limit: int = 1000) -> None:
    """``TextLog`` events on the timeline: emergency braking on/off (WARN), collisions
    (ERROR); at most ``limit`` AEB edges (a chattering AEB would flood the log)."""
    rr = _rr()
    edges = np.flatnonzero(np.diff(aeb_on.astype(np.int8), prepend=np.int8(0)))
    times, texts, levels = [], [], []
    for k in edges[:limit]:
        times.append(t[k])
        texts.append("CAV emergency braking ON" if aeb_on[k] else "CAV emergency braking off")
        levels.append("WARN")
    for i in np.flatnonzero(collided):
        times.append(ctime[i])
        texts.append(f"COLLISION: {names[i]} hit the vehicle ahead")
        levels.append("ERROR")
    if not times:
        return
    order = np.argsort(times, kind="stable")
    rec.send_columns(
        entity,
        indexes=[_time_column(np.asarray(times, dtype=np.float64)[order])],
        columns=rr.TextLog.columns(
            text=[texts[i] for i in order], level=[levels[i] for i in order]
        ),
    )


def record_simulation(
    rec: Any,
    result: Any,
    scenario: str,
    *,
    controller: str | None = None,
    metrics: Mapping[str, Any] | None = None,
    decimate: int = 1,
    run: int = 0,
    mpc_history: Any = None,
) -> str:
    """Record one controller's simulation (one batch member) and flush it.

    Parameters
    ----------
    rec : rerun.RecordingStream
        From :func:`open_recording`.
    result : lcc_synth.simulation.SimResult
        Arrays ``(batch, T, n_vehicles)`` etc. (see the simulator's contract).
    scenario : str
        Entity prefix (the problem name).
    controller : str, optional
        Entity name of the controller (default ``result.controller``); e.g. ``"fd_lcc_seed3"``
        to record several batch members of one controller.
    metrics : mapping, optional
        The run's metrics (e.g. the ``--json`` shape of ``lcc-synth simulate``): scalars go into
        the per-controller and comparison tables, per-vehicle lists into a vehicle table.
    decimate : int
        Record every ``decimate``-th step (the last step is always recorded).
    run : int
        Which batch member to record.
    mpc_history : optional
        An MPC controller's per-step history (see :func:`record_mpc_history`).

    Returns
    -------
    str
        The entity prefix ``/<scenario>/<controller>``.
    """
    if isinstance(decimate, bool) or not isinstance(decimate, int | np.integer) or decimate < 1:
        raise ConfigError("decimate", f"must be an integer >= 1, got {decimate!r}")
    rr = _rr()
    t_all = np.asarray(result.t, dtype=np.float64)
    velocity = np.asarray(result.velocity)
    batch, T, nv = velocity.shape
    if not 0 <= run < batch:
        raise ConfigError("run", f"must be in [0, {batch - 1}], got {run}")
    m, n, cav = int(result.m), int(result.n), int(result.cav)
    if nv != m + n + 2 or cav != m + 1 or t_all.shape != (T,):
        raise ConfigError(
            "result",
            f"inconsistent SimResult shapes: velocity {velocity.shape}, m={m}, n={n}, cav={cav}",
        )
    s = entity_name(scenario)
    c = entity_name(controller if controller is not None else result.controller)
    base = f"/{s}/{c}"
    idx = _sample_indices(T, int(decimate))
    t = t_all[idx]
    tcol = _time_column(t)
    names = vehicle_names(m, n)
    colors = vehicle_colors(m, n)
    label = [f"{c} {v}" for v in names]

    vel = velocity[run, idx]
    _send_series(rec, f"{base}/velocity", tcol, vel, label, colors)
    _send_series(
        rec,
        f"{base}/spacing",
        tcol,
        np.asarray(result.spacing)[run, idx, 1:],
        label[1:],
        colors[1:],
    )
    _send_series(
        rec, f"{base}/acceleration", tcol, np.asarray(result.acceleration)[run, idx], label, colors
    )
    state = _state(rec)
    u_color = state.color(base)  # one color per controller: u_cmd of all controllers overlaid
    u_cmd = np.asarray(result.u_cmd)[run, idx, None]
    _send_series(rec, f"{base}/cav/u_cmd", tcol, u_cmd, [f"{c} u_cmd"], [u_color])
    aeb = np.asarray(result.aeb_active)[run, idx].astype(np.float64)[:, None]
    _send_series(rec, f"{base}/cav/aeb_active", tcol, aeb, [f"{c} AEB active"], [(214, 39, 40)])

    # Road view (Fig. 11): x = position relative to the CAV, y = scaled velocity error.
    pos = np.asarray(result.position)[run, idx]
    v_star = float(np.asarray(result.v_star).reshape(-1)[run])
    xy = np.empty((len(idx), nv, 2), dtype=np.float32)
    xy[..., 0] = pos - pos[:, cav : cav + 1]
    xy[..., 1] = ROAD_Y_SCALE * (vel - v_star)
    rec.log(
        f"{base}/road",
        rr.Points2D.from_fields(colors=colors, radii=[1.5] * nv, labels=names, show_labels=False),
        static=True,
    )
    import pyarrow as pa

    item = pa.list_(pa.field("item", pa.float32(), nullable=False), 2)
    points = pa.FixedSizeListArray.from_arrays(pa.array(xy.reshape(-1)), type=item)
    rec.send_columns(
        f"{base}/road",
        indexes=[tcol],
        columns=[_rows(rr, rr.Points2D.descriptor_positions(), points, len(idx), nv)],
    )
    x_lo, x_hi = float(np.nanmin(xy[..., 0])), float(np.nanmax(xy[..., 0]))
    rec.log(
        f"{base}/road/equilibrium",
        rr.LineStrips2D([[[x_lo - 5.0, 0.0], [x_hi + 5.0, 0.0]]], colors=[(90, 90, 90)], radii=0.2),
        static=True,
    )

    # Texts: controller description and metrics.
    info = dict(getattr(result, "controller_info", {}) or {})
    stats = dict(getattr(result, "controller_stats", {}) or {})
    s_star = float(np.asarray(result.s_star).reshape(-1)[run])
    header = (
        f"# {c}\n\nscenario `{scenario}`, run {run} of {batch}; m = {m} ahead, n = {n} behind; "
        f"v* = {_fmt(v_star)} m/s, s* = {_fmt(s_star)} m; {T} steps recorded every {decimate}.\n\n"
    )
    record_text(
        rec,
        f"{base}/controller",
        header
        + _mapping_markdown("description", info)
        + "\n"
        + _mapping_markdown("run statistics", stats),
    )
    collided = np.asarray(result.collided)[run]
    ctime = np.asarray(result.collision_time)[run]
    crash = [f"{names[i]} at t = {_fmt(float(ctime[i]))} s" for i in np.flatnonzero(collided)]
    aeb_on = np.asarray(result.aeb_active)[run].astype(bool)
    episodes = int(np.count_nonzero(aeb_on[1:] & ~aeb_on[:-1]) + bool(aeb_on[0])) if T else 0
    _record_events(rec, f"{base}/events", t_all, aeb_on, collided, ctime, names)
    state.runs[(s, c)] = _RunFacts(
        names,
        f"collisions: {', '.join(crash) if crash else 'none'}; emergency braking: "
        f"{episodes} episode(s), {int(aeb_on.sum())} sample(s) active",
        {"collisions": len(crash), "aeb_episodes": episodes},
    )
    record_metrics(rec, scenario, c, metrics or {})
    if mpc_history is not None:
        record_mpc_history(rec, base, mpc_history, run=run)
    _flush_started(rec)
    return base


def record_metrics(rec: Any, scenario: str, controller: str, metrics: Mapping[str, Any]) -> None:
    """(Re)write the metrics document of a recorded run and the scenario's comparison table.

    ``controller`` is the name given to :func:`record_simulation`. Use it when the metrics are
    only known after every controller ran (e.g. reductions versus a baseline).
    """
    s, c = entity_name(scenario), entity_name(controller)
    state = _state(rec)
    facts = state.runs.get((s, c))
    if facts is None:
        raise ConfigError("controller", f"{controller!r} was not recorded in scenario {scenario!r}")
    mdict = {k: v for k, v in dict(metrics).items() if k not in ("controller", "controller_stats")}
    record_text(
        rec,
        f"/{s}/{c}/metrics",
        f"# {c}: metrics\n\n"
        + (_mapping_markdown("metrics", mdict, facts.vehicles) if mdict else "")
        + f"\n{facts.events}\n",
    )
    rows = state.rows.setdefault(s, {})
    rows[c] = {**facts.row, **{k: v for k, v in mdict.items() if _is_scalar(v)}}
    record_text(rec, f"/{s}/metrics", _comparison_markdown(scenario, rows))
    _flush_started(rec)


class SimulationRecorder:
    """Record the controllers of one problem as their results arrive (for CLI commands).

    The recording opens at the first result (its default path needs the problem name), inside
    ``stack`` so that it is finalised however the command ends; each call records one
    controller at once, so an interrupted command keeps every controller finished before.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed flags of :func:`add_recording_arguments` (validated here, before any work).
    stack : contextlib.ExitStack
        Owns the open recording.

    Examples
    --------
    >>> with ExitStack() as stack:                                        # doctest: +SKIP
    ...     recorder = SimulationRecorder(args, stack)
    ...     for name, result in ...:
    ...         recorder(spec, name, result)
    ...     recorder.metrics({name: metrics_dict, ...})
    """

    def __init__(self, args: argparse.Namespace, stack: Any):
        self.args = args
        self.stack = stack
        self.enabled = not getattr(args, "no_record", False)
        self.every = recording_decimation(args)
        if self.enabled:
            recording_path(args, "check")  # a bad --rrd fails before the simulation runs
        self.path: Path | None = None
        self.rec: Any = None
        self.scenario: str | None = None

    def __call__(self, spec: Any, name: str, result: Any) -> None:
        """Record controller ``name``'s ``result`` of ``spec`` (``spec.name``,
        ``spec.controllers``); MPC controllers' ``history()`` is recorded too."""
        if not self.enabled:
            return
        if self.rec is None:
            self.scenario = spec.name
            self.path = recording_path(self.args, spec.name)
            mpc = [
                n
                for n, c in dict(spec.controllers).items()
                if callable(getattr(c, "history", None))
            ]
            blueprint = simulation_blueprint(spec.name, list(spec.controllers), mpc)
            self.rec = self.stack.enter_context(open_recording(self.path, spec.name, blueprint))
        controller = dict(spec.controllers).get(name)
        history = None
        if callable(getattr(controller, "history", None)):
            history = controller.history() or None
        record_simulation(
            self.rec, result, self.scenario, controller=name, decimate=self.every,
            mpc_history=history,
        )  # fmt: skip

    def metrics(self, report: Mapping[str, Mapping[str, Any]]) -> None:
        """Write each controller's final metrics (``{name: metrics}``) and the comparison."""
        if self.rec is None:
            return
        for name, entry in report.items():
            record_metrics(self.rec, self.scenario, name, entry)


#: ``lcc_synth.mpc`` per-step status codes (its ``STATUS_CODES``); 0 = QP solved.
_MPC_STATUS = {0: "qp", 1: "shifted_plan", 2: "static_gain", 3: "hold"}


def record_mpc_history(
    rec: Any, base: str, history: Mapping[str, Any], run: int = 0, plan_every: int | None = None
) -> None:
    """Record an MPC controller's per-step history under ``<base>/mpc/``.

    ``history`` is ``MPCController.history()`` of :mod:`lcc_synth.mpc`: ``t (S,)`` controller
    step times; per scenario ``(B, S, ...)``: ``step_time`` and ``osqp_time`` (s), ``status``
    (0 QP, 1 shifted plan, 2 static gain, 3 hold), ``plan (B, S, N)`` planned model inputs,
    ``predicted_velocity`` / ``predicted_spacing`` ``(B, S, N+1, V)`` and ``pred_time (N+1,)``
    offsets (s); arrays without the batch axis are accepted too.

    Entities: ``mpc/solve_time_ms`` (series: whole step, OSQP), ``mpc/status`` (status code and
    1 when a fallback was used), and ``mpc/predicted/{u,velocity,spacing}``: ``LineStrips2D``
    at each recorded controller step, x = seconds ahead of that step, y = the predicted value
    (one strip per vehicle), so scrubbing the timeline shows the plan of the moment.
    ``plan_every`` records every k-th plan (default: at most about 200 plans).
    """
    import pyarrow as pa

    rr = _rr()
    if "t" not in history:
        raise ConfigError("mpc_history", "needs the controller step times 't'")
    t = np.asarray(history["t"], dtype=np.float64).reshape(-1)
    S = t.size
    if S == 0:
        return

    def member(key: str, per_step_ndim: int):
        if key not in history or history[key] is None:
            return None
        x = np.asarray(history[key])
        if x.ndim == per_step_ndim + 2:  # (B, S, ...)
            if not 0 <= run < x.shape[0]:
                raise ConfigError("run", f"must be in [0, {x.shape[0] - 1}], got {run}")
            x = x[run]
        return x[:S]

    tcol = _time_column(t)
    times = [member(k, 0) for k in ("step_time", "osqp_time", "solve_time")]
    times = [(k, x) for k, x in zip(("step", "OSQP", "solve"), times, strict=True) if x is not None]
    if times:
        vals = np.column_stack([x.astype(np.float64) * 1e3 for _, x in times])
        _send_series(
            rec, f"{base}/mpc/solve_time_ms", tcol, vals, [f"{k} time (ms)" for k, _ in times],
            _PALETTE[: len(times)],
        )  # fmt: skip
    status = member("status", 0)
    if status is not None:
        code = status.astype(np.float64)
        vals = np.column_stack([code, (code > 0).astype(np.float64)])
        names = ["status (" + ", ".join(f"{k} {v}" for k, v in _MPC_STATUS.items()) + ")",
                 "fallback used"]  # fmt: skip
        _send_series(rec, f"{base}/mpc/status", tcol, vals, names, [(90, 90, 90), (214, 39, 40)])

    every = plan_every or max(1, S // 200)
    steps = np.arange(0, S, every)
    offsets = history.get("pred_time")
    for key, label in (("plan", "u"), ("predicted_velocity", "velocity"),
                       ("predicted_spacing", "spacing")):  # fmt: skip
        pred = member(key, 1 if key == "plan" else 2)
        if pred is None:
            continue
        pred = np.asarray(pred, dtype=np.float64)[steps]
        if pred.ndim == 2:
            pred = pred[:, :, None]
        K, H, V = pred.shape
        if offsets is not None:
            x = np.asarray(offsets, dtype=np.float64)[:H]
        elif "dt" in history:
            x = float(history["dt"]) * np.arange(H)
        else:
            raise ConfigError("mpc_history", f"{key} needs 'pred_time' or 'dt'")
        xy = np.empty((K, V, H, 2), dtype=np.float32)
        xy[..., 0] = x[None, None, :]
        xy[..., 1] = np.transpose(pred, (0, 2, 1))
        item = pa.list_(pa.field("item", pa.float32(), nullable=False), 2)
        pts = pa.FixedSizeListArray.from_arrays(pa.array(xy.reshape(-1)), type=item)
        strip_off = np.arange(0, K * V * H + 1, H, dtype=np.int32)
        strips = pa.ListArray.from_arrays(pa.array(strip_off), pts)
        rec.send_columns(
            f"{base}/mpc/predicted/{label}",
            indexes=[_time_column(t[steps])],
            columns=[_rows(rr, rr.LineStrips2D.descriptor_strips(), strips, K, V)],
        )
    _flush_started(rec)


def record_gamma(
    rec: Any,
    case: str,
    omega: np.ndarray,
    magnitude: np.ndarray,
    report: Mapping[str, Any] | None = None,
    color: Sequence[int] | None = None,
) -> None:
    """Record one |Gamma(j omega)| curve under ``/analysis/gamma/<case>``.

    x = log10(omega) (rad/s), y = |Gamma|; the line |Gamma| = 1 is ``/analysis/gamma/unit``.
    ``report`` (e.g. the string-stability report fields) goes to ``.../<case>/report``.
    """
    rr = _rr()
    omega = np.asarray(omega, dtype=np.float64).reshape(-1)
    mag = np.asarray(magnitude, dtype=np.float64).reshape(-1)
    if omega.shape != mag.shape or omega.size < 2 or np.any(omega <= 0):
        raise ConfigError("omega", "needs >= 2 positive frequencies matching the magnitudes")
    c = entity_name(case)
    xy = np.column_stack([np.log10(omega), mag]).astype(np.float32)
    col = color if color is not None else _state(rec).color(f"gamma/{c}")
    rec.log(
        f"/analysis/gamma/{c}",
        rr.LineStrips2D([xy], colors=[col], labels=[case], radii=0.01),
        static=True,
    )
    lo, hi = float(xy[0, 0]), float(xy[-1, 0])
    rec.log(
        "/analysis/gamma/unit",
        rr.LineStrips2D(
            [[[lo, 1.0], [hi, 1.0]]], colors=[(120, 120, 120)], labels=["|Γ| = 1"], radii=0.005
        ),
        static=True,
    )
    k = int(np.argmax(mag))
    data = {"peak |Γ| on the grid": float(mag[k]), "at ω (rad/s)": float(omega[k])}
    data.update(dict(report or {}))
    record_text(
        rec,
        f"/analysis/gamma/{c}/report",
        f"# {case}\n\n" + _mapping_markdown("head-to-tail", data),
    )
    _flush_started(rec)


def record_region_map(
    rec: Any,
    name: str,
    classes: np.ndarray,
    mu: np.ndarray,
    k: np.ndarray,
    report: Mapping[str, Any] | None = None,
) -> None:
    """Record a stable-region map (Figs. 7-8) under ``/analysis/regions/<name>``.

    ``classes[i, j]`` is the class at gains ``(k[i], mu[j])``: 0 plant unstable, 1 stable but not
    string stable, 2 string stable. The image is drawn with k increasing upwards; an annotation
    context names the classes (hover shows them). The report gives the axes and fractions.
    """
    rr = _rr()
    classes = np.asarray(classes)
    mu = np.asarray(mu, dtype=np.float64).reshape(-1)
    k = np.asarray(k, dtype=np.float64).reshape(-1)
    if classes.shape != (k.size, mu.size):
        raise ConfigError(
            "classes", f"shape {classes.shape} must be (len(k), len(mu)) = {(k.size, mu.size)}"
        )
    if classes.size and (classes.min() < 0 or classes.max() > 2):
        raise ConfigError("classes", "values must be 0 (unstable), 1 (stable) or 2 (string stable)")
    r = entity_name(name)
    img = classes.astype(np.uint8)
    if k.size > 1 and k[1] > k[0]:
        img = img[::-1]  # row 0 of an image is the top: put the largest k there
    rec.log(
        f"/analysis/regions/{r}",
        rr.AnnotationContext([(i, _REGION_LABELS[i], _REGION_COLORS[i]) for i in range(3)]),
        static=True,
    )
    rec.log(f"/analysis/regions/{r}", rr.SegmentationImage(img), static=True)
    total = max(classes.size, 1)
    data = {
        "mu range": f"[{_fmt(mu.min())}, {_fmt(mu.max())}] ({mu.size} points, left to right)",
        "k range": f"[{_fmt(k.min())}, {_fmt(k.max())}] ({k.size} points, bottom to top)",
        "fraction plant stable": float(np.count_nonzero(classes >= 1)) / total,
        "fraction string stable": float(np.count_nonzero(classes == 2)) / total,
    }
    data.update(dict(report or {}))
    record_text(
        rec,
        f"/analysis/regions/{r}/report",
        f"# region map {name}\n\n" + _mapping_markdown("grid", data),
    )
    _flush_started(rec)


def gamma_grid(peak_omega: float | None = None, points: int = 400) -> np.ndarray:
    """Frequencies (rad/s) for |Gamma| curves: log-spaced 1e-3..10, plus the peak frequency."""
    omega = np.logspace(-3, 1, points)
    if peak_omega is not None and np.isfinite(peak_omega) and peak_omega > 0:
        omega = np.unique(np.append(omega, float(peak_omega)))
    return omega


def record_synthesis(rec: Any, rep: Any, system: Any = None) -> None:
    """Record a synthesis report (``lcc_synth.synthesis.report.SynthesisReport``).

    Under ``/synthesis/<problem>/``: the gains bar chart and report (the gains file of contract
    3 plus solver, polish, baseline, timings and notes), the Pareto front of a sparsity sweep
    (``pareto``: LineStrips2D of the front and Points2D of every pattern found, x = vehicles
    heard, y = true H2); and, when ``system`` (the problem's :class:`~lcc_synth.problem.System`)
    is given and the model has a head vehicle, ``/analysis/gamma/<problem>``: |Gamma(j omega)|
    of the synthesised gain.
    """
    from lcc_synth.synthesis.gains_file import gains_document

    rr = _rr()
    name = rep.problem
    doc = dict(gains_document(rep))
    for key in ("solver", "polish", "baseline", "timings", "notes"):
        value = getattr(rep, key, None)
        if value:
            doc[key] = _jsonable(value)
    record_gains(rec, name, doc)
    if rep.pareto:
        n = entity_name(name)
        pts = np.array([[p["count"], p["h2"]] for p in rep.pareto], dtype=np.float32)
        labels = [
            ", ".join(str(v) for v in p.get("vehicles", [])) or "CAV only" for p in rep.pareto
        ]
        rec.log(
            f"/synthesis/{n}/pareto/patterns",
            rr.Points2D(pts, labels=labels, colors=[COLOR_HDV], radii=0.05),
            static=True,
        )
        front = sorted((p for p in rep.pareto if p.get("on_front")), key=lambda p: p["count"])
        if front:
            xy = np.array([[p["count"], p["h2"]] for p in front], dtype=np.float32)
            rec.log(
                f"/synthesis/{n}/pareto/front",
                rr.LineStrips2D([xy], colors=[COLOR_CAV], labels=["Pareto front"], radii=0.02),
                static=True,
            )
    if system is not None and rep.kind != "fd_lcc":
        from lcc_synth.string_stability import gamma_state_space

        model = system.linear_model(warn=False)
        omega = gamma_grid(rep.check.gamma_peak_omega)
        gamma = gamma_state_space(model, np.asarray(rep.input_K, float), float(rep.input_kh), omega)
        record_gamma(
            rec,
            name,
            omega,
            np.abs(gamma),
            {
                "gamma_peak (global check)": rep.check.gamma_peak,
                "gamma_peak_omega (rad/s)": rep.check.gamma_peak_omega,
                "string_stable": rep.check.string_stable,
                "plant_stable": rep.check.plant_stable,
            },
        )
    _flush_started(rec)


def record_synthesis_file(path: str | Path, rep: Any, system: Any = None) -> Path:
    """Write a synthesis recording to ``path`` (see :func:`record_synthesis`)."""
    path = Path(path)
    blueprint = synthesis_blueprint(
        [rep.problem], gamma=system is not None and rep.kind != "fd_lcc", pareto=bool(rep.pareto)
    )
    with open_recording(path, rep.problem, blueprint) as rec:
        record_synthesis(rec, rep, system)
    return path


def record_analysis_file(
    path: str | Path,
    name: str,
    *,
    gamma: Mapping[str, tuple[np.ndarray, np.ndarray, Mapping[str, Any]]] | None = None,
    regions: Mapping[str, Any] | None = None,
    region_reports: Mapping[str, Mapping[str, Any]] | None = None,
    summary: Mapping[str, Any] | None = None,
) -> Path:
    """Write an analysis recording (``lcc-synth analyze`` / ``regions``) to ``path``.

    Parameters
    ----------
    gamma : mapping, optional
        ``{case: (omega, |Gamma(j omega)|, report)}`` (see :func:`record_gamma`).
    regions : mapping, optional
        ``{name: RegionMap}`` of :mod:`lcc_synth.regions` (``mu``, ``k``, ``labels[a, b]`` at
        ``(mu[a], k[b])``; labels 0 unstable, 1 stable, 2 string stable).
    region_reports : mapping, optional
        Extra report fields per region map (fractions, fixed gains, expansion...).
    summary : mapping, optional
        The command's whole report (e.g. its ``--json`` object): ``/analysis/report``.
    """
    gamma = dict(gamma or {})
    regions = dict(regions or {})
    path = Path(path)
    blueprint = analysis_blueprint(list(gamma), list(regions), report=summary is not None)
    with open_recording(path, name, blueprint) as rec:
        for case, (omega, mag, report) in gamma.items():
            record_gamma(rec, case, omega, mag, report)
        for rname, rm in regions.items():
            extra = dict((region_reports or {}).get(rname, {}))
            record_region_map(rec, rname, np.asarray(rm.labels).T, rm.mu, rm.k, extra)
        if summary is not None:
            record_text(
                rec, "/analysis/report", f"# {name}\n\n" + _mapping_markdown("report", summary)
            )
    return path


def record_gains(rec: Any, name: str, gains: Mapping[str, Any]) -> None:
    """Record a synthesised gain under ``/synthesis/<name>/``.

    ``gains`` is the gains-file dict (``state_names``, ``gains`` {state: value}, ``K``, norms
    and verdicts...) or simply ``{state_name: value}``. ``gains`` becomes a ``BarChart`` (one bar
    per state, in state order) and the whole dict a markdown report.
    """
    rr = _rr()
    g = gains.get("gains") if isinstance(gains.get("gains"), Mapping) else None
    if g is None:
        if not all(isinstance(v, int | float) for v in gains.values()):
            raise ConfigError("gains", "expected a gains-file dict or {state_name: value}")
        g, rest = dict(gains), {}
    else:
        rest = {k: v for k, v in gains.items() if k != "gains"}
    states = list(rest.get("state_names") or g.keys())
    values = np.array([float(g.get(sn, 0.0)) for sn in states], dtype=np.float64)
    n = entity_name(name)
    rec.log(f"/synthesis/{n}/gains", rr.BarChart(values, color=COLOR_CAV), static=True)
    lines = [f"# {name}", "", "| state | gain |", "|---|---|"]
    lines += [f"| {sn} | {_fmt(v)} |" for sn, v in zip(states, values, strict=True)]
    lines.append("")
    other = {k: v for k, v in rest.items() if k not in ("state_names", "K")}
    if other:
        lines.append(_mapping_markdown("report", other))
    record_text(rec, f"/synthesis/{n}/report", "\n".join(lines))
    _flush_started(rec)


# --------------------------------------------------------------------------------------------
# Rerun processes (viewer, rrd tools)
# --------------------------------------------------------------------------------------------


def rerun_binary() -> Path:
    """The Rerun viewer/CLI executable shipped in the ``rerun-sdk`` wheel (not the Python
    ``rerun`` wrapper script, so that stopping it stops the viewer itself)."""
    import rerun_cli

    base = Path(rerun_cli.__file__).parent
    for cand in (
        base / "rerun",
        base / "rerun.exe",
        base / "Rerun.app" / "Contents" / "MacOS" / "Rerun",
    ):
        if cand.exists():
            return cand
    raise ConfigError(
        "rerun", f"the Rerun viewer binary is missing from {base} (reinstall rerun-sdk)"
    )


def viewer_environment(base: Mapping[str, str] | None = None) -> dict[str, str]:
    """Environment for Rerun processes we start: analytics off (``CI=1``, see module doc)."""
    env = dict(os.environ if base is None else base)
    env["CI"] = env.get("CI") or "1"
    return env


# --------------------------------------------------------------------------------------------
# Reading recordings back
# --------------------------------------------------------------------------------------------


@dataclass
class EntitySummary:
    """What one entity holds: archetype components, samples (rows) and time range."""

    path: str
    components: list[str] = field(default_factory=list)
    samples: int = 0
    static: bool = False
    t_min: float = math.inf
    t_max: float = -math.inf
    series: int = 0


@dataclass
class RecordingSummary:
    """What a recording holds (see :func:`summarize_recording`)."""

    path: str
    size_bytes: int
    application_id: str
    recording_ids: list[str]
    has_blueprint: bool
    entities: dict[str, EntitySummary]
    texts: dict[str, str]
    views: list[dict[str, str]] = field(default_factory=list)

    @property
    def time_range(self) -> tuple[float, float] | None:
        lo = min(
            (e.t_min for e in self.entities.values() if e.samples and not e.static),
            default=math.inf,
        )
        hi = max(
            (e.t_max for e in self.entities.values() if e.samples and not e.static),
            default=-math.inf,
        )
        return (lo, hi) if lo <= hi else None

    def to_json(self) -> dict[str, Any]:
        tr = self.time_range
        return {
            "path": self.path,
            "size_bytes": self.size_bytes,
            "application_id": self.application_id,
            "recording_ids": self.recording_ids,
            "has_blueprint": self.has_blueprint,
            "time_range": list(tr) if tr else None,
            "entities": {
                p: {
                    "components": e.components,
                    "samples": e.samples,
                    "static": e.static,
                    "series": e.series,
                    "time_range": [e.t_min, e.t_max] if e.samples and not e.static else None,
                }
                for p, e in sorted(self.entities.items())
            },
            "texts": dict(sorted(self.texts.items())),
            "views": self.views,
        }


_VIEW_FIELDS = ("class_identifier", "display_name", "space_origin")


def _open_reader(path: str | Path):
    p = Path(path)
    if not p.is_file():
        raise ConfigError("path", "no such recording file", str(p))
    from rerun.chunk import RrdReader

    try:
        reader = RrdReader(p)
        recordings = reader.recordings()
    except Exception as err:  # the bindings raise various errors on non-rrd input
        raise ConfigError("path", f"not a readable Rerun recording (.rrd): {err}", str(p)) from None
    if not recordings:
        raise ConfigError("path", "the file holds no Rerun recording", str(p))
    return reader, recordings


def summarize_recording(path: str | Path) -> RecordingSummary:
    """Read a recording back: entities, samples, time ranges, and every text document.

    Raises :class:`ConfigError` when the file is missing or is not a Rerun recording.
    """
    import pyarrow as pa

    reader, recordings = _open_reader(path)
    entities: dict[str, EntitySummary] = {}
    texts: dict[str, str] = {}
    try:
        chunks = list(reader.stream(store=recordings[0]))
        blueprints = reader.blueprints()
        bp_chunks = list(reader.stream(store=blueprints[0])) if blueprints else []
    except Exception as err:
        raise ConfigError("path", f"corrupt Rerun recording: {err}", str(path)) from None
    views = []
    for ch in bp_chunks:
        rb = ch.to_record_batch()
        if "ViewBlueprint:space_origin" in rb.schema.names:
            row = {
                k: rb.column(f"ViewBlueprint:{k}").to_pylist()[-1]
                for k in _VIEW_FIELDS
                if f"ViewBlueprint:{k}" in rb.schema.names
            }
            views.append({k: (v[-1] if isinstance(v, list) and v else v) for k, v in row.items()})
    views.sort(key=lambda v: (str(v.get("space_origin")), str(v.get("display_name"))))
    for ch in chunks:
        ep = ch.entity_path
        if ep.startswith("/__"):
            continue
        rb = ch.to_record_batch()
        ent = entities.setdefault(ep, EntitySummary(ep))
        for fld in rb.schema:
            meta = fld.metadata or {}
            if meta.get(b"rerun:kind") == b"data":
                comp = fld.name
                if comp not in ent.components:
                    ent.components.append(comp)
        if ch.is_static:
            ent.static = ent.static or not ent.samples
            if "TextDocument:text" in rb.schema.names:
                col = rb.column("TextDocument:text").to_pylist()
                if col and col[-1]:
                    texts[ep] = col[-1][-1]
            continue
        ent.static = False
        ent.samples += ch.num_rows
        if "time" in rb.schema.names and ch.num_rows:
            tcol = rb.column("time").cast(pa.int64()).to_numpy()
            ent.t_min = min(ent.t_min, float(tcol.min()) / 1e9)
            ent.t_max = max(ent.t_max, float(tcol.max()) / 1e9)
        for comp in ("Scalars:scalars", "Points2D:positions"):
            if comp in rb.schema.names and ch.num_rows:
                first = rb.column(comp)[0].values
                ent.series = max(ent.series, len(first) if first is not None else 0)
    # Static-only entities (texts, styles) count as static.
    for ent in entities.values():
        if ent.samples == 0:
            ent.static = True
    p = Path(path)
    return RecordingSummary(
        path=str(p),
        size_bytes=p.stat().st_size,
        application_id=recordings[0].application_id,
        recording_ids=[r.recording_id for r in recordings],
        has_blueprint=bool(blueprints),
        entities=entities,
        texts=texts,
        views=views,
    )
