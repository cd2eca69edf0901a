"""Settings of the LCC model predictive controller and their validation.

A problem file selects the MPC with a controller table (every key optional)::

    [controllers.mpc]
    type = "mpc"
    sample_time = 0.1          # controller period (s); the simulator holds the command between
    horizon = 50               # prediction steps N (horizon N * sample_time seconds)
    n_model = 10               # HDVs behind that the MPC predicts (default: all of [system].n)
    fallback_gains_file = "gains.json"   # static fallback gain (default: the paper's gain)
    fallback = "h2"            # or: another controller's static gain (experiments.spec)

    [controllers.mpc.weights]  # stage cost x'Qx + w_input u^2 + w_jerk (du)^2
    velocity = 1.0             # velocity error of every vehicle, (m/s)^-2
    spacing = 0.5              # spacing error of every HDV, m^-2
    spacing_cav = 0.5          # the CAV's own spacing error s_0 (LCC / CF-LCC); default = spacing
    position = 0.0             # FD-LCC's -p_0 state (marginally stable; 0 = not regulated)
    input = 1.0                # CAV acceleration (see input_on), > 0
    jerk = 0.0                 # change of that acceleration between steps
    input_on = "total"         # CF-LCC: "total" CAV acceleration or the "model" input u_hat
    slack = 100.0              # exact (l1) penalty on spacing-constraint violation, per m and step
    slack_quadratic = 1.0      # small quadratic slack term (keeps the QP strictly convex)

    [controllers.mpc.constraints]
    a_min = -5.0               # hard bounds on the CAV's total acceleration (m/s^2)
    a_max = 2.0
    s_min = 5.0                # soft safe spacing to the vehicle ahead, ABSOLUTE metres:
    t_gap = 0.8                #   s_0 >= s_min + t_gap * v_0
    margin = 0.1               # the QP enforces the bounds this much tighter (m): covers the
                               #   prediction's mismatch with the simulator (Euler steps)
    spacing_ahead = true       # enforce it (needs a vehicle ahead)
    behind = []                # HDVs behind with soft bounds s_i >= s_min_behind + t_gap_behind v_i
    s_min_behind = 5.0
    t_gap_behind = 0.8
    jerk_scale = 0.9           # comfort: |a_k - a_{k-W}| <= jerk_scale * ISO 15622 limit at the
                               #   CAV's speed * W Ts (0 = off; yields to the spacing bounds)
    jerk_window = 1.0          # W Ts (s): 1 s = ISO 15622's average, sample_time = per step
    spacing = "safe"           # the CAVs' own spacing bound: "safe" (s_min + t_gap v above) or
                               #   "equilibrium": the DeeP-LCC paper's bound on the spacing ERROR
    spacing_error = [-15.0, 20.0]   # from the equilibrium spacing s*(v_eq) (m; "equilibrium" only)

    [controllers.mpc.prediction]
    head = "constant"          # "constant": head velocity held; "accel": its measured
    head_accel_hold = 1.0      #   acceleration held for this long (s), then constant
    equilibrium = "moving_average"   # or "fixed" (system v_star); FD-LCC default: "fixed"
    equilibrium_window = 5.0   # moving-average window (s)
    relinearize = false        # re-linearise the HDV model when v_eq drifts ...
    relinearize_threshold = 1.0     # ... by more than this (m/s)
    delay = 0.0                # HDV reaction delay (s) in the prediction: one for every HDV
                               #   or a list, one per modelled HDV front to tail (mpc.delay)
    cav_lag = 0.0              # the CAV's actuator lag (s) in the prediction (mpc.lag)

    [controllers.mpc.solver]
    method = "osqp"            # or "daqp": exact dense active set (lcc_synth.mpc.active_set)
    eps_abs = 1.0e-6           # OSQP's tolerances and polish (not DAQP's)
    eps_rel = 1.0e-6
    max_iter = 10000
    polish = true
    warm_start = true
    time_limit = 0.0           # s, 0 = none

Every bad value is a :class:`~lcc_synth.errors.ConfigError` naming the dotted field.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.models.lag import check_lag
from lcc_synth.models.records import Record
from lcc_synth.schema import declared

__all__ = [
    "paper_fallback_gains",
    "Weights",
    "Constraints",
    "Prediction",
    "SolverSettings",
    "MPCSettings",
    "SPACING_TARGETS",
    "check_spacing_target",
    "settings_from_table",
    "table_solver_method",
]

HEAD_PREDICTIONS = ("constant", "accel")
INPUT_ON = ("total", "model")
EQUILIBRIA = ("moving_average", "fixed")
SOLVER_METHODS = ("osqp", "daqp")


def table_solver_method(table: Mapping[str, Any]) -> str:
    """The QP solver a ``[controllers.NAME]`` table of an MPC or DeeP-LCC asks for
    (``solver.method``; ``"osqp"`` when the table does not say): what the run-time estimates
    price a step at, before the table is checked (the loaders check it)."""
    solver = table.get("solver")
    return str(solver.get("method", "osqp")) if isinstance(solver, Mapping) else "osqp"
SPACING_TARGETS = ("safe", "equilibrium")


@dataclass(frozen=True, repr=False)
class Weights(Record):
    """Cost weights (all >= 0; ``input`` > 0 so the QP is strictly convex)."""

    velocity: float = 1.0
    spacing: float = 0.5
    spacing_cav: float | None = None
    position: float = 0.0
    input: float = 1.0
    jerk: float = 0.0
    input_on: str = "total"
    slack: float = 100.0
    slack_quadratic: float = 1.0

    @property
    def cav_spacing(self) -> float:
        """Weight of the CAV's own spacing error (``spacing`` unless set)."""
        return self.spacing if self.spacing_cav is None else self.spacing_cav


@dataclass(frozen=True, repr=False)
class Constraints(Record):
    """Hard input bounds and soft spacing bounds.

    ``spacing`` selects the bound on each CAV's own spacing ahead: ``"safe"`` (the default),
    the absolute ``s >= s_min + t_gap v``; ``"equilibrium"``, the DeeP-LCC paper's bound on
    the spacing error from the equilibrium spacing of the estimated equilibrium velocity,
    ``spacing_error[0] <= s - s*(v_eq) <= spacing_error[1]`` (Wang et al., IEEE T-CST 2023,
    Sec. VI: -15 and 20 m), both sides soft and ``margin`` tighter, ``s_min`` and ``t_gap``
    unused. It moves the bound with ``v_eq`` (:func:`~lcc_synth.mpc.formulation.
    spacing_families`); the bounds ``behind`` stay absolute. Verified against the paper's
    published MATLAB code (``main_brake_simulation.m``: ``s_limit = [5, 40] - s_star`` with
    ``s_star = 20`` at 15 m/s, the equilibrium velocity the mean of the head's last 20
    samples, the spacing errors re-measured from the OVM ``s*(v_eq)`` at every step).
    Measured on ``problems/platoon_deeplcc_brake.toml`` (fuel saved against all-HDV, 431.28
    mL): the joint MPC 20.53 % with ``"safe"``, 21.70 % with ``"equilibrium"``; DeeP-LCC
    22.48 % and 25.68 % (the paper: about 25 %). The paper's bound is never active there (at
    5 m/s ``s*(v) - 15`` m is below zero), so the CAVs close in further: minimum spacings
    12.75 / 12.06 m instead of 13.35 / 12.26 m (MPC), 10.38 / 11.07 m instead of 12.25 /
    12.35 m (DeeP-LCC).
    """

    a_min: float = -5.0
    a_max: float = 2.0
    s_min: float = 5.0
    t_gap: float = 0.8
    margin: float = 0.1
    spacing_ahead: bool = True
    behind: tuple[int, ...] = ()
    s_min_behind: float = 5.0
    t_gap_behind: float = 0.8
    jerk_scale: float = 0.9
    jerk_window: float = 1.0
    spacing: str = "safe"
    spacing_error: tuple[float, float] = (-15.0, 20.0)


@dataclass(frozen=True, repr=False)
class Prediction(Record):
    """Head-vehicle prediction and equilibrium estimation."""

    head: str = "constant"
    head_accel_hold: float = 1.0
    equilibrium: str | None = None  # None: "fixed" for FD-LCC, else "moving_average"
    equilibrium_window: float = 5.0
    relinearize: bool = False
    relinearize_threshold: float = 1.0
    delay: float | tuple[float, ...] = 0.0
    cav_lag: float = 0.0

    def equilibrium_mode(self, kind: str) -> str:
        """The estimator used for a model of ``kind``."""
        if self.equilibrium is not None:
            return self.equilibrium
        return "fixed" if kind == "fd_lcc" else "moving_average"


@dataclass(frozen=True, repr=False)
class SolverSettings(Record):
    """QP solver settings: OSQP (tight by default: the applied input must match an exact QP
    solution) or DAQP (``method = "daqp"``, :mod:`lcc_synth.mpc.active_set`)."""

    method: str = "osqp"
    eps_abs: float = 1.0e-6
    eps_rel: float = 1.0e-6
    max_iter: int = 10000
    polish: bool = True
    warm_start: bool = True
    time_limit: float = 0.0

    def osqp_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``osqp.OSQP.setup``."""
        out = {
            "eps_abs": self.eps_abs,
            "eps_rel": self.eps_rel,
            "max_iter": self.max_iter,
            "polishing": self.polish,
            "polish_refine_iter": 5,
            "warm_starting": self.warm_start,
            "verbose": False,
        }
        if self.time_limit > 0:
            out["time_limit"] = self.time_limit
        return out


@dataclass(frozen=True, repr=False)
class MPCSettings(Record):
    """Everything that defines the MPC (see the module docstring for the meaning)."""

    sample_time: float = 0.1
    horizon: int = 50
    n_model: int | None = None
    weights: Weights = field(default_factory=Weights)
    constraints: Constraints = field(default_factory=Constraints)
    prediction: Prediction = field(default_factory=Prediction)
    solver: SolverSettings = field(default_factory=SolverSettings)
    fallback_gains_file: str | None = None

    def __post_init__(self) -> None:
        validate(self)

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable view."""
        out = asdict(self)
        out["constraints"]["behind"] = list(self.constraints.behind)
        out["constraints"]["spacing_error"] = list(self.constraints.spacing_error)
        if isinstance(self.prediction.delay, tuple):
            out["prediction"]["delay"] = list(self.prediction.delay)
        return out

    def toml_table(self) -> dict[str, Any]:
        """The ``[controllers.NAME]`` table of an MPC with these settings (``None`` values are
        the loader's defaults and are left out)."""
        return {"type": "mpc", **self.as_dict()}


def _pos(value: float, name: str, strict: bool = False) -> None:
    import math

    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    ok = ok and (value > 0 if strict else value >= 0)
    if not ok:
        raise ConfigError(name, f"must be {'> 0' if strict else '>= 0'}, got {value!r}")


def check_spacing_target(spacing: Any, spacing_error: Any, prefix: str) -> None:
    """Check ``spacing`` and ``spacing_error`` of a constraints table (the MPC's and
    DeeP-LCC's); ``prefix`` is the table's dotted path (``"...constraints"``).

    Raises
    ------
    ConfigError
        ``spacing`` not one of :data:`SPACING_TARGETS`, or ``spacing_error`` not two finite
        numbers ``[lo, hi]`` with ``lo < 0 < hi`` (the equilibrium itself must satisfy it).
    """
    import math

    if spacing not in SPACING_TARGETS:
        raise ConfigError(f"{prefix}.spacing",
                          f"must be one of {list(SPACING_TARGETS)}, got {spacing!r}")
    e = spacing_error
    ok = isinstance(e, tuple | list) and len(e) == 2 and all(
        isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in e)
    if not ok or not e[0] < 0.0 < e[1]:
        raise ConfigError(f"{prefix}.spacing_error",
                          "must be [lo, hi] in metres with lo < 0 < hi (the bounds on s - s*(v_eq)"
                          f", e.g. the DeeP-LCC paper's [-15, 20]), got {e!r}")


def validate(s: MPCSettings, field_prefix: str = "") -> None:
    """Check the cross-field rules; raise :class:`ConfigError` naming the field."""
    pre = f"{field_prefix}." if field_prefix else ""
    _pos(s.sample_time, f"{pre}sample_time", strict=True)
    if isinstance(s.horizon, bool) or not isinstance(s.horizon, int) or s.horizon < 1:
        raise ConfigError(f"{pre}horizon", f"must be an integer >= 1, got {s.horizon!r}")
    if s.n_model is not None and (not isinstance(s.n_model, int) or s.n_model < 0):
        raise ConfigError(f"{pre}n_model", f"must be an integer >= 0, got {s.n_model!r}")
    w = s.weights
    for name in ("velocity", "spacing", "position", "jerk", "slack", "slack_quadratic"):
        _pos(getattr(w, name), f"{pre}weights.{name}")
    if w.spacing_cav is not None:
        _pos(w.spacing_cav, f"{pre}weights.spacing_cav")
    _pos(w.input, f"{pre}weights.input", strict=True)
    if w.input_on not in INPUT_ON:
        raise ConfigError(
            f"{pre}weights.input_on", f"must be one of {list(INPUT_ON)}, got {w.input_on!r}"
        )
    c = s.constraints
    if not c.a_min < 0 < c.a_max:
        if not c.a_min < c.a_max:
            raise ConfigError(
                f"{pre}constraints.a_min",
                f"must be < a_max = {c.a_max}, got a_min = {c.a_min}",
            )
        raise ConfigError(
            f"{pre}constraints.a_min",
            f"need a_min < 0 < a_max so that holding speed is allowed, got [{c.a_min}, {c.a_max}]",
        )
    for name in ("s_min", "t_gap", "margin", "s_min_behind", "t_gap_behind"):
        _pos(getattr(c, name), f"{pre}constraints.{name}")
    _pos(c.jerk_scale, f"{pre}constraints.jerk_scale")
    if c.jerk_scale > 1.0:
        raise ConfigError(
            f"{pre}constraints.jerk_scale",
            f"is a fraction of ISO 15622's limit, in [0, 1] (0 = off), got {c.jerk_scale}",
        )
    _pos(c.jerk_window, f"{pre}constraints.jerk_window", strict=True)
    if c.jerk_scale > 0 and not 0.5 * s.sample_time <= c.jerk_window <= 10.0:
        raise ConfigError(
            f"{pre}constraints.jerk_window",
            f"must be in [sample_time = {s.sample_time}, 10] s, got {c.jerk_window}",
        )
    for i in c.behind:
        if isinstance(i, bool) or not isinstance(i, int) or i < 1:
            raise ConfigError(
                f"{pre}constraints.behind", f"entries are HDV indices >= 1, got {i!r}"
            )
    if len(set(c.behind)) != len(c.behind):
        raise ConfigError(f"{pre}constraints.behind", f"has duplicates: {list(c.behind)}")
    check_spacing_target(c.spacing, c.spacing_error, f"{pre}constraints")
    p = s.prediction
    if p.head not in HEAD_PREDICTIONS:
        raise ConfigError(
            f"{pre}prediction.head", f"must be one of {list(HEAD_PREDICTIONS)}, got {p.head!r}"
        )
    if p.equilibrium is not None and p.equilibrium not in EQUILIBRIA:
        raise ConfigError(
            f"{pre}prediction.equilibrium",
            f"must be one of {list(EQUILIBRIA)}, got {p.equilibrium!r}",
        )
    _pos(p.head_accel_hold, f"{pre}prediction.head_accel_hold")
    _pos(p.equilibrium_window, f"{pre}prediction.equilibrium_window", strict=True)
    _pos(p.relinearize_threshold, f"{pre}prediction.relinearize_threshold", strict=True)
    for tau in p.delay if isinstance(p.delay, tuple) else (p.delay,):
        _pos(tau, f"{pre}prediction.delay")
        if tau > 5.0:
            raise ConfigError(f"{pre}prediction.delay", f"must be <= 5 s, got {tau}")
    if isinstance(p.delay, tuple) and not p.delay:
        raise ConfigError(f"{pre}prediction.delay", "must be a number or a non-empty list")
    check_lag(p.cav_lag, f"{pre}prediction.cav_lag")
    o = s.solver
    if o.method not in SOLVER_METHODS:
        raise ConfigError(f"{pre}solver.method",
                          f"must be one of {', '.join(SOLVER_METHODS)}, got {o.method!r}")
    _pos(o.eps_abs, f"{pre}solver.eps_abs", strict=True)
    _pos(o.eps_rel, f"{pre}solver.eps_rel")
    if o.eps_abs > 1e-3 or o.eps_rel > 1e-3:
        raise ConfigError(
            f"{pre}solver.eps_abs",
            "must be <= 1e-3 (OSQP's 1e-3 default already moves the applied input by up to "
            f"0.4 m/s^2); got eps_abs={o.eps_abs}, eps_rel={o.eps_rel}",
        )
    if isinstance(o.max_iter, bool) or not isinstance(o.max_iter, int) or o.max_iter < 1:
        raise ConfigError(f"{pre}solver.max_iter", f"must be an integer >= 1, got {o.max_iter!r}")
    _pos(o.time_limit, f"{pre}solver.time_limit")


# --------------------------------------------------------------------------------------------
# Problem-file table -> settings
# --------------------------------------------------------------------------------------------

def settings_from_table(table: Mapping[str, Any], field_name: str) -> MPCSettings:
    """Parse a ``[controllers.NAME]`` table of ``type = "mpc"`` into :class:`MPCSettings`.

    Parameters
    ----------
    table : mapping
        The controller table.
    field_name : str
        Its dotted path (e.g. ``"controllers.mpc"``), used in error messages.
    """
    f = field_name
    top = declared("controllers.NAME:mpc")
    top.check(table, f)

    def read(sub: str, cls) -> Any:
        """The sub-table ``sub`` as ``cls``, every declared key read through the schema."""
        t = declared(f"controllers.NAME.{sub}:mpc")
        raw = top.get(table, sub, f)
        t.check(raw, f"{f}.{sub}")
        values = {}
        for k in t.names:
            if k == "behind":
                behind = t.raw(raw, "behind")
                if not isinstance(behind, list):
                    raise ConfigError(
                        f"{f}.constraints.behind", f"must be a list of integers, got {behind!r}"
                    )
                values[k] = tuple(behind)
            elif k == "delay":
                tau = t.raw(raw, "delay")
                if not isinstance(tau, list | int | float) or isinstance(tau, bool):
                    raise ConfigError(f"{f}.prediction.delay",
                                      f"must be a number (s) or a list of numbers, got {tau!r}")
                values[k] = tuple(tau) if isinstance(tau, list) else tau
            elif k == "spacing_error":
                values[k] = tuple(t.get(raw, k, f"{f}.{sub}"))
            else:
                values[k] = t.get(raw, k, f"{f}.{sub}")
        return cls(**values)

    weights = read("weights", Weights)
    constraints = read("constraints", Constraints)
    prediction = read("prediction", Prediction)
    solver = read("solver", SolverSettings)
    fb = top.raw(table, "fallback_gains_file")
    if fb is not None and (not isinstance(fb, str) or not fb):
        raise ConfigError(f"{f}.fallback_gains_file", f"must be a file path, got {fb!r}")
    n_model = top.get(table, "n_model", f)
    try:
        return MPCSettings(
            sample_time=top.get(table, "sample_time", f),
            horizon=top.get(table, "horizon", f),
            n_model=n_model,
            weights=weights,
            constraints=constraints,
            prediction=prediction,
            solver=solver,
            fallback_gains_file=fb,
        )
    except ConfigError as err:
        if err.field.startswith(f):
            raise
        raise ConfigError(f"{f}.{err.field}", err.message) from None


_PAPER_TAIL = {"v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}


def paper_fallback_gains(kind: str, n: int) -> Gains:
    """The default fallback: the paper's Section V-B gains (FD-LCC; CF-LCC adds ``0.1 s_0``),
    restricted to the vehicles the model has, or the CAV's HDV law for LCC / CCC."""
    if kind in ("fd_lcc", "cf_lcc"):
        g = {k: v for k, v in _PAPER_TAIL.items() if int(k.split("_")[1]) <= n}
        if kind == "cf_lcc":
            g["s_0"] = 0.1
        return Gains.named(g, "replace")
    return Gains.named({}, "added")
