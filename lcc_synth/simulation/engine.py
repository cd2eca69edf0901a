"""Nonlinear mixed-traffic simulator (Section V): a string of vehicles on an open single lane.

Column 0 is the head vehicle (prescribed motion: cruising unless perturbed), columns ``1..m``
the HDVs ahead, ``m + 1`` the CAV, ``m + 2 .. m + n + 1`` the HDVs behind. Many scenarios
(``batch``) advance together; each may have its own HDV parameters and reaction delays.

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
* CAV: the controller's command (held between controller samples: zero-order hold) clipped to
  ``[a_min, a_max]``, then emergency braking, eq. (29): ``a_min`` when
  ``(v_0^2 - v_-1^2) / (2 s_0) >= |a_min|`` on the CAV's exact state.
* Perturbations override the acceleration of their vehicle while active (not clipped: they are
  the scenario's input); speed profiles are tracked within the limits.
* Collisions: a vehicle with spacing ``<= 0`` at a sample is marked (per vehicle, with the
  time) and its scenario STOPS: that sample is recorded, every later sample of the scenario
  is NaN. Other scenarios of the batch go on.

What the CAV observes (V2V): at each controller sample every other vehicle's link delivers its
spacing, velocity and position, ``latency`` seconds old and with Gaussian measurement noise,
with probability ``1 - loss_rate``; a lost packet leaves the last received value. The CAV's own
spacing, velocity and position are exact.

The stepping loop is compiled with numba. Controllers with a fixed linear law (the CAV as an
HDV, static gains, with the fixed or the estimated equilibrium; see
:class:`~lcc_synth.controllers.static.LinearLaw`) are evaluated inside the compiled loop; any other
controller is called from Python once per controller sample and the compiled loop advances the
scenarios between samples.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np

from lcc_synth.controllers.base import ControlContext, Controller, Observation
from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import IDM, OVM
from lcc_synth.simulation.perturbations import Perturbation, overrides

__all__ = [
    "MODEL_PARAMS",
    "V2V",
    "Scenario",
    "Draws",
    "SimResult",
    "simulate",
    "simulate_many",
]

#: Parameter order of each HDV model inside the compiled loop.
MODEL_PARAMS = {
    "ovm": ("alpha", "beta", "s_st", "s_go", "v_max"),
    "idm": ("v0", "T", "s0", "a", "b", "delta"),
}
_MODEL_CODE = {"ovm": 0, "idm": 1}
_MODEL_CLASS = {"ovm": OVM, "idm": IDM}


# --------------------------------------------------------------------------------------------
# Scenario description
# --------------------------------------------------------------------------------------------


def _num(name: str, value, lo=None, hi=None, lo_open=False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(name, f"must be a number, got {value!r}") from None
    ok = math.isfinite(x)
    if ok and lo is not None:
        ok = x > lo if lo_open else x >= lo
    if ok and hi is not None:
        ok = x <= hi
    if not ok:
        rng = []
        if lo is not None:
            rng.append(f"{'>' if lo_open else '>='} {lo}")
        if hi is not None:
            rng.append(f"<= {hi}")
        raise ConfigError(name, f"must be {' and '.join(rng) or 'finite'}, got {value!r}")
    return x


@dataclass(frozen=True)
class V2V:
    """What the CAV receives from the other vehicles.

    Parameters
    ----------
    loss_rate : float or sequence of float
        Packet-loss probability in [0, 1], one for all links or one per vehicle column
        (head..tail; the CAV's entry is ignored).
    latency : float
        Age (s) of every received value, >= 0; rounded to simulation steps.
    spacing_noise, velocity_noise, position_noise : float
        Standard deviations of the measurement noise on received values, >= 0.
    """

    loss_rate: float | Sequence[float] = 0.0
    latency: float = 0.0
    spacing_noise: float = 0.0
    velocity_noise: float = 0.0
    position_noise: float = 0.0

    def __post_init__(self) -> None:
        rates = np.atleast_1d(np.asarray(self.loss_rate, dtype=float))
        if rates.ndim != 1 or not np.all(np.isfinite(rates)) or np.any((rates < 0) | (rates > 1)):
            raise ConfigError(
                "scenario.v2v.loss_rate", f"must be in [0, 1], got {self.loss_rate!r}"
            )
        _num("scenario.v2v.latency", self.latency, lo=0.0)
        for key in ("spacing_noise", "velocity_noise", "position_noise"):
            _num(f"scenario.v2v.{key}", getattr(self, key), lo=0.0)

    def rates(self, nv: int) -> np.ndarray:
        """Per-column loss rates ``(nv,)``."""
        rates = np.atleast_1d(np.asarray(self.loss_rate, dtype=float))
        if rates.size == 1:
            return np.full(nv, float(rates[0]))
        if rates.size != nv:
            raise ConfigError(
                "scenario.v2v.loss_rate",
                f"needs 1 or {nv} entries (one per vehicle, head..tail), got {rates.size}",
            )
        return rates.copy()


@dataclass(frozen=True)
class Scenario:
    """A mixed-traffic scenario (or a batch of ``batch`` scenarios differing in random draws).

    Parameters
    ----------
    m, n : int
        HDVs ahead of and behind the CAV.
    hdv : OVM or IDM
        Nominal HDV model (also the CAV's own HDV law).
    v_star : float
        Equilibrium velocity; the initial state is the equilibrium.
    dt, duration, t_start : float
        Step, length (``round(duration / dt)`` samples) and time of the first sample.
    batch : int
        Number of scenarios advanced together.
    a_min, a_max : float
        Acceleration limits of every vehicle.
    cav_aeb, hdv_aeb : bool
        Emergency braking (eq. 29) for the CAV / for every HDV.
    perturbations : sequence
        Prescribed motions (:mod:`lcc_synth.simulation.perturbations`).
    hdv_values : mapping, optional
        Explicit per-vehicle parameters: name -> array broadcastable to ``(batch, nv)``;
        default the nominal model everywhere.
    heterogeneity : mapping
        Parameter -> half width ``w``: every HDV of every scenario adds ``U[-w, w]``.
    delay : float or array
        Base reaction delay (s) of the HDVs, broadcastable to ``(batch, nv)``.
    delay_spread : float
        Every HDV adds ``U[-delay_spread, delay_spread]`` to its delay.
    delay_model : {"full", "perception"}
        ``full``: the whole state the HDV reacts to (spacing, relative speed, own speed) is
        ``delay`` old; ``perception``: spacing and relative speed are ``delay`` old, the own
        speed is current.
    hdv_accel_noise : float
        Standard deviation of white acceleration noise on every HDV (m/s^2).
    v2v : V2V
        Communication model of what the CAV receives.
    seed : int
        Base seed; scenario ``b`` of the batch draws from ``[seed, first_index + b]``
        (independent of the batch size).
    first_index : int
        Index of the batch's first scenario in a larger study (Monte Carlo sweeps run it in
        chunks): scenario ``b`` is study scenario ``first_index + b``, and every random draw
        (parameters, delays, acceleration noise, V2V loss and noise) depends only on
        ``(seed, first_index + b)``.
    record_every : int
        Keep every k-th sample in the result.
    spacing_reference : {"nominal", "own_equilibrium"}
        Reference of the spacing errors the controllers see: the nominal ``s*`` for every
        vehicle, or each HDV's own equilibrium spacing at ``v*`` (the heterogeneous
        linearisation, eq. 8 around each vehicle's equilibrium). Same thing when homogeneous.
    """

    m: int
    n: int
    hdv: OVM | IDM = field(default_factory=OVM)
    v_star: float = 15.0
    dt: float = 0.01
    duration: float = 100.0
    t_start: float = 0.0
    batch: int = 1
    a_min: float = -5.0
    a_max: float = 2.0
    cav_aeb: bool = True
    hdv_aeb: bool = False
    perturbations: tuple[Perturbation, ...] = ()
    hdv_values: Mapping[str, Any] | None = None
    heterogeneity: Mapping[str, float] = field(default_factory=dict)
    delay: Any = 0.0
    delay_spread: float = 0.0
    delay_model: str = "full"
    hdv_accel_noise: float = 0.0
    v2v: V2V = field(default_factory=V2V)
    seed: int = 0
    first_index: int = 0
    record_every: int = 1
    spacing_reference: str = "nominal"
    name: str = "scenario"

    def __post_init__(self) -> None:
        for key, lo in (
            ("m", 0), ("n", 0), ("batch", 1), ("record_every", 1), ("seed", 0), ("first_index", 0)
        ):
            val = getattr(self, key)
            if isinstance(val, bool) or not isinstance(val, int | np.integer) or val < lo:
                raise ConfigError(f"scenario.{key}", f"must be an integer >= {lo}, got {val!r}")
        if self.delay_model not in ("full", "perception"):
            raise ConfigError(
                "scenario.delay.model",
                f'must be "full" or "perception", got {self.delay_model!r}',
            )
        if self.spacing_reference not in ("nominal", "own_equilibrium"):
            raise ConfigError(
                "scenario.spacing_reference",
                f'must be "nominal" or "own_equilibrium", got {self.spacing_reference!r}',
            )
        _num("scenario.dt", self.dt, lo=0.0, lo_open=True)
        _num("scenario.duration", self.duration, lo=0.0, lo_open=True)
        _num("scenario.t_start", self.t_start)
        if self.steps < 1:
            raise ConfigError("scenario.duration", f"must be at least dt = {self.dt}")
        _num("scenario.a_min", self.a_min, hi=0.0)
        if not self.a_min < 0:
            raise ConfigError("scenario.a_min", f"must be < 0, got {self.a_min}")
        _num("scenario.a_max", self.a_max, lo=0.0, lo_open=True)
        _num("scenario.hdv_accel_noise", self.hdv_accel_noise, lo=0.0)
        _num("scenario.delay_spread", self.delay_spread, lo=0.0)
        delay = np.asarray(self.delay, dtype=float)
        if not np.all(np.isfinite(delay)) or np.any(delay < 0):
            raise ConfigError("scenario.delay", f"must be >= 0 s, got {self.delay!r}")
        if np.any(delay - self.delay_spread < 0):
            raise ConfigError(
                "scenario.delay.spread",
                f"must be <= the mean delay (delays cannot be negative), got {self.delay_spread}",
            )
        try:
            self.hdv.equilibrium_spacing(self.v_star)
        except ConfigError as err:
            raise ConfigError("system.v_star", err.message) from None
        allowed = MODEL_PARAMS[self.hdv.name]
        for key, w in self.heterogeneity.items():
            if key not in allowed:
                raise ConfigError(
                    f"scenario.heterogeneity.{key}",
                    f"not a parameter of the {self.hdv.name} model; allowed: {list(allowed)}",
                )
            _num(f"scenario.heterogeneity.{key}", w, lo=0.0)
        for key in self.hdv_values or {}:
            if key not in allowed:
                raise ConfigError(
                    f"scenario.hdv_values.{key}",
                    f"not a parameter of the {self.hdv.name} model; allowed: {list(allowed)}",
                )

    @property
    def steps(self) -> int:
        """Number of samples."""
        return int(round(self.duration / self.dt))

    @property
    def n_vehicles(self) -> int:
        return self.m + self.n + 2

    @property
    def cav(self) -> int:
        return self.m + 1

    @property
    def s_star(self) -> float:
        """Nominal equilibrium spacing."""
        return float(self.hdv.equilibrium_spacing(self.v_star))

    def times(self) -> np.ndarray:
        """Sample times ``t_start + k dt``."""
        return self.t_start + self.dt * np.arange(self.steps)

    def is_hdv(self) -> np.ndarray:
        """``(nv,)`` mask of the HDV columns (not head, not CAV)."""
        mask = np.ones(self.n_vehicles, dtype=bool)
        mask[0] = False
        mask[self.cav] = False
        return mask

    def draw(self) -> Draws:
        """Per-scenario HDV parameters, delays and initial state (deterministic in ``seed``)."""
        B, nv = self.batch, self.n_vehicles
        names = MODEL_PARAMS[self.hdv.name]
        hdv_mask = self.is_hdv()
        values = {}
        for key in names:
            base = getattr(self.hdv, key)
            if self.hdv_values and key in self.hdv_values:
                try:
                    base = np.broadcast_to(
                        np.asarray(self.hdv_values[key], dtype=float), (B, nv)
                    )
                except ValueError:
                    raise ConfigError(
                        f"scenario.hdv_values.{key}", f"must broadcast to (batch, nv) = {(B, nv)}"
                    ) from None
            values[key] = np.array(np.broadcast_to(base, (B, nv)), dtype=float)
        delays = np.array(np.broadcast_to(np.asarray(self.delay, float), (B, nv)), dtype=float)
        rngs = [np.random.default_rng([self.seed, self.first_index + b]) for b in range(B)]
        for key in names:
            w = float(self.heterogeneity.get(key, 0.0))
            if w > 0:
                draws = np.stack([r.uniform(-w, w, nv) for r in rngs])
                values[key] = np.where(hdv_mask, values[key] + draws, values[key])
        if self.delay_spread > 0:
            draws = np.stack([r.uniform(-self.delay_spread, self.delay_spread, nv) for r in rngs])
            delays = delays + draws
        delays = np.where(hdv_mask, np.maximum(delays, 0.0), 0.0)
        # the head and the CAV follow no HDV law: nominal values there
        for key in names:
            values[key][:, ~hdv_mask] = getattr(self.hdv, key)
        try:
            model = _MODEL_CLASS[self.hdv.name](**values)
            s_eq = np.broadcast_to(model.equilibrium_spacing(self.v_star), (B, nv)).copy()
        except ConfigError as err:
            raise ConfigError(
                f"scenario.heterogeneity.{err.field}", f"a drawn HDV is invalid: {err.message}"
            ) from None
        s_eq[:, 0] = np.nan
        s_eq[:, self.cav] = self.s_star
        return Draws(values, delays, s_eq)


@dataclass(frozen=True)
class Draws:
    """The random (or explicit) per-vehicle quantities of a batch.

    Attributes
    ----------
    hdv_values : dict of str to numpy.ndarray
        Each model parameter, ``(batch, nv)``.
    delay : numpy.ndarray
        Reaction delay (s) before rounding to steps, ``(batch, nv)`` (0 for head and CAV).
    initial_spacing : numpy.ndarray
        ``(batch, nv)`` initial spacing (each HDV's own equilibrium at ``v*``, the CAV at the
        nominal ``s*``; NaN for the head).
    """

    hdv_values: dict[str, np.ndarray]
    delay: np.ndarray
    initial_spacing: np.ndarray


# --------------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------------


@dataclass
class SimResult:
    """Trajectories of a batch of runs with one controller.

    Attributes
    ----------
    t : numpy.ndarray
        ``(T,)`` recorded sample times.
    position, velocity, acceleration, spacing : numpy.ndarray
        ``(batch, T, n_vehicles)``, columns head, HDVs ahead, CAV, HDVs behind. ``acceleration``
        is the applied one (after limits, emergency braking, perturbations); ``spacing[..., 0]``
        is NaN. After a collision every later sample of that scenario is NaN.
    u_cmd : numpy.ndarray
        ``(batch, T)`` CAV command before limits and emergency braking (held between samples).
    aeb_active : numpy.ndarray
        ``(batch, T)`` bool, the CAV's emergency braking overrode the command.
    collided, collision_time : numpy.ndarray
        ``(batch, n_vehicles)``: vehicle reached spacing <= 0, and when (NaN if never).
    m, n, cav : int
        Layout and the CAV's column.
    v_star, s_star : numpy.ndarray
        ``(batch,)`` nominal equilibrium.
    controller, controller_info, controller_stats
        Name, ``describe()`` and ``stats()`` of the controller.
    dt, sim_dt : float
        Spacing of the recorded samples and simulation step.
    scenario, draws
        What was simulated (per-vehicle parameters, delays, initial spacings).
    wall_time : float
        Seconds spent in :func:`simulate`.
    """

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    spacing: np.ndarray
    u_cmd: np.ndarray
    aeb_active: np.ndarray
    collided: np.ndarray
    collision_time: np.ndarray
    m: int
    n: int
    cav: int
    v_star: np.ndarray
    s_star: np.ndarray
    controller: str
    controller_info: dict[str, Any]
    controller_stats: dict[str, Any]
    dt: float
    sim_dt: float
    scenario: Scenario | None = None
    draws: Draws | None = None
    wall_time: float = 0.0

    @property
    def batch(self) -> int:
        return self.position.shape[0]

    @property
    def n_vehicles(self) -> int:
        return self.position.shape[2]

    def vehicle_labels(self) -> list[str]:
        """``head, -m, ..., -1, CAV, 1, ..., n``."""
        return ["head", *[str(i) for i in range(-self.m, 0)], "CAV"] + [
            str(i) for i in range(1, self.n + 1)
        ]


# --------------------------------------------------------------------------------------------
# Compiled kernels
# --------------------------------------------------------------------------------------------

_NAN = np.nan


@numba.njit(cache=True, inline="always")
def _mix(x):
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@numba.njit(cache=True, inline="always")
def _u01(seed, b, j, k, ch):
    """Counter-based uniform in (0, 1): the same draw for (seed, b, j, k, ch) on any thread."""
    x = _mix(np.uint64(seed) + np.uint64(0x9E3779B97F4A7C15))
    x = _mix(x ^ np.uint64(b))
    x = _mix(x ^ (np.uint64(j) + np.uint64(0x632BE59BD9B4E019)))
    x = _mix(x ^ np.uint64(k))
    x = _mix(x ^ np.uint64(ch))
    return (float(x >> np.uint64(11)) + 0.5) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True, inline="always")
def _normal(seed, b, j, k, ch):
    u1 = _u01(seed, b, j, k, ch)
    u2 = _u01(seed, b, j, k, ch + 1)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@numba.njit(cache=True, inline="always")
def _hdv_accel(code, pr, s, ds, v):
    """OVM (code 0) or IDM (code 1) acceleration; mirrors hdv.ovm_accel / hdv.idm_accel."""
    return _hdv_accel6(code, pr[0], pr[1], pr[2], pr[3], pr[4], pr[5], s, ds, v)


@numba.njit(cache=True, inline="always")
def _hdv_accel6(code, p0, p1, p2, p3, p4, p5, s, ds, v):
    """:func:`_hdv_accel` with the six parameters as scalars (no array view in the loop)."""
    if code == 0:
        sc = min(max(s, p2), p3)
        vd = 0.5 * p4 * (1.0 - math.cos(math.pi * (sc - p2) / (p3 - p2)))
        return p0 * (vd - v) + p1 * ds
    v0, T, s0, a, b, delta = p0, p1, p2, p3, p4, p5
    vp = max(v, 0.0)
    s_des = s0 + max(vp * T - vp * ds / (2.0 * math.sqrt(a * b)), 0.0)
    return a * (1.0 - (vp / v0) ** delta - (s_des / max(s, 1e-3)) ** 2)


@numba.njit(cache=True, inline="always")
def _eq_spacing(code, pr, v):
    """Equilibrium spacing at ``v``; mirrors OVM / IDM ``equilibrium_spacing``."""
    if code == 0:
        return pr[2] + (pr[3] - pr[2]) / math.pi * math.acos(1.0 - 2.0 * v / pr[4])
    return (pr[2] + v * pr[1]) / math.sqrt(1.0 - (v / pr[0]) ** pr[5])


@numba.njit(cache=True)
def _observe(b, k, p, v, hp, hv, L, lat, loss, noise, seed, sid0, cav, obs_s, obs_v, obs_p):
    """Update the CAV's received values of scenario ``b`` at sample ``k`` (V2V model)."""
    nv = p.shape[1]
    for j in range(nv):
        if j == cav:
            obs_p[b, j] = p[b, j]
            obs_v[b, j] = v[b, j]
            obs_s[b, j] = p[b, j - 1] - p[b, j]
            continue
        if loss[j] > 0.0 and _u01(seed, sid0 + b, j, k, 2) < loss[j]:
            continue  # packet lost: hold the last value
        if lat == 0:
            pj = p[b, j]
            vj = v[b, j]
            sj = p[b, j - 1] - p[b, j] if j > 0 else _NAN
        else:
            slot = (k - lat + L) % L
            pj = hp[slot, b, j]
            vj = hv[slot, b, j]
            sj = hp[slot, b, j - 1] - hp[slot, b, j] if j > 0 else _NAN
        if noise[0] > 0.0 and j > 0:
            sj += noise[0] * _normal(seed, sid0 + b, j, k, 3)
        if noise[1] > 0.0:
            vj += noise[1] * _normal(seed, sid0 + b, j, k, 5)
        if noise[2] > 0.0:
            pj += noise[2] * _normal(seed, sid0 + b, j, k, 7)
        obs_s[b, j] = sj
        obs_v[b, j] = vj
        obs_p[b, j] = pj


@numba.njit(cache=True, nogil=True)
def _advance(
    b0, b1, k0, k1, p, v, hp, hv, L, delay_steps, delay_own, code, params, nom_code,
    nom_params, dt, t_start, a_min, a_max, cav, cav_aeb, hdv_aeb, noise_std, seed, sid0,
    acc_ovr, spd_ovr, mode, ratio, u_hold, Ks, Kv, Kp, hdv_law, v_star, s_ref, p_ref,
    est_decay, v_lo, v_hi, v_hat,
    loss, lat, obs_noise, obs_s, obs_v, obs_p, alive, collided, ctime,
    stride, out_p, out_v, out_a, out_s, out_u, out_aeb,
):  # fmt: skip
    """Advance scenarios ``b0 .. b1 - 1`` from sample ``k0`` to ``k1`` (exclusive).

    Releases the GIL: disjoint scenario ranges run on several threads at once.

    ``mode`` 1 evaluates the linear law (Ks, Kv, Kp, hdv_law) at every ``ratio``-th sample;
    mode 0 applies the held command ``u_hold`` (set by a Python controller). ``est_decay >= 0``
    takes the law's errors from the equilibrium estimate ``v_hat`` (``(batch,)``, updated in
    place; see :class:`~lcc_synth.controllers.static.LinearLaw`), ``est_decay < 0`` from ``v_star``.
    """
    nv = p.shape[1]
    abs_min = abs(a_min)
    acc = np.empty(nv)
    for b in range(b0, b1):
        for k in range(k0, k1):
            rec = k % stride == 0
            r = k // stride
            if not alive[b]:
                if rec:
                    for j in range(nv):
                        out_p[b, r, j] = _NAN
                        out_v[b, r, j] = _NAN
                        out_a[b, r, j] = _NAN
                        out_s[b, r, j] = _NAN
                    out_u[b, r] = _NAN
                continue
            t = t_start + k * dt
            if L > 1:
                slot = k % L
                for j in range(nv):
                    hp[slot, b, j] = p[b, j]
                    hv[slot, b, j] = v[b, j]
            hit = False
            for j in range(1, nv):
                if p[b, j - 1] - p[b, j] <= 0.0:
                    collided[b, j] = True
                    ctime[b, j] = t
                    hit = True
            if rec:
                out_s[b, r, 0] = _NAN
                for j in range(nv):
                    out_p[b, r, j] = p[b, j]
                    out_v[b, r, j] = v[b, j]
                    if j > 0:
                        out_s[b, r, j] = p[b, j - 1] - p[b, j]
            if hit:
                alive[b] = False
                if rec:
                    for j in range(nv):
                        out_a[b, r, j] = _NAN
                    out_u[b, r] = _NAN
                continue
            # ---- CAV command (sampled, zero-order hold) ----
            if mode == 1 and k % ratio == 0:
                _observe(b, k, p, v, hp, hv, L, lat, loss, obs_noise, seed, sid0, cav,
                         obs_s, obs_v, obs_p)  # fmt: skip
                u = 0.0
                if hdv_law:
                    u = _hdv_accel(
                        nom_code, nom_params, obs_s[b, cav],
                        obs_v[b, cav - 1] - obs_v[b, cav], obs_v[b, cav],
                    )  # fmt: skip
                ve = v_star[b]
                sh = 0.0
                if est_decay >= 0.0:
                    ve = min(max(v_hat[b], v_lo), v_hi)
                    sh = _eq_spacing(nom_code, nom_params, ve) - _eq_spacing(
                        nom_code, nom_params, v_star[b]
                    )
                    y = obs_v[b, cav - 1]
                    v_hat[b] = y + (v_hat[b] - y) * est_decay
                for j in range(1, nv):
                    if Ks[j] != 0.0:
                        u += Ks[j] * (obs_s[b, j] - (s_ref[b, j] + sh))
                for j in range(nv):
                    if Kv[j] != 0.0:
                        u += Kv[j] * (obs_v[b, j] - ve)
                if Kp != 0.0:
                    u -= Kp * (obs_p[b, cav] - p_ref[b] - v_star[b] * (t - t_start))
                u_hold[b] = u
            aeb = False
            # ---- accelerations ----
            for j in range(nv):
                if j == 0:
                    a = 0.0
                elif j == cav:
                    a = min(max(u_hold[b], a_min), a_max)
                    if cav_aeb:
                        s0 = p[b, j - 1] - p[b, j]
                        if (v[b, j] ** 2 - v[b, j - 1] ** 2) / (2.0 * s0) >= abs_min:
                            a = a_min
                            aeb = True
                else:
                    d = delay_steps[b, j]
                    if d == 0:
                        s = p[b, j - 1] - p[b, j]
                        ds = v[b, j - 1] - v[b, j]
                        vv = v[b, j]
                    else:
                        sl = (k - d + L) % L
                        s = hp[sl, b, j - 1] - hp[sl, b, j]
                        ds = hv[sl, b, j - 1] - hv[sl, b, j]
                        vv = hv[sl, b, j] if delay_own else v[b, j]
                    a = _hdv_accel6(
                        code, params[b, j, 0], params[b, j, 1], params[b, j, 2],
                        params[b, j, 3], params[b, j, 4], params[b, j, 5], s, ds, vv,
                    )  # fmt: skip
                    if noise_std > 0.0:
                        a += noise_std * _normal(seed, sid0 + b, j, k, 0)
                    a = min(max(a, a_min), a_max)
                    if hdv_aeb:
                        s = p[b, j - 1] - p[b, j]
                        if (v[b, j] ** 2 - v[b, j - 1] ** 2) / (2.0 * s) >= abs_min:
                            a = a_min
                ov = acc_ovr[k, j]
                if ov == ov:
                    a = ov
                    if j == cav:
                        aeb = False
                sv = spd_ovr[k, j]
                if sv == sv:
                    a = min(max((sv - v[b, j]) / dt, a_min), a_max)
                    if j == cav:
                        aeb = False
                if v[b, j] + dt * a < 0.0:
                    a = -v[b, j] / dt
                acc[j] = a
            if rec:
                for j in range(nv):
                    out_a[b, r, j] = acc[j]
                out_u[b, r] = u_hold[b]
                out_aeb[b, r] = aeb
            for j in range(nv):
                p[b, j] += dt * v[b, j]
                v[b, j] += dt * acc[j]


@numba.njit(cache=True)
def _observe_all(
    k, p, v, hp, hv, L, lat, loss, noise, seed, sid0, cav, obs_s, obs_v, obs_p, alive
):
    B = p.shape[0]
    nv = p.shape[1]
    if L > 1:
        slot = k % L
        for b in range(B):
            for j in range(nv):
                hp[slot, b, j] = p[b, j]
                hv[slot, b, j] = v[b, j]
    for b in range(B):
        if alive[b]:
            _observe(b, k, p, v, hp, hv, L, lat, loss, noise, seed, sid0, cav, obs_s, obs_v, obs_p)


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------


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
    wall0 = time.perf_counter()
    sc = scenario
    B, nv, T, dt = sc.batch, sc.n_vehicles, sc.steps, sc.dt
    cav = sc.cav
    draws = sc.draw() if draws is None else draws
    t = sc.times()

    # initial state: equilibrium cruise, head at p = 0
    s0 = np.nan_to_num(draws.initial_spacing, nan=0.0)
    p = -np.cumsum(s0, axis=1)
    v = np.full((B, nv), float(sc.v_star))

    # delays / latency ring buffer (history before t_start: the equilibrium cruise)
    delay_steps = np.rint(draws.delay / dt).astype(np.int64)
    lat = _steps_of(sc.v2v.latency, dt, "scenario.v2v.latency", multiple=False)
    L = int(max(int(delay_steps.max(initial=0)), lat)) + 1
    if L > 1:
        back = np.arange(L)  # steps before the first sample
        slots = (-back) % L
        hp = np.empty((L, B, nv))
        hv = np.empty((L, B, nv))
        hp[slots] = p[None] - (back * dt)[:, None, None] * v[None]
        hv[slots] = v[None]
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

    acc_ovr, spd_ovr = overrides(sc.perturbations, t, dt, sc.m, sc.n)

    v_star = np.full(B, float(sc.v_star))
    s_star = np.full(B, sc.s_star)
    if sc.spacing_reference == "own_equilibrium":
        s_ref = draws.initial_spacing.copy()
        s_ref[:, 0] = s_star
    else:
        s_ref = np.repeat(s_star[:, None], nv, axis=1)
    ctx = ControlContext(
        sc.m, sc.n, B, dt, v_star, s_star, sc.a_min, sc.a_max, sc.hdv, s_ref=s_ref.copy()
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
    p_ref = p[:, cav].copy()

    stride = sc.record_every
    Tr = (T - 1) // stride + 1
    out_p = np.empty((B, Tr, nv))
    out_v = np.empty((B, Tr, nv))
    out_a = np.empty((B, Tr, nv))
    out_s = np.empty((B, Tr, nv))
    out_u = np.empty((B, Tr))
    out_aeb = np.zeros((B, Tr), dtype=np.bool_)
    alive = np.ones(B, dtype=np.bool_)
    collided = np.zeros((B, nv), dtype=np.bool_)
    ctime = np.full((B, nv), np.nan)
    u_hold = np.zeros(B)

    v_hat = v_star.copy()
    est = (-1.0, 0.0, 0.0)  # (decay, v_lo, v_hi); decay < 0: errors from the fixed v*
    if law is not None and law.equilibrium_decay is not None:
        est = (float(law.equilibrium_decay), *map(float, law.v_bounds))

    def advance_range(b0, b1, k0, k1, mode, Ks, Kv, Kp, hdv_law):
        _advance(
            b0, b1, k0, k1, p, v, hp, hv, L, delay_steps, sc.delay_model == "full", code,
            params, code, nom_params,
            float(dt), float(sc.t_start), float(sc.a_min), float(sc.a_max), cav,
            bool(sc.cav_aeb), bool(sc.hdv_aeb), float(sc.hdv_accel_noise), int(sc.seed),
            int(sc.first_index),
            acc_ovr, spd_ovr, mode, ratio, u_hold, Ks, Kv, float(Kp), bool(hdv_law),
            v_star, s_ref, p_ref, est[0], est[1], est[2], v_hat,
            loss, lat, obs_noise, obs_s, obs_v, obs_p,
            alive, collided, ctime, stride, out_p, out_v, out_a, out_s, out_u, out_aeb,
        )  # fmt: skip

    n_threads = _threads(B, (T if law is not None else ratio) * nv)

    def advance(k0, k1, mode, Ks, Kv, Kp, hdv_law):
        if n_threads == 1:
            advance_range(0, B, k0, k1, mode, Ks, Kv, Kp, hdv_law)
            return
        edges = np.linspace(0, B, n_threads + 1).astype(int)
        futures = [
            _executor().submit(advance_range, b0, b1, k0, k1, mode, Ks, Kv, Kp, hdv_law)
            for b0, b1 in zip(edges[:-1], edges[1:], strict=True)
        ]
        for f in futures:
            f.result()

    if law is not None:
        Ks = np.ascontiguousarray(law.Ks, dtype=float)
        Kv = np.ascontiguousarray(law.Kv, dtype=float)
        if Ks.shape != (nv,) or Kv.shape != (nv,) or Ks[0] != 0.0:
            raise ConfigError(
                f"controllers.{controller.name}",
                f"linear law needs {nv} spacing and velocity gains, none on the head's spacing",
            )
        advance(0, T, 1, Ks, Kv, law.Kp, law.hdv_law)
    else:
        zeros = np.zeros(nv)
        for k0 in range(0, T, ratio):
            _observe_all(k0, p, v, hp, hv, L, lat, loss, obs_noise, int(sc.seed),
                         int(sc.first_index), cav,
                         obs_s, obs_v, obs_p, alive)  # fmt: skip
            tk = float(t[k0])
            obs = Observation(tk, obs_s.copy(), obs_v.copy(), obs_p.copy())
            u = np.asarray(controller(obs), dtype=float).reshape(-1)
            if u.shape != (B,):
                raise RuntimeError(
                    f"controller {controller.name!r} returned shape {u.shape}, expected ({B},)"
                )
            bad = alive & ~np.isfinite(u)
            if bad.any():
                raise RuntimeError(
                    f"controller {controller.name!r} returned a non-finite command at t = {tk:g} s "
                    f"for scenario(s) {np.flatnonzero(bad).tolist()}"
                )
            u_hold[:] = np.where(alive, u, 0.0)
            advance(k0, min(k0 + ratio, T), 0, zeros, zeros, 0.0, False)

    return SimResult(
        t=t[::stride].copy(),
        position=out_p,
        velocity=out_v,
        acceleration=out_a,
        spacing=out_s,
        u_cmd=out_u,
        aeb_active=out_aeb,
        collided=collided,
        collision_time=ctime,
        m=sc.m,
        n=sc.n,
        cav=cav,
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
    """Run several controllers on the same draws; returns ``{name: SimResult}`` in order."""
    items = controllers.items() if isinstance(controllers, Mapping) else (
        (c.name, c) for c in controllers
    )
    draws = scenario.draw()
    return {name: simulate(scenario, ctrl, draws) for name, ctrl in items}
