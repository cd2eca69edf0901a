"""Hankel matrices of DeeP-LCC data, the fundamental-lemma predictor and the exact reduction
of the data-enabled QP to its few constrained directions.

**Data and windows.** A data set holds ``T`` samples of the CAV inputs ``u_k`` (``n_c``),
the head velocity error ``e_k`` and the outputs ``y_{k+1}`` (``p``: velocity errors of every
vehicle behind the head, then the spacing errors of the CAVs), paired so that ``u_k`` and
``e_k`` act over ``[t_k, t_{k+1})`` and ``y_{k+1}`` is measured at its end (the simulator's
Euler step, :mod:`lcc_synth.simulation.engine`: the pair is an LTI system with direct
feed-through near the equilibrium). A Hankel matrix of depth ``L = Tini + N`` stacks ``L``
consecutive samples per column, time-major (``K = T - L + 1`` columns); ``U_p, E_p, Y_p``
are its first ``Tini`` block rows, ``U_f, E_f, Y_f`` the last ``N``.

**Fundamental lemma** (Willems et al. 2005): for an LTI system of order ``n_x`` whose inputs
are persistently exciting of order ``L + n_x``, every length-``L`` trajectory is ``H g`` for
some ``g``; with ``Tini`` at least the lag, ``(u_ini, e_ini, y_ini, u_f, e_f)`` fix ``y_f``
(:func:`predict`; ``tests/test_deeplcc.py`` reproduces a linear model's outputs to 1e-9).

**The QP in g** (Wang et al. 2023, eq. 23): minimise
``sum ||y_f||_Q^2 + ||u_f||_R^2 + lambda_g ||g||^2 + lambda_y ||Y_p g - y_ini||^2`` over ``g``
subject to ``U_p g = u_ini``, ``E_p g = e_ini``, ``E_f g = e_f`` and inequality constraints
on ``C g``, ``C = [U_f; W_f]``: the future inputs (acceleration limits) and, per CAV and step,
``w = s~ - t_gap v~`` of its predicted spacing and velocity errors (the absolute safe spacing
``s >= s_min + t_gap v`` is a lower bound on ``w``). With ``A = [U_p; E_p; E_f]`` and
``b = [u_ini; e_ini; e_f]`` this is ``min 1/2 g'Hg + f'g`` with
``H = 2 (Y_f'QY_f + U_f'RU_f + lambda_g I + lambda_y Y_p'Y_p)`` (positive definite) and
``f = -2 lambda_y Y_p' y_ini``.

**Exact reduction** (:func:`reduce`). By the KKT conditions the optimal ``g`` satisfies
``H g + f = A' lambda + C' nu`` for some multipliers, and ``A g = b`` fixes ``lambda`` given
``nu``; so the optimum lies on ``g(nu) = g0(b, y_ini) + G nu``, on which the cost equals
``1/2 nu' Gamma nu`` plus a constant and ``C g(nu) = c(b, y_ini) + Gamma nu`` (the linear term
vanishes because ``G' (H g0 + f) = G' A' lambda0 = 0``). In whitened coordinates
(``Z_X = W X'`` for any ``W`` with ``W' W = H^-1``) with ``Q_A`` an orthonormal basis of
``Z_A`` (``Z_A = Q_A R_A``) and ``M = (I - Q_A Q_A') Z_C``:

    Gamma = M' M,   c = Z_C' Q_A R_A^-T b - M' Z_f y_ini,   G = W' M,
    g0 = W' (Q_A R_A^-T b - (I - Q_A Q_A') Z_f y_ini),   Z_f = W (-2 lambda_y Y_p').

The whitening works in the ``m = N (p + n_c) + Tini p`` weighted rows ``B`` of the cost
(890 for the sweep's data) instead of the ``K`` columns (1931): with ``H = 2 (lambda_g I + B'B)``
and ``P = lambda_g I + B B'`` (Woodbury), ``W = (2 lambda_g)^-1/2 [I - B' P^-1 B;
sqrt(lambda_g) P^-1 B]`` (``K + m`` rows) has ``W' W = H^-1``, and only ``P`` is factored
(Cholesky). The rows of ``U_f`` and of ``Y_p`` are rows of ``B`` (``X = E B``; ``R`` and
``lambda_y`` are positive), so their whitened columns ``W B' E' = (2 lambda_g)^-1/2
[lambda_g B' P^-1 E'; sqrt(lambda_g) (E' - lambda_g P^-1 E')]`` take no difference of large
terms; ``A``'s and those of the constrained rows ``W_f`` (outside ``B`` when the spacing weight
is 0, which the schema allows) take one, ``X' - B' P^-1 B X'``, whose round-off is absolute
(about ``eps |X|``), not relative to a cancelled result. The maps back to ``g`` apply ``W'``.

So the online QP needs at most ``dim C = 2 N n_c`` unknowns (plus the spacing slacks) instead
of ``K`` (1931 for T = 2000), with constant matrices; ``Gamma`` is a Gram matrix (positive
semidefinite by construction, possibly singular: with exact noise-free data the future
outputs are determined and ``Gamma`` has rank ``N n_c + min(n_x, N n_c)``; the ``nu``-form
needs no rank decision, unlike a value function in ``C g``, which would be infinite off a
subspace). :mod:`lcc_synth.deeplcc.qp` solves it in the future inputs and the spacings'
deviation from what they imply, the variables in which it is well conditioned.
Only ``A`` must have full row rank: the persistency-of-excitation
check (:mod:`lcc_synth.deeplcc.data`) guarantees it.

**The noise-free limit** (``lambda_g = 0``, ``past_outputs = "exact"``; :func:`reduce` with
``exact_past``). With exact data of an LTI system the Hankel matrix ``D`` of all six windows
has rank ``L (n_c + 1) + n_x`` (58 of 175 rows on the test case, the next singular value
5e-16 of the largest against 9e-6 for the last kept one), and the cost and every constraint
see ``g`` only through ``D g``: ``g = V z`` on its row space (the SVD's right singular
vectors, a rank decision that refuses a gap too close to call) loses nothing and makes the
problem strictly convex on the equalities. Those (``A_V z = b``, with ``Y_p`` among them
when the past outputs are exact) repeat rows (``y_ini`` is fixed by ``u_ini, e_ini`` and the
initial state), so the equalities are handled by their own SVD: ``z = A_V^+ b + N xi`` with
``N`` an orthonormal basis of their null space, ``H_N = N' H N = L_N L_N'`` and
``M = L_N^-1 N' C'`` in place of the whitened projection above (the same ``Gamma = M' M``
and a vanishing linear term in ``nu``). This is the fundamental lemma's form of the
model-based MPC: on the test case DeeP-LCC's plan equals the finite-horizon QP of the model on
the same cost to 6e-13, with and without an active input bound, and two independent data
sets give the same plan. Noisy or nonlinear data give ``D`` full row rank (every future fits
the past: the unregularised QP plans ``u = y = 0``), so ``lambda_g = 0`` is refused by name
there; with the slack kept (``lambda_y = 1e4``) the plan stays 4.6e-4 from the MPC's. The
default path (``lambda_g > 0``, soft past) is the whitened one above, unchanged.

Numerical limits (measured): for the sweep's data (``problems/sweep_robustness.toml``, T = 2000,
n = 10, default weights) ``H`` has eigenvalues from ``2 lambda_g`` = 200 to 3.7e8 (condition
number 1.8e6; the refusal floor below is 4e-8) and ``P`` the same spread. Against the reduction
whitened by the Householder QR of the stacked ``sqrt(2) [B; sqrt(lambda_g) I]`` (round-off set
by ``cond(H)^1/2``; ``tests/test_deeplcc.py`` has it as a second method) this one agrees to
1.4e-15 / 8.8e-14 / 1.6e-12 of the largest entry of ``Gamma`` / ``Cb`` / ``Cy`` (three
scenarios); the Cholesky of the ``K x K`` ``H`` it replaced gave 2e-12 / 1.3e-11 / 4.4e-11, in
0.19 s instead of 0.11 s (one BLAS thread). On the test case (T = 160) the reduced QP's plan
matched the full QP in ``g`` (cvxpy + Clarabel at 1e-11) to 3e-11 (exact data) and 6e-11 (noisy
data). A ``lambda_g`` at or below the round-off of the data's squared norm, ``eps ||B||_F^2``,
leaves ``P`` (and ``H``) singular to working precision: :func:`reduce` refuses it by name
(``weights.lambda_g``); with exact data the noise-free limit is ``lambda_g = 0`` itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from lcc_synth.errors import ConfigError

__all__ = ["DataSet", "hankel", "Windows", "windows", "predict", "ReducedQP", "reduce",
           "spacing_rows"]


@dataclass(frozen=True, eq=False)
class DataSet:
    """Input/output data of DeeP-LCC, paired as in the module docstring.

    Attributes
    ----------
    u : numpy.ndarray
        ``(T, n_c)`` applied CAV accelerations (m/s^2).
    e : numpy.ndarray
        ``(T,)`` head velocity errors (m/s).
    y : numpy.ndarray
        ``(T, p)`` outputs one sample later (m/s, then m).
    dt : float
        Sample time (s).
    """

    u: np.ndarray
    e: np.ndarray
    y: np.ndarray
    dt: float

    @property
    def T(self) -> int:
        """Number of samples."""
        return int(self.u.shape[0])

    @property
    def n_c(self) -> int:
        """Number of CAV inputs."""
        return int(self.u.shape[1])

    @property
    def p(self) -> int:
        """Number of outputs."""
        return int(self.y.shape[1])


def hankel(w: np.ndarray, depth: int) -> np.ndarray:
    """Block Hankel matrix of depth ``depth`` of the samples ``w`` (``(T, d)`` or ``(T,)``):
    ``(depth * d, T - depth + 1)``, column ``j`` = ``[w_j; w_{j+1}; ...]`` (time-major)."""
    w = np.asarray(w, dtype=float)
    if w.ndim == 1:
        w = w[:, None]
    T, d = w.shape
    if depth < 1 or depth > T:
        raise ValueError(f"depth {depth} needs 1 <= depth <= T = {T}")
    view = np.lib.stride_tricks.sliding_window_view(w, depth, axis=0)  # (K, d, depth)
    return np.ascontiguousarray(view.transpose(2, 1, 0).reshape(depth * d, T - depth + 1))


@dataclass(frozen=True, eq=False)
class Windows:
    """Past and future block rows of the Hankel matrices (module docstring)."""

    Up: np.ndarray
    Ep: np.ndarray
    Yp: np.ndarray
    Uf: np.ndarray
    Ef: np.ndarray
    Yf: np.ndarray


def windows(data: DataSet, t_ini: int, horizon: int) -> Windows:
    """Split the depth-``t_ini + horizon`` Hankel matrices of ``data`` into past and future."""
    L = t_ini + horizon
    Hu, He, Hy = hankel(data.u, L), hankel(data.e, L), hankel(data.y, L)
    nc, p = data.n_c, data.p
    return Windows(Hu[: t_ini * nc], He[:t_ini], Hy[: t_ini * p],
                   Hu[t_ini * nc:], He[t_ini:], Hy[t_ini * p:])  # fmt: skip


def predict(win: Windows, u_ini, e_ini, y_ini, u_f, e_f) -> np.ndarray:
    """Outputs ``y_f`` ``(N, p)`` of the trajectory through the past window
    ``(u_ini, e_ini, y_ini)`` with future inputs ``(u_f, e_f)`` (arrays of samples, time
    first): ``Y_f g`` with the least-norm ``g`` solving the stacked Hankel equations (the
    fundamental lemma; exact for data of an LTI system)."""
    D = np.vstack([win.Up, win.Ep, win.Yp, win.Uf, win.Ef])
    rhs = np.concatenate([np.ravel(u_ini), np.ravel(e_ini), np.ravel(y_ini), np.ravel(u_f),
                          np.ravel(e_f)])  # fmt: skip
    g = np.linalg.lstsq(D, rhs, rcond=None)[0]
    N = np.ravel(e_f).size
    return (win.Yf @ g).reshape(N, -1)


@dataclass(frozen=True, eq=False)
class ReducedQP:
    """The constant matrices of the reduced QP (module docstring).

    Attributes
    ----------
    Gamma : numpy.ndarray
        ``(nC, nC)`` Hessian of the reduced cost ``1/2 nu' Gamma nu``; ``C g = c + Gamma nu``.
    Cb : numpy.ndarray
        ``(nC, nb)``: ``c`` from ``b = [u_ini; e_ini; e_f]``.
    Cy : numpy.ndarray
        ``(nC, Tini p)``: ``c`` from ``y_ini``.
    G, G0b, G0y : numpy.ndarray or None
        ``g = G0b b + G0y y_ini + G nu`` (``(K, ...)``; for checks and predictions), computed
        by :func:`reduce` with ``maps=True`` only: the controller never needs ``g``, and the
        maps' ``K``-row products and solves with ``P`` would add about a third to the
        reduction; ``Gamma``, ``Cb``, ``Cy`` and ``B`` are bit for bit the same either way.
    B : numpy.ndarray
        ``(nC, r)`` factor ``Gamma = B B'`` on its range (``B = V sqrt(Lambda)`` over the
        eigenvalues above round-off, ``nC eps lambda_max``): ``B B'`` is the exactly positive
        semidefinite ``Gamma`` the online QP is built from (:mod:`lcc_synth.deeplcc.qp`).
    n_u : int
        Rows of ``C`` that are future inputs (``N n_c``); the rest are the ``w`` rows.
    """

    Gamma: np.ndarray
    Cb: np.ndarray
    Cy: np.ndarray
    G: np.ndarray | None
    G0b: np.ndarray | None
    G0y: np.ndarray | None
    n_u: int
    B: np.ndarray


def spacing_rows(N: int, p: int, cav_velocity: list[int], t_gap: float) -> np.ndarray:
    """``(N n_c, N p)`` map of ``y_f`` to ``w = s~ - t_gap v~`` per step and CAV: CAV ``j``'s
    spacing error is output ``p - n_c + j``, its velocity error output ``cav_velocity[j]``."""
    n_c = len(cav_velocity)
    W = np.zeros((N * n_c, N * p))
    for k in range(N):
        for j, vj in enumerate(cav_velocity):
            W[k * n_c + j, k * p + p - n_c + j] = 1.0
            W[k * n_c + j, k * p + vj] -= t_gap
    return W


def _row_basis(X: np.ndarray, what: str, field: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin SVD ``X = U diag(s) W'`` of ``X`` cut at its numerical rank, a rank decision that
    does not depend on rounding: the kept singular values must exceed ``max(X.shape) eps
    s_max`` by a factor ``1e4`` and the dropped ones stay below it (exact data have a gap of
    many orders of magnitude), otherwise a :class:`ConfigError` for ``field``."""
    U, s, Wt = np.linalg.svd(X, full_matrices=False)
    if s.size == 0 or s[0] == 0.0:
        raise ConfigError(field, f"{what} is zero: the data carry no information")
    tol = max(X.shape) * np.finfo(float).eps * s[0]
    r = int(np.count_nonzero(s > tol))
    if s[r - 1] < 1e4 * tol:
        raise ConfigError(field, f"the rank of {what} is too close to call (singular value "
                          f"{s[r - 1] / s[0]:.1e} of the largest, round-off {tol / s[0]:.1e}); "
                          "this needs exact (noise-free) data, or lambda_g > 0 and "
                          'past_outputs = "slack"')  # fmt: skip
    return U[:, :r], s[:r], Wt[:r].T


def reduce(
    win: Windows,
    q: np.ndarray,
    r: np.ndarray,
    lambda_g: float,
    lambda_y: float,
    W_rows: np.ndarray,
    exact_past: bool = False,
    maps: bool = False,
) -> ReducedQP:
    """The exact reduction of the QP in ``g`` (module docstring).

    Parameters
    ----------
    win : Windows
    q : numpy.ndarray
        ``(p,)`` diagonal output weight ``Q`` (per step).
    r : numpy.ndarray
        ``(n_c,)`` diagonal input weight ``R``.
    lambda_g, lambda_y : float
        Regularisation of ``g`` (``>= 0``; ``0`` needs exact data, module docstring) and
        penalty of the past-output slack (unused with ``exact_past``).
    W_rows : numpy.ndarray
        ``(n_w, N p)`` maps ``y_f`` to the constrained output combinations ``w``.
    exact_past : bool
        ``Y_p g = y_ini`` as an equality (no slack): the noise-free form of the QP.
    maps : bool
        Also the maps back to ``g`` (:attr:`ReducedQP.G`, ``G0b``, ``G0y``; ``None``
        without), for checks and predictions; the online QP does not use them.
    """
    N = win.Ef.shape[0]
    qf = np.tile(np.asarray(q, float), N)
    rf = np.tile(np.asarray(r, float), N)
    if lambda_g == 0.0 or exact_past:
        return _reduce_exact(win, qf, rf, lambda_g, lambda_y, W_rows, exact_past, maps)
    # H = 2 (lambda_g I + B'B) with the weighted rows B; P = lambda_g I + B B' (m x m)
    nY, nU = win.Yf.shape[0], win.Uf.shape[0]
    B = np.vstack([np.sqrt(qf)[:, None] * win.Yf, np.sqrt(rf)[:, None] * win.Uf,
                   np.sqrt(lambda_y) * win.Yp])  # fmt: skip
    m = B.shape[0]
    P = B @ B.T
    floor = np.finfo(float).eps * float(np.trace(P))  # round-off of ||B||_F^2 >= ||B'B||
    too_small = ConfigError(
        "weights.lambda_g",
        f"{lambda_g:g} is too small for these data: 2 (lambda_g I + B'B), the Hessian of the "
        f"QP in g, is singular to working precision (lambda_g must exceed {floor:.1e}, the "
        "round-off of the data's squared norm); raise lambda_g, or use lambda_g = 0 with "
        "exact data",
    )
    if not lambda_g > floor:
        raise too_small
    P[np.diag_indices(m)] += lambda_g
    try:
        factor = sla.cho_factor(P, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        raise too_small from None
    # the rows of A = [U_p; E_p; E_f] and of W Y_f (a spacing weight may be 0) in general;
    # those of U_f (r > 0) and of Fy' = -2 lambda_y Y_p (lambda_y > 0) are rows of B: E B
    X = np.vstack([win.Up, win.Ep, win.Ef, W_rows @ win.Yf])  # A, then C's W Y_f rows
    nA, nW = X.shape[0] - W_rows.shape[0], W_rows.shape[0]
    E = np.zeros((m, nU + win.Yp.shape[0]))  # E'
    E[nY:nY + nU, :nU] = np.diag(1.0 / np.sqrt(rf))
    E[nY + nU:, nU:] = -2.0 * np.sqrt(lambda_y) * np.eye(win.Yp.shape[0])
    QX, QE = np.hsplit(sla.cho_solve(factor, np.hstack([B @ X.T, E]), check_finite=False),
                       [nA + nW])  # fmt: skip
    s, sl = 1.0 / np.sqrt(2.0 * lambda_g), np.sqrt(lambda_g)
    top_X = s * (X.T - B.T @ QX)  # the factor W X' (module docstring), in two blocks of rows
    bot_X = (s * sl) * QX
    top_E = (s * lambda_g) * (B.T @ QE[:, :nU])
    bot_E = (s * sl) * (E - lambda_g * QE)
    top_A, bot_A = top_X[:, :nA], bot_X[:, :nA]
    top_C = np.hstack([top_E, top_X[:, nA:]])
    bot_C = np.hstack([bot_E[:, :nU], bot_X[:, nA:]])
    bot_F = bot_E[:, nU:]
    QQ, RA = np.linalg.qr(np.vstack([top_A, bot_A]))
    K = B.shape[1]
    Qt, Qb = QQ[:K], QQ[K:]
    proj = Qt.T @ top_C + Qb.T @ bot_C
    M_top, M_bot = top_C - Qt @ proj, bot_C - Qb @ proj
    Gamma = M_top.T @ M_top + M_bot.T @ M_bot
    Gamma = 0.5 * (Gamma + Gamma.T)
    RinvT = sla.solve_triangular(RA, np.eye(nA), trans="T", check_finite=False)  # R_A^-T
    Cb = proj.T @ RinvT
    # M' Z_F without the K-row block of Z_F: top_F = s lambda_g B' Q_F
    Cy = -((s * lambda_g) * ((B @ M_top).T @ QE[:, nU:]) + M_bot.T @ bot_F)
    G = G0b = G0y = None
    if maps:
        top_F = (s * lambda_g) * (B.T @ QE[:, nU:])
        projF = Qt.T @ top_F + Qb.T @ bot_F

        def back(top: np.ndarray, bot: np.ndarray) -> np.ndarray:
            """``W' z`` of a whitened ``z`` (two blocks of rows): the map back to ``g``."""
            return s * (top + B.T @ sla.cho_solve(factor, sl * bot - B @ top,
                                                  check_finite=False))

        G = back(M_top, M_bot)
        G0b = back(Qt @ RinvT, Qb @ RinvT)
        G0y = -back(top_F - Qt @ projF, bot_F - Qb @ projF)
    return ReducedQP(Gamma, Cb, Cy, G, G0b, G0y, nU, _range_factor(Gamma))


def _range_factor(Gamma: np.ndarray) -> np.ndarray:
    """``B`` with ``B B' = Gamma`` over the eigenvalues above round-off (:class:`ReducedQP`)."""
    lam, V = np.linalg.eigh(Gamma)
    keep = lam > Gamma.shape[0] * np.finfo(float).eps * max(float(lam[-1]), 0.0)
    return V[:, keep] * np.sqrt(lam[keep])


def _reduce_exact(
    win: Windows,
    qf: np.ndarray,
    rf: np.ndarray,
    lambda_g: float,
    lambda_y: float,
    W_rows: np.ndarray,
    exact_past: bool,
    maps: bool,
) -> ReducedQP:
    """:func:`reduce` for ``lambda_g = 0`` or ``Y_p g = y_ini`` (module docstring, "The
    noise-free limit"): ``g = V z`` on the row space of the data, ``z = A_V^+ b + N xi`` on
    the equalities ``A_V z = b`` (``N`` an orthonormal basis of their null space), and the
    inequality multipliers ``nu`` as in the default path."""
    D = np.vstack([win.Up, win.Ep, win.Yp, win.Uf, win.Ef, win.Yf])
    if lambda_g == 0.0:  # the cost and every constraint see g through D g only
        V = _row_basis(D, "the Hankel matrix", "weights.lambda_g")[2]
        if V.shape[1] == min(D.shape):
            raise ConfigError("weights.lambda_g", "0 needs noise-free data: the Hankel matrix "
                              f"has full rank {V.shape[1]}, so every future fits the past "
                              "(noisy or nonlinear data); use lambda_g > 0")  # fmt: skip
    else:
        V = np.eye(D.shape[1])
    rows = [np.sqrt(qf)[:, None] * win.Yf, np.sqrt(rf)[:, None] * win.Uf]
    if not exact_past:
        rows.append(np.sqrt(lambda_y) * win.Yp)
    BV = np.vstack(rows) @ V
    H = 2.0 * (BV.T @ BV + lambda_g * np.eye(V.shape[1]))
    A = np.vstack([win.Up, win.Ep, win.Ef] + ([win.Yp] if exact_past else [])) @ V
    C = np.vstack([win.Uf, W_rows @ win.Yf]) @ V
    Fy = np.zeros((V.shape[1], 0)) if exact_past else -2.0 * lambda_y * (win.Yp @ V).T
    UA, sA, WA = _row_basis(A.T, "the equality constraints", "weights.past_outputs")
    Ap = UA @ (WA / sA).T  # the pseudo-inverse of A on its range: z_p = Ap b
    Nq = np.linalg.qr(UA, mode="complete")[0][:, UA.shape[1]:]  # null space of A
    Hn = Nq.T @ H @ Nq
    try:
        Ln = sla.cholesky(0.5 * (Hn + Hn.T), lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        raise ConfigError(
            "weights.lambda_g",
            f"{lambda_g:g} is too small for these data: the cost does not fix g on the "
            "equality constraints (its Hessian there is singular); raise lambda_g",
        ) from None
    M = sla.solve_triangular(Ln, Nq.T @ C.T, lower=True, check_finite=False)
    Gamma = M.T @ M
    Gamma = 0.5 * (Gamma + Gamma.T)
    # z(nu) = (I - N Hn^-1 N' H) Ap b - N Hn^-1 N' Fy y_ini + N Ln^-T M nu
    NHi = Nq @ sla.cho_solve((Ln, True), Nq.T, check_finite=False)  # N Hn^-1 N'
    P0 = Ap - NHi @ (H @ Ap)
    nb = win.Up.shape[0] + win.Ep.shape[0] + win.Ef.shape[0]
    if exact_past:
        Z0b, Z0y = P0[:, :nb], P0[:, nb:]
    else:
        Z0b, Z0y = P0, -NHi @ Fy
    G = G0b = G0y = None
    if maps:
        G = V @ (Nq @ sla.solve_triangular(Ln.T, M, lower=False, check_finite=False))
        G0b, G0y = V @ Z0b, V @ Z0y
    return ReducedQP(Gamma, C @ Z0b, C @ Z0y, G, G0b, G0y, win.Uf.shape[0],
                     _range_factor(Gamma))
