"""Recording a Monte Carlo sweep (``lcc-synth sweep``): every scenario's metrics, per
controller, to find and re-run the bad cases.

Under ``/sweep/<name>/``:

- ``<metric>`` for every per-scenario metric of the sweep (AAVE, fuel, min spacing, min TTC,
  max |u|, the CAV's jerks, the wave metrics, seconds over ISO 15622's jerk limit, collisions,
  emergency-braking steps): ``Scalars`` with one point series per controller, on the
  ``scenario`` timeline (a sequence: x = the scenario index ``i``). Hovering an outlier names its
  controller and index; scenario ``i`` draws everything from ``(seed, i)`` only, so it is the
  same scenario in every run of the file with that seed, whatever the count, batch size or
  worker. A run with a collision has no AAVE or fuel (NaN: a gap in the series, as in
  ``samples.csv``).
- ``report``: the summary, one row per metric and one column per controller (mean [p5, p95],
  then the counts; the simulation recordings' comparison table), and the sweep's settings and
  timings.

Size, measured: 1000 scenarios x 6 controllers x 13 metrics is 0.98 MB, written in 13 ms (one
``send_columns`` call per metric); 60 scenarios 0.25 MB, mostly the layout and the per-entity
overhead.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.recording.core import (
    _PALETTE,
    _cell,
    _comparison_markdown,
    _flush_started,
    _fmt,
    _jsonable,
    _mapping_markdown,
    _rr,
    _send_series,
    entity_name,
    open_recording,
    record_provenance,
    record_text,
    set_status,
    written_path,
)
from lcc_synth.recording.layout import sweep_blueprint

__all__ = ["record_sweep", "record_sweep_file"]


def record_sweep(
    rec: Any,
    name: str,
    samples: Mapping[str, Mapping[str, np.ndarray]],
    labels: Mapping[str, str],
    summary: Mapping[str, Mapping[str, Any]] | None = None,
    info: Mapping[str, Any] | None = None,
) -> None:
    """Record a sweep's per-scenario samples and its summary (module docstring).

    Parameters
    ----------
    rec : rerun.RecordingStream
        From :func:`~lcc_synth.recording.core.open_recording`.
    name : str
        The sweep's name (entity ``/sweep/<name>``).
    samples : mapping
        ``{controller: {metric: (count,) array}}``, as
        :attr:`lcc_synth.experiments.sweep.SweepResult.samples`.
    labels : mapping
        ``{metric: label with unit}``: the metrics to record, in order.
    summary : mapping, optional
        ``{controller: {metric: {"mean", "p5", "p95", ...}, "collisions", ...}}``
        (:attr:`~lcc_synth.experiments.sweep.SweepResult.summary`): a table with one row per
        metric and one column per controller, ``mean [p5, p95]``, then the counts.
    info : mapping, optional
        Settings and timings of the run (``SweepResult.info``).

    Raises
    ------
    ConfigError
        ``samples`` is empty, a controller lacks a metric of ``labels``, or the controllers'
        scenario counts differ.
    """
    rr = _rr()
    ctrls = list(samples)
    count = _scenario_count(samples, labels)
    s = entity_name(name)
    index = rr.TimeColumn("scenario", sequence=np.arange(count, dtype=np.int64))
    colors = np.array([_PALETTE[k % len(_PALETTE)] for k in range(len(ctrls))], np.uint8)
    for metric in labels:
        entity = f"/sweep/{s}/{entity_name(metric)}"
        values = np.column_stack([np.asarray(samples[c][metric], dtype=np.float64)
                                  for c in ctrls])  # fmt: skip
        _send_series(rec, entity, index, values, ctrls, colors, points=True)
    title = f"sweep {name}: {count} scenarios x {len(ctrls)} controllers"
    if summary:
        text = _comparison_markdown(f"{title}, mean [p5, p95]", _summary_rows(summary, labels))
    else:
        text = f"# {title}\n"
    if info:
        text += "\n" + _mapping_markdown("run", _jsonable(dict(info)))
    record_text(rec, f"/sweep/{s}/report", text)
    _flush_started(rec)


def record_sweep_file(
    path: str | Path,
    name: str,
    samples: Mapping[str, Mapping[str, np.ndarray]],
    labels: Mapping[str, str],
    summary: Mapping[str, Mapping[str, Any]] | None = None,
    info: Mapping[str, Any] | None = None,
    overwrite: bool = False,
    provenance: Mapping[str, Any] | None = None,
    failed: str = "",
) -> Path:
    """Write a sweep recording to ``path`` (see :func:`record_sweep`) with its default layout
    (:func:`~lcc_synth.recording.layout.sweep_blueprint`) and ``provenance`` at
    ``/provenance``; returns the file written (:func:`~.core.open_recording`: ``overwrite`` an
    existing one, else the next free name). ``failed`` (the controllers whose solver failed)
    makes its status **partial**."""
    path = Path(path)
    _scenario_count(samples, labels)  # bad samples: an error before the file is created
    blueprint = sweep_blueprint(name, list(labels.items()))
    with open_recording(path, name, blueprint, overwrite=overwrite) as rec:
        if provenance is not None:
            record_provenance(rec, provenance)
        record_sweep(rec, name, samples, labels, summary, info)
        if failed:
            set_status(rec, "partial", failed)
    return written_path(rec) or path



def _scenario_count(samples: Mapping[str, Mapping[str, np.ndarray]], labels: Mapping[str, str]):
    """The number of scenarios, after checking every controller has every metric of ``labels``
    with one value per scenario."""
    if not samples:
        raise ConfigError("samples", "a sweep recording needs at least one controller")
    shapes = set()
    for c, per in samples.items():
        missing = [m for m in labels if m not in per]
        if missing:
            raise ConfigError("samples", f"controller {c!r} has no samples of {missing}")
        shapes |= {np.asarray(per[m]).shape for m in labels}
    if len(shapes) != 1 or len(next(iter(shapes))) != 1:
        raise ConfigError("samples", f"every metric needs one value per scenario, got {shapes}")
    return next(iter(shapes))[0]


#: Counts of the summary table: (label, total key, scenarios key or None).
_COUNTS = (("collisions (scenarios)", "collisions", "collision_scenarios"),
           ("AEB steps (scenarios)", "aeb_activations", "aeb_scenarios"),
           ("unsafe scenarios", "unsafe_scenarios", None),
           ("scenarios over ISO jerk", "jerk_scenarios", None),
           ("MPC fallbacks", "fallbacks", None))  # fmt: skip


def _summary_rows(summary: Mapping[str, Mapping[str, Any]], labels: Mapping[str, str]):
    """``{controller: {label: cell}}`` for the comparison table: a first row ``safety``
    (``safe``, ``unsafe in k/N`` or ``collided in k/N`` scenarios), ``mean [p5, p95]`` of every
    metric with a distribution, then the counts; safety before efficiency: the controllers in
    the order of :func:`~lcc_synth.metrics.sweep_safety_rank` (as the ``sweep`` table)."""
    from lcc_synth.metrics import sweep_safety_rank

    rows: dict[str, dict[str, str]] = {}
    for c, e in sorted(summary.items(), key=lambda item: sweep_safety_rank(item[1])):
        n = e.get("scenarios", "?")
        hit, unsafe = int(e.get("collision_scenarios") or 0), int(e.get("unsafe_scenarios") or 0)
        row = rows[c] = {"safety": f"collided in {hit}/{n}" if hit else
                         f"unsafe in {unsafe}/{n}" if unsafe else "safe"}  # fmt: skip
        for metric, label in labels.items():
            d = e.get(metric)
            if isinstance(d, Mapping) and "mean" in d:
                row[_cell(label)] = ("n/a" if d["mean"] is None else
                                     f"{_fmt(d['mean'])} [{_fmt(d['p5'])}, {_fmt(d['p95'])}]")
        for label, total, scen in _COUNTS:
            if total in e:
                row[label] = str(e[total]) + (f" ({e[scen]})" if scen else "")
    return rows
