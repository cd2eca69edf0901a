"""Recording analysis and synthesis results: |Gamma| curves, region maps, gains, Pareto
fronts."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.recording.core import (
    _REGION_COLORS,
    _REGION_LABELS,
    COLOR_CAV,
    COLOR_HDV,
    SCREEN_UP,
    _flush_started,
    _fmt,
    _jsonable,
    _mapping_markdown,
    _rr,
    _state,
    entity_name,
    open_recording,
    record_provenance,
    record_text,
    written_path,
)
from lcc_synth.recording.layout import analysis_blueprint, synthesis_blueprint


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
    xy = np.column_stack([np.log10(omega), SCREEN_UP * mag]).astype(np.float32)  # up is more
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
            [[[lo, SCREEN_UP], [hi, SCREEN_UP]]], colors=[(120, 120, 120)], labels=["|Γ| = 1"],
            radii=0.005,
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


#: Fields of a platoon report left out of its markdown report (the gains are recorded per CAV).
_PLATOON_BULK = ("state_names", "K", "gains", "input_K", "input_kh", "conserved", "pareto")


def record_synthesis(rec: Any, rep: Any, system: Any = None, name: str | None = None) -> None:
    """Record a synthesis report of any layout
    (:class:`~lcc_synth.synthesis.report.SynthesisReport`) under ``/synthesis/<name>/``
    (``name``: the report's problem unless given, e.g. ``<layout>.<controller>`` in a run).

    One CAV: ``gains`` (``BarChart``) and ``report`` (the gains file plus solver, polish,
    baseline, timings and notes), the Pareto front of a sparsity sweep (``pareto``:
    LineStrips2D of the front and Points2D of every pattern found, x = vehicles heard, y = true
    H2); and, when ``system`` (the problem's :class:`~lcc_synth.problem.System`) is given and
    the model has a head vehicle, ``/analysis/gamma/<name>``: |Gamma(j omega)| of the gain.

    A gain row per CAV (platoon / ring): per CAV input ``u_<col>``, ``<u_col>/gains``
    (``BarChart`` of its row of ``K`` on every state, in state order) and ``<u_col>/report``
    (its gains, heard positions and input gains); ``report``: the whole report but the arrays
    (design, check, stages, notes, ...), with the range front as a table for ``design =
    "sparsity"``, whose ``pareto/loss_percent`` (``BarChart``, one bar per point of the greedy
    front in order) is each point's H2 loss against the unstructured optimum, in percent.
    """
    name = rep.problem if name is None else name
    if rep.per_cav:
        _record_cav_rows(rec, rep, name)
    else:
        _record_one_cav(rec, rep, name)
    if _records_gamma(rep, system):
        from lcc_synth.analysis.transfer import gamma_state_space

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


def synthesis_cavs(reports: Mapping[str, Any]) -> dict[str, list[str]]:
    """``{name: CAV inputs}`` of the reports ``{name: SynthesisReport}`` with a gain row per CAV:
    the ``cavs`` of :func:`~lcc_synth.recording.layout.synthesis_blueprint`."""
    return {name: list(rep.gains) for name, rep in reports.items() if rep.per_cav}


def _records_gamma(rep: Any, system: Any) -> bool:
    """Does :func:`record_synthesis` record |Gamma| (one CAV with a head vehicle, ``system``
    given)?"""
    return system is not None and not rep.per_cav and rep.kind != "fd_lcc"


def _record_one_cav(rec: Any, rep: Any, name: str) -> None:
    """One CAV's gain, report and Pareto front (:func:`record_synthesis`)."""
    from lcc_synth.synthesis.gains_file import gains_document

    rr = _rr()
    doc = dict(gains_document(rep))
    for key in ("solver", "polish", "baseline", "timings", "notes"):
        value = getattr(rep, key, None)
        if value:
            doc[key] = _jsonable(value)
    record_gains(rec, name, doc)
    if rep.pareto:
        n = entity_name(name)
        pts = np.array([[p["count"], SCREEN_UP * p["h2"]] for p in rep.pareto], dtype=np.float32)
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
            xy = np.array([[p["count"], SCREEN_UP * p["h2"]] for p in front], dtype=np.float32)
            rec.log(
                f"/synthesis/{n}/pareto/front",
                rr.LineStrips2D([xy], colors=[COLOR_CAV], labels=["Pareto front"], radii=0.02),
                static=True,
            )


def _record_cav_rows(rec: Any, rep: Any, name: str) -> None:
    """Each CAV's gain row, the whole report and the range front (:func:`record_synthesis`)."""
    rr = _rr()
    n = entity_name(name)
    for i, (cav, row) in enumerate(rep.gains.items()):
        doc = {"state_names": list(rep.state_names), "gains": dict(row),
               "heard positions": list(rep.patterns.get(cav, [])),
               "input_kh": rep.input_kh[i]}  # fmt: skip
        record_gains(rec, cav, doc, under=name)
    summary = {k: v for k, v in _jsonable(rep.as_dict()).items() if k not in _PLATOON_BULK}
    text = f"# {name}\n\n" + _mapping_markdown("report", summary)
    if rep.pareto:
        loss = np.array([100.0 * p["loss"] for p in rep.pareto], dtype=np.float64)
        rec.log(f"/synthesis/{n}/pareto/loss_percent", rr.BarChart(loss, color=COLOR_HDV),
                static=True)  # fmt: skip
        rows = [f"| {k} | {', '.join(f'{c} {r}' for c, r in p['ranges'].items())} | "
                f"{p['heard']} | {_fmt(p['h2'])} | {_fmt(100.0 * p['loss'])} | "
                f"{'yes' if p.get('chosen') else ''} |" for k, p in enumerate(rep.pareto)]
        text += ("\n\n## range front (greedy, in order; the bars: loss %)\n\n"
                 "| step | ranges | vehicles heard | true H2 | loss % | chosen |\n"
                 "|---|---|---|---|---|---|\n" + "\n".join(rows))  # fmt: skip
    record_text(rec, f"/synthesis/{n}/report", text)


def record_synthesis_file(
    path: str | Path, rep: Any, system: Any = None, overwrite: bool = False,
    provenance: Mapping[str, Any] | None = None,
) -> Path:  # fmt: skip
    """Write a synthesis recording of any layout to ``path`` (see :func:`record_synthesis`;
    ``provenance`` at ``/provenance``); returns the file written
    (:func:`~.core.open_recording`)."""
    path = Path(path)
    blueprint = synthesis_blueprint(
        [rep.problem], gamma=_records_gamma(rep, system), pareto=bool(rep.pareto),
        cavs=synthesis_cavs({rep.problem: rep}),
    )  # fmt: skip
    with open_recording(path, rep.problem, blueprint, overwrite=overwrite) as rec:
        if provenance is not None:
            record_provenance(rec, provenance)
        record_synthesis(rec, rep, system)
    return written_path(rec) or path


def record_analysis_file(
    path: str | Path,
    name: str,
    *,
    gamma: Mapping[str, tuple[np.ndarray, np.ndarray, Mapping[str, Any]]] | None = None,
    regions: Mapping[str, Any] | None = None,
    region_reports: Mapping[str, Mapping[str, Any]] | None = None,
    summary: Mapping[str, Any] | None = None,
    overwrite: bool = False,
    provenance: Mapping[str, Any] | None = None,
) -> Path:
    """Write an analysis recording (``lcc-synth analyze`` / ``regions``) to ``path``; returns
    the file written (:func:`~.core.open_recording`: ``overwrite`` an existing one, else the
    next free name).

    Parameters
    ----------
    gamma : mapping, optional
        ``{case: (omega, |Gamma(j omega)|, report)}`` (see :func:`record_gamma`).
    regions : mapping, optional
        ``{name: RegionMap}`` of :mod:`lcc_synth.analysis.regions` (``mu``, ``k``, ``labels[a, b]``
        at ``(mu[a], k[b])``; labels 0 unstable, 1 stable, 2 string stable).
    region_reports : mapping, optional
        Extra report fields per region map (fractions, fixed gains, expansion...).
    summary : mapping, optional
        The command's whole report (e.g. its ``--json`` object): ``/analysis/report``.
    """
    gamma = dict(gamma or {})
    regions = dict(regions or {})
    path = Path(path)
    blueprint = analysis_blueprint(list(gamma), list(regions), report=summary is not None)
    with open_recording(path, name, blueprint, overwrite=overwrite) as rec:
        if provenance is not None:
            record_provenance(rec, provenance)
        for case, (omega, mag, report) in gamma.items():
            record_gamma(rec, case, omega, mag, report)
        for rname, rm in regions.items():
            extra = dict((region_reports or {}).get(rname, {}))
            record_region_map(rec, rname, np.asarray(rm.labels).T, rm.mu, rm.k, extra)
        if summary is not None:
            record_text(
                rec, "/analysis/report", f"# {name}\n\n" + _mapping_markdown("report", summary)
            )
    return written_path(rec) or path


def record_gains(rec: Any, name: str, gains: Mapping[str, Any], under: str | None = None) -> None:
    """Record a synthesised gain under ``/synthesis/<name>/`` (``/synthesis/<under>/<name>/``
    when ``under`` is given: one CAV's gain of a platoon design).

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
    n = entity_name(name) if under is None else f"{entity_name(under)}/{entity_name(name)}"
    rec.log(f"/synthesis/{n}/gains", rr.BarChart(values, color=COLOR_CAV), static=True)
    lines = [f"# {name}", "", "| state | gain |", "|---|---|"]
    lines += [f"| {sn} | {_fmt(v)} |" for sn, v in zip(states, values, strict=True)]
    lines.append("")
    other = {k: v for k, v in rest.items() if k not in ("state_names", "K")}
    if other:
        lines.append(_mapping_markdown("report", other))
    record_text(rec, f"/synthesis/{n}/report", "\n".join(lines))
    _flush_started(rec)
