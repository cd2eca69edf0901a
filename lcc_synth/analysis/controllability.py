"""Controllability and observability of LCC systems (Section III-A/C, Theorems 1-4, Cor. 1-5).

Reports on :class:`~lcc_synth.models.linear.LCCModel`: rank, verdict (``controllable`` /
``uncontrollable`` / ``undecided``), stabilisability and which vehicles lie in the controllable
or observable subspace. The subspaces come from :mod:`lcc_synth.analysis.staircase` (exact
structural split, log balancing, a probe-perturbed staircase with data-relative rank decisions;
its docstring gives the method and the measured figures).

Vehicle classification
----------------------
Vehicle ``i``'s two coordinate directions (its spacing/position and velocity errors) are *in* the
subspace when both project onto it with residual ``||(I - Q Q^T) e|| <= membership_tol`` (default
``1e-8``), *outside* when the subspace is orthogonal to both (``||Q^T e|| <= membership_tol``),
*partial* otherwise (e.g. FD-LCC with the output ``v_k``: ``v_0`` is observable, ``-p_0`` not).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from lcc_synth.analysis.staircase import (
    MEMBERSHIP_TOL,
    Staircase,
    kalman_decomposition,
    uncontrollable_modes,
)
from lcc_synth.errors import ConfigError
from lcc_synth.models.linear import LCCModel
from lcc_synth.models.records import Record

__all__ = [
    "SubspaceReport",
    "ControllabilityReport",
    "ObservabilityReport",
    "controllability_report",
    "observability_report",
    "default_outputs",
    "classify_vehicles",
]


# --------------------------------------------------------------------------------------------
# Reports on LCC models
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, repr=False)
class SubspaceReport(Record):
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

    def _verdict(self, yes: str, no: str) -> str:
        if self.rank == self.n_states:
            return yes
        return no if self.rank_upper < self.n_states else "undecided"

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
        }

    def contains_state(self, model: LCCModel, name: str) -> bool:
        """Whether the coordinate direction of state ``name`` lies in the subspace."""
        e = np.zeros(self.n_states)
        e[model.index(name)] = 1.0
        res = e - self.basis @ (self.basis.T @ e)
        return bool(np.linalg.norm(res) <= self.membership_tol)


@dataclass(frozen=True, repr=False)
class ControllabilityReport(SubspaceReport):
    """Controllable subspace of ``(A, B)``; ``controllable`` iff ``rank == n_states`` for sure.

    ``verdict`` is ``"controllable"``, ``"uncontrollable"`` or ``"undecided"`` (the data are
    within round-off of both; ``controllable`` is then False). ``uncontrollable_eigenvalues``
    are the eigenvalues of the uncontrollable block ``A_u`` of the Kalman decomposition (no
    input can move them); ``stabilizable`` iff all have a negative real part. When undecided,
    ``A_u`` also holds the undecided directions, so ``stabilizable`` errs on the safe side.
    Repeated eigenvalues of ``A_u`` come out scattered by round-off (see the module
    docstring), their real parts stay reliable to that scatter.
    """

    controllable: bool = False
    uncontrollable_eigenvalues: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def verdict(self) -> str:
        """``"controllable"``, ``"uncontrollable"`` or ``"undecided"``."""
        return self._verdict("controllable", "uncontrollable")

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
        }


@dataclass(frozen=True, repr=False)
class ObservabilityReport(SubspaceReport):
    """Observable subspace of ``(A, C)`` for the named state outputs; ``verdict`` is
    ``"observable"``, ``"unobservable"`` or ``"undecided"``."""

    outputs: list[str] = field(default_factory=list)
    observable: bool = False

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
    blocks = {vehicle: model.block(vehicle) for vehicle in model.vehicles}
    inside, outside, partial = classify_vehicles(blocks, basis, membership_tol)
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
        rank_upper=int(dec.n_c_upper),
        margin=dec.decision_margin,
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
