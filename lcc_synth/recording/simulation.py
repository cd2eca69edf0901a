"""Recording simulation results: trajectories, road view, events, metrics, MPC history.

Several CAVs (a mixed platoon or a ring): vehicles are named by position (``p1`` .. ``pN``,
a CAV ``cavI``), each CAV has its own colour (:data:`CAV_COLORS`, the first the single-CAV
blue), and ``cav/u_cmd`` and ``cav/aeb_active`` hold one series per CAV. The ring's road view
is a circle: a vehicle at position ``p`` (not wrapped by the simulator) is drawn at the angle
``2 pi p / C`` on the circle of circumference ``C`` (radius ``R = C / 2 pi``), its radius
raised by ``RING_V_SCALE * R`` per m/s of velocity error (:func:`ring_view`); the open road
view is as for one CAV, positions relative to the first CAV.

A scenario that replays a recording (a ``type = "trajectory"`` head,
:class:`~lcc_synth.simulation.perturbations.Recorded`) also gets the recorded trajectories,
once per scenario, under ``/<scenario>/recorded/`` (:func:`record_recorded`): the recorded
leader's speed, and with ``[scenario] initial = "data"`` (one file vehicle per simulated
vehicle) every recorded follower's speed and spacing (``headway - vehicle_length``), on the
simulated time (the file's first sample at the perturbation's ``start``), named and coloured
as the simulated vehicle in that column, every sample exactly as read.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.recording.core import (
    _PALETTE,
    COLOR_ALARM,
    COLOR_CAV,
    COLOR_HDV,
    COLOR_HEAD,
    ROAD_Y_SCALE,
    SCREEN_UP,
    _comparison_markdown,
    _flush_started,
    _fmt,
    _is_scalar,
    _mapping_markdown,
    _rows,
    _rr,
    _RunFacts,
    _sample_indices,
    _send_series,
    _state,
    _time_column,
    entity_name,
    record_text,
    vehicle_colors,
    vehicle_names,
    vehicle_widths,
)
from lcc_synth.recording.decimate import (
    MPC_PLAN_S,
    MPC_TIMING_BUCKET_S,
    ROAD_BUCKET_S,
    VIEWER_BUCKET_S,
    event_rows,
    frame_rows,
    linear_rows,
    plan_rows,
    strip_points,
    viewer_rows,
)

#: Colours of the CAVs of a platoon or ring, in order (the first is the single CAV's blue).
#: Never the alarm red (:data:`~lcc_synth.recording.core.COLOR_ALARM`), the head's yellow or the
#: HDVs' grey.
CAV_COLORS = ((31, 119, 180), (148, 103, 189), (44, 160, 44), (23, 190, 207), (255, 127, 14),
              (140, 86, 75))  # fmt: skip
#: The colour key and axes of a simulation's plots (``/<scenario>/key``, above the plots): the
#: per-vehicle plots hide their legends (a dozen series would cover the curves).
KEY_TEXT = ("**head** yellow · **CAV** blue, thick (more CAVs: purple, green, cyan) · **HDVs** "
            "grey · **AEB** red, nothing else · v velocity, s spacing, a acceleration · x axes: "
            "simulated time t (s) · road: x m from the CAV, up = faster")  # fmt: skip
#: Name of every AEB flag series (``cav/aeb_active``, all red): the viewer's plot legend has
#: one entry per distinct name, so the overlaid command view lists each controller's ``u_cmd``
#: and this one entry (toggling it shows or hides every controller's flags), not two entries
#: per controller, which overflowed the legend of a short view (4 of 8 shown for 4 controllers).
AEB_SERIES = "AEB active (every controller)"
#: Ring road view: radial offset per m/s of velocity error, as a fraction of the radius.
RING_V_SCALE = 0.02


#: Road view: radius (UI points, pixels at 100 % scaling, whatever the zoom) of an HDV's dot,
#: and how much it grows per unit of the vehicle's line width (:func:`vehicle_style`: 1 for an
#: HDV, 2.5 the head, 3 a CAV): HDVs 4, the head 6.25, a CAV 7 points. Radii in metres (1.5 m,
#: before) drew a dot of 0.5 px in a road view 45 px tall and 3 px in one 300 px tall.
ROAD_DOT_PT = 4.0
ROAD_DOT_PT_PER_WIDTH = 1.5
#: Road view: width (UI points) of the equilibrium line (zero velocity error).
ROAD_LINE_PT = 1.0


def road_radii(widths) -> np.ndarray:
    """Radii (UI points) of the road view's dots for vehicles of line widths ``widths``: the
    CAVs and the head larger than the HDVs. Logged through Rerun's ``Radius.ui_points``."""
    w = np.asarray(widths, dtype=np.float32)
    return ROAD_DOT_PT + ROAD_DOT_PT_PER_WIDTH * np.maximum(w - 1.0, 0.0)


#: Entity (under ``/<scenario>/``) of the trajectories a scenario replays.
RECORDED_ENTITY = "recorded"


@dataclass(frozen=True)
class RecordedTrajectories:
    """What a scenario replays, on the simulated time.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Simulated time (s) of every recorded sample.
    velocity : ndarray, shape (T, k)
        Recorded speeds (m/s) of array columns ``0 .. k - 1`` (the head, then with
        ``initial = "data"`` every follower).
    spacing : ndarray, shape (T, k - 1)
        Recorded spacings (m, ``headway - vehicle_length``) of columns ``1 .. k - 1``.
    file : str
        The trajectory file.
    """

    t: np.ndarray
    velocity: np.ndarray
    spacing: np.ndarray
    file: str


def recorded_trajectories(scenario: Any, base_dir: str | Path | None = None):
    """The :class:`RecordedTrajectories` of ``scenario``'s recorded head
    (:class:`~lcc_synth.simulation.perturbations.Recorded`), or ``None`` when it replays none.
    With an initial state from the data the file (``base_dir``: the problem file's directory)
    is read again for every follower's speed and headway."""
    from lcc_synth.schema.trajectories import read_trajectory
    from lcc_synth.simulation.perturbations import Recorded

    found = [p for p in getattr(scenario, "perturbations", ()) if isinstance(p, Recorded)]
    if not found:
        return None
    p = found[0]
    t = np.asarray(p.times, dtype=np.float64)
    head = np.asarray(p.speeds, dtype=np.float64)[:, None]
    if getattr(scenario, "initial_state", None) is None:
        return RecordedTrajectories(t, head, np.empty((len(t), 0)), p.file)
    path = Path(p.file)
    if base_dir is not None and not path.is_absolute():
        path = Path(base_dir) / path
    tr = read_trajectory(path, "scenario.perturbations.file")
    gaps = tr.headway[1:].T - float(scenario.vehicle_length)
    return RecordedTrajectories(t, tr.v.T.astype(np.float64), gaps, p.file)


def record_recorded(rec: Any, scenario: str, data: RecordedTrajectories, result: Any) -> str:
    """Record ``data`` (:func:`recorded_trajectories`) under ``/<scenario>/recorded/``
    (``velocity``, and ``spacing`` when there are followers), every sample; names and colours
    those of ``result``'s columns (:func:`vehicle_style`). Returns the entity prefix."""
    names, colors, widths = vehicle_style(result)
    base = f"/{entity_name(scenario)}/{RECORDED_ENTITY}"
    k = data.velocity.shape[1]
    label = [f"recorded {v}" for v in names[:k]]
    tcol = _time_column(data.t)
    _send_series(rec, f"{base}/velocity", tcol, data.velocity, label, colors[:k], widths[:k])
    if data.spacing.shape[1]:
        _send_series(rec, f"{base}/spacing", tcol, data.spacing, label[1:], colors[1:k],
                     widths[1:k])  # fmt: skip
    record_text(rec, f"{base}/source", f"# recorded\n\n`{data.file}`: {k} vehicle(s), "
                f"{len(data.t)} samples from t = {_fmt(float(data.t[0]))} s.\n")  # fmt: skip
    return base


def vehicle_style(result) -> tuple[list[str], np.ndarray, list[float]]:
    """``(names, colors, widths)`` of every column of ``result``: the single-CAV names of
    :func:`~lcc_synth.recording.core.vehicle_names`, or a platoon's / ring's by position
    (``head``, ``p1`` .. ``pN``, CAVs ``cavI``) with one colour per CAV (:data:`CAV_COLORS`)."""
    m, n = int(result.m), int(result.n)
    sc = getattr(result, "scenario", None)
    if sc is None or sc.layout is None:
        return vehicle_names(m, n), vehicle_colors(m, n), vehicle_widths(m, n)
    nv, ring, cavs = int(result.n_vehicles), bool(result.ring), tuple(result.cavs)
    off = 1 if ring else 0
    names = [
        "head" if j == 0 and not ring else f"cav{j + off}" if j in cavs else f"p{j + off}"
        for j in range(nv)
    ]
    colors = np.tile(np.array(COLOR_HDV, dtype=np.uint8), (nv, 1))
    widths = [1.0] * nv
    if not ring:
        colors[0] = COLOR_HEAD
        widths[0] = 2.5
    for k, c in enumerate(cavs):
        colors[c] = CAV_COLORS[k % len(CAV_COLORS)]
        widths[c] = 3.0
    return names, colors, widths


def ring_view(position: np.ndarray, velocity: np.ndarray, v_star: float, circumference: float):
    """``(..., 2)`` points of the ring's road view (see the module docstring): angle
    ``2 pi p / C`` (positions wrap here only), radius ``R (1 + RING_V_SCALE (v - v*))``."""
    R = circumference / (2.0 * np.pi)
    theta = 2.0 * np.pi * np.mod(position, circumference) / circumference
    r = R * (1.0 + RING_V_SCALE * (velocity - v_star))
    return np.stack([r * np.cos(theta), SCREEN_UP * r * np.sin(theta)], axis=-1)


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
    decimate: int | str = "minmax",
    run: int = 0,
    mpc_history: Any = None,
) -> str:
    """Record one controller's simulation (one batch member) and flush it.

    Parameters
    ----------
    rec : rerun.RecordingStream
        From :func:`open_recording`.
    result : lcc_synth.simulation.results.SimResult
        Arrays ``(batch, T, n_vehicles)`` etc.
    scenario : str
        Entity prefix (the problem name).
    controller : str, optional
        Entity name of the controller (default ``result.controller``); e.g. ``"fd_lcc_seed3"``
        to record several batch members of one controller.
    metrics : mapping, optional
        The run's metrics (e.g. the ``--json`` shape of ``lcc-synth simulate``): scalars go into
        the per-controller and comparison tables, per-vehicle lists into a vehicle table.
    decimate : int or "minmax"
        ``"minmax"`` (the default): each entity keeps its own rows
        (:mod:`lcc_synth.recording.decimate`: what the viewer draws within about a pixel,
        every visible peak and dip, the exact extremes, full rate around emergency braking,
        collisions and the CAV's jerk peaks); or every ``decimate``-th step (the last step is
        always recorded; ``1``: every value exactly as simulated).
    run : int
        Which batch member to record.
    mpc_history : optional
        An MPC controller's per-step history (see :func:`record_mpc_history`).

    Returns
    -------
    str
        The entity prefix ``/<scenario>/<controller>``.
    """
    minmax = decimate == "minmax"
    if not minmax and (
        isinstance(decimate, bool) or not isinstance(decimate, int | np.integer) or decimate < 1
    ):
        raise ConfigError("decimate", f"must be an integer >= 1 or 'minmax', got {decimate!r}")
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
    names, colors, widths = vehicle_style(result)
    label = [f"{c} {v}" for v in names]
    vel_all = velocity[run]
    acc_all = np.asarray(result.acceleration)[run]
    cavs = tuple(getattr(result, "cavs", None) or (cav,))
    ring = bool(getattr(result, "ring", False))
    aeb_cav = np.asarray(result.aeb_active)[run].astype(bool).reshape(T, -1)
    aeb_on = aeb_cav.any(axis=1)
    collided = np.asarray(result.collided)[run]
    ctime = np.asarray(result.collision_time)[run]
    stride = _sample_indices(T, 1 if minmax else int(decimate))
    dt_rec, forced = (float(t_all[1] - t_all[0]) if T > 1 else 1.0), None
    if minmax and T > 1:
        forced = event_rows(t_all, aeb_on, np.where(collided, ctime, np.nan), acc_all[:, cav])
    kept: list[int] = []

    def rows(values: np.ndarray, how: str = "signal"):
        """``(rows, TimeColumn)`` of one entity: its own rows (``how``: a ``"signal"``
        (:func:`viewer_rows`), a piecewise-constant ``"flag"`` (its breakpoints, exact) or the
        road's ``"frames"``), or the stride."""
        if not minmax:
            idx = stride
        elif how == "flag":
            idx = linear_rows(values, 0.0)
        elif how == "frames":
            idx = frame_rows(values, max(1, int(round(ROAD_BUCKET_S / dt_rec))))
        else:
            bucket = max(1, int(round(VIEWER_BUCKET_S / dt_rec)))
            idx = viewer_rows(values, bucket, forced=forced)
        kept.append(len(idx))
        return idx, _time_column(t_all[idx])

    idx, tcol = rows(vel_all)
    vel = vel_all[idx]
    _send_series(rec, f"{base}/velocity", tcol, vel, label, colors, widths)
    j0 = 0 if ring else 1  # the head has no spacing; the ring's column 0 has
    spacing = np.asarray(result.spacing)[run, :, j0:]
    idx, tcol = rows(spacing)
    _send_series(rec, f"{base}/spacing", tcol, spacing[idx], label[j0:], colors[j0:], widths[j0:])
    idx, tcol = rows(acc_all)
    _send_series(rec, f"{base}/acceleration", tcol, acc_all[idx], label, colors, widths)
    state = _state(rec)
    u_color = state.color(base)  # one color per controller: u_cmd of all controllers overlaid
    u_all = np.asarray(result.u_cmd)[run].reshape(T, -1)
    idx, tcol = rows(u_all)
    if len(cavs) == 1:
        u_names, u_colors = [f"{c} u_cmd"], [u_color]
    else:
        u_names = [f"{c} u_cmd {names[j]}" for j in cavs]
        u_colors = [tuple(int(x) for x in colors[j]) for j in cavs]
    aeb_names = [AEB_SERIES] * len(cavs)  # one legend entry for every controller's flags
    _send_series(rec, f"{base}/cav/u_cmd", tcol, u_all[idx], u_names, u_colors,
                 [2.0] * len(cavs))  # fmt: skip
    aeb = aeb_cav.astype(np.float64)
    idx, tcol = rows(aeb, "flag")
    red = [COLOR_ALARM] * len(cavs)
    _send_series(rec, f"{base}/cav/aeb_active", tcol, aeb[idx], aeb_names, red, flag=True)

    # Road view (Fig. 11): x = position relative to the CAV, y = scaled velocity error.
    pos = np.asarray(result.position)[run]
    v_star = float(np.asarray(result.v_star).reshape(-1)[run])
    xy_all = np.empty((T, nv, 2), dtype=np.float32)
    if ring:
        xy_all[:] = ring_view(pos, vel_all, v_star, float(result.circumference))
    else:
        xy_all[..., 0] = pos - pos[:, cav : cav + 1]
        xy_all[..., 1] = SCREEN_UP * ROAD_Y_SCALE * (vel_all - v_star)  # faster is up
    idx, tcol = rows(xy_all.reshape(T, -1), "frames")  # scrubbing / playback: 5 frames/s
    xy = xy_all[idx]
    rec.log(
        f"{base}/road",
        rr.Points2D.from_fields(colors=colors, labels=names, show_labels=False,
                                radii=rr.components.Radius.ui_points(road_radii(widths))),
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
    if ring:
        circle = ring_view(np.linspace(0.0, float(result.circumference), 181), v_star, v_star,
                           float(result.circumference))  # fmt: skip
        strip = [circle.tolist()]
    else:
        x_lo, x_hi = float(np.nanmin(xy[..., 0])), float(np.nanmax(xy[..., 0]))
        strip = [[[x_lo - 5.0, 0.0], [x_hi + 5.0, 0.0]]]
    rec.log(
        f"{base}/road/equilibrium",
        rr.LineStrips2D(strip, colors=[(90, 90, 90)],
                        radii=rr.components.Radius.ui_points(ROAD_LINE_PT)),
        static=True,
    )

    # Texts: controller description and metrics.
    info = dict(getattr(result, "controller_info", {}) or {})
    stats = dict(getattr(result, "controller_stats", {}) or {})
    s_star = float(np.asarray(result.s_star).reshape(-1)[run])
    how = (
        f"min/max-preserving, {min(kept)}-{max(kept)} rows per entity"
        if minmax
        else f"every {decimate}"
    )
    header = (
        f"# {c}\n\nscenario `{scenario}`, run {run} of {batch}; {_layout_text(result, names)}; "
        f"v* = {_fmt(v_star)} m/s, s* = {_fmt(s_star)} m; {T} steps recorded {how}.\n\n"
    )
    record_text(
        rec,
        f"{base}/controller",
        header
        + _mapping_markdown("description", info)
        + "\n"
        + _mapping_markdown("run statistics", stats),
    )
    record_text(rec, f"/{s}/key", KEY_TEXT)  # the legend of every plot of the scenario
    crash = [f"{names[i]} at t = {_fmt(float(ctime[i]))} s" for i in np.flatnonzero(collided)]
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
        record_mpc_history(rec, base, mpc_history, run=run, decimate=decimate)
    _flush_started(rec)
    return base


def _layout_text(result, names: list[str]) -> str:
    """``m = .. ahead, n = .. behind`` (one CAV) or the platoon's / ring's CAVs."""
    sc = getattr(result, "scenario", None)
    if sc is None or sc.layout is None:
        return f"m = {int(result.m)} ahead, n = {int(result.n)} behind"
    size, ring = sc.layout
    road = f"ring of {size} vehicles, C = {_fmt(float(result.circumference))} m" if ring else (
        f"platoon of {size} vehicles behind the head"
    )
    return f"{road}, CAVs {', '.join(names[j] for j in result.cavs)}"


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


#: ``lcc_synth.mpc`` per-step status codes (its ``STATUS_CODES``); 0 = QP solved.
_MPC_STATUS = {0: "qp", 1: "shifted_plan", 2: "static_gain", 3: "hold"}


def record_mpc_history(
    rec: Any,
    base: str,
    history: Mapping[str, Any],
    run: int = 0,
    plan_every: int | None = None,
    decimate: int | str = 1,
) -> None:
    """Record an MPC controller's per-step history under ``<base>/mpc/``.

    ``history`` is ``MPCController.history()`` of :mod:`lcc_synth.mpc`: ``t (S,)`` controller
    step times; per scenario ``(B, S, ...)``: ``step_time`` and ``osqp_time`` (s), ``status``
    (0 QP, 1 shifted plan, 2 static gain, 3 hold), ``plan (B, S, N)`` planned model inputs,
    ``predicted_velocity`` / ``predicted_spacing`` ``(B, S, N+1, V)`` and ``pred_time (N+1,)``
    offsets (s); arrays without the batch axis are accepted too.

    Entities: ``mpc/solve_time_ms`` (series: whole step, QP solver), ``mpc/status`` (status
    code and 1 when a fallback was used), and ``mpc/predicted/{u,velocity,spacing}``:
    ``LineStrips2D`` at each recorded controller step, x = seconds ahead of that step, y = the
    predicted value (one strip per vehicle), so scrubbing the timeline shows the plan of the moment.
    ``plan_every`` records every k-th plan (default: at most about 200 plans).

    ``decimate="minmax"`` (what the commands record by default): the solve times keep the
    min/max rows of every :data:`~lcc_synth.recording.decimate.MPC_TIMING_BUCKET_S` (their
    peaks, :func:`~lcc_synth.recording.decimate.viewer_rows`), the status its changes only
    (exact), and the plans one per :data:`~lcc_synth.recording.decimate.MPC_PLAN_S` s
    (``plan_every`` steps when given), a plan unchanged since the last recorded one skipped
    (:func:`~lcc_synth.recording.decimate.plan_rows`), each strip through the points that
    draw it within 0.2 % of the span (:func:`~lcc_synth.recording.decimate.strip_points`).
    An integer ``decimate`` records every controller step and the plans as above.
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

    minmax = decimate == "minmax"
    Ts = float(np.median(np.diff(t))) if S > 1 else 0.1

    def rows(values: np.ndarray, flag: bool = False):
        """``(rows, TimeColumn)`` of one per-step entity (every step unless ``minmax``)."""
        if not minmax:
            idx = np.arange(S)
        elif flag:
            idx = linear_rows(values, 0.0)
        else:
            bucket = max(1, int(round(MPC_TIMING_BUCKET_S / Ts)))
            idx = viewer_rows(values, bucket, noisy_bucket=bucket)
        return idx, _time_column(t[idx])

    times = [member(k, 0) for k in ("step_time", "osqp_time", "solve_time")]
    names = ("step", "QP solver", "solve")
    times = [(k, x) for k, x in zip(names, times, strict=True) if x is not None]
    if times:
        vals = np.column_stack([x.astype(np.float64) * 1e3 for _, x in times])
        idx, tcol = rows(vals)
        _send_series(
            rec, f"{base}/mpc/solve_time_ms", tcol, vals[idx],
            [f"{k} time (ms)" for k, _ in times], _PALETTE[: len(times)],
        )  # fmt: skip
    # the joint MPC of a platoon or ring (lcc_synth.mpc.joint): a status per CAV, plans
    # (B, S, N, n_cav), predicted error states (B, S, N+1, nx) on s_1, v_1, ..., s_N, v_N
    joint = "predicted_states" in history and "predicted_velocity" not in history
    status = member("status", 1 if joint else 0)
    if status is not None:
        code = status.astype(np.float64).reshape(status.shape[0], -1)
        vals = np.column_stack([code, (code > 0).any(axis=1).astype(np.float64)])
        legend = ", ".join(f"{k} {v}" for k, v in _MPC_STATUS.items())
        names = ([f"status of CAV {j + 1} ({legend})" for j in range(code.shape[1])]
                 if joint else [f"status ({legend})"]) + ["fallback used"]  # fmt: skip
        colors = [_PALETTE[j % len(_PALETTE)] for j in range(code.shape[1])] if joint else [
            (90, 90, 90)]
        idx, tcol = rows(vals, flag=True)
        _send_series(rec, f"{base}/mpc/status", tcol, vals[idx], names, [*colors, COLOR_ALARM],
                     flag=True)  # fmt: skip
    if not joint:
        _record_lookahead(rec, base, t, history, member, minmax)
    if joint:
        X = member("predicted_states", 2)
        history = {k: v for k, v in history.items() if k not in ("predicted_velocity",
                                                                  "predicted_spacing")}
        if X is not None:  # run's (S, N+1, nx): spacing and velocity errors per vehicle
            history["predicted_spacing"], history["predicted_velocity"] = X[..., 0::2], X[..., 1::2]
        if "pred_time" not in history and "dt" not in history and "plan" in history:
            Ts = float(np.median(np.diff(t))) if S > 1 else 0.1
            history["dt"] = Ts

    if plan_every is not None:
        every = max(1, int(plan_every))
    elif minmax:
        every = max(1, int(round(MPC_PLAN_S / Ts)))
    else:
        every = max(1, S // 200)
    offsets = history.get("pred_time")
    item = pa.list_(pa.field("item", pa.float32(), nullable=False), 2)
    strip_type = pa.list_(pa.field("item", item, nullable=False))  # what the viewer expects
    for key, label in (("plan", "u"), ("predicted_velocity", "velocity"),
                       ("predicted_spacing", "spacing")):  # fmt: skip
        pred = member(key, 2 if key == "plan" and joint else 1 if key == "plan" else 2)
        if pred is None:
            continue
        pred = np.asarray(pred, dtype=np.float64)
        if pred.ndim == 2:
            pred = pred[:, :, None]
        steps = plan_rows(pred, every) if minmax else np.arange(0, S, every)
        pred = pred[steps]
        K, H, V = pred.shape
        if offsets is not None:
            x = np.asarray(offsets, dtype=np.float64)[:H]
        elif "dt" in history:
            x = float(history["dt"]) * np.arange(H)
        else:
            raise ConfigError("mpc_history", f"{key} needs 'pred_time' or 'dt'")
        ys = np.transpose(pred, (0, 2, 1)).reshape(K * V, H)  # one strip per plan and vehicle
        keep = strip_points(x, ys) if minmax else np.ones((K * V, H), dtype=bool)
        xy = np.empty((int(keep.sum()), 2), dtype=np.float32)
        xy[:, 0] = np.broadcast_to(x, ys.shape)[keep]
        xy[:, 1] = SCREEN_UP * ys[keep]  # up is more
        pts = pa.FixedSizeListArray.from_arrays(pa.array(xy.reshape(-1)), type=item)
        strip_off = np.concatenate([[0], np.cumsum(keep.sum(axis=1))]).astype(np.int32)
        strips = pa.ListArray.from_arrays(pa.array(strip_off), pts, type=strip_type)
        rec.send_columns(
            f"{base}/mpc/predicted/{label}",
            indexes=[_time_column(t[steps])],
            columns=[_rows(rr, rr.LineStrips2D.descriptor_strips(), strips, K, V)],
        )
    _flush_started(rec)


#: Look-ahead times (s) of the MPC's predictions drawn against what happened
#: (``mpc/lookahead/*``).
LOOKAHEAD_S = (1.0, 3.0)


def _record_lookahead(rec: Any, base: str, t: np.ndarray, history: Mapping[str, Any],
                     member: Any, minmax: bool = True) -> None:  # fmt: skip
    """The one-CAV MPC's predictions of its CAV on axes, against what happened: at the time
    ``t_k + L`` the value step ``k`` predicted ``L`` s ahead (``L`` in :data:`LOOKAHEAD_S`),
    next to the value the MPC measured at its steps, for the CAV's velocity
    (``mpc/lookahead/velocity``), its own spacing (``.../spacing``) and the model input
    (``.../u``: the planned input against the one applied). A prediction that keeps missing
    what follows shows as a gap between the curves. The joint MPC of several CAVs records its
    plans as strips only (no ``v_0`` among its state names). With ``minmax`` each series
    keeps the rows that draw it within 0.2 % of its span
    (:func:`~lcc_synth.recording.decimate.linear_rows`: smooth, a few hundred rows)."""

    def thin(values: np.ndarray) -> np.ndarray:
        if not minmax or values.size < 3:
            return np.arange(values.shape[0])
        return linear_rows(np.where(np.isfinite(values), values, np.nan))
    names = history.get("state_names")
    offsets = history.get("pred_time")
    pv, ps = member("predicted_velocity", 2), member("predicted_spacing", 2)
    if names is None or offsets is None or pv is None:
        return
    vel_names = [str(n) for n in np.asarray(names).reshape(-1)[1::2]]
    if "v_0" not in vel_names:
        return
    cav = vel_names.index("v_0")
    offsets = np.asarray(offsets, dtype=np.float64).reshape(-1)
    dt = float(offsets[1] - offsets[0]) if offsets.size > 1 else 0.0
    steps = [(L, int(round(L / dt))) for L in LOOKAHEAD_S if dt > 0]
    plan, applied = member("plan", 1), member("u_model", 0)

    def floats(x: Any) -> np.ndarray | None:
        return None if x is None else np.asarray(x, dtype=np.float64)

    series = {"velocity": (pv[:, :, cav], None),
              "spacing": (None if ps is None else ps[:, :, cav], None),
              "u": (floats(plan), floats(applied))}  # fmt: skip
    for quantity, (pred, now) in series.items():
        if pred is None or not np.isfinite(pred).any():
            continue
        measured = pred[:, 0] if now is None else now
        entity = f"{base}/mpc/lookahead/{quantity}"
        label = "applied" if quantity == "u" else "measured"
        idx = thin(measured)
        _send_series(rec, f"{entity}/measured", t[idx], measured[idx, None], [label],
                     [COLOR_CAV], [2.0])  # fmt: skip
        for k, (L, j) in enumerate(steps):
            if j >= pred.shape[1]:
                continue
            reached = np.flatnonzero(t + offsets[j] <= t[-1])  # times the run reached
            idx = reached[thin(pred[reached, j])] if reached.size else reached
            _send_series(rec, f"{entity}/ahead_{L:g}s", (t + offsets[j])[idx],
                         pred[idx, j, None], [f"predicted {L:g} s before"],
                         [_PALETTE[k % len(_PALETTE)]])  # fmt: skip
