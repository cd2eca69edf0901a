"""Head-to-tail transfer function Gamma(s), Section IV (eq. 24) and Appendix A.

``Gamma(s) = V_t(s) / V_h(s)``: the velocity error of the tail vehicle over the velocity error
of the head vehicle, for the CAV law (eq. 23)::

    u = a1 s_0 - a2 v_0 + a3 v_-1 + sum_i (mu_i s_i + k_i v_i).

Two independent computations:

* :func:`gamma_closed_form` evaluates the paper's formula ``Gamma = G (phi/gamma)^(n+m)`` with
  ``phi = a3 s + a1``, ``gamma = s^2 + a2 s + a1`` and ``H_i = mu_i (gamma/phi - 1) + k_i s``,
  generalised to per-vehicle (heterogeneous) coefficients by replacing every power of
  ``phi/gamma`` with the product of the vehicles' own ratios (Appendix A, same derivation).
  :func:`gamma_polynomials` gives the same function as an exact ratio of polynomials
  ``num/den``; ``den`` is the closed-loop characteristic polynomial.
* :func:`gamma_state_space` evaluates ``c (jw I - A_cl)^-1 h_cl`` of the closed loop
  (``feedback.closed_loop``) by a vectorised Hessenberg solve (orthogonal reduction once, then an
  O(nx^2) elimination with pivoting per frequency), never by an eigen-decomposition: identical
  vehicle blocks make ``A`` nearly defective. It takes any layout with a head vehicle (one CAV
  or several, :func:`head_to_tail_loop`).

Several CAVs: when every CAV's command uses only its own ``s_c, v_c`` and its predecessor's
``v_{c-1}`` (``v_h`` for the first vehicle), ``u_c = k_s s_c + k_v v_c + k_p v_{c-1}``, the
string is a cascade and :func:`gamma_product` gives ``Gamma = prod_i T_i`` with ``T_i = phi_i /
gamma_i = (a3 s + a1) / (s^2 + a2 s + a1)`` for an HDV (eq. 8) and ``T_c = (k_p s + k_s) / (s^2
- k_v s + k_s)`` for a CAV; a CAV that hears anyone else breaks the cascade
(:func:`local_cav_laws` says which one). For a cascade the low-frequency curvature is the sum of
the vehicles' own, ``c = sum_i (a3_i^2 - a2_i^2 + 2 a1_i) / a1_i^2`` (CAV: ``(k_p^2 - k_v^2 + 2
k_s) / k_s^2``), the identity the tests use to build a gain exactly on the string-stability
boundary. Measured (``python benchmarks/bench_platoon_analysis.py``): on the DeeP-LCC platoon
(two CAVs with local gains) the state space and the product agree to 2.0e-15 relative on 400
frequencies in 1e-3..1e2 rad/s (0.4 ms for the state-space curve).

Closed-loop eigenvalues (:func:`closed_loop_eigenvalues`) are computed per strongly connected
block of ``A_cl`` (a permutation to block-triangular form, exact): HDVs that the CAV does not
feed back form their own 2x2 blocks, so their eigenvalues are exact instead of being scattered
by a long Jordan chain. The string-stability verdict built on these is in
:mod:`lcc_synth.analysis.string_stability`.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import scipy.linalg as sla
from scipy.sparse.csgraph import connected_components

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import closed_loop, hdv_law
from lcc_synth.models.hdv import LinearCoefficients
from lcc_synth.models.linear import LCCModel

__all__ = [
    "phi_gamma",
    "closed_form_gains",
    "gamma_closed_form",
    "gamma_polynomials",
    "gamma_state_space",
    "head_to_tail_loop",
    "local_cav_laws",
    "vehicle_transfers",
    "gamma_product",
    "hessenberg_solver",
    "transfer_response",
    "tail_output",
    "has_head",
    "check_head",
    "closed_loop_eigenvalues",
    "low_frequency_curvature",
    "MERGE_RTOL",
    "merge_frequencies",
    "golden_max",
    "hamiltonian_matrix",
    "level_crossings",
    "hinf_norm_hamiltonian",
]

_GOLDEN_ITERS = 45
_EPS = float(np.finfo(float).eps)
MERGE_RTOL = 1e-7

CoefSpec = LinearCoefficients | Mapping[int, LinearCoefficients]


# --------------------------------------------------------------------------------------------
# Closed form (eq. 24, Appendix A)
# --------------------------------------------------------------------------------------------


def phi_gamma(coef: LinearCoefficients) -> tuple[np.ndarray, np.ndarray]:
    """``phi(s) = a3 s + a1`` and ``gamma(s) = s^2 + a2 s + a1`` (highest power first)."""
    return (
        np.array([coef.alpha3, coef.alpha1], dtype=float),
        np.array([1.0, coef.alpha2, coef.alpha1], dtype=float),
    )


def _per_vehicle(coefs: CoefSpec, m: int, n: int) -> dict[int, LinearCoefficients]:
    if isinstance(coefs, LinearCoefficients):
        return {i: coefs for i in range(-m, n + 1)}
    out = dict(coefs)
    missing = [i for i in range(-m, n + 1) if i not in out]
    if missing:
        raise ConfigError("coefficients", f"missing linear coefficients of vehicles {missing}")
    return out


def _check_gains(mu: Mapping[int, float], k: Mapping[int, float], m: int, n: int) -> None:
    for name, table in (("mu", mu), ("k", k)):
        for i in table:
            if not (-m <= int(i) <= n):
                raise ConfigError(
                    f"{name}[{i}]", f"vehicle index must be in [{-m}, {n}] (m={m}, n={n})"
                )


def _cav_polys(c0: LinearCoefficients, mu0: float, k0: float, kh: float):
    """CAV law ``(a1 + mu0) s_0 + (k0 - a2) v_0 + (a3 + kh) v_ahead`` -> (phi_0, gamma_0)."""
    phi0 = np.array([c0.alpha3 + kh, c0.alpha1 + mu0])
    gam0 = np.array([1.0, c0.alpha2 - k0, c0.alpha1 + mu0])
    return phi0, gam0


def closed_form_gains(
    model: LCCModel, K: np.ndarray, kh: float = 0.0
) -> tuple[dict[int, float], dict[int, float], float]:
    """Translate input feedback ``(K, kh)`` into the paper's ``mu_i, k_i`` (eq. 23).

    Returns ``(mu, k, kh_extra)``: the gains *added* to the CAV's HDV law (``mu[0]``/``k[0]``
    add to ``a1``/``-a2``; ``k[-1]`` adds to ``a3``), and for ``m = 0`` the gain added to ``a3``
    on the head velocity. Any static CAV command on an LCC model has this form.
    """
    check_head(model)
    K = np.asarray(K, dtype=float).reshape(-1)
    if K.shape[0] != model.nx:
        raise ConfigError("gain", f"needs {model.nx} entries for this model, got {K.shape[0]}")
    K_law, kh_law = hdv_law(model)
    if model.kind == "cf_lcc":  # the model's input is u_hat; the HDV law is inside A
        K_added, kh_added = K.copy(), float(kh)
    else:
        K_added, kh_added = K - K_law, float(kh) - kh_law
    mu = {i: float(K_added[2 * j]) for j, i in enumerate(model.vehicles)}
    kk = {i: float(K_added[2 * j + 1]) for j, i in enumerate(model.vehicles)}
    return mu, kk, kh_added


def gamma_closed_form(
    coefs: CoefSpec,
    mu: Mapping[int, float],
    k: Mapping[int, float],
    m: int,
    n: int,
    s,
    kh: float = 0.0,
):
    """Evaluate eq. (24), ``Gamma(s) = G(s) (phi/gamma)^(n+m)``, at complex ``s``.

    Parameters
    ----------
    coefs : LinearCoefficients or mapping
        Homogeneous coefficients (exactly the paper's formula) or one set per vehicle index
        ``-m..n`` (index 0: the CAV's HDV law). Heterogeneous strings use the product of the
        vehicles' own ``phi_j/gamma_j`` in place of each power of ``phi/gamma``.
    mu, k : mapping of int to float
        Spacing and velocity gains ``mu_i, k_i`` per vehicle index (missing: 0). ``mu[0]``,
        ``k[0]`` add to the CAV's ``a1``/``-a2``.
    m, n : int
        HDVs ahead / behind.
    s : complex array_like
        Laplace variable (``1j * omega`` for the frequency response).
    kh : float
        For ``m = 0`` only: gain added to ``a3`` on the head velocity.
    """
    _check_gains(mu, k, m, n)
    c = _per_vehicle(coefs, m, n)
    s = np.asarray(s, dtype=complex)
    T = {}
    H = {}
    for i in [*range(-m, 0), *range(1, n + 1)]:
        ph, ga = phi_gamma(c[i])
        phv, gav = np.polyval(ph, s), np.polyval(ga, s)
        T[i] = phv / gav
        H[i] = mu.get(i, 0.0) * (gav / phv - 1.0) + k.get(i, 0.0) * s
    phi0, gam0 = _cav_polys(c[0], mu.get(0, 0.0), k.get(0, 0.0), kh if m == 0 else 0.0)
    if m > 0 and kh:
        raise ConfigError("kh", "only for m = 0 (with m > 0 use k[-1])")
    num = np.polyval(phi0, s).astype(complex)
    for i in range(-m, 0):
        inv = np.ones_like(s)
        for j in range(i + 1, 0):
            inv = inv / T[j]
        num = num + H[i] * inv  # homogeneous: H_i (phi/gamma)^(i+1)
    den = np.polyval(gam0, s).astype(complex)
    prod = np.ones_like(s)
    for i in range(1, n + 1):
        prod = prod * T[i]
        den = den - H[i] * prod  # homogeneous: H_i (phi/gamma)^i
    G = num / den
    out = G
    for i in T:
        out = out * T[i]  # homogeneous: (phi/gamma)^(n+m)
    return out


def gamma_polynomials(
    coefs: CoefSpec,
    mu: Mapping[int, float],
    k: Mapping[int, float],
    m: int,
    n: int,
    kh: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """``Gamma = num / den`` as exact polynomials (highest power first).

    ``den`` is the closed-loop characteristic polynomial (degree ``2(m+n+1)``, monic):
    ``prod_{P} gamma_j * [gamma_0 prod_F gamma_j - sum_{i in F} h_i(s) prod_{j<i} phi_j
    prod_{j>i} gamma_j]`` with ``h_i = mu_i (gamma_i - phi_i) + k_i s phi_i``; ``num`` is
    ``prod_F phi_j * [phi_0 prod_P phi_j + sum_{i in P} h_i ...]``. Both are affine in every
    single pair ``(mu_i, k_i)``: the fact the region maps exploit. Products of quadratics only:
    no cancellation, no root finding.
    """
    _check_gains(mu, k, m, n)
    if m > 0 and kh:
        raise ConfigError("kh", "only for m = 0 (with m > 0 use k[-1])")
    c = _per_vehicle(coefs, m, n)
    pg = {i: phi_gamma(c[i]) for i in c if i != 0}

    def h(i):
        ph, ga = pg[i]
        return np.polyadd(
            mu.get(i, 0.0) * np.polysub(ga, np.concatenate([[0.0], ph])),
            k.get(i, 0.0) * np.polymul([1.0, 0.0], ph),
        )

    def prod(polys):
        out = np.array([1.0])
        for p in polys:
            out = np.polymul(out, p)
        return out

    phi0, gam0 = _cav_polys(c[0], mu.get(0, 0.0), k.get(0, 0.0), kh if m == 0 else 0.0)
    P = list(range(-m, 0))
    F = list(range(1, n + 1))
    # ahead part: V_0 numerator over prod_P gamma
    num_p = prod([phi0] + [pg[j][0] for j in P])
    for i in P:
        term = prod([h(i)] + [pg[j][0] for j in P if j < i] + [pg[j][1] for j in P if j > i])
        num_p = np.polyadd(num_p, term)
    den_f = prod([gam0] + [pg[j][1] for j in F])
    for i in F:
        term = prod([h(i)] + [pg[j][0] for j in F if j < i] + [pg[j][1] for j in F if j > i])
        den_f = np.polysub(den_f, term)
    num = np.polymul(num_p, prod([pg[j][0] for j in F]))
    den = np.polymul(den_f, prod([pg[j][1] for j in P]))
    return np.trim_zeros(num, "f"), den


# --------------------------------------------------------------------------------------------
# State space
# --------------------------------------------------------------------------------------------


def hessenberg_solver(A: np.ndarray, b: np.ndarray, c: np.ndarray):
    """A function ``s -> c (s I - A)^-1 b`` (see :func:`transfer_response`), reduction done once.

    ``b`` may hold several right-hand sides as columns ``(nx, k)`` with ``k > 1``; the
    function then returns an array of shape ``s.shape + (k,)`` (one elimination per ``s``
    serves all columns). A vector or an ``(nx, 1)`` column gives ``s.shape``.
    """
    from lcc_synth.analysis.hessenberg_kernel import hessenberg_responses

    A = np.asarray(A, dtype=float)
    b = np.asarray(b, dtype=float)
    single = b.ndim == 1 or b.shape[-1] == 1
    b = b.reshape(A.shape[0], -1)
    c = np.asarray(c, dtype=float).reshape(-1)
    Hs, Q = sla.hessenberg(A, calc_q=True)
    Hs = np.ascontiguousarray(Hs)
    bh = np.ascontiguousarray(Q.T @ b)
    ch = np.ascontiguousarray(c @ Q)

    def solve(s):
        s = np.asarray(s, dtype=complex)
        out = hessenberg_responses(Hs, bh, ch, np.ascontiguousarray(s.reshape(-1)))
        out = out.reshape(s.shape + (bh.shape[1],))
        return out[..., 0] if single else out

    return solve


def transfer_response(A: np.ndarray, b: np.ndarray, c: np.ndarray, s) -> np.ndarray:
    """``c (s I - A)^-1 b`` for every complex ``s`` (SISO), numerically stable.

    ``A`` is reduced once to upper Hessenberg form ``A = Q Hs Q^T`` (orthogonal); each
    ``(s I - Hs) y = Q^T b`` is then solved by Gaussian elimination of the single subdiagonal
    with row pivoting between the two candidate rows (backward stable, O(nx^2) per ``s``), in
    a compiled loop (:mod:`lcc_synth.analysis.hessenberg_kernel`).
    """
    return hessenberg_solver(A, b, c)(np.atleast_1d(np.asarray(s, dtype=complex)))


def tail_output(model) -> np.ndarray:
    """Output row ``c`` that picks the tail vehicle's velocity error from the state (any
    layout: the velocity of the last of ``model.vehicles``)."""
    c = np.zeros(model.nx)
    c[model.index(f"v_{model.vehicles[-1]}")] = 1.0
    return c


def has_head(model) -> bool:
    """Whether a vehicle of the layout follows a head vehicle: the head-velocity input ``H``
    is not zero (false for FD-LCC and the ring)."""
    return bool(np.any(model.H))


def check_head(model) -> None:
    """Raise :class:`~lcc_synth.errors.ConfigError` (field ``system.kind``) for a layout with
    no head vehicle (:func:`has_head`): the head-to-tail transfer is undefined."""
    if not has_head(model):
        raise ConfigError(
            "system.kind",
            f"{model.kind} has no head vehicle: the head-to-tail transfer is undefined",
        )


def head_to_tail_loop(model, K, kh=0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(A_cl, h, c)``: the closed loop of ``input = K x + kh v_h`` on any layout with a head
    vehicle, from the head's velocity error (``h``) to the tail's (``c``).

    ``K``, ``kh``: one CAV, ``nx`` entries and a number
    (:func:`lcc_synth.models.feedback.input_feedback`); several, one row / entry per CAV
    (:meth:`lcc_synth.models.feedback.Gains.input_feedback`).
    """
    check_head(model)
    Acl, Hcl = closed_loop(model, K, kh)
    return Acl, Hcl.reshape(-1), tail_output(model)


def gamma_state_space(model, K: np.ndarray, kh=0.0, omega=None) -> np.ndarray:
    """``Gamma(j omega)`` from the closed-loop state space (input feedback ``K``, ``kh``; any
    layout with a head vehicle, see :func:`head_to_tail_loop`)."""
    Acl, h, c = head_to_tail_loop(model, K, kh)
    omega = np.asarray(omega, dtype=float)
    return transfer_response(Acl, h, c, 1j * omega)


# --------------------------------------------------------------------------------------------
# A cascade of vehicles: Gamma as the product of per-vehicle transfer functions
# --------------------------------------------------------------------------------------------


def local_cav_laws(model, K, kh=0.0) -> dict[int, tuple[float, float, float]]:
    """``{c: (k_s, k_v, k_p)}``: every CAV's acceleration ``dv_c = k_s s_c + k_v v_c + k_p
    v_{c-1}`` in the closed loop of ``input = K x + kh v_h`` (``v_{c-1}``: the vehicle ahead
    in ``model.vehicles``, ``v_h`` for the first). Read from the closed loop's ``v_c`` row, so
    an ``"added"`` gain's HDV law (and CF-LCC's, which its ``A`` holds) is included.

    Raises
    ------
    ConfigError
        ``system.kind`` for a layout without a head vehicle; ``gains.u_c`` when CAV ``c`` uses
        another vehicle's state (or ``v_h`` when it does not follow the head): the string is
        then not a cascade of per-vehicle transfer functions.
    """
    Acl, h, _ = head_to_tail_loop(model, K, kh)
    vehicles = list(model.vehicles)
    out = {}
    for c in model.cavs:
        row = model.index(f"v_{c}")
        own_s, own_v = row - 1, row
        j = vehicles.index(c)
        pred = model.index(f"v_{vehicles[j - 1]}") if j > 0 else None
        allowed = {own_s, own_v} | ({pred} if pred is not None else set())
        other = [model.state_names[i] for i in np.nonzero(Acl[row])[0] if i not in allowed]
        if pred is not None and h[row] != 0:
            other.append("v_h")
        if other:
            raise ConfigError(
                f"gains.u_{c}",
                f"uses {other}: only s_{c}, v_{c} and the predecessor's velocity keep the "
                "string a cascade of per-vehicle transfer functions",
            )
        k_p = float(Acl[row, pred]) if pred is not None else float(h[row])
        out[c] = (float(Acl[row, own_s]), float(Acl[row, own_v]), k_p)
    return out


def vehicle_transfers(model, K, kh, s) -> np.ndarray:
    """``(N,) + s.shape`` array: each vehicle's ``T_i(s) = V_i / V_{i-1}``, in the order of
    ``model.vehicles``: ``phi_i / gamma_i`` (eq. 8) for an HDV, ``(k_p s + k_s) / (s^2 - k_v s
    + k_s)`` for a CAV with a local law (:func:`local_cav_laws`; from ``s V_c = u_c`` and
    ``s S_c = V_{c-1} - V_c``)."""
    laws = local_cav_laws(model, K, kh)
    s = np.asarray(s, dtype=complex)
    out = np.empty((len(model.vehicles),) + s.shape, dtype=complex)
    for j, (i, coef) in enumerate(zip(model.vehicles, model.vehicle_coefficients, strict=True)):
        if i in laws:
            k_s, k_v, k_p = laws[i]
            num, den = np.array([k_p, k_s]), np.array([1.0, -k_v, k_s])
        else:
            num, den = phi_gamma(coef)
        out[j] = np.polyval(num, s) / np.polyval(den, s)
    return out


def gamma_product(model, K, kh, omega) -> np.ndarray:
    """``Gamma(j omega) = prod_i T_i(j omega)`` (:func:`vehicle_transfers`; every CAV with a
    local law, else ConfigError)."""
    s = 1j * np.asarray(omega, dtype=float)
    return np.prod(vehicle_transfers(model, K, kh, s), axis=0)


def closed_loop_eigenvalues(Acl: np.ndarray) -> np.ndarray:
    """Eigenvalues of ``Acl`` computed per strongly connected block (exact permutation to
    block-triangular form), so uncoupled identical vehicles do not scatter each other's."""
    Acl = np.asarray(Acl, dtype=float)
    ncomp, labels = connected_components(Acl != 0, directed=True, connection="strong")
    parts = []
    for comp in range(ncomp):
        idx = np.nonzero(labels == comp)[0]
        parts.append(np.linalg.eigvals(Acl[np.ix_(idx, idx)]))
    return np.concatenate(parts)


def low_frequency_curvature(Acl: np.ndarray, h: np.ndarray, c: np.ndarray):
    """``(g0, c2, c_rel)``: ``Gamma(0)``, the curvature ``c`` of ``|Gamma(jw)|^2 = g0^2 + c w^2
    + O(w^4)`` and ``c`` relative to its two terms (``c = g1^2 - g0 g2``, Taylor coefficients of
    ``Gamma`` at 0 from three solves with ``Acl``)."""
    lu = sla.lu_factor(Acl)
    y1 = sla.lu_solve(lu, np.asarray(h, float).reshape(-1))
    y2 = sla.lu_solve(lu, y1)
    y3 = sla.lu_solve(lu, y2)
    g0 = -float(c @ y1)
    g1 = -float(c @ y2)
    g2 = -2.0 * float(c @ y3)
    curv = g1 * g1 - g0 * g2
    scale = g1 * g1 + abs(g0 * g2)
    return g0, curv, (curv / scale if scale > 0 else 0.0)


# --------------------------------------------------------------------------------------------
# Frequency-response tools: golden-section peak refinement, Hamiltonian level sets, H-infinity
# --------------------------------------------------------------------------------------------


def merge_frequencies(w: np.ndarray, rtol: float = MERGE_RTOL) -> np.ndarray:
    """Sorted ``w`` with points closer than ``rtol`` (relative) merged."""
    w = np.sort(w)
    if w.size < 2:
        return w
    keep = np.concatenate([[True], np.diff(w) > rtol * w[1:]])
    return w[keep]


def golden_max(f, lo: np.ndarray, hi: np.ndarray):
    """Vectorised golden-section maximisation on ``log w`` brackets ``[lo, hi]``."""
    a, b = np.log(lo), np.log(hi)
    r = (np.sqrt(5.0) - 1.0) / 2.0
    x1 = b - r * (b - a)
    x2 = a + r * (b - a)
    f1, f2 = f(np.exp(x1)), f(np.exp(x2))
    for _ in range(_GOLDEN_ITERS):
        left = f1 >= f2  # maximum in [a, x2]
        a_new = np.where(left, a, x1)
        b_new = np.where(left, x2, b)
        # the kept interior point becomes the new x2 (left) or x1 (right)
        keep_x = np.where(left, x1, x2)
        keep_f = np.where(left, f1, f2)
        new_x = np.where(left, b_new - r * (b_new - a_new), a_new + r * (b_new - a_new))
        new_f = f(np.exp(new_x))
        x1 = np.where(left, new_x, keep_x)
        f1 = np.where(left, new_f, keep_f)
        x2 = np.where(left, keep_x, new_x)
        f2 = np.where(left, keep_f, new_f)
        a, b = a_new, b_new
    xb = np.where(f1 >= f2, x1, x2)
    return np.exp(xb), np.maximum(f1, f2)


def hamiltonian_matrix(A: np.ndarray, b: np.ndarray, c: np.ndarray, level: float) -> np.ndarray:
    """Hamiltonian ``[[A, b b'/level], [-c' c/level, -A']]``: its imaginary eigenvalues ``jw``
    are the frequencies where ``|c (jwI - A)^-1 b| = level``."""
    b = b.reshape(-1, 1)
    c = c.reshape(1, -1)
    return np.block([[A, b @ b.T / level], [-c.T @ c / level, -A.T]])


def level_crossings(
    A: np.ndarray, b: np.ndarray, c: np.ndarray, level: float, rtol: float | None = None
) -> np.ndarray:
    """Frequencies ``w >= 0`` with ``|c (jw I - A)^-1 b| = level``: the imaginary-axis
    eigenvalues ``jw`` of the Hamiltonian ``[[A, b b^T/level], [-c^T c/level, -A^T]]``.

    An eigenvalue counts as imaginary when ``|Re| <= rtol * ||H||`` (default ``rtol`` =
    ``sqrt(eps)``: a simple eigenvalue on the axis moves off it by about ``eps ||H||`` times
    its condition number). Not for the level ``|Gamma(0)|`` itself, whose double root at 0 is
    rounding-decided: :func:`loop_string_stability` deflates it.
    """
    A = np.asarray(A, float)
    b = np.asarray(b, float).reshape(-1)
    c = np.asarray(c, float).reshape(-1)
    Hm = hamiltonian_matrix(A, b, c, level)
    ev = np.linalg.eigvals(Hm)
    tol = (np.sqrt(_EPS) if rtol is None else rtol) * np.linalg.norm(Hm, 1)
    on_axis = np.abs(ev.real) <= tol
    return merge_frequencies(np.abs(ev[on_axis].imag))


def hinf_norm_hamiltonian(
    A: np.ndarray, b: np.ndarray, c: np.ndarray, tol: float = 1e-10, max_iter: int = 100
) -> tuple[float, float]:
    """``(sup_w |G(jw)|, argmax)`` of a stable SISO ``G = c (sI - A)^-1 b`` by the
    quadratically convergent level-set iteration of Boyd & Balakrishnan (each new lower bound
    refined by golden section between the crossings, so the value is exact to ``tol``)."""
    A = np.asarray(A, float)
    b = np.asarray(b, float).reshape(-1)
    c = np.asarray(c, float).reshape(-1)
    eigs = np.linalg.eigvals(A)
    cand = np.concatenate([[0.0], np.abs(eigs.imag), np.abs(eigs)])
    vals = np.abs(transfer_response(A, b, c, 1j * cand))
    i = int(np.argmax(vals))
    lb, w_best = float(vals[i]), float(cand[i])
    solver = hessenberg_solver(A, b, c)

    def mag(w):
        return np.abs(solver(1j * np.asarray(w, float)))

    for _ in range(max_iter):
        level = (1.0 + 2.0 * tol) * lb
        ws = level_crossings(A, b, c, level)
        ws = ws[ws > 0]
        if ws.size < 2:
            return lb, w_best
        om, mv = golden_max(mag, ws[:-1], ws[1:])
        j = int(np.argmax(mv))
        if mv[j] <= lb:
            return lb, w_best
        lb, w_best = float(mv[j]), float(om[j])
    return lb, w_best


