"""Co-simulation in SUMO: the scenario's string on a SUMO road, the HDVs driven by SUMO's
car-following models, the CAV by any lcc_synth controller, stepped in-process with libsumo.

:func:`simulate_sumo` is the ``backend = "sumo"`` counterpart of
:func:`lcc_synth.simulation.engine.simulate`: the same arguments, the same
:class:`~lcc_synth.simulation.results.SimResult` (metrics, tables, figures and recordings are
unchanged), for every layout of the built-in simulator: the open straight road with one CAV
(column 0 the head, ``1..m`` the HDVs ahead, ``m + 1`` the CAV, the HDVs behind), a mixed
platoon with several CAVs (column ``i`` position ``i``), and the ring road (column ``j``
position ``j + 1``, column 0 following column N-1; the ring, the vehicles' loops and the lap
tracking are :mod:`.sumo_road`'s).

Per scenario of the batch (one SUMO run each: ``libsumo.start`` / ``close``, one at a time per
process):

* a straight single-lane road built by ``netconvert`` (long enough for the head's prescribed
  motion plus the string; :mod:`.sumo_net`) or the ring (:mod:`.sumo_road`), one vehicle
  type per HDV with its drawn parameters
  (:func:`~lcc_synth.simulation.sumo_net.vehicle_types`), every vehicle inserted at
  time 0 at the built-in simulator's initial state (equilibrium spacings at ``v*``, every speed
  ``v*``), SUMO's step = the scenario's ``dt``;
* the head, every CAV, and every HDV while a perturbation drives it, are commanded: speed mode
  0 and lane-change mode 0 (SUMO's safety checks off), ``vehicle.setSpeed(v_k + dt a_k)`` each
  step with ``a_k`` computed exactly as the built-in kernel does (perturbation overrides,
  speed-profile tracking within the limits, each CAV's command (its column of the
  controller's ``(batch, n_cav)``) clipped to ``[a_min, a_max]`` then its emergency braking
  eq. 29 on the state read from SUMO, towards its own predecessor, then, with an actuator lag
  (``cav_lag``), the lag's state in its place, updated from the applied acceleration as the
  built-in kernel does; speeds kept >= 0); an HDV is released to SUMO's model when its
  perturbation ends;
* with ``hdv_accel_noise > 0`` every HDV is commanded too, with SUMO's own IDM speed plus the
  built-in simulator's noise draws; a controller switched on at a time (``start``) leaves its
  CAVs to SUMO's model until the switch (:mod:`.sumo_drive`);
* the controller sees what it would see in the built-in simulator: the same V2V model
  (loss, latency, noise; the built-in simulator's compiled observation routine and its random
  streams), at its sample time with zero-order hold;
* collisions are SUMO's (``--collision.action warn``, ``collisionMinGapFactor = 0``:
  ``libsumo.simulation.getCollisions``) and any spacing ``<= 0`` at a sample, whichever
  comes first; as in the built-in simulator the scenario stops there (later samples NaN).

The recorded acceleration of a sample is ``(v_{k+1} - v_k) / dt`` of SUMO's speeds (what SUMO
applied); the spacing is SUMO's bumper-to-bumper gap (module docstring of :mod:`.sumo_net`).

Differences from the built-in simulator (measured on ``problems/sumo_head_brake.toml``: an IDM
string, v* = 15 m/s, the CAV and 10 HDVs behind, the head-brake profile, dt = 0.01 s;
``tests/test_sumo.py`` checks them, ``benchmarks/bench_sumo.py`` prints them):

* Integration. The built-in simulator is explicit Euler (``p_{k+1} = p_k + dt v_k``). SUMO's
  default is semi-implicit Euler (``p_{k+1} = p_k + dt v_{k+1}``), ``step_method =
  "ballistic"`` the mean speed (``p_{k+1} = p_k + dt (v_k + v_{k+1}) / 2``). That is the whole
  difference: SUMO's IDM string equals the built-in IDM law integrated with SUMO's position
  update to 1e-10 m. For equal speeds each gap moves by ``dt`` times the relative speed, which
  the string carries on: all-HDV max |dv| 0.023 m/s, max |ds| 0.077 m, AAVE -0.13 %, fuel
  -0.03 % (ballistic: half of each); h2 and MPC alike. First order in dt (x 5 at dt = 0.05 s),
  and less than half of either simulator's own step error (0.05-0.06 m/s against a
  dt = 0.0005 s run).
* IDM sub-stepping. SUMO's IDM integrates its speed over ``round(dt / stepping)`` sub-steps
  (``stepping`` 0.25 s by default, the leader's speed held); the backend sets ``stepping = dt``:
  one sub-step, the built-in simulator's update. SUMO's default gives the same run, bit for bit,
  up to dt = 0.25 s; at dt = 0.5 s (2 sub-steps) it moves velocities by up to 0.58 m/s.
* Minimum gap. SUMO's ``minGap`` is the IDM jam distance ``s0`` inside the desired gap, and its
  IDM reports a collision below ``collisionMinGapFactor x minGap`` (0.5 by default): the backend
  sets the factor to 0 (collision = negative gap, the built-in definition) and reports SUMO's
  bumper-to-bumper gap as the spacing (the vehicle length changes the run by < 1e-12).
* Deceleration bound. SUMO never brakes harder than ``emergencyDecel`` (set to ``|a_min|``,
  the built-in clip) and accelerates at most ``accel`` (the IDM ``a <= a_max``).

On the ring the same holds (SUMO's ring reproduces its own scheme to 1e-12 m over laps), but
the all-HDV ring is unstable and each scheme gives its stop-and-go modes their own growth rate
(first order in dt; explicit Euler the fastest), so the difference grows with the wave
(``tests/test_sumo_ring.py``, ``benchmarks/bench_sumo_ring.py``, README).

Wall time: about 35 us per step for 12 vehicles at low load (0.25 s for the 70 s all-HDV run,
0.42 s with a static gain called from Python every step; the built-in compiled loop takes
3 ms); SUMO's own step is about a quarter of it, the rest this module's Python loop.
"""

from __future__ import annotations

import shutil
import tempfile
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.controllers.base import ControlContext, Controller, Observation
from lcc_synth.controllers.switch import switch_step
from lcc_synth.simulation.kernels import _observe_all
from lcc_synth.simulation.perturbations import overrides
from lcc_synth.simulation.results import SimResult
from lcc_synth.simulation.scenario import MODEL_PARAMS, Draws, Scenario
from lcc_synth.simulation.sumo_drive import cav_law_params, hdv_noise, lift_speed_cap
from lcc_synth.simulation.sumo_net import require_sumo, route_file, vehicle_types
from lcc_synth.simulation.sumo_road import place_string, work_dir

__all__ = ["simulate_sumo", "head_travel", "merge_stats"]

#: libsumo holds one simulation per process: runs from several threads take turns.
_LOCK = threading.Lock()


def head_travel(acc_ovr: np.ndarray, spd_ovr: np.ndarray, v0: float, dt: float,
                a_min: float, a_max: float) -> float:  # fmt: skip
    """Distance (m) the head vehicle covers under its prescribed motion (cruise at ``v0``
    unless a perturbation drives it), integrated as the backend commands it."""
    v, dist = float(v0), 0.0
    for k in range(acc_ovr.shape[0]):
        a = 0.0
        if acc_ovr[k, 0] == acc_ovr[k, 0]:
            a = float(acc_ovr[k, 0])
        if spd_ovr[k, 0] == spd_ovr[k, 0]:
            a = min(max((float(spd_ovr[k, 0]) - v) / dt, a_min), a_max)
        v = max(v + dt * a, 0.0)
        dist += dt * v
    return dist


def merge_stats(stats: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """One statistics dict from the per-scenario ``controller.stats()`` of a batch run
    scenario by scenario: integers summed (``steps``, the controller's samples, counted once as
    for a batch run together: the maximum), ``max*`` values the maximum, lists concatenated,
    other numbers averaged over the scenarios (e.g. a median time becomes the mean of the
    per-scenario medians); nested dicts alike."""
    stats = [s for s in stats if s]
    if not stats:
        return {}
    if len(stats) == 1:
        return dict(stats[0])
    out: dict[str, Any] = {}
    for key in stats[0]:
        vals = [s.get(key) for s in stats]
        real = [v for v in vals if v is not None]
        first = real[0] if real else None
        if first is None:
            out[key] = None
        elif isinstance(first, dict):
            out[key] = merge_stats([v for v in real if isinstance(v, dict)])
        elif isinstance(first, list | tuple):
            out[key] = [x for v in real for x in v]
        elif isinstance(first, bool):
            out[key] = any(real)
        elif isinstance(first, int | np.integer) and all(isinstance(v, int | np.integer)
                                                        for v in real):  # fmt: skip
            keep_max = str(key).startswith("max") or key == "steps"
            out[key] = max(real) if keep_max else int(sum(real))
        elif isinstance(first, float | int | np.floating):
            out[key] = (max(real) if str(key).startswith("max")
                        else float(np.mean(real)))  # fmt: skip
        else:
            out[key] = first
    return out


def _start_args(sc: Scenario, net: Path, routes: Path, seed: int) -> list[str]:
    args = ["sumo", "--net-file", str(net), "--route-files", str(routes),
            "--step-length", repr(float(sc.dt)), "--begin", "0",
            "--collision.action", "warn", "--collision.mingap-factor", "0",
            "--time-to-teleport", "-1", "--no-step-log", "true", "--no-warnings", "true",
            "--duration-log.disable", "true", "--seed", str(seed)]  # fmt: skip
    if sc.sumo.step_method == "ballistic":
        args += ["--step-method.ballistic", "true"]
    return args


def _one(sc: Scenario, controller: Controller, draws: Draws, b: int, acc_ovr, spd_ovr, ratio,
         out: dict[str, np.ndarray]) -> dict[str, Any]:  # fmt: skip
    """Run scenario ``b`` of the batch in SUMO; fills row ``b`` of ``out``; returns the
    controller's statistics."""
    from lcc_synth.simulation.engine import _steps_of

    sumo = require_sumo()
    nv, T, dt = sc.n_vehicles, sc.steps, float(sc.dt)
    cavs = np.asarray(sc.cav_columns, dtype=np.int64)
    n_cav = len(cavs)
    is_cav = np.full(nv, -1, dtype=np.int64)  # the observation kernel's CAV index per column
    is_cav[cavs] = np.arange(n_cav)
    ring = bool(sc.ring)
    circ = float(sc.circumference) if ring else 0.0
    ahead = np.arange(nv) - 1
    ahead[0] = nv - 1  # the ring's column 0 follows the last column
    t = sc.times()
    L_veh = float(sc.sumo.vehicle_length)
    a_min, a_max = float(sc.a_min), float(sc.a_max)
    v_star = float(sc.v_star)

    s0 = np.nan_to_num(draws.initial_spacing[b], nan=0.0)
    v = np.full(nv, v_star)
    if sc.initial_state is not None:  # a recording's first sample, as the built-in simulator
        s0[:] = sc.initial_state[0]
        s0[0] = 0.0
        v[:] = sc.initial_state[1]
    if ring:  # column 0 at 0; its spacing is what the others leave of the circumference
        s0[0] = 0.0
    p = -np.cumsum(s0)  # built-in frame: column 0 at 0
    names = MODEL_PARAMS["idm"]
    params = {k: draws.hdv_values[k][b] for k in names}
    vmax = max(float(np.max(params["v0"])), v_star, float(np.max(v)),
               float(np.nanmax(spd_ovr, initial=0.0)))  # fmt: skip
    travel = 0.0 if ring else head_travel(acc_ovr, spd_ovr, float(v[0]), dt, a_min, a_max)
    road = place_string(p, L_veh, circ if ring else None, travel, 2.0 * vmax + 10.0,
                        T * dt)  # fmt: skip
    hdv_mask = sc.is_hdv()
    start = getattr(controller, "start", None)  # controllers.switch.SwitchedOn
    k_on = 0 if start is None else switch_step(start, float(sc.t_start), dt, ratio, T)
    sigma = float(sc.hdv_accel_noise)  # > 0: every HDV commanded with SUMO's speed + noise
    cap = 2.0 * vmax + 10.0
    types = []
    for j in range(nv):
        idm = {k: float(params[k][j]) for k in names}
        if k_on > 0 and is_cav[j] >= 0:  # an HDV of SUMO until the switch (.sumo_drive)
            idm = cav_law_params(sc, params, j)
        elif not hdv_mask[j]:  # commanded vehicles: no speed cap from their type
            idm["v0"] = cap
        types.append(vehicle_types(sc.sumo, idm, dt, a_min))
    run_dir = Path(tempfile.mkdtemp(prefix="run_", dir=work_dir()))
    departures = list(zip(road.lane_pos, v.tolist(), strict=True))  # (lane position, speed)
    routes = route_file(run_dir / "string.rou.xml", types, departures, routes=road.routes)
    ids = [f"v{j}" for j in range(nv)]
    seed = int(np.random.default_rng([int(sc.seed), int(sc.first_index) + b]).integers(2**31 - 1))

    # V2V: the built-in observation routine on a batch of one (random streams of scenario
    # first_index + b), its latency ring buffer filled with the equilibrium cruise
    lat = _steps_of(sc.v2v.latency, dt, "scenario.v2v.latency", multiple=False)
    L = lat + 1
    P, V = p[None].copy(), v[None].copy()
    if L > 1:
        back = np.arange(L)
        hp = np.empty((1, L, nv))  # the kernels' layout: (scenario, slot, vehicle)
        hv = np.empty((1, L, nv))
        hp[:, (-back) % L] = P[:, None] - (back * dt)[None, :, None] * V[:, None]
        hv[:, (-back) % L] = V[:, None]
    else:
        hp = np.empty((1, 1, 1))
        hv = np.empty((1, 1, 1))
    loss = sc.v2v.rates(nv)
    noise = np.array([sc.v2v.spacing_noise, sc.v2v.velocity_noise, sc.v2v.position_noise])
    obs_p, obs_v = P.copy(), V.copy()
    obs_s = np.concatenate([np.full((1, 1), np.nan), P[:, :-1] - P[:, 1:]], axis=1)
    if ring:
        obs_s[:, 0] = P[:, -1] + circ - P[:, 0]
    alive = np.ones(1, dtype=np.bool_)
    controller.reset(_context(sc, draws, b))

    stride = sc.record_every
    o_p, o_v, o_a, o_s = (out[k][b] for k in ("position", "velocity", "acceleration", "spacing"))
    o_u, o_aeb = out["u_cmd"][b], out["aeb_active"][b]
    o_p[:], o_v[:], o_a[:], o_s[:], o_u[:] = np.nan, np.nan, np.nan, np.nan, np.nan
    collided, ctime = out["collided"][b], out["collision_time"][b]
    commanded = np.zeros(nv, dtype=bool)
    commanded[cavs] = k_on == 0
    if sigma > 0.0:
        commanded[hdv_mask] = True
    a_noise = np.zeros(nv)
    min_gap = np.array([float(params["s0"][j]) for j in range(nv)])
    decel = np.array([float(params["b"][j]) for j in range(nv)])
    if not ring:
        commanded[0] = True  # the head
    u_hold = np.zeros(n_cav)
    aeb = np.zeros(n_cav, dtype=bool)
    # actuator lag per CAV (the built-in kernel's: the clipped / braking command drives the
    # lag's state, which the CAV applies; the state then follows the applied acceleration)
    lag_f = np.array([dt / tau if tau > 0 else 0.0 for tau in sc.lags()])
    lagged = bool(lag_f.any())
    a_lag = np.zeros(n_cav)
    cmd = np.zeros(n_cav)
    applied = np.zeros(n_cav)
    abs_min = abs(a_min)
    j0 = 0 if ring else 1  # first column with a vehicle ahead
    want = (1,) if n_cav == 1 else (1, n_cav)

    var_pos, var_speed = sumo.constants.VAR_LANEPOSITION, sumo.constants.VAR_SPEED
    var_idx = sumo.constants.VAR_ROUTE_INDEX
    variables = (var_pos, var_speed, var_idx) if road.ring else (var_pos, var_speed)
    # the columns commanded at some step: head, CAVs, every vehicle a perturbation drives
    ever = np.isfinite(acc_ovr) | np.isfinite(spd_ovr)
    cols = sorted(set(np.flatnonzero(commanded).tolist()) | set(cavs.tolist())
                  | set(np.flatnonzero(ever.any(axis=0)).tolist()))  # fmt: skip

    def read() -> tuple[np.ndarray, np.ndarray]:
        got = sumo.vehicle.getAllSubscriptionResults()
        x = np.array([got[i][var_pos] for i in ids])
        idx = np.array([got[i][var_idx] for i in ids]) if road.ring else 0
        return road.to_builtin(idx, x), np.array([got[i][var_speed] for i in ids])

    sumo.start(_start_args(sc, road.net, routes, seed))
    try:
        sumo.simulationStep()  # inserts every vehicle at its departure state: sample 0
        for j in np.flatnonzero(commanded):
            sumo.vehicle.setSpeedMode(ids[j], 0)
        for i in ids:
            sumo.vehicle.setLaneChangeMode(i, 0)
            sumo.vehicle.subscribe(i, variables)
        p, v = read()
        hit_sumo: set[int] = set()
        for k in range(T):
            rec = k % stride == 0
            r = k // stride
            spacing = np.concatenate([[np.nan], p[:-1] - p[1:]])
            if ring:
                spacing[0] = p[-1] + circ - p[0]
            hit = set(hit_sumo)
            if np.any(spacing[j0:] <= 0.0):
                hit |= set((np.flatnonzero(spacing[j0:] <= 0.0) + j0).tolist())
            if rec:
                o_p[r], o_v[r], o_s[r] = p, v, spacing
            if hit:
                for j in hit:
                    collided[j] = True
                    ctime[j] = t[k]
                break
            P[0], V[0] = p, v
            if L > 1:
                hp[0, k % L], hv[0, k % L] = p, v
            if k == k_on and k > 0 and lagged:  # the lag starts from SUMO's acceleration
                a_lag[:] = np.where(lag_f > 0.0, u_hold, 0.0)
            if k % ratio == 0 or k < k_on:  # before a switch: observed every step, as built in
                _observe_all(k, P, V, hp, hv, L, lat, loss, noise, int(sc.seed),
                             int(sc.first_index) + b, is_cav, ring, circ,
                             obs_s, obs_v, obs_p, alive)  # fmt: skip
            if k % ratio == 0 and k >= k_on:
                u = np.asarray(
                    controller(Observation(float(t[k]), obs_s.copy(), obs_v.copy(),
                                           obs_p.copy(), a_lag[None].copy() if lagged
                                           else None)),
                    dtype=float,
                )  # fmt: skip
                if n_cav == 1 and u.shape == (1, 1):
                    u = u[:, 0]
                if u.shape != want:
                    raise RuntimeError(
                        f"controller {controller.name!r} returned shape {u.shape}, expected "
                        f"{want}"
                    )
                if not np.isfinite(u).all():
                    raise RuntimeError(
                        f"controller {controller.name!r} returned a non-finite command at "
                        f"t = {t[k]:g} s for scenario {b}"
                    )
                u_hold[:] = u.reshape(n_cav)
            aeb[:] = False
            if sigma > 0.0:
                hdv_noise(sigma, int(sc.seed), int(sc.first_index) + b, k, hdv_mask, a_noise)
            for j in cols:
                ov, sv = acc_ovr[k, j], spd_ovr[k, j]
                driven = bool(ever[k, j])
                kc = int(is_cav[j])
                if j == 0 and not ring:
                    a = 0.0  # the head: cruising unless a perturbation drives it
                elif kc >= 0 and k >= k_on:
                    a = min(max(u_hold[kc], a_min), a_max)
                    lead = ahead[j]
                    if sc.cav_aeb and (v[j] ** 2 - v[lead] ** 2) / (2.0 * spacing[j]) >= abs_min:
                        a, aeb[kc] = a_min, True
                    if lag_f[kc] > 0.0:  # actuator lag: the CAV applies the lag's state
                        cmd[kc], a = a, a_lag[kc]
                elif driven:
                    a = 0.0
                elif sigma > 0.0 and kc < 0:  # SUMO's follow speed plus the noise
                    lead = ahead[j]
                    v_cf = sumo.vehicle.getFollowSpeed(ids[j], v[j], spacing[j] - min_gap[j],
                                                       v[lead], decel[lead], ids[lead])
                    a = min(max((v_cf - v[j]) / dt + a_noise[j], a_min), a_max)
                else:
                    if commanded[j]:  # its perturbation ended: back to SUMO's model
                        sumo.vehicle.setSpeed(ids[j], -1.0)
                        sumo.vehicle.setSpeedMode(ids[j], 31)
                        commanded[j] = False
                    continue
                if ov == ov:
                    a = float(ov)
                if sv == sv:
                    a = min(max((float(sv) - v[j]) / dt, a_min), a_max)
                if driven and kc >= 0:
                    aeb[kc] = False
                if not commanded[j]:
                    sumo.vehicle.setSpeedMode(ids[j], 0)
                    commanded[j] = True
                    if kc >= 0 and k >= k_on:  # switched on
                        lift_speed_cap(sumo, ids[j], cap)
                sumo.vehicle.setSpeed(ids[j], max(v[j] + dt * a, 0.0))
                if kc >= 0:
                    applied[kc] = max(a, -v[j] / dt)  # the standstill floor, as built in
            if lagged:
                a_lag[:] = np.where(lag_f > 0.0, applied + lag_f * (cmd - applied), 0.0)
            sumo.simulationStep()
            hit_sumo = {ids.index(c.collider) for c in sumo.simulation.getCollisions()
                        if c.collider in ids}  # fmt: skip
            p_next, v_next = read()
            if k < k_on:  # the CAVs' acceleration under SUMO's model (recorded as u)
                u_hold[:] = (v_next[cavs] - v[cavs]) / dt
            if rec:
                o_a[r] = (v_next - v) / dt
                o_u[r] = u_hold
                o_aeb[r] = aeb
            p, v = p_next, v_next
    finally:
        sumo.close()
        shutil.rmtree(run_dir, ignore_errors=True)
    return controller.stats()


def _context(sc: Scenario, draws: Draws, b: int) -> ControlContext:
    """Scenario ``b``'s :class:`ControlContext` (a batch of one), as the built-in simulator
    builds it."""
    s_star = np.array([sc.s_star])
    ring = bool(sc.ring)
    if sc.spacing_reference == "own_equilibrium":
        s_ref = draws.initial_spacing[b].copy()
        if not ring:
            s_ref[0] = sc.s_star
    else:
        s_ref = np.full(sc.n_vehicles, sc.s_star)
    return ControlContext(
        sc.m, sc.n, 1, float(sc.dt), np.array([float(sc.v_star)]), s_star, sc.a_min, sc.a_max,
        sc.hdv, s_ref=s_ref[None].copy(), cavs=tuple(int(c) for c in sc.cav_columns),
        ring=ring, circumference=float(sc.circumference) if ring else float("nan"),
        cav_models=sc.cav_models(),
    )  # fmt: skip


def simulate_sumo(
    scenario: Scenario, controller: Controller, draws: Draws | None = None
) -> SimResult:
    """Run ``controller`` on every scenario of the batch in SUMO (module docstring).

    Parameters
    ----------
    scenario : Scenario
        With ``backend = "sumo"`` (or any scenario that passes
        :func:`~lcc_synth.simulation.sumo_net.check_sumo_scenario`); its ``sumo`` settings
        choose the car-following model and SUMO's integration scheme.
    controller : Controller
        Any object of the controller protocol, called from Python at its sample time (reset
        once per scenario, with a batch of one).
    draws : Draws, optional
        Per-vehicle draws (default ``scenario.draw()``).

    Returns
    -------
    SimResult
        As :func:`lcc_synth.simulation.engine.simulate`; ``controller_stats`` merges the
        per-scenario statistics (:func:`merge_stats`).
    """
    from lcc_synth.simulation.engine import _steps_of
    from lcc_synth.simulation.sumo_net import check_sumo_scenario

    wall0 = time.perf_counter()
    sc = scenario
    check_sumo_scenario(sc)
    require_sumo()
    draws = sc.draw() if draws is None else draws
    B, nv, T, dt = sc.batch, sc.n_vehicles, sc.steps, sc.dt
    ts = controller.sample_time
    ratio = 1 if ts is None else _steps_of(
        ts, dt, f"controllers.{controller.name}.sample_time", multiple=True
    )
    acc_ovr, spd_ovr = overrides(sc.perturbations, sc.times(), dt, sc.m, sc.n, sc.layout)
    n_cav = len(sc.cav_columns)
    Tr = (T - 1) // sc.record_every + 1
    out = {
        "position": np.empty((B, Tr, nv)),
        "velocity": np.empty((B, Tr, nv)),
        "acceleration": np.empty((B, Tr, nv)),
        "spacing": np.empty((B, Tr, nv)),
        "u_cmd": np.empty((B, Tr, n_cav)),
        "aeb_active": np.zeros((B, Tr, n_cav), dtype=np.bool_),
        "collided": np.zeros((B, nv), dtype=np.bool_),
        "collision_time": np.full((B, nv), np.nan),
    }
    stats = []
    with _LOCK:
        for b in range(B):
            stats.append(_one(sc, controller, draws, b, acc_ovr, spd_ovr, ratio, out))
    if n_cav == 1:  # one CAV: (batch, samples), as the built-in simulator
        out["u_cmd"], out["aeb_active"] = out["u_cmd"][:, :, 0], out["aeb_active"][:, :, 0]
    L_sys = float(sc.vehicle_length)  # [system] vehicle_length: the road's positions, built in
    if L_sys > 0:
        out["position"] -= L_sys * np.arange(nv)
    return SimResult(
        t=sc.times()[:: sc.record_every].copy(),
        **out,
        m=sc.m,
        n=sc.n,
        cav=sc.cav,
        cavs=tuple(int(c) for c in sc.cav_columns),
        ring=bool(sc.ring),
        circumference=float(sc.circumference) + nv * L_sys if sc.ring else float("nan"),
        vehicle_length=L_sys,
        v_star=np.full(B, float(sc.v_star)),
        s_star=np.full(B, sc.s_star),
        controller=controller.name,
        controller_info=controller.describe(),
        controller_stats=merge_stats(stats),
        dt=dt * sc.record_every,
        sim_dt=dt,
        scenario=sc,
        draws=draws,
        wall_time=time.perf_counter() - wall0,
    )
