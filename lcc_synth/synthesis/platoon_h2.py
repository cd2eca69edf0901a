"""Multi-input H2 for mixed platoons and the ring road: plant, true H2, Riccati, derivatives.

The platoon design plant
------------------------
For a :class:`~lcc_synth.models.platoon.PlatoonModel` ``dx = A x + B u + H v_h`` (one input
column per CAV) and a gain semantics (:meth:`~lcc_synth.models.platoon.PlatoonGains.
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
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from lcc_synth.errors import ConfigError
from lcc_synth.models.platoon import SEMANTICS, PlatoonGains, PlatoonModel
from lcc_synth.synthesis.h2 import STABILITY_TOL, SynthesisError, Weights, single_thread_blas
from lcc_synth.synthesis.lyapunov import ClosedLoopSchur, closed_loop_schur

__all__ = [
    "PlatoonPlant",
    "make_platoon_plant",
    "H2Eval",
    "platoon_cost",
    "platoon_gradient",
    "platoon_hessian",
    "platoon_h2",
    "platoon_riccati",
    "check_platoon_stabilisable",
    "pattern_rows",
]


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

    @property
    def nx(self) -> int:
        """Number of (full) states."""
        return self.A.shape[0]

    @property
    def n_in(self) -> int:
        """Number of CAV inputs."""
        return self.B.shape[1]

    @property
    def ring(self) -> bool:
        """Whether the plant is a ring (reduced to the invariant subspace)."""
        return self.model.ring

    def with_basis(self, V: np.ndarray) -> PlatoonPlant:
        """The same plant reduced with another orthonormal basis ``V`` of the same subspace
        (for the basis-independence check)."""
        return _reduced(self, np.asarray(V, float))

    def gains(self, K: np.ndarray) -> PlatoonGains:
        """The :class:`PlatoonGains` (semantics of the plant) of design gain ``K``."""
        return PlatoonGains(np.asarray(K, float), self.model.cavs, self.semantics)

    def input_feedback(self, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(Ku, ku_h)``: the CAV inputs ``u = Ku x + ku_h v_h`` of design gain ``K``."""
        return self.gains(K).input_feedback(self.model)

    def closed_loop(self, K: np.ndarray) -> np.ndarray:
        """Reduced closed loop ``A_r + B_r K V``."""
        return self.Ar + self.Br @ (np.asarray(K, float) @ self.V)


def _reduced(p: PlatoonPlant, V: np.ndarray) -> PlatoonPlant:
    return PlatoonPlant(
        p.model, p.semantics, p.weights, p.A, p.B, p.Bw, p.Q, p.r, p.w_names, p.K0, p.kh0, V,
        V.T @ p.A @ V, V.T @ p.B, V.T @ p.Bw, V.T @ p.Q @ V,
    )  # fmt: skip


def make_platoon_plant(
    model: PlatoonModel, semantics: str = "replace", weights: Weights | None = None
) -> PlatoonPlant:
    """Build the :class:`PlatoonPlant` of ``model`` under ``semantics`` and ``weights``.

    ``weights.position`` / ``q_p`` (FD-LCC only) are ignored; ``weights.head`` needs a head
    vehicle (an open platoon).

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
    n_in = len(model.cavs)
    K0, kh0 = PlatoonGains(np.zeros((n_in, model.nx)), model.cavs, semantics).input_feedback(
        model
    )
    A = model.A + model.B @ K0
    H_eff = (model.H + model.B @ kh0[:, None]).ravel()
    names = model.state_names
    cols, w_names = [], []
    if weights.head > 0 and np.any(H_eff != 0):
        cols.append(weights.head * H_eff)
        w_names.append("v_h")
    if weights.accel > 0:
        for j, nm in enumerate(names):
            if nm.startswith("v_"):
                col = np.zeros(model.nx)
                col[j] = weights.accel
                cols.append(col)
                w_names.append(f"a_{nm[2:]}")
    if not cols:
        raise ConfigError("synthesis.weights", "head and accel disturbance weights are both 0 "
                          "(or the head disturbance reaches no state): nothing to design for")
    Bw = np.column_stack(cols)
    cav_states = {f"s_{i}" for i in model.cavs}
    q = np.array([weights.cav_spacing if nm in cav_states
                  else (weights.q_s if nm.startswith("s_") else weights.q_v) for nm in names])
    Q = np.diag(q)
    if weights.q_a > 0:
        hdv_v = [model.index(f"v_{i}") for i in range(1, model.platoon.size + 1)
                 if i not in model.cavs]  # fmt: skip
        Ca = A[hdv_v]
        Q = Q + weights.q_a * (Ca.T @ Ca)
    V = model.invariant_basis()
    full = PlatoonPlant(model, semantics, weights, A, model.B.copy(), Bw, Q, float(weights.r),
                        tuple(w_names), K0, kh0, V, A, model.B, Bw, Q)  # fmt: skip
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


def check_platoon_stabilisable(plant: PlatoonPlant, tol: float = 1e-9) -> None:
    """Every uncontrollable mode of the reduced ``(A_r, B_r)`` (Kalman decomposition) must have
    ``Re < -tol``; else :class:`SynthesisError` naming the mode (on the ring the conserved
    total-spacing mode is not part of the reduced plant and never counts)."""
    from lcc_synth.analysis.staircase import uncontrollable_modes

    where = " on the ring's invariant subspace (c x = 0)" if plant.ring else ""
    for lam in uncontrollable_modes(plant.Ar, plant.Br):
        if lam.real >= -tol:
            raise SynthesisError(
                f"the plant is not stabilisable{where}: mode {lam:.4g} is not controllable "
                "from the CAVs", {"mode": [lam.real, lam.imag]},
            )  # fmt: skip


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
        check_platoon_stabilisable(plant)
        raise SynthesisError(f"Riccati solver failed: {err}") from None
    Kr = -(plant.Br.T @ P) / plant.r
    mre = float(np.max(np.linalg.eigvals(plant.Ar + plant.Br @ Kr).real))
    if not (np.all(np.isfinite(Kr)) and mre < -STABILITY_TOL):
        check_platoon_stabilisable(plant)
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
