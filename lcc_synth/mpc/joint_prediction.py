"""The joint MPC's prediction model of every CAV of a platoon or ring, and the shape of its QP.

The QP itself is :class:`lcc_synth.mpc.formulation.Formulation` with one input per CAV (the
one condensed formulation for any number of CAVs); this module gives it the platoon's
discrete model, stage weights, steady direction and terminal cost.

Prediction model: the platoon model of :mod:`lcc_synth.models.platoon` (one input column per
CAV, each HDV linearised at its own equilibrium) discretised exactly (ZOH) at ``Ts``::

    x_{k+1} = Ad x_k + Bd u_k + Hd d_k,       u_k = (u_{1,k} .. u_{nu,k}),  k = 0 .. N-1

(ring: ``Hd = 0``, no head). With ``prediction.cav_lag = tau > 0`` the state is ``[x; a_1 ..
a_nu]``, each CAV's acceleration lagging its command (``da_i/dt = (u_i - a_i) / tau``,
:func:`lcc_synth.models.lag.with_actuator_lag`), discretised exactly the same way; the ``a_i``
carry no weight and no steady-state offset, and on the ring the terminal cost's invariant
hyperplane is extended by them (they do not change the total spacing). Checked against the
lagged ODE integrated by scipy and against the single-CAV lag-aware MPC on a platoon with one
CAV (``tests/test_mpc_layouts.py``). With ``prediction.delay`` the state is augmented with the
HDVs' delay register instead (:func:`joint_delay_model`; measured against the delay differential
equation: 0.16 % of the response for 0.4 s on an open platoon, 0.36 % for 0.45 s on a ring); the
two in one prediction are a ConfigError. Each CAV's input is its whole acceleration (eq. 9), so
the input constraint is on ``u`` itself. The QP is condensed, with the same structure as the
single-CAV QP of :mod:`lcc_synth.mpc.formulation` (one CAV: the same variables, rows and order):
``z = [u_0 .. u_{N-1}, e_1 .. e_{F N}]`` (``u_k`` the ``nu`` CAV inputs of step ``k``, one
spacing slack per CAV and step, family-major), and

    min  sum_{k=1}^{N-1} r_k' Q r_k + r_N' P r_N + w_u sum_k |u_k|^2 + w_j sum_k |u_k - u_{k-1}|^2
         + rho_1 sum e + rho_2 sum e^2,       r_k = x_k - x_dir d_k
    s.t. a_min,i <= u_{i,k} <= a_max,i                       (hard, every CAV and step)
         s_{i,k} - t_gap v_{i,k} + e_{i,k} >= b_{i,k}        (soft spacing of CAV i, k = 1..N)
         e >= 0
         |u_{i,k} - u_{i,k-W}| <= J_i W Ts                   (comfort, per CAV; option)

Rows: the ``N nu`` input rows (step-major), the ``F N`` spacing rows, the ``F N`` slack rows,
then the ``N nu`` comfort rows (step-major). ``Q`` weighs every velocity error
(``weights.velocity``), every HDV's spacing error (``weights.spacing``) and every CAV's
(``weights.spacing_cav``). ``x_dir d`` is the platoon's steady state when the head's velocity
error is ``d`` (every velocity error ``d``, spacing errors ``(alpha2 - alpha3)/alpha1 d`` with
each vehicle's own coefficients); zero on the ring.

The step parameter is ``p = [x_0, d_0..d_{N-1}, u_{-1} (nu), c_{-1} (nu) .. c_{-W} (nu)]``
(``c_{-j}`` the commands applied ``j`` samples ago, newest first); ``q = Qp p + q0`` and the
constraint offset ``Gp p + g0`` are affine in it, as in the single-CAV QP.

**Terminal cost.** ``P`` solves the discrete Riccati equation of the stage cost with
``R = w_u I``. On the ring the total spacing ``c x`` is conserved (``c Ad = c``, ``c Bd = 0``):
an eigenvalue 1 of ``Ad`` that no input reaches. Weighted by ``Q`` it would make the Riccati
equation unsolvable, so ``P`` is solved on the invariant hyperplane ``c x = 0``
(``V = PlatoonModel.invariant_basis()``: ``P = V P_r V'``, ``P_r`` from ``(V'Ad V, V'Bd,
V'QV)``); the controller projects the measured error state onto the hyperplane, where the
prediction stays (``c x_k = c x_0 = 0`` for every input), so the QP never sees the conserved
coordinate (see :mod:`lcc_synth.mpc.joint`). Measured: the ring Riccati residual on the
hyperplane is at round-off (2e-13), ``|P c| <= 1e-14``.

Measured (``benchmarks/bench_mpc_platoon.py``, N = 50, 2 shared cores): building the
formulation and the Riccati solution takes about 0.1 s for the two-CAV 8-vehicle platoon (200
variables, 400 rows) and 0.07 s for the 20-vehicle ring with one AV (100 variables, 200 rows).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg as sla

from lcc_synth.errors import ConfigError
from lcc_synth.models.lag import with_actuator_lag
from lcc_synth.models.platoon import Platoon, PlatoonModel, discretize, platoon_model
from lcc_synth.mpc.delay import DelayModel, delay_model, delay_samples, pad
from lcc_synth.mpc.formulation import riccati
from lcc_synth.mpc.settings import MPCSettings
from lcc_synth.resources import single_thread_blas

__all__ = [
    "JointLinearization",
    "joint_state_weights",
    "joint_terminal_cost",
    "joint_steady_direction",
    "linearize_joint",
    "joint_delay_model",
]


@dataclass(frozen=True, eq=False)
class JointLinearization:
    """The discrete prediction model of a platoon at one equilibrium velocity ``v_lin``.

    ``Bd`` is ``(nx, nu)`` (one column per CAV), ``Hd`` ``(nx,)`` (zero on a ring).
    """

    v_lin: float
    model: PlatoonModel
    Ad: np.ndarray
    Bd: np.ndarray
    Hd: np.ndarray
    P: np.ndarray
    x_dir: np.ndarray
    cav_lag: float = 0.0  # > 0: the last nu states are the CAVs' accelerations
    delay: DelayModel | None = None  # prediction.delay: the matrices are the augmented ones

    def predict(self, x0: np.ndarray, d: np.ndarray, U: np.ndarray) -> np.ndarray:
        """Predicted states ``(N+1, nx)`` for inputs ``U`` ``(N, nu)`` and head errors ``d``."""
        U = np.asarray(U, float).reshape(len(d), -1)
        X = np.empty((len(d) + 1, x0.size))
        X[0] = x0
        for k in range(len(d)):
            X[k + 1] = self.Ad @ X[k] + self.Bd @ U[k] + self.Hd * d[k]
        return X


def joint_state_weights(model: PlatoonModel, settings: MPCSettings) -> np.ndarray:
    """Diagonal of ``Q``: ``velocity`` on every ``v_i``, ``spacing`` on every HDV's ``s_i`` and
    ``spacing_cav`` on every CAV's."""
    w = settings.weights
    q = np.empty(model.nx)
    cavs = set(model.cavs)
    for i in range(1, model.platoon.size + 1):
        q[2 * i - 2] = w.cav_spacing if i in cavs else w.spacing
        q[2 * i - 1] = w.velocity
    return q


def joint_steady_direction(model: PlatoonModel) -> np.ndarray:
    """``x_dir``: the platoon's equilibrium error state per unit head-velocity error (each
    vehicle's own ``(alpha2 - alpha3) / alpha1``; zero on a ring, which has no head)."""
    x = np.zeros(model.nx)
    if model.ring:
        return x
    for i, c in enumerate(model.coefficients):
        x[2 * i] = (c.alpha2 - c.alpha3) / c.alpha1
        x[2 * i + 1] = 1.0
    return x


def joint_terminal_cost(model: PlatoonModel, Ad: np.ndarray, Bd: np.ndarray, q: np.ndarray,
                          r: float) -> np.ndarray:
    """Terminal weight ``P`` of the stage cost ``x'diag(q)x + r |u|^2`` (discrete Riccati).

    On a ring it is solved on the invariant hyperplane of the conserved total spacing
    (module docstring); ``P`` then has ``P c = 0``.

    Raises
    ------
    ConfigError
        When the Riccati equation has no stabilising solution.
    """
    V = model.invariant_basis()
    if Ad.shape[0] > V.shape[0]:  # lag states or delay register: untouched by the conservation
        V = sla.block_diag(V, np.eye(Ad.shape[0] - V.shape[0]))
    A_r = V.T @ Ad @ V
    B_r = V.T @ Bd
    Q_r = V.T @ np.diag(q) @ V
    Q_r = 0.5 * (Q_r + Q_r.T)
    P = V @ riccati(A_r, B_r, Q_r, r * np.eye(Bd.shape[1])) @ V.T
    return 0.5 * (P + P.T)


def linearize_joint(platoon: Platoon, v_lin: float, settings: MPCSettings
                      ) -> JointLinearization:
    """The platoon linearised at ``v_lin`` (every vehicle at its own equilibrium spacing) and
    its discrete prediction model and terminal cost."""
    with single_thread_blas():
        if float(v_lin) != float(platoon.v_star):
            platoon = replace(platoon, v_star=float(v_lin), circumference=None)
        model = platoon_model(platoon, warn=False)
        q, x_dir = joint_state_weights(model, settings), joint_steady_direction(model)
        tau = float(settings.prediction.cav_lag)
        delayed = np.any(np.asarray(settings.prediction.delay, dtype=float) != 0.0)
        dm = None
        if tau and delayed:
            raise ConfigError("prediction.cav_lag", "cannot be combined with prediction.delay "
                              "(HDV delays) in one prediction; give one of them")  # fmt: skip
        if delayed:
            dm = joint_delay_model(model, settings.prediction.delay, settings.sample_time)
        if dm is not None:  # the HDVs' delay register (lcc_synth.mpc.delay)
            Ad, Bd, Hd = dm.Ad, dm.Bd, dm.Hd
            q, x_dir = pad(q, Ad.shape[0]), pad(x_dir, Ad.shape[0])
        elif tau == 0.0:
            Ad, Bd, Hd = model.discretize(settings.sample_time)
        else:  # each CAV's acceleration a_i appended to the state (module docstring)
            lag = with_actuator_lag(model.A, model.B, model.H,
                                    [model.index(f"v_{i}") for i in model.cavs], tau,
                                    model.state_names)  # fmt: skip
            Ad, BH = discretize(lag.A, np.hstack([lag.B, lag.H]), settings.sample_time)
            Bd, Hd = BH[:, : lag.B.shape[1]], BH[:, lag.B.shape[1]:]
            q, x_dir = pad(q, Ad.shape[0]), pad(x_dir, Ad.shape[0])
        P = joint_terminal_cost(model, Ad, Bd, q, settings.weights.input)
    return JointLinearization(float(v_lin), model, Ad, Bd, Hd[:, 0].copy(), P, x_dir, tau, dm)


def joint_delay_model(model: PlatoonModel, delay, Ts: float) -> DelayModel | None:
    """The delayed discrete model of a platoon or ring whose HDVs react ``delay`` seconds late
    (one value, or one per HDV front to tail, positions ``1..N`` without the CAVs); ``None``
    when every delay is 0.

    The delayed rows are the HDVs' velocity rows (eq. 8, as in
    :func:`~lcc_synth.mpc.delay.lcc_delay_model`); the register keeps their structural
    entries: ``s_i``, ``v_i`` and the velocity of the vehicle ahead (``d`` behind the head,
    ``v_N`` for position 1 of a ring).
    """
    N, nx = model.platoon.size, model.nx
    hdvs = [i for i in range(1, N + 1) if i not in model.cavs]
    samples = delay_samples(delay, hdvs, Ts)
    row = np.zeros(nx)
    cols: set[int] = set()
    for i in hdvs:
        j = i - 1
        if samples[i] > 0:
            row[2 * j + 1] = samples[i]
            ahead = 2 * j - 1 if j > 0 else (2 * N - 1 if model.ring else nx)
            cols.update((2 * j, 2 * j + 1, ahead))
    if not np.any(row):
        return None
    return delay_model(model.A, model.B, model.H, row, Ts, np.array(sorted(cols)))
