"""Controllability and observability of LCC systems (Section III-A/C, Theorems 1-4, Cor. 1-5).

Why not the textbook tests
--------------------------
Identical (or similar) vehicle blocks give ``A`` eigenvalues of high algebraic multiplicity with
long Jordan chains. Computed eigenvalues of such a matrix scatter by about ``eps**(1/k)`` for a
chain of length ``k``, so the PBH test ``rank [lambda I - A, B]`` at *computed* eigenvalues
decides on a matrix that is not the one of the theorem, and the Kalman matrix
``[B, AB, A^2 B, ...]`` has columns whose norms span many orders of magnitude, so its numerical
rank is meaningless beyond ~20 states. Both give wrong verdicts on these models (see
``tests/test_controllability.py``).

Method
------
1. Structural split (exact): states that cannot be reached from the input in the directed
   graph of ``A`` (edge ``j -> i`` when ``A[i, j] != 0``) span an uncontrollable subspace
   exactly, without rounding: a permutation separates them (the HDVs ahead of the CAV,
   Theorem 2 / Corollary 2). Without this step the round-off of the orthogonal steps below is
   amplified along long chains of similar vehicles: on the general LCC with m = 5, n = 15 a
   coupling that is exactly zero came out at 1e-10, above any eps-based tolerance.
2. The controllability staircase form (Van Dooren 1981; Varga's ``AB01ND`` / ``TB01PD``) of
   the reachable part: an orthogonal transformation ``T`` built one block at a time. At step
   ``k`` the part of the input direction not yet reached is compressed by an SVD; singular
   values below the tolerance count as zero and the other ``r_k`` directions join the
   controllable subspace. ``T.T @ A @ T`` is then block upper triangular
   ``[[A_c, A_12], [0, A_u]]`` and ``T.T @ B = [[B_c], [0]]``; the first ``n_c`` columns of ``T``
   are an orthonormal basis of the controllable subspace. Every step is orthogonal (backward
   stable), and the rank decisions compare the *couplings* between successive blocks (O(1)
   numbers such as 1, alpha3 or combinations of the alphas) with the tolerance, never a
   power of ``A``.

Default tolerance: ``tol = TOLERANCE_FACTOR * nx * eps * max(||A||_F, ||B||_F, 1)`` with
``TOLERANCE_FACTOR = 100``: a coupling at or below it is zero. Measured on random valid models
(heterogeneous alpha1 in [0.05, 3], alpha3 in [0.1, 2], alpha2 - alpha3 in [0.1, 2],
``|eq. 13| > 0.05``): for m <= 5, n <= 15 the kept couplings are >= 1e-4 and the dropped ones
(exactly zero in exact arithmetic) <= 3e-13 against tol ~ 1e-11; violating eq. (13) gives dropped
couplings ~ 1e-16 against kept ones >= 0.1 up to n = 30. The gap closes for long heterogeneous
strings (m <= 10, n <= 40: kept couplings down to 6e-11, dropped up to 6e-12, tol ~ 5e-11):
such systems are within round-off of a different rank, and the reports say so through
``decision_margin``.

Observability is controllability of the dual pair ``(A.T, C.T)``: the observable subspace is the
row space of the observability matrix, i.e. the orthogonal complement of the unobservable
subspace; the state ``e_i^T x`` can be reconstructed from the output iff ``e_i`` lies in it.

Vehicle classification
----------------------
Vehicle ``i``'s two coordinate directions (its spacing/position and velocity errors) are *in* the
subspace when both project onto it with residual ``||(I - Q Q^T) e|| <= membership_tol`` (default
``1e-8``), *outside* when the subspace is orthogonal to both (``||Q^T e|| <= membership_tol``),
*partial* otherwise (e.g. FD-LCC with the output ``v_k``: ``v_0`` is observable, ``-p_0`` not).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.linear import LCCModel

__all__ = [
    "TOLERANCE_FACTOR",
    "MEMBERSHIP_TOL",
    "default_tolerance",
    "structural_split",
    "Staircase",
    "kalman_decomposition",
    "uncontrollable_modes",
    "controllable_subspace",
    "observable_subspace",
    "SubspaceReport",
    "ControllabilityReport",
    "ObservabilityReport",
    "controllability_report",
    "observability_report",
    "default_outputs",
]

TOLERANCE_FACTOR = 100.0
MEMBERSHIP_TOL = 1e-8


def default_tolerance(A: np.ndarray, B: np.ndarray) -> float:
    """Rank tolerance ``TOLERANCE_FACTOR * nx * eps * max(||A||_F, ||B||_F, 1)``."""
    nx = A.shape[0]
    scale = max(np.linalg.norm(A, "fro"), np.linalg.norm(B, "fro"), 1.0)
    return float(TOLERANCE_FACTOR * nx * np.finfo(float).eps * scale)


def _check_pair(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    if B.ndim == 1:
        B = B.reshape(-1, 1)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ConfigError("A", f"must be a square matrix, got shape {A.shape}")
    if B.ndim != 2 or B.shape[0] != A.shape[0]:
        raise ConfigError("B", f"must have {A.shape[0]} rows, got shape {B.shape}")
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
        raise ConfigError("A", "A and B must be finite")
    return A, B


def structural_split(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split the state indices into those reachable from the input in the graph of ``A``.

    Edge ``j -> i`` when ``A[i, j] != 0``; the search starts at the rows where ``B`` is non-zero.
    The unreachable states ``U`` satisfy ``A[U, R] == 0`` and ``B[U] == 0`` exactly, so they span
    an uncontrollable subspace found without any rounding (e.g. the HDVs ahead, Theorem 2).

    Returns
    -------
    reachable, unreachable : int arrays of state indices (ascending).
    """
    A, B = _check_pair(A, B)
    nx = A.shape[0]
    seen = np.zeros(nx, dtype=bool)
    frontier = np.flatnonzero(np.any(B != 0.0, axis=1))
    seen[frontier] = True
    nz = A != 0.0
    while frontier.size:
        nxt = np.flatnonzero(np.any(nz[:, frontier], axis=1) & ~seen)
        seen[nxt] = True
        frontier = nxt
    return np.flatnonzero(seen), np.flatnonzero(~seen)


@dataclass(frozen=True)
class Staircase:
    """Result of :func:`kalman_decomposition`.

    Attributes
    ----------
    T : (nx, nx) orthogonal array
        ``T.T @ A @ T`` is block upper triangular with the controllable part ``A_c`` in its
        leading ``n_c x n_c`` block, ``T.T @ B`` is zero below row ``n_c``; the first ``n_c``
        columns of ``T`` are an orthonormal basis of the controllable subspace.
    n_c : int
        Dimension of the controllable subspace.
    steps : list of int
        Block sizes of the staircase (they sum to ``n_c``).
    min_accepted : float
        Smallest coupling singular value counted as non-zero (``inf`` if none).
    max_rejected : float
        Largest coupling singular value counted as zero (0 if none). The ratio
        ``min_accepted / max_rejected`` is the gap behind the rank decision.
    n_structural : int
        Number of states removed exactly by :func:`structural_split`.
    tol : float
        The rank tolerance used.
    """

    T: np.ndarray
    n_c: int
    steps: list[int]
    min_accepted: float
    max_rejected: float
    n_structural: int
    tol: float


def _reflectors(Y: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """Householder vectors ``(j, v)`` with ``H_0 ... H_{r-1} = Q`` whose first r columns span
    the (orthonormal) columns of ``Y``; ``H_j = I - 2 v v^T`` acts on rows ``j:``."""
    Y = Y.copy()
    out = []
    for j in range(Y.shape[1]):
        x = Y[j:, j]
        alpha = -np.copysign(np.linalg.norm(x), x[0])
        v = x.copy()
        v[0] -= alpha
        v /= np.linalg.norm(v)
        Y[j:, :] -= 2.0 * np.outer(v, v @ Y[j:, :])
        out.append((j, v))
    return out


def _staircase(A: np.ndarray, B: np.ndarray, tol: float):
    nx = A.shape[0]
    T = np.eye(nx)
    Ak = A.copy()  # transformed A; rows/columns from n_c on are still to be processed
    coupling = B.copy()  # what drives the not-yet-reached part of the state
    n_c = 0
    steps: list[int] = []
    min_acc, max_rej = np.inf, 0.0
    while n_c < nx and coupling.shape[1] > 0:
        U, sv, _ = np.linalg.svd(coupling, full_matrices=False)
        r = int(np.sum(sv > tol))
        if r:
            min_acc = min(min_acc, float(sv[r - 1]))
        if r < sv.size:
            max_rej = max(max_rej, float(sv[r]))
        if r == 0:
            break
        # Rotate the trailing coordinates (Householder reflections, O(nx^2) each) so that the
        # newly reached directions U[:, :r] come first.
        for j, v in _reflectors(U[:, :r]):
            k = n_c + j
            Ak[k:, :] -= 2.0 * np.outer(v, v @ Ak[k:, :])
            Ak[:, k:] -= 2.0 * np.outer(Ak[:, k:] @ v, v)
            T[:, k:] -= 2.0 * np.outer(T[:, k:] @ v, v)
        steps.append(r)
        new = slice(n_c, n_c + r)
        n_c += r
        coupling = Ak[n_c:, new]
    return T, n_c, steps, min_acc, max_rej


def kalman_decomposition(
    A: np.ndarray, B: np.ndarray, tol: float | None = None, structural: bool = True
) -> Staircase:
    """Orthogonal controllability staircase (Kalman) decomposition of ``(A, B)``.

    Parameters
    ----------
    A : (nx, nx) array
    B : (nx, nu) array
    tol : float, optional
        Coupling singular values at or below ``tol`` count as zero; default
        :func:`default_tolerance`.
    structural : bool
        First remove the states unreachable in the graph of ``A`` (exact, see
        :func:`structural_split`) and run the staircase on the rest. Without it the round-off
        of the orthogonal steps is amplified along long chains of similar vehicles (general LCC
        with m = 5, n = 15: a coupling that is exactly zero came out at 1e-10).

    Returns
    -------
    Staircase
    """
    A, B = _check_pair(A, B)
    nx = A.shape[0]
    tol = default_tolerance(A, B) if tol is None else float(tol)
    if structural:
        reach, unreach = structural_split(A, B)
    else:
        reach, unreach = np.arange(nx), np.arange(0)
    Tr, n_c, steps, min_acc, max_rej = _staircase(A[np.ix_(reach, reach)], B[reach], tol)
    T = np.zeros((nx, nx))
    T[np.ix_(reach, np.arange(reach.size))] = Tr
    T[unreach, reach.size + np.arange(unreach.size)] = 1.0
    return Staircase(T, n_c, steps, min_acc, max_rej, int(unreach.size), tol)


def uncontrollable_modes(
    A: np.ndarray, B: np.ndarray, tol: float | None = None, dec: Staircase | None = None
) -> np.ndarray:
    """Eigenvalues of the uncontrollable block ``A_u`` of the Kalman decomposition.

    ``(A, B)`` is stabilizable iff all have a negative real part. ``dec`` reuses a
    decomposition already computed with :func:`kalman_decomposition`.
    """
    A = np.asarray(A, dtype=float)
    dec = kalman_decomposition(A, B, tol) if dec is None else dec
    Au = dec.T[:, dec.n_c :].T @ A @ dec.T[:, dec.n_c :]
    return np.linalg.eigvals(Au) if Au.size else np.zeros(0, dtype=complex)


def controllable_subspace(A: np.ndarray, B: np.ndarray, tol: float | None = None) -> np.ndarray:
    """Orthonormal basis ``(nx, n_c)`` of the controllable subspace of ``(A, B)``."""
    dec = kalman_decomposition(A, B, tol)
    return dec.T[:, : dec.n_c]


def observable_subspace(A: np.ndarray, C: np.ndarray, tol: float | None = None) -> np.ndarray:
    """Orthonormal basis of the observable subspace (row space of the observability matrix).

    Computed as the controllable subspace of the dual pair ``(A.T, C.T)``.
    """
    C = np.atleast_2d(np.asarray(C, dtype=float))
    return controllable_subspace(np.asarray(A, dtype=float).T, C.T, tol)


# --------------------------------------------------------------------------------------------
# Reports on LCC models
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SubspaceReport:
    """Common part of the controllability / observability reports.

    Attributes
    ----------
    kind, m, n : model layout.
    rank : int
        Dimension of the controllable (observable) subspace.
    n_states : int
        Number of states of the model.
    vehicles_in_subspace : list of int
        Vehicles whose two states both lie in the subspace.
    vehicles_outside : list of int
        Vehicles whose two states are both orthogonal to the subspace.
    vehicles_partial : list of int
        The rest (one state in, or a mixed direction).
    basis : ndarray (n_states, rank)
        Orthonormal basis of the subspace.
    tolerance : float
        Rank tolerance of the staircase algorithm.
    min_accepted, max_rejected : float
        Smallest coupling kept / largest coupling dropped by the staircase (the gap behind
        the rank decision; see :class:`Staircase`).
    membership_tol : float
        Projection tolerance of the vehicle classification.
    """

    kind: str
    m: int
    n: int
    rank: int
    n_states: int
    vehicles_in_subspace: list[int]
    vehicles_outside: list[int]
    vehicles_partial: list[int]
    basis: np.ndarray = field(repr=False)
    tolerance: float
    min_accepted: float
    max_rejected: float
    membership_tol: float

    @property
    def decision_margin(self) -> float:
        """How far the rank decision is from the tolerance: ``min(min_accepted / tolerance,
        tolerance / max_rejected)`` (``inf`` when there was nothing to decide). Below ~10 the
        verdict is numerically fragile (the system is within round-off of a different rank)."""
        up = self.min_accepted / self.tolerance
        down = self.tolerance / self.max_rejected if self.max_rejected > 0 else np.inf
        return float(min(up, down))

    def _summary(self) -> dict:
        return {
            "kind": self.kind,
            "m": self.m,
            "n": self.n,
            "rank": int(self.rank),
            "n_states": int(self.n_states),
            "vehicles_in_subspace": [int(v) for v in self.vehicles_in_subspace],
            "vehicles_outside": [int(v) for v in self.vehicles_outside],
            "vehicles_partial": [int(v) for v in self.vehicles_partial],
            "tolerance": float(self.tolerance),
            "min_accepted_coupling": _finite_or_none(self.min_accepted),
            "max_rejected_coupling": float(self.max_rejected),
            "decision_margin": _finite_or_none(self.decision_margin),
        }

    def contains_state(self, model: LCCModel, name: str) -> bool:
        """Whether the coordinate direction of state ``name`` lies in the subspace."""
        e = np.zeros(self.n_states)
        e[model.index(name)] = 1.0
        res = e - self.basis @ (self.basis.T @ e)
        return bool(np.linalg.norm(res) <= self.membership_tol)


@dataclass(frozen=True)
class ControllabilityReport(SubspaceReport):
    """Controllable subspace of ``(A, B)``; ``controllable`` iff ``rank == n_states``.

    ``uncontrollable_eigenvalues`` are the eigenvalues of the uncontrollable block ``A_u`` of the
    Kalman decomposition (no input can move them); ``stabilizable`` iff all have a negative real
    part. Repeated eigenvalues of ``A_u`` come out scattered by round-off (see the module
    docstring), their real parts stay reliable to that scatter.
    """

    controllable: bool = False
    uncontrollable_eigenvalues: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def stabilizable(self) -> bool:
        """All uncontrollable modes are asymptotically stable."""
        return bool(np.all(self.uncontrollable_eigenvalues.real < 0))

    @property
    def uncontrollable_max_real(self) -> float | None:
        """Largest real part of an uncontrollable mode (``None`` when controllable)."""
        ev = self.uncontrollable_eigenvalues
        return float(ev.real.max()) if ev.size else None

    def as_dict(self) -> dict:
        """JSON-serialisable summary (no basis)."""
        return {
            "controllable": bool(self.controllable),
            "stabilizable": self.stabilizable,
            "uncontrollable_max_real": self.uncontrollable_max_real,
            **self._summary(),
        }


@dataclass(frozen=True)
class ObservabilityReport(SubspaceReport):
    """Observable subspace of ``(A, C)`` for the named state outputs."""

    outputs: list[str] = field(default_factory=list)
    observable: bool = False

    def as_dict(self) -> dict:
        """JSON-serialisable summary (no basis)."""
        return {
            "observable": bool(self.observable),
            "outputs": list(self.outputs),
            **self._summary(),
        }


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def _classify(
    model: LCCModel, basis: np.ndarray, membership_tol: float
) -> tuple[list[int], list[int], list[int]]:
    nx = model.nx
    eye = np.eye(nx)
    coords = basis.T @ eye  # (rank, nx): projection coefficients of every coordinate direction
    inside_res = np.linalg.norm(eye - basis @ coords, axis=0)  # residual of each e_i
    along = np.linalg.norm(coords, axis=0)  # length of each e_i's projection
    inside, outside, partial = [], [], []
    for vehicle in model.vehicles:
        b = model.block(vehicle)
        if np.all(inside_res[b] <= membership_tol):
            inside.append(vehicle)
        elif np.all(along[b] <= membership_tol):
            outside.append(vehicle)
        else:
            partial.append(vehicle)
    return inside, outside, partial


def controllability_report(
    model: LCCModel, tol: float | None = None, membership_tol: float = MEMBERSHIP_TOL
) -> ControllabilityReport:
    """Controllable subspace of the model's ``(A, B)`` and which vehicles it contains.

    Parameters
    ----------
    model : LCCModel
    tol : float, optional
        Staircase rank tolerance (default :func:`default_tolerance`).
    membership_tol : float
        Projection tolerance for the vehicle classification.

    Returns
    -------
    ControllabilityReport
        Theorem 2: for the general LCC the vehicles ahead are outside and the CAV and the
        vehicles behind inside (when eq. 13 holds); Theorem 1 / Corollary 1: FD/CF-LCC fully
        controllable; Corollary 2: for CCC only the CAV.
    """
    dec = kalman_decomposition(model.A, model.B, tol)
    fields = _subspace_fields(model, dec, membership_tol)
    return ControllabilityReport(
        **fields,
        controllable=fields["rank"] == model.nx,
        uncontrollable_eigenvalues=uncontrollable_modes(model.A, model.B, tol, dec),
    )


def _subspace_fields(model: LCCModel, dec: Staircase, membership_tol: float) -> dict:
    """The fields shared by the controllability and observability reports."""
    basis = dec.T[:, : dec.n_c]
    inside, outside, partial = _classify(model, basis, membership_tol)
    return dict(
        kind=model.kind,
        m=model.m,
        n=model.n,
        rank=basis.shape[1],
        n_states=model.nx,
        vehicles_in_subspace=inside,
        vehicles_outside=outside,
        vehicles_partial=partial,
        basis=basis,
        tolerance=dec.tol,
        min_accepted=dec.min_accepted,
        max_rejected=dec.max_rejected,
        membership_tol=membership_tol,
    )


def default_outputs(model: LCCModel, k: int | None = None) -> list[str]:
    """The paper's measurement set: ``C^(k)`` (eq. 21) or ``C_f^(k)`` (eq. 19).

    For the general LCC and CCC: the CAV's own ``s_0, v_0`` plus ``v_k`` (none for CCC);
    for FD-/CF-LCC: ``v_k`` only. ``k`` defaults to ``n`` (the tail).
    """
    k = model.n if k is None else int(k)
    if model.n > 0 and not 1 <= k <= model.n:
        raise ConfigError("k", f"must be in [1, {model.n}], got {k}")
    if model.kind in ("fd_lcc", "cf_lcc"):
        return [f"v_{k}"]
    names = ["s_0", "v_0"]
    if model.n > 0:
        names.append(f"v_{k}")
    return names


def observability_report(
    model: LCCModel,
    outputs: Sequence[str],
    tol: float | None = None,
    membership_tol: float = MEMBERSHIP_TOL,
) -> ObservabilityReport:
    """Observable subspace for the measured states ``outputs`` and which vehicles it contains.

    Parameters
    ----------
    model : LCCModel
    outputs : sequence of str
        Measured state names, e.g. ``["s_0", "v_0", "v_3"]`` (eq. 21) or ``["v_3"]`` (eq. 19);
        see :func:`default_outputs`.
    tol, membership_tol : float, optional
        As in :func:`controllability_report`.

    Returns
    -------
    ObservabilityReport
        Theorems 3/4: with ``v_k`` measured, the vehicles up to ``k`` are observable and
        ``k+1..n`` unobservable (outside).
    """
    outputs = [str(o) for o in outputs]
    if not outputs:
        raise ConfigError("outputs", "needs at least one measured state name")
    C = model.output_matrix(outputs)
    dec = kalman_decomposition(model.A.T, C.T, tol)
    fields = _subspace_fields(model, dec, membership_tol)
    return ObservabilityReport(**fields, outputs=outputs, observable=fields["rank"] == model.nx)
