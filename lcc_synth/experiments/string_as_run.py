"""Head-to-tail string stability of the controllers as they run, and as they are measured.

* :func:`controller_loop`: the exact linear loop (:mod:`lcc_synth.analysis.as_run`) of a linear
  controller of the registry (the CAV as an HDV, static gains with a fixed or estimated
  equilibrium, a sample time, a measurement filter) on a string with a given simulator step
  and V2V latency: the law the simulator runs (``controller.linear_law``), evaluated every
  ``sample_time`` (or every simulator step).
* :func:`measured_ratio`: the small-signal tail/head velocity amplitude ratio measured in the
  simulator, for any controller (the only answer for a controller that is not linear, such as
  the MPC). The head vehicle's velocity is ``v*`` plus a multisine, one sine of amplitude
  ``a / sqrt(k)`` per frequency (``a = MEASURE_AMPLITUDE = 0.1`` m/s, ``k`` frequencies): the
  spacings move by < 0.1 m and accelerations by < 0.1 m/s^2 at 1 rad/s, the OVM stays in its
  linear regime (at ``v* = v_max / 2``, its inflection point, the quadratic term vanishes;
  amplitudes 0.1 and 0.02 m/s give ratios within 1e-5) and far from every constraint of the
  MPC. The run lasts ``MEASURE_SETTLE = 150`` s (the slowest pole of the showcase's loops is
  -0.068 1/s: its transient is e^-10 of its start) plus ``MEASURE_PERIODS = 1`` period of the
  slowest frequency, over which the head and tail velocities are fitted by least squares to
  a constant plus a sine and a cosine per frequency; the ratio is that of the fitted
  amplitudes. No noise, no packet loss, no reaction delays: the nominal string. A controller
  whose QP is solved by a polishing OSQP (the MPC's and DeeP-LCC's default) is measured with
  that QP solved by DAQP (:func:`lcc_synth.mpc.active_set.exact_qp`): a successful polish
  returns the QP's exact optimum, which DAQP reaches from the previous active set. Measured
  on the showcase (``lcc-synth run``, every solve of its OSQP polished): the ratios of every
  measured curve (mpc and mpc_delay on string10, mpc on sec5a and platoon8, deep_lcc) are
  OSQP's to 12 digits, at a quarter to a seventh of the CPU time per curve (string10's mpc 2.9 s ->
  0.43 s, deep_lcc 7.5 s -> 1.7 s); ``tests/test_as_run.py`` compares the two.
* :func:`gamma_curves`: both, for every controller of a layout (``lcc-synth run``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lcc_synth.analysis.as_run import NotRepresentable, as_run_report, law_loop
from lcc_synth.analysis.transfer import check_head
from lcc_synth.controllers.base import ControlContext, Controller
from lcc_synth.controllers.static import HDVController, StaticGainController
from lcc_synth.interrupts import checkpoint

__all__ = [
    "MEASURE_AMPLITUDE",
    "MEASURE_SETTLE",
    "MEASURE_PERIODS",
    "MEASURE_OMEGA",
    "MEASURE_SETTLE_RUN",
    "MeasuredReport",
    "controller_loop",
    "measured_ratio",
    "gamma_curves",
]

MEASURE_AMPLITUDE = 0.1
MEASURE_SETTLE = 150.0
MEASURE_PERIODS = 1
#: Frequencies (rad/s) at which ``lcc-synth run`` measures a controller that is not linear,
#: and its settling time (s): the showcase's MPC gives the same ratios to 1e-5 after 80 s and
#: after 150 s (6.6 s instead of 11 s per string10 measurement).
MEASURE_OMEGA = (0.05, 0.1, 0.3, 1.0)
MEASURE_SETTLE_RUN = 80.0


def _context(system, dt: float) -> ControlContext:
    v = np.array([float(system.v_star)])
    s = np.array([float(system.hdv.equilibrium_spacing(system.v_star))])
    if system.platoon is None:
        return ControlContext(system.m, system.n, 1, float(dt), v, s, -5.0, 2.0, system.hdv)
    # an open platoon: column i is position i (the head column 0), size + 1 columns
    cavs, size = system.platoon.cavs, system.platoon.size
    return ControlContext(cavs[0] - 1, size - cavs[0], 1, float(dt), v, s, -5.0, 2.0,
                          system.hdv, cavs=tuple(cavs))  # fmt: skip


def controller_loop(ctrl: Controller, system, dt: float = 0.01, latency: float = 0.0):
    """The :class:`~lcc_synth.analysis.as_run.AsRunLoop` of ``ctrl`` on ``system`` (``None``
    when the controller is not linear): one CAV, or every CAV of an open platoon. Raises
    ``NotRepresentable`` for a latency that is not a multiple of the controller's period, and
    ConfigError naming ``system.kind`` on a ring (no head vehicle)."""
    if isinstance(ctrl, StaticGainController):
        model = ctrl.model
    elif isinstance(ctrl, HDVController):
        model = system.linear_model(warn=False)
    else:
        return None
    check_head(model)  # a ring: no head-to-tail transfer (ConfigError naming system.kind)
    law = ctrl.linear_law(_context(system, dt))
    period = float(dt if ctrl.sample_time is None else ctrl.sample_time)
    lat = round(float(latency) / dt) * float(dt)  # the simulator rounds it to steps
    return law_loop(model, law, period, lat)


def measured_ratio(
    ctrl: Controller,
    system,
    omega: Sequence[float],
    dt: float = 0.01,
    latency: float = 0.0,
    amplitude: float = MEASURE_AMPLITUDE,
    settle: float = MEASURE_SETTLE,
    periods: int = MEASURE_PERIODS,
    cav_lag: float = 0.0,
    exact: bool = True,
) -> np.ndarray:
    """Tail/head velocity amplitude ratio of ``ctrl`` in the simulator at each ``omega``
    (``cav_lag``: the CAV's actuator lag, :class:`~lcc_synth.simulation.scenario.Scenario`;
    ``exact``: a polishing OSQP's QP solved by DAQP,
    :func:`lcc_synth.mpc.active_set.exact_qp`; ``False`` runs the controller's own solver).

    One run with all the frequencies at once (a multisine: head velocity
    ``v* + sum_i (a / sqrt(k)) sin(w_i t + phi_i)``, Schroeder phases ``phi_i = -pi i (i-1)/k``
    to keep the peak low; superposition holds in the linear regime), ``settle`` s plus
    ``periods`` periods of the slowest frequency; the amplitudes are the least-squares fit of
    ``c0 + sum_i (a_i sin(w_i t) + b_i cos(w_i t))`` to the head and tail velocities over those
    last periods (an exact decomposition for a sum of these sines and a constant: the Euler
    integration of the head's cosine acceleration adds a constant offset).
    """
    from lcc_synth.simulation.engine import simulate
    from lcc_synth.simulation.perturbations import Profile
    from lcc_synth.simulation.scenario import V2V, Scenario

    w = np.asarray(omega, dtype=float)
    k = w.size
    amp = amplitude / np.sqrt(k)
    phase = -np.pi * np.arange(k) * (np.arange(k) - 1) / k
    window = periods * 2.0 * np.pi / w.min()
    duration = settle + window
    t = dt * np.arange(int(round(duration / dt)) + 1)
    accel = (amp * w * np.cos(np.outer(t, w) + phase)).sum(axis=1)
    head = Profile(tuple(t), tuple(accel), target="accel", interpolation="step")
    if system.platoon is None:
        sc = Scenario(
            m=system.m, n=system.n, hdv=system.hdv, v_star=system.v_star, dt=dt,
            duration=duration, perturbations=(head,), v2v=V2V(latency=latency),
            cav_lag=cav_lag,
        )  # fmt: skip
    else:  # a platoon's CAV columns, every vehicle's own parameters and equilibrium
        from lcc_synth.simulation.scenario_file import scenario_for

        sc = scenario_for(system, (head,), dt=dt, duration=duration,
                          v2v=V2V(latency=latency), cav_lag=cav_lag)  # fmt: skip
    from lcc_synth.mpc.active_set import exact_qp

    with exact_qp() if exact else nullcontext():
        res = simulate(sc, ctrl)
    tt = res.t
    keep = tt >= tt[-1] - window
    tt = tt[keep]
    basis = np.column_stack([np.ones(tt.size), np.sin(np.outer(tt, w)), np.cos(np.outer(tt, w))])
    vel = res.velocity[0][keep]
    coef = np.linalg.lstsq(basis, vel[:, [0, -1]], rcond=None)[0]
    amps = np.hypot(coef[1 : 1 + k], coef[1 + k :])
    return amps[:, 1] / amps[:, 0]


@dataclass(frozen=True)
class MeasuredReport:
    """The measured amplitude ratio of a controller that is not linear (``verdict``
    ``"not_linear"``: no analysis; ``gamma_peak`` is the largest measured ratio)."""

    omega: np.ndarray
    ratio: np.ndarray
    settings: dict = field(default_factory=dict)
    verdict: str = "not_linear"

    @property
    def gamma_peak(self) -> float:
        return float(np.max(self.ratio))

    @property
    def gamma_peak_omega(self) -> float:
        return float(self.omega[int(np.argmax(self.ratio))])

    def as_dict(self) -> dict[str, Any]:
        return {
            "verdict": self.verdict,
            "linear": False,
            "measured_omega": [float(w) for w in self.omega],
            "measured_ratio": [float(r) for r in self.ratio],
            "gamma_peak": self.gamma_peak,
            "gamma_peak_omega": self.gamma_peak_omega,
            "measurement": dict(self.settings),
        }


def gamma_curves(
    controllers: Mapping[str, Controller],
    system,
    omega: np.ndarray,
    dt: float = 0.01,
    latency: float = 0.0,
    measure_omega: Sequence[float] | None = MEASURE_OMEGA,
) -> dict[str, tuple[np.ndarray, Any]]:
    """``{name: (|Gamma| on omega, report)}`` of every controller as it runs on ``system``.

    A linear controller gets its as-run loop's ``|Gamma|`` and
    :class:`~lcc_synth.analysis.as_run.AsRunReport`; any other controller (or a loop with no
    exact linear model) the :class:`MeasuredReport` at ``measure_omega`` (its curve is NaN
    except at those frequencies, interpolated on ``log omega``); ``measure_omega=None`` skips
    them. An open platoon's loop holds every CAV (:func:`controller_loop`). Layouts without a
    head vehicle (``fd_lcc``, a ring) give ``{}``.
    """
    if system.kind in ("fd_lcc", "ring"):
        return {}
    omega = np.asarray(omega, dtype=float)
    out: dict[str, tuple[np.ndarray, Any]] = {}
    for name, ctrl in controllers.items():
        checkpoint()  # a signal lost in an extension's callback (lcc_synth.interrupts)
        why = "not linear"
        try:
            loop = controller_loop(ctrl, system, dt, latency)
        except NotRepresentable as err:
            loop, why = None, err.message
        if loop is not None:
            out[name] = (np.abs(loop.response(omega)), as_run_report(loop))
            continue
        if measure_omega is None:
            continue
        wm = np.asarray(measure_omega, dtype=float)
        from lcc_synth.mpc.active_set import exact_qp

        with exact_qp() as swapped:
            ratio = measured_ratio(ctrl, system, wm, dt, latency, settle=MEASURE_SETTLE_RUN,
                                   exact=False)  # fmt: skip
        inside = (omega >= wm.min()) & (omega <= wm.max())
        mag = np.full(omega.shape, np.nan)
        mag[inside] = np.interp(np.log(omega[inside]), np.log(wm), ratio)
        settings = {
            "why": why, "amplitude_m_s": MEASURE_AMPLITUDE, "settle_s": MEASURE_SETTLE_RUN,
            "periods": MEASURE_PERIODS, "dt": dt, "latency": latency,
            "qp_solver": "daqp (the exact optimum of the controller's QP, which its polished "
                         "OSQP solutions are)" if swapped else "the controller's own",
        }  # fmt: skip
        out[name] = (mag, MeasuredReport(wm, ratio, settings))
    return out
