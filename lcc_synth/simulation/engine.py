"""Nonlinear mixed-traffic simulator (Section V): a string of vehicles on a single lane, open
or closed into a ring.

Open string: column 0 is the head vehicle (prescribed motion: cruising unless perturbed),
columns ``1..m`` the HDVs ahead, ``m + 1`` the CAV, ``m + 2 .. m + n + 1`` the HDVs behind.
A mixed platoon (``[system] kind = "platoon"``) has several CAVs: column ``i`` is position
``i`` (1..N) behind the head, the CAV columns are :attr:`Scenario.cav_columns`. A ring
(``kind = "ring"``) has no head: column ``j`` is position ``j + 1`` (0..N-1), column 0 follows
column N-1, and its spacing is ``p[N-1] + C - p[0]`` (``C`` the circumference). Positions are
never wrapped (the road view wraps them, angle ``2 pi p / C``): the ring offset enters only
column 0's spacing, so the open string's arithmetic is untouched. Many scenarios (``batch``)
advance together; each may have its own HDV parameters and reaction delays.

Integration, as in the paper's reference scripts: sample ``k`` is at ``t_k = t_start + k dt``;
the acceleration ``a_k`` of every vehicle is computed from the state at sample ``k``
(perturbations evaluated at ``t_k``), then ``v_{k+1} = v_k + dt a_k`` and
``p_{k+1} = p_k + dt v_k`` (position with the previous velocity). Velocities never go below 0
(the acceleration is raised to ``-v_k / dt`` instead).

Per step:

* HDVs: car-following law (OVM or IDM, per-vehicle parameters) on the spacing, relative speed
  and own speed seen ``delay`` seconds earlier (``delay_model = "full"``; a ring buffer of past
  states, the history before ``t_start`` being the equilibrium cruise) or on the delayed
  spacing and relative speed with the current own speed (``"perception"``), plus optional white
  acceleration noise, clipped to ``[a_min, a_max]``; optionally emergency braking (eq. 29) on
  the current state.
* CAVs: each CAV's command (held between controller samples: zero-order hold) clipped to
  ``[a_min, a_max]``, then emergency braking, eq. (29): ``a_min`` when
  ``(v_0^2 - v_-1^2) / (2 s_0) >= |a_min|`` on that CAV's exact state (per CAV).
  Optional actuator lag ``tau`` (``[scenario] cav_lag``): that clipped command, or the
  braking command, is the input of ``da/dt = (u - a) / tau`` (Euler at ``dt``; braking goes
  through the same brake actuator), and the CAV applies ``a``, the lag's state, which then
  takes every change made to the applied acceleration below (noise, overrides, floor).
* Optional uniform acceleration noise ``U[-w, w]`` (``accel_noise_uniform``) on every vehicle
  but the head, added after the limits and emergency braking (the DeeP-LCC reference scheme).
* Perturbations override the acceleration of their vehicle while active (not clipped: they are
  the scenario's input); speed profiles are tracked within the limits.
* Collisions: a vehicle with spacing ``<= 0`` at a sample is marked (per vehicle, with the
  time) and its scenario STOPS: that sample is recorded, every later sample of the scenario
  is NaN. Other scenarios of the batch go on.

What the CAVs observe (V2V): at each controller sample every other vehicle's link delivers its
spacing, velocity and position, ``latency`` seconds old and with Gaussian measurement noise,
with probability ``1 - loss_rate``; a lost packet leaves the last received value. Every CAV's
own spacing, velocity and position are exact, and the CAVs are connected: each CAV's exact
values are known to all (one observation serves every CAV).

The stepping loop is compiled with numba. Controllers with a fixed linear law (the CAV as an
HDV, static gains, with the fixed or the estimated equilibrium and the optional measurement
filter; see :class:`~lcc_synth.controllers.static.LinearLaw`) are evaluated inside the compiled
loop; any other controller is called from Python once per controller sample and the compiled
loop advances the scenarios between samples. A controller switched on at a time
(:class:`~lcc_synth.controllers.switch.SwitchedOn`, ``start``) has the CAVs drive with their
HDV law in the compiled loop until the switch sample, then runs as above.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from lcc_synth.controllers.base import ControlContext, Controller, Observation
from lcc_synth.controllers.switch import switch_step
from lcc_synth.errors import ConfigError
from lcc_synth.interrupts import checkpoint
from lcc_synth.resources import require_memory, simulation_bytes
from lcc_synth.simulation.perturbations import overrides
from lcc_synth.simulation.results import SimResult
from lcc_synth.simulation.scenario import MODEL_PARAMS, Draws, Scenario

__all__ = ["simulate", "simulate_many"]

#: Code of each HDV model inside the compiled loop.
_MODEL_CODE = {"ovm": 0, "idm": 1}


_POOL: ThreadPoolExecutor | None = None


def _cpu_count() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def _threads(batch: int, work_per_call: int) -> int:
    """Threads for one kernel call: 1 unless there are several scenarios and enough work."""
    if batch < 2 or batch * work_per_call < 200_000:
        return 1
    return min(batch, _cpu_count())


def _executor() -> ThreadPoolExecutor:
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=_cpu_count(), thread_name_prefix="lcc-sim")
    return _POOL


def _steps_of(value: float, dt: float, field: str, multiple: bool) -> int:
    ratio = value / dt
    r = int(round(ratio))
    if multiple and (r < 1 or abs(ratio - r) > 1e-6 * max(1.0, ratio)):
        raise ConfigError(field, f"must be a positive multiple of dt = {dt} s, got {value}")
    return r


def _law_arrays(law, n_cav: int, nv: int, ring: bool, name: str):
    """``(Ks, Kv, Kp)`` of a :class:`~lcc_synth.controllers.static.LinearLaw` as one row per
    CAV (``(n_cav, nv)``, ``(n_cav,)``): a single row (one CAV, or a law without gains such as
    the HDV law) applies to every CAV."""
    Ks = np.atleast_2d(np.asarray(law.Ks, dtype=float))
    Kv = np.atleast_2d(np.asarray(law.Kv, dtype=float))
    Kp = np.atleast_1d(np.asarray(law.Kp, dtype=float))
    field = f"controllers.{name}"
    if Ks.shape[1:] != (nv,) or Kv.shape != Ks.shape or Kp.shape != (Ks.shape[0],):
        raise ConfigError(field, f"linear law needs {nv} spacing and velocity gains per CAV")
    if not ring and np.any(Ks[:, 0] != 0.0):
        raise ConfigError(field, "linear law has a gain on the head's spacing (it has none)")
    if Ks.shape[0] != n_cav:
        if Ks.shape[0] != 1 or (n_cav > 1 and (Ks.any() or Kv.any() or Kp.any())):
            raise ConfigError(
                field, f"has gains for {Ks.shape[0]} CAV(s); the scenario has {n_cav}"
            )
        Ks, Kv, Kp = (np.repeat(x, n_cav, axis=0) for x in (Ks, Kv, Kp))
    return tuple(np.ascontiguousarray(x) for x in (Ks, Kv, Kp))


def simulate(
    scenario: Scenario, controller: Controller, draws: Draws | None = None
) -> SimResult:
    """Run ``controller`` on every scenario of the batch.

    Parameters
    ----------
    scenario : Scenario
    controller : Controller
        Any object of the controller protocol. A controller with a ``linear_law(ctx)`` method
        (HDV and static-gain controllers) runs inside the compiled loop.
    draws : Draws, optional
        Per-vehicle draws to use (default ``scenario.draw()``); passing the same draws to
        several controllers compares them on identical scenarios.

    Returns
    -------
    SimResult
    """
    # the compiled kernels (numba) here, not at the top: checking a problem file's time step
    # (simulation.timestep, _steps_of) needs no compiler
    from lcc_synth.simulation.kernels import _advance, _observe_all

    wall0 = time.perf_counter()
    sc = scenario
    B, nv, T, dt = sc.batch, sc.n_vehicles, sc.steps, sc.dt
    cav = sc.cav
    cavs = np.asarray(sc.cav_columns, dtype=np.int64)
    n_cav = len(cavs)
    is_cav = np.full(nv, -1, dtype=np.int64)
    is_cav[cavs] = np.arange(n_cav)
    ring, circ = bool(sc.ring), float(sc.circumference) if sc.ring else 0.0
    require_memory(
        "scenario.duration",
        simulation_bytes(sc),
        f"{T} steps x {nv} vehicles x {B} scenario(s), every {sc.record_every} step(s) kept",
        "shorten scenario.duration, raise scenario.dt or scenario.record_every, or run fewer "
        "seeds at once",
    )
    draws = sc.draw() if draws is None else draws
    t = sc.times()

    # initial state: equilibrium cruise, head at p = 0
    s0 = np.nan_to_num(draws.initial_spacing, nan=0.0)
    v = np.full((B, nv), float(sc.v_star))
    if sc.initial_state is not None:  # a recording's first sample ([scenario] initial = "data")
        s0[:] = sc.initial_state[0]
        s0[:, 0] = 0.0
        v[:] = sc.initial_state[1]
    if ring:  # column 0 at p = 0; its spacing is what the others leave of the circumference
        s0[:, 0] = 0.0
    p = -np.cumsum(s0, axis=1)

    # delays / latency ring buffer (history before t_start: the equilibrium cruise)
    delay_steps = np.rint(draws.delay / dt).astype(np.int64)
    lat = _steps_of(sc.v2v.latency, dt, "scenario.v2v.latency", multiple=False)
    L = int(max(int(delay_steps.max(initial=0)), lat)) + 1
    if L > 1:
        back = np.arange(L)  # steps before the first sample
        slots = (-back) % L
        hp = np.empty((B, L, nv))  # scenario-major: one scenario's history is contiguous
        hv = np.empty((B, L, nv))
        hp[:, slots] = p[:, None] - (back * dt)[None, :, None] * v[:, None]
        hv[:, slots] = v[:, None]
    else:
        hp = np.empty((1, 1, 1))
        hv = np.empty((1, 1, 1))

    code = _MODEL_CODE[sc.hdv.name]
    names = MODEL_PARAMS[sc.hdv.name]
    params = np.zeros((B, nv, 6))
    for i, key in enumerate(names):
        params[:, :, i] = draws.hdv_values[key]
    nom_params = np.zeros(6)
    for i, key in enumerate(names):
        nom_params[i] = getattr(sc.hdv, key)
    if sc.cavs is None:  # the CAV's HDV law: the nominal model
        law_params = np.ascontiguousarray(np.broadcast_to(nom_params, (B, 1, 6)))
    else:  # each CAV's own slot (platoon)
        law_params = np.ascontiguousarray(params[:, cavs, :])

    acc_ovr, spd_ovr = overrides(sc.perturbations, t, dt, sc.m, sc.n, sc.layout)
    ovr_cols = ~(np.isnan(acc_ovr).all(axis=0) & np.isnan(spd_ovr).all(axis=0))

    v_star = np.full(B, float(sc.v_star))
    s_star = np.full(B, sc.s_star)
    if sc.spacing_reference == "own_equilibrium":
        s_ref = draws.initial_spacing.copy()
        if not ring:
            s_ref[:, 0] = s_star
    else:
        s_ref = np.repeat(s_star[:, None], nv, axis=1)
    ctx = ControlContext(
        sc.m, sc.n, B, dt, v_star, s_star, sc.a_min, sc.a_max, sc.hdv, s_ref=s_ref.copy(),
        cavs=tuple(int(c) for c in cavs), ring=ring,
        circumference=float(sc.circumference) if ring else float("nan"),
        cav_models=sc.cav_models(),
    )
    controller.reset(ctx)
    ts = controller.sample_time
    ratio = 1 if ts is None else _steps_of(
        ts, dt, f"controllers.{controller.name}.sample_time", multiple=True
    )
    law_fn = getattr(controller, "linear_law", None)
    law = law_fn(ctx) if callable(law_fn) else None

    loss = sc.v2v.rates(nv)
    obs_noise = np.array([sc.v2v.spacing_noise, sc.v2v.velocity_noise, sc.v2v.position_noise])
    obs_p = p.copy()
    obs_v = v.copy()
    obs_s = np.concatenate([np.full((B, 1), np.nan), p[:, :-1] - p[:, 1:]], axis=1)
    if ring:
        obs_s[:, 0] = p[:, -1] + circ - p[:, 0]
    p_ref = p[:, cavs].copy()

    stride = sc.record_every
    Tr = (T - 1) // stride + 1
    out_p = np.empty((B, Tr, nv))
    out_v = np.empty((B, Tr, nv))
    out_a = np.empty((B, Tr, nv))
    out_s = np.empty((B, Tr, nv))
    out_u = np.empty((B, Tr, n_cav))
    out_aeb = np.zeros((B, Tr, n_cav), dtype=np.bool_)
    alive = np.ones(B, dtype=np.bool_)
    collided = np.zeros((B, nv), dtype=np.bool_)
    ctime = np.full((B, nv), np.nan)
    u_hold = np.zeros((B, n_cav))
    lag_f = np.array([dt / tau if tau > 0 else 0.0 for tau in sc.lags()])  # per CAV
    a_lag = np.zeros((B, n_cav))  # the lagged CAVs' accelerations (cruise: 0)
    lagged = bool(lag_f.any())  # else the kernel runs without the lag (None)

    v_hat = v_star.copy()
    est = (-1.0, 0.0, 0.0)  # (decay, v_lo, v_hi); decay < 0: errors from the fixed v*
    if law is not None and law.equilibrium_decay is not None:
        if n_cav > 1:
            raise ConfigError(
                f"controllers.{controller.name}.equilibrium",
                'must be "fixed" with several CAVs (the estimate follows one CAV\'s predecessor)',
            )
        est = (float(law.equilibrium_decay), *map(float, law.v_bounds))
    meas = None if law is None else law.measurement_decay(ratio * dt)
    meas_decay = -1.0 if meas is None else float(meas)  # < 0: the values as received
    f_s = np.full((B, nv), np.nan)  # measurement filter states (NaN: not started)
    f_v = np.full((B, nv), np.nan)

    def advance_range(b0, b1, k0, k1, mode, Ks, Kv, Kp, hdv_law, ratio=ratio, law_state=True):
        # law_state False (before a switch-on): the HDV law on the exact state, no estimate or
        # filter (they start at the switch, as the wrapped controller does)
        e0, md = (est[0], meas_decay) if law_state else (-1.0, -1.0)
        _advance(
            b0, b1, k0, k1, p, v, hp, hv, L, delay_steps, sc.delay_model == "full", code,
            params, code, law_params,
            float(dt), float(sc.t_start), float(sc.a_min), float(sc.a_max), cavs, is_cav,
            ring, circ, bool(sc.cav_aeb), bool(sc.hdv_aeb), float(sc.hdv_accel_noise),
            float(sc.accel_noise_uniform), int(sc.seed), int(sc.first_index),
            acc_ovr, spd_ovr, ovr_cols, mode, ratio, u_hold, Ks, Kv, Kp, bool(hdv_law),
            v_star, s_ref, p_ref, e0, est[1], est[2], v_hat, md, f_s, f_v,
            loss, lat, obs_noise, obs_s, obs_v, obs_p,
            alive, collided, ctime, stride, out_p, out_v, out_a, out_s, out_u, out_aeb,
            lag_f if lagged else None, a_lag if lagged else None,
        )  # fmt: skip

    n_threads = _threads(B, (T if law is not None else ratio) * nv)

    def advance(k0, k1, mode, Ks, Kv, Kp, hdv_law, r=ratio, law_state=True):
        if n_threads == 1:
            advance_range(0, B, k0, k1, mode, Ks, Kv, Kp, hdv_law, r, law_state)
            return
        edges = np.linspace(0, B, n_threads + 1).astype(int)
        futures = [
            _executor().submit(advance_range, b0, b1, k0, k1, mode, Ks, Kv, Kp, hdv_law, r,
                               law_state)
            for b0, b1 in zip(edges[:-1], edges[1:], strict=True)
        ]
        for f in futures:
            f.result()

    zeros = np.zeros((n_cav, nv))
    kp0 = np.zeros(n_cav)
    start = getattr(controller, "start", None)  # controllers.switch.SwitchedOn
    k_on = 0 if start is None else switch_step(start, float(sc.t_start), dt, ratio, T)
    if k_on > 0:  # before the switch: every CAV's HDV law, every step, compiled
        advance(0, k_on, 1, zeros, zeros, kp0, True, 1, False)
    if law is not None:
        Ks, Kv, Kp = _law_arrays(law, n_cav, nv, ring, controller.name)
        advance(k_on, T, 1, Ks, Kv, Kp, law.hdv_law)
    else:
        for k0 in range(k_on, T, ratio):
            checkpoint()  # a signal whose exception an extension dropped (interrupts)
            _observe_all(k0, p, v, hp, hv, L, lat, loss, obs_noise, int(sc.seed),
                         int(sc.first_index), is_cav, ring, circ,
                         obs_s, obs_v, obs_p, alive)  # fmt: skip
            tk = float(t[k0])
            obs = Observation(tk, obs_s.copy(), obs_v.copy(), obs_p.copy(),
                              a_lag.copy() if lagged else None)
            u = np.asarray(controller(obs), dtype=float)
            want = (B,) if n_cav == 1 else (B, n_cav)
            if n_cav == 1 and u.ndim == 2 and u.shape == (B, 1):
                u = u[:, 0]
            if u.shape != want:
                raise RuntimeError(
                    f"controller {controller.name!r} returned shape {u.shape}, expected {want}"
                )
            u = u.reshape(B, n_cav)
            bad = alive & ~np.isfinite(u).all(axis=1)
            if bad.any():
                raise RuntimeError(
                    f"controller {controller.name!r} returned a non-finite command at t = {tk:g} s "
                    f"for scenario(s) {np.flatnonzero(bad).tolist()}"
                )
            u_hold[:] = np.where(alive[:, None], u, 0.0)
            advance(k0, min(k0 + ratio, T), 0, zeros, zeros, kp0, False)

    if sc.vehicle_length > 0:  # gap coordinates -> the road's front-bumper positions
        out_p -= sc.vehicle_length * np.arange(nv)
    return SimResult(
        t=t[::stride].copy(),
        position=out_p,
        velocity=out_v,
        acceleration=out_a,
        spacing=out_s,
        u_cmd=out_u[:, :, 0] if n_cav == 1 else out_u,
        aeb_active=out_aeb[:, :, 0] if n_cav == 1 else out_aeb,
        collided=collided,
        collision_time=ctime,
        m=sc.m,
        n=sc.n,
        cav=cav,
        cavs=tuple(int(c) for c in cavs),
        ring=ring,
        circumference=float(sc.circumference) + nv * sc.vehicle_length if ring else float("nan"),
        vehicle_length=float(sc.vehicle_length),
        v_star=v_star,
        s_star=s_star,
        controller=controller.name,
        controller_info=controller.describe(),
        controller_stats=controller.stats(),
        dt=dt * stride,
        sim_dt=dt,
        scenario=sc,
        draws=draws,
        wall_time=time.perf_counter() - wall0,
    )


def simulate_many(
    scenario: Scenario, controllers: Mapping[str, Controller] | Sequence[Controller]
) -> dict[str, SimResult]:
    """Run several controllers on the same draws; returns ``{name: SimResult}`` in order.

    Every result stays in memory: their total is checked (``scenario.batch``) before the
    draws are made."""
    items = list(controllers.items() if isinstance(controllers, Mapping) else (
        (c.name, c) for c in controllers
    ))  # fmt: skip
    sc, n = scenario, len(items)
    require_memory(
        "scenario.batch", n * simulation_bytes(sc),
        f"{n} results of {sc.steps} steps x {sc.n_vehicles} vehicles x {sc.batch} scenario(s)",
        "run fewer scenarios or controllers at once",
    )  # fmt: skip
    draws = scenario.draw()
    return {name: simulate(scenario, ctrl, draws) for name, ctrl in items}
