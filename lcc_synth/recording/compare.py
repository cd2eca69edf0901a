"""Two recordings side by side (``lcc-synth review A.rrd B.rrd``): the same controller before
and after a change, in one viewer window.

The Rerun viewer opens several recordings as separate entries of its recording list, one shown
at a time; it has no view that shows two of them next to each other. :func:`side_by_side`
therefore writes one recording that holds both:

* every chunk of A's recording under ``/<label A>/...`` and of B's under ``/<label B>/...``
  (``rerun.chunk``: ``Chunk.with_entity_path``, the data copied as they are, not re-simulated);
* a blueprint with one row per quantity of every run the two have in common (the same
  ``/<scenario>/<controller>``): A's plot on the left, B's on the right, each on the whole
  run (the union of the two time ranges; each plot's own x axis, as
  :func:`lcc_synth.recording.layout.simulation_blueprint`'s),
  then the scenarios' metrics tables side by side; the time panel paused on the simulated
  time (:func:`lcc_synth.recording.layout.time_panel`);
* the merge is ``rerun rrd merge`` of the data and the blueprint (``.rbl``).

Measured here: two Table II recordings (0.7 MB each) merge in 0.6-0.9 s.
"""

from __future__ import annotations

import subprocess
import uuid
from pathlib import Path

from lcc_synth.errors import ConfigError, FileError
from lcc_synth.recording.core import entity_name

__all__ = ["comparison_labels", "common_runs", "side_by_side"]

#: Quantities compared per run, each a row of the layout (entity under ``/<scenario>/<run>``).
COMPARED = (("velocity", "v (m/s)"), ("spacing", "s (m)"), ("acceleration", "a (m/s²)"),
            ("cav/u_cmd", "u_cmd (m/s²)"))  # fmt: skip


def comparison_labels(a: Path, b: Path) -> tuple[str, str]:
    """Entity-safe labels of the two files: their stems, or ``A_<stem>`` / ``B_<stem>`` when
    the stems are equal (the same name in two directories)."""
    la, lb = entity_name(Path(a).stem), entity_name(Path(b).stem)
    return (f"A_{la}", f"B_{lb}") if la == lb else (la, lb)


def common_runs(paths_a: set[str], paths_b: set[str]) -> list[tuple[str, str]]:
    """``(scenario, run)`` pairs recorded in both (an entity ``/<scenario>/<run>/velocity``)."""

    def runs(paths: set[str]) -> set[tuple[str, str]]:
        out = set()
        for p in paths:
            parts = p.strip("/").split("/")
            if len(parts) == 3 and parts[2] == "velocity":
                out.add((parts[0], parts[1]))
        return out

    return sorted(runs(paths_a) & runs(paths_b))


def _blueprint(labels: tuple[str, str], runs: list[tuple[str, str]], scenarios: list[str],
               span: tuple[float, float] | None):  # fmt: skip
    import rerun.blueprint as rrb

    from lcc_synth.recording.layout import _time_views, time_panel

    la, lb = labels
    link = _time_views(rrb, {"time": span} if span else {})  # the whole run
    tabs = []
    for s, c in runs:
        rows = [
            rrb.Horizontal(*[
                rrb.TimeSeriesView(origin=f"/{lab}/{s}/{c}/{q}", name=f"{lab}: {c} {title}",
                                   plot_legend=rrb.PlotLegend(visible=False), **link)
                for lab in (la, lb)
            ])  # fmt: skip
            for q, title in COMPARED
        ]
        tabs.append(rrb.Vertical(*rows, name=f"{s}/{c}"))
    for s in scenarios:
        tabs.append(rrb.Horizontal(
            *[rrb.TextDocumentView(origin=f"/{lab}/{s}/metrics", name=f"{lab}: {s} metrics")
              for lab in (la, lb)], name=f"{s}: metrics"))  # fmt: skip
    return rrb.Blueprint(rrb.Tabs(*tabs), time_panel(rrb), collapse_panels=True)


def side_by_side(a: str | Path, b: str | Path, out: str | Path, rerun: str | Path) -> Path:
    """Write ``out``: recordings ``a`` and ``b`` in one file, side by side (module docstring).

    ``rerun`` is the viewer binary (:func:`lcc_synth.recording.rerun_binary`), whose
    ``rrd merge`` joins the data and the blueprint.

    Raises
    ------
    ConfigError
        A file is not a readable recording, or the two have no simulation run in common
        (nothing to put side by side: open them one at a time).
    FileError
        ``out`` cannot be written.
    """
    import rerun.chunk as rc

    from lcc_synth.recording import summarize_recording

    a, b, out = Path(a), Path(b), Path(out)
    sa, sb = summarize_recording(a), summarize_recording(b)  # validates both files
    runs = common_runs(set(sa.entities), set(sb.entities))
    if not runs:
        raise ConfigError("PATH.rrd", f"{a} and {b} have no simulation run in common (the same "
                          "/<scenario>/<controller>): open them one at a time")  # fmt: skip
    labels = comparison_labels(a, b)
    scenarios = sorted({s for s, _ in runs})
    data, blueprint = out.with_suffix(".data.rrd"), out.with_suffix(".rbl")
    app = "lcc_synth"
    try:
        streams = [rc.RrdReader(p).stream().map(
            lambda ch, lab=lab: ch.with_entity_path(f"/{lab}{ch.entity_path}"))
            for p, lab in zip((a, b), labels, strict=True)]  # fmt: skip
        rc.LazyChunkStream.merge(*streams).write_rrd(
            data, application_id=app, recording_id=str(uuid.uuid4()))
        spans = [x.time_range for x in (sa, sb) if x.time_range]
        span = (min(t[0] for t in spans), max(t[1] for t in spans)) if spans else None
        _blueprint(labels, runs, scenarios, span).save(app, str(blueprint))
        with open(out, "wb") as fh:
            proc = subprocess.run([str(rerun), "rrd", "merge", str(data), str(blueprint)],
                                  stdout=fh, stderr=subprocess.PIPE, text=True)  # fmt: skip
        if proc.returncode != 0:
            last = (proc.stderr.strip().splitlines() or ["?"])[-1]
            raise ConfigError("PATH.rrd", f"rerun rrd merge failed: {last}")
    except OSError as err:
        raise FileError(out, err.strerror or str(err)) from None
    finally:
        for p in (data, blueprint):
            p.unlink(missing_ok=True)
    return out
