"""Control energy of LCC systems (Section III-B, Definition 3, Lemma 2, Fig. 5).

The finite-horizon controllability Gramian ``W(t) = int_0^t e^{A tau} B B^T e^{A^T tau} dtau``
(eq. 15) is computed exactly, up to round-off, with Van Loan's block matrix exponential
(Van Loan 1978): for ``M = [[-A, B B^T], [0, A^T]]``,
``expm(M h) = [[F11, F12], [0, F22]]`` with ``F22 = e^{A^T h}`` and ``W(h) = F22^T F12``, on a
short interval ``h``, extended to ``t`` by exact doubling (see :func:`gramian`).
The open-loop LCC matrices have zero eigenvalues, so the infinite-horizon Lyapunov equation does
not apply; the finite horizon is what the paper uses.

Every layout
------------
One CAV (``B`` one column), several (one column per CAV) and the ring: a ring conserves its
total spacing (``c A = 0``, ``c B = 0``, so ``W c = 0``), and the report is of the hyperplane
``c x = 0`` its dynamics keep, ``V^T W V`` in the model's orthonormal ``invariant_basis()``
(``nx - 1`` states; its eigenvalues are the full ``W``'s without the zero). On an open string
that basis is the identity and every number is the one of ``W`` bit for bit. A target whose
total spacing differs from the start's is unreachable on a ring: a ConfigError. Measured: five
OVM vehicles (paper parameters), CAVs at 1 and 3, t = 10 s: the open platoon has cond 2.1e7,
the ring 1.1e7 on its 9-state hyperplane; float64 and multiprecision agree on ``lambda_min`` to
1.1e-11 and 2.0e-10 relative (``digits`` states 8.3 and 8.6).

Numerical singularity
---------------------
``W(t)`` of a long string is extremely ill-conditioned (the minimum energy grows exponentially
with n). A float64 ``W`` carries absolute errors of at least ``eps * ||W||`` (its entries are
rounded), and by Weyl's inequality ``lambda_min`` moves by as much, so a computed
``lambda_min`` near ``eps * lambda_max`` is noise, and so are ``W^{-1}``, ``tr(W^{-1})`` and the
minimum energy. Every function here refuses with :class:`NumericallySingularError` when
``cond(W) = lambda_max / lambda_min`` exceeds ``COND_LIMIT = 0.01 / eps`` (about 4.5e13: at the
limit ``lambda_min`` is 100 times that error bound, about two correct digits), or when a computed
eigenvalue is not positive. Measured on FD-LCC with the paper's parameters (Fig. 5), this
method and an adaptive quadrature of eq. (15) (``scipy.integrate.quad_vec``) agree on
``lambda_min`` to 1e-5 relative at n = 5, t = 20 s (cond 3.5e13, just inside the limit); at
n = 5, t = 10 s (cond 1.3e16, refused) they differ by 2 %, and from n = 7 the computed
``lambda_min`` of both is negative.

Beyond float64 (Fig. 5 to n = 30)
---------------------------------
The paper stops at small n for this reason. :func:`energy_reports_mp` (and
``energy_vs_size(method="mp")``) compute the same Gramian in multiprecision (mpmath): the
float64 ``A``, ``B`` taken exactly, the Taylor series of ``e^{Ah}`` and of ``W(h)`` on a short
step (Paterson-Stockmeyer; the Krylov vectors ``A^i B``), exact doublings and sums of positive
semidefinite terms as above, eigenvalues by ``mpmath.eigsy``, all at ``dps`` working digits.
Round-off in ``W`` is then ``10^-dps ||W||`` and ``lambda_min`` keeps about
``dps - log10(cond)`` digits, so the working precision is raised until it exceeds
``log10(cond) + digits + MP_GUARD``; the report states ``digits = dps - log10(cond) - 1``.
A square-root (Cholesky-factor) Gramian in float64 would keep ``W`` positive definite but not
``lambda_min`` below ``eps * lambda_max``, which is the whole difficulty here.
Measured on FD-LCC, paper's parameters, t = 10 / 20 / 30 s (``benchmarks/bench_fig5_digits.py``):
cond(W) grows ~1e5 per HDV, to 3.0e153 at n = 30, t = 10 s (``lambda_min`` 1.4e-151); the
working precision reaches 176 digits. Against a second computation at 50 more digits, every
``lambda_min`` and ``tr(W^-1)`` for n = 1..30 agrees to >= 24 significant digits (the stated
estimate is 1.6-6.1 digits conservative), so every float64 value returned is correct to the
last digit. At a fixed 50 digits the agreement is ``50 - log10(cond) + 3`` (15.7 digits at
n = 10, t = 10 s; none from n = 14). The float64 values agree with these to 13 digits at n = 1
and 4.6 at n = 5 (t = 20 s, cond 3.5e13), i.e. ``-log10(eps * cond)``. Cost: the whole sweep
n = 1..30, three horizons (which share one step), about 2 min of CPU here (n = 30 alone
~20 s). A ``lambda_min`` still at round-off at ``MP_MAX_DPS = 600`` digits is refused as
singular (an uncontrollable model).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from lcc_synth.errors import ConfigError
from lcc_synth.models.linear import LCCModel
from lcc_synth.models.platoon import PlatoonModel
from lcc_synth.models.records import Record

__all__ = [
    "COND_LIMIT",
    "NumericallySingularError",
    "EnergyReport",
    "EnergySweep",
    "energy_vs_size",
    "gramian",
    "condition_limit",
    "energy_report",
    "min_energy",
    "min_energy_input",
    "gramians_mp",
    "energy_reports_mp",
    "MP_MAX_DPS",
]

COND_LIMIT = 0.01 / float(np.finfo(float).eps)


class NumericallySingularError(ValueError):
    """The Gramian is numerically singular: its inverse and the energies are not computable.

    Attributes
    ----------
    condition : float
        ``lambda_max / lambda_min`` of the computed Gramian (``inf`` if ``lambda_min <= 0``).
    limit : float
        The largest condition number accepted (:func:`condition_limit`).
    n_states, n : int
        Size of the system (``n`` = HDVs behind the CAV when known, else -1).
    t : float
        Horizon (s).
    """

    def __init__(
        self, condition: float, limit: float, n_states: int, n: int, t: float,
        dps: int | None = None,
    ):  # fmt: skip
        self.condition = condition
        self.limit = limit
        self.n_states = n_states
        self.n = n
        self.t = t
        size = f"n = {n} ({n_states} states)" if n >= 0 else f"{n_states} states"
        if dps is not None:  # multiprecision (energy_reports_mp)
            super().__init__(
                f"controllability Gramian W(t = {t:g} s) is singular at {size}: its smallest "
                f"eigenvalue stays at the round-off of {dps} digits (the system is "
                "uncontrollable)"
            )
            return
        super().__init__(
            f"controllability Gramian W(t = {t:g} s) is numerically singular at {size}: "
            f"cond(W) = {condition:.3g} exceeds the limit {limit:.3g} = 0.01 / eps; "
            "lambda_min(W), tr(W^-1) and the minimum energy would be round-off (the system is "
            "uncontrollable, or too close to it for float64)"
        )


def _check_t(t: float) -> float:
    if (
        isinstance(t, bool)
        or not isinstance(t, int | float | np.floating)
        or not (np.isfinite(t) and t > 0)
    ):
        raise ConfigError("t", f"must be a finite horizon > 0 s, got {t!r}")
    return float(t)


def _van_loan(A: np.ndarray, BBt: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """``(W(h), e^{Ah})`` from one exponential of ``[[-A, B B^T], [0, A^T]] h``."""
    nx = A.shape[0]
    M = np.zeros((2 * nx, 2 * nx))
    M[:nx, :nx] = -A
    M[:nx, nx:] = BBt
    M[nx:, nx:] = A.T
    E = sla.expm(M * h)
    eAt = E[nx:, nx:].T
    return eAt @ E[:nx, nx:], eAt


def gramian(A: np.ndarray, B: np.ndarray, t: float) -> np.ndarray:
    """Finite-horizon controllability Gramian ``W(t)`` of eq. (15).

    Van Loan's block exponential on a short interval ``h = t / 2^k`` with ``||A|| h <= 1/2``,
    then ``k`` exact doublings ``W(2 tau) = W(tau) + e^{A tau} W(tau) e^{A^T tau}``. Applying
    Van Loan to the whole horizon at once forms ``e^{-A t}``, whose entries grow like
    ``e^{|Re lambda| t}`` for the stable modes, and the cancellation in ``e^{At} F12`` then
    costs accuracy: measured on FD-LCC (paper's alphas, t = 30 s, n = 15) it gave absolute
    errors ~1e-8 in ``W`` against ~1e-14 here. Each doubling adds positive semidefinite terms,
    so no cancellation occurs.

    Parameters
    ----------
    A : (nx, nx) array
    B : (nx, nu) array
    t : float
        Horizon (s), > 0.

    Returns
    -------
    (nx, nx) symmetric positive semidefinite array.
    """
    t = _check_t(t)
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float).reshape(A.shape[0], -1)
    norm = np.linalg.norm(A, 1)
    k = max(0, int(np.ceil(np.log2(max(norm * t / 0.5, 1.0)))))
    W, E = _van_loan(A, B @ B.T, t / 2**k)
    for _ in range(k):
        W = W + E @ W @ E.T
        E = E @ E
    return 0.5 * (W + W.T)


def condition_limit(nx: int) -> float:
    """Largest accepted ``cond(W)`` (:data:`COND_LIMIT`, the same for every size ``nx``)."""
    return COND_LIMIT


@dataclass(frozen=True, repr=False)
class EnergyReport(Record):
    """Energy metrics of Fig. 5 at one horizon.

    Attributes
    ----------
    kind : str
    n : int
        HDVs behind the CAV.
    n_states : int
    t : float
        Horizon (s).
    lambda_min, lambda_max : float
        Extreme eigenvalues of ``W(t)``; ``lambda_min`` is the worst-case controllability.
    trace_inv : float
        ``tr(W(t)^{-1})``, the average minimum energy over random unit targets.
    condition : float
        ``lambda_max / lambda_min``.
    condition_limit : float
        The limit beyond which the report would have been refused.
    method : {"double", "mp"}
        float64 (:func:`energy_report`) or multiprecision (:func:`energy_reports_mp`).
    digits : float
        Estimated correct significant digits of ``lambda_min`` (and so of ``tr(W^{-1})``,
        dominated by ``1 / lambda_min``): ``-log10(eps * cond)`` in float64,
        ``dps - log10(cond) - 1`` at ``dps`` working digits (module docstring).
    """

    kind: str
    n: int
    n_states: int
    t: float
    lambda_min: float
    lambda_max: float
    trace_inv: float
    condition: float
    condition_limit: float
    method: str = "double"
    digits: float = float("nan")

    def as_dict(self) -> dict:
        """JSON-serialisable dict."""
        return {
            "kind": self.kind,
            "n": int(self.n),
            "n_states": int(self.n_states),
            "t": float(self.t),
            "lambda_min": float(self.lambda_min),
            "lambda_max": float(self.lambda_max),
            "trace_inv": float(self.trace_inv),
            "condition": float(self.condition),
            "condition_limit": float(self.condition_limit),
            "method": self.method,
            "digits": float(self.digits),
        }


def _checked_eig(W: np.ndarray, t: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Eigen-decomposition of W, or NumericallySingularError."""
    lam, V = np.linalg.eigh(W)
    nx = W.shape[0]
    limit = condition_limit(nx)
    cond = float(lam[-1] / lam[0]) if lam[0] > 0 else np.inf
    if not cond <= limit:
        raise NumericallySingularError(cond, limit, nx, n, t)
    return lam, V


def _kept_gramian(model: LCCModel | PlatoonModel, t: float) -> tuple[np.ndarray, np.ndarray]:
    """``(V^T W(t) V, V)``: the Gramian on the space the model's dynamics keep, in the
    orthonormal basis ``V = model.invariant_basis()`` (the identity on an open string, where
    ``V^T W V`` is ``W`` bit for bit; the ring's hyperplane ``c x = 0``, where ``W c = 0``)."""
    V = model.invariant_basis()
    return V.T @ gramian(model.A, model.B, t) @ V, V


def energy_report(model: LCCModel | PlatoonModel, t: float) -> EnergyReport:
    """``lambda_min(W(t))``, ``tr(W(t)^{-1})`` and ``cond(W(t))`` for the model's ``(A, B)``.

    Any layout: one CAV, several (``B`` has one column per CAV), a ring on the hyperplane its
    dynamics never leave (the conserved total spacing is not a target: ``n_states`` is then
    ``nx - 1`` and the eigenvalues are the full Gramian's without its zero).

    Raises
    ------
    NumericallySingularError
        When ``W(t)`` is numerically singular (see the module docstring); this includes every
        uncontrollable model (general LCC with m > 0, CCC, a platoon with HDVs ahead of its
        first CAV).
    """
    t = _check_t(t)
    W, V = _kept_gramian(model, t)
    lam, _ = _checked_eig(W, t, model.n)
    nx = V.shape[1]
    return EnergyReport(
        kind=model.kind,
        n=model.n,
        n_states=nx,
        t=t,
        lambda_min=float(lam[0]),
        lambda_max=float(lam[-1]),
        trace_inv=float(np.sum(1.0 / lam)),
        condition=float(lam[-1] / lam[0]),
        condition_limit=condition_limit(nx),
        digits=float(-np.log10(np.finfo(float).eps * lam[-1] / lam[0])),
    )


MP_GUARD = 10  # working digits kept beyond log10(cond) + the digits asked for
MP_MAX_DPS = 600  # a lambda_min still at round-off at this precision (cond > ~1e595): singular


def _mp_taylor_step(Am, Bm, norm: float, t: float, dps: int):
    """``(W(t), e^{At})`` in mpmath at ``dps`` digits (call inside ``mp.workdps``).

    ``h = t / 2^k`` with ``||A h||_1 <= 2^-4``; ``e^{Ah}`` by its Taylor series evaluated with
    Paterson-Stockmeyer (about ``2 sqrt(N)`` products for ``N`` terms); ``W(h)`` exactly from the
    same series, ``W(h) = sum_ij A^i B B^T A^T^j h^(i+j+1) / (i! j! (i+j+1))`` on the Krylov
    vectors ``A^i B``; then ``k`` exact doublings as in :func:`gramian`.
    """
    import mpmath as mp

    nx, nu = Bm.rows, Bm.cols
    k = max(0, int(np.ceil(np.log2(max(norm * t, 1.0))))) + 4
    h = mp.mpf(t) / 2**k
    theta, log_term, N = norm * t / 2**k, 0.0, 0
    while log_term >= -dps - 2 and theta > 0:  # truncation below the working precision
        N += 1
        log_term += np.log10(theta / N)
    X = Am * h
    q = max(1, int(np.ceil(np.sqrt(N + 1))))
    powers = [mp.eye(nx), X]
    for _ in range(q - 1):
        powers.append(powers[-1] * X)
    inv_fact = [1 / mp.factorial(i) for i in range(N + 1)]
    E = mp.zeros(nx, nx)
    for start in reversed(range(0, N + 1, q)):  # Horner in X^q over blocks of q terms
        block = mp.zeros(nx, nx)
        for i in range(start, min(start + q, N + 1)):
            block += powers[i - start] * inv_fact[i]
        E = block if start == N // q * q else block + E * powers[q]
    K = mp.zeros(nx, (N + 1) * nu)
    v = Bm
    for i in range(N + 1):
        for r in range(nx):
            for c in range(nu):
                K[r, i * nu + c] = v[r, c] * h**i * inv_fact[i]
        v = Am * v
    C = mp.zeros((N + 1) * nu, (N + 1) * nu)
    for i in range(N + 1):
        for j in range(N + 1):
            for c in range(nu):
                C[i * nu + c, j * nu + c] = h / (i + j + 1)
    W = K * C * K.T
    for _ in range(k):
        W = W + E * W * E.T
        E = E * E
    return W, E


def gramians_mp(A: np.ndarray, B: np.ndarray, horizons, dps: int) -> list:
    """``W(t)`` of eq. (15) in multiprecision (mpmath) at every horizon, ``dps`` digits.

    ``A`` and ``B`` are taken as exact binary numbers (the float64 model), so the result is the
    Gramian of the same matrices that :func:`gramian` uses, without its round-off. The smallest
    horizon is computed as in :func:`gramian` (series on a short step, then exact doublings); a
    later horizon adds ``W(t_2) = W(t_1) + e^{A t_1} W(t_2 - t_1) e^{A^T t_1}`` (positive
    semidefinite terms only; an increment already computed is reused).

    Parameters
    ----------
    A : (nx, nx) array
    B : (nx, nu) array
    horizons : sequence of float
        Horizons (s), > 0.
    dps : int
        Working decimal digits (>= 15).

    Returns
    -------
    list of mpmath.matrix, in the order of ``horizons``.
    """
    import mpmath as mp

    if isinstance(dps, bool) or not isinstance(dps, int) or dps < 15:
        raise ConfigError("dps", f"must be an integer >= 15 (decimal digits), got {dps!r}")
    ts = [_check_t(t) for t in horizons]
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float).reshape(A.shape[0], -1)
    norm = float(np.linalg.norm(A, 1))
    out: dict[float, object] = {}
    with mp.workdps(dps):
        Am, Bm = mp.matrix(A.tolist()), mp.matrix(B.tolist())
        steps: dict[float, tuple] = {}
        prev_t, W, E = 0.0, None, None
        for t in sorted(set(ts)):
            d = t - prev_t
            if d not in steps:
                steps[d] = _mp_taylor_step(Am, Bm, norm, d, dps)
            Wd, Ed = steps[d]
            W, E = (Wd, Ed) if W is None else (W + E * Wd * E.T, E * Ed)
            out[t], prev_t = W, t
    return [out[t] for t in ts]


def energy_reports_mp(model: LCCModel, horizons, digits: int = 10, dps: int | None = None):
    """:func:`energy_report` in multiprecision: Fig. 5 beyond the float64 limit.

    Works at ``dps`` digits (default ``30 + digits`` to start), raised until every horizon has
    ``dps >= log10(cond(W)) + digits + MP_GUARD``; eigenvalues by ``mpmath.eigsy`` at the same
    precision. Never refuses: a controllable model only needs more digits.

    Parameters
    ----------
    model : LCCModel
    horizons : sequence of float
        Horizons ``t`` (s).
    digits : int
        Correct significant digits wanted for ``lambda_min`` and ``tr(W^{-1})`` (1..100).
    dps : int, optional
        First working precision to try (e.g. from a smaller system).

    Returns
    -------
    list of EnergyReport (``method = "mp"``; ``digits`` the estimate ``dps - log10(cond) - 1``),
    in the order of ``horizons``.

    Raises
    ------
    NumericallySingularError
        When ``lambda_min`` is still round-off at ``MP_MAX_DPS = 600`` digits (an uncontrollable
        model: general LCC with m > 0, CCC; a controllable one would need cond(W) > 1e595).
    """
    import mpmath as mp

    if isinstance(digits, bool) or not isinstance(digits, int) or not 1 <= digits <= 100:
        raise ConfigError("digits", f"must be an integer in 1..100, got {digits!r}")
    work = 30 + digits if dps is None else max(int(dps), 15)
    while True:
        Ws = gramians_mp(model.A, model.B, horizons, work)
        with mp.workdps(work):
            V = _invariant_basis_mp(model, mp)
            Ws = Ws if V is None else [V.T * W * V for W in Ws]
            eig = [sorted(mp.eigsy(W, eigvals_only=True)) for W in Ws]
            bad = any(lam[0] <= 0 for lam in eig)
            logc = np.inf if bad else max(float(mp.log10(lam[-1] / lam[0])) for lam in eig)
            need = logc + digits + MP_GUARD
            if logc > work - 5 and work >= MP_MAX_DPS:  # lambda_min at round-off level
                raise NumericallySingularError(np.inf, np.inf, model.nx, model.n,
                                               float(horizons[0]), dps=work)  # fmt: skip
            if not bad and work >= need:
                reports = []
                for t, lam in zip(horizons, eig, strict=True):
                    cond = lam[-1] / lam[0]
                    reports.append(EnergyReport(
                        kind=model.kind, n=model.n, n_states=Ws[0].rows, t=float(t),
                        lambda_min=float(lam[0]), lambda_max=float(lam[-1]),
                        trace_inv=float(mp.fsum(1 / x for x in lam)), condition=float(cond),
                        condition_limit=float("inf"), method="mp",
                        digits=float(work - mp.log10(cond) - 1),
                    ))  # fmt: skip
                return reports
        work = min(MP_MAX_DPS, max(2 * work if bad else int(np.ceil(min(need, 1e9))), work + 10))


def _invariant_basis_mp(model: LCCModel | PlatoonModel, mp):
    """:meth:`~lcc_synth.models.platoon.PlatoonModel.invariant_basis` at the working precision
    (the Householder reflector of the conserved direction, normalised in ``mp``: the ring's
    equal float entries give its exact direction), ``None`` when the model conserves nothing."""
    c = model.conserved
    if c is None:
        return None
    w = mp.matrix(np.asarray(c, dtype=float).tolist())
    w = w / mp.norm(w)
    w[0] -= 1
    H = mp.eye(model.nx) - 2 * (w * w.T) / (w.T * w)[0]
    return H[:, 1:]


def _state(model: LCCModel | PlatoonModel, x, name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=float).reshape(-1)
    if arr.shape != (model.nx,):
        raise ConfigError(
            name, f"must have {model.nx} entries (the model's states), got {arr.size}"
        )
    if not np.all(np.isfinite(arr)):
        raise ConfigError(name, "must be finite")
    return arr


def _steering(model: LCCModel | PlatoonModel, t: float, x0, x_target):
    t = _check_t(t)
    x0 = _state(model, x0, "x0")
    xt = _state(model, x_target, "x_target")
    W, Vk = _kept_gramian(model, t)
    lam, V = _checked_eig(W, t, model.n)
    d = xt - sla.expm(model.A * t) @ x0
    dk = Vk.T @ d  # the part of d the dynamics can reach (all of it on an open string)
    if np.linalg.norm(d - Vk @ dk) > 1e-9 * max(1.0, float(np.linalg.norm(d))):
        raise ConfigError(
            "x_target", "is not reachable from x0: the ring conserves the total spacing "
            "(sum of s_i), which must be the same in x_target as in x0",
        )
    w = Vk @ (V @ ((V.T @ dk) / lam))  # W^{-1} d on the kept space
    return t, d, w


def min_energy(model: LCCModel | PlatoonModel, t: float, x0, x_target) -> float:
    """Minimum control energy ``int_0^t u^T u`` from ``x0`` to ``x_target`` (Lemma 2, eq. 16):
    ``(x_tar - e^{At} x0)^T W(t)^{-1} (x_tar - e^{At} x0)``."""
    _, d, w = _steering(model, t, x0, x_target)
    return float(d @ w)


def min_energy_input(
    model: LCCModel | PlatoonModel, t: float, x0, x_target
) -> Callable[[np.ndarray], np.ndarray]:
    """The minimum-energy input ``u(tau) = B^T e^{A^T (t - tau)} W(t)^{-1} (x_tar - e^{At} x0)``.

    Returns a function of ``tau`` (scalar or array, 0 <= tau <= t) giving ``u`` with shape
    ``tau.shape + (nu,)``.
    """
    t, _, w = _steering(model, t, x0, x_target)
    A, B = model.A, model.B

    def u(tau):
        tau_arr = np.asarray(tau, dtype=float)
        flat = tau_arr.reshape(-1)
        out = np.stack([B.T @ (sla.expm(A.T * (t - s)) @ w) for s in flat])
        return out.reshape(tau_arr.shape + (B.shape[1],))

    return u


@dataclass(frozen=True, repr=False)
class EnergySweep(Record):
    """Energy metrics against the system size (Fig. 5).

    Attributes
    ----------
    reports : dict of float to list of EnergyReport
        For every horizon, the reports for ``n = 1, 2, ...`` up to the last computable size.
    singular : dict of float to NumericallySingularError or None
        For every horizon, the refusal at the first numerically singular size (``None`` when
        every size up to ``n_max`` was computable).
    """

    reports: dict[float, list[EnergyReport]]
    singular: dict[float, NumericallySingularError | None]

    def singular_n(self, t: float) -> int | None:
        """First ``n`` at which ``W(t)`` is numerically singular, or ``None``."""
        err = self.singular[t]
        return None if err is None else err.n

    def as_dict(self) -> dict:
        """JSON-serialisable dict keyed by the horizon as a string."""
        return {
            f"{t:g}": {
                "reports": [r.as_dict() for r in self.reports[t]],
                "singular_n": self.singular_n(t),
                "singular_condition": (
                    None if self.singular[t] is None else float(self.singular[t].condition)
                ),
            }
            for t in self.reports
        }


def energy_vs_size(
    coefficients,
    horizons=(10.0, 20.0, 30.0),
    n_max: int = 30,
    kind: str = "fd_lcc",
    method: str = "double",
    digits: int = 10,
) -> EnergySweep:
    """Fig. 5: ``lambda_min(W(t))`` and ``tr(W(t)^{-1})`` for ``n = 1..n_max`` HDVs behind.

    Stops, for each horizon, at the first ``n`` where ``W(t)`` is numerically singular (the
    energy only grows with ``n``, so larger sizes are singular too).

    Parameters
    ----------
    coefficients : LinearCoefficients
        Homogeneous HDV coefficients (e.g. ``OVM().linear_coefficients(15.0)``).
    horizons : sequence of float
        Horizons ``t`` (s).
    n_max : int
        Largest size tried.
    kind : {"fd_lcc", "cf_lcc"}
        Model family (the paper uses FD-LCC).
    method : {"double", "mp"}
        float64 (:func:`energy_report`, stops at the first singular size, as in the paper) or
        multiprecision (:func:`energy_reports_mp`, every size to ``n_max``).
    digits : int
        Significant digits wanted with ``method = "mp"``.
    """
    from lcc_synth.models.linear import build_model

    if kind not in ("fd_lcc", "cf_lcc"):
        raise ConfigError("kind", f"must be 'fd_lcc' or 'cf_lcc' (controllable), got {kind!r}")
    if isinstance(n_max, bool) or not isinstance(n_max, int) or n_max < 1:
        raise ConfigError("n_max", f"must be an integer >= 1, got {n_max!r}")
    if method not in ("double", "mp"):
        raise ConfigError("method", f"must be 'double' or 'mp', got {method!r}")
    reports: dict[float, list[EnergyReport]] = {}
    singular: dict[float, NumericallySingularError | None] = {}
    if method == "mp":
        ts = [_check_t(t) for t in horizons]
        reports = {t: [] for t in ts}
        singular = dict.fromkeys(ts)
        logc: list[float] = []
        for n in range(1, n_max + 1):
            # start from the precision the last sizes needed, extrapolated (log10 cond ~ linear)
            guess = None
            if len(logc) >= 2:
                guess = int(np.ceil(2 * logc[-1] - logc[-2])) + digits + MP_GUARD + 2
            batch = energy_reports_mp(build_model(kind, 0, n, coefficients), ts, digits, guess)
            for t, rep in zip(ts, batch, strict=True):
                reports[t].append(rep)
            logc.append(max(np.log10(r.condition) for r in batch))
        return EnergySweep(reports, singular)
    for t in horizons:
        t = _check_t(t)
        reports[t], singular[t] = [], None
        for n in range(1, n_max + 1):
            try:
                reports[t].append(energy_report(build_model(kind, 0, n, coefficients), t))
            except NumericallySingularError as err:
                singular[t] = err
                break
    return EnergySweep(reports, singular)
