"""Default layouts (Rerun blueprints) saved in the recordings.

Legends
-------
The viewer's plot legend (Rerun 0.41) has one entry per distinct series name, sorted by name,
and is not scrolled: entries beyond the view's height are cut. The per-vehicle plots hide theirs
(12 series; the one-line key above them says the colours); the overlaid CAV command view lists
one ``u_cmd`` per controller and one shared entry for every AEB flag
(:data:`~lcc_synth.recording.simulation.AEB_SERIES`), and gets the height for them
(:data:`RIGHT_SHARES`).

Time-axis labels of narrow plots
--------------------------------
A time-series plot 290 px wide (four controllers side by side on a 1920 px screen) labels only
``+0s`` for a 60 s run (``+0s`` and ``+1m`` for 100 s). The blueprint cannot change that: the
viewer places the grid of a duration timeline itself (Rerun 0.41, ``re_view_time_series``,
its nanosecond grid spacer): at most one "medium" grid line per 150 px of plot width, with
spacings stepping 1 s, 10 s, 60 s, 10 min, and a line gets a label only when its neighbours are
far enough apart on screen (10 s lines were labelled 123 px apart and not 48 px apart). A plot
of a run of ``D`` seconds gets a label every 10 s from about ``15 D`` px wide (900 px for 60 s,
1,500 px for 100 s). The blueprint API has no setting that reaches the grid: ``TimeAxis`` holds
``link``, ``view_range`` and ``zoom_lock``; ``TimeSeriesView`` adds ``axis_y``,
``plot_legend``, ``background``, ``interaction`` and ``time_ranges``; a narrower ``view_range``
would hide part of the run. So the plots keep the whole run; the time panel below them (same
``time`` timeline, the whole width) carries the seconds, hovering a curve shows its time, and a
view maximised (its expand button) gets 10 s labels.

Road views
----------
A 2-D view scales x and y alike and letterboxes its visual bounds (Rerun 0.41,
``VisualBounds2D``: everything inside is visible). The road of ``mpc_head_brake`` spans
x -227 .. 36 m and y -51 .. 114 (10 per m/s of velocity error, :func:`road_bounds`), about
1.6 : 1. Four road views stacked in the right column (2 of its 5.5 shares) were 45 px tall
each at 1920x1080: 0.17 px per m, the dots (1.5 m) under a pixel, the string a faint line
(web viewer, ``benchmarks/screenshot_review.py``). The road is now one tab per controller (the
tab strip names them; the key says the axes), the whole 2 shares: 765 x 290 px, 1.76 px per m,
and its dots are sized in UI points (:data:`~lcc_synth.recording.simulation.ROAD_DOT_PT`: 4 px
for an HDV, 7 px for the CAV, whatever the zoom). The command view keeps its 1.5 of 5.5 (its
legend) and the reports their 2. ``run`` sent its layout before any result, without road
bounds (the viewer fitted the data it had; vehicles left the frame during an event). It now
sends it once, when its runs are done however they end (``lcc_synth.cli.run``; its recording
is a file, not watched live), each scenario's road bounds merged over the runs recorded: a
minimum and a maximum per run, no second pass over the data. Sending it at the start and
again at the end cost 2.06 MB more on the showcase's 7.17 MB (a layout is 740 small chunks).

The time cursor
---------------
The blueprint sets the time panel's state, timeline, play state and time selection
(:func:`time_panel`: expanded, ``time``, paused, from the first event to the end), but not
where the cursor stands: Rerun 0.41's ``TimePanel`` / ``TimePanelBlueprint`` hold ``state``,
``timeline``, ``playback_speed``, ``fps``, ``play_state``, ``loop_mode`` and
``time_selection`` only, and Rerun's guide says so ("The time panel blueprint has no field for
the position of the time cursor"). Its other way, a viewer URL ending in ``#when=time@...``,
belongs to recordings on a Rerun server (dataset segment URLs): the web viewer serving a
``.rrd`` (``lcc-synth review --web``, a ``rerun+http://.../proxy`` URL) left its cursor at the
start of the run with ``#when=time@20s`` inside its ``url`` parameter (the MPC head brake) and
on the page address (Table II) alike, in headless Chromium driven as
``benchmarks/screenshot_review.py`` drives it (2026-12-02), and never wrote a fragment to its
address. So a recording opens with the cursor at the start, the
event marked by the selection; every plot shows the whole run, and the road views show the
moment under the cursor (click the time panel at the selection's start to go there).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.recording.core import ROAD_Y_SCALE, _rrb, entity_name

#: Quantities of the time-series rows of :func:`simulation_blueprint` (and ``"u_cmd"``).
PLOT_QUANTITIES = ("velocity", "spacing", "acceleration")
#: Heights of the right column of :func:`simulation_blueprint`: road views, the overlaid CAV
#: command view, the reports. The command view's legend is not scrolled by the viewer (Rerun
#: 0.41): entries beyond its height are cut. At 1920x1080 a share of 1 in 5 showed 4 legend
#: rows; 1.5 in 5.5 holds the 5 of four controllers (one ``u_cmd`` each and the shared AEB
#: entry, :data:`~lcc_synth.recording.simulation.AEB_SERIES`).
RIGHT_SHARES = (2.0, 1.5, 2.0)



def _span(lo: float, hi: float, pad: float = 0.08, min_span: float = 1.0) -> tuple[float, float]:
    """``[lo, hi]`` padded by ``pad`` of its span, at least ``min_span`` wide (a flat signal
    would otherwise open on an axis like 14.9999998 .. 15)."""
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return (0.0, 1.0)
    mid, half = 0.5 * (lo + hi), 0.5 * max(hi - lo, 0.0)
    half = max(half * (1.0 + pad), 0.5 * min_span)
    return (float(mid - half), float(mid + half))


def plot_ranges(result: Any) -> dict[str, Any]:
    """Axis ranges for :func:`simulation_blueprint` from a ``SimResult`` (several CAVs: the
    commands of all; a ring: column 0's spacing too): ``{"time": (t0, t1),
    "velocity" | "spacing" | "acceleration" | "u_cmd": (lo, hi)}`` over the whole batch, padded.

    Non-finite samples (after a collision) are ignored; spacings are clipped below at -5 m."""
    t = np.asarray(result.t, dtype=np.float64)
    out: dict[str, Any] = {}
    if t.size:
        out["time"] = (float(t[0]), float(t[-1]))

    def finite(x):
        x = np.asarray(x, dtype=np.float64)
        return x[np.isfinite(x)]

    data = {
        "velocity": finite(result.velocity),
        "spacing": finite(np.asarray(result.spacing)[..., 0 if getattr(result, "ring", False)
                                                     else 1:]),
        "acceleration": finite(result.acceleration),
        "u_cmd": np.concatenate([finite(result.u_cmd), [0.0, 1.0]]),  # + the AEB flag 0/1
    }
    for key, x in data.items():
        if x.size:
            lo, hi = float(x.min()), float(x.max())
            if key == "spacing":
                lo = max(lo, -5.0)
            out[key] = _span(lo, hi)
    out.update(road_bounds(result))
    return out


def road_bounds(result: Any) -> dict[str, Any]:
    """``road_x``, ``road_y``: the bounds of every vehicle's point in the road view over the
    whole run (:func:`lcc_synth.recording.simulation.record_simulation`: x m from the CAV, y
    the scaled velocity error, up = faster; a ring: the circle with its radial offsets), so
    that the view opens with every vehicle inside it at every time, not shrunk to dots."""
    from lcc_synth.recording.core import SCREEN_UP

    pos = np.asarray(getattr(result, "position", np.empty(0)), dtype=np.float64)
    vel = np.asarray(result.velocity, dtype=np.float64)
    if pos.shape != vel.shape or pos.ndim != 3 or not pos.size:
        return {}
    v_star = np.asarray(result.v_star, dtype=np.float64).reshape(-1, 1, 1)
    if getattr(result, "ring", False):
        from lcc_synth.recording.simulation import RING_V_SCALE

        radius = float(result.circumference) / (2.0 * np.pi)
        dv = vel - v_star
        r = radius * (1.0 + RING_V_SCALE * dv[np.isfinite(dv)])
        big = float(np.abs(r).max()) if r.size else radius
        return {"road_x": _span(-big, big), "road_y": _span(-big, big)}
    cav = int(result.cav)  # the road view's origin (as record_simulation draws it)
    x = pos - pos[:, :, cav : cav + 1]
    y = SCREEN_UP * ROAD_Y_SCALE * (vel - v_star)
    x, y = x[np.isfinite(x)], y[np.isfinite(y)]
    if not x.size or not y.size:
        return {}
    return {"road_x": _span(float(x.min()) - 5.0, float(x.max()) + 5.0),
            "road_y": _span(float(y.min()), float(y.max()), min_span=20.0)}  # fmt: skip


def merge_ranges(*ranges: Mapping[str, Any]) -> dict[str, Any]:
    """The union of several :func:`plot_ranges`."""
    out: dict[str, Any] = {}
    for r in ranges:
        for key, (lo, hi) in r.items():
            a, b = out.get(key, (lo, hi))
            out[key] = (min(a, lo), max(b, hi))
    return out


def _time_views(rrb, ranges: Mapping[str, Any]) -> dict[str, Any]:
    """Keyword arguments of every time-series view: the whole run on the x axis.

    With the run's ``"time"`` span the x axis is that span and **independent**: Rerun 0.41
    ignores a view's own range when its axis is linked (``LinkToGlobal`` reads one shared,
    hidden range instead, which no blueprint API sets), and that shared range falls back to the
    data when it spans at most 60 s and to the time cursor +- 30 s beyond: Table II's 100 s run
    opened on -30 .. +30 s, its brake and the whole recovery off screen. Zooming one plot
    therefore no longer zooms the others (the hover cursor is still shared; a double click
    returns a plot to the whole run). Without a span (nothing known yet) the axes stay linked
    on the viewer's default. The whole timeline is queried by default (Rerun's
    ``VisibleTimeRanges``: "for time series views, the default is to show the entire
    timeline"), so no visible time range is saved (3.3 kB per view in the file)."""
    t = ranges.get("time")
    if t is None:
        infinite = rrb.TimeRangeBoundary.infinite()
        return {"axis_x": rrb.TimeAxis(view_range=rrb.TimeRange(start=infinite, end=infinite),
                                       link=rrb.components.LinkAxis.LinkToGlobal)}  # fmt: skip
    start = rrb.TimeRangeBoundary.absolute(seconds=float(t[0]))
    end = rrb.TimeRangeBoundary.absolute(seconds=float(t[1]))
    return {
        "axis_x": rrb.TimeAxis(
            view_range=rrb.TimeRange(start=start, end=end),
            link=rrb.components.LinkAxis.Independent,
        ),
    }


def time_panel(rrb, ranges: Mapping[str, Any] | None = None):
    """The time panel every recording opens with: expanded, on the simulated ``time``
    timeline (not the viewer's ``log_time``, which it would show while loading), paused (the
    web viewer otherwise plays from wherever it is), and, when ``ranges`` has the run's
    ``"time"`` span, its time selection from the first event (``"event"``: a perturbation's
    start, :func:`lcc_synth.recording.context.first_event`) to the end of the run."""
    selection = None
    t = (ranges or {}).get("time")
    if t is not None:
        event = (ranges or {}).get("event")
        lo = float(event) if event is not None and t[0] <= float(event) <= t[1] else float(t[0])
        selection = _time_range(lo, float(t[1]))
    return rrb.TimePanel(state="expanded", timeline="time", play_state="paused",
                         time_selection=selection)  # fmt: skip


def _time_range(lo: float, hi: float):
    """A Rerun absolute time range ``[lo, hi]`` seconds of a duration timeline."""
    import rerun.encodings as enc

    return enc.AbsoluteTimeRange(min=enc.TimeInt(seconds=lo), max=enc.TimeInt(seconds=hi))


def _y_axis(rrb, ranges: Mapping[str, Any], key: str):
    r = ranges.get(key)
    return rrb.ScalarAxis(range=r, zoom_lock=False) if r is not None else None


def simulation_blueprint(
    scenario: str,
    controllers: Sequence[str],
    mpc: Sequence[str] = (),
    ranges: Mapping[str, Any] | None = None,
    recorded: bool = False,
):
    """Default layout of a simulation recording.

    Left: one row per quantity (velocity, spacing, acceleration), one time-series view per
    controller side by side. Right: the road views (one tab per controller, the first open;
    visual bounds ``ranges["road_x"]``, ``ranges["road_y"]``: :func:`road_bounds`), the CAV
    command of all controllers overlaid, the comparison metrics and each controller's
    description; for the MPC controllers named in ``mpc``, tabs with their solve times / status
    and their predicted velocities.

    Every time-series view opens on the whole run. ``ranges`` (:func:`plot_ranges`) fixes the
    opening time span (each view's own x axis: ``_time_views``) and y ranges; without it
    the x axes are linked on the viewer's default (the data up to 60 s long, else the cursor
    +- 30 s) and y fits the data. The per-vehicle plots hide their legends (12 series
    would cover the curves; hovering names a curve); a one-line key above them
    (``/<scenario>/key``, :data:`~lcc_synth.recording.simulation.KEY_TEXT`) says the colours
    and the axes. The time panel opens paused, its selection from the first event
    (:func:`time_panel`; the cursor cannot be placed in Rerun 0.41: see the module's notes).
    ``recorded``: the scenario replays a recording (``/<scenario>/recorded``,
    :func:`~lcc_synth.recording.simulation.record_recorded`): the velocity and spacing rows
    end with a view of the recorded trajectories, next to the simulated ones.
    """
    rrb = _rrb()
    s = entity_name(scenario)
    ctrls = [entity_name(c) for c in controllers]
    if not ctrls:
        raise ConfigError("controllers", "a simulation recording needs at least one controller")
    ranges = dict(ranges or {})
    tkw = _time_views(rrb, ranges)

    def row(quantity: str, title: str):
        short = {"velocity": "v (m/s)", "spacing": "s (m)", "acceleration": "a (m/s²)"}
        shown = [*ctrls, *(["recorded"] if recorded and quantity != "acceleration" else [])]
        return rrb.Horizontal(
            *[
                rrb.TimeSeriesView(
                    origin=f"/{s}/{c}/{quantity}",
                    name=f"{c}: {short[quantity]}",  # fits a quarter of the screen
                    axis_y=_y_axis(rrb, ranges, quantity),
                    plot_legend=rrb.PlotLegend(visible=False),
                    **tkw,
                )
                for c in shown
            ],
            name=title,
        )

    plots = rrb.Vertical(
        rrb.TextDocumentView(origin=f"/{s}/key", name="key"),
        row("velocity", "velocity (m/s)"),
        row("spacing", "spacing (m)"),
        row("acceleration", "acceleration (m/s²)"),
        row_shares=[1, 3, 3, 3],
        name="time series",
    )
    bounds = (rrb.VisualBounds2D(x_range=ranges["road_x"], y_range=ranges["road_y"])
                   if "road_x" in ranges and "road_y" in ranges else None)  # fmt: skip
    # one tab per controller, the whole road column's height each (stacked, four views were
    # 45 px tall: see the module's notes); bounds from the data, so every vehicle stays inside
    road = rrb.Tabs(
        *[
            rrb.Spatial2DView(origin=f"/{s}/{c}/road", name=f"{c}: road",
                              visual_bounds=bounds)
            for c in ctrls
        ],
        name="road (x m from the CAV; up: faster)",
        active_tab=0,
    )  # fmt: skip
    u_cmd = rrb.TimeSeriesView(
        origin=f"/{s}",
        contents=[f"+ /{s}/{c}/cav/**" for c in ctrls],
        name="CAV command u_cmd (m/s²) and AEB",
        axis_y=_y_axis(rrb, ranges, "u_cmd"),
        plot_legend=rrb.PlotLegend(rrb.Corner2D.RightBottom),
        **tkw,
    )
    tabs = [
        rrb.TextDocumentView(origin=f"/{s}/metrics", name="metrics"),
        rrb.TextDocumentView(origin=f"/{s}/context", name="context"),
        *[
            rrb.TextDocumentView(origin=f"/{s}/{c}/controller", name=f"{c}: controller")
            for c in ctrls
        ],
        rrb.TextDocumentView(origin=f"/{s}/status", name="status"),
        rrb.TextLogView(
            origin=f"/{s}", contents=[f"+ /{s}/{c}/events" for c in ctrls], name="events"
        ),
    ]
    first = []  # an MPC run opens on its predictions and solver: its first screen
    for c in (entity_name(x) for x in mpc):
        look = [
            rrb.TimeSeriesView(
                origin=f"/{s}/{c}/mpc/lookahead/{q}",
                name=f"{c}: CAV {label}, predicted vs measured",
                plot_legend=rrb.PlotLegend(rrb.Corner2D.LeftBottom),
                **tkw,
            )
            for q, label in (("velocity", "v (m/s)"), ("spacing", "s (m)"), ("u", "u (m/s²)"))
        ]
        first += [
            rrb.Vertical(*look, name=f"{c}: predictions"),
            rrb.TimeSeriesView(
                origin=f"/{s}/{c}/mpc",
                contents=[f"+ /{s}/{c}/mpc/solve_time_ms", f"+ /{s}/{c}/mpc/status"],
                name=f"{c}: MPC solve time (ms), status",
                plot_legend=rrb.PlotLegend(rrb.Corner2D.RightTop),
                **tkw,
            ),
            rrb.Spatial2DView(
                origin=f"/{s}/{c}/mpc/predicted/velocity",
                name=f"{c}: plans (x s ahead; up: faster)",
            ),
        ]
    tabs = [*first, *tabs]
    # the first tab shown, saved rather than left to the viewer: an MPC run's predictions,
    # else the comparison metrics
    texts = rrb.Tabs(*tabs, name="reports", active_tab=0)
    right = rrb.Vertical(road, u_cmd, texts, row_shares=list(RIGHT_SHARES))
    return rrb.Blueprint(
        rrb.Horizontal(plots, right, column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        time_panel(rrb, ranges),
    )


def seeds_blueprint(
    scenario: str,
    controllers: Sequence[str],
    seeds: Sequence[int],
    mpc: Sequence[str] = (),
    ranges: Mapping[str, Any] | None = None,
):
    """Default layout of a recording of several seeds: one tab per seed, each the
    :func:`simulation_blueprint` of the controllers recorded as ``<controller>_seed<k>``."""
    rrb = _rrb()
    tabs = [
        rrb.Vertical(
            simulation_blueprint(
                scenario,
                [seed_entity(c, k) for c in controllers],
                [seed_entity(c, k) for c in mpc],
                ranges,
            ).root_container,
            name=f"seed {k}",
        )
        for k in seeds
    ]
    return rrb.Blueprint(
        rrb.Tabs(*tabs),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        time_panel(rrb, ranges),
    )


def seed_entity(controller: str, seed: int) -> str:
    """Entity name of scenario ``seed`` of ``controller`` in a several-seed recording."""
    return f"{entity_name(controller)}_seed{int(seed)}"


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


def synthesis_blueprint(
    names: Sequence[str], gamma: bool = True, pareto: bool = False,
    cavs: Mapping[str, Sequence[str]] | None = None,
):  # fmt: skip
    """Default layout of a synthesis recording, for every layout.

    Per name in ``names``: the gains bar chart (a name in ``cavs``, a platoon or ring design:
    one per CAV input ``cavs[name]``, ``/synthesis/<name>/<u_col>/gains``), the Pareto front of
    a sparsity design (``pareto``; a platoon's range front: its H2 loss per greedy step) and the
    report (then each CAV's); ``gamma``: the |Gamma| curves under ``/analysis/gamma``.
    """
    rrb = _rrb()
    plots, reports = [], []
    cavs = dict(cavs or {})
    for name in names:
        n, rows = entity_name(name), cavs.get(name, ())
        plots += [
            rrb.BarChartView(origin=f"/synthesis/{n}/{entity_name(c)}/gains", name=f"{c}: gains")
            for c in rows
        ] or [rrb.BarChartView(origin=f"/synthesis/{n}/gains", name=f"{name}: gains")]
        reports += [
            rrb.TextDocumentView(origin=f"/synthesis/{n}/{e}report", name=f"{label}: report")
            for e, label in [("", name)] + [(f"{entity_name(c)}/", c) for c in rows]
        ]
    plots = plots or [rrb.BarChartView(origin="/synthesis")]
    if gamma:
        plots.append(rrb.Spatial2DView(origin="/analysis/gamma", name="|Γ(jω)| vs log10 ω"))
    if pareto:
        plots += [
            rrb.BarChartView(origin=f"/synthesis/{entity_name(name)}/pareto/loss_percent",
                             name="range front: H2 loss % per greedy step") if name in cavs
            else rrb.Spatial2DView(origin=f"/synthesis/{entity_name(name)}/pareto",
                                   name=f"{name}: Pareto front (vehicles heard vs true H2)")
            for name in names
        ]  # fmt: skip
    reports = reports or [rrb.TextDocumentView(origin="/synthesis")]
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(*plots), rrb.Tabs(*reports), column_shares=[3, 2])
    )


def sweep_blueprint(name: str, metrics: Sequence[tuple[str, str]]):
    """Default layout of a sweep recording (:mod:`lcc_synth.recording.sweep`): a grid of one
    scatter plot per ``(metric, label)`` (x = scenario index, one colour per controller, legend
    in the corner) and the summary report."""
    rrb = _rrb()
    s = entity_name(name)
    plots = [
        rrb.TimeSeriesView(origin=f"/sweep/{s}/{entity_name(m)}", name=f"{label} vs scenario",
                           plot_legend=rrb.PlotLegend(rrb.Corner2D.RightTop))
        for m, label in metrics
    ]  # fmt: skip
    report = rrb.TextDocumentView(origin=f"/sweep/{s}/report", name=f"{name}: report")
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Grid(*plots, grid_columns=3), report, column_shares=[5, 2]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )
