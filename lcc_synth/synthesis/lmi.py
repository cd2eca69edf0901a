"""The H2 LMI designs of every layout, one input or several (Clarabel via cvxpy, solved by
``solve_checked``): the full-state LMI (:func:`lmi_full_state`,
one CAV's design plant or a platoon's reduced plant; it equals the Riccati optimum to about
1e-8, which ``cross_check`` verifies) and the convex restriction of the structured design:
sparsity invariance with chordal decomposition (:func:`convex_restriction`) and the start it
offers the polish (:func:`restriction_start`, used by
:func:`~lcc_synth.synthesis.structured.structured_h2` and
:func:`~lcc_synth.synthesis.structured.structured_start`).

The restriction (the H2 state-feedback LMI with ``X`` restricted): ``min tr(Q X) + r tr(W)`` over a
block-diagonal ``X > 0`` and a ``Z`` with the pattern, ``A X + X A' + B Z + Z' B' + B_w B_w'
<= 0`` and ``[[W, Z], [Z', X]] >= 0``; the gain ``K = Z X^-1`` keeps every row's pattern and
``J(K) <= tr(Q X) + r tr(W)`` (the bound, reported but never used to rank: the polish works on
the true H2). One CAV has one heard block; a platoon a block per set of states heard by the
same CAVs; a ring moves its conserved mode off 0 (:data:`RING_CONSERVED_DECAY`) instead of
reducing to the hyperplane, whose basis would mix the pattern's zeros.

Measured (2 shared cores, Clarabel): the full-state LMI of a two-CAV platoon or ring of 6 (12
states) in about 0.05 s, its gain's H2 within 2e-10 (platoon) and 5e-12 (ring) of Riccati's;
of the one-AV ring of 20 (39 reduced states) 11 s. The restriction of those two of 6 about
0.03 s; of a ring of 20 with two CAVs and comm_range 2 (40 states, largest cone 26) about 2 s,
against 0.05 s for the whole ``method = "direct"`` design, which reaches the same polished H2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lcc_synth.synthesis.h2 import H2Plant, PlatoonPlant, SynthesisError

__all__ = [
    "LMIResult",
    "solve_checked",
    "lmi_full_state",
    "true_h2",
    "convex_restriction",
    "restriction_start",
    "RING_CONSERVED_DECAY",
]


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


def lmi_full_state(plant: H2Plant | PlatoonPlant, eps: float = 1e-7) -> LMIResult:
    """Full-state H2 synthesis by the standard LMI (Clarabel), one input or several.

    ``min tr(Q X) + r tr(W)`` over ``X > 0, Z, W`` with
    ``A X + X A' + B Z + Z' B' + B_w B_w' <= 0`` and ``[[W, Z], [Z', X]] >= 0``; then
    ``K = Z X^-1`` and ``J(K) <= tr(Q X) + r tr(W)``. The returned bound is its square root.

    One CAV works on the design plant (``A, B, B_w, Q``; ``g`` a row); a platoon or ring on
    its reduced plant (``A_r, B_r, B_wr, Q_r``; on a ring the hyperplane ``c x = 0``, where
    the conserved mode that no ``X > 0`` could certify is absent) and returns the gain rows
    ``K = K_r V'`` (``n_cav x nx``: on a ring the representative with no component along ``c``,
    whatever the basis ``V``).
    """
    import cvxpy as cp

    A, B, Bw, Q = (plant.Ar, plant.Br, plant.Bwr, plant.Qr)
    nx, nu = A.shape[0], B.shape[1]
    X = cp.Variable((nx, nx), symmetric=True)
    Z = cp.Variable((nu, nx))
    W = cp.Variable((nu, nu), symmetric=True)
    M = A @ X + X @ A.T + B @ Z + Z.T @ B.T + Bw @ Bw.T
    cons = [X >> eps * np.eye(nx), -(M + M.T) / 2 >> 0, cp.bmat([[W, Z], [Z.T, X]]) >> 0]
    obj = cp.Minimize(cp.trace(Q @ X) + plant.r * cp.trace(W))
    prob = cp.Problem(obj, cons)
    status, dt, value = solve_checked(prob, "full-state H2 LMI")
    Xv, Zv = X.value, Z.value
    Kr = np.linalg.solve(Xv.T, Zv.T).T
    Mv = A @ Xv + Xv @ A.T + B @ Zv + Zv.T @ B.T + Bw @ Bw.T
    residual = float(max(np.max(np.linalg.eigvalsh((Mv + Mv.T) / 2)), 0.0))
    g = plant.design_gain(Kr @ plant.V.T)
    return LMIResult(g, math.sqrt(max(value, 0.0)), status, dt, residual)


def true_h2(plant: H2Plant | PlatoonPlant, g: np.ndarray) -> float:
    """True closed-loop H2 norm of a design gain on either plant (``plant.true_h2``: a row,
    or a gain row per CAV; ``inf`` when not stable)."""
    return plant.true_h2(g)


def _x_blocks(veh: np.ndarray, mask: np.ndarray) -> tuple[list[np.ndarray], int]:
    """Index sets of the diagonal blocks of X and how many of them are heard: first the states
    heard by the same set of inputs (one block per set, in the order of their first state;
    one CAV: its heard states), then each vehicle's states that no input hears."""
    heard = mask.any(axis=0)
    classes: dict[bytes, list[int]] = {}
    for j in np.flatnonzero(heard):
        classes.setdefault(mask[:, j].tobytes(), []).append(int(j))
    blocks = [np.array(c, dtype=np.intp) for c in classes.values()]
    nh = len(blocks)
    for v in dict.fromkeys(veh[~heard]):
        blocks.append(np.flatnonzero((veh == v) & ~heard))
    return blocks, nh


def _restriction_plant(plant: H2Plant | PlatoonPlant):
    """``(A, B, B_w, Q, vehicle of each state)`` of the convex restriction: one CAV's design
    plant; a platoon's full-state plant, on a ring ``A_d - sigma e_j c / c_j`` (``j`` the last
    spacing state ``s_N``, ``sigma`` :data:`RING_CONSERVED_DECAY`): the same dynamics on the
    hyperplane ``c x = 0``, which the disturbances never leave, and the conserved mode moved
    from 0 to ``-sigma`` (``c A = -sigma c``)."""
    c = plant.conserved
    A = plant.A
    if c is not None:
        j = plant.nx - 2  # one dense row, last but one in the elimination order: small cliques
        A = A.copy()
        A[j] -= RING_CONSERVED_DECAY * c / c[j]
    return A, plant.B, plant.Bw, plant.Q, plant.vehicle_of_state()


def _cliques(adj: np.ndarray) -> list[np.ndarray]:
    """Maximal cliques of a chordal extension of the graph ``adj`` (natural elimination order).

    The LCC string's graph is banded (plus a dense block on the heard vehicles), so the
    natural order produces little fill-in.
    """
    n = adj.shape[0]
    adj = adj.copy()
    cand = []
    for k in range(n):
        later = np.flatnonzero(adj[k, k + 1 :]) + k + 1
        if later.size:
            adj[np.ix_(later, later)] = True  # fill-in makes the later neighbours a clique
        cand.append(np.concatenate([[k], later]))
    sets = [frozenset(c.tolist()) for c in cand]
    out = []
    for i, s in enumerate(sets):
        if not any(i != j and s < t for j, t in enumerate(sets)) and s not in [
            frozenset(o.tolist()) for o in out
        ]:
            out.append(np.array(sorted(s)))
    return out


def _windows(blocks: list[np.ndarray], band: int) -> list[np.ndarray]:
    """Index sets of the PSD terms of ``X_N``: windows of ``band + 1`` consecutive vehicles."""
    if band <= 0 or len(blocks) <= 1:
        return list(blocks)
    k = min(band + 1, len(blocks))
    return [np.concatenate(blocks[i : i + k]) for i in range(len(blocks) - k + 1)]


#: Ring: the rate ``sigma`` (1/s) the convex restriction gives the conserved total-spacing mode.
#: It changes neither the dynamics on the hyperplane ``c x = 0`` nor the true H2 norm of any
#: gain, only how much of the block-diagonal ``X`` the conserved direction takes, i.e. the
#: bound. Measured (ring of 20, CAVs 20 and 10, comm_range 2, q_s = 0.03, q_v = 0.15): sigma =
#: 0.01 / 0.1 / 0.3 / 1 / 3 gave the bounds 3.59 / 2.96 / 3.11 / 3.54 / 4.29 (true H2 of the
#: restriction's gain 2.18-2.38; polished from it or from the truncated Riccati gain 2.1069,
#: full information 2.0728; the restriction's solve about 2 s); the dense shift
#: ``-sigma c' c`` made every spacing one clique (largest cone 40 instead of 26) and a bound
#: of 7.25 at sigma = 1.
RING_CONSERVED_DECAY = 0.1


def convex_restriction(
    plant: H2Plant | PlatoonPlant, mask: np.ndarray, eps: float = 1e-7, chordal: bool = True,
    band: int = 4,
) -> LMIResult:
    """Feasible structured gain and an upper bound on its H2 norm (sparsity invariance), for
    one CAV (a gain row) or several (a row per CAV, each with its own pattern).

    The states heard by the same set of inputs form a class ``C``; ``X = blkdiag(X_C, ..., X_N)``
    with a full block per class and ``X_N`` on the states no input hears, and ``Z`` zero on
    every state its row does not hear, so ``K = Z X^-1`` (``K[:, C] = Z[:, C] X_C^-1``) keeps
    every row's pattern for ANY ``X_N``. One CAV has one class (its heard states P: ``X =
    blkdiag(X_P, X_N)``). ``X_N`` is parametrised as ``eps I + sum_k F_k' T_k F_k`` with
    ``T_k >= 0`` on windows of ``band + 1`` consecutive vehicles: every PSD matrix with that
    band (chordal) sparsity has this form, so ``X_N`` is a banded PSD matrix with its zeros
    built in (``band = 0``: 2x2 blocks per vehicle). A wider band tightens the bound (a full
    ``X_N`` is the least conservative) at the price of larger cliques in the Lyapunov LMI.

    A platoon works on its full-state plant (the pattern is on ``K``, not on ``K V``); a ring
    on ``A_d - sigma e_j c / c_j`` (:data:`RING_CONSERVED_DECAY`), whose closed loop has the
    eigenvalues of the reduced one and ``-sigma``, and the same true H2 norm for every gain
    (the disturbances stay on ``c x = 0``, where the two plants agree): no basis ``V`` enters.

    Parameters
    ----------
    plant : H2Plant or PlatoonPlant
    mask : numpy.ndarray
        Boolean mask of allowed gain entries: one CAV ``(nx,)`` (:func:`pattern_mask`), a
        platoon ``(n_cav, nx)`` (:func:`~lcc_synth.synthesis.h2.pattern_rows`).
    eps : float
        Lower bound on the eigenvalues of X.
    chordal : bool
        Decompose the Lyapunov LMI over the cliques of its sparsity graph (default). ``False``
        imposes it as one dense PSD constraint (for cross-checks; much slower for long strings).
    band : int
        Coupling range of ``X_N`` in vehicles (>= 0).

    Returns
    -------
    LMIResult
        ``g``: one CAV a row, a platoon ``(n_cav, nx)``.

    Raises
    ------
    SynthesisError
        Infeasible restriction (no gain of this pattern is certified by such an X) or solver
        failure.
    """
    import cvxpy as cp
    import scipy.sparse as sp

    A, B, Bw, Q, veh = _restriction_plant(plant)
    nx, nu = A.shape[0], B.shape[1]
    mask = np.asarray(mask, bool).reshape(nu, nx)
    blocks, nh = _x_blocks(veh, mask)
    classes = blocks[:nh]
    H_idx = np.concatenate(classes)
    N_idx = np.flatnonzero(~mask.any(axis=0))
    windows = _windows(blocks[nh:], int(band))
    # the heard states each row may use, as positions in H_idx
    row_free = [np.flatnonzero(mask[k, H_idx]) for k in range(nu)]

    def sel(idx, n=nx):
        return sp.csr_matrix((np.ones(len(idx)), (np.arange(len(idx)), idx)), shape=(len(idx), n))

    XC = [cp.Variable((len(c), len(c)), symmetric=True) for c in classes]
    T = [cp.Variable((len(w), len(w)), symmetric=True) for w in windows]
    if all(f.size == H_idx.size for f in row_free):
        z = cp.Variable((nu, len(H_idx)))
    else:  # a row's zeros on the classes it does not hear are built in
        zk = [cp.Variable((1, f.size)) for f in row_free]
        parts = [np.eye(nu)[:, [k]] @ v @ sel(f, H_idx.size)
                 for k, (v, f) in enumerate(zip(zk, row_free, strict=True))]  # fmt: skip
        z = sum(parts[1:], parts[0])
    cons = [x >> eps * np.eye(len(c)) for x, c in zip(XC, classes, strict=True)]
    cons += [t >> 0 for t in T]
    XH = XC[0] if nh == 1 else cp.bmat(
        [[XC[a] if a == b else np.zeros((len(ca), len(cb))) for b, cb in enumerate(classes)]
         for a, ca in enumerate(classes)])  # fmt: skip
    EH = sel(H_idx)
    X = EH.T @ XH @ EH + sum(sel(w).T @ t @ sel(w) for w, t in zip(windows, T, strict=True))
    X_const = np.zeros((nx, nx))
    X_const[N_idx, N_idx] = eps
    X = X + X_const
    Z = z @ EH
    AX = A @ X
    BZ = B @ Z
    M = AX + AX.T + BZ + BZ.T + Bw @ Bw.T
    # sparsity graph of M
    xpat = np.zeros((nx, nx), bool)
    for b in [*classes, *windows]:
        xpat[np.ix_(b, b)] = True
    zpat = np.zeros((nx, nx), bool)
    for k in range(nu):
        zpat[np.ix_(np.flatnonzero(B[:, k] != 0), H_idx[row_free[k]])] = True
    apat = (np.abs(A) > 0).astype(int) @ xpat.astype(int) > 0
    pat = apat | apat.T | zpat | zpat.T | (np.abs(Bw @ Bw.T) > 0) | np.eye(nx, dtype=bool)
    if chordal:
        cl = _cliques(pat)
        S = [cp.Variable((len(c), len(c)), symmetric=True) for c in cl]
        cons += [s >> 0 for s in S]
        Ssum = sum(sel(c).T @ s @ sel(c) for c, s in zip(cl, S, strict=True))
        cover = np.zeros((nx, nx), bool)
        for c in cl:
            cover[np.ix_(c, c)] = True
        rows, cols = np.nonzero(np.tril(cover))
        flat = rows * nx + cols  # row-major index into the nx*nx matrix
        MS = M + Ssum
        cons.append(cp.reshape(MS, (nx * nx,), order="C")[flat] == 0)
        cones = [len(c) for c in cl]
    else:
        cons.append(-(M + M.T) / 2 >> 0)
        cones = [nx]
    W = cp.Variable((nu, nu), symmetric=True)
    cons.append(cp.bmat([[W, z], [z.T, XH]]) >> 0)
    qterms = [cp.trace(Q[np.ix_(c, c)] @ x) for c, x in zip(classes, XC, strict=True)]
    obj = cp.Minimize(
        sum(qterms[1:], qterms[0])
        + sum(cp.trace(Q[np.ix_(w, w)] @ t) for w, t in zip(windows, T, strict=True))
        + float(np.trace(Q @ X_const))
        + plant.r * cp.trace(W)
    )
    prob = cp.Problem(obj, cons)
    status, dt, value = solve_checked(
        prob,
        "structured H2 convex restriction",
        "; the restriction certifies no gain of this pattern (use method = 'direct' to "
        "polish from the truncated Riccati gain)",
    )
    Xv = X_const.copy()
    for c, x in zip(classes, XC, strict=True):
        Xv[np.ix_(c, c)] += x.value
    for w, t in zip(windows, T, strict=True):
        Xv[np.ix_(w, w)] += t.value
    zv = np.asarray(z.value).reshape(nu, len(H_idx))
    K = np.zeros((nu, nx))
    start = 0
    for c, x in zip(classes, XC, strict=True):
        K[:, c] = np.linalg.solve(x.value.T, zv[:, start : start + len(c)].T).T
        start += len(c)
    K = np.where(mask, K, 0.0)  # exact zeros off every row's pattern (already so; explicit)
    Zv = np.zeros((nu, nx))
    Zv[:, H_idx] = zv
    Mv = A @ Xv + Xv @ A.T + B @ Zv + Zv.T @ B.T + Bw @ Bw.T
    residual = float(max(np.max(np.linalg.eigvalsh((Mv + Mv.T) / 2)), 0.0))
    cones += [*(len(c) for c in classes), *(len(w) for w in windows), len(H_idx) + nu]
    return LMIResult(
        plant.design_gain(K),
        math.sqrt(max(value, 0.0)),
        status,
        dt,
        residual,
        {"n_psd_cones": len(cones), "largest_cone": max(cones), "band": int(band)},
    )


def restriction_start(
    plant: H2Plant | PlatoonPlant, mask: np.ndarray, band: int = 4
) -> tuple[LMIResult, float]:
    """The convex restriction (:func:`convex_restriction`) and the true squared H2 norm of its
    gain, the start it offers the polish.

    Raises
    ------
    SynthesisError
        The restriction fails, or its gain does not stabilise the plant (solver status and
        residual named).
    """
    lmi = convex_restriction(plant, mask, band=band)
    J = plant.cost(lmi.g)
    if not math.isfinite(J):
        raise SynthesisError(
            "the convex restriction returned a gain that does not stabilise the plant "
            f"(solver status {lmi.status}, residual {lmi.residual:.2e})",
            {"status": lmi.status, "residual": lmi.residual},
        )
    return lmi, J
