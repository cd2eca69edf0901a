"""The field's own CAV controllers, as baselines: FollowerStopper and PI with saturation (Stern
et al., 2018), constant time-gap ACC and CACC (Ploeg et al., 2011).

Each is a :class:`~lcc_synth.controllers.base.Controller` that reads only what a vehicle's own
sensors (and, for CACC, its V2V link to the vehicle ahead) give: the gap ``dx`` to the vehicle
ahead, its speed ``v_lead`` and the CAV's own speed ``v``. The pure laws are module functions
(vectorised over any array shape) so that tests check them at hand-picked points.

Sources and defaults
--------------------
* **FollowerStopper** (Stern et al., "Dissipation of stop-and-go waves via control of autonomous
  vehicles: Field experiments", Transportation Research Part C 89, 2018, Sec. 3.1): three
  boundaries ``dx_k = dx0_k + (dv_-)^2 / (2 d_k)``, ``dv_- = min(v_lead - v, 0)``,
  ``dx0 = (4.5, 5.25, 6.0)`` m, ``d = (1.5, 1.0, 0.5)`` m/s²; with ``w = min(max(v_lead, 0), U)``
  the command is 0 below ``dx_1``, rises linearly from 0 to ``w`` on ``[dx_1, dx_2]``, from
  ``w`` to ``U`` on ``[dx_2, dx_3]`` and is ``U`` above ``dx_3``. ``U`` (the target speed) has
  no published default: it is the experiment's set speed; we require it.
* **PI with saturation** (same paper, Sec. 3.2): ``U`` is the mean of the AV's own speed over
  the last ``window = 38`` s; ``v_target = U + v_catch clip((dx - g_l) / (g_u - g_l), 0, 1)``
  with ``g_l = 7`` m, ``g_u = 30`` m, ``v_catch = 1`` m/s; ``alpha = clip((dx - dx_s) / gamma,
  0, 1)`` with ``dx_s = max(2 (v_lead - v), 4)`` m and ``gamma = 2`` m; ``beta = 1 - alpha / 2``;
  ``v_cmd <- beta (alpha v_target + (1 - alpha) v_lead) + (1 - beta) v_cmd``. The command
  starts at the AV's speed.
* **ACC**: ``a = k_s (dx - s0 - h v) + k_v (v_lead - v)`` with Milanés & Shladover's fitted
  production-ACC gains ("Modeling cooperative and autonomous adaptive cruise control dynamic
  responses using experimental data", Transportation Research Part C 48, 2014):
  ``k_s = 0.23`` s⁻², ``k_v = 0.07`` s⁻¹, time gap ``h = 1.1`` s (their shortest ACC setting);
  the standstill gap ``s0 = 2`` m is ours (the paper measures the gap bumper to bumper with no
  standstill term).
* **CACC** (Ploeg, Scheepers, van Nunen, van de Wouw, Nijmeijer, "Design and experimental
  evaluation of cooperative adaptive cruise control", IEEE ITSC 2011): spacing error
  ``e = dx - (r + h v)``, controller ``h du/dt = -u + k_p e + k_d de/dt + u_lead`` with the
  preceding vehicle's acceleration ``u_lead`` fed forward over V2V; ``h = 0.7`` s,
  ``k_p = 0.2`` s⁻², ``k_d = 0.7`` s⁻¹ (their experiment), standstill distance ``r = 2`` m.
  ``de/dt = (v_lead - v) - h a`` with ``a`` the CAV's last command; ``u_lead`` is the change of
  the received speed of the vehicle ahead over one controller period (so V2V loss, latency and
  noise act on it as on every received value). Discretised by forward Euler at the controller
  period ``T`` (``T < h``).

From velocity to acceleration
-----------------------------
FollowerStopper and PI with saturation command a *velocity*. As the published implementations
(Flow's velocity controllers; the field experiment's low-level speed loop) do, the CAV tracks
the command within one controller period: ``a = (v_cmd - v) / T``, which the simulator then
clips to ``[a_min, a_max]`` and overrides by emergency braking; ``T`` is ``sample_time`` or,
when absent, the simulation step.

Gaps: ``dx = spacing - length``, ``length`` (m, default 0) being the vehicle length the
simulator's front-to-front spacing includes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from lcc_synth.controllers.base import ControlContext, Observation
from lcc_synth.errors import ConfigError
from lcc_synth.models.records import Record

__all__ = [
    "follower_stopper_velocity",
    "pi_saturation_step",
    "acc_accel",
    "cacc_step",
    "FollowerStopperParams",
    "PISaturationParams",
    "ACCParams",
    "CACCParams",
    "BaselineController",
    "BASELINE_TYPES",
]


def _positive(field: str, value: float, allow_zero: bool = False) -> float:
    x = float(value)
    ok = math.isfinite(x) and (x >= 0 if allow_zero else x > 0)
    if not ok:
        raise ConfigError(field, f"must be {'>= 0' if allow_zero else '> 0'}, got {value!r}")
    return x


# --------------------------------------------------------------------------------------------
# The laws
# --------------------------------------------------------------------------------------------


def follower_stopper_velocity(dx, v, v_lead, U, dx0=(4.5, 5.25, 6.0), d=(1.5, 1.0, 0.5)):
    """FollowerStopper's commanded velocity (Stern et al. 2018, Sec. 3.1); broadcasts."""
    dx, v, v_lead = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (dx, v, v_lead)))
    dv = np.minimum(v_lead - v, 0.0)
    x1, x2, x3 = (dx0[k] + dv**2 / (2.0 * d[k]) for k in range(3))
    w = np.minimum(np.maximum(v_lead, 0.0), U)
    ramp1 = w * (dx - x1) / (x2 - x1)
    ramp2 = w + (U - w) * (dx - x2) / (x3 - x2)
    return np.where(dx <= x1, 0.0, np.where(dx <= x2, ramp1, np.where(dx <= x3, ramp2, U)))


def pi_saturation_step(dx, v, v_lead, U, v_cmd, p: PISaturationParams):
    """One update of the PI-with-saturation command (Stern et al. 2018, Sec. 3.2); ``U`` the
    mean of the AV's speed over the window, ``v_cmd`` the previous command. Broadcasts."""
    dx, v, v_lead, U, v_cmd = (np.asarray(a, dtype=float) for a in (dx, v, v_lead, U, v_cmd))
    v_target = U + p.v_catch * np.clip((dx - p.g_l) / (p.g_u - p.g_l), 0.0, 1.0)
    dx_s = np.maximum(2.0 * (v_lead - v), p.dx_s_min)
    alpha = np.clip((dx - dx_s) / p.gamma, 0.0, 1.0)
    beta = 1.0 - 0.5 * alpha
    return beta * (alpha * v_target + (1.0 - alpha) * v_lead) + (1.0 - beta) * v_cmd


def acc_accel(dx, v, v_lead, p: ACCParams):
    """Constant time-gap ACC: ``k_s (dx - s0 - h v) + k_v (v_lead - v)``; broadcasts."""
    return p.k_s * (np.asarray(dx) - p.s0 - p.h * np.asarray(v)) + p.k_v * (
        np.asarray(v_lead) - np.asarray(v)
    )


def cacc_step(u, dx, v, v_lead, a, u_lead, T: float, p: CACCParams):
    """One forward-Euler step of Ploeg et al.'s CACC, ``h du/dt = -u + k_p e + k_d de/dt +
    u_lead``, ``e = dx - r - h v``, ``de/dt = v_lead - v - h a``; returns the new ``u``."""
    e = np.asarray(dx) - p.r - p.h * np.asarray(v)
    de = np.asarray(v_lead) - np.asarray(v) - p.h * np.asarray(a)
    return u + (T / p.h) * (-u + p.k_p * e + p.k_d * de + u_lead)


# --------------------------------------------------------------------------------------------
# Parameters (problem-file tables)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, repr=False)
class FollowerStopperParams(Record):
    """FollowerStopper: target speed ``U`` (m/s, >= 0), boundary offsets ``dx0`` (m, increasing)
    and decelerations ``d`` (m/s², > 0); defaults Stern et al. (2018)."""

    U: float
    dx0: tuple[float, float, float] = (4.5, 5.25, 6.0)
    d: tuple[float, float, float] = (1.5, 1.0, 0.5)

    def __post_init__(self) -> None:
        _positive("U", self.U, allow_zero=True)
        dx0 = tuple(float(x) for x in self.dx0)
        d = tuple(float(x) for x in self.d)
        if len(dx0) != 3 or not (0 <= dx0[0] < dx0[1] < dx0[2]):
            raise ConfigError("dx0", f"must be 3 increasing gaps >= 0 m, got {list(self.dx0)}")
        if len(d) != 3 or not all(x > 0 and math.isfinite(x) for x in d):
            raise ConfigError("d", f"must be 3 decelerations > 0 m/s², got {list(self.d)}")
        object.__setattr__(self, "dx0", dx0)
        object.__setattr__(self, "d", d)


@dataclass(frozen=True, repr=False)
class PISaturationParams(Record):
    """PI with saturation; defaults Stern et al. (2018): averaging ``window`` (s), gaps
    ``g_l < g_u`` (m), ``v_catch`` (m/s), ``gamma`` (m), the floor ``dx_s_min`` of ``dx_s``
    (m)."""

    window: float = 38.0
    g_l: float = 7.0
    g_u: float = 30.0
    v_catch: float = 1.0
    gamma: float = 2.0
    dx_s_min: float = 4.0

    def __post_init__(self) -> None:
        for key in ("window", "gamma"):
            _positive(key, getattr(self, key))
        for key in ("g_l", "v_catch", "dx_s_min"):
            _positive(key, getattr(self, key), allow_zero=True)
        if not self.g_u > self.g_l:
            raise ConfigError("g_u", f"must be > g_l = {self.g_l} m, got {self.g_u}")


@dataclass(frozen=True, repr=False)
class ACCParams(Record):
    """Constant time-gap ACC; defaults Milanés & Shladover (2014): ``k_s`` (1/s², > 0),
    ``k_v`` (1/s, >= 0), time gap ``h`` (s, > 0), standstill gap ``s0`` (m, >= 0)."""

    k_s: float = 0.23
    k_v: float = 0.07
    h: float = 1.1
    s0: float = 2.0

    def __post_init__(self) -> None:
        _positive("k_s", self.k_s)
        _positive("k_v", self.k_v, allow_zero=True)
        _positive("h", self.h)
        _positive("s0", self.s0, allow_zero=True)


@dataclass(frozen=True, repr=False)
class CACCParams(Record):
    """Ploeg et al. (2011) CACC: time gap ``h`` (s, > 0), gains ``k_p`` (1/s², > 0) and ``k_d``
    (1/s, >= 0), standstill distance ``r`` (m, >= 0)."""

    h: float = 0.7
    k_p: float = 0.2
    k_d: float = 0.7
    r: float = 2.0

    def __post_init__(self) -> None:
        _positive("h", self.h)
        _positive("k_p", self.k_p)
        _positive("k_d", self.k_d, allow_zero=True)
        _positive("r", self.r, allow_zero=True)


#: Controller ``type`` -> its parameter dataclass.
BASELINE_TYPES = {
    "follower_stopper": FollowerStopperParams,
    "pi_saturation": PISaturationParams,
    "acc": ACCParams,
    "cacc": CACCParams,
}


# --------------------------------------------------------------------------------------------
# The controller
# --------------------------------------------------------------------------------------------


class BaselineController:
    """One of :data:`BASELINE_TYPES` driving every CAV of the run (each from its own gap).

    Parameters
    ----------
    name : str
    kind : str
        A key of :data:`BASELINE_TYPES`.
    params : dataclass
        The matching parameters.
    sample_time : float, optional
        Controller period (s); default every simulation step.
    length : float
        Vehicle length (m) subtracted from the simulator's spacing to get the gap.
    """

    def __init__(
        self, name: str, kind: str, params, sample_time: float | None = None, length: float = 0.0
    ):
        if kind not in BASELINE_TYPES:
            raise ConfigError("type", f"must be one of {sorted(BASELINE_TYPES)}, got {kind!r}")
        if not isinstance(params, BASELINE_TYPES[kind]):
            raise ConfigError("params", f"{kind} needs {BASELINE_TYPES[kind].__name__}")
        if sample_time is not None:
            _positive("sample_time", sample_time)
        if kind == "cacc" and sample_time is not None and sample_time >= params.h:
            raise ConfigError(
                "sample_time", f"must be < h = {params.h} s for CACC's Euler step, got "
                f"{sample_time}",
            )  # fmt: skip
        self.name = name
        self.kind = kind
        self.params = params
        self.sample_time = sample_time
        self.length = _positive("length", length, allow_zero=True)
        self._ctx: ControlContext | None = None

    def reset(self, ctx: ControlContext) -> None:
        """Allocate the per-scenario state (PI window, CACC state, last commands)."""
        self._ctx = ctx
        self._cavs = np.asarray(getattr(ctx, "cavs", (ctx.cav,)), dtype=int)
        # the vehicle ahead: the previous column (on a ring, column 0 follows the last one)
        self._lead = np.where(self._cavs > 0, self._cavs - 1, ctx.n_vehicles - 1)
        self._T = float(self.sample_time or ctx.dt)
        shape = (ctx.batch, self._cavs.size)
        self._v_cmd = None
        self._u = np.zeros(shape)
        self._a_last = np.zeros(shape)
        self._v_lead_last = None
        k = max(1, int(round(getattr(self.params, "window", 0.0) / self._T)))
        self._hist = np.full((k, *shape), np.nan)
        self._count = 0
        self._calls = 0

    def __call__(self, obs: Observation) -> np.ndarray:
        """Commanded acceleration of every CAV: ``(batch,)`` for one, ``(batch, n_cav)``."""
        v = obs.velocity[:, self._cavs]
        v_lead = obs.velocity[:, self._lead]
        dx = obs.spacing[:, self._cavs] - self.length
        p, T = self.params, self._T
        if self.kind == "follower_stopper":
            a = (follower_stopper_velocity(dx, v, v_lead, p.U, p.dx0, p.d) - v) / T
        elif self.kind == "pi_saturation":
            if self._v_cmd is None:
                self._v_cmd = v.copy()
            self._hist[self._count % self._hist.shape[0]] = v
            self._count += 1
            U = np.nanmean(self._hist, axis=0)
            self._v_cmd = pi_saturation_step(dx, v, v_lead, U, self._v_cmd, p)
            a = (self._v_cmd - v) / T
        elif self.kind == "acc":
            a = acc_accel(dx, v, v_lead, p)
        else:
            u_lead = (
                np.zeros_like(v) if self._v_lead_last is None else (v_lead - self._v_lead_last) / T
            )
            self._v_lead_last = v_lead.copy()
            self._u = cacc_step(self._u, dx, v, v_lead, self._a_last, u_lead, T, p)
            a = self._u.copy()
        ctx = self._ctx
        a = np.clip(a, ctx.a_min, ctx.a_max)
        self._a_last = a
        self._calls += 1
        return a[:, 0] if self._cavs.size == 1 else a

    def describe(self) -> dict[str, Any]:
        """Type, parameters, period and vehicle length (JSON-serialisable)."""
        return {"type": self.kind, "params": self.params.as_dict(),
                "sample_time": self.sample_time, "length": self.length}  # fmt: skip

    def toml_table(self) -> dict[str, Any]:
        """The ``[controllers.NAME]`` table that builds this controller."""
        params = {k: list(v) if isinstance(v, tuple) else v
                  for k, v in self.params.as_dict().items()}  # fmt: skip
        return {"type": self.kind, **params, "sample_time": self.sample_time,
                "length": self.length}  # fmt: skip

    def as_dict(self) -> dict[str, Any]:
        """Name and :meth:`BaselineController.describe`."""
        return {"name": self.name, **self.describe()}

    def stats(self) -> dict[str, Any]:
        """Number of controller samples of the last run."""
        return {"samples": self._calls}

