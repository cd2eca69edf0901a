"""Exact rational reference for head-to-tail string stability (test helper, no tests here).

Given float closed-loop data ``(A, h, c)``, ``Gamma(s) = c (sI - A)^-1 h``, every float is
converted exactly (floats are dyadic rationals) and the verdict is decided in exact integer
arithmetic; only the reported peak and the decision-function maximum use multiprecision
(mpmath, 50 digits).

Exact route (plain Python integers, no SymPy needed):

* scale: ``M = 2^E A``, ``u = 2^Eh h``, ``w = 2^Ec c`` are integer; with ``t = 2^E s``,
  ``Gamma(s) = 2^(E - Eh - Ec) w (tI - M)^-1 u``;
* ``den(t) = det(tI - M)`` by Berkowitz's division-free algorithm (sparse matrix-vector
  products, integer coefficients); ``w adj(tI - M) u = det(tI - M) - det(tI - M - u w)``
  (matrix determinant lemma), so the numerator is the difference of two characteristic
  polynomials: exact, no interpolation;
* ``g0 = num(0) / den(0)`` as a reduced fraction ``a/b``;
* ``P(x) = g0^2 |den(j w)|^2 - |num(j w)|^2`` as an integer polynomial in ``x = w^2`` (scaled by
  ``b^2``), ``P(0) = 0`` exactly, ``R(x) = P(x) / x``. ``|Gamma|^2 - g0^2 = -P / |den|^2``,
  hence ``R(0) = -c den(0)^2`` (``c`` the low-frequency curvature);
* plant stability: exact Routh-Hurwitz (integer rows, positive-content normalisation);
* string stability: plant stable, ``R(0) > 0`` and no root of ``R`` in ``(0, inf)`` (Descartes'
  rule of signs first, Sturm sequence with sign-correct primitive pseudo-remainders otherwise).

The verdict is about the float data given, compared against ``|g0|`` (``g0 = 1`` exactly for an
LCC closed loop built from its model; a float similarity transform moves it by round-off).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import mpmath
import numpy as np

__all__ = [
    "ExactVerdict",
    "ExactRational",
    "exact_rational",
    "exact_string_verdict",
    "charpoly_int",
    "hurwitz_stable",
    "positive_root_count",
]

DPS = 50


# --------------------------------------------------------------------------------------------
# Integer polynomials: lists of Python ints, lowest degree first
# --------------------------------------------------------------------------------------------


def _trim(p: list[int]) -> list[int]:
    p = list(p)
    while len(p) > 1 and p[-1] == 0:
        p.pop()
    return p


def _add(p, q):
    n = max(len(p), len(q))
    return _trim([(p[i] if i < len(p) else 0) + (q[i] if i < len(q) else 0) for i in range(n)])


def _scale(p, k):
    return [k * a for a in p]


def _mul(p, q):
    out = [0] * (len(p) + len(q) - 1)
    for i, a in enumerate(p):
        if a:
            for j, b in enumerate(q):
                out[i + j] += a * b
    return _trim(out)


def _deriv(p):
    return _trim([i * p[i] for i in range(1, len(p))]) if len(p) > 1 else [0]


def _content(p):
    g = 0
    for a in p:
        g = math.gcd(g, a)
    return g


def _primitive(p):
    g = _content(p)
    return [a // g for a in p] if g > 1 else list(p)


def _abs_square_even(p: list[int]) -> list[int]:
    """``|p(j y)|^2`` as a polynomial in ``X = y^2`` (real integer ``p``)."""
    ev = [p[k] * (-1) ** (k // 2) for k in range(0, len(p), 2)]
    od = [p[k] * (-1) ** ((k - 1) // 2) for k in range(1, len(p), 2)]
    out = _mul(ev, ev) if ev else [0]
    if od:
        out = _add(out, [0] + _mul(od, od))
    return out


def _sign_variations(seq) -> int:
    signs = [1 if a > 0 else -1 for a in seq if a != 0]
    return sum(1 for i in range(1, len(signs)) if signs[i] != signs[i - 1])


def _prem_signed(f: list[int], g: list[int]) -> list[int]:
    """A positive multiple of ``rem(f, g)`` (integer pseudo-division), primitive."""
    r = list(f)
    dg = len(g) - 1
    L = g[-1]
    steps = 0
    while len(r) - 1 >= dg and any(r):
        shift = len(r) - 1 - dg
        lead = r[-1]
        r = [L * a for a in r]
        for i, b in enumerate(g):
            r[shift + i] -= lead * b
        r.pop()  # leading term cancels exactly
        steps += 1
        r = _trim(r) if r else [0]
        if len(r) - 1 < dg:
            break
    if L < 0 and steps % 2 == 1:
        r = [-a for a in r]
    r = _trim(r)
    return _primitive(r) if any(r) else [0]


def positive_root_count(p: list[int]) -> int:
    """Number of distinct real roots of integer ``p`` in ``(0, inf)`` (exact)."""
    p = _trim(p)
    while len(p) > 1 and p[0] == 0:  # a root at 0 is not positive
        p = p[1:]
    if len(p) <= 1:
        return 0
    v = _sign_variations(p)
    if v <= 1:  # Descartes: the count of positive roots (with multiplicity) is v - 2k
        return v
    seq = [_primitive(p), _primitive(_deriv(p))]
    while len(seq[-1]) > 1:
        r = _prem_signed(seq[-2], seq[-1])
        if not any(r):
            break
        seq.append([-a for a in r])
    at0 = [q[0] for q in seq]
    atinf = [q[-1] for q in seq]
    return _sign_variations(at0) - _sign_variations(atinf)


def hurwitz_stable(p: list[int]) -> bool:
    """All roots of integer ``p`` (lowest degree first) in the open left half plane (Routh)."""
    d = list(reversed(_trim(p)))  # highest degree first
    if d[0] < 0:
        d = [-a for a in d]
    deg = len(d) - 1
    if deg == 0:
        return True
    if any(a <= 0 for a in d):
        return False
    r0, r1 = d[0::2], d[1::2]
    rows = 2
    while rows < deg + 1:
        if r1[0] <= 0:
            return False
        width = max(len(r0) - 1, 1)
        r2 = []
        for k in range(width):
            a = r0[k + 1] if k + 1 < len(r0) else 0
            b = r1[k + 1] if k + 1 < len(r1) else 0
            r2.append(r1[0] * a - r0[0] * b)
        while len(r2) > 1 and r2[-1] == 0:
            r2.pop()
        g = _content(r2)
        if g > 1:
            r2 = [x // g for x in r2]
        r0, r1 = r1, r2
        rows += 1
    return r1[0] > 0 and r0[0] > 0


# --------------------------------------------------------------------------------------------
# Exact conversion and characteristic polynomials
# --------------------------------------------------------------------------------------------


def _dyadic(x: float) -> tuple[int, int]:
    """``x = p / 2^e`` exactly: ``(p, e)`` (``e`` may be negative)."""
    p, q = float(x).as_integer_ratio()
    e = q.bit_length() - 1
    if p and e == 0:  # strip powers of two from integers so large values get e < 0
        tz = (p & -p).bit_length() - 1
        return p >> tz, -tz
    return p, e


def _integer_scaled(values) -> tuple[list[int], int]:
    """Integers ``N`` and ``E`` with ``values = N / 2^E`` exactly (``E`` as small as possible)."""
    pairs = [_dyadic(v) for v in values]
    E = max((e for p, e in pairs if p), default=0)
    return [p << (E - e) if p else 0 for p, e in pairs], E


def charpoly_int(rows: list[list[tuple[int, int]]], n: int) -> list[int]:
    """``det(tI - M)`` of a sparse integer matrix (row ``i`` = list of ``(j, M_ij)``), lowest
    degree first, by Berkowitz's division-free algorithm."""
    if n == 0:
        return [1]
    dense_diag = [0] * n
    for i in range(n):
        for j, v in rows[i]:
            if j == i:
                dense_diag[i] = v
    # v: coefficients highest first of the charpoly of M[r:, r:]
    vec = [1, -dense_diag[n - 1]]
    for r in range(n - 2, -1, -1):
        k = n - r - 1  # size of the trailing submatrix
        a = dense_diag[r]
        Rrow = [(j, v) for j, v in rows[r] if j > r]
        # column C = M[r+1:, r]
        x = [0] * n
        for i in range(r + 1, n):
            for j, v in rows[i]:
                if j == r:
                    x[i] = v
        diags = [1, -a]
        for it in range(k):
            diags.append(-sum(v * x[j] for j, v in Rrow))
            if it == k - 1:
                break
            y = [0] * n
            for i in range(r + 1, n):
                s = 0
                for j, v in rows[i]:
                    if j > r:
                        xj = x[j]
                        if xj:
                            s += v * xj
                y[i] = s
            x = y
        # new = Toeplitz(diags) (k+2 x k+1, lower triangular) @ vec
        new = [0] * (k + 2)
        for i in range(k + 2):
            s = 0
            for j in range(max(0, i - len(diags) + 1), min(i + 1, k + 1)):
                s += diags[i - j] * vec[j]
            new[i] = s
        vec = new
    return list(reversed(vec))


def _sparse_rows(Mint: list[int], n: int) -> list[list[tuple[int, int]]]:
    return [[(j, Mint[i * n + j]) for j in range(n) if Mint[i * n + j]] for i in range(n)]


@dataclass(frozen=True)
class ExactRational:
    """``Gamma(s) = num(t) / den(t)`` with ``t = 2^E s`` (integer coefficients, lowest first)."""

    num: list[int]
    den: list[int]
    E: int
    n: int


def exact_rational(A, h, c) -> ExactRational:
    """Exact ``Gamma`` of float ``(A, h, c)`` as an integer rational function of ``t = 2^E s``."""
    A = np.asarray(A, dtype=float)
    n = A.shape[0]
    h = np.asarray(h, dtype=float).reshape(-1)
    c = np.asarray(c, dtype=float).reshape(-1)
    Mint, E = _integer_scaled(A.ravel().tolist())
    u, Eh = _integer_scaled(h.tolist())
    w, Ec = _integer_scaled(c.tolist())
    den = charpoly_int(_sparse_rows(Mint, n), n)
    # M + u w (exact integers): the determinant lemma gives w adj(tI - M) u
    Muw = list(Mint)
    for i in range(n):
        if u[i]:
            for j in range(n):
                if w[j]:
                    Muw[i * n + j] += u[i] * w[j]
    den2 = charpoly_int(_sparse_rows(Muw, n), n)
    num = _add(den, [-a for a in den2])
    # Gamma(s) = 2^(E - Eh - Ec) num(t) / den(t)
    sh = E - Eh - Ec
    if sh >= 0:
        num = [a << sh for a in num]
    else:
        den = [a << (-sh) for a in den]
    return ExactRational(num=_trim(num), den=_trim(den), E=E, n=n)


# --------------------------------------------------------------------------------------------
# Verdict
# --------------------------------------------------------------------------------------------


@dataclass
class ExactVerdict:
    """Exact string-stability verdict of float ``(A, h, c)``.

    Attributes
    ----------
    plant_stable : bool
        Exact Routh-Hurwitz on ``den``.
    string_stable : bool
        ``plant_stable`` and ``R(x) > 0`` for every ``x >= 0`` (so ``|Gamma(jw)| < |g0|`` for
        all ``w > 0``).
    positive_roots : int
        Distinct roots of ``R`` in ``(0, inf)`` (crossings / touchings of ``|Gamma| = |g0|``).
    c_sign : int
        Sign of the low-frequency curvature ``c`` (``-sign R(0)``): ``+1`` string unstable
        just above ``w = 0``, ``0`` exactly on the boundary.
    g0 : float
        ``Gamma(0)`` (exact, rounded for the report); ``g0_is_one`` tells whether it is 1.
    peak, peak_omega : float
        ``sup_{w > 0} |Gamma(jw)|`` (mpmath) and where (``0.0``: the ``w -> 0`` limit).
    q_max, q_max_omega : float
        ``max_{w >= 0} q(w)`` of the exact decision function ``q = Q / S`` (mpmath) and where.
    curvature : float
        ``c`` itself (exact rational rounded).
    seconds : float
        Wall time of the exact part (polynomials, Routh, Sturm) and of the whole call.
    """

    plant_stable: bool
    string_stable: bool
    positive_roots: int
    c_sign: int
    g0: float
    g0_is_one: bool
    curvature: float
    peak: float = float("nan")
    peak_omega: float = float("nan")
    q_max: float = float("nan")
    q_max_omega: float = float("nan")
    seconds_exact: float = 0.0
    seconds_total: float = 0.0
    extra: dict = field(default_factory=dict, repr=False)

    def q_exact(self, omega: float) -> float:
        """Exact decision function ``q`` at ``omega`` (mpmath, rounded to float)."""
        return float(self.extra["q_fn"](mpmath.mpf(omega)))


def _mp_poly(p: list[int]):
    return [mpmath.mpf(a) for a in reversed(p)]  # highest first for mpmath.polyval


def exact_string_verdict(
    A, h, c, peak: bool = True, q: bool = True, grid_per_decade: int = 40
) -> ExactVerdict:
    """Exact verdict of float ``(A, h, c)``; ``peak``/``q``: also the multiprecision
    supremum of ``|Gamma|`` and maximum of the decision function ``q``."""
    t0 = time.perf_counter()
    er = exact_rational(A, h, c)
    num, den, E = er.num, er.den, er.E
    plant_stable = hurwitz_stable(den)
    a, b = num[0], den[0]
    if b == 0:
        raise ZeroDivisionError("A is singular: Gamma(0) undefined")
    g = math.gcd(a, b)
    a, b = a // g, b // g
    if b < 0:
        a, b = -a, -b
    D = _abs_square_even(den)
    N = _abs_square_even(num)
    P = _add(_scale(D, a * a), _scale(N, -b * b))
    if P[0] != 0:
        raise AssertionError("P(0) != 0: exact arithmetic violated")
    R = P[1:] if len(P) > 1 else [0]
    r0 = R[0]
    c_sign = -1 if r0 > 0 else (1 if r0 < 0 else 0)
    npos = positive_root_count(R)
    string_stable = bool(plant_stable and r0 > 0 and npos == 0)
    # curvature c = -R(0)/den(0)^2 in t units; in s units multiply by 4^E (x_t = 4^E x),
    # and R, D carry the factor b^2 of P
    from fractions import Fraction

    curv = -Fraction(r0, b * b * den[0] * den[0]) * Fraction(4) ** E
    t_exact = time.perf_counter() - t0
    out = ExactVerdict(
        plant_stable=plant_stable,
        string_stable=string_stable,
        positive_roots=npos,
        c_sign=c_sign,
        g0=float(Fraction(a, b)),
        g0_is_one=(a == b),
        curvature=float(curv),
        seconds_exact=t_exact,
    )
    if peak or q:
        _multiprecision(out, A, num, den, a, b, E, R, D, N, peak, q, grid_per_decade)
    out.seconds_total = time.perf_counter() - t0
    return out


def _omega_grid(A, per_decade: int) -> list[float]:
    eig = np.linalg.eigvals(np.asarray(A, dtype=float))
    mags = np.abs(eig)
    mags = mags[mags > 0]
    lo = 1e-4 * (mags.min() if mags.size else 1.0)
    hi = 1e4 * (mags.max() if mags.size else 1.0)
    count = int(np.ceil(per_decade * np.log10(hi / lo))) + 1
    grid = np.logspace(np.log10(lo), np.log10(hi), count)
    extra = np.concatenate([np.abs(eig.imag), mags])
    extra = extra[(extra > lo) & (extra < hi)]
    # resonances: a few points around each pole frequency (relative width of the damping)
    around = []
    for lam in eig:
        wi = abs(lam.imag)
        if wi > lo:
            zeta = max(abs(lam.real) / abs(lam), 1e-6)
            around.extend(wi * (1 + zeta * np.linspace(-3, 3, 13)))
    pts = np.concatenate([grid, extra, np.array(around, dtype=float)])
    pts = pts[pts > 0]
    return sorted(set(pts.tolist()))


def _multiprecision(out, A, num, den, a, b, E, R, D, N, want_peak, want_q, per_decade):
    with mpmath.workdps(DPS + 10):
        s4 = mpmath.mpf(4) ** E
        s2 = mpmath.mpf(2) ** E
        Dp, Np = _mp_poly(D), _mp_poly(N)
        g0 = mpmath.mpf(a) / b

        def F(om):  # |Gamma(j om)|^2
            x = s4 * om * om
            return mpmath.polyval(Np, x) / mpmath.polyval(Dp, x)

        # Gamma1 = 2^E N1(t) / (b den(t)), Gamma2 = 4^E N2(t) / (b den(t) den(0))
        bn = [b * v for v in num]
        ad = [a * v for v in den]
        t1 = _add(bn, [-v for v in ad])
        assert t1[0] == 0
        N1 = t1[1:] if len(t1) > 1 else [0]
        d0, n10 = den[0], N1[0]
        t2 = _add(_scale(N1, d0), _scale(den, -n10))
        assert t2[0] == 0
        N2 = t2[1:] if len(t2) > 1 else [0]
        denp, N1p, N2p = _mp_poly(den), _mp_poly(N1), _mp_poly(N2)

        def q_fn(om):
            om = mpmath.mpf(om)
            t = mpmath.mpc(0, s2 * om)
            dv = mpmath.polyval(denp, t)
            G1 = s2 * mpmath.polyval(N1p, t) / (b * dv)
            G2 = s4 * mpmath.polyval(N2p, t) / (b * dv * d0)
            a1 = abs(G1) ** 2
            Q = a1 - 2 * g0 * mpmath.re(G2)
            S = a1 + 2 * abs(g0 * mpmath.re(G2))
            return Q / S if S != 0 else mpmath.mpf(0)

        out.extra["q_fn"] = q_fn
        grid = _omega_grid(A, per_decade)
        if want_peak:
            _peak(out, F, grid, g0)
        if want_q:
            _qmax(out, q_fn, grid)


def _golden(f, lo, hi, iters=80):
    lo, hi = mpmath.log(lo), mpmath.log(hi)
    r = (mpmath.sqrt(5) - 1) / 2
    x1, x2 = hi - r * (hi - lo), lo + r * (hi - lo)
    f1, f2 = f(mpmath.exp(x1)), f(mpmath.exp(x2))
    for _ in range(iters):
        if f1 >= f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - r * (hi - lo)
            f1 = f(mpmath.exp(x1))
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + r * (hi - lo)
            f2 = f(mpmath.exp(x2))
    return (mpmath.exp(x1), f1) if f1 >= f2 else (mpmath.exp(x2), f2)


def _local_max_refine(f, grid, vals, top=6):
    cand = []
    for i in range(1, len(grid) - 1):
        if vals[i] >= vals[i - 1] and vals[i] >= vals[i + 1]:
            cand.append(i)
    cand.sort(key=lambda i: vals[i], reverse=True)
    best = []
    for i in cand[:top]:
        om, v = _golden(f, mpmath.mpf(grid[i - 1]), mpmath.mpf(grid[i + 1]))
        if v < vals[i]:
            om, v = mpmath.mpf(grid[i]), vals[i]
        best.append((v, om))
    return best


def _peak(out, F, grid, g0):
    vals = [F(mpmath.mpf(w)) for w in grid]
    best = _local_max_refine(F, grid, vals)
    dc2 = g0 * g0
    peak2, peak_w = dc2, mpmath.mpf(0)
    for v, om in best:
        if v > peak2:
            peak2, peak_w = v, om
    if vals[-1] > peak2:  # rising at the top of the grid (not for strictly proper Gamma)
        peak2, peak_w = vals[-1], mpmath.mpf(grid[-1])
    out.peak = float(mpmath.sqrt(peak2))
    out.peak_omega = float(peak_w)
    out.extra["peak_mp"] = mpmath.sqrt(peak2)


def _qmax(out, q_fn, grid):
    q0 = q_fn(0)
    vals = [q_fn(w) for w in grid]
    best = _local_max_refine(q_fn, grid, vals)
    qm, qw = q0, mpmath.mpf(0)
    for v, om in best:
        if v > qm:
            qm, qw = v, om
    if vals[0] > qm:
        qm, qw = vals[0], mpmath.mpf(grid[0])
    if vals[-1] > qm:
        qm, qw = vals[-1], mpmath.mpf(grid[-1])
    out.q_max = float(qm)
    out.q_max_omega = float(qw)
    out.extra["q0"] = float(q0)
