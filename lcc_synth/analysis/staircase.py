"""Controllable / observable subspaces of a pair ``(A, B)`` decided without rounding (Section III).

The numerical core of :mod:`lcc_synth.analysis.controllability`: structural split, log
balancing, a probe-perturbed orthogonal staircase and the Kalman decomposition.

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
   Theorem 2 / Corollary 2). It does not change under permutations or diagonal scalings of the
   states; an orthogonal or general change of coordinates hides it, so the steps below must
   (and do) stand on their own.
2. Log balancing (:func:`balance_pair`): a diagonal scaling by powers of 2, the least-squares
   fit of ``log2|a_ij|`` on the graph of ``(A, B)``. It is exactly equivariant under diagonal
   changes of units and permutations, and ignores the overall scales of ``A`` and ``B``, so
   the pair the staircase sees does not depend on units (up to a factor 2 per state).
3. The controllability staircase (Van Dooren 1981; Varga's ``AB01ND`` / ``TB01PD``) of the
   balanced reachable part: an orthogonal transformation built one block at a time. At step
   ``k`` the part of the input direction not yet reached (the *coupling*: ``B`` at step 1, a
   block of the transformed ``A`` after) is compressed by an SVD. ``T.T @ A @ T`` is then block
   upper triangular ``[[A_c, A_12], [0, A_u]]`` and ``T.T @ B = [[B_c], [0]]``; the first ``n_c``
   columns of ``T`` (re-orthonormalised after undoing the balancing) span the controllable
   subspace.
4. Rank decisions relative to the data, with probes: the staircase is run in lockstep on
   ``PROBES = 3`` copies of the balanced pair perturbed by fixed-seed random matrices of
   relative Frobenius size ``eta = PROBE_FACTOR * nx * eps`` (``PROBE_FACTOR = 8``, i.e.
   ``||E_A|| = eta ||A_bal||_F``, ``||E_B|| = eta ||B_bal||_F``: no absolute floor). The
   *noise* of a coupling singular value ``sigma`` is the largest change of it over the probes,
   or ``||A_bal||_2`` times the angle between the probes' and the unperturbed subspace built so
   far, whichever is larger. With ``q = sigma / noise``:

   - ``q >= KEEP_RATIO = 30``: kept (no perturbation of size ``eta`` can make it vanish);
   - ``q <= DROP_RATIO = 0.1``, and the noise ``KEEP_RATIO`` times below every coupling kept so
     far (the probes still linear): dropped (the coupling is what round-off amplified along
     the chain makes of an exact zero: rounding of the data, ~``eps``, is ~100 times below
     ``eta``, so a true zero has ``q`` ~ 1e-2);
   - otherwise ``undecided``: the staircase stops there (``rank`` = what was kept, a lower
     bound) and a second pass keeps every coupling above ``eta * scale`` (``rank_upper``, an
     upper bound: what it drops is a perturbation of that size). Reports then say
     ``verdict = "undecided"`` unless both bounds give the same verdict.

   Every quantity is a ratio of data-derived numbers, so ``B * 1e-12`` or ``A, B`` in other
   time units give the same decisions. A Gaussian probe is distributed the same in any
   orthonormal coordinates, so orthogonal changes of coordinates only change the (tiny)
   rounding of the data.

Why probes rather than a tolerance: in coordinates without visible structure, round-off is
amplified along the chain of vehicles by roughly ``||A||/sigma`` per step. Measured on the
sweep of ``tests/test_controllability_invariance.py`` (lcc m <= 5, n <= 15, cf/fd-LCC, CCC,
homogeneous and heterogeneous alphas) after random orthogonal or cond-10 similarity
transforms: couplings that are exactly zero in theory come out up to 5e-8 ||A|| while true
couplings go down to 2e-6 ||A||, so no fixed multiple of ``eps`` separates them (the previous
``100 nx eps max(||A||, ||B||, 1)``, ~1e-11, gave 32 instead of 22 for lcc(5, 10) and 42
instead of 32 for lcc(5, 15); with its floor ``B * 1e-12`` gave rank 0 and ``B * 1e12`` dropped
true couplings). Measured ``q``: true couplings >= 555 (1st percentile 3.5e3) and dropped ones
<= 0.056 (99th percentile 0.046) in dense coordinates; >= 1.9e5 with nothing to drop after
permutations, unit changes, ``B * 1e+-12`` and 1e-12 relative perturbations. Before/after on
300 seeded models x 8 transforms: wrong ranks 586 of 2400 before (orthogonal 55, similarity
57, orthogonal after 1e-12 perturbation 55, ``B*1e-12`` 239, ``B*1e12`` 180), 0 after; 6-8 %
of the dense-coordinate cases are ``undecided`` (long homogeneous strings whose tail couplings
are ~1e-3: the probes' noise grows ~100-1000x per step there), the theory always within
``[rank, rank_upper]``; no structure-preserving transform is ever undecided. On the eq. (13)
boundary the float model is within ~1e-16 of the exact rank-``n + 2`` system: it is reported
uncontrollable (or undecided after a dense transform), never controllable. Also note that two
or more identical HDVs at ``|eq. 13| = delta`` lose a mode at distance ~``delta^2``: for
``delta <= 1e-9`` that is below round-off and is reported uncontrollable with confidence.
Cost: about 4-6 staircases, ~10-20 ms for 42 states.

A fixed ``tol`` can still be passed (a plain threshold on the balanced couplings, no
``undecided``; not invariant).

Observability is controllability of the dual pair ``(A.T, C.T)``: the observable subspace is the
row space of the observability matrix, i.e. the orthogonal complement of the unobservable
subspace; the state ``e_i^T x`` can be reconstructed from the output iff ``e_i`` lies in it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lcc_synth.errors import ConfigError

__all__ = [
    "TOLERANCE_FACTOR",
    "PROBE_FACTOR",
    "PROBES",
    "KEEP_RATIO",
    "DROP_RATIO",
    "MEMBERSHIP_TOL",
    "default_tolerance",
    "structural_split",
    "balance_pair",
    "StaircaseStep",
    "Staircase",
    "kalman_decomposition",
    "uncontrollable_modes",
    "controllable_subspace",
    "observable_subspace",
]

EPS = float(np.finfo(float).eps)
PROBE_FACTOR = 8.0
PROBES = 3
KEEP_RATIO = 30.0
DROP_RATIO = 0.1
TOLERANCE_FACTOR = PROBE_FACTOR  # backward-compatible name: probe size in units of nx * eps
MEMBERSHIP_TOL = 1e-8
_PROBE_SEED = 0x1CC5


def default_tolerance(A: np.ndarray, B: np.ndarray) -> float:
    """Size of the probe perturbation of ``A``: ``PROBE_FACTOR * nx * eps * ||A||_F``.

    No absolute floor: it scales with the data. The staircase compares every coupling with
    how much probes of this size move it (see the module docstring), not with this number
    itself; pass an explicit ``tol`` to :func:`kalman_decomposition` for a fixed threshold.
    """
    A, B = _check_pair(A, B)
    return float(PROBE_FACTOR * A.shape[0] * EPS * np.linalg.norm(A, "fro"))


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
    The split does not change under permutations and diagonal scalings of the states.

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


def balance_pair(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """State scaling ``d`` (powers of 2) that balances the pair ``(A, B)`` in the log sense.

    ``x = log2 d`` minimises ``sum (log2|a_ij| - x_i + x_j - mu)^2`` over the non-zero
    off-diagonal entries of ``A`` plus ``sum (log2|b_ij| - x_i + y_j)^2`` over those of ``B``
    (``mu``: the overall scale of ``A``, ``y``: input scalings, both free), i.e. it makes every
    entry of ``diag(d)^-1 A diag(d)`` as close to the others in magnitude as the pattern allows
    (least squares on the graph of ``A``; minimum norm solution). Scaling the states by any
    ``D`` shifts ``x`` by ``log2 D`` exactly (up to a constant per connected component, which
    changes nothing), scaling ``A`` or ``B`` (units of time, of the input) only moves ``mu`` or
    ``y``, and a permutation permutes ``x``,
    so the balanced pair does not depend on the units of the states (up to the rounding of
    ``x`` to integers, a factor of at most 2 per state). Unlike LAPACK ``gebal`` it also
    scales states whose column or row is zero (``-p_0`` of FD-LCC). Entries below
    ``nx * eps * ||A||_F`` (``||B||_F`` for ``B``) are ignored: round-off debris of an
    earlier transformation would otherwise dominate the logarithms.
    """
    A, B = _check_pair(A, B)
    nx, nu = B.shape
    # Entries at rounding level (debris of earlier transformations) would pull the logs to
    # -100 and ruin the scaling: below nx eps ||.||_F they count as zero here.
    debris = nx * EPS
    ia, ja = np.nonzero(np.abs(A) > debris * np.linalg.norm(A, "fro"))
    off = ia != ja
    ia, ja = ia[off], ja[off]
    ib, jb = np.nonzero(np.abs(B) > debris * np.linalg.norm(B, "fro"))
    if nx == 0 or ia.size + ib.size == 0:
        return np.ones(nx)
    # x_i - x_j + mu ~ log2|a_ij| (mu: the scale of A, free, so that c A balances like A) and
    # x_i - y_j ~ log2|b_ij|: least squares via the normal equations (minimum norm solution).
    na, nb = ia.size, ib.size
    M = np.zeros((na + nb, nx + nu + 1))
    M[np.arange(na), ia] += 1.0
    M[np.arange(na), ja] -= 1.0
    M[np.arange(na), nx + nu] = 1.0
    M[na + np.arange(nb), ib] += 1.0
    M[na + np.arange(nb), nx + jb] -= 1.0
    logs = np.concatenate([np.log2(np.abs(A[ia, ja])), np.log2(np.abs(B[ib, jb]))])
    x = (np.linalg.pinv(M.T @ M, hermitian=True) @ (M.T @ logs))[:nx]
    return np.exp2(np.round(x))


@dataclass(frozen=True)
class StaircaseStep:
    """One rank decision of the staircase.

    Attributes
    ----------
    singular_values : ndarray
        Singular values of the coupling block (the input ``B`` at the first step, a block of
        the transformed ``A`` after), largest first.
    noise : ndarray
        For each, the largest change caused by the probe perturbations (see the module
        docstring); ``nan`` with a fixed tolerance.
    kept, upper : int
        Directions kept for sure / kept when the undecided ones are counted in.
    """

    singular_values: np.ndarray
    noise: np.ndarray
    kept: int
    upper: int

    @property
    def ratios(self) -> np.ndarray:
        """``singular_values / noise`` (``inf`` for an exact non-zero, 0 for an exact zero)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            q = self.singular_values / self.noise
        q[(self.noise == 0) & (self.singular_values > 0)] = np.inf
        q[self.singular_values == 0] = 0.0
        return q


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
        Dimension of the controllable subspace. When some decision is undecided this is the
        lower value (the undecided directions counted as zero); ``n_c_upper`` is the other one.
    steps : list of int
        Block sizes of the staircase (they sum to ``n_c``).
    min_accepted : float
        Smallest coupling singular value counted as non-zero (``inf`` if none).
    max_rejected : float
        Largest coupling singular value counted as zero (0 if none), in balanced coordinates.
    n_structural : int
        Number of states removed exactly by :func:`structural_split`.
    tol : float
        Size of the probe perturbation of the balanced ``A`` (or the fixed tolerance passed).
    n_c_upper : int
        Dimension when the undecided directions are counted as controllable (``== n_c`` when
        every decision was clear).
    undecided : bool
        Some coupling was neither clearly above nor clearly at the rounding level.
    min_kept_ratio, max_dropped_ratio : float
        Smallest ``coupling / noise`` kept, largest dropped (``inf`` / 0 when none); kept needs
        ``>= KEEP_RATIO``, dropped ``<= DROP_RATIO``.
    step_log : list of StaircaseStep
        Every decision, for diagnostics.
    """

    T: np.ndarray
    n_c: int
    steps: list[int]
    min_accepted: float
    max_rejected: float
    n_structural: int
    tol: float
    n_c_upper: int = -1
    undecided: bool = False
    min_kept_ratio: float = np.inf
    max_dropped_ratio: float = 0.0
    step_log: list[StaircaseStep] = field(default_factory=list, repr=False)

    @property
    def decision_margin(self) -> float:
        """``min(min_kept_ratio / KEEP_RATIO, DROP_RATIO / max_dropped_ratio)``: at least 1 when
        every decision is clear, below 1 when undecided (``inf`` when nothing was decided)."""
        up = self.min_kept_ratio / KEEP_RATIO
        down = DROP_RATIO / self.max_dropped_ratio if self.max_dropped_ratio > 0 else np.inf
        return float(min(up, down))


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
        nv = np.linalg.norm(v)
        if nv == 0.0:  # already the coordinate direction
            continue
        v /= nv
        Y[j:, :] -= 2.0 * np.outer(v, v @ Y[j:, :])
        out.append((j, v))
    return out


class _Run:
    """One staircase in progress: the transformed ``A``, the current coupling, optionally ``T``."""

    def __init__(self, A: np.ndarray, B: np.ndarray, track: bool):
        self.Ak = A.copy()
        self.coupling = B.copy()
        self.T = np.eye(A.shape[0]) if track else None

    def advance(self, U: np.ndarray, n_c: int, r: int) -> None:
        """Rotate the trailing coordinates so that ``U[:, :r]`` come first (Householder)."""
        for j, v in _reflectors(U[:, :r]):
            k = n_c + j
            self.Ak[k:, :] -= 2.0 * np.outer(v, v @ self.Ak[k:, :])
            self.Ak[:, k:] -= 2.0 * np.outer(self.Ak[:, k:] @ v, v)
            if self.T is not None:
                self.T[:, k:] -= 2.0 * np.outer(self.T[:, k:] @ v, v)
        self.coupling = self.Ak[n_c + r :, n_c : n_c + r]


def _probes(A: np.ndarray, B: np.ndarray, eta: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """``PROBES`` deterministic random perturbations of relative Frobenius size ``eta``."""
    rng = np.random.default_rng(_PROBE_SEED)
    na, nb = np.linalg.norm(A, "fro"), np.linalg.norm(B, "fro")
    out = []
    for _ in range(PROBES):
        EA = rng.standard_normal(A.shape)
        EB = rng.standard_normal(B.shape)
        EA *= eta * na / max(np.linalg.norm(EA, "fro"), np.finfo(float).tiny)
        EB *= eta * nb / max(np.linalg.norm(EB, "fro"), np.finfo(float).tiny)
        out.append((A + EA, B + EB))
    return out


def _decide(sv: np.ndarray, noise: np.ndarray, smallest_kept: float) -> tuple[int, int]:
    """``(kept, upper)``: leading values kept for sure, and ``sv.size`` minus the trailing
    values dropped for sure (so ``kept < upper`` means some are undecided).

    A value is dropped only while the probes are in their linear regime (their noise is
    ``KEEP_RATIO`` times below every coupling kept so far): past that point the probes no
    longer tell how large the round-off of the unperturbed staircase is.
    """
    q = StaircaseStep(sv, noise, 0, 0).ratios
    keep = q >= KEEP_RATIO
    drop = (q <= DROP_RATIO) & (noise * KEEP_RATIO <= smallest_kept)
    low = int(np.argmin(keep)) if not keep.all() else sv.size
    high = sv.size - (int(np.argmin(drop[::-1])) if not drop.all() else sv.size)
    return low, max(low, high)


def _staircase(A: np.ndarray, B: np.ndarray, tol: float | None, upper: bool):
    """Staircase of ``(A, B)``.

    ``tol=None, upper=False``: probe-based decisions; it stops at the first undecided step (the
    lower bound of the rank). ``upper=True``: every coupling above the rounding level
    ``eta * scale`` is kept (an upper bound: the couplings dropped are a perturbation of that
    size). A float ``tol``: fixed threshold. Returns the fields of :class:`Staircase` except
    the structural ones.
    """
    nx = A.shape[0]
    eta = PROBE_FACTOR * max(nx, 1) * EPS
    scale_a, scale_b = np.linalg.norm(A, "fro"), np.linalg.norm(B, "fro")
    probing = tol is None and not upper
    runs = [_Run(A, B, True)]
    if probing:
        runs += [_Run(Ap, Bp, True) for Ap, Bp in _probes(A, B, eta)]
    norm_a = np.linalg.norm(A, 2) if A.size else 0.0
    n_c = 0
    steps: list[int] = []
    log: list[StaircaseStep] = []
    min_acc, max_rej = np.inf, 0.0
    min_q, max_q = np.inf, 0.0
    undecided = False
    while n_c < nx and runs[0].coupling.shape[1] > 0:
        svds = [np.linalg.svd(run.coupling, full_matrices=False) for run in runs]
        sv = svds[0][1]
        scale = scale_b if n_c == 0 else scale_a
        noise = np.full(sv.shape, np.nan)
        if probing:
            # How far the probes moved the coupling values, and the basis built so far (a basis
            # tilted by an angle theta can create a coupling of ||A|| theta out of nothing).
            Q = runs[0].T[:, :n_c]
            noise = np.zeros(sv.shape)
            for run, s in zip(runs[1:], svds[1:], strict=True):
                Qp = run.T[:, :n_c]
                tilt = np.linalg.norm(Qp - Q @ (Q.T @ Qp), 2) if n_c else 0.0
                noise = np.maximum(noise, np.maximum(np.abs(s[1] - sv), norm_a * tilt))
            low, high = _decide(sv, noise, min_acc)
        else:
            cut = eta * scale if tol is None else tol
            low = high = int(np.sum(sv > cut))
        rec = StaircaseStep(sv, noise, low, high)
        log.append(rec)
        r = low
        if probing:
            q = rec.ratios
            if low:
                min_q = min(min_q, float(q[:low].min()))
            if high < sv.size:
                max_q = max(max_q, float(q[high:].max()))
            if high > low:  # undecided: the margin is below 1 and the lower path stops here
                undecided = True
                min_q = min(min_q, float(q[low:high].min()))
        if r:
            min_acc = min(min_acc, float(sv[r - 1]))
        if r < sv.size:
            max_rej = max(max_rej, float(sv[r]))
        if r == 0:
            break
        for run, (U, _, _) in zip(runs, svds, strict=True):
            run.advance(U, n_c, r)
        steps.append(r)
        n_c += r
        if undecided:
            break
    return runs[0].T, n_c, steps, min_acc, max_rej, undecided, min_q, max_q, log


def kalman_decomposition(
    A: np.ndarray, B: np.ndarray, tol: float | None = None, structural: bool = True
) -> Staircase:
    """Orthogonal controllability staircase (Kalman) decomposition of ``(A, B)``.

    Parameters
    ----------
    A : (nx, nx) array
    B : (nx, nu) array
    tol : float, optional
        Fixed absolute threshold: coupling singular values (of the balanced pair) at or below
        it count as zero, with no ``undecided`` verdict. Default (recommended): probe-based
        decisions relative to the data, see the module docstring.
    structural : bool
        First remove the states unreachable in the graph of ``A`` (exact, see
        :func:`structural_split`) and run the staircase on the rest.

    Returns
    -------
    Staircase
    """
    A, B = _check_pair(A, B)
    nx = A.shape[0]
    if structural:
        reach, unreach = structural_split(A, B)
    else:
        reach, unreach = np.arange(nx), np.arange(0)
    Ar, Br = A[np.ix_(reach, reach)], B[reach]
    d = balance_pair(Ar, Br)
    Ab, Bb = Ar * (d[None, :] / d[:, None]), Br / d[:, None]
    tol = None if tol is None else float(tol)
    Tb, n_c, steps, min_acc, max_rej, undecided, min_q, max_q, log = _staircase(
        Ab, Bb, tol, upper=False
    )
    n_up = n_c
    if undecided:
        n_up = max(n_c, _staircase(Ab, Bb, tol, upper=True)[1])
    # Back to the original coordinates: diag(d) Tb = Q R, R upper triangular, keeps the nested
    # subspaces of the leading columns and makes the transformation orthogonal again.
    Tr, R = np.linalg.qr(d[:, None] * Tb)
    Tr = Tr * np.where(np.diag(R) < 0, -1.0, 1.0)
    T = np.zeros((nx, nx))
    T[np.ix_(reach, np.arange(reach.size))] = Tr
    T[unreach, reach.size + np.arange(unreach.size)] = 1.0
    probe = default_tolerance(Ab, Bb) if tol is None else tol
    return Staircase(
        T,
        n_c,
        steps,
        min_acc,
        max_rej,
        int(unreach.size),
        probe,
        n_c_upper=n_up,
        undecided=bool(undecided),
        min_kept_ratio=min_q,
        max_dropped_ratio=max_q,
        step_log=log,
    )


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


