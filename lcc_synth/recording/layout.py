"""Default layouts (Rerun blueprints) saved in the recordings."""

from __future__ import annotations

from collections.abc import Sequence

from lcc_synth.errors import ConfigError
from lcc_synth.recording.core import ROAD_Y_SCALE, _rrb, entity_name


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
