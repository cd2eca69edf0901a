"""Controllers with a fixed linear law: the CAV driving as an HDV, and static gains (eq. 23).

The simulator evaluates their :class:`LinearLaw` inside its compiled loop (no Python call per
step); ``__call__`` evaluates the same law for any other caller.

Several CAVs (a mixed platoon or a ring): :class:`HDVController` drives every CAV with its own
HDV law (its slot's parameters), and the one :class:`StaticGainController` applies one row of
a :class:`~lcc_synth.models.feedback.Gains` per CAV (``PlatoonGainController`` is another name
of the same class). Gains of a platoon or ring are on the platoon model's states ``s_i, v_i``
of positions ``i``: position ``i`` is array column ``i`` of an open platoon and ``i - 1`` on a
ring, and every spacing error is taken from that vehicle's own equilibrium spacing at ``v*``
(the model linearises each vehicle at its own equilibrium).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from lcc_synth.controllers.base import ControlContext, Observation
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import PAPER_CAVS
from lcc_synth.models.hdv import free_speed

__all__ = [
    "LinearLaw", "HDVController", "StaticGainController", "PlatoonGainController", "EQUILIBRIA",
]

#: Equilibrium options of the static-gain controllers (see :class:`StaticGainController`).
EQUILIBRIA = ("fixed", "estimated")


@dataclass(frozen=True)
class LinearLaw:
    """A CAV command that is a fixed function of the observation (no internal state).

    ``u = [F_hdv(s_0, v_-1 - v_0, v_0) if hdv_law] + sum_j Ks[j] (s_j - s_ref_j)
    + sum_j Kv[j] (v_j - v*) + Kp * (-(p_0 - p_0(t_0) - v* (t - t_0)))``
    with the nominal HDV model ``F_hdv`` of the :class:`ControlContext` and ``t_0`` the first
    sample. Arrays are indexed by vehicle column (head = 0); with several CAVs ``Ks``, ``Kv``
    are ``(n_cav, n_vehicles)`` and ``Kp`` ``(n_cav,)``, one row per CAV (a single row, e.g.
    the HDV law's zeros, applies to every CAV), and ``F_hdv`` is each CAV's own HDV law
    (``ControlContext.cav_models``). The simulator evaluates this law
    inside its compiled loop (no Python call per step); ``__call__`` evaluates the same law.

    With ``equilibrium_decay`` set (the only state of the law), ``v*`` above is replaced by an
    estimate ``w`` clipped to ``v_bounds``, and every ``s_ref_j`` is shifted by
    ``s_e(w) - s_e(v*)`` (``s_e`` the nominal model's equilibrium spacing). ``w`` starts at the
    nominal ``v*``; after each controller sample, which uses the current ``w``, it moves
    towards the observed velocity ``y`` of the vehicle right ahead of the CAV:
    ``w <- y + (w - y) * equilibrium_decay``, the exact discretisation of ``tau dw/dt = y - w``
    with ``y`` held over the sample period ``Ts`` (``equilibrium_decay = exp(-Ts / tau)``).

    With ``measurement_filter = tau_f > 0`` (s; 0 = off) the law reads, in place of every
    received spacing and velocity ``y`` (every vehicle but the CAV, whose own spacing, velocity
    and position are exact), a first-order low-pass ``y_f`` of it,
    ``tau_f dy_f/dt = y - y_f``, discretised exactly with ``y`` held over the sample period:
    each controller sample uses the current ``y_f``, then ``y_f <- y + (y_f - y) * d``,
    ``d = exp(-Ts / tau_f)`` (:meth:`measurement_decay`); ``y_f`` starts at the first value
    received. Everything the law computes from those values (the HDV law's relative speed,
    the gains, the equilibrium estimate) uses ``y_f``.
    """

    Ks: np.ndarray
    Kv: np.ndarray
    Kp: float | np.ndarray = 0.0
    hdv_law: bool = False
    equilibrium_decay: float | None = None
    v_bounds: tuple[float, float] = (0.0, float("inf"))
    measurement_filter: float = 0.0

    def measurement_decay(self, ts: float) -> float | None:
        """``exp(-ts / measurement_filter)`` per sample period ``ts``; ``None`` when off."""
        if self.measurement_filter <= 0.0:
            return None
        return math.exp(-ts / self.measurement_filter)


def _law_from_gains(gains, m: int, n: int) -> LinearLaw:
    nv = m + n + 2
    Ks = np.zeros(nv)
    Kv = np.zeros(nv)
    Kp = 0.0
    for name, value in gains.gains.items():
        if name == "-p_0":
            Kp += value
            continue
        kind, idx = name.split("_", 1)
        col = int(idx) + m + 1
        (Ks if kind == "s" else Kv)[col] += value
    return LinearLaw(Ks, Kv, Kp, gains.semantics == "added")


class _LinearController(ABC):
    """Shared evaluation of a :class:`LinearLaw` (see :class:`StaticGainController`)."""

    name: str
    sample_time: float | None

    @abstractmethod
    def _law(self, ctx: ControlContext) -> LinearLaw:
        """The linear law this controller applies in ``ctx``."""

    def reset(self, ctx: ControlContext) -> None:
        self._ctx = ctx
        self._law_cache = self._law(ctx)
        self._p_ref = None
        self._t_ref = None
        self._v_hat = np.array(ctx.v_star, dtype=float, copy=True)
        self._filtered = None  # (spacing, velocity) states of the measurement filter

    def linear_law(self, ctx: ControlContext) -> LinearLaw:
        """The law for ``ctx`` (the simulator runs it in its compiled loop)."""
        return self._law(ctx)

    def _received(self, obs: Observation) -> tuple[np.ndarray, np.ndarray]:
        """Spacings and velocities the law reads: as received, or the filter's outputs."""
        ts = self._ctx.dt if self.sample_time is None else float(self.sample_time)
        d = self._law_cache.measurement_decay(ts)
        if d is None:
            return obs.spacing, obs.velocity
        y = (obs.spacing, obs.velocity)
        if self._filtered is None:  # started at the first received values
            self._filtered = tuple(x.copy() for x in y)
        out = tuple(f.copy() for f in self._filtered)
        cols = list(self._ctx.cavs)
        for f, x in zip(out, y, strict=True):
            f[:, cols] = x[:, cols]  # the CAVs' own values: exact, unfiltered
        self._filtered = tuple(x + (f - x) * d for x, f in zip(y, self._filtered, strict=True))
        return out

    def _call_rows(self, obs: Observation) -> np.ndarray:
        """The law with one gain row per CAV (several CAVs or a ring; fixed equilibrium)."""
        ctx, law = self._ctx, self._law_cache
        spacing, velocity = self._received(obs)
        Ks, Kv = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (law.Ks, law.Kv))
        Kp = np.atleast_1d(np.asarray(law.Kp, dtype=float))
        if Ks.shape[0] == 1:
            Ks, Kv, Kp = (np.repeat(x, ctx.n_cav, axis=0) for x in (Ks, Kv, Kp))
        s_err = np.nan_to_num(spacing - ctx.spacing_reference())  # the head's: no gain
        v_err = velocity - np.asarray(ctx.v_star, dtype=float)[:, None]
        u = s_err @ Ks.T + v_err @ Kv.T
        if self._p_ref is None:
            self._p_ref = obs.position[:, list(ctx.cavs)].copy()
            self._t_ref = obs.t
        for k, c in enumerate(ctx.cavs):
            if law.hdv_law:
                a = ctx.ahead(c)
                u[:, k] += ctx.cav_models[k].accel(
                    spacing[:, c], velocity[:, a] - velocity[:, c], velocity[:, c]
                )
            if Kp[k] != 0.0:
                drift = obs.position[:, c] - self._p_ref[:, k] - ctx.v_star * (obs.t - self._t_ref)
                u[:, k] -= Kp[k] * drift
        return u[:, 0] if ctx.n_cav == 1 else u

    def __call__(self, obs: Observation) -> np.ndarray:
        ctx, law = self._ctx, self._law_cache
        if ctx.n_cav > 1 or ctx.ring or np.ndim(law.Ks) == 2:
            return self._call_rows(obs)
        cav = ctx.cav
        spacing, velocity = self._received(obs)
        vs = ctx.v_star
        s_ref = ctx.spacing_reference()
        if law.equilibrium_decay is not None:
            vs = np.clip(self._v_hat, *law.v_bounds)
            shift = ctx.hdv.equilibrium_spacing(vs) - ctx.hdv.equilibrium_spacing(ctx.v_star)
            s_ref = s_ref + np.asarray(shift, dtype=float).reshape(-1)[:, None]
            y = velocity[:, cav - 1]
            self._v_hat = y + (self._v_hat - y) * law.equilibrium_decay
        u = np.zeros(velocity.shape[0])
        if law.hdv_law:
            u += ctx.hdv.accel(
                spacing[:, cav],
                velocity[:, cav - 1] - velocity[:, cav],
                velocity[:, cav],
            )
        cols = np.flatnonzero(law.Ks)
        if cols.size:
            u += (spacing[:, cols] - s_ref[:, cols]) @ law.Ks[cols]
        cols = np.flatnonzero(law.Kv)
        if cols.size:
            u += (velocity[:, cols] - vs[:, None]) @ law.Kv[cols]
        if law.Kp != 0.0:
            if self._p_ref is None:
                self._p_ref = obs.position[:, cav].copy()
                self._t_ref = obs.t
            u += law.Kp * -(obs.position[:, cav] - self._p_ref - ctx.v_star * (obs.t - self._t_ref))
        return u

    def stats(self) -> dict[str, Any]:
        return {}


class HDVController(_LinearController):
    """The CAV drives exactly like an HDV: the nominal car-following law of the context.

    Parameters
    ----------
    name : str
    sample_time : float, optional
        Controller period (s); default every simulation step.
    """

    def __init__(self, name: str = "hdv", sample_time: float | None = None):
        self.name = name
        self.sample_time = sample_time

    def _law(self, ctx: ControlContext) -> LinearLaw:
        nv = ctx.n_vehicles
        return LinearLaw(np.zeros(nv), np.zeros(nv), 0.0, True)

    def describe(self) -> dict[str, Any]:
        return {"type": "hdv", "sample_time": self.sample_time}

    def toml_table(self) -> dict[str, Any]:
        """The ``[controllers.NAME]`` table that builds this controller."""
        return {"type": "hdv", "sample_time": self.sample_time}

    def as_dict(self) -> dict[str, Any]:
        """Name and :meth:`HDVController.describe`."""
        return {"name": self.name, **self.describe()}


class StaticGainController(_LinearController):
    """Static state feedback of eq. (23) of every CAV of a layout on its observation: the
    paper's one CAV, or row ``k`` of the gains as CAV ``cavs[k]``'s command on the platoon
    model's state errors (a platoon or ring, see the module docstring).

    Parameters
    ----------
    name : str
    gains : lcc_synth.models.feedback.Gains
        Gains keyed by state name and their semantics (``added`` keeps the CAV's nonlinear
        HDV law towards the vehicle ahead and adds the gains, plus ``kh`` times the head's
        velocity error for a platoon's rows; ``replace`` uses them alone).
    model : lcc_synth.models.linear.LCCModel or lcc_synth.models.platoon.PlatoonModel
        The linear model the gains are written for (checked: its CAVs, every name a state;
        a platoon's CAV positions and ring flag are checked against the scenario's).
    sample_time : float, optional
        Controller period (s); default every simulation step.
    equilibrium : {"fixed", "estimated"}
        The equilibrium ``(v*, s*)`` the errors are taken from. ``"fixed"`` (default): the
        nominal ``v*`` and the spacing reference of the context, for the whole run.
        ``"estimated"``: the velocity errors use an estimate ``v_hat`` of the equilibrium
        velocity, a first-order low-pass (time constant ``equilibrium_tau``, exact
        discretisation per controller sample, started at the nominal ``v*``) of the velocity
        of the vehicle right ahead of the CAV as the CAV observes it (its own sensing of its
        predecessor: the same value its HDV law uses for the relative speed; in the simulator
        it goes through the ``[scenario.v2v]`` model of that vehicle's column, exact when that
        link is ideal). The paper (Section II-B, remark after eq. 14) obtains ``v*`` from the
        head vehicle's steady velocity; in steady state every vehicle ahead moves at it. The
        spacing references move with it by ``s_e(v_hat) - s_e(v*)``, ``s_e`` the nominal HDV
        model's equilibrium spacing; ``v_hat`` is clipped into the model's valid range
        (1 %..99 % of ``v_max`` for the OVM, of ``v0`` for the IDM). While the vehicle ahead
        cruises at exactly ``v*`` both options give the same run, bit for bit. Not for
        ``fd_lcc`` (no vehicle ahead), nor for a platoon or ring (the estimate follows one
        CAV's predecessor).
    equilibrium_tau : float
        Time constant (s, > 0) of the estimate; default 1.0. Only with ``"estimated"``.
    measurement_filter : float
        Time constant (s, >= 0) of a first-order low-pass on every received spacing and
        velocity the law reads (see :class:`LinearLaw`); default 0: off (the values as
        received).
    """

    def __init__(
        self,
        name: str,
        gains,
        model,
        sample_time: float | None = None,
        equilibrium: str = "fixed",
        equilibrium_tau: float | None = None,
        measurement_filter: float = 0.0,
    ):
        gains.check(model)
        mf = measurement_filter
        if isinstance(mf, bool) or not isinstance(mf, int | float) or not 0.0 <= mf < np.inf:
            raise ConfigError(
                "measurement_filter", f"must be a number of seconds >= 0 (0: off), got {mf!r}"
            )
        if equilibrium not in EQUILIBRIA:
            raise ConfigError(
                "equilibrium", f"must be one of {list(EQUILIBRIA)}, got {equilibrium!r}"
            )
        if equilibrium == "fixed":
            if equilibrium_tau is not None:
                raise ConfigError(
                    "equilibrium_tau", 'only applies with equilibrium = "estimated"'
                )
        else:
            if gains.cavs != PAPER_CAVS:
                raise ConfigError(
                    "equilibrium",
                    f"must be \"fixed\" for kind = {model.kind!r} (the estimate follows one "
                    "CAV's predecessor)",
                )
            if model.kind == "fd_lcc":
                raise ConfigError(
                    "equilibrium",
                    'must be "fixed" for fd_lcc: FD-LCC has no vehicle ahead of the CAV to '
                    "estimate the equilibrium velocity from",
                )
            equilibrium_tau = 1.0 if equilibrium_tau is None else equilibrium_tau
            tau = float(equilibrium_tau) if isinstance(equilibrium_tau, int | float) else None
            if isinstance(equilibrium_tau, bool) or tau is None or not (0.0 < tau < np.inf):
                raise ConfigError(
                    "equilibrium_tau", f"must be a number of seconds > 0, got {equilibrium_tau!r}"
                )
            equilibrium_tau = tau
        self.name = name
        self.gains = gains
        self.model = model
        self.sample_time = sample_time
        self.equilibrium = equilibrium
        self.equilibrium_tau = equilibrium_tau
        self.measurement_filter = float(mf)

    def _law(self, ctx: ControlContext) -> LinearLaw:
        if self.gains.cavs != PAPER_CAVS:
            return self._rows_law(ctx)
        if ctx.n_cav != 1 or ctx.ring:
            raise ConfigError(
                f"controllers.{self.name}",
                f"{self.model.kind} gains are for one CAV on an open string; the scenario has "
                f"{ctx.n_cav} CAV(s){' on a ring' if ctx.ring else ''} (use kind = platoon / "
                "ring gains)",
            )
        if (ctx.m, ctx.n) != (self.model.m, self.model.n):
            raise ConfigError(
                f"controllers.{self.name}",
                f"gains are for m={self.model.m}, n={self.model.n}; the scenario has "
                f"m={ctx.m}, n={ctx.n}",
            )
        law = replace(
            _law_from_gains(self.gains, ctx.m, ctx.n), measurement_filter=self.measurement_filter
        )
        if self.equilibrium == "fixed":
            return law
        ts = ctx.dt if self.sample_time is None else float(self.sample_time)
        v_lim = free_speed(ctx.hdv)
        return replace(
            law,
            equilibrium_decay=math.exp(-ts / self.equilibrium_tau),
            v_bounds=(0.01 * v_lim, 0.99 * v_lim),
        )

    def columns(self) -> tuple[int, ...]:
        """Array column of every position 1..N of a platoon's gains (``i`` open, ``i - 1`` on
        the ring)."""
        off = 1 if self.model.ring else 0
        return tuple(i - off for i in range(1, self.model.platoon.size + 1))

    def _rows_law(self, ctx: ControlContext) -> LinearLaw:
        """The law of a platoon's or ring's gains: one row per CAV."""
        cols = self.columns()
        want = tuple(cols[i - 1] for i in self.model.cavs)
        nv = len(cols) + (0 if self.model.ring else 1)
        if ctx.cavs != want or bool(ctx.ring) != self.model.ring or ctx.n_vehicles != nv:
            road = "ring" if self.model.ring else "platoon"
            raise ConfigError(
                f"controllers.{self.name}",
                f"gains are for CAV columns {list(want)} of {nv} ({road}); the scenario has "
                f"CAV columns {list(ctx.cavs)} of {ctx.n_vehicles}"
                f"{' on a ring' if ctx.ring else ''}",
            )
        K = self.gains.matrix(self.model)  # the model's state order
        Ks = np.zeros((len(want), nv))
        Kv = np.zeros((len(want), nv))
        Ks[:, list(cols)] = K[:, 0::2]
        Kv[:, list(cols)] = K[:, 1::2]
        if not self.model.ring:
            Kv[:, 0] += self.gains.kh  # the head's velocity error
        return LinearLaw(
            Ks, Kv, np.zeros(len(want)), self.gains.semantics == "added",
            measurement_filter=self.measurement_filter,
        )  # fmt: skip

    def describe(self) -> dict[str, Any]:
        out = {
            "type": "static",
            "kind": self.model.kind,
            "semantics": self.gains.semantics,
            "gains": self.gains.as_table(),
            "sample_time": self.sample_time,
            "equilibrium": self.equilibrium,
            "measurement_filter": self.measurement_filter,
        }
        if self.equilibrium == "estimated":
            out["equilibrium_tau"] = self.equilibrium_tau
        return out

    def toml_table(self) -> dict[str, Any]:
        """The ``[controllers.NAME]`` table that builds this controller (``type = "static"``,
        the gains inline: a ``gains_file`` controller is written with the gains it read)."""
        out = self.describe()
        if out["measurement_filter"] == 0.0:
            del out["measurement_filter"]  # the default: off
        return out

    def as_dict(self) -> dict[str, Any]:
        """Name, :meth:`StaticGainController.describe` and the model's layout (``m``, ``n``
        of the paper's one CAV; the CAV positions of a platoon or ring)."""
        if self.gains.cavs != PAPER_CAVS:
            return {"name": self.name, "cavs": list(self.model.cavs), **self.describe()}
        return {"name": self.name, "m": self.model.m, "n": self.model.n, **self.describe()}


#: The same class as :class:`StaticGainController` (a platoon's or ring's gains).
PlatoonGainController = StaticGainController
