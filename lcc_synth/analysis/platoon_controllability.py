"""Controllability and observability of mixed platoons and the ring (several CAVs).

Generalises the paper's Theorems 1-2 (Section III-A, eq. 13) to the models of
:mod:`lcc_synth.models.platoon`. The numerics are the package's robust staircase
(:func:`lcc_synth.analysis.staircase.kalman_decomposition`: structural split, log balancing,
probe-perturbed rank decisions relative to the data, ``undecided`` when too close to call);
the theorem below is checked against it exactly (:func:`segment_cancellations` decides the
condition in rational arithmetic on the model's own floats).

Theorem (several CAVs)
----------------------
CAVs at positions ``c_1 < ... < c_k`` (``k >= 1``); every HDV with ``a1_i > 0``; for HDV ``i``
``phi_i(s) = a3_i s + a1_i`` and ``gamma_i(s) = s^2 + a2_i s + a1_i``. *Segment* ``j`` is CAV
``c_j`` with the HDVs behind it up to the next CAV (the last segment: up to ``N``; on the ring
around to ``c_1 - 1``). Condition (S): there are no two HDVs ``k``, ``i`` of one segment, ``k``
at or ahead of ``i``, with ``gamma_i(-a1_k / a3_k) = 0`` (the zero of ``k``'s transfer function
``phi_k / gamma_k`` is a pole of ``i``'s). For ``k = i`` this is eq. (13) of vehicle ``i``; in a
homogeneous segment (S) *is* eq. (13); across vehicles the order matters (``k`` behind ``i``
cancels nothing).

1. Open platoon: the vehicles ``1 .. c_1 - 1`` ahead of the first CAV are uncontrollable (exactly:
   no input reaches them, Theorem 2 (i)); the states of the vehicles ``c_1 .. N`` are
   controllable iff (S) holds.
2. Ring: ``c = sum_i s_i`` is conserved (``c A = 0``, ``c B = 0``): the eigenvalue 0 of the
   quotient is uncontrollable and no velocity disturbance excites it. The restriction to the
   invariant hyperplane ``c x = 0`` is controllable iff (S) holds (one CAV suffices).
3. The modes (S) loses are ``lambda = -a1_k / a3_k < 0``: the platoon is always stabilisable
   (the HDVs ahead are Hurwitz, ``a1, a2 > 0``), the ring on its hyperplane too.
4. All-HDV ring (``k = 0``): ``B = 0``, nothing is controllable.

*Proof sketch* (PBH, as the paper's Theorem 1). Let ``rho^T [lambda I - A, B] = 0`` and
``w_i = rho_i1 + a3_i rho_i2`` (``a3 := 0`` for a CAV: what vehicle ``i`` feeds back to the
velocity column of its predecessor). The columns of vehicle ``i`` read, for an HDV,
``lambda rho_i1 = a1_i rho_i2`` and ``(lambda + a2_i) rho_i2 + rho_i1 = w_{i+1}``; for a CAV
``rho_c2 = 0`` (``rho^T B = 0``), ``lambda rho_c1 = 0`` and ``rho_c1 = w_{c+1}`` (open:
``w_{N+1} = 0``; ring: indices mod ``N``). An HDV with ``gamma_i(lambda) != 0`` gives
``rho_i = w_{i+1} (a1_i, lambda) / gamma_i`` and ``w_i = (phi_i / gamma_i)(lambda) w_{i+1}``; one
with ``gamma_i(lambda) = 0`` (so ``lambda != 0``) is solvable iff ``w_{i+1} = 0``, and then
``rho_i = t (a1_i, lambda) / lambda`` is free with ``w_i = t phi_i(lambda) / lambda``.
For ``lambda != 0`` every CAV forces ``rho_c = 0`` and ``w_{c+1} = 0``: the segments decouple;
in one segment, walked from its tail, ``rho != 0`` iff some free ``t`` (a root of a
``gamma_i``) is cancelled before it reaches the CAV, i.e. ``phi_k(lambda) = 0`` at or ahead of
``i`` -- that is (S). For ``lambda = 0``: ``gamma_i(0) = a1_i != 0`` and ``(phi/gamma)(0) = 1``,
and a CAV passes ``w_c = w_{c+1}``, so all ``w`` are equal: open, ``w_{N+1} = 0`` gives
``rho = 0``; ring, ``rho = (1, 0, 1, 0, ...)``: the conserved row. On the hyperplane (in the
coordinates ``[V, n]`` the ring's ``A`` is ``[[A_r, *], [0, 0]]``) left eigenvectors for
``lambda != 0`` correspond one to one; at ``lambda = 0`` one would need ``rho`` orthogonal to
``c`` with ``rho^T A = kappa c^T``, ``rho^T B = 0``, but the column ``s_c`` of a CAV is zero in
``A`` while ``c`` is not zero there, so ``kappa = 0`` and ``rho = 0``. Lost modes:
``lambda = -a1_k / a3_k``. The exact rational ranks in ``tests/test_platoon_analysis.py``
confirm it, and the count: a homogeneous segment on the eq. (13) boundary loses exactly one
mode per HDV.

Numerics
--------
The open platoon is analysed as it is (the structural split removes the vehicles ahead of the
first CAV exactly). The ring is analysed on its hyperplane in the coordinates ``z`` = the state
without one spacing ``s_k`` (``s_k = -sum_{i != k} s_i``): ``A_z = P A W``, ``B_z = P B``
(:func:`reduce_conserved`). With ``s_k`` a CAV's spacing (whose column of ``A`` is zero) this is
``A`` with row and column ``s_k`` deleted, exactly, so the staircase still sees the sparsity.
The orthonormal Householder basis of :meth:`PlatoonModel.invariant_basis` gives the same
verdicts (a test checks it) but makes ``A`` dense. The full ring state, conserved direction
included, is not a good place to decide: decided at ``N = 20`` (39 of 40) but ``undecided`` at
``N = 40`` (rank 65..80, margin 0.89), the probes' noise growing along the long cycle.
The vehicle classification uses, on the ring, each state direction projected onto the
hyperplane (a spacing ``e_{s_i}`` itself is not in it).

Measured (``python benchmarks/bench_platoon_analysis.py``, 2 shared cores under load):
DeeP-LCC platoon (8 vehicles, CAVs 3 and 6): rank 12 of 16, vehicles 1, 2 outside, the 12
reachable states controllable, decided with margin 2.3e10 (no coupling to drop), 2 ms; the
closest pair of (S) is vehicle 7's own eq. (13), relative residual 0.11. OVM rings with one
AV (the paper's alpha 0.6, beta 0.9, v* 15): N = 20 controllable on the hyperplane (39 of 39),
margin 9.5e8, 45-60 ms; N = 40: 79 of 79, margin 2.2e8, 0.2-0.3 s (Householder basis: the same
ranks, margins 1.9e8 and 4.2e7, 50-150 ms). The all-HDV rings: rank 0, not stabilisable
(their stop-and-go mode has real part +0.027). Under the Prescott, Sandybridge and SkylakeX
OpenBLAS kernels the tests' verdicts are the same.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from lcc_synth.analysis.controllability import (
    ControllabilityReport,
    ObservabilityReport,
    classify_vehicles,
)
from lcc_synth.analysis.staircase import MEMBERSHIP_TOL, kalman_decomposition, uncontrollable_modes
from lcc_synth.errors import ConfigError
from lcc_synth.models.platoon import PlatoonModel
from lcc_synth.models.records import Record

__all__ = [
    "Cancellation",
    "segments",
    "segment_cancellations",
    "reduce_conserved",
    "drop_index",
    "PlatoonControllabilityReport",
    "PlatoonObservabilityReport",
    "platoon_controllability",
    "platoon_default_outputs",
    "platoon_observability",
]


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
        Positions ``k`` and ``i`` (equal: vehicle ``i``'s own eq. 13).
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


def segments(model: PlatoonModel) -> list[tuple[int, tuple[int, ...]]]:
    """``[(cav, (hdv, ...)), ...]``: each CAV with the HDVs behind it up to the next CAV (open:
    up to ``N``; ring: around to the first CAV), front to tail."""
    N = model.platoon.size
    cavs = list(model.cavs)
    out = []
    for j, c in enumerate(cavs):
        if j + 1 < len(cavs):
            end = cavs[j + 1]
        else:
            end = cavs[0] + N if model.ring else N + 1
        out.append((c, tuple((i - 1) % N + 1 for i in range(c + 1, end))))
    return out


def segment_cancellations(model: PlatoonModel) -> list[Cancellation]:
    """Every pair ``(k, i)`` of condition (S) (module docstring), closest first.

    The test ``gamma_i(-a1_k / a3_k) = 0`` is done in exact rational arithmetic on the model's
    floats (:attr:`Cancellation.exact`), so the theorem's verdict on the given data does not
    depend on rounding; ``residual`` says how far each pair is from cancelling.
    """
    out = []
    for cav, hdvs in segments(model):
        for a, k in enumerate(hdvs):
            ck = model.coefficients[k - 1]
            if ck.alpha3 == 0:
                continue  # phi_k is a non-zero constant: no zero
            lam = -Fraction(ck.alpha1) / Fraction(ck.alpha3)
            lam_f = float(lam)
            for i in hdvs[a:]:
                ci = model.coefficients[i - 1]
                g = lam * lam + Fraction(ci.alpha2) * lam + Fraction(ci.alpha1)
                scale = lam_f * lam_f + abs(ci.alpha2 * lam_f) + abs(ci.alpha1)
                res = abs(float(g)) / scale if scale > 0 else 0.0
                out.append(Cancellation(cav, k, i, lam_f, res, g == 0))
    return sorted(out, key=lambda c: c.residual)


def _theory(model: PlatoonModel, pairs: list[Cancellation]) -> tuple[bool | None, int | None]:
    """``(S holds, the rank the theorem gives)``: ``(None, None)`` when it does not apply (an
    HDV with ``a1 <= 0``); the rank is ``None`` when (S) fails (it is then below the bound)."""
    N = model.platoon.size
    if not model.cavs:
        return True, 0
    hdvs = [i for _, seg in segments(model) for i in seg]
    if any(not model.coefficients[i - 1].alpha1 > 0 for i in hdvs):
        return None, None
    holds = not any(p.exact for p in pairs)
    full = 2 * N - 1 if model.ring else 2 * (N - model.cavs[0] + 1)
    return holds, (full if holds else None)


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


# --------------------------------------------------------------------------------------------
# Reports
# --------------------------------------------------------------------------------------------


def _layout(model: PlatoonModel) -> dict:
    first = model.cavs[0] if model.cavs else model.platoon.size + 1
    return dict(
        kind="ring" if model.ring else "platoon",
        m=first - 1,
        n=model.platoon.size + 1 - first,
    )


def _reachable(model: PlatoonModel) -> int:
    """States any input can reach at most: the first CAV and every vehicle behind it (open),
    the hyperplane (ring with a CAV), none without CAVs."""
    if not model.cavs:
        return 0
    if model.ring:
        return model.nx - 1
    return 2 * (model.platoon.size - model.cavs[0] + 1)


def _blocks(model: PlatoonModel) -> dict[int, slice]:
    return {i: model.block(i) for i in range(1, model.platoon.size + 1)}


def _hyperplane_directions(model: PlatoonModel) -> np.ndarray:
    """Columns: every state direction projected onto ``c x = 0``, unit length."""
    c = model.conserved
    P = np.eye(model.nx) - np.outer(c, c)
    return P / np.linalg.norm(P, axis=0)


@dataclass(frozen=True, repr=False)
class PlatoonControllabilityReport(ControllabilityReport):
    """:class:`ControllabilityReport` of a platoon or ring, on the space that matters.

    Open platoon: the full state (``n_states = 2N``). Ring: the invariant hyperplane
    ``c x = 0`` (``n_states = 2N - 1``), the conserved total spacing named in
    ``conserved_mode`` and left out of ``uncontrollable_eigenvalues`` and ``stabilizable``.
    ``rank``, ``verdict``, ``decision_margin`` and ``basis`` (orthonormal, in the model's
    coordinates ``s_1, v_1, ...``) refer to that space.

    Attributes
    ----------
    cavs : tuple of int
    ring : bool
    model_states : int
        ``2N``.
    reachable_states : int
        See :attr:`PlatoonControllabilityReport.reachable_verdict`.
    subspace : str
        What was analysed.
    conserved_mode : str or None
        :attr:`PlatoonModel.conserved_mode` (ring).
    conserved_residual : float or None
        ``max(|c A|, |c B|) / ||A||``: the conservation law in the data (0 exactly for the
        model; non-zero only for a perturbed matrix).
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
        The rank the theorem gives when (S) holds: ``2 (N - c_1 + 1)`` (open), ``2N - 1``
        (ring), 0 without CAVs; ``None`` when (S) fails (the rank is then lower).
    """

    cavs: tuple[int, ...] = ()
    ring: bool = False
    model_states: int = 0
    subspace: str = "full state"
    conserved_mode: str | None = None
    conserved_residual: float | None = None
    segments: tuple = ()
    cancellations: tuple[Cancellation, ...] = field(default=(), repr=False)
    closest: Cancellation | None = field(default=None, repr=False)
    condition_s: bool | None = None
    theory_rank: int | None = None
    reachable_states: int = 0

    @property
    def reachable_verdict(self) -> str:
        """The verdict on the states of the first CAV and every vehicle behind it (open
        platoon: the most any input can reach, Theorem 2 (i); ring: the hyperplane), i.e.
        ``rank`` against ``reachable_states`` instead of ``n_states``."""
        if self.rank == self.reachable_states:
            return "controllable"
        return "uncontrollable" if self.rank_upper < self.reachable_states else "undecided"

    def as_dict(self) -> dict:
        """JSON-serialisable summary (no basis)."""
        return {
            **super().as_dict(),
            "cavs": [int(c) for c in self.cavs],
            "ring": bool(self.ring),
            "model_states": int(self.model_states),
            "subspace": self.subspace,
            "conserved_mode": self.conserved_mode,
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
class PlatoonObservabilityReport(ObservabilityReport):
    """:class:`ObservabilityReport` of a platoon or ring (ring: on the invariant hyperplane;
    the total spacing is known there, from the circumference).

    Attributes
    ----------
    ring : bool
    model_states : int
    subspace : str
    conserved_mode : str or None
    """

    ring: bool = False
    model_states: int = 0
    subspace: str = "full state"
    conserved_mode: str | None = None

    def as_dict(self) -> dict:
        """JSON-serialisable summary (no basis)."""
        return {
            **super().as_dict(),
            "ring": bool(self.ring),
            "model_states": int(self.model_states),
            "subspace": self.subspace,
            "conserved_mode": self.conserved_mode,
        }


def _analysed_pair(model: PlatoonModel) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    if not model.ring:
        return model.A, model.B, None
    return reduce_conserved(model.A, model.B, model.conserved)


def _decided_fields(dec, n_states: int, membership_tol: float) -> dict:
    return dict(
        n_states=n_states,
        tolerance=dec.tol,
        min_accepted=dec.min_accepted,
        max_rejected=dec.max_rejected,
        membership_tol=membership_tol,
        rank_upper=int(dec.n_c_upper),
        margin=dec.decision_margin,
    )


def _orth(X: np.ndarray) -> np.ndarray:
    if X.shape[1] == 0:
        return X
    Q, R = np.linalg.qr(X)
    return Q * np.where(np.diag(R) < 0, -1.0, 1.0)


def platoon_controllability(
    model: PlatoonModel, tol: float | None = None, membership_tol: float = MEMBERSHIP_TOL
) -> PlatoonControllabilityReport:
    """Controllability and stabilisability of a platoon (several CAVs) or a ring.

    Parameters
    ----------
    model : PlatoonModel
    tol : float, optional
        Fixed staircase threshold (default: the probe-based decisions, see
        :mod:`lcc_synth.analysis.staircase`).
    membership_tol : float
        Projection tolerance of the vehicle classification.

    Returns
    -------
    PlatoonControllabilityReport
        Open platoon: the vehicles ahead of the first CAV outside, the rest inside when
        condition (S) holds. Ring: analysed on the invariant hyperplane; with one CAV
        controllable there (the conserved total spacing is named, never a reason for
        "unstabilisable").
    """
    if not isinstance(model, PlatoonModel):
        raise ConfigError("system.kind", "platoon_controllability needs a platoon or ring model")
    Aa, Ba, W = _analysed_pair(model)
    dec = kalman_decomposition(Aa, Ba, tol)
    Xa = dec.T[:, : dec.n_c]
    basis = Xa if W is None else _orth(W @ Xa)
    directions = None if W is None else _hyperplane_directions(model)
    inside, outside, partial = classify_vehicles(
        _blocks(model), basis, membership_tol, directions
    )
    pairs = segment_cancellations(model)
    holds, theory_rank = _theory(model, pairs)
    resid = None
    if model.ring:
        c = model.conserved
        scale = max(np.linalg.norm(model.A, "fro"), np.finfo(float).tiny)
        resid = float(max(np.abs(c @ model.A).max(), np.abs(c @ model.B).max(initial=0.0))
                      / scale)  # fmt: skip
    return PlatoonControllabilityReport(
        **_layout(model),
        rank=int(dec.n_c),
        vehicles_in_subspace=inside,
        vehicles_outside=outside,
        vehicles_partial=partial,
        basis=basis,
        **_decided_fields(dec, Aa.shape[0], membership_tol),
        controllable=dec.n_c == Aa.shape[0],
        uncontrollable_eigenvalues=uncontrollable_modes(Aa, Ba, tol, dec),
        cavs=tuple(model.cavs),
        ring=model.ring,
        model_states=model.nx,
        subspace="invariant hyperplane sum(s_i) = const" if model.ring else "full state",
        conserved_mode=model.conserved_mode,
        conserved_residual=resid,
        segments=tuple(segments(model)),
        cancellations=tuple(p for p in pairs if p.exact),
        closest=pairs[0] if pairs else None,
        condition_s=holds,
        theory_rank=theory_rank,
        reachable_states=_reachable(model),
    )


def platoon_default_outputs(model: PlatoonModel) -> list[str]:
    """Every CAV's own ``s_i, v_i`` plus the tail's ``v_N`` (open platoon; the paper's eq. 21
    with ``k = n`` for one CAV); on the ring the CAVs' own states (an all-HDV ring: ``v_N``)."""
    names = [f"{q}_{i}" for i in model.cavs for q in ("s", "v")]
    tail = f"v_{model.platoon.size}"
    if (not model.ring or not names) and tail not in names:
        names.append(tail)
    return names


def platoon_observability(
    model: PlatoonModel,
    outputs: Sequence[str] | None = None,
    tol: float | None = None,
    membership_tol: float = MEMBERSHIP_TOL,
) -> PlatoonObservabilityReport:
    """Observable subspace of a platoon or ring for the measured states ``outputs``.

    The dual staircase of :func:`platoon_controllability` (ring: on the invariant hyperplane).
    A vehicle is *inside* when both its states can be reconstructed from the output (on the
    ring: their restrictions to the hyperplane).

    Parameters
    ----------
    model : PlatoonModel
    outputs : sequence of str, optional
        Measured state names (default :func:`platoon_default_outputs`).
    tol, membership_tol : float, optional
        As in :func:`platoon_controllability`.
    """
    if not isinstance(model, PlatoonModel):
        raise ConfigError("system.kind", "platoon_observability needs a platoon or ring model")
    outputs = [str(o) for o in (platoon_default_outputs(model) if outputs is None else outputs)]
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
    inside, outside, partial = classify_vehicles(_blocks(model), L, membership_tol, directions)
    basis = L
    if W is not None:  # z-functionals -> x (zero on the dropped entry), projected on c x = 0
        Lx = np.insert(L, drop_index(model.A, model.conserved), 0.0, axis=0)
        c = model.conserved
        basis = _orth(Lx - np.outer(c, c @ Lx))
    return PlatoonObservabilityReport(
        **_layout(model),
        rank=int(dec.n_c),
        vehicles_in_subspace=inside,
        vehicles_outside=outside,
        vehicles_partial=partial,
        basis=basis,
        **_decided_fields(dec, Aa.shape[0], membership_tol),
        outputs=outputs,
        observable=dec.n_c == Aa.shape[0],
        ring=model.ring,
        model_states=model.nx,
        subspace="invariant hyperplane sum(s_i) = const" if model.ring else "full state",
        conserved_mode=model.conserved_mode,
    )
