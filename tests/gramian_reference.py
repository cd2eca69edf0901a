"""The controllability Gramian by adaptive quadrature (test helper, no tests here).

``W(t) = int_0^t e^{A tau} B B' e^{A' tau} d tau`` integrated entry-wise by
``scipy.integrate.quad_vec`` on ``scipy.linalg.expm``: a second method, independent of the
package's Van Loan block exponential with doubling (:func:`lcc_synth.analysis.energy.gramian`),
for the paper's Eq. (15) Gramian and its energy tests on every layout.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from scipy.integrate import quad_vec

__all__ = ["quad_gramian"]


def quad_gramian(A: np.ndarray, B: np.ndarray, t: float) -> np.ndarray:
    """``W(t)`` by quadrature (absolute tolerance 1e-14, relative 1e-12)."""

    def integrand(tau: float) -> np.ndarray:
        X = sla.expm(A * tau) @ B
        return X @ X.T

    W, _ = quad_vec(integrand, 0.0, t, epsabs=1e-14, epsrel=1e-12)
    return W
