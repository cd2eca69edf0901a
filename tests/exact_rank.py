"""Exact ranks over the rationals (test helper, no tests here).

Every float is a dyadic rational, so ``Fraction(x)`` converts a model's matrices exactly: with
dyadic coefficients the float model *is* the rational one and these ranks are the truth the
staircase's verdicts are checked against (Gauss-Jordan elimination in ``fractions.Fraction``,
no rounding anywhere).
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

__all__ = ["rational", "rational_rank", "kalman_rank", "observability_rank"]


def rational(X) -> list[list[Fraction]]:
    """The entries of the float matrix ``X`` as exact fractions."""
    return [[Fraction(float(x)) for x in row] for row in np.atleast_2d(X)]


def rational_rank(M: list[list[Fraction]]) -> int:
    """Exact rank by Gauss-Jordan elimination over the rationals."""
    M = [row[:] for row in M]
    rank = 0
    for col in range(len(M[0]) if M else 0):
        piv = next((r for r in range(rank, len(M)) if M[r][col] != 0), None)
        if piv is None:
            continue
        M[rank], M[piv] = M[piv], M[rank]
        for r in range(len(M)):
            if r != rank and M[r][col] != 0:
                f = M[r][col] / M[rank][col]
                M[r] = [a - f * b for a, b in zip(M[r], M[rank], strict=True)]
        rank += 1
    return rank


def kalman_rank(A, B) -> int:
    """Exact rank of ``[B, AB, ..., A^(n-1) B]`` (entries of ``A``, ``B`` converted exactly)."""
    A, B = rational(A), rational(np.asarray(B).reshape(len(A), -1))
    n = len(A)
    cols = [[row[j] for row in B] for j in range(len(B[0]))]
    K = []
    for _ in range(n):
        K += cols
        cols = [[sum(a * x for a, x in zip(row, v, strict=True)) for row in A] for v in cols]
    return rational_rank(K) if K else 0


def observability_rank(A, C) -> int:
    """Exact rank of ``[C; CA; ...; CA^(n-1)]``: the Kalman rank of ``(A^T, C^T)``."""
    return kalman_rank(np.asarray(A).T, np.asarray(C).T)
