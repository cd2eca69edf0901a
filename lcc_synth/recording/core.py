"""Core of the recordings: constants, entity and vehicle names, colours, opening a
recording, and the low-level writers and markdown helpers the ``record_*`` modules share."""

from __future__ import annotations

import json
import math
import os
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
from lcc_synth.interrupts import interruption_behind

APP_ID = "lcc_synth"
#: Road view: metres of screen height per m/s of velocity error (the 2D view keeps aspect 1:1).
ROAD_Y_SCALE = 10.0
COLOR_CAV = (31, 119, 180)
COLOR_HDV = (150, 150, 150)
COLOR_HEAD = (230, 180, 0)
#: Rerun's 2-D views draw y downward and ignore view coordinates (rerun-io/rerun#1387, open in
#: 0.41), so a plotted value would rise as it falls. Every 2-D view of a recording logs
#: ``y * SCREEN_UP``: up means more (faster, larger |Gamma|, higher H2 cost) as in a paper's
#: figure; a hovered point's y reads with the opposite sign.
SCREEN_UP = -1.0
#: The alarm colour, and nothing else is drawn in it: emergency braking (AEB) flags, an MPC's
#: "fallback used" (a controller's curve in the AEB red would read as an alarm).
COLOR_ALARM = (214, 39, 40)
#: Colors of controllers in overlay views (u_cmd of all controllers in one plot), and of the
#: series of one view (an MPC's step / OSQP / solve times): never the alarm red, the CAV blue,
#: the head yellow or the HDV grey, whose meanings are fixed.
_PALETTE = [
    (44, 160, 44), (148, 103, 189), (255, 127, 14), (23, 190, 207),
    (140, 86, 75), (227, 119, 194), (188, 189, 34), (0, 0, 0),
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


def entity_name(name: str) -> str:
    """``name`` reduced to one safe entity-path part (``[A-Za-z0-9_.-]``, others -> ``_``): the
    same rule as a file name's part (:func:`lcc_synth.outputs.path_part`)."""
    from lcc_synth.outputs import path_part

    return path_part(name, "name")


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


def vehicle_widths(m: int, n: int) -> list[float]:
    """Line widths of the per-vehicle series: the CAV and the head drawn thicker than HDVs."""
    widths = [1.0] * (m + n + 2)
    widths[0], widths[m + 1] = 2.5, 3.0
    return widths


#: Seconds of one flush slice while a recording is finalised (a signal is handled between two).
_FLUSH_SLICE = 0.25
#: Seconds a recording's temporary file may stop growing, on a full file system, before the
#: flush is declared failed (Rerun's file writer waits forever on a full disk).
_STALL_S = 3.0


@contextmanager
def open_recording(
    path: str | Path, name: str, blueprint: Any = None, scenario: str | None = None,
    overwrite: bool = False,
) -> Iterator[Any]:  # fmt: skip
    """Open a Rerun recording that writes to ``path``; yields the ``rerun.RecordingStream``.

    The recording streams to a private temporary file next to ``path``
    (:func:`lcc_synth.outputs.temporary_path`), which is flushed, finalised and published
    under ``path`` when the block ends, however it ends (:func:`lcc_synth.outputs.publish`:
    exclusively, ``NAME-2.rrd``... if the name was taken meanwhile, or over it with
    ``overwrite``); :func:`written_path` gives the name used. A reader never sees a half file.

    ``/<scenario>/status`` records how the run ended: **complete**; **interrupted** by a signal
    or Ctrl-C; **failed** with the error that ended it; or what :func:`set_status` set
    (**partial**: some controllers failed, **failed**: none produced a result). Everything
    recorded before an interruption or error stays in a valid file, and the exception
    propagates.

    The file is finalised in flush slices of 0.25 s, so a signal is handled during a long
    flush; a file writer that stops (a full disk: Rerun's writer would wait forever) is a
    :class:`~lcc_synth.errors.FileError` naming ``path``, and the temporary file is removed.

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
    overwrite : bool
        Replace an existing file at ``path`` (``--overwrite``) instead of taking the next free
        name.
    """
    from lcc_synth.errors import FileError
    from lcc_synth.outputs import publish, temporary_path

    rr = _rr()
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError("--rrd", f"cannot create directory {str(path.parent)!r}: {err}") from None
    if not os.access(path.parent, os.W_OK):
        raise ConfigError("--rrd", f"directory {str(path.parent)!r} is not writable")
    status = f"/{entity_name(scenario or name)}/status"
    tmp = temporary_path(path)
    rec = rr.RecordingStream(APP_ID, recording_id=uuid.uuid4())
    state = _state(rec)
    state.target = path
    try:  # the blueprint is sent afterwards, not through save(): save() writes a default
        # blueprint synchronously and waits forever when the disk is full at that moment
        rec.save(tmp)
    except Exception as err:  # noqa: BLE001 - Rerun raises its own error types
        raise FileError(path, str(err)) from None
    if blueprint is not None:
        rec.send_blueprint(blueprint, make_active=True, make_default=True)
    rec.send_recording_name(name)
    started = datetime.now(UTC).isoformat(timespec="seconds")
    record_text(rec, status, f"# Status\n\nstarted {started}: **running**\n")
    outcome: BaseException | None = None
    try:
        yield rec
    except BaseException as err:  # recorded, then raised again once the file is finalised
        outcome = err
        if not isinstance(err, GeneratorExit):  # GeneratorExit: the block was abandoned
            what = type(err).__name__ + (f": {err}" if str(err) else "")
            stop = isinstance(err, KeyboardInterrupt) or interruption_behind(err) is not None
            how = f"**interrupted** by `{what}`" if stop else f"**failed**: `{what}`"
            record_text(
                rec,
                status,
                f"# Status\n\nstarted {started}: {how}; the recording holds everything "
                f"recorded before the {'interruption' if stop else 'error'}.\n",
            )
    else:
        done = datetime.now(UTC).isoformat(timespec="seconds")
        word, detail = state.status
        more = f"\n\n{detail}\n" if detail else "\n"
        record_text(rec, status, f"# Status\n\nstarted {started}, **{word}** {done}{more}")
    try:
        _finalise(rec, tmp, path)
        state.written = publish(tmp, path, overwrite)
    except BaseException as err:
        _abandon(rec, tmp)
        if outcome is None:
            raise
        import sys

        print(f"lcc-synth: the recording was not written: {err}", file=sys.stderr)
    if outcome is not None:
        raise outcome


def _finalise(rec: Any, tmp: Path, path: Path) -> None:
    """Flush ``rec`` to ``tmp`` in slices and finalise the file (footer), never hanging: a
    writer thread that died, or a file that stopped growing on a full file system, is a
    :class:`~lcc_synth.errors.FileError` naming ``path``."""
    import time

    from lcc_synth.errors import FileError
    from lcc_synth.outputs import free_bytes

    state = _state(rec)
    size, since = -1, time.monotonic()
    while True:
        if state.failure:
            raise FileError(path, _reason(state.failure, tmp))
        try:
            rec.flush(timeout_sec=_FLUSH_SLICE)
            break
        except RuntimeError as err:
            if "timed out" not in str(err).lower():
                raise FileError(path, _reason(str(err), tmp)) from None
        now_size = tmp.stat().st_size if tmp.exists() else 0
        if now_size != size:
            size, since = now_size, time.monotonic()
        elif time.monotonic() - since > _STALL_S and free_bytes(tmp) < (1 << 20):
            raise FileError(path, "No space left on device")
    rec.disconnect()  # writes the footer: the file is complete


def _abandon(rec: Any, tmp: Path) -> None:
    """Drop a recording that cannot be written: detach its file sink (so that Rerun's own
    flush at interpreter exit does not wait forever on a dead writer) and remove the
    temporary file."""
    import threading

    import rerun as rr

    t = threading.Thread(target=rec.disconnect, daemon=True, name="lcc-rrd-drop")
    t.start()
    t.join(2.0)
    if t.is_alive():  # the writer is stuck: Rerun's at-exit flush would be too
        rr.unregister_shutdown()
    try:
        tmp.unlink()
    except OSError:
        pass


def _reason(message: str, tmp: Path) -> str:
    """A file writer's error as the reason of a one-line error (a full disk said plainly)."""
    from lcc_synth.outputs import free_bytes

    try:
        if free_bytes(tmp) < (1 << 20):
            return "No space left on device"
    except OSError:
        pass
    return f"the recording's file writer stopped ({message})"


def written_path(rec: Any) -> Path | None:
    """The file a recording of :func:`open_recording` was published as (after its block;
    ``None`` before, or for a recording that could not be written)."""
    return _state(rec).written


def set_status(rec: Any, status: str, detail: str = "") -> None:
    """The status :func:`open_recording` records when its block ends normally: ``"complete"``
    (the default), ``"partial"`` (some controllers failed: ``detail`` says which) or
    ``"failed"`` (no result)."""
    if status not in ("complete", "partial", "failed"):
        raise ValueError(f"status must be complete, partial or failed, got {status!r}")
    _state(rec).status = (status, detail)


def record_provenance(rec: Any, doc: Mapping[str, Any]) -> None:
    """Record the run's provenance (:func:`lcc_synth.provenance.provenance`: package version,
    problem file and its SHA-256, backend, seeds, solvers) as the document ``/provenance``."""
    record_text(rec, "/provenance", "# Provenance\n\n" + _mapping_markdown("run", doc))


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


def _send_series(
    rec: Any, entity: str, t: Any, values: np.ndarray, names, colors, widths=None,
    points: bool = False, flag: bool = False,
) -> None:  # fmt: skip
    """One entity with ``values.shape[1]`` scalar series (one ``send_columns`` call); ``t`` is
    the times (s) or a ready ``TimeColumn``; ``widths`` the line widths (default 1.5), or with
    ``points`` the marker sizes (default 2: a scatter plot, for values that are not a signal).

    ``flag``: a piecewise-constant series (a 0/1 flag, a status code) recorded at its
    breakpoints: drawn as steps. No line is averaged by the viewer (aggregation ``Off``): the
    rows are already those that draw the line at about a pixel (the ``minmax`` recording,
    :mod:`~lcc_synth.recording.decimate`), and Rerun's default aggregation (``Average`` of the
    points within a pixel) turns a plateau kept as its two ends into a slope: a chattering AEB
    flag rose from 0 at t = 0 to 0.6 at 27 s, and the head's acceleration of the MPC head brake
    (0 up to 20 s, then -5 m/s²) was drawn as a ramp from 0 at t = 0 to -2.5 at 20 s (its rows
    (20.00 s, 0) and (20.01 s, -5) averaged in one pixel; web viewer, 218 px wide plot)."""
    import pyarrow as pa

    rr = _rr()
    values = np.ascontiguousarray(values, dtype=np.float64)
    rows, k = values.shape
    colors = np.asarray(colors, dtype=np.uint8)
    if points:
        style = rr.SeriesPoints(
            names=list(names), colors=colors, markers=["circle"] * k,
            marker_sizes=[2.0] * k if widths is None else [float(w) for w in widths],
        )  # fmt: skip
    else:
        step = {"interpolation_mode": "StepAfter"} if flag else {}
        style = rr.SeriesLines(
            aggregation_policy="Off",
            names=list(names), colors=colors,
            widths=[1.5] * k if widths is None else [float(w) for w in widths], **step,
        )  # fmt: skip
    rec.log(entity, style, static=True)
    flat = pa.array(values.reshape(-1), type=pa.float64())  # NaN stays NaN (a gap)
    column = _rows(rr, rr.Scalars.descriptor_scalars(), flat, rows, k)
    tcol = _time_column(t) if isinstance(t, np.ndarray) else t
    rec.send_columns(entity, indexes=[tcol], columns=[column])


def _flush_started(rec: Any) -> None:
    """Start writing what was logged without waiting (the context manager's exit waits); a
    file writer that has stopped (a full disk) is remembered and reported when the recording
    is finalised, not raised in the middle of the work."""
    try:
        rec.flush(timeout_sec=0.0)
    except RuntimeError as err:
        if "timed out" not in str(err).lower():
            _state(rec).failure = str(err)


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
    #: the file asked for, the file published (:func:`written_path`), how the run ended
    #: (:func:`set_status`) and a file-writer failure seen while recording
    target: Path | None = None
    written: Path | None = None
    status: tuple[str, str] = ("complete", "")
    failure: str = ""

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


#: Rows of a comparison table that carry nothing when every run has them at this value.
_NOTHING_AT = {"batch": 1, "aave_std": 0, "fuel_ml_std": 0, "collided": False,
               "scenarios_with_collision": 0, "failed_steps": 0}  # fmt: skip


def _comparison_markdown(scenario: str, rows: Mapping[str, Mapping[str, Any]]) -> str:
    """A scenario's metrics, one column per controller, as a table of a paper: each metric
    labelled with its unit and rounded as the ``run`` table rounds it
    (:data:`lcc_synth.metrics.METRIC_DISPLAY`), without the rows that carry nothing (a batch
    of 1 and its zero standard deviations, no collision, no solver failure). Safety before
    efficiency: when the runs have safety metrics, a first row ``safety`` says which runs
    collided or were unsafe (:func:`lcc_synth.metrics.unsafe_reasons`) and why, and their
    columns come after the safe ones."""
    from lcc_synth.metrics import METRIC_DISPLAY, format_metric, unsafe_reasons

    def numbers(row: Mapping[str, Any]) -> dict[str, Any]:
        return {k: v for k, v in row.items()
                if isinstance(v, int | float | np.number) and not isinstance(v, bool)}

    nums = {c: numbers(row) for c, row in rows.items()}
    verdicts = {c: (bool(n.get("collisions")), unsafe_reasons(n)) for c, n in nums.items()}
    judged = any(k in n for n in nums.values()
                 for k in ("min_spacing", "min_ttc", "aeb_activations"))  # fmt: skip
    ctrls = (sorted(rows, key=lambda c: (verdicts[c][0], bool(verdicts[c][1]))) if judged
             else list(rows))  # fmt: skip
    keys: list[str] = []
    for row in rows.values():
        keys += [k for k, v in row.items() if _is_scalar(v) and k not in keys]
    keys = [k for k in keys if not (k in _NOTHING_AT and all(
        rows[c].get(k, _NOTHING_AT[k]) == _NOTHING_AT[k] for c in ctrls))]  # fmt: skip
    lines = [f"# {scenario}: metrics", ""]
    lines += ["| metric | " + " | ".join(ctrls) + " |", "|---|" + "---|" * len(ctrls)]
    if judged:
        cells = []
        for c in ctrls:
            hit, why = verdicts[c]
            cells.append("collided" if hit else ("unsafe: " + ", ".join(why)) if why else "safe")
        lines.append("| safety | " + " | ".join(cells) + " |")

    def cell(k: str, v: Any) -> str:
        if k in METRIC_DISPLAY and isinstance(v, int | float | np.number):
            return _cell(format_metric(v, METRIC_DISPLAY[k][1]))
        return _cell(_fmt(v))

    for k in keys:
        label = _cell(METRIC_DISPLAY[k][0]) if k in METRIC_DISPLAY else k
        lines.append(f"| {label} | " + " | ".join(cell(k, rows[c].get(k, "")) for c in ctrls)
                     + " |")  # fmt: skip
    return "\n".join(lines) + "\n"
