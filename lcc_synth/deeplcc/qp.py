"""DeeP-LCC's online QP, formulated once with CasADi on the reduced data matrices.

Decision vector ``x = [nu (2 N n_c), sigma (N n_c)]`` (:mod:`lcc_synth.deeplcc.hankel`: the
multipliers of the constrained directions, ``C g = c + Gamma nu``, and one spacing slack per
CAV and step)::

    min  1/2 nu' Gamma nu + rho_1 sum sigma + rho_2 sum sigma^2
    s.t. a_min <= (c + Gamma nu)_u <= a_max                 (hard, every CAV and step)
         (c + Gamma nu)_w + sigma >= s_min + margin + t_gap v_eq - s_eq   (soft, absolute)
         sigma >= 0

``Gamma`` is used as ``B B'`` (its range factor, exactly positive semidefinite); ``nu``'s
component in its null space changes neither the cost nor ``C g`` and gets the cost
``lambda_max(Gamma) ||(I - V V') nu||^2 / 2`` (``V``: the range's orthonormal basis), which
leaves the solution in ``C g`` unchanged and makes the QP strictly convex (without it OSQP
once reported a false "dual infeasible" on the free directions). Measured on
the head brake (1200 steps): this form needed at most 1425 OSQP iterations; the equivalent
``phi``-form (``C g = c + B phi``, identity Hessian) is 3x faster per iteration but did not
converge in 10000 iterations on one step, where two of its 52 directions are 1e-4 and 4e-6 of
the largest (the nonlinearity the data hold beyond the input-determined response) and OSQP's
column scaling turns them into a Hessian of condition 1e5.

``u`` rows are the future CAV accelerations, ``w`` rows ``s~ - t_gap v~`` of each CAV's
predicted spacing and velocity errors, so the bound is ``s >= s_min + margin + t_gap v`` in
absolute metres with ``s = s_eq + s~``, ``v = v_eq + v~`` (the MPC's definition,
:class:`lcc_synth.mpc.settings.Constraints`), its l1 penalty exact for a violation the
hard constraints force. ``c`` is affine in the measured past (``c = C_b b + C_y y_ini``); only
the vectors change between steps. The Hessian, the constraint matrix and the map of ``c``
into the bounds are extracted from the CasADi expressions once (:func:`formulate`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from lcc_synth.deeplcc.hankel import ReducedQP
from lcc_synth.mpc.formulation import QPMatrices

__all__ = ["DeepQP", "formulate"]


@dataclass(frozen=True, eq=False)
class DeepQP:
    """The QP of one DeeP-LCC controller (module docstring).

    Attributes
    ----------
    qp : QPMatrices
        ``P`` (upper triangle) and ``A`` for OSQP.
    q : numpy.ndarray
        Constant linear term.
    Gamma : numpy.ndarray
        ``B B'`` (:class:`~lcc_synth.deeplcc.hankel.ReducedQP`).
    n_nu, n_w : int
        Sizes of ``nu`` and of ``sigma`` (= the ``w`` and ``u`` rows).
    Gc : numpy.ndarray
        ``(3 n_w, 2 n_w)``: the constraint rows' dependence on ``c`` (offsets ``Gc c``).
    """

    qp: QPMatrices
    q: np.ndarray
    n_nu: int
    n_w: int
    Gc: np.ndarray
    Gamma: np.ndarray

    def bounds(self, c: np.ndarray, a_min: float, a_max: float, b_w: np.ndarray):
        """``(l, u)`` of OSQP for ``c`` and the spacing bounds ``b_w`` (``(n_w,)``)."""
        n = self.n_w
        off = self.Gc @ c
        lo = np.empty(3 * n)
        hi = np.empty(3 * n)
        lo[:n], hi[:n] = a_min, a_max
        lo[n:2 * n], hi[n:2 * n] = b_w, np.inf
        lo[2 * n:], hi[2 * n:] = 0.0, np.inf
        return lo - off, hi - off

    def shift_indices(self, n_c: int) -> tuple[np.ndarray, np.ndarray]:
        """Index arrays shifting a primal / dual solution by one step (warm start)."""
        n = self.n_w
        N = n // n_c
        k = np.minimum(np.arange(N) + 1, N - 1)
        base = (k[:, None] * n_c + np.arange(n_c)[None, :]).ravel()
        z = np.concatenate([base, base + n, base + 2 * n])
        return z, z.copy()


def formulate(red: ReducedQP, slack: float, slack_quadratic: float) -> DeepQP:
    """Build the QP of the module docstring with CasADi and extract its matrices once."""
    import casadi as ca

    Gamma = red.B @ red.B.T
    n_nu = n_c_rows = Gamma.shape[0]
    # the null space of Gamma moves neither the cost nor C g: give it a cost of Gamma's scale
    # so that OSQP sees a strictly convex problem (no false "dual infeasible")
    V = red.B / np.linalg.norm(red.B, axis=0)
    scale = float(np.max(np.linalg.norm(red.B, axis=0)) ** 2) if red.B.size else 1.0
    Pnu = Gamma + scale * (np.eye(n_nu) - V @ V.T)
    n_w = red.n_u
    nz = n_nu + n_w
    x = ca.MX.sym("x", nz)
    c = ca.MX.sym("c", n_c_rows)
    nu, sigma = x[:n_nu], x[n_nu:]
    Gm = ca.DM(Gamma)
    cost = 0.5 * ca.dot(nu, ca.DM(Pnu) @ nu) + slack * ca.sum1(sigma) + slack_quadratic * ca.dot(
        sigma, sigma
    )
    v = c + Gm @ nu
    g = ca.vertcat(v[:n_w], v[n_w:] + sigma, sigma)
    H, grad = ca.hessian(cost, x)
    fun = ca.Function("deep_qp", [x, c], [H, ca.jacobian(g, x), ca.jacobian(g, c),
                                          ca.substitute(grad, x, ca.DM.zeros(nz))])
    Hn, An, Gcn, q0 = (np.array(m) for m in fun(np.zeros(nz), np.zeros(n_c_rows)))
    P = sp.csc_matrix(np.triu(0.5 * (Hn + Hn.T)))
    A = sp.csc_matrix(An)
    empty = np.zeros((0, 0))
    qp = QPMatrices(P, A, empty, empty, np.zeros(0), np.zeros(0))
    return DeepQP(qp, q0.reshape(-1), n_nu, n_w, Gcn, Gamma)
