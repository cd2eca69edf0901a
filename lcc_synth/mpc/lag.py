"""The CAV's actuator lag in the MPC's discrete prediction model (``prediction.cav_lag``).

With a first-order lag ``tau`` between the command and the CAV's acceleration (the simulator's
``[scenario] cav_lag``, :mod:`lcc_synth.simulation.engine`) the command no longer moves the
CAV's velocity directly: ``dv_0/dt = a_0``, ``da_0/dt = (u - a_0) / tau``
(:func:`lcc_synth.models.lag.with_actuator_lag` on the MPC's linear model; for CF-LCC the HDV
law and the added input both feed the lag). The prediction is the exact zero-order-hold
discretisation of that model at the MPC's period (``expm`` of the augmented matrix, as the
delay-free model), so ``z = [x; a_0]`` and the condensed QP of
:mod:`lcc_synth.mpc.formulation` keep their form: ``a_0`` carries no weight, no gain and no
steady-state offset (:func:`~lcc_synth.mpc.delay.pad`), and the acceleration limits stay on
the command (the simulator clips the command, then lags it).

The state ``a_0`` at each sample is the CAV's measured acceleration (the simulator passes its
lag state as :attr:`~lcc_synth.controllers.base.Observation.cav_acceleration`); when the
simulator has no lag (the observation carries none) the CAV applies its command, and ``a_0``
is the MPC's previous command. ``prediction.cav_lag = 0`` (default) is today's model bit for
bit: :func:`prediction_extension` returns the delay model (``None`` without delays). The lag
and HDV delays (``prediction.delay``) in one prediction are not implemented (ConfigError).

Measured (``problems/mpc_head_brake.toml`` with ``[scenario] cav_lag = 0.3``, default MPC):
the lag-free prediction uses up the 0.1 m constraint margin of the safe spacing (closest 0.008
m inside it; AAVE 2.204 m/s, fuel 694.6 mL), the lag-aware one keeps it as without lag (0.098
m; AAVE 2.257 m/s, fuel 696.3 mL); no slack, fallback or collision in either.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.lag import with_actuator_lag
from lcc_synth.models.linear import discretize
from lcc_synth.mpc.delay import DelayModel, lcc_delay_model

__all__ = ["LagPrediction", "LagState", "prediction_extension"]


@dataclass(frozen=True, eq=False)
class LagPrediction:
    """The lagged discrete model of :func:`prediction_extension`.

    Attributes
    ----------
    Ad, Bd, Hd : numpy.ndarray
        ``(nx + 1, nx + 1)``, ``(nx + 1, 1)``, ``(nx + 1, 1)``; the last state is ``a_0``.
    nx : int
        States of the lag-free model.
    tau : float
        The lag (s).
    """

    Ad: np.ndarray
    Bd: np.ndarray
    Hd: np.ndarray
    nx: int
    tau: float

    @property
    def nz(self) -> int:
        """States of the prediction, ``nx + 1``."""
        return self.Ad.shape[0]

    def history(self) -> LagState:
        """The per-member state extension (:class:`LagState`)."""
        return LagState()


class LagState:
    """Appends the CAV's acceleration ``a_0`` to the MPC's error state at each sample."""

    def push(self, x: np.ndarray, d: float, s_eq: float, v_eq: float, obs=None, b: int = 0,
             u_prev: float = 0.0) -> np.ndarray:  # fmt: skip
        """``[x, a_0]``: ``a_0`` measured (``obs.cav_acceleration[b, 0]``) when the observation
        has it, else ``u_prev`` (the previous command: no lag in the plant)."""
        acc = None if obs is None else getattr(obs, "cav_acceleration", None)
        a0 = float(np.asarray(acc)[b].reshape(-1)[0]) if acc is not None else float(u_prev)
        return np.append(x, a0)


def prediction_extension(model, prediction, Ts: float) -> DelayModel | LagPrediction | None:
    """The MPC's extended prediction model: the lag model for ``prediction.cav_lag > 0``,
    else :func:`~lcc_synth.mpc.delay.lcc_delay_model` (``None``: the plain model)."""
    tau = float(prediction.cav_lag)
    if tau == 0.0:
        return lcc_delay_model(model, prediction.delay, Ts)
    if np.any(np.asarray(prediction.delay, dtype=float) != 0.0):
        raise ConfigError("prediction.cav_lag", "cannot be combined with prediction.delay "
                          "(HDV delays) in one prediction; give one of them")  # fmt: skip
    lag = with_actuator_lag(model.A, model.B, model.H, [model.index("v_0")], tau,
                            model.state_names)  # fmt: skip
    Ad, BH = discretize(lag.A, np.hstack([lag.B, lag.H]), Ts)
    return LagPrediction(Ad, BH[:, :1].copy(), BH[:, 1:].copy(), model.nx, tau)
