"""Controllability and observability of every layout (Section III-A/C, Theorems 1-4, Cor. 1-5,
and their generalisation to several CAVs and the ring).

One report for any linear model of mixed traffic: the paper's one-CAV models
(:class:`~lcc_synth.models.linear.LCCModel`: general LCC, CF-LCC, FD-LCC, CCC) and platoons with
several CAVs or a ring (:class:`~lcc_synth.models.platoon.PlatoonModel`). Both expose the same
layout (``vehicles`` front to tail, ``cavs``, ``ring``, ``vehicle_coefficients``), and the
analysis reads nothing else: a one-CAV model is a platoon with one CAV, vehicle 0.
:func:`controllability_report` and :func:`observability_report` give the rank, the verdict
(``controllable`` / ``uncontrollable`` / ``undecided``), stabilisability and which vehicles lie
in the controllable or observable subspace. The subspaces come from
:mod:`lcc_synth.analysis.staircase` (exact structural split, log balancing, a probe-perturbed
staircase with data-relative rank decisions; its docstring gives the method and the measured
figures); the theorem below is checked against it exactly (:func:`segment_cancellations`
decides its condition in rational arithmetic on the model's own floats).

The paper's theorems (one CAV)
------------------------------
With every HDV's ``alpha1 > 0`` and eq. (13), ``alpha1 - alpha2 alpha3 + alpha3^2 != 0``:

* Theorem 1 / Corollary 1: FD-LCC (eq. 12) and CF-LCC (eq. 11) are controllable;
* Theorem 2: in the general LCC (eq. 9) the HDVs ahead of the CAV are uncontrollable, the CAV
  and the HDVs behind it controllable; Corollary 2: in CCC (eq. 14) only the CAV is;
* Theorems 3 / 4: with ``v_k`` measured (eq. 19, 21) the vehicles up to ``k`` are observable
  and ``k + 1 .. n`` are not (:func:`default_outputs`).

They are the one-CAV case of the theorem below: one segment, the CAV with the ``n`` HDVs
behind it, and (S) is eq. (13) on a homogeneous string.

Theorem (any number of CAVs)
----------------------------
CAVs at positions ``c_1 < ... < c_k`` (``k >= 1``); every HDV with ``a1_i > 0``; for HDV ``i``
``phi_i(s) = a3_i s + a1_i`` and ``gamma_i(s) = s^2 + a2_i s + a1_i``. *Segment* ``j`` is CAV
``c_j`` with the HDVs behind it up to the next CAV (the last segment: up to the tail; on the
ring around to ``c_1 - 1``). Condition (S): there are no two HDVs ``k``, ``i`` of one segment,
``k`` at or ahead of ``i``, with ``gamma_i(-a1_k / a3_k) = 0`` (the zero of ``k``'s transfer
function ``phi_k / gamma_k`` is a pole of ``i``'s). For ``k = i`` this is eq. (13) of vehicle
``i``; in a homogeneous segment (S) *is* eq. (13); across vehicles the order matters (``k``
behind ``i`` cancels nothing).

1. Open string: the vehicles ahead of the first CAV are uncontrollable (exactly: no input
   reaches them, Theorem 2 (i)); the states of the first CAV and every vehicle behind it are
   controllable iff (S) holds.
2. Ring: ``c = sum_i s_i`` is conserved (``c A = 0``, ``c B = 0``): the eigenvalue 0 of the
   quotient is uncontrollable and no velocity disturbance excites it. The restriction to the
   invariant hyperplane ``c x = 0`` is controllable iff (S) holds (one CAV suffices).
3. The modes (S) loses are ``lambda = -a1_k / a3_k < 0``: the open string is always
   stabilisable (the HDVs ahead are Hurwitz, ``a1, a2 > 0``), the ring on its hyperplane too.
4. All-HDV ring (``k = 0``): ``B = 0``, nothing is controllable.

*Proof sketch* (PBH, as the paper's Theorem 1). Let ``rho^T [lambda I - A, B] = 0`` and
``w_i = rho_i1 + a3_i rho_i2`` (``a3 := 0`` for a CAV: what vehicle ``i`` feeds back to the
velocity column of its predecessor). The columns of vehicle ``i`` read, for an HDV,
``lambda rho_i1 = a1_i rho_i2`` and ``(lambda + a2_i) rho_i2 + rho_i1 = w_{i+1}``; for a CAV
``rho_c2 = 0`` (``rho^T B = 0``), ``lambda rho_c1 = 0`` and ``rho_c1 = w_{c+1}`` (open:
``w_{N+1} = 0``; ring: indices mod ``N``; a CAV that keeps its HDV law, CF-LCC, or has no
predecessor, FD-LCC, gives the same two equations). An HDV with ``gamma_i(lambda) != 0``
gives ``rho_i = w_{i+1} (a1_i, lambda) / gamma_i`` and ``w_i = (phi_i / gamma_i)(lambda)
w_{i+1}``; one with ``gamma_i(lambda) = 0`` (so ``lambda != 0``) is solvable iff ``w_{i+1} =
0``, and then ``rho_i = t (a1_i, lambda) / lambda`` is free with ``w_i = t phi_i(lambda) /
lambda``. For ``lambda != 0`` every CAV forces ``rho_c = 0`` and ``w_{c+1} = 0``: the segments
decouple; in one segment, walked from its tail, ``rho != 0`` iff some free ``t`` (a root of a
``gamma_i``) is cancelled before it reaches the CAV, i.e. ``phi_k(lambda) = 0`` at or ahead of
``i`` -- that is (S). For ``lambda = 0``: ``gamma_i(0) = a1_i != 0`` and ``(phi/gamma)(0) =
1``, and a CAV passes ``w_c = w_{c+1}``, so all ``w`` are equal: open, ``w_{N+1} = 0`` gives
``rho = 0``; ring, ``rho = (1, 0, 1, 0, ...)``: the conserved row. On the hyperplane (in the
coordinates ``[V, n]`` the ring's ``A`` is ``[[A_r, *], [0, 0]]``) left eigenvectors for
``lambda != 0`` correspond one to one; at ``lambda = 0`` one would need ``rho`` orthogonal to
``c`` with ``rho^T A = kappa c^T``, ``rho^T B = 0``, but the column ``s_c`` of a CAV is zero in
``A`` while ``c`` is not zero there, so ``kappa = 0`` and ``rho = 0``. Lost modes:
``lambda = -a1_k / a3_k``. The exact rational ranks in ``tests/test_platoon_analysis.py`` and
``tests/test_controllability.py`` confirm it, and the count: a homogeneous segment on the
eq. (13) boundary loses exactly one mode per HDV.

Numerics
--------
An open string is analysed as it is (the structural split removes the vehicles ahead of the
first CAV exactly). The ring is analysed on its hyperplane in the coordinates ``z`` = the state
without one spacing ``s_k`` (``s_k = -sum_{i != k} s_i``): ``A_z = P A W``, ``B_z = P B``
(:func:`reduce_conserved`). With ``s_k`` a CAV's spacing (whose column of ``A`` is zero) this is
``A`` with row and column ``s_k`` deleted, exactly, so the staircase still sees the sparsity.
The orthonormal Householder basis of :meth:`PlatoonModel.invariant_basis
<lcc_synth.models.platoon.PlatoonModel.invariant_basis>` gives the same verdicts (a test checks
it) but makes ``A`` dense. The full ring state, conserved direction included, is not a good
place to decide: decided at ``N = 20`` (39 of 40) but ``undecided`` at ``N = 40`` (rank
65..80, margin 0.89), the probes' noise growing along the long cycle.

Measured (``python benchmarks/bench_platoon_analysis.py``, 2 shared cores under load):
DeeP-LCC platoon (8 vehicles, CAVs 3 and 6): rank 12 of 16, vehicles 1, 2 outside, the 12
reachable states controllable, decided with margin 2.3e10 (no coupling to drop), 2 ms; the
closest pair of (S) is vehicle 7's own eq. (13), relative residual 0.11. OVM rings with one
AV (the paper's alpha 0.6, beta 0.9, v* 15): N = 20 controllable on the hyperplane (39 of 39),
margin 9.5e8, 45-60 ms; N = 40: 79 of 79, margin 2.2e8, 0.2-0.3 s (Householder basis: the same
ranks, margins 1.9e8 and 4.2e7, 50-150 ms). The all-HDV rings: rank 0, not stabilisable
(their stop-and-go mode has real part +0.027). Under the Prescott, Sandybridge and SkylakeX
OpenBLAS kernels the tests' verdicts are the same.

Vehicle classification
----------------------
Vehicle ``i``'s two coordinate directions (its spacing/position and velocity errors) are *in* the
subspace when both project onto it with residual ``||(I - Q Q^T) e|| <= membership_tol`` (default
``1e-8``), *outside* when the subspace is orthogonal to both (``||Q^T e|| <= membership_tol``),
*partial* otherwise (e.g. FD-LCC with the output ``v_k``: ``v_0`` is observable, ``-p_0`` not).
On the ring each direction is first projected onto the hyperplane (a spacing ``e_{s_i}``
itself is not in it).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from lcc_synth.analysis.staircase import (
    MEMBERSHIP_TOL,
    Staircase,
    kalman_decomposition,
    uncontrollable_modes,
)
from lcc_synth.errors import ConfigError
from lcc_synth.models.records import Record

__all__ = [
    "Cancellation",
    "segments",
    "segment_cancellations",
    "reduce_conserved",
    "drop_index",
    "SubspaceReport",
    "ControllabilityReport",
    "ObservabilityReport",
    "classify_vehicles",
    "controllability_report",
    "default_outputs",
    "observability_report",
]

_HYPERPLANE = "invariant hyperplane sum(s_i) = const"


# --------------------------------------------------------------------------------------------
# The theorem's condition (S), decided exactly
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, repr=False)
class Cancellation(Record):
    """A zero of HDV ``zero_vehicle`` against a pole of HDV ``pole_vehicle`` (same segment,
    ``zero_vehicle`` at or ahead of ``pole_vehicle``).

    Attributes
    ----------
    cav : int
        The CAV leading the segment.
    zero_vehicle, pole_vehicle : int
        Vehicles ``k`` and ``i`` (equal: vehicle ``i``'s own eq. 13).
    eigenvalue : float
        ``lambda = -a1_k / a3_k``: the mode lost when ``gamma_i(lambda) = 0``.
    residual : float
        ``|gamma_i(lambda)| / (lambda^2 + a2_i |lambda| + a1_i)`` (relative, in ``[0, 1]``).
    exact : bool
        ``gamma_i(lambda) = 0`` exactly for the model's floats (rational arithmetic).
    """

    cav: int
    zero_vehicle: int
    pole_vehicle: int
    eigenvalue: float
    residual: float
    exact: bool


def _first_cav(model) -> int:
    """Position of the first CAV in ``model.vehicles`` (their number without a CAV)."""
    return list(model.vehicles).index(model.cavs[0]) if model.cavs else len(model.vehicles)


def segments(model) -> list[tuple[int, tuple[int, ...]]]:
    """``[(cav, (hdv, ...)), ...]``: each CAV with the HDVs behind it up to the next CAV (open:
    up to the tail; ring: around to the first CAV), front to tail, by vehicle index."""
    vehicles = list(model.vehicles)
    N = len(vehicles)
    where = [vehicles.index(c) for c in model.cavs]
    out = []
    for j, (c, p) in enumerate(zip(model.cavs, where, strict=True)):
        if j + 1 < len(where):
            end = where[j + 1]
        else:
            end = where[0] + N if model.ring else N
        out.append((c, tuple(vehicles[i % N] for i in range(p + 1, end))))
    return out


def segment_cancellations(model) -> list[Cancellation]:
    """Every pair ``(k, i)`` of condition (S) (module docstring), closest first.

    The test ``gamma_i(-a1_k / a3_k) = 0`` is done in exact rational arithmetic on the model's
    floats (:attr:`Cancellation.exact`), so the theorem's verdict on the given data does not
    depend on rounding; ``residual`` says how far each pair is from cancelling.
    """
    coef = dict(zip(model.vehicles, model.vehicle_coefficients, strict=True))
    out = []
    for cav, hdvs in segments(model):
        for a, k in enumerate(hdvs):
            ck = coef[k]
            if ck.alpha3 == 0:
                continue  # phi_k is a non-zero constant: no zero
            lam = -Fraction(ck.alpha1) / Fraction(ck.alpha3)
            lam_f = float(lam)
            for i in hdvs[a:]:
                ci = coef[i]
                g = lam * lam + Fraction(ci.alpha2) * lam + Fraction(ci.alpha1)
                scale = lam_f * lam_f + abs(ci.alpha2 * lam_f) + abs(ci.alpha1)
                res = abs(float(g)) / scale if scale > 0 else 0.0
                out.append(Cancellation(cav, k, i, lam_f, res, g == 0))
    return sorted(out, key=lambda c: c.residual)


def _reachable(model) -> int:
    """States any input can reach at most: the first CAV and every vehicle behind it (open),
    the hyperplane (ring with a CAV), none without CAVs."""
    if not model.cavs:
        return 0
    if model.ring:
        return model.nx - 1
    return 2 * (len(model.vehicles) - _first_cav(model))


def _theory(model, pairs: list[Cancellation]) -> tuple[bool | None, int | None]:
    """``(S holds, the rank the theorem gives)``: ``(None, None)`` when it does not apply (an
    HDV with ``a1 <= 0``); the rank is ``None`` when (S) fails (it is then below the bound)."""
    if not model.cavs:
        return True, 0
    coef = dict(zip(model.vehicles, model.vehicle_coefficients, strict=True))
    hdvs = [i for _, seg in segments(model) for i in seg]
    if any(not coef[i].alpha1 > 0 for i in hdvs):
        return None, None
    holds = not any(p.exact for p in pairs)
    return holds, (_reachable(model) if holds else None)


# --------------------------------------------------------------------------------------------
# The ring's invariant hyperplane
# --------------------------------------------------------------------------------------------


def reduce_conserved(
    A: np.ndarray, B: np.ndarray, c: np.ndarray, k: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(A_z, B_z, W)``: the pair on the hyperplane ``c x = 0`` in the coordinates ``z`` = ``x``
    without entry ``k`` (``x = W z``, ``x_k = -sum_{j != k} c_j x_j / c_k``).

    Requires ``c A = 0`` (the hyperplane is invariant and contains the range of ``A``) and
    ``c B = 0``; then ``A W = W A_z`` with ``A_z = P A W`` (``P``: drop row ``k``), in floating
    point too for the ring's matrices (entries ``a - b`` with one of them zero).
    ``k`` defaults to the entry of ``c`` whose column of ``A`` is smallest (a CAV's spacing on
    the ring: zero, and ``A_z`` is ``A`` with row and column ``k`` deleted), ties broken by the
    largest ``|c_k|``.
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float).reshape(A.shape[0], -1)
    c = np.asarray(c, dtype=float).reshape(-1)
    nx = A.shape[0]
    k = drop_index(A, c) if k is None else int(k)
    keep = np.array([j for j in range(nx) if j != k])
    W = np.zeros((nx, nx - 1))
    W[keep, np.arange(nx - 1)] = 1.0
    W[k, :] = -c[keep] / c[k]
    Az = A[keep] @ W
    return Az, B[keep], W


def drop_index(A: np.ndarray, c: np.ndarray) -> int:
    """The entry :func:`reduce_conserved` drops by default: among those with ``|c_k| >=
    max|c| / 2``, the one whose column of ``A`` is smallest (ties: the largest ``|c_k|``, then
    the first)."""
    A = np.asarray(A, dtype=float)
    c = np.asarray(c, dtype=float).reshape(-1)
    cand = np.nonzero(np.abs(c) >= 0.5 * np.abs(c).max())[0]
    cols = np.linalg.norm(A[:, cand], axis=0)
    return int(cand[np.lexsort((-np.abs(c[cand]), cols))[0]])


def _analysed_pair(model) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``(A, B, W)`` of the space that matters: the model as it is (``W = None``) when open,
    the ring's hyperplane (:func:`reduce_conserved`)."""
    if not model.ring:
        return model.A, model.B, None
    return reduce_conserved(model.A, model.B, model.conserved)


def _hyperplane_directions(model) -> np.ndarray:
    """Columns: every state direction projected onto ``c x = 0``, unit length."""
    c = model.conserved
    P = np.eye(model.nx) - np.outer(c, c)
    return P / np.linalg.norm(P, axis=0)


def _orth(X: np.ndarray) -> np.ndarray:
    if X.shape[1] == 0:
        return X
    Q, R = np.linalg.qr(X)
    return Q * np.where(np.diag(R) < 0, -1.0, 1.0)


# --------------------------------------------------------------------------------------------
# Reports
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, repr=False)
class SubspaceReport(Record):
    """Common part of the controllability / observability reports, on the space that matters:
    the full state of an open layout, the ring's invariant hyperplane ``c x = 0`` (``n_states =
    2N - 1``; ``rank``, ``verdict``, ``decision_margin`` refer to it, ``basis`` is orthonormal
    in the model's coordinates).

    Attributes
    ----------
    kind : str
        The model's kind (``"lcc"``, ``"cf_lcc"``, ``"fd_lcc"``, ``"ccc"``, ``"platoon"``,
        ``"ring"``).
    m, n : int
        The model's sizes, as the problem file's ``[system]``: the paper's kinds, HDVs ahead
        of / behind the CAV; a platoon or ring, vehicles ahead of the first CAV / from the first
        CAV to the tail, *that CAV counted* (``n = reachable_states / 2`` on an open platoon).
        ``vehicles_behind`` is the paper's ``n`` on every layout.
    rank : int
        Dimension of the controllable (observable) subspace.
    n_states : int
        Dimension of the analysed space.
    vehicles_in_subspace : list of int
        Vehicles whose two states both lie in the subspace.
    vehicles_outside : list of int
        Vehicles whose two states are both orthogonal to the subspace.
    vehicles_partial : list of int
        The rest (one state in, or a mixed direction).
    basis : ndarray (model_states, rank)
        Orthonormal basis of the subspace.
    tolerance : float
        Rank tolerance of the staircase algorithm.
    min_accepted, max_rejected : float
        Smallest coupling kept / largest coupling dropped by the staircase (balanced
        coordinates; see :class:`Staircase`).
    membership_tol : float
        Projection tolerance of the vehicle classification.
    rank_upper : int
        Largest rank consistent with the data; ``rank_upper > rank`` means the rank is
        ``undecided`` (``rank`` is then the lower bound and ``basis`` spans only the directions
        reached for sure).
    margin : float
        :attr:`Staircase.decision_margin` (>= 1 when every decision was clear).
    cavs : tuple of int
        The CAVs' vehicle indices (``(0,)`` for the paper's models).
    vehicles_behind : int
        Vehicles behind the first CAV (0 without a CAV).
    ring : bool
    model_states : int
        States of the model (``2N``; ``n_states + 1`` on the ring).
    subspace : str
        What was analysed (``"full state"`` or the ring's hyperplane).
    conserved_mode : str or None
        The ring's conserved mode (:attr:`PlatoonModel.conserved_mode`), left out of the
        analysed space.
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
    rank_upper: int
    margin: float
    cavs: tuple[int, ...]
    vehicles_behind: int
    ring: bool
    model_states: int
    subspace: str
    conserved_mode: str | None

    @property
    def undecided(self) -> bool:
        """The data do not fix the rank: some coupling is neither clearly above its noise nor
        clearly at it (see the module docstring)."""
        return self.rank_upper > self.rank

    @property
    def decision_margin(self) -> float:
        """``min(smallest kept coupling/noise / KEEP_RATIO, DROP_RATIO / largest dropped
        coupling/noise)``: >= 1 when every decision was clear, < 1 when one was not (``inf``
        when there was nothing to decide)."""
        return float(self.margin)

    def _verdict(self, yes: str, no: str, full: int | None = None) -> str:
        full = self.n_states if full is None else full
        if self.rank == full:
            return yes
        return no if self.rank_upper < full else "undecided"

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
            "rank_upper": int(self.rank_upper),
            "undecided": bool(self.undecided),
            "tolerance": float(self.tolerance),
            "min_accepted_coupling": _finite_or_none(self.min_accepted),
            "max_rejected_coupling": float(self.max_rejected),
            "decision_margin": _finite_or_none(self.decision_margin),
            "cavs": [int(c) for c in self.cavs],
            "vehicles_behind": int(self.vehicles_behind),
            "ring": bool(self.ring),
            "model_states": int(self.model_states),
            "subspace": self.subspace,
            "conserved_mode": self.conserved_mode,
        }

    def contains_state(self, model, name: str) -> bool:
        """Whether the coordinate direction of state ``name`` lies in the subspace."""
        e = np.zeros(self.model_states)
        e[model.index(name)] = 1.0
        res = e - self.basis @ (self.basis.T @ e)
        return bool(np.linalg.norm(res) <= self.membership_tol)


@dataclass(frozen=True, repr=False)
class ControllabilityReport(SubspaceReport):
    """Controllable subspace of ``(A, B)``; ``controllable`` iff ``rank == n_states`` for sure.

    ``verdict`` is ``"controllable"``, ``"uncontrollable"`` or ``"undecided"`` (the data are
    within round-off of both; ``controllable`` is then False). ``uncontrollable_eigenvalues``
    are the eigenvalues of the uncontrollable block ``A_u`` of the Kalman decomposition (no
    input can move them; on the ring the conserved mode is named in ``conserved_mode``, not
    counted); ``stabilizable`` iff all have a negative real part. When undecided, ``A_u`` also
    holds the undecided directions, so ``stabilizable`` errs on the safe side. Repeated
    eigenvalues of ``A_u`` come out scattered by round-off (see the module docstring), their
    real parts stay reliable to that scatter.

    Attributes
    ----------
    controllable : bool
    uncontrollable_eigenvalues : ndarray
    reachable_states : int
        See :attr:`reachable_verdict`.
    conserved_residual : float or None
        Ring: ``max(|c A|, |c B|) / ||A||``, the conservation law in the data (0 exactly for
        the model; non-zero only for a perturbed matrix).
    segments : tuple
        ``(cav, (hdv, ...))`` per CAV (:func:`segments`).
    cancellations : tuple of Cancellation
        The pairs violating condition (S) exactly (empty when it holds).
    closest : Cancellation or None
        The pair nearest to violating it.
    condition_s : bool or None
        Whether condition (S) holds (``None``: the theorem does not apply, an HDV has
        ``a1 <= 0``).
    theory_rank : int or None
        The rank the theorem gives when (S) holds: ``reachable_states``; ``None`` when (S)
        fails (the rank is then lower).
    """

    controllable: bool
    uncontrollable_eigenvalues: np.ndarray = field(repr=False)
    reachable_states: int
    conserved_residual: float | None
    segments: tuple
    cancellations: tuple[Cancellation, ...] = field(repr=False)
    closest: Cancellation | None = field(repr=False)
    condition_s: bool | None
    theory_rank: int | None

    @property
    def verdict(self) -> str:
        """``"controllable"``, ``"uncontrollable"`` or ``"undecided"``."""
        return self._verdict("controllable", "uncontrollable")

    @property
    def reachable_verdict(self) -> str:
        """The verdict on the states of the first CAV and every vehicle behind it (open: the
        most any input can reach, Theorem 2 (i); ring: the hyperplane), i.e. ``rank`` against
        ``reachable_states`` instead of ``n_states``."""
        return self._verdict("controllable", "uncontrollable", self.reachable_states)

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
            "verdict": self.verdict,
            "stabilizable": self.stabilizable,
            "uncontrollable_max_real": self.uncontrollable_max_real,
            **self._summary(),
            "conserved_residual": self.conserved_residual,
            "uncontrollable_eigenvalues": [
                [float(e.real), float(e.imag)] for e in self.uncontrollable_eigenvalues
            ],
            "segments": [{"cav": int(c), "hdvs": [int(i) for i in s]} for c, s in self.segments],
            "cancellations": [x.as_dict() for x in self.cancellations],
            "closest_cancellation": None if self.closest is None else self.closest.as_dict(),
            "reachable_states": int(self.reachable_states),
            "reachable_verdict": self.reachable_verdict,
            "condition_s": self.condition_s,
            "theory_rank": self.theory_rank,
        }


@dataclass(frozen=True, repr=False)
class ObservabilityReport(SubspaceReport):
    """Observable subspace of ``(A, C)`` for the named state outputs; ``verdict`` is
    ``"observable"``, ``"unobservable"`` or ``"undecided"`` (ring: on the invariant hyperplane;
    the total spacing is known there, from the circumference)."""

    outputs: list[str]
    observable: bool

    @property
    def verdict(self) -> str:
        """``"observable"``, ``"unobservable"`` or ``"undecided"``."""
        return self._verdict("observable", "unobservable")

    def as_dict(self) -> dict:
        """JSON-serialisable summary (no basis)."""
        return {
            "observable": bool(self.observable),
            "verdict": self.verdict,
            "outputs": list(self.outputs),
            **self._summary(),
        }


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def classify_vehicles(
    blocks: Mapping[int, slice],
    basis: np.ndarray,
    membership_tol: float = MEMBERSHIP_TOL,
    directions: np.ndarray | None = None,
) -> tuple[list[int], list[int], list[int]]:
    """``(inside, outside, partial)``: which vehicles' states lie in the subspace ``basis``.

    Parameters
    ----------
    blocks : mapping of int to slice
        Each vehicle's state indices.
    basis : (nx, rank) array
        Orthonormal basis of the subspace.
    membership_tol : float
        Projection tolerance (see the module docstring).
    directions : (nx, nx) array, optional
        Column ``i`` is the direction tested for state ``i`` (default the coordinate direction
        ``e_i``; on a ring: its projection onto the invariant hyperplane).
    """
    nx = basis.shape[0]
    eye = np.eye(nx) if directions is None else directions
    coords = basis.T @ eye  # (rank, nx): projection coefficients of every coordinate direction
    inside_res = np.linalg.norm(eye - basis @ coords, axis=0)  # residual of each e_i
    along = np.linalg.norm(coords, axis=0)  # length of each e_i's projection
    inside, outside, partial = [], [], []
    for vehicle, b in blocks.items():
        if np.all(inside_res[b] <= membership_tol):
            inside.append(vehicle)
        elif np.all(along[b] <= membership_tol):
            outside.append(vehicle)
        else:
            partial.append(vehicle)
    return inside, outside, partial


def _report_fields(model, dec: Staircase, n_states: int, basis: np.ndarray, classes,
                   membership_tol: float) -> dict:  # fmt: skip
    """The fields shared by the controllability and observability reports."""
    inside, outside, partial = classes
    first = _first_cav(model)
    return dict(
        kind=model.kind,
        m=model.m,
        n=model.n,
        rank=int(dec.n_c),
        n_states=n_states,
        vehicles_in_subspace=inside,
        vehicles_outside=outside,
        vehicles_partial=partial,
        basis=basis,
        tolerance=dec.tol,
        min_accepted=dec.min_accepted,
        max_rejected=dec.max_rejected,
        membership_tol=membership_tol,
        rank_upper=int(dec.n_c_upper),
        margin=dec.decision_margin,
        cavs=tuple(model.cavs),
        vehicles_behind=max(len(model.vehicles) - first - 1, 0),
        ring=bool(model.ring),
        model_states=model.nx,
        subspace=_HYPERPLANE if model.ring else "full state",
        conserved_mode=model.conserved_mode,
    )


def _blocks(model) -> dict[int, slice]:
    return {vehicle: model.block(vehicle) for vehicle in model.vehicles}


def controllability_report(
    model, tol: float | None = None, membership_tol: float = MEMBERSHIP_TOL
) -> ControllabilityReport:
    """Controllability and stabilisability of any layout, and which vehicles it reaches.

    Parameters
    ----------
    model : LCCModel or PlatoonModel
        The paper's one-CAV models, an open platoon with any CAVs, or a ring.
    tol : float, optional
        Fixed staircase threshold (default: the probe-based decisions, see
        :mod:`lcc_synth.analysis.staircase`).
    membership_tol : float
        Projection tolerance of the vehicle classification.

    Returns
    -------
    ControllabilityReport
        Theorem 2: for the general LCC the vehicles ahead are outside and the CAV and the
        vehicles behind inside (when eq. 13 holds); Theorem 1 / Corollary 1: FD/CF-LCC fully
        controllable; Corollary 2: for CCC only the CAV. Several CAVs: the vehicles ahead of
        the first CAV outside, the rest inside when condition (S) holds. Ring: analysed on the
        invariant hyperplane; with one CAV controllable there (the conserved total spacing is
        named, never a reason for "unstabilisable").
    """
    Aa, Ba, W = _analysed_pair(model)
    dec = kalman_decomposition(Aa, Ba, tol)
    Xa = dec.T[:, : dec.n_c]
    basis = Xa if W is None else _orth(W @ Xa)
    directions = None if W is None else _hyperplane_directions(model)
    classes = classify_vehicles(_blocks(model), basis, membership_tol, directions)
    pairs = segment_cancellations(model)
    holds, theory_rank = _theory(model, pairs)
    resid = None
    if model.ring:
        c = model.conserved
        scale = max(np.linalg.norm(model.A, "fro"), np.finfo(float).tiny)
        resid = float(max(np.abs(c @ model.A).max(), np.abs(c @ model.B).max(initial=0.0))
                      / scale)  # fmt: skip
    return ControllabilityReport(
        **_report_fields(model, dec, Aa.shape[0], basis, classes, membership_tol),
        controllable=dec.n_c == Aa.shape[0],
        uncontrollable_eigenvalues=uncontrollable_modes(Aa, Ba, tol, dec),
        reachable_states=_reachable(model),
        conserved_residual=resid,
        segments=tuple(segments(model)),
        cancellations=tuple(p for p in pairs if p.exact),
        closest=pairs[0] if pairs else None,
        condition_s=holds,
        theory_rank=theory_rank,
    )


def default_outputs(model, k: int | None = None) -> list[str]:
    """The measured states the paper's Theorems 3/4 and their generalisation assume.

    FD-/CF-LCC: ``v_k`` only (``C_f^(k)``, eq. 19). Every other layout: every CAV's own
    spacing and velocity plus ``v_k`` (``C^(k)``, eq. 21: ``s_0, v_0, v_k`` for the general
    LCC, ``s_0, v_0`` for CCC); ``k`` defaults to the tail, on a ring to none (an all-HDV ring:
    the tail). ``k`` must be a vehicle behind the first CAV of an open layout (the paper's
    ``1..n``; ignored when there is none, CCC), any vehicle of a ring.
    """
    vehicles = list(model.vehicles)
    behind = vehicles if model.ring else vehicles[_first_cav(model) + 1:]
    if k is not None:
        k = int(k)
        if behind and k not in behind:
            raise ConfigError("k", f"must be in [{behind[0]}, {behind[-1]}], got {k}")
        k = k if behind else None  # nobody behind the CAV (CCC): its own states only
    if model.kind in ("fd_lcc", "cf_lcc"):
        return [f"v_{vehicles[-1] if k is None else k}"]
    names = [f"{q}_{c}" for c in model.cavs for q in ("s", "v")]
    if k is None and (not model.ring or not names):
        k = vehicles[-1]
    if k is not None and f"v_{k}" not in names:
        names.append(f"v_{k}")
    return names


def observability_report(
    model,
    outputs: Sequence[str] | None = None,
    tol: float | None = None,
    membership_tol: float = MEMBERSHIP_TOL,
) -> ObservabilityReport:
    """Observable subspace for the measured states ``outputs`` and which vehicles it contains.

    The dual staircase of :func:`controllability_report` (ring: on the invariant hyperplane).
    A vehicle is *inside* when both its states can be reconstructed from the output (on the
    ring: their restrictions to the hyperplane).

    Parameters
    ----------
    model : LCCModel or PlatoonModel
        Any layout.
    outputs : sequence of str, optional
        Measured state names, e.g. ``["s_0", "v_0", "v_3"]`` (eq. 21) or ``["v_3"]``
        (eq. 19); default :func:`default_outputs`.
    tol, membership_tol : float, optional
        As in :func:`controllability_report`.

    Returns
    -------
    ObservabilityReport
        Theorems 3/4: with ``v_k`` measured, the vehicles up to ``k`` are observable and
        ``k+1..n`` unobservable (outside).
    """
    outputs = [str(o) for o in (default_outputs(model) if outputs is None else outputs)]
    if not outputs:
        raise ConfigError("outputs", "needs at least one measured state name")
    C = model.output_matrix(outputs)
    Aa, _, W = _analysed_pair(model)
    Ca = C if W is None else C @ W
    dec = kalman_decomposition(Aa.T, Ca.T, tol)
    L = dec.T[:, : dec.n_c]  # observable functionals (rows of the observability matrix)
    directions = None
    if W is not None:  # the functional x_i restricted to the hyperplane, in z coordinates
        directions = W.T / np.maximum(np.linalg.norm(W.T, axis=0), np.finfo(float).tiny)
    classes = classify_vehicles(_blocks(model), L, membership_tol, directions)
    basis = L
    if W is not None:  # z-functionals -> x (zero on the dropped entry), projected on c x = 0
        Lx = np.insert(L, drop_index(model.A, model.conserved), 0.0, axis=0)
        c = model.conserved
        basis = _orth(Lx - np.outer(c, c @ Lx))
    return ObservabilityReport(
        **_report_fields(model, dec, Aa.shape[0], basis, classes, membership_tol),
        outputs=outputs,
        observable=dec.n_c == Aa.shape[0],
    )
