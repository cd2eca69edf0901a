"""H2 synthesis set-up for every layout: plant, weights, true H2 norm, Riccati and LMI designs.

One CAV (:func:`make_plant`, a gain row ``g``) and a platoon or ring
(:func:`make_platoon_plant`, a gain row per CAV; the ring on its invariant hyperplane ``V``)
share the weights, the disturbances, the checks and the LMI designs
(:mod:`~lcc_synth.synthesis.lmi`); both plants are the same for one CAV (a test matches them
to 1e-9).

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

The platoon design plant
------------------------
For a :class:`~lcc_synth.models.platoon.PlatoonModel` ``dx = A x + B u + H v_h`` (one input
column per CAV) and a gain semantics (:meth:`~lcc_synth.models.feedback.Gains.
input_feedback`) the CAVs' gain rows ``K`` (``n_cav x nx``) act as
``u = (K0 + K) x + kh0 v_h`` (``"replace"``: ``K0 = 0``; ``"added"``: the CAVs' HDV-law rows),
so the synthesis works on

    dx = A_d x + B K x + B_w w,   A_d = A + B K0,    z = [Q^1/2 x ; R^1/2 K x],

``Q`` diagonal (``q_s`` on every spacing, ``q_s0`` on the CAVs' own, ``q_v`` on every
velocity) plus ``q_a`` times the HDVs' squared acceleration rows of ``A_d``, ``R = r I``.
Disturbances (columns of ``B_w``): ``accel`` on every velocity state (the CAVs included) and,
on an open platoon, ``head`` times the head-velocity column ``H + B kh0`` -- the same plant as
:func:`lcc_synth.synthesis.h2.make_plant` for one CAV (a test matches them to 1e-9).

The ring road
-------------
On the ring the total spacing ``c x`` is conserved for every gain (``c B = 0``) and no
disturbance excites it (``c B_w = 0``): the closed loop always has the eigenvalue 0 on the
direction ``c``, so the full-state H2 norm is NOT the quantity to compute -- the state never
leaves the hyperplane ``c x = 0``. With the orthonormal basis ``V`` of the hyperplane
(:meth:`~lcc_synth.models.platoon.PlatoonModel.invariant_basis`), ``x = V xi`` and

    A_r = V' A_d V,  B_r = V' B,  B_wr = V' B_w,  Q_r = V' Q V,  closed loop A_r + B_r K V;

stabilisability, stability and the H2 norm are those of the reduced system (open platoons:
``V = I``). ``K`` and ``K + k c`` (any column ``k``) act identically: a ring gain is defined
modulo the conserved direction. The value does not depend on the basis (a test rotates ``V``).

The cost and its derivatives
----------------------------
With ``A_K = A_r + B_r K V``: ``A_K L + L A_K' + B_wr B_wr' = 0``,
``A_K' P + P A_K + Q_r + V'K'RKV = 0``, ``J = tr(B_wr' P B_wr)`` (the squared H2 norm),
``dJ/dK = 2 (R K V + B_r' P) L V'`` and the exact Hessian on the free entries of a pattern
(two Lyapunov solves per free entry, all with one real Schur form of ``A_K``:
:mod:`~lcc_synth.synthesis.lyapunov`). Measured (2 shared cores, one BLAS thread): the
40-vehicle ring (79 reduced states), one cost + gradient 2.5 ms, the 22-entry Hessian 40 ms.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import asdict, dataclass, field

import numpy as np
import scipy.linalg as sla

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import SEMANTICS, Gains, input_feedback
from lcc_synth.models.lag import with_actuator_lag
from lcc_synth.models.linear import LCCModel
from lcc_synth.models.platoon import PlatoonModel
from lcc_synth.models.records import Record
from lcc_synth.resources import single_thread_blas
from lcc_synth.synthesis.lyapunov import ClosedLoopSchur, closed_loop_schur

__all__ = [
    "SynthesisError",
    "Weights",
    "H2Plant",
    "disturbances",
    "make_plant",
    "check_stabilisable",
    "closed_loop_matrix",
    "max_real_eig",
    "h2_cost",
    "h2_cost_schur",
    "h2_norm",
    "riccati_gain",
    "STABILITY_TOL",
    "PlatoonPlant",
    "make_platoon_plant",
    "H2Eval",
    "platoon_cost",
    "platoon_gradient",
    "platoon_hessian",
    "platoon_h2",
    "platoon_riccati",
    "pattern_rows",
]

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

    @property
    def Ar(self) -> np.ndarray:
        """The state matrix stability is judged on: one CAV's design plant is never reduced
        (a platoon's :attr:`PlatoonPlant.Ar` is, on a ring)."""
        return self.A

    @property
    def Br(self) -> np.ndarray:
        """The input matrix beside :attr:`Ar` (``B``)."""
        return self.B

    # what every design plant offers (this one: a gain row; PlatoonPlant: a row per CAV)
    Bwr = property(lambda self: self.Bw, doc="The disturbances beside :attr:`Ar` (``B_w``).")
    Qr = property(lambda self: self.Q, doc="The state weight beside :attr:`Ar` (``Q``).")
    V = property(lambda self: np.eye(self.nx), doc="Basis of the (unreduced) design state.")
    conserved = property(lambda self: None, doc="No conserved direction: the string is open.")

    def design_gain(self, K: np.ndarray) -> np.ndarray:
        """A gain in this plant's form: one row (``K.ravel()``)."""
        return np.asarray(K, dtype=float).ravel()

    def cost(self, g: np.ndarray) -> float:
        """Squared true H2 norm of ``g`` (``inf`` when not stable): :func:`h2_cost`."""
        return h2_cost(self, g)[0]

    def true_h2(self, g: np.ndarray) -> float:
        """True H2 norm of ``g``: :func:`h2_norm`."""
        return h2_norm(self, g)

    def polish_cost(self, g: np.ndarray):
        """``(J, L, P, S)`` of the polish: :func:`h2_cost_schur`."""
        return h2_cost_schur(self, g)

    def head_tail(self) -> tuple[np.ndarray, np.ndarray]:
        """``(h, c)``: the head-velocity input column and the tail-velocity output row of the
        design state (with the lag state ``a_0`` last); fd_lcc has no head vehicle."""
        model = self.model
        if model.kind == "fd_lcc":
            raise ConfigError("system.kind", "fd_lcc has no head vehicle: string stability is "
                              "undefined")  # fmt: skip
        if self.lag > 0:
            from lcc_synth.analysis.lag_string import lagged_lcc

            lag = lagged_lcc(model, self.lag)
            h = (lag.H + lag.B * self.kh0).ravel()[[*self.keep, model.nx]]
        else:
            h = (model.H + model.B * self.kh0).ravel()[self.keep]
        c = np.zeros(self.nx)
        c[list(self.keep).index(model.tail_velocity_index)] = 1.0
        return h, c

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

    def gains(self, g: np.ndarray) -> Gains:
        """The :class:`Gains` (semantics of the plant) realising design gain ``g``."""
        full = self.to_model_gain(g)
        names = self.model.state_names
        return Gains.named({names[i]: float(full[i]) for i in range(len(names))}, self.semantics)

    def input_feedback(self, g: np.ndarray) -> tuple[np.ndarray, float]:
        """``(K, kh)`` on the model's input, as ``feedback.input_feedback`` returns."""
        return self.to_model_gain(g) + self.K0, self.kh0


def disturbances(
    head: np.ndarray, names: list[str], nd: int, weights: Weights
) -> tuple[np.ndarray | None, tuple[str, ...]]:
    """The disturbance matrix ``B_w`` of every layout and the names of its columns.

    ``head`` times the head-velocity column ``head`` (when it reaches a state) and one
    ``accel`` column on every velocity state ``v_*`` of ``names`` (the design states, the CAVs'
    included; ``nd`` rows, more than ``len(names)`` with an actuator-lag state). ``None`` when
    both weights leave no column: the caller names its error.
    """
    cols, w_names = [], []
    if weights.head > 0 and np.any(head != 0):
        cols.append(weights.head * head)
        w_names.append("v_h")
    if weights.accel > 0:
        for j, nm in enumerate(names):
            if nm.startswith("v_"):
                col = np.zeros(nd)
                col[j] = weights.accel
                cols.append(col)
                w_names.append(f"a_{nm[2:]}")
    return (np.column_stack(cols) if cols else None), tuple(w_names)


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
    K0, kh0 = input_feedback(model, Gains.named({}, semantics))
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
        aug = with_actuator_lag(A, B, H_d, [list(keep).index(model.index("v_0"))], lag)
        A, B, H_d, nd = aug.A, aug.B, aug.H.ravel(), aug.nx
    Bw, w_names = disturbances(H_d, [names[i] for i in keep], nd, weights)
    if Bw is None:
        raise ConfigError(
            "weights.head",
            f"{model.kind} has no head vehicle: the head disturbance alone leaves nothing to "
            "design for; set weights.accel > 0",
        )
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


def check_stabilisable(plant: H2Plant | PlatoonPlant, tol: float = 1e-9) -> None:
    """Every uncontrollable mode (Kalman decomposition,
    :mod:`lcc_synth.analysis.controllability`) of the design plant -- one CAV: ``(A_d, B)``; a
    platoon or ring: the reduced ``(A_r, B_r)``, so that the ring's conserved total-spacing mode
    is not part of it and never counts -- must have Re < -tol; else :class:`SynthesisError`
    naming the mode."""
    from lcc_synth.analysis.staircase import uncontrollable_modes

    where = " on the ring's invariant subspace (c x = 0)" if plant.model.ring else ""
    who = "the CAV" if len(plant.model.cavs) == 1 else "the CAVs"
    for lam in uncontrollable_modes(plant.Ar, plant.Br):
        if lam.real >= -tol:
            raise SynthesisError(
                f"the plant is not stabilisable{where}: mode {lam:.4g} is not controllable "
                f"from {who}", {"mode": [lam.real, lam.imag]},
            )  # fmt: skip


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


@dataclass(frozen=True, eq=False)
class PlatoonPlant:
    """The design plant of the module docstring (full state and reduced to ``c x = 0``).

    Attributes
    ----------
    model : PlatoonModel
    semantics : str
    weights : Weights
    A, B, Bw, Q : numpy.ndarray
        ``A_d``, ``B`` (``nx x n_cav``), ``B_w``, ``Q`` on the full state.
    r : float
        ``R = r I``.
    w_names : tuple of str
        Name of each disturbance column.
    K0 : numpy.ndarray
        ``(n_cav, nx)`` input feedback of the zero gain under the semantics.
    kh0 : numpy.ndarray
        ``(n_cav,)`` head-velocity feed-through of the zero gain.
    V : numpy.ndarray
        Basis of the invariant subspace (identity for an open platoon).
    Ar, Br, Bwr, Qr : numpy.ndarray
        The reduced plant.
    lag : float
        The CAVs' actuator lag (s; 0: none): then ``nx = model.nx + n_cav`` (the ``a_i``, zero
        columns of ``K``; :meth:`model_gain` is ``K`` on the model's states).
    """

    model: PlatoonModel
    semantics: str
    weights: Weights
    A: np.ndarray
    B: np.ndarray
    Bw: np.ndarray
    Q: np.ndarray
    r: float
    w_names: tuple[str, ...]
    K0: np.ndarray
    kh0: np.ndarray
    V: np.ndarray
    Ar: np.ndarray
    Br: np.ndarray
    Bwr: np.ndarray
    Qr: np.ndarray
    lag: float = 0.0

    @property
    def nx(self) -> int:
        """Number of (full) states (the lag states included)."""
        return self.A.shape[0]

    @property
    def conserved(self) -> np.ndarray | None:
        """The ring's conserved ``c`` on the plant's state (0 on the lag states); else None."""
        c = self.model.conserved
        return None if c is None else np.concatenate([c, np.zeros(self.nx - c.size)])

    def model_gain(self, K: np.ndarray) -> np.ndarray:
        """The design gain ``K`` on the model's states (without the lag states' columns)."""
        return np.asarray(K, float).reshape(self.n_in, self.nx)[:, : self.model.nx]

    @property
    def n_in(self) -> int:
        """Number of CAV inputs."""
        return self.B.shape[1]

    def design_gain(self, K: np.ndarray) -> np.ndarray:
        """A gain in this plant's form: a row per CAV (``K`` itself)."""
        return K

    def cost(self, K: np.ndarray) -> float:
        """Squared true H2 norm of ``K`` (``inf`` when not stable): :func:`platoon_cost`."""
        return platoon_cost(self, K).J

    def true_h2(self, K: np.ndarray) -> float:
        """True H2 norm of ``K``: :func:`platoon_h2`."""
        return platoon_h2(self, K)

    def polish_cost(self, K: np.ndarray):
        """``(J, L, P, S)`` of the polish (an open platoon): :func:`platoon_cost`."""
        ev = platoon_cost(self, K)
        return ev.J, ev.L, ev.P, ev.S

    def vehicle_of_state(self) -> np.ndarray:
        """Position of each state's vehicle (a lag state: -1, a vehicle no pattern names)."""
        veh = np.repeat(np.array(self.model.vehicles), 2)
        return np.concatenate([veh, np.full(self.nx - veh.size, -1)])

    def head_tail(self) -> tuple[np.ndarray, np.ndarray]:
        """``(h, c)`` of the head-to-tail loop (:func:`~lcc_synth.analysis.transfer.
        head_to_tail_loop`; a ring has no head: ConfigError naming ``system.kind``)."""
        from lcc_synth.analysis.transfer import head_to_tail_loop

        _, h, c = head_to_tail_loop(self.model, self.K0, self.kh0)
        return h, c

    @property
    def ring(self) -> bool:
        """Whether the plant is a ring (reduced to the invariant subspace)."""
        return self.model.ring

    def with_basis(self, V: np.ndarray) -> PlatoonPlant:
        """The same plant reduced with another orthonormal basis ``V`` of the same subspace
        (for the basis-independence check)."""
        return _reduced(self, np.asarray(V, float))

    def gains(self, K: np.ndarray) -> Gains:
        """The :class:`Gains` (semantics of the plant) of design gain ``K``."""
        return Gains.on(self.model, self.model_gain(K), self.semantics)

    def input_feedback(self, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(Ku, ku_h)``: the CAV inputs ``u = Ku x + ku_h v_h`` of design gain ``K``."""
        return self.gains(K).input_feedback(self.model)

    def closed_loop(self, K: np.ndarray) -> np.ndarray:
        """Reduced closed loop ``A_r + B_r K V``."""
        return self.Ar + self.Br @ (np.asarray(K, float) @ self.V)


def _reduced(p: PlatoonPlant, V: np.ndarray) -> PlatoonPlant:
    return PlatoonPlant(
        p.model, p.semantics, p.weights, p.A, p.B, p.Bw, p.Q, p.r, p.w_names, p.K0, p.kh0, V,
        V.T @ p.A @ V, V.T @ p.B, V.T @ p.Bw, V.T @ p.Q @ V, p.lag,
    )  # fmt: skip


def make_platoon_plant(
    model: PlatoonModel, semantics: str = "replace", weights: Weights | None = None,
    lag: float = 0.0,
) -> PlatoonPlant:  # fmt: skip
    """Build the :class:`PlatoonPlant` of ``model`` under ``semantics`` and ``weights``.

    ``weights.position`` / ``q_p`` (FD-LCC only) are ignored; ``weights.head`` needs a head
    vehicle (an open platoon). ``lag`` (s; 0: none): every CAV's actuator lag, a state ``a_i``
    per CAV after the model's (:func:`lcc_synth.models.lag.with_actuator_lag` on the whole
    command, the HDV law of "added" too), unweighted, in no pattern, the identity in a ring's
    ``V`` (:mod:`lcc_synth.synthesis.lag_design`).

    Raises
    ------
    ConfigError
        Unknown semantics, a head disturbance on a ring, or no disturbance at all.
    """
    weights = weights or Weights()
    if semantics not in SEMANTICS:
        raise ConfigError("synthesis.semantics",
                          f"must be one of {list(SEMANTICS)}, got {semantics!r}")  # fmt: skip
    if model.ring and weights.head > 0:
        raise ConfigError("synthesis.weights.head", "a ring has no head vehicle: set it to 0")
    K0, kh0 = Gains.zero(model, semantics).input_feedback(model)
    A = model.A + model.B @ K0
    B = model.B.copy()
    H_eff = (model.H + model.B @ kh0[:, None]).ravel()
    names = model.state_names
    V = model.invariant_basis()
    if lag > 0:
        aug = with_actuator_lag(A, B, H_eff, [model.index(f"v_{i}") for i in model.cavs], lag,
                                names)  # fmt: skip
        A, B, H_eff = aug.A, aug.B, aug.H.ravel()
        V = sla.block_diag(V, np.eye(aug.nx - aug.nx0))
    nd = A.shape[0]
    Bw, w_names = disturbances(H_eff, names, nd, weights)
    if Bw is None:
        raise ConfigError("synthesis.weights", "head and accel disturbance weights are both 0 "
                          "(or the head disturbance reaches no state): nothing to design for")
    cav_states = {f"s_{i}" for i in model.cavs}
    q = np.array([weights.cav_spacing if nm in cav_states
                  else (weights.q_s if nm.startswith("s_") else weights.q_v) for nm in names]
                 + [0.0] * (nd - model.nx))  # fmt: skip
    Q = np.diag(q)
    if weights.q_a > 0:
        hdv_v = [model.index(f"v_{i}") for i in range(1, model.platoon.size + 1)
                 if i not in model.cavs]  # fmt: skip
        Ca = A[hdv_v]
        Q = Q + weights.q_a * (Ca.T @ Ca)
    full = PlatoonPlant(model, semantics, weights, A, B, Bw, Q, float(weights.r),
                        tuple(w_names), K0, kh0, V, A, B, Bw, Q, float(lag))  # fmt: skip
    return _reduced(full, V) if model.ring else full


@dataclass(frozen=True, eq=False)
class H2Eval:
    """The true squared H2 cost of a gain with the Gramians and Schur form that gave it.

    Attributes
    ----------
    J : float
        Squared H2 norm (``inf`` when the reduced closed loop is not stable).
    Kr : numpy.ndarray
        ``K V``.
    L, P : numpy.ndarray or None
        Controllability and observability Gramians of the reduced closed loop.
    S : ClosedLoopSchur or None
        Its real Schur form.
    max_real_eig : float
        Largest real part of its eigenvalues.
    """

    J: float
    Kr: np.ndarray
    L: np.ndarray | None
    P: np.ndarray | None
    S: ClosedLoopSchur | None
    max_real_eig: float

    @property
    def stable(self) -> bool:
        """Reduced closed loop stable (every eigenvalue below ``-STABILITY_TOL``)."""
        return math.isfinite(self.J)


def platoon_cost(plant: PlatoonPlant, K: np.ndarray) -> H2Eval:
    """True squared H2 norm of design gain ``K`` on the (reduced) plant."""
    K = np.asarray(K, float).reshape(plant.n_in, plant.nx)
    Kr = K @ plant.V
    Acl = plant.Ar + plant.Br @ Kr
    if not np.all(np.isfinite(Acl)):
        return H2Eval(math.inf, Kr, None, None, None, math.inf)
    S = closed_loop_schur(Acl)
    mre = S.max_real_eig
    if mre >= -STABILITY_TOL:
        return H2Eval(math.inf, Kr, None, None, None, mre)
    L = S.solve(plant.Bwr @ plant.Bwr.T)
    Qk = plant.Qr + plant.r * (Kr.T @ Kr)
    P = S.solve(Qk, transpose=True)
    J = float(np.trace(Qk @ L))
    if not (math.isfinite(J) and J >= 0):
        return H2Eval(math.inf, Kr, None, None, None, mre)
    return H2Eval(J, Kr, L, P, S, mre)


def platoon_h2(plant: PlatoonPlant, K: np.ndarray) -> float:
    """True closed-loop H2 norm ``sqrt(J)`` of ``K`` (``inf`` when not stable)."""
    J = platoon_cost(plant, K).J
    return math.sqrt(J) if math.isfinite(J) else math.inf


def platoon_gradient(plant: PlatoonPlant, ev: H2Eval) -> np.ndarray:
    """``dJ/dK = 2 (R K V + B_r' P) L V'`` (``n_cav x nx``) at a stable :class:`H2Eval`."""
    return 2.0 * ((plant.r * ev.Kr + plant.Br.T @ ev.P) @ ev.L) @ plant.V.T


def platoon_hessian(plant: PlatoonPlant, ev: H2Eval, free: np.ndarray) -> np.ndarray:
    """Exact Hessian of ``J`` on the free entries ``free`` (flat, row-major indices of ``K``).

    Along the unit direction ``D`` of entry ``(k, j)`` (``D_r = D V``, row ``k`` = ``V[j]``) the
    Gramians move by ``L'``, ``P'``: ``A_K L' + L' A_K' + B_r D_r L + L D_r' B_r' = 0``,
    ``A_K' P' + P' A_K + D_r' B_r' P + P B_r D_r + r (D_r' K_r + K_r' D_r) = 0``, and
    ``G' = 2 ((r D_r + B_r' P') L + (r K_r + B_r' P) L') V'``.
    """
    L, P, S, Kr, V, Br, r = ev.L, ev.P, ev.S, ev.Kr, plant.V, plant.Br, plant.r
    row = r * Kr + Br.T @ P
    PB = P @ Br
    Hs = np.empty((free.size, free.size))
    for c, f in enumerate(free):
        k, j = divmod(int(f), plant.nx)
        vj = V[j]
        BdL = np.outer(Br[:, k], vj @ L)
        dL = S.solve(BdL + BdL.T)
        M = np.outer(PB[:, k], vj) + r * np.outer(vj, Kr[k])
        dP = S.solve(M + M.T, transpose=True)
        dGr = 2.0 * ((Br.T @ dP) @ L + row @ dL)
        dGr[k] += 2.0 * r * (vj @ L)
        Hs[:, c] = (dGr @ V.T).ravel()[free]
    return 0.5 * (Hs + Hs.T)


@single_thread_blas
def platoon_riccati(plant: PlatoonPlant) -> tuple[np.ndarray, float, np.ndarray]:
    """Full-information H2 optimum from the CARE on the reduced plant.

    Returns
    -------
    K : numpy.ndarray
        ``(n_cav, nx)`` ``= -R^-1 B_r' P V'`` (on the ring the representative with no component
        along ``c``).
    J : float
        Its squared H2 norm ``tr(B_wr' P B_wr)`` from the Riccati solution.
    P : numpy.ndarray
        The stabilising CARE solution (reduced coordinates).

    Raises
    ------
    SynthesisError
        The CARE fails or its gain does not stabilise (the mode is then named).
    """
    R = plant.r * np.eye(plant.n_in)
    try:
        P = sla.solve_continuous_are(plant.Ar, plant.Br, plant.Qr, R)
    except (np.linalg.LinAlgError, ValueError) as err:
        check_stabilisable(plant)
        raise SynthesisError(f"Riccati solver failed: {err}") from None
    Kr = -(plant.Br.T @ P) / plant.r
    mre = float(np.max(np.linalg.eigvals(plant.Ar + plant.Br @ Kr).real))
    if not (np.all(np.isfinite(Kr)) and mre < -STABILITY_TOL):
        check_stabilisable(plant)
        raise SynthesisError("Riccati gain does not stabilise the plant", {"max_real_eig": mre})
    J = float(np.trace(plant.Bwr.T @ P @ plant.Bwr))
    return Kr @ plant.V.T, J, P


def pattern_rows(plant: PlatoonPlant, patterns: dict[int, tuple[int, ...]] | None) -> np.ndarray:
    """``(n_cav, nx)`` boolean mask: row ``k`` True on the two states of every vehicle CAV
    ``cavs[k]`` hears (``None``: every state)."""
    m = plant.model
    mask = np.zeros((plant.n_in, plant.nx), bool)
    for k, i in enumerate(m.cavs):
        heard = range(1, m.platoon.size + 1) if patterns is None else patterns[i]
        for v in heard:
            mask[k, m.block(v)] = True
    return mask
