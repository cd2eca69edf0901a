"""Is the simulation step fine enough for the dynamics it integrates?

The simulator integrates with explicit (forward) Euler, ``v_{k+1} = v_k + dt a_k``,
``p_{k+1} = p_k + dt v_k`` (:mod:`lcc_synth.simulation.engine`). Near the equilibrium the
string is the linear closed loop ``dx/dt = A x`` of Section II (eq. 9-12 with the CAV's
feedback, eq. 23), and Euler advances each of its modes ``lambda`` by the factor
``1 + lambda dt`` per step where the exact flow has ``exp(lambda dt)``.

Stability (error)
    Euler reproduces the decay of a mode with ``Re lambda < 0`` only if
    ``|1 + lambda dt| < 1``, i.e. ``dt < dt_E = 2 |Re lambda| / |lambda|^2``: ``2 tau`` for a
    real mode ``lambda = -1 / tau``, ``2 zeta / omega_n`` for an oscillatory one (damping
    ``zeta``, natural frequency ``omega_n``). At or beyond ``dt_E`` the simulated string
    oscillates with constant or growing amplitude where the modelled one settles: the run says
    nothing about the controller, and :func:`check_time_step` raises :class:`ConfigError`.

Accuracy (warning)
    Below ``dt_E`` the simulation reproduces each mode as the continuous mode
    ``lambda_E = ln(1 + lambda dt) / dt`` (the step factor ``1 + lambda dt = exp(lambda_E dt)``),
    ``lambda_E = lambda (1 - lambda dt / 2 + ...)``. Two relative errors of it are judged:

    * of the mode, ``|lambda_E / lambda - 1|`` (about ``|lambda| dt / 2``): above
      :data:`MODE_FRACTION` (5 %), i.e. roughly ``dt > tau / 10`` for the mode's time
      constant ``tau = 1 / |lambda|``, the fastest closed-loop or HDV mode is under-resolved;
    * of its decay rate, ``|Re lambda_E / Re lambda - 1|`` (0 for ``dt -> 0``, 1 at ``dt_E``,
      ``dt / dt_E`` to first order for a lightly damped mode): above :data:`WARN_FRACTION`
      (10 %) the simulation under-damps a lightly damped mode by more than a tenth, a tenth of
      the way to the stability limit, and so errs by as much in its amplitude after one decay
      time ``1 / |Re lambda|``.

    :func:`check_time_step` then warns with :class:`TimeStepWarning` and gives the largest
    step keeping every mode within both. Measured on the shipped problems (AAVE against
    dt = 0.01): Table II moves by 5-7 % at dt = 0.05 and 11-16 % at dt = 0.1 (limit 0.097 s),
    the Section V-A cases by 5-11 % at 0.05 and 12-25 % at 0.1 (limits 0.046-0.10 s).

Which dynamics: the closed loop of a static-gain controller (its own linear model and gains,
as :func:`lcc_synth.models.feedback.closed_loop`), and for every other controller (the CAV
driving as an HDV, MPC, any nonlinear law) the string with the CAV following the HDV law, whose
modes are the HDVs' own time constants. Nominal HDV parameters at ``v*``; modes with
``Re lambda = 0`` (the FD-LCC position integrator ``lambda = 0``, which Euler integrates
exactly; undamped modes) are not judged. A loop with growing modes (``Re lambda > 0``: the
all-HDV ring of ``problems/ring_stop_and_go.toml``, +0.0269 +- 0.428j 1/s) is judged by the
error of their growth rate (Euler over-amplifies them, ``Re lambda_E - Re lambda ~
|lambda|^2 dt / 2``) and of the decaying modes only those decaying faster than the fastest
growing mode grows: a slower one (that ring's -0.0232 +- 0.747j, 12 % decay-rate error at
dt = 0.01 s) is swamped by the growing wave. Measured on that ring (growth-rate error of the
wave 17 % / 3.4 % / 1.7 % at dt = 0.05 / 0.01 / 0.005 s): at 0.05 s the all-HDV wave ends in
a collision at t = 209 s, at 0.01 s its AAVE and fuel over 200-300 s are within 0.8 % / 1.0 %
of dt = 0.005 s. The ring's conserved total-spacing mode (0) is never judged: the check runs
on the invariant hyperplane, where it is absent. Reaction delays,
a controller's sample-and-hold and the equilibrium estimator are not part of this check.

Figures: at the paper's dt = 0.01 s every loop of the shipped problems stays within 21 % of
the warning thresholds (the closest: Section V-A case D, whose lightly damped mode
-0.63 +- 1.73j has dt_E = 0.37 s). Table II (``problems/paper_table2.toml``) warns from
dt = 0.092 s and is an error from dt = 1.23 s; at dt = 1.0 s (accepted silently before) Euler
misstates its FD-LCC loop's mode by 81 % and the minimum spacing comes out 5.9 m, not 17.1 m.
"""

from __future__ import annotations

import cmath
import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from lcc_synth.errors import ConfigError

__all__ = [
    "WARN_FRACTION",
    "MODE_FRACTION",
    "TimeStepWarning",
    "StepCheck",
    "damping_error",
    "mode_error",
    "euler_check",
    "loop_matrix",
    "check_time_step",
]

#: Largest relative error of a mode's decay rate (see the module docstring) accepted silently.
WARN_FRACTION = 0.1
#: Largest relative error of a mode itself (``|lambda| dt / 2``: dt <= tau / 10) accepted silently.
MODE_FRACTION = 0.05


class TimeStepWarning(UserWarning):
    """The simulation step is coarse for the closed loop's fastest or least damped mode."""


def damping_error(lam: complex, dt: float) -> float:
    """Relative error ``|ln|1 + lam dt| / (dt Re lam) - 1|`` of explicit Euler's decay rate of
    a mode ``lam`` (``Re lam < 0``); ``inf`` where one step kills it (``1 + lam dt = 0``)."""
    rho = abs(1.0 + lam * dt)
    if rho == 0.0:
        return math.inf
    return abs(math.log(rho) / (dt * lam.real) - 1.0)


def mode_error(lam: complex, dt: float) -> float:
    """Relative error ``|ln(1 + lam dt) / (lam dt) - 1|`` of the mode explicit Euler
    reproduces (principal logarithm; ``inf`` where one step kills the mode)."""
    z = 1.0 + lam * dt
    if z == 0:
        return math.inf
    return abs(cmath.log(z) / (lam * dt) - 1.0)


def _excess(lam: complex, dt: float) -> float:
    """How far past its thresholds a mode's errors are (> 1: warn)."""
    return max(mode_error(lam, dt) / MODE_FRACTION, damping_error(lam, dt) / WARN_FRACTION)


def _advised_dt(lam: complex) -> float:
    """Largest ``dt`` keeping both errors of ``lam`` within their thresholds (bisection: they
    grow from 0 and stay above them up to the stability limit; a growing mode: up to
    ``1 / |lam|``, where its growth-rate error is far above them)."""
    lo = 0.0
    hi = 2.0 * abs(lam.real) / abs(lam) ** 2 if lam.real < 0 else 1.0 / abs(lam)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _excess(lam, mid) <= 1.0:
            lo = mid
        else:
            hi = mid
    return lo


@dataclass(frozen=True)
class StepCheck:
    """Explicit Euler at step ``dt`` on one loop's modes.

    Attributes
    ----------
    loop : str
        What was analysed (e.g. ``"the closed loop of controller 'h2'"``).
    dt : float
    mode : complex
        The mode furthest past the thresholds (``nan`` when no mode decays).
    error, damping : float
        Its relative errors at ``dt``: of the mode and of its decay rate (0 when no mode
        decays).
    excess : float
        ``max(error / MODE_FRACTION, damping / WARN_FRACTION)``: above 1 the step is coarse.
    stable : bool
        ``|1 + lambda dt| < 1`` for every decaying mode.
    dt_stable : float
        Euler's stability limit ``2 |Re lambda| / |lambda|^2``, smallest over the modes.
    dt_advised : float
        Largest step keeping every mode within :data:`MODE_FRACTION` and
        :data:`WARN_FRACTION`.
    """

    loop: str
    dt: float
    mode: complex
    error: float
    damping: float
    excess: float
    stable: bool
    dt_stable: float
    dt_advised: float


def euler_check(A: np.ndarray, dt: float, loop: str = "the loop") -> StepCheck:
    """:class:`StepCheck` of explicit Euler at ``dt`` on ``dx/dt = A x``."""
    lam = np.linalg.eigvals(np.asarray(A, dtype=float))
    decaying = [complex(x) for x in lam if x.real < -1e-9 * max(1.0, abs(x))]
    growing = [complex(x) for x in lam if x.real > 1e-9 * max(1.0, abs(x))]
    sigma = max((x.real for x in growing), default=0.0)
    # an unstable loop (the all-HDV ring): its growing modes set what the run shows, so their
    # growth rate is judged, and a decaying mode only if it decays faster than they grow
    judged = [x for x in decaying if -x.real >= sigma] + growing
    if not judged:
        return StepCheck(loop, dt, complex(math.nan), 0.0, 0.0, 0.0, True, math.inf, math.inf)
    excess = [_excess(x, dt) for x in judged]
    worst = judged[int(np.argmax(excess))]
    return StepCheck(
        loop=loop,
        dt=dt,
        mode=worst,
        error=mode_error(worst, dt),
        damping=damping_error(worst, dt),
        excess=max(excess),
        stable=all(abs(1.0 + x * dt) < 1.0 for x in decaying),
        dt_stable=min((2.0 * abs(x.real) / abs(x) ** 2 for x in decaying), default=math.inf),
        dt_advised=min(_advised_dt(x) for x in judged),
    )


def loop_matrix(controller, scenario) -> tuple[np.ndarray, str] | None:
    """``(A, description)`` of the linear loop ``controller`` closes on ``scenario``'s string
    (see the module docstring); ``None`` when its gains are for another string (the simulator
    reports that)."""
    from lcc_synth.controllers.static import StaticGainController
    from lcc_synth.models.feedback import PAPER_CAVS, Gains, closed_loop, input_feedback
    from lcc_synth.models.linear import model_from_hdv

    name = getattr(controller, "name", "?")
    if scenario.cavs is not None:
        return _platoon_loop(controller, scenario, name)
    if isinstance(controller, StaticGainController) and controller.gains.cavs == PAPER_CAVS:
        model, gains = controller.model, controller.gains
        if (model.m, model.n) != (scenario.m, scenario.n):
            return None
        what = f"the closed loop of controller {name!r}"
    else:
        kind = "cf_lcc" if scenario.m == 0 else "lcc"
        model = model_from_hdv(kind, scenario.m, scenario.n, scenario.hdv, scenario.v_star,
                               warn=False)  # fmt: skip
        gains = Gains.named({}, "added")
        what = f"the HDV string (controller {name!r} checked with the CAV as an HDV)"
    A, _ = closed_loop(model, *input_feedback(model, gains))
    return A, what


def _platoon_loop(controller, scenario, name: str) -> tuple[np.ndarray, str] | None:
    """:func:`loop_matrix` of a mixed platoon or ring: a platoon gain's closed loop, or every
    CAV driving with its own HDV law (the platoon model rebuilt from the scenario's vehicles;
    the ring on its invariant hyperplane, where the conserved total spacing does not move)."""
    from dataclasses import replace

    from lcc_synth.controllers.static import StaticGainController
    from lcc_synth.models.feedback import PAPER_CAVS, Gains
    from lcc_synth.models.platoon import Platoon, platoon_model

    if isinstance(controller, StaticGainController) and controller.gains.cavs != PAPER_CAVS:
        model, gains = controller.model, controller.gains
        what = f"the closed loop of controller {name!r}"
    else:
        ring, off = bool(scenario.ring), 0 if scenario.ring else 1
        values = scenario.hdv_values or {}
        models = tuple(
            replace(scenario.hdv, **{k: float(np.asarray(v).reshape(-1)[j])
                                     for k, v in values.items() if np.ndim(v) <= 1})
            for j in range(off, scenario.n_vehicles)
        )  # fmt: skip
        cavs = tuple(c + 1 - off for c in scenario.cav_columns)
        model = platoon_model(Platoon(models, cavs, float(scenario.v_star), ring), warn=False)
        gains = Gains.zero(model, "added")
        what = f"the platoon with its CAVs as HDVs (controller {name!r})"
    A = gains.closed_loop(model)[0]
    if model.ring:
        V = model.invariant_basis()
        A = V.T @ A @ V
    return A, what


def _mode(lam: complex) -> str:
    return f"{lam.real:.3g} {'+-'[lam.imag < 0]} {abs(lam.imag):.3g}j 1/s"


def check_time_step(
    scenario, controllers: Mapping[str, object], field: str = "scenario.dt"
) -> list[StepCheck]:
    """Check ``scenario.dt`` against the loop of every controller (module docstring).

    Raises :class:`ConfigError` naming ``field`` when Euler is unstable for some loop, or
    naming ``controllers.NAME.sample_time`` when a controller's period is not a positive
    multiple of the step (as the simulator would, but before any run, so that the caller can
    name the file); warns (:class:`TimeStepWarning`) when a mode's damping error exceeds
    :data:`WARN_FRACTION`. Returns the checks. A scenario of another backend (SUMO, whose
    semi-implicit or ballistic update is not explicit Euler) gets the period check only.
    """
    from lcc_synth.simulation.engine import _steps_of

    dt = float(scenario.dt)
    for name, ctrl in controllers.items():
        ts = getattr(ctrl, "sample_time", None)
        if ts is not None:
            _steps_of(ts, dt, f"controllers.{name}.sample_time", multiple=True)
    if getattr(scenario, "backend", "builtin") != "builtin":
        return []  # SUMO integrates with its own scheme; the verdicts judge explicit Euler
    checks = []
    for ctrl in controllers.values():
        loop = loop_matrix(ctrl, scenario)
        if loop is not None:
            checks.append(euler_check(loop[0], dt, loop[1]))
    if not checks:
        return checks
    limit = min(c.dt_stable for c in checks)
    advised = min(c.dt_advised for c in checks)
    unstable = [c for c in checks if not c.stable]
    if unstable:
        c = min(unstable, key=lambda c: c.dt_stable)
        raise ConfigError(
            field,
            f"must be < {limit:.3g} s, got {dt:g}: explicit Euler is unstable for a mode "
            f"of {c.loop} (|1 + lambda dt| >= 1 for lambda = {_mode(c.mode)}), so the "
            f"simulated string would not settle where the model does; use dt <= "
            f"{advised:.2g} s",
        )
    c = max(checks, key=lambda c: c.excess)
    if c.excess > 1.0:
        warnings.warn(
            f"{field} = {dt:g} s is coarse for {c.loop}: explicit Euler misstates its mode "
            f"lambda = {_mode(c.mode)} by {100 * c.error:.0f} % and its "
            f"{'growth' if c.mode.real > 0 else 'decay'} rate by "
            f"{100 * c.damping:.0f} % (limits {100 * MODE_FRACTION:.0f} % and "
            f"{100 * WARN_FRACTION:.0f} %; unstable from dt = {limit:.3g} s); "
            f"use dt <= {advised:.2g} s",
            TimeStepWarning,
            stacklevel=2,
        )
    return checks
