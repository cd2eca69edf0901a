"""H2 synthesis set-up for LCC models: plant, weights, true H2 norm, Riccati and LMI designs.

The design plant
----------------
For an :class:`~lcc_synth.models.linear.LCCModel` ``dx = A x + B u + H v_h`` and a gain semantics
(``feedback.py``, eq. 23) the CAV's static gains ``g`` (a row on the model's states) act as

    input = (g + K0) x + kh0 v_h,     (K0, kh0) = feedback.input_feedback(model, zero gains)

so the synthesis works on the *design plant*

    dx = A_d x + B g x + B_w w,       A_d = A + B K0,
    z  = [Q^1/2 x ; R^1/2 g x]

and the designed row ``g`` IS the ``gains`` vector of the semantics (``u = +g x``, no minus
sign, as in ``feedback.py``). For ``"added"`` the CAV keeps its HDV law and ``g`` is added; for
``"replace"`` ``g`` is the whole command (CF-LCC then does not use ``v_h``: ``kh0 = -alpha3``).

Disturbances ``w`` (columns of ``B_w``, each scaled by its weight):

* ``head``  the head-vehicle velocity error ``v_h`` entering through ``H + B kh0``
  (absent in FD-LCC, which has no head vehicle);
* ``accel`` one acceleration-noise column on every velocity state (CAV included).

With the head disturbance alone ``B_w`` has rank one and the H2 cost only sees the part of
the state the disturbance excites: any two gains that differ only on directions outside the
controllable subspace of ``(A_d + B g, B_w)`` have the same cost, so the optimal gain is not
unique (FD-LCC: no head vehicle, every stabilising gain has cost 0). Keep ``accel > 0`` for a
unique optimum.

FD-LCC's position state ``-p_0`` is a pure integrator (zero open-loop eigenvalue) that feeds no
other state. ``position = "drop"`` (default) removes it from the design (its gain is 0, the
CAV's position drifts freely as in the paper's gains); ``position = "weight"`` keeps it with
weight ``q_p > 0`` so the gain also regulates the position and the closed loop is
asymptotically stable in every state.

In general LCC the vehicles ahead of the CAV are not controllable from ``u`` but stable (their
HDV blocks do not depend on anything behind them): the plant is stabilisable, the Riccati and
LMI designs work on the whole state, and the gains on the states ahead act as feed-forward.
:func:`check_stabilisable` verifies this (uncontrollable modes of the Kalman decomposition).
"""

from __future__ import annotations

import functools
import math
import weakref
from dataclasses import asdict, dataclass, field

import numpy as np
import scipy.linalg as sla

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import SEMANTICS, StaticGains, input_feedback
from lcc_synth.models.linear import LCCModel
from lcc_synth.models.records import Record
from lcc_synth.synthesis.lyapunov import closed_loop_schur

__all__ = [
    "SynthesisError",
    "Weights",
    "H2Plant",
    "make_plant",
    "check_stabilisable",
    "closed_loop_matrix",
    "max_real_eig",
    "h2_cost",
    "h2_cost_schur",
    "h2_norm",
    "riccati_gain",
    "LMIResult",
    "lmi_full_state",
    "STABILITY_TOL",
    "single_thread_blas",
]

def single_thread_blas(fn):
    """Run ``fn`` with single-threaded BLAS/LAPACK (threadpoolctl).

    The synthesis works on matrices of at most a few hundred rows, where OpenBLAS's threads cost
    far more than they gain: polishing an 82-state structured design took 9.8 s with the
    default threads on a loaded 2-core machine and 0.5 s with one thread.
    """

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            return fn(*args, **kwargs)

    return wrapper


#: a closed loop counts as stable when every eigenvalue has real part below ``-STABILITY_TOL``
STABILITY_TOL = 1e-9


class SynthesisError(RuntimeError):
    """A synthesis failed: solver failure, infeasibility or a non-stabilising result.

    The CLI prints it as one line and exits 1. ``details`` holds solver status, residuals and
    eigenvalue margins for the report.
    """

    def __init__(self, message: str, details: dict | None = None):
        self.details = dict(details or {})
        super().__init__(message)


@dataclass(frozen=True, repr=False)
class Weights(Record):
    """Performance and disturbance weights of the H2 problem.

    Attributes
    ----------
    q_s, q_v : float
        Weight on every spacing error / velocity error squared (``Q`` diagonal), > 0.
    q_s0 : float or None
        Weight on the CAV's own spacing error ``s_0`` (LCC, CF-LCC), > 0; ``None`` (default)
        = ``q_s``. The H2 cost measures errors from the fixed equilibrium ``v*`` and its
        disturbances are zero-mean noise, so it never sees a lasting change of the head
        vehicle's speed: after a speed change ``dv`` the CAV settles at the spacing error
        ``-(sum_i g_si s_e + dv sum_i g_vi) / g_s0`` (``s_e`` the HDVs' equilibrium spacing
        change), which only a stiff ``g_s0`` keeps small. Weighting ``s_0`` alone buys that
        stiffness without weighting the HDVs' spacings. No effect on FD-LCC (no ``s_0``).
    q_a : float
        Weight on every HDV's acceleration squared, >= 0 (``a_i`` is the HDV's velocity row of
        ``A``, linear in the state, so ``Q += q_a sum_i A_vi' A_vi`` stays a state weight; the
        head-velocity feed-through of the first HDV is left out). A smooth-driving proxy for
        fuel: the Bowyer fuel model charges accelerations and wastes hard braking.
    q_p : float
        Weight on FD-LCC's ``-p_0`` when ``position = "weight"`` (> 0 then).
    r : float
        Weight on the gain's input squared (``R``), > 0.
    head : float
        Standard deviation-like weight of the head-vehicle velocity disturbance, >= 0.
    accel : float
        Weight of the per-vehicle acceleration noise (every velocity state), >= 0.
    position : {"drop", "weight"}
        FD-LCC position-state handling (see module docstring).
    """

    q_s: float = 1.0
    q_v: float = 1.0
    q_a: float = 0.0
    q_p: float = 0.1
    r: float = 1.0
    head: float = 0.0
    accel: float = 1.0
    position: str = "drop"
    q_s0: float | None = None

    def __post_init__(self) -> None:
        for name in ("q_s", "q_v", "r"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(f"weights.{name}", f"must be a finite number > 0, got {v!r}")
        v = self.q_s0
        if v is not None and not (
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v > 0
        ):
            raise ConfigError("weights.q_s0", f"must be a finite number > 0, got {v!r}")
        for name in ("q_a", "q_p", "head", "accel"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"weights.{name}", f"must be a finite number >= 0, got {v!r}")
        if self.position not in ("drop", "weight"):
            raise ConfigError(
                "weights.position", f"must be 'drop' or 'weight', got {self.position!r}"
            )
        if self.head == 0 and self.accel == 0:
            raise ConfigError("weights", "head and accel disturbance weights cannot both be 0")

    @property
    def cav_spacing(self) -> float:
        """Weight of the CAV's own spacing error ``s_0`` (``q_s`` unless ``q_s0`` is set)."""
        return self.q_s if self.q_s0 is None else self.q_s0

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True, eq=False)
class H2Plant:
    """The design plant of the module docstring, on the kept states.

    Attributes
    ----------
    model : LCCModel
    semantics : str
    weights : Weights
    keep : numpy.ndarray
        Indices (into the model's states) of the design states.
    state_names : tuple of str
        Names of the design states.
    A, B, Bw : numpy.ndarray
        Design plant ``A_d``, input ``B`` (nx, 1), disturbances ``B_w`` (nx, nw).
    q : numpy.ndarray
        Diagonal state weights (``q_s``, ``q_s0`` on ``s_0``, ``q_v``, ``q_p``) on the design
        states.
    Q : numpy.ndarray
        The state weight ``diag(q) + q_a sum_i A_vi' A_vi`` (symmetric, banded).
    r : float
        ``R``.
    w_names : tuple of str
        Name of each disturbance column.
    K0 : numpy.ndarray
        ``(model.nx,)`` input feedback of the zero gain under the semantics.
    kh0 : float
        Head-velocity feed-through of the zero gain under the semantics.
    lag : float
        The CAV's actuator lag ``tau`` (s; 0: none). With ``tau > 0`` the design state ends with
        the CAV's acceleration ``a_0`` (:mod:`lcc_synth.models.lag`; not weighted, not in any
        pattern: the gain acts on the model's states, as the simulator's linear laws do).
    """

    model: LCCModel
    semantics: str
    weights: Weights
    keep: np.ndarray
    state_names: tuple[str, ...]
    A: np.ndarray
    B: np.ndarray
    Bw: np.ndarray
    q: np.ndarray
    Q: np.ndarray
    r: float
    w_names: tuple[str, ...]
    K0: np.ndarray
    kh0: float
    meta: dict = field(default_factory=dict)
    lag: float = 0.0

    @property
    def nx(self) -> int:
        return self.A.shape[0]

    def vehicle_of_state(self) -> np.ndarray:
        """Vehicle index (-m..n) of each design state (the lag state ``a_0``: ``n + 1``, a
        vehicle no pattern names)."""
        veh = np.repeat(np.array(self.model.vehicles), 2)
        if self.lag > 0:
            return np.append(veh[self.keep], self.model.n + 1)
        return veh[self.keep]

    def to_model_gain(self, g: np.ndarray) -> np.ndarray:
        """Gain row on the model's full state (dropped states get 0; the lag state's entry,
        0 on every pattern, is left out)."""
        full = np.zeros(self.model.nx)
        g = np.asarray(g, dtype=float).ravel()
        full[self.keep] = g[: self.keep.size] if self.lag > 0 else g
        return full

    def gains(self, g: np.ndarray) -> StaticGains:
        """The :class:`StaticGains` (semantics of the plant) realising design gain ``g``."""
        full = self.to_model_gain(g)
        names = self.model.state_names
        return StaticGains({names[i]: float(full[i]) for i in range(len(names))}, self.semantics)

    def input_feedback(self, g: np.ndarray) -> tuple[np.ndarray, float]:
        """``(K, kh)`` on the model's input, as ``feedback.input_feedback`` returns."""
        return self.to_model_gain(g) + self.K0, self.kh0


def make_plant(
    model: LCCModel, semantics: str = "replace", weights: Weights | None = None, lag: float = 0.0
):
    """Build the :class:`H2Plant` of ``model`` under ``semantics`` and ``weights`` (``lag``:
    the CAV's actuator lag, :func:`lcc_synth.models.lag.with_actuator_lag` on the design
    plant; the acceleration noise stays on the velocity rows, after the actuator)."""
    weights = weights or Weights()
    if semantics not in SEMANTICS:
        raise ConfigError("semantics", f"must be one of {list(SEMANTICS)}, got {semantics!r}")
    if semantics == "added" and model.kind == "fd_lcc":
        raise ConfigError(
            "synthesis.semantics",
            "'added' needs a vehicle ahead to follow with the HDV law; FD-LCC has none: "
            "use 'replace'",
        )
    K0, kh0 = input_feedback(model, StaticGains({}, semantics))
    A_full = model.A + model.B @ K0.reshape(1, -1)
    H_eff = (model.H + model.B * kh0).ravel()
    names = model.state_names
    keep = np.arange(model.nx)
    if model.kind == "fd_lcc" and weights.position == "drop":
        keep = keep[[nm != "-p_0" for nm in names]]
    elif model.kind == "fd_lcc" and weights.q_p <= 0:
        raise ConfigError("weights.q_p", "must be > 0 when weights.position = 'weight'")
    A = A_full[np.ix_(keep, keep)]
    B = model.B[keep]
    H_d = H_eff[keep]
    nd = len(keep)
    if lag > 0:
        from lcc_synth.models.lag import with_actuator_lag

        aug = with_actuator_lag(A, B, H_d, [list(keep).index(model.index("v_0"))], lag)
        A, B, H_d, nd = aug.A, aug.B, aug.H.ravel(), aug.nx
    cols, w_names = [], []
    if weights.head > 0 and np.any(H_d != 0):
        cols.append(weights.head * H_d)
        w_names.append("v_h")
    if weights.accel > 0:
        for j, i in enumerate(keep):
            if names[i].startswith("v_"):
                col = np.zeros(nd)
                col[j] = weights.accel
                cols.append(col)
                w_names.append(f"a_{names[i][2:]}")
    if not cols:
        raise ConfigError(
            "weights.head",
            f"{model.kind} has no head vehicle: the head disturbance alone leaves nothing to "
            "design for; set weights.accel > 0",
        )
    Bw = np.column_stack(cols)
    def state_weight(nm: str) -> float:
        if nm == "-p_0":
            return weights.q_p
        if nm == "s_0":
            return weights.cav_spacing
        return weights.q_s if nm.startswith("s_") else weights.q_v

    q = np.array([state_weight(names[i]) for i in keep] + [0.0] * (nd - len(keep)))
    Q = np.diag(q)
    if weights.q_a > 0:
        veh = np.repeat(np.array(model.vehicles), 2)[keep]
        rows = [j for j, i in enumerate(keep) if names[i].startswith("v_") and veh[j] != 0]
        Ca = A[rows]
        Q = Q + weights.q_a * (Ca.T @ Ca)
    return H2Plant(
        model=model,
        semantics=semantics,
        weights=weights,
        keep=keep,
        state_names=tuple(names[i] for i in keep) + ("a_0",) * (nd - len(keep)),
        A=A,
        B=B,
        Bw=Bw,
        q=q,
        Q=Q,
        r=float(weights.r),
        w_names=tuple(w_names),
        K0=K0,
        kh0=float(kh0),
        lag=float(lag),
    )


def check_stabilisable(plant: H2Plant, tol: float = 1e-9) -> None:
    """Every uncontrollable mode (Kalman decomposition,
    :mod:`lcc_synth.analysis.controllability`) must have Re < -tol; else :class:`SynthesisError`."""
    from lcc_synth.analysis.staircase import uncontrollable_modes

    for lam in uncontrollable_modes(plant.A, plant.B):
        if lam.real >= -tol:
            raise SynthesisError(
                f"the plant is not stabilisable: mode {lam:.4g} is not controllable from the CAV",
                {"mode": [lam.real, lam.imag]},
            )


def closed_loop_matrix(plant: H2Plant, g: np.ndarray) -> np.ndarray:
    """``A_K = A + B g`` of the design plant under the gain row ``g``."""
    return plant.A + plant.B @ np.asarray(g, dtype=float).reshape(1, -1)


def max_real_eig(M: np.ndarray) -> float:
    """Largest real part of the eigenvalues of ``M`` (stable below 0)."""
    return float(np.max(np.linalg.eigvals(M).real))


def h2_cost(plant: H2Plant, g: np.ndarray) -> tuple[float, np.ndarray | None, np.ndarray | None]:
    """True squared H2 norm ``J(g)`` from ``w`` to ``z`` with the controllability Gramian ``L``
    and observability Gramian ``P`` of the closed loop (``inf, None, None`` if unstable).

    ``A_K L + L A_K' + B_w B_w' = 0``, ``A_K' P + P A_K + Q + g' R g = 0``,
    ``J = tr(B_w' P B_w) = tr((Q + g' R g) L)``.
    """
    J, L, P, _ = h2_cost_schur(plant, g)
    return J, L, P


def h2_cost_schur(plant: H2Plant, g: np.ndarray):
    """:func:`h2_cost` plus the closed loop's Schur form
    (:class:`~lcc_synth.synthesis.lyapunov.ClosedLoopSchur`, ``None`` if unstable) for further
    Lyapunov equations with the same closed loop (one factorisation for all of them)."""
    g = np.asarray(g, dtype=float).reshape(1, -1)
    AK = plant.A + plant.B @ g
    if not np.all(np.isfinite(AK)):
        return math.inf, None, None, None
    S = closed_loop_schur(AK)
    if S.max_real_eig >= -STABILITY_TOL:
        return math.inf, None, None, None
    L = S.solve(plant.Bw @ plant.Bw.T)
    Qk = plant.Q + plant.r * (g.T @ g)
    P = S.solve(Qk, transpose=True)
    J = float(np.trace(Qk @ L))
    if not math.isfinite(J) or J < 0:
        return math.inf, None, None, None
    return J, L, P, S


def h2_norm(plant: H2Plant, g: np.ndarray) -> float:
    """True closed-loop H2 norm ``sqrt(J(g))`` (``inf`` when the closed loop is not stable)."""
    J, _, _ = h2_cost(plant, g)
    return math.sqrt(J) if math.isfinite(J) else math.inf


#: Riccati solutions of the plants already solved (an H2Plant is immutable; a design asks for
#: the same plant's optimum two or three times, each with a stabilisability check).
_RICCATI_CACHE: weakref.WeakKeyDictionary[H2Plant, tuple[np.ndarray, np.ndarray]] = (
    weakref.WeakKeyDictionary()
)


def riccati_gain(plant: H2Plant) -> tuple[np.ndarray, np.ndarray]:
    """Unstructured H2-optimal gain ``g = -R^-1 B' P`` from the CARE; returns ``(g, P)``
    (solved once per plant; copies are returned)."""
    if plant not in _RICCATI_CACHE:
        _RICCATI_CACHE[plant] = _riccati(plant)
    g, P = _RICCATI_CACHE[plant]
    return g.copy(), P.copy()


@single_thread_blas
def _riccati(plant: H2Plant) -> tuple[np.ndarray, np.ndarray]:
    # A stabilising Riccati gain proves the plant stabilisable; the Kalman-decomposition check
    # (7.4 s of the 11 s at 402 states) only runs to name the mode when the CARE fails.
    try:
        P = sla.solve_continuous_are(plant.A, plant.B, plant.Q, np.array([[plant.r]]))
    except (np.linalg.LinAlgError, ValueError) as err:
        check_stabilisable(plant)
        raise SynthesisError(f"Riccati solver failed: {err}") from None
    g = -(plant.B.T @ P) / plant.r
    if not (np.all(np.isfinite(g))
            and max_real_eig(closed_loop_matrix(plant, g)) < -STABILITY_TOL):
        check_stabilisable(plant)
        raise SynthesisError("Riccati gain does not stabilise the plant")
    return g.ravel(), P


@dataclass
class LMIResult:
    """A gain from a convex (LMI) design with its bound and solver diagnostics."""

    g: np.ndarray
    bound: float
    status: str
    solve_time: float
    residual: float
    info: dict = field(default_factory=dict)


def _clarabel(prob) -> tuple[str, float | None, list]:
    """Solve ``prob`` with Clarabel (named explicitly; see STACK_NOTES: left to choose, cvxpy
    picks SCS); returns its status, value and every variable's value, which is what comes back
    from :func:`~lcc_synth.interrupts.call_in_child`."""
    import warnings

    import cvxpy as cp

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "solution may be inaccurate"
        try:
            prob.solve(solver=cp.CLARABEL)
        except cp.error.SolverError as err:
            return "solver_error", str(err), []
    return prob.status, prob.value, [v.value for v in prob.variables()]


def solve_checked(prob, what: str, hint: str = "") -> tuple[str, float, float]:
    """Solve a cvxpy problem with Clarabel (named explicitly); raise on failure.

    The solve runs in a forked child process (:func:`lcc_synth.interrupts.call_in_child`), so
    that Ctrl-C or SIGTERM stops it at once: cvxpy's compilation and Clarabel hold the
    interpreter lock for seconds at a time on large designs. The variables of ``prob`` get the
    solution's values (bit for bit those of an in-process solve).

    Accepts ``optimal`` and ``optimal_inaccurate`` (the caller checks the *result*: eigenvalues
    and the true H2 norm); anything else is a :class:`SynthesisError`.

    Returns
    -------
    status : str
    seconds : float
        Wall time of the solve.
    value : float
        The optimal value.
    """
    import time

    from lcc_synth.interrupts import call_in_child

    t0 = time.perf_counter()
    status, value, values = call_in_child(_clarabel, prob)
    if status == "solver_error":
        raise SynthesisError(
            f"{what}: Clarabel failed ({value}); the problem is probably infeasible or "
            f"badly conditioned{hint}",
            {"status": "solver_error"},
        )
    dt = time.perf_counter() - t0
    if status not in ("optimal", "optimal_inaccurate"):
        raise SynthesisError(f"{what}: solver status {status!r}{hint}", {"status": status})
    for var, val in zip(prob.variables(), values, strict=True):
        var.save_value(val)
    return status, dt, float(value)


def lmi_full_state(plant: H2Plant, eps: float = 1e-7) -> LMIResult:
    """Full-state H2 synthesis by the standard LMI (Clarabel).

    ``min tr(Q X) + R W`` over ``X > 0, Z, W`` with
    ``A X + X A' + B Z + Z' B' + B_w B_w' <= 0`` and ``[[W, Z], [Z', X]] >= 0``; then
    ``g = Z X^-1`` and ``J(g) <= tr(Q X) + R W``. The returned bound is its square root.
    """
    import cvxpy as cp

    nx = plant.nx
    X = cp.Variable((nx, nx), symmetric=True)
    Z = cp.Variable((1, nx))
    W = cp.Variable((1, 1), symmetric=True)
    M = plant.A @ X + X @ plant.A.T + plant.B @ Z + Z.T @ plant.B.T + plant.Bw @ plant.Bw.T
    cons = [X >> eps * np.eye(nx), -(M + M.T) / 2 >> 0, cp.bmat([[W, Z], [Z.T, X]]) >> 0]
    obj = cp.Minimize(cp.trace(plant.Q @ X) + plant.r * W[0, 0])
    prob = cp.Problem(obj, cons)
    status, dt, value = solve_checked(prob, "full-state H2 LMI")
    Xv, Zv = X.value, Z.value
    g = np.linalg.solve(Xv.T, Zv.T).T.ravel()
    Mv = plant.A @ Xv + Xv @ plant.A.T + plant.B @ Zv + Zv.T @ plant.B.T + plant.Bw @ plant.Bw.T
    residual = float(max(np.max(np.linalg.eigvalsh((Mv + Mv.T) / 2)), 0.0))
    return LMIResult(g, math.sqrt(max(value, 0.0)), status, dt, residual)
