"""H2 norm of the loop as it runs (:mod:`lcc_synth.analysis.as_run`).

:func:`as_run_h2` is the H2 norm of the design's performance channel (white noise on the plant
states -> weighted states and command) of an as-run loop: continuous Lyapunov equations when
the loop is continuous, otherwise the exact sampled-data (time-averaged power) norm of
continuous white noise on the plant through the discrete loop (Van Loan integrals of the noise
covariance over a period and of the intra-sample cost). It is defined when no white noise
reaches a sampled measurement directly (head-velocity noise read by a sampled law): otherwise
``None``.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg as sla

from lcc_synth.analysis.as_run import AsRunLoop

__all__ = ["as_run_h2"]


def _blocks_exp(A: np.ndarray, Q: np.ndarray, Bw: np.ndarray, T: float):
    """Exact integrals over one period (Van Loan 1978) of ``dx = A x + Bw w``:
    ``Wd = int_0^T e^{At} Bw Bw' e^{A't} dt`` (the noise covariance), ``Qint = int_0^T e^{A't} Q
    e^{At} dt`` and ``S = int_0^T Qint(t) dt`` (``tr(Bw' S Bw)`` is the cost of the noise inside
    a period: ``int_0^T tr(Q W(t)) dt = tr(Bw' S Bw)``)."""
    n = A.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -A
    M[:n, n:] = Bw @ Bw.T
    M[n:, n:] = A.T
    E = sla.expm(M * T)
    Wd = E[n:, n:].T @ E[:n, n:]
    C = np.zeros((3 * n, 3 * n))
    C[:n, :n] = -A.T
    C[:n, n : 2 * n] = np.eye(n)
    C[n : 2 * n, n : 2 * n] = -A.T
    C[n : 2 * n, 2 * n :] = Q
    C[2 * n :, 2 * n :] = A
    F = sla.expm(C * T)
    eAtT = F[2 * n :, 2 * n :].T  # e^{A' T}
    Qint = eAtT @ F[n : 2 * n, 2 * n :]
    S = eAtT @ F[:n, 2 * n :]
    return Wd, 0.5 * (Qint + Qint.T), 0.5 * (S + S.T)


def as_run_h2(
    loop: AsRunLoop, Bw: np.ndarray, Q: np.ndarray, r: float, head: float = 0.0
) -> float | None:
    """H2 norm of ``loop`` from white noise to ``z``, ``z'z = x'Qx + r u_g^2``.

    ``Bw`` ``(nx_model, nw)``: noise on the model's states (e.g. the acceleration noise of the
    design), ``Q`` ``(nx_model, nx_model)``, ``u_g`` the command without the HDV law (the
    design's input; an open platoon's loop: one per CAV, ``r sum_i u_g,i^2``); ``head``:
    intensity of white noise on the head velocity. Continuous loop:
    Lyapunov equations. Sampled loop: the time-averaged power of ``z`` (the sampled-data H2
    norm): the discrete Lyapunov equation of the loop with the exact per-period noise
    covariance, plus the exact intra-sample cost of ``[x_k, u_k]`` and of the noise.
    ``None`` when undefined: white head noise read by a sampled law. ``inf`` when unstable.
    """
    nx, N = loop.nx, loop.A.shape[0]
    nm = Q.shape[0]
    Bw = np.asarray(Bw, float).reshape(nm, -1)
    A0, B0, H0 = loop.plant
    Bx = np.zeros((nx, Bw.shape[1]))
    Bx[:nm] = Bw
    Qx = np.zeros((nx, nx))
    Qx[:nm, :nm] = Q
    X = np.zeros((nx, N))
    X[:, :nx] = np.eye(nx)
    ug, ug_v = loop.u_gain if loop.u_gain is not None else (loop.u_row, loop.u_v)
    ug = np.atleast_2d(ug)  # a row per CAV
    nc = ug.shape[0]
    if loop.sample_time is None:
        if np.max(np.linalg.eigvals(loop.A).real) >= 0:
            return math.inf
        G = np.zeros((N, Bx.shape[1]))
        G[:nx] = Bx
        if head > 0:
            if np.any(np.asarray(ug_v) != 0.0):
                return None  # white noise straight into the weighted command
            G = np.column_stack([G, head * loop.h])
        L = sla.solve_continuous_lyapunov(loop.A, -G @ G.T)
        Qk = X.T @ Qx @ X + r * (ug.T @ ug)
        return math.sqrt(max(float(np.trace(Qk @ L)), 0.0))
    if head > 0:
        if loop.measured_head:
            return None
        Bx = np.column_stack([Bx, head * H0[:, 0]])
    T = loop.sample_time
    if np.max(np.abs(np.linalg.eigvals(loop.A))) >= 1:
        return math.inf
    Wd, _, S = _blocks_exp(A0, Qx, Bx, T)
    n1 = nx + nc  # [x; u] with u held: the intra-sample cost of the sampled state and command
    Aa = np.zeros((n1, n1))
    Aa[:nx, :nx] = A0
    Aa[:nx, nx:] = B0
    Qa = np.zeros((n1, n1))
    Qa[:nx, :nx] = Qx
    _, Qint_a, _ = _blocks_exp(Aa, Qa, np.zeros((n1, 1)), T)
    G = np.zeros((N, N))
    G[:nx, :nx] = Wd
    P = sla.solve_discrete_lyapunov(loop.A, G)
    Mxu = np.vstack([X, np.atleast_2d(loop.u_row)])
    J = (
        float(np.trace(Mxu.T @ Qint_a @ Mxu @ P))
        + r * T * float(np.trace(ug @ P @ ug.T))
        + float(np.trace(Bx.T @ S @ Bx))
    )
    return math.sqrt(max(J / T, 0.0))
