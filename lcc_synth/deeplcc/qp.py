"""DeeP-LCC's online QP, formulated once with CasADi on the reduced data matrices.

The reduced problem (:mod:`lcc_synth.deeplcc.hankel`) is ``min 1/2 nu' Gamma nu`` with the
constrained quantities ``v = C g = c + Gamma nu``: the future CAV inputs ``v_u`` and, per CAV
and step, ``v_w = s~ - t_gap v~`` of its predicted spacing and velocity errors. It is solved in
the variables that the data make well conditioned: the future inputs themselves and the
deviation of the predicted spacings from what the inputs imply. With the blocks of ``Gamma``
(``Gamma_uu`` positive definite: the inputs are free), ``K = Gamma_wu Gamma_uu^-1`` and the
Schur complement ``S = Gamma_ww - K Gamma_uw = V diag(s) V'`` (its eigenvalues above round-off,
``S^1/2 = V diag(sqrt(s))``), every ``v`` in ``c + range(Gamma)`` is
``v_w = c_w + K (v_u - c_u) + S^1/2 beta`` and the cost is
``1/2 (v_u - c_u)' Gamma_uu^-1 (v_u - c_u) + 1/2 ||beta||^2`` (the block factorisation of the
pseudo-inverse; the minimum-norm ``beta`` is optimal). Decision vector
``x = [v_u (N n_c), beta (rank S), sigma (N n_c)]``::

    min  1/2 (v_u - c_u)' Gamma_uu^-1 (v_u - c_u) + 1/2 ||beta||^2
         + rho_1 sum sigma + rho_2 sum sigma^2
    s.t. a_min <= v_u <= a_max                                  (hard, every CAV and step)
         c_w + K (v_u - c_u) + S^1/2 beta + sigma >= s_min + margin + t_gap v_eq - s_eq
         sigma >= 0                                             (soft, absolute metres)

(with ``constraints.spacing = "equilibrium"``: ``t_gap = 0``, ``v_w`` the spacing errors
from ``s_eq``, the lower bound ``lo + margin`` and upper rows ``-v_w + sigma_up >= -(hi -
margin)`` with their own slacks, :func:`formulate`'s ``upper``), so the bound is
``s >= s_min + margin + t_gap v`` with ``s = s_eq + s~``, ``v = v_eq + v~`` (the
MPC's definition, :class:`lcc_synth.mpc.settings.Constraints`), its l1 penalty exact. Only the
vectors change between steps (``c`` is affine in the measured past); the Hessian, the
constraint matrix and the maps of ``c`` into ``q`` and the bounds are extracted from the
CasADi expressions once (:func:`formulate`).

Why these variables (measured, OSQP at eps 1e-6): with noisy nonlinear data ``Gamma`` has
``N n_c`` eigenvalues of order 1 (the inputs) and ``N n_c`` from 3e-3 down to 1e-6 (the
spacings the data nearly determine). Solved in ``nu`` (Hessian ``Gamma``) or in its
eigen-coordinates, ADMM needed up to 10000 iterations on the two-CAV platoon brake (4 and 13
failures in 800 steps, p99 285 / 800 ms CPU); in these variables p99 81 ms and 2 failures, and
on the one-CAV head brake p99 0.6 ms (``nu``: 2.8 ms).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from lcc_synth.deeplcc.hankel import ReducedQP
from lcc_synth.errors import ConfigError
from lcc_synth.interrupts import checkpoint
from lcc_synth.mpc.formulation import QPMatrices

__all__ = ["DeepQP", "formulate", "ExactSolver"]


@dataclass(frozen=True, eq=False)
class DeepQP:
    """The QP of one DeeP-LCC controller (module docstring).

    Attributes
    ----------
    qp : QPMatrices
        ``P`` (upper triangle) and ``A`` for OSQP.
    q0 : numpy.ndarray
        Constant part of the linear term.
    Qc, Gc : numpy.ndarray
        Dependence of the linear term and of the constraint offsets on ``c``.
    n_w : int
        Future inputs (= spacing rows = slacks), ``N n_c``.
    n_beta : int
        Rank of ``S``.
    n_up : int
        Upper spacing rows ``-v_w + sigma_up >= b_up`` and their slacks (``n_w`` with
        ``constraints.spacing = "equilibrium"``, else 0).
    """

    qp: QPMatrices
    q0: np.ndarray
    Qc: np.ndarray
    Gc: np.ndarray
    n_w: int
    n_beta: int
    n_up: int = 0

    @property
    def n_var(self) -> int:
        """Number of decision variables."""
        return 2 * self.n_w + self.n_beta + self.n_up

    def vectors(self, c: np.ndarray, a_min: float, a_max: float, b_w: np.ndarray,
                b_up: np.ndarray | None = None):  # fmt: skip
        """``(q, l, u)`` of OSQP for ``c`` and the spacing bounds ``b_w`` (``(n_w,)``) and,
        with upper rows, ``b_up`` (``(n_up,)``; ``-inf`` disables a row)."""
        n, nu = self.n_w, self.n_up
        off = self.Gc @ c
        lo = np.empty(3 * n + 2 * nu)
        hi = np.empty(3 * n + 2 * nu)
        lo[:n], hi[:n] = a_min, a_max
        lo[n:2 * n], hi[n:2 * n] = b_w, np.inf
        lo[2 * n:3 * n], hi[2 * n:3 * n] = 0.0, np.inf
        if nu:
            lo[3 * n:3 * n + nu] = -np.inf if b_up is None else b_up
            hi[3 * n:3 * n + nu] = np.inf
            lo[3 * n + nu:], hi[3 * n + nu:] = 0.0, np.inf
        return self.Qc @ c + self.q0, lo - off, hi - off

    def plan(self, x: np.ndarray) -> np.ndarray:
        """The planned inputs ``v_u`` of a solution (``(n_w,)``, step-major)."""
        return x[: self.n_w]

    def slack(self, x: np.ndarray) -> np.ndarray:
        """The spacing slacks of a solution."""
        return x[self.n_w + self.n_beta:]

    def shift_indices(self, n_c: int) -> tuple[np.ndarray, np.ndarray]:
        """Index arrays shifting a primal / dual solution by one step (warm start; ``beta``,
        which has no time order, is kept)."""
        n = self.n_w
        N = n // n_c
        k = np.minimum(np.arange(N) + 1, N - 1)
        base = (k[:, None] * n_c + np.arange(n_c)[None, :]).ravel()
        z = [base, n + np.arange(self.n_beta), n + self.n_beta + base]
        y = [base, base + n, base + 2 * n]
        if self.n_up:
            z.append(2 * n + self.n_beta + base)
            y += [base + 3 * n, base + 4 * n]
        return np.concatenate(z), np.concatenate(y)


def formulate(red: ReducedQP, slack: float, slack_quadratic: float,
              upper: bool = False) -> DeepQP:  # fmt: skip
    """Build the QP of the module docstring with CasADi and extract its matrices once.

    ``upper`` adds the upper spacing rows ``-v_w + sigma_up >= b_up`` with their own slacks
    (the same l1 and quadratic penalty): the spacing-error bound of
    ``constraints.spacing = "equilibrium"`` is two-sided (the rows ``v_w`` are then the
    spacing errors ``s~`` alone).
    """
    import casadi as ca

    G = red.B @ red.B.T
    n = red.n_u
    Guu, Guw, Gww = G[:n, :n], G[:n, n:], G[n:, n:]
    try:
        Luu = np.linalg.cholesky(Guu)
    except np.linalg.LinAlgError:
        raise ConfigError("data", "the data do not leave the future inputs free (Gamma_uu is "
                          "singular): collect richer data") from None  # fmt: skip
    Gi = np.linalg.inv(Luu)
    Gi = Gi.T @ Gi
    K = np.linalg.solve(Guu, Guw).T
    S = Gww - K @ Guw
    s, V = np.linalg.eigh(0.5 * (S + S.T))
    keep = s > G.shape[0] * np.finfo(float).eps * max(float(np.abs(s).max(initial=0.0)),
                                                     float(np.linalg.norm(G, 2)))  # fmt: skip
    Sh = V[:, keep] * np.sqrt(s[keep])
    nb = Sh.shape[1]
    n_up = n if upper else 0
    nz = 2 * n + nb + n_up
    x = ca.MX.sym("x", nz)
    c = ca.MX.sym("c", 2 * n)
    vu, beta = x[:n], x[n:n + nb]
    sigma = x[n + nb:n + nb + n] if upper else x[n + nb:]
    du = vu - c[:n]
    cost = (0.5 * ca.dot(du, ca.DM(Gi) @ du) + 0.5 * ca.dot(beta, beta)
            + slack * ca.sum1(sigma) + slack_quadratic * ca.dot(sigma, sigma))  # fmt: skip
    vw = c[n:] + ca.DM(K) @ du + (ca.DM(Sh) @ beta if nb else 0)
    g = ca.vertcat(vu, vw + sigma, sigma)
    if upper:
        sig_up = x[n + nb + n:]
        cost = cost + slack * ca.sum1(sig_up) + slack_quadratic * ca.dot(sig_up, sig_up)
        g = ca.vertcat(g, -vw + sig_up, sig_up)
    H, grad = ca.hessian(cost, x)
    grad0 = ca.substitute(grad, x, ca.DM.zeros(nz))
    fun = ca.Function("deep_qp", [x, c], [H, ca.jacobian(g, x), ca.jacobian(g, c),
                                          ca.jacobian(grad0, c), grad0])  # fmt: skip
    Hn, An, Gcn, Qcn, q0 = (np.array(m) for m in fun(np.zeros(nz), np.zeros(2 * n)))
    checkpoint()  # CasADi's wrappers drop a signal's exception (lcc_synth.interrupts)
    P = sp.csc_matrix(np.triu(0.5 * (Hn + Hn.T)))
    A = sp.csc_matrix(An)
    empty = np.zeros((0, 0))
    qp = QPMatrices(P, A, empty, empty, np.zeros(0), np.zeros(0))
    return DeepQP(qp, q0.reshape(-1), Qcn, Gcn, n, nb, n_up)


class ExactSolver:
    """DAQP (an exact dual active-set solver, CasADi's ``conic`` plugin) on the constant
    Hessian and constraint matrix of a :class:`DeepQP`, set up once; only the vectors change
    per solve. DeeP-LCC's second solver: OSQP stops at ``max_iter`` on the few ill-conditioned
    steps (module docstring of :mod:`lcc_synth.deeplcc.controller`).

    Parameters
    ----------
    qp : QPMatrices
        ``P`` (upper triangle) and ``A`` of the QP.
    """

    def __init__(self, qp: QPMatrices):
        import casadi as ca

        Pu = qp.P.toarray()
        self._H = ca.DM(Pu + np.triu(Pu, 1).T)
        self._A = ca.DM(qp.A.toarray())
        self._conic = ca.conic("deep_lcc_exact", "daqp", {"h": self._H.sparsity(),
                               "a": self._A.sparsity()}, {"error_on_fail": False})  # fmt: skip

    def solve(self, q, l, u) -> tuple[np.ndarray, np.ndarray] | None:
        """``(x, y)`` (primal, constraint multipliers) of ``min 1/2 x'Px + q'x, l <= Ax <= u``,
        or None when DAQP does not report success."""
        big = 1e20  # DAQP's "no bound"
        lo = np.where(np.isfinite(l), l, -big)
        hi = np.where(np.isfinite(u), u, big)
        sol = self._conic(h=self._H, g=np.asarray(q, float), a=self._A, lba=lo, uba=hi)
        if not self._conic.stats().get("success", False):
            return None
        return np.array(sol["x"]).reshape(-1), np.array(sol["lam_a"]).reshape(-1)
