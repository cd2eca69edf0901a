"""What is simulated: the :class:`Scenario` of a batch of runs (string, limits, perturbations,
heterogeneity, delays, V2V) and its random :class:`Draws`; the ``[scenario]`` table is read by
:mod:`lcc_synth.simulation.scenario_file`.

Vehicle columns as in :mod:`lcc_synth.simulation.engine`: 0 the head vehicle, ``1..m`` the HDVs
ahead, ``m + 1`` the CAV, ``m + 2 .. m + n + 1`` the HDVs behind. A mixed platoon or ring
(``cavs`` given) keeps ``m`` = first CAV column - 1 and ``n`` = columns after it, so that
``m + n + 2`` is the number of columns: the open platoon's column ``i`` is position ``i``, the
ring's column ``j`` position ``j + 1`` (no head).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import IDM, MODELS, OVM
from lcc_synth.models.records import Record, ValueEq
from lcc_synth.schema import declared
from lcc_synth.simulation.checks import check_draw_bounds
from lcc_synth.simulation.perturbations import Perturbation
from lcc_synth.simulation.sumo_net import SumoSettings, check_sumo_scenario
from lcc_synth.simulation.v2v import V2V
from lcc_synth.simulation.v2v import check_number as _num

__all__ = [
    "BACKENDS", "MODEL_PARAMS", "RANGE_FIELDS", "V2V", "Scenario", "Draws", "draw_ranges",
    "scenario_variant", "split_ranges",
]  # fmt: skip

#: Simulators a scenario runs in (:func:`lcc_synth.simulation.backends.run_scenario`).
BACKENDS = ("builtin", "sumo")

#: Parameter order of each HDV model inside the compiled loop.
MODEL_PARAMS = {
    "ovm": ("alpha", "beta", "s_st", "s_go", "v_max"),
    "idm": ("v0", "T", "s0", "a", "b", "delta"),
}


@dataclass(frozen=True, eq=False, repr=False)
class Scenario(ValueEq, Record):
    """A mixed-traffic scenario (or a batch of ``batch`` scenarios differing in random draws).

    Two scenarios are equal (``==``) when every field is (:func:`~lcc_synth.models.records.same`:
    explicit per-vehicle arrays by value).

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
    backend : {"builtin", "sumo"}
        The simulator: the built-in one (:mod:`lcc_synth.simulation.engine`) or SUMO
        (:mod:`lcc_synth.simulation.sumo`; checked here for what SUMO cannot reproduce).
    sumo : SumoSettings
        SUMO's car-following model and integration scheme (``backend = "sumo"`` only).
    cavs : tuple of int, optional
        CAV columns of a mixed platoon or ring (sorted, at least one; ``m`` must be
        ``cavs[0] - 1``); ``None``: the single CAV at column ``m + 1``. With ``cavs`` given the
        explicit ``hdv_values`` of the CAV columns are kept (each CAV's own HDV law, used when
        it drives as an HDV) and every vehicle, CAVs included, starts at its own equilibrium
        spacing at ``v*``.
    ring : bool
        A ring road: no head vehicle, column 0 follows the last column (needs ``cavs``).
    circumference : float, optional
        Ring length (m), > 0, in gap coordinates (what the dynamics see: the road's length
        minus ``N * vehicle_length``); ``None`` on an open road.
    vehicle_length : float
        Length (m, >= 0) of every vehicle; display only. Every spacing the simulator
        integrates and records is the bumper-to-bumper gap (exact for gap-based laws); the
        result's positions put column ``j`` ``j * vehicle_length`` further back and its
        circumference is ``circumference + N * vehicle_length`` (the road a user sees).
    initial_state : pair of tuples, optional
        ``(spacings, speeds)``, one per column (the head's spacing is ignored): the initial
        state instead of the equilibrium at ``v*`` (``[scenario] initial = "data"``: a
        recording's first sample). Spacing errors stay relative to the equilibrium.
    accel_noise_uniform : float
        Half width ``w`` (m/s^2, >= 0) of a uniform acceleration noise ``U[-w, w]`` on every
        vehicle but the head (CAVs included), added after the limits and emergency braking
        (the DeeP-LCC paper's scheme; ``hdv_accel_noise`` is Gaussian, HDVs only, before the
        limits).
    cav_lag : float or tuple of float
        First-order actuator lag ``tau`` (s) of the CAVs' acceleration, ``da/dt = (u - a) /
        tau``: one for every CAV or one per CAV; 0 (default) is no lag, else ``tau >= dt``
        (the Euler step of the lag stays monotone). Limits and emergency braking act on the
        command ``u`` (see :mod:`~lcc_synth.simulation.engine`).
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
    backend: str = "builtin"
    sumo: SumoSettings = field(default_factory=SumoSettings, repr=False)
    cavs: tuple[int, ...] | None = None
    ring: bool = False
    circumference: float | None = None
    accel_noise_uniform: float = 0.0
    cav_lag: float | tuple[float, ...] = 0.0
    vehicle_length: float = 0.0
    initial_state: tuple[tuple[float, ...], tuple[float, ...]] | None = None

    def __post_init__(self) -> None:
        self._check_layout()
        self._check_initial_state()
        for key, lo in (
            ("m", -1 if self.ring else 0), ("n", 0), ("batch", 1), ("record_every", 1),
            ("seed", 0), ("first_index", 0),
        ):  # fmt: skip
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
        if self.backend not in BACKENDS:
            raise ConfigError(
                "scenario.backend", f"must be one of {list(BACKENDS)}, got {self.backend!r}"
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
        _num("scenario.accel_noise_uniform", self.accel_noise_uniform, lo=0.0)
        _num("system.vehicle_length", self.vehicle_length, lo=0.0)
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
        self._check_draw_bounds()
        for key in self.hdv_values or {}:
            if key not in allowed:
                raise ConfigError(
                    f"scenario.hdv_values.{key}",
                    f"not a parameter of the {self.hdv.name} model; allowed: {list(allowed)}",
                )
        for tau in self.lags():
            if 0.0 < tau < self.dt:
                raise ConfigError(
                    "scenario.cav_lag", f"must be 0 or >= dt = {self.dt} s, got {tau}"
                )
        if self.backend == "sumo":
            check_sumo_scenario(self)

    def _check_initial_state(self) -> None:
        """An explicit initial state: one finite spacing (> 0 behind the head) and speed
        (>= 0) per column, on an open road, in the built-in simulator; a recorded head
        (:class:`~lcc_synth.simulation.perturbations.Recorded`) starts at its recording's
        first speed."""
        from lcc_synth.simulation.perturbations import Recorded

        f = "scenario.initial"
        head_v = float(self.v_star)
        if self.initial_state is not None:
            gaps, speeds = (np.asarray(x, dtype=float) for x in self.initial_state)
            nv = self.m + self.n + 2
            if self.ring or gaps.shape != (nv,) or speeds.shape != (nv,):
                raise ConfigError(f, f"an initial state needs one spacing and one speed per "
                                  f"vehicle of an open road ({nv}), got {gaps.shape[0]} and "
                                  f"{speeds.shape[0]}{' on a ring' if self.ring else ''}")
            if not (np.all(np.isfinite(gaps[1:])) and np.all(gaps[1:] > 0)):
                raise ConfigError(f, f"every initial spacing behind the head must be > 0 m, got "
                                  f"{np.round(gaps[1:], 3).tolist()}: check [system] "
                                  "vehicle_length against the recorded headways")
            if not (np.all(np.isfinite(speeds)) and np.all(speeds >= 0)):
                raise ConfigError(f, f"every initial speed must be >= 0 m/s, got "
                                  f"{np.round(speeds, 3).tolist()}")
            head_v = float(speeds[0])
        for i, p in enumerate(self.perturbations):
            if not isinstance(p, Recorded):
                continue
            if abs(p.speeds[0] - head_v) > 1e-9 * max(1.0, head_v):
                raise ConfigError(f"scenario.perturbations[{i}].column", f"the head starts at "
                                  f"{head_v:g} m/s but the recording starts at {p.speeds[0]:g} "
                                  'm/s: set [scenario] initial = "data" or [system] v_star = '
                                  f"{p.speeds[0]:g}")

    def _hdv_base(self) -> dict[str, np.ndarray] | None:
        """Every model parameter's value of every HDV before the draws (nominal, or the
        explicit ``hdv_values``): ``{name: 1-D array}``; ``None`` when ``hdv_values`` does not
        broadcast (:meth:`draw` reports it)."""
        nv, mask = self.n_vehicles, self.is_hdv()
        out = {}
        for key in MODEL_PARAMS[self.hdv.name]:
            value = (self.hdv_values or {}).get(key, getattr(self.hdv, key))
            try:
                arr = np.asarray(value, dtype=float)
                arr = np.broadcast_to(arr, np.broadcast_shapes(arr.shape, (nv,)))
            except (TypeError, ValueError):
                return None
            out[key] = arr.reshape(-1, nv)[:, mask].ravel()
        return out

    def _check_draw_bounds(self) -> None:
        """Every value the heterogeneity draws can produce must be valid
        (:func:`~lcc_synth.simulation.checks.check_draw_bounds`), found here, before any draw
        (a sweep would otherwise find it on its workers)."""
        widths = {k: float(w) for k, w in self.heterogeneity.items() if float(w) > 0}
        base = self._hdv_base() if widths else None
        if base and next(iter(base.values())).size:
            check_draw_bounds(MODELS[self.hdv.name], base, widths, self.v_star)

    def lags(self) -> tuple[float, ...]:
        """The actuator lag ``tau`` (s) of each CAV (``cav_lag`` per CAV)."""
        lag = self.cav_lag
        if np.ndim(lag) == 0:
            return tuple(_num("scenario.cav_lag", lag, lo=0.0) for _ in self.cav_columns)
        if len(lag) != len(self.cav_columns):
            raise ConfigError(
                "scenario.cav_lag",
                f"needs one value or one per CAV ({len(self.cav_columns)}), got {len(lag)}",
            )
        return tuple(_num("scenario.cav_lag", x, lo=0.0) for x in lag)

    def _check_layout(self) -> None:
        if self.cavs is None:
            if self.ring:
                raise ConfigError("scenario.cavs", "a ring needs its CAV columns (cavs)")
            return
        cavs = tuple(self.cavs)
        nv = self.m + self.n + 2
        lo = 0 if self.ring else 1
        if not cavs or any(
            isinstance(c, bool) or not isinstance(c, int | np.integer) or not lo <= c < nv
            for c in cavs
        ) or list(cavs) != sorted(set(cavs)):
            raise ConfigError(
                "system.cavs",
                f"CAV columns must be distinct, sorted, in [{lo}, {nv - 1}] and at least one "
                f"(the simulator needs a CAV: drive it as an HDV for an all-HDV run), got "
                f"{list(cavs)}",
            )
        object.__setattr__(self, "cavs", tuple(int(c) for c in cavs))
        if self.m != cavs[0] - 1:
            raise ConfigError("scenario.m", f"must be cavs[0] - 1 = {cavs[0] - 1}, got {self.m}")
        if self.ring:
            c = float("nan") if self.circumference is None else float(self.circumference)
            if not (np.isfinite(c) and c > 0):
                raise ConfigError("system.circumference", f"must be > 0 m, got {c!r}")

    @property
    def cav_columns(self) -> tuple[int, ...]:
        """Array columns of the CAVs (``(m + 1,)`` for the paper's single CAV)."""
        return (self.m + 1,) if self.cavs is None else tuple(self.cavs)

    @property
    def layout(self) -> tuple[int, bool] | None:
        """``(N, ring)`` of a mixed platoon or ring (vehicles named by position, see
        :func:`~lcc_synth.simulation.perturbations.vehicle_column`); ``None`` for the paper's
        single-CAV string (vehicles named by the paper's index)."""
        if self.cavs is None:
            return None
        return (self.n_vehicles if self.ring else self.n_vehicles - 1, bool(self.ring))

    def cav_models(self):
        """Each CAV's own HDV law (the nominal model, or a platoon slot's explicit values)."""
        if self.cavs is None or not self.hdv_values:
            return tuple(self.hdv for _ in self.cav_columns)
        from dataclasses import replace

        out = []
        for c in self.cav_columns:
            kw = {
                k: float(np.asarray(v, dtype=float).reshape(-1)[c])
                for k, v in self.hdv_values.items()
                if np.ndim(v) <= 1
            }
            out.append(replace(self.hdv, **kw))
        return tuple(out)

    def toml_table(self) -> dict[str, Any]:
        """The ``[scenario]`` table of this scenario (what :func:`scenario_from` reads; ``m``,
        ``n``, ``hdv`` and ``v_star`` belong to ``[hdv]`` / ``[system]``, ``first_index`` and
        ``name`` to the study that runs it). Per-vehicle ``hdv_values`` are written for the
        HDV columns, head..tail; a ``(batch, nv)`` array or a per-vehicle delay has no table
        form (ConfigError)."""
        out: dict[str, Any] = {
            k: getattr(self, k)
            for k in ("dt", "duration", "t_start", "a_min", "a_max", "cav_aeb", "hdv_aeb",
                      "seed", "batch", "record_every", "spacing_reference", "hdv_accel_noise")
        }  # fmt: skip
        if np.ndim(self.delay) != 0:
            raise ConfigError("scenario.delay", "a per-vehicle delay has no problem-file form")
        out["delay"] = {"mean": float(self.delay), "spread": float(self.delay_spread),
                        "model": self.delay_model}  # fmt: skip
        out["heterogeneity"] = {k: float(w) for k, w in self.heterogeneity.items()}
        out["v2v"] = self.v2v.toml_table()
        if self.accel_noise_uniform:
            out["accel_noise_uniform"] = float(self.accel_noise_uniform)
        if any(self.lags()):
            if len(set(self.lags())) > 1:
                raise ConfigError("scenario.cav_lag", "a per-CAV lag has no problem-file form")
            out["cav_lag"] = self.lags()[0]
        if self.hdv_values and self.cavs is None:  # a platoon's come from [system.hdv_values]
            hdv = self.is_hdv()
            out["hdv_values"] = {}
            for key, arr in self.hdv_values.items():
                arr = np.asarray(arr, dtype=float)
                if arr.shape != (self.n_vehicles,):
                    raise ConfigError(
                        f"scenario.hdv_values.{key}",
                        f"only one value per vehicle (shape ({self.n_vehicles},)) has a "
                        f"problem-file form, got shape {arr.shape}",
                    )
                out["hdv_values"][key] = arr[hdv].tolist()
        out["perturbations"] = [p.toml_table() for p in self.perturbations]
        if self.initial_state is not None:
            out["initial"] = "data"
        if self.backend != "builtin":
            out["backend"] = self.backend
            out["sumo"] = self.sumo.toml_table()
        return out

    @property
    def steps(self) -> int:
        """Number of samples."""
        return int(round(self.duration / self.dt))

    @property
    def last_time(self) -> float:
        """Time of the last sample, ``t_start + (steps - 1) dt``."""
        return float(self.t_start + (self.steps - 1) * self.dt)

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
        if not self.ring:
            mask[0] = False
        mask[list(self.cav_columns)] = False
        return mask

    def draw(self) -> Draws:
        """Per-scenario HDV parameters, delays and initial state (deterministic in ``seed``).

        Raises
        ------
        ConfigError
            ``scenario.batch``: the draws (a random generator per scenario) would not fit in
            the memory available, checked before any is drawn.
        """
        B, nv = self.batch, self.n_vehicles
        from lcc_synth.resources import DRAW_SCENARIO_BYTES, DRAW_VEHICLE_BYTES, require_memory

        need = B * (DRAW_VEHICLE_BYTES * nv + DRAW_SCENARIO_BYTES)
        if need > 1 << 26:  # below 64 MB: not worth asking the system
            require_memory(
                "scenario.batch", need, f"random draws of {B} scenarios x {nv} vehicles",
                "run fewer scenarios at once (scenario.batch, --seeds)",
            )  # fmt: skip
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
        # the head and the CAV follow no HDV law: nominal values there (a platoon's CAVs keep
        # their slot's explicit values: their own HDV law)
        fixed = ~hdv_mask
        if self.cavs is not None and self.hdv_values:
            fixed[list(self.cav_columns)] = False
        for key in names:
            values[key][:, fixed] = getattr(self.hdv, key)
        try:
            model = MODELS[self.hdv.name](**values)
            s_eq = np.broadcast_to(model.equilibrium_spacing(self.v_star), (B, nv)).copy()
        except ConfigError as err:
            raise ConfigError(
                f"scenario.heterogeneity.{err.field}", f"a drawn HDV is invalid: {err.message}"
            ) from None
        if not self.ring:
            s_eq[:, 0] = np.nan
        if self.cavs is None:
            s_eq[:, self.cav] = self.s_star
        return Draws(values, delays, s_eq)


@dataclass(frozen=True, repr=False)
class Draws(Record):
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


#: Settings a sweep may draw per scenario (``[lo, hi]`` in ``[scenario]``: U[lo, hi]), with
#: their allowed ranges; each has its own random stream ``(seed, i, tag)``.
def _bounds(key, tag: int) -> tuple[float, float, int]:
    return (float(key.lo), np.inf if key.hi is None else float(key.hi), tag)


_SC, _V2V = declared("scenario"), declared("scenario.v2v")
RANGE_FIELDS = {  # bounds from the schema (lcc_synth.schema), random-stream tags
    "hdv_accel_noise": _bounds(_SC.key("hdv_accel_noise"), 1),
    "v2v.loss_rate": _bounds(_V2V.key("loss_rate"), 2),
    "v2v.latency": _bounds(_V2V.key("latency"), 3),
    "v2v.spacing_noise": _bounds(_V2V.key("spacing_noise"), 4),
    "v2v.velocity_noise": _bounds(_V2V.key("velocity_noise"), 5),
    "v2v.position_noise": _bounds(_V2V.key("position_noise"), 6),
}


def split_ranges(
    table: Mapping[str, Any], n_vehicles: int
) -> tuple[dict[str, Any], dict[str, tuple[float, float]]]:
    """A ``[scenario]`` table with every ``[lo, hi]`` of :data:`RANGE_FIELDS` replaced by
    ``lo`` (so the table validates as usual), and those ranges ``{dotted key: (lo, hi)}``.

    A list of ``n_vehicles`` loss rates stays a per-vehicle list (not a range)."""
    out = {k: (dict(v) if isinstance(v, Mapping) else v) for k, v in dict(table).items()}
    ranges: dict[str, tuple[float, float]] = {}
    for key, (lo, hi, _) in RANGE_FIELDS.items():
        parent, _, leaf = key.rpartition(".")
        t = out.get(parent) if parent else out
        if not isinstance(t, dict) or not isinstance(t.get(leaf), list):
            continue
        value = t[leaf]
        if key == "v2v.loss_rate" and len(value) == n_vehicles and n_vehicles != 2:
            continue
        field_name = f"scenario.{key}"
        if len(value) != 2 or not all(
            isinstance(x, int | float) and not isinstance(x, bool) for x in value
        ):
            raise ConfigError(field_name, f"a range is [lo, hi] (two numbers), got {value!r}")
        a, b = (float(x) for x in value)
        if not (np.isfinite(a) and np.isfinite(b) and lo <= a <= b <= hi):
            raise ConfigError(
                field_name, f"range [lo, hi] needs {lo:g} <= lo <= hi <= {hi:g}, got {value!r}"
            )
        ranges[key] = (a, b)
        t[leaf] = a
    return out, ranges


def draw_ranges(ranges: Mapping[str, tuple[float, float]], seed: int, index: int):
    """Scenario ``index``'s value of every range, U[lo, hi], from ``(seed, index)`` only."""
    out = {}
    for key, (a, b) in ranges.items():
        rng = np.random.default_rng([int(seed), int(index), RANGE_FIELDS[key][2]])
        out[key] = float(rng.uniform(a, b)) if b > a else a
    return out


def scenario_variant(sc: Scenario, ranges: Mapping[str, tuple[float, float]], index: int):
    """Study scenario ``index`` alone (``batch = 1``, ``first_index = index``) with its drawn
    :func:`draw_ranges` values (the V2V latency is then rounded to steps by the simulator)."""
    from dataclasses import replace

    drawn = draw_ranges(ranges, sc.seed, index)
    v2v = {k.split(".", 1)[1]: v for k, v in drawn.items() if k.startswith("v2v.")}
    return replace(
        sc,
        batch=1,
        first_index=int(index),
        hdv_accel_noise=drawn.get("hdv_accel_noise", sc.hdv_accel_noise),
        v2v=replace(sc.v2v, **v2v),
    )
