"""Closed-loop Lyapunov equations sharing one real Schur factorisation (Bartels-Stewart).

The true H2 cost of a static gain ``g`` needs, for the closed loop ``A_K = A + B g``, the
controllability Gramian ``L`` (``A_K L + L A_K' + B_w B_w' = 0``) and the observability Gramian
``P`` (``A_K' P + P A_K + Q + g' R g = 0``); the Newton step of the structured design
(:func:`lcc_synth.synthesis.structured.polish`) needs ``2k`` more equations with the same
``A_K`` (``k`` free gain entries). ``scipy.linalg.solve_continuous_lyapunov`` recomputes the
Schur form for every equation, and the stability test computes the eigenvalues once more.

Method: ``A_K = Z T Z'`` once (LAPACK ``dgees`` via :func:`scipy.linalg.schur`); the real parts
of the eigenvalues are the diagonal of ``T`` (the 2x2 blocks of complex pairs are standardised
with equal diagonal entries), and every equation ``A_K X + X A_K' = -C`` (or its transpose) is
one quasi-triangular Sylvester solve (``dtrsyl``) between two orthogonal transforms
(``Z' C Z`` and ``Z X Z'``), the same algorithm scipy uses but with the factorisation reused.
Numerical limits are those of Bartels-Stewart: the relative residual is a modest multiple of
eps; ``dtrsyl`` scales the solution (``scale < 1``) only when ``A_K`` has eigenvalue pairs with
``lambda_i + lambda_j`` near 0, i.e. an almost unstable loop, which the cost reports as
unstable anyway (``STABILITY_TOL``).

Measured (2 cores, OpenBLAS Haswell kernel, one BLAS thread, CF-LCC with 10..100 HDVs): one
Schur form plus both Gramians costs about 0.4 of ``eigvals`` + two
``solve_continuous_lyapunov`` calls (202 states: see ``benchmarks/bench_synthesis.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy.linalg.lapack import dtrsyl

__all__ = ["ClosedLoopSchur", "closed_loop_schur"]


@dataclass(frozen=True)
class ClosedLoopSchur:
    """Real Schur form ``A = Z T Z'`` of a closed-loop matrix, reused for every equation."""

    T: np.ndarray
    Z: np.ndarray

    @property
    def max_real_eig(self) -> float:
        """Largest real part of the eigenvalues (the diagonal of ``T``)."""
        return float(np.max(np.diag(self.T)))

    def solve(self, C: np.ndarray, transpose: bool = False) -> np.ndarray:
        """``X`` with ``A X + X A' + C = 0`` (``transpose``: ``A' X + X A + C = 0``).

        Raises
        ------
        numpy.linalg.LinAlgError
            When LAPACK reports an illegal argument (a non-finite right-hand side).
        """
        Z = self.Z
        Ct = Z.T @ C @ Z
        trana, tranb = ("T", "N") if transpose else ("N", "T")
        X, scale, info = dtrsyl(self.T, self.T, -Ct, trana=trana, tranb=tranb)
        if info < 0:
            raise np.linalg.LinAlgError(f"dtrsyl: illegal argument {-info}")
        X = Z @ (X * scale) @ Z.T
        return 0.5 * (X + X.T)


def closed_loop_schur(A: np.ndarray) -> ClosedLoopSchur:
    """Real Schur factorisation of ``A`` (raises ``LinAlgError`` if QR does not converge)."""
    T, Z = sla.schur(np.asarray(A, dtype=float), output="real")
    return ClosedLoopSchur(T, Z)
