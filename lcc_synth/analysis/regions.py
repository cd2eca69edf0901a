"""Head-to-tail string-stable regions of one vehicle's gains (Figs. 7-8), vectorised.

Over a grid of ``(mu_i, k_i)`` for one vehicle ``i``, all other gains fixed, every point is
classified as

``0`` unstable            the closed loop has an eigenvalue with ``Re >= 0``;
``1`` stable              plant stable, not head-to-tail string stable;
``2`` string stable       plant stable and ``|Gamma(jw)| < 1`` for all ``w > 0``.

Why it is fast: ``Gamma = num/den`` (:func:`lcc_synth.analysis.transfer.gamma_polynomials`) with
``num`` and ``den`` *affine* in ``(mu_i, k_i)``: ``num = N0 + mu N1 + k N2``, ``den = D0 + mu D1
+ k D2`` (``den`` is the closed-loop characteristic polynomial). Hence

* plant stability: a vectorised Routh-Hurwitz test on the coefficients of ``den`` for every
  grid point (exact sign test, no eigenvalues), in chunks of rows to bound memory;
* low frequencies: ``|Gamma(jw)|^2 = 1 + c w^2 + O(w^4)`` with ``c`` a quadratic in
  ``(mu, k)`` from the three lowest coefficients; string stability needs
  ``c_rel < -LOW_FREQ_TOL`` (as :func:`~lcc_synth.analysis.string_stability.string_stability`);
* ``w > 0``: for a fixed row ``mu`` and frequency ``w``, ``|num(jw)|^2 - rho |den(jw)|^2`` is a
  *quadratic in k* (``rho = (1 - PEAK_TOL)^2``). Its non-negative set is at most two intervals
  of ``k``, found in closed form; marking them on the ``k`` axis (a difference array and one
  cumulative sum) flags every grid point with ``|Gamma(jw)| >= 1 - PEAK_TOL`` at that ``w``. The
  work is ``O(n_mu * n_omega)`` closed-form roots plus ``O(n_mu * n_k)``, instead of
  ``O(n_mu * n_k * n_omega)`` evaluations, so the frequency grid can be dense.

Frequency grid (:func:`region_frequency_grid`): logarithmic, ``DEFAULT_PER_DECADE`` = 200
points per decade on ``[1e-3, 1e2]`` rad/s plus ``DEFAULT_DENSE_PER_DECADE`` = 3000 per decade on
``[0.03, 10]`` rad/s, where the resonance peaks of the paper's maps lie (sampled peaks at 0.12-1.9
rad/s; closed-loop poles up to ~5 rad/s). Relative spacing in the dense band: 0.08 %. The grid is
exact in the direction "unstable": a flagged point has a witness frequency. A point whose
exceedance band is narrower than the grid spacing (only possible next to the plant-stability
boundary, for a pole with damping ratio below ~1e-3) could be reported string stable; the tests
compare the map with the exact per-point global check on random samples of grid points.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from lcc_synth.analysis.string_stability import LOW_FREQ_TOL, PEAK_TOL
from lcc_synth.analysis.transfer import closed_form_gains, gamma_polynomials
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import StaticGains, input_feedback
from lcc_synth.models.linear import LCCModel

__all__ = [
    "UNSTABLE",
    "STABLE",
    "STRING_STABLE",
    "DEFAULT_PER_DECADE",
    "DEFAULT_DENSE_PER_DECADE",
    "RegionMap",
    "region_frequency_grid",
    "affine_polynomials",
    "hurwitz",
    "region_map",
    "grid_axis",
    "region_fractions",
    "RegionSpec",
    "region_specs_from",
    "run_region_specs",
    "expansion",
]

UNSTABLE, STABLE, STRING_STABLE = 0, 1, 2
DEFAULT_PER_DECADE = 200
DEFAULT_DENSE_PER_DECADE = 3000
_LABEL_NAMES = {UNSTABLE: "unstable", STABLE: "stable", STRING_STABLE: "string_stable"}


@dataclass(frozen=True)
class RegionMap:
    """Classification of a ``(mu_i, k_i)`` grid for one vehicle.

    Attributes
    ----------
    name : str
        Map name (from the problem file).
    vehicle : int
        Vehicle index ``i`` whose gains vary.
    mu, k : numpy.ndarray
        Grid axes ``(n_mu,)`` and ``(n_k,)``.
    labels : numpy.ndarray
        ``(n_mu, n_k)`` int8: :data:`UNSTABLE`, :data:`STABLE` or :data:`STRING_STABLE`;
        ``labels[a, b]`` is the point ``(mu[a], k[b])``.
    fixed : dict
        The other gains (state name -> value, "added" semantics).
    n_omega : int
        Size of the frequency grid used.
    seconds : float
        Wall time of the computation.
    """

    name: str
    vehicle: int
    mu: np.ndarray
    k: np.ndarray
    labels: np.ndarray
    fixed: dict = field(default_factory=dict)
    n_omega: int = 0
    seconds: float = 0.0

    @property
    def points(self) -> int:
        """Number of grid points."""
        return int(self.labels.size)

    @property
    def plant_stable_fraction(self) -> float:
        """Fraction of the grid with a plant-stable closed loop (labels 1 and 2)."""
        return float(np.count_nonzero(self.labels != UNSTABLE)) / self.labels.size

    @property
    def string_stable_fraction(self) -> float:
        """Fraction of the grid that is head-to-tail string stable."""
        return float(np.count_nonzero(self.labels == STRING_STABLE)) / self.labels.size

    def area(self, label: int = STRING_STABLE) -> float:
        """Area of the ``(mu, k)`` plane with ``label`` (grid cells times cell area)."""
        dmu = (self.mu[-1] - self.mu[0]) / max(len(self.mu) - 1, 1)
        dk = (self.k[-1] - self.k[0]) / max(len(self.k) - 1, 1)
        return float(np.count_nonzero(self.labels == label)) * dmu * dk

    def as_dict(self, include_labels: bool = False) -> dict:
        """JSON-ready summary (``labels`` as nested lists only when asked)."""
        out = {
            "name": self.name,
            "vehicle": self.vehicle,
            "mu_range": [float(self.mu[0]), float(self.mu[-1])],
            "k_range": [float(self.k[0]), float(self.k[-1])],
            "shape": list(self.labels.shape),
            "points": self.points,
            "fixed_gains": dict(self.fixed),
            "plant_stable_fraction": self.plant_stable_fraction,
            "string_stable_fraction": self.string_stable_fraction,
            "stable_not_string_stable_fraction": float(
                np.count_nonzero(self.labels == STABLE) / self.labels.size
            ),
            "unstable_fraction": float(np.count_nonzero(self.labels == UNSTABLE))
            / self.labels.size,
            "n_omega": self.n_omega,
            "seconds": self.seconds,
            "labels_legend": {str(k): v for k, v in _LABEL_NAMES.items()},
        }
        if include_labels:
            out["labels"] = self.labels.tolist()
        return out


def grid_axis(
    lo: float, hi: float, step: float, field_name: str = "grid", step_field: str | None = None
) -> np.ndarray:
    """Inclusive grid ``lo, lo + step, ..., hi`` (``hi`` kept when it is on the lattice).

    Errors name ``field_name`` (the range) or ``step_field`` (default ``field_name.step``).
    """
    step_field = step_field or f"{field_name}.step"
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ConfigError(field_name, f"must be [low, high] with low < high, got {[lo, hi]}")
    if not (np.isfinite(step) and step > 0):
        raise ConfigError(step_field, f"must be > 0, got {step}")
    count = int(np.floor((hi - lo) / step + 1e-9)) + 1
    if count > 20001:
        raise ConfigError(
            step_field, f"gives {count} points on {field_name} = [{lo}, {hi}]; at most 20001"
        )
    return lo + step * np.arange(count)


def region_frequency_grid(
    omega_min: float = 1e-3,
    omega_max: float = 1e2,
    per_decade: int = DEFAULT_PER_DECADE,
    dense: tuple[float, float] = (0.03, 10.0),
    dense_per_decade: int = DEFAULT_DENSE_PER_DECADE,
) -> np.ndarray:
    """The frequency grid of the region maps (see the module docstring)."""
    if not (0 < omega_min < omega_max):
        raise ConfigError("omega_min", f"needs 0 < omega_min < omega_max, got {omega_min}")
    parts = [
        np.logspace(
            np.log10(omega_min),
            np.log10(omega_max),
            int(np.ceil(per_decade * np.log10(omega_max / omega_min))) + 1,
        )
    ]
    lo, hi = max(dense[0], omega_min), min(dense[1], omega_max)
    if dense_per_decade > 0 and lo < hi:
        count = int(np.ceil(dense_per_decade * np.log10(hi / lo))) + 1
        parts.append(np.logspace(np.log10(lo), np.log10(hi), count))
    return np.unique(np.concatenate(parts))


def _base_gains(model: LCCModel, gains) -> tuple[dict, dict, float]:
    if gains is None:
        gains = StaticGains({})
    if isinstance(gains, StaticGains):
        K, kh = input_feedback(model, gains)
    else:
        K, kh = gains
    return closed_form_gains(model, K, kh)


def affine_polynomials(model: LCCModel, vehicle: int, gains=None):
    """``(N0, N1, N2, D0, D1, D2)``: ``num = N0 + mu N1 + k N2``, ``den = D0 + mu D1 + k D2``
    for the gains ``(mu, k)`` of ``vehicle``, the other gains from ``gains``.

    Coefficients are in *ascending* powers, all padded to the degree of ``den``.
    ``gains`` is a :class:`~lcc_synth.models.feedback.StaticGains` or input feedback ``(K, kh)``.
    """
    if vehicle == 0 or vehicle not in model.vehicles:
        allowed = [i for i in model.vehicles if i != 0]
        raise ConfigError("vehicle", f"must be one of {allowed} (an HDV), got {vehicle!r}")
    mu, kk, kh = _base_gains(model, gains)
    deg = 2 * len(model.vehicles)

    def polys(a, b):
        m2, k2 = dict(mu), dict(kk)
        m2[vehicle], k2[vehicle] = a, b
        num, den = gamma_polynomials(model.coefficients, m2, k2, model.m, model.n, kh)
        out = []
        for p in (num, den):
            asc = np.zeros(deg + 1)
            asc[: len(p)] = p[::-1]
            out.append(asc)
        return out

    (n0, d0), (n1, d1), (n2, d2) = polys(0.0, 0.0), polys(1.0, 0.0), polys(0.0, 1.0)
    return n0, n1 - n0, n2 - n0, d0, d1 - d0, d2 - d0


def hurwitz(coef_desc: np.ndarray) -> np.ndarray:
    """Vectorised Routh-Hurwitz test: ``coef_desc (..., N+1)`` highest power first (leading
    coefficient > 0). True where every root has negative real part (a zero in the first
    column, i.e. a root on or right of the axis to round-off, counts as not stable)."""
    a = np.asarray(coef_desc, dtype=float)
    N = a.shape[-1] - 1
    if N == 0:
        return np.ones(a.shape[:-1], dtype=bool)
    width = N // 2 + 1
    r0 = np.zeros(a.shape[:-1] + (width + 1,))
    r1 = np.zeros(a.shape[:-1] + (width + 1,))
    e = a[..., 0::2]
    o = a[..., 1::2]
    r0[..., : e.shape[-1]] = e
    r1[..., : o.shape[-1]] = o
    ok = a[..., 0] > 0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for _ in range(N):
            piv = r1[..., 0]
            ok &= piv > 0
            nxt = np.zeros_like(r0)
            nxt[..., :-1] = r0[..., 1:] - (r0[..., :1] / piv[..., None]) * r1[..., 1:]
            r0, r1 = r1, nxt
    return ok & np.isfinite(r0[..., 0])


def _polyval_asc(c: np.ndarray, s: np.ndarray) -> np.ndarray:
    out = np.zeros_like(s, dtype=complex)
    for coef in c[::-1]:
        out = out * s + coef
    return out


def _curvature_term(p0, p1, p2, mr, k):
    """``q1^2 - 2 q0 q2`` for ``q = p0 + mu p1 + k p2`` on the ``(mr, k)`` grid."""

    def c(j):
        return p0[j] + mr[:, None] * p1[j] + k[None, :] * p2[j]

    return c(1) ** 2 - 2.0 * c(0) * c(2)


def _mark_intervals(k: np.ndarray, A, B, C) -> np.ndarray:
    """For each row (axis 0) and frequency (axis 1), the ``k`` grid points where
    ``A + B k + C k^2 >= 0``; returns ``(rows, n_k)`` bool 'flagged at some frequency'."""
    rows, nw = A.shape
    nk = k.size
    disc = B * B - 4.0 * A * C
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        sq = np.sqrt(np.maximum(disc, 0.0))
        q = -0.5 * (B + np.where(B >= 0, sq, -sq))
        r_a = q / C
        r_b = A / q
    lo_root = np.fmin(r_a, r_b)
    hi_root = np.fmax(r_a, r_b)
    inf = np.inf
    # up to two intervals [l1, h1], [l2, h2] per (row, w); NaN bounds mean "empty"
    quad = C != 0
    up = quad & (C > 0)
    down = quad & (C < 0)
    has_roots = disc >= 0
    l1 = np.full(A.shape, np.nan)
    h1 = np.full(A.shape, np.nan)
    l2 = np.full(A.shape, np.nan)
    h2 = np.full(A.shape, np.nan)
    # C > 0: outside the roots (everything when no real root)
    m = up & has_roots
    l1[m], h1[m], l2[m], h2[m] = -inf, lo_root[m], hi_root[m], inf
    m = up & ~has_roots
    l1[m], h1[m] = -inf, inf
    # C < 0: between the roots
    m = down & has_roots
    l1[m], h1[m] = lo_root[m], hi_root[m]
    # C == 0: linear B k + A >= 0
    lin = ~quad
    with np.errstate(divide="ignore", invalid="ignore"):
        root = -A / B
    m = lin & (B > 0)
    l1[m], h1[m] = root[m], inf
    m = lin & (B < 0)
    l1[m], h1[m] = -inf, root[m]
    m = lin & (B == 0) & (A >= 0)
    l1[m], h1[m] = -inf, inf

    diff = np.zeros(rows * (nk + 1))
    row_off = (np.arange(rows) * (nk + 1))[:, None]
    for lo, hi in ((l1, h1), (l2, h2)):
        valid = ~np.isnan(lo) & ~np.isnan(hi)
        start = np.searchsorted(k, np.where(valid, lo, inf), side="left")
        stop = np.searchsorted(k, np.where(valid, hi, -inf), side="right")
        good = valid & (stop > start)
        diff += np.bincount((row_off + start)[good], minlength=diff.size)
        diff -= np.bincount((row_off + stop)[good], minlength=diff.size)
    counts = np.cumsum(diff.reshape(rows, nk + 1), axis=1)[:, :nk]
    return counts > 0.5


def region_map(
    model: LCCModel,
    vehicle: int,
    mu: np.ndarray,
    k: np.ndarray,
    gains=None,
    omega: np.ndarray | None = None,
    name: str = "",
    chunk_points: int = 250_000,
) -> RegionMap:
    """Classify every ``(mu[a], k[b])`` for ``vehicle`` (see the module docstring).

    Parameters
    ----------
    model : LCCModel
        A model with a head vehicle (``lcc``, ``cf_lcc``, ``ccc``).
    vehicle : int
        The HDV whose ``s_i``/``v_i`` gains vary (``i != 0``).
    mu, k : array_like
        Grid axes, ``k`` sorted increasing.
    gains : StaticGains or (K, kh), optional
        The other gains (those of ``vehicle`` are replaced by the grid values).
    omega : array_like, optional
        Frequency grid; default :func:`region_frequency_grid`.
    chunk_points : int
        Grid points processed at once (bounds memory: about 100 bytes per point plus
        ``48 * rows * n_omega`` bytes).
    """
    t0 = time.perf_counter()
    mu = np.asarray(mu, dtype=float).reshape(-1)
    k = np.asarray(k, dtype=float).reshape(-1)
    if mu.size == 0 or k.size == 0:
        raise ConfigError("grid", "mu and k axes must not be empty")
    if np.any(np.diff(k) <= 0):
        raise ConfigError("grid.k", "k axis must be strictly increasing")
    w = region_frequency_grid() if omega is None else np.asarray(omega, dtype=float)
    if w.size == 0 or np.any(w <= 0) or not np.all(np.isfinite(w)):
        raise ConfigError("omega", "frequency grid must be finite, positive and non-empty")
    n0, n1, n2, d0, d1, d2 = affine_polynomials(model, vehicle, gains)
    rho = (1.0 - PEAK_TOL) ** 2
    s = 1j * w
    vN0, vN1, vN2 = (_polyval_asc(p, s) for p in (n0, n1, n2))
    vD0, vD1, vD2 = (_polyval_asc(p, s) for p in (d0, d1, d2))
    C_row = np.abs(vN2) ** 2 - rho * np.abs(vD2) ** 2  # independent of mu

    den_fixed = not (np.any(d1) or np.any(d2))
    stable_const = bool(hurwitz(d0[::-1])) if den_fixed else None

    labels = np.empty((mu.size, k.size), dtype=np.int8)
    rows_per_chunk = max(1, min(mu.size, chunk_points // k.size))
    for r0 in range(0, mu.size, rows_per_chunk):
        mr = mu[r0 : r0 + rows_per_chunk]
        # plant stability: Routh-Hurwitz on den(mu, k)
        if den_fixed:
            stable = np.full((mr.size, k.size), stable_const)
        else:
            den = (
                d0[None, None, :]
                + mr[:, None, None] * d1[None, None, :]
                + k[None, :, None] * d2[None, None, :]
            )
            stable = hurwitz(den[..., ::-1])
        # low-frequency curvature: |p(jw)|^2 = p0^2 + (p1^2 - 2 p0 p2) w^2 + ...
        a_num = _curvature_term(n0, n1, n2, mr, k)
        a_den = _curvature_term(d0, d1, d2, mr, k)
        scale = np.abs(a_num) + np.abs(a_den)
        with np.errstate(divide="ignore", invalid="ignore"):
            crel = np.where(scale > 0, (a_num - a_den) / scale, 0.0)
        low_ok = crel < -LOW_FREQ_TOL
        # w > 0: |num|^2 - rho |den|^2 = A + B k + C k^2 for each (row, w)
        Nm = vN0[None, :] + mr[:, None] * vN1[None, :]
        Dm = vD0[None, :] + mr[:, None] * vD1[None, :]
        A = np.abs(Nm) ** 2 - rho * np.abs(Dm) ** 2
        B = 2.0 * ((Nm * np.conj(vN2)).real - rho * (Dm * np.conj(vD2)).real)
        C = np.broadcast_to(C_row, A.shape)
        violated = _mark_intervals(k, A, B, C)
        lab = np.where(stable, STABLE, UNSTABLE).astype(np.int8)
        lab[stable & low_ok & ~violated] = STRING_STABLE
        labels[r0 : r0 + mr.size] = lab
    fixed = {}
    if isinstance(gains, StaticGains):
        fixed = {
            n: v
            for n, v in gains.gains.items()
            if n not in (f"s_{vehicle}", f"v_{vehicle}") and v != 0.0
        }
    return RegionMap(
        name=name or f"vehicle_{vehicle}",
        vehicle=int(vehicle),
        mu=mu,
        k=k,
        labels=labels,
        fixed=fixed,
        n_omega=int(w.size),
        seconds=time.perf_counter() - t0,
    )


def region_fractions(maps: Mapping[str, RegionMap]) -> dict[str, dict[str, float]]:
    """``{name: {"plant_stable": f, "string_stable": f}}`` for a set of maps."""
    return {
        n: {"plant_stable": m.plant_stable_fraction, "string_stable": m.string_stable_fraction}
        for n, m in maps.items()
    }


# --------------------------------------------------------------------------------------------
# Problem files: [regions] and [maps.NAME]
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RegionSpec:
    """One ``[maps.NAME]`` table: which vehicle's gains vary, the fixed gains, the grid."""

    name: str
    vehicle: int
    mu: np.ndarray
    k: np.ndarray
    gains: StaticGains
    baseline: str | None = None
    title: str = ""


_REGION_KEYS = [
    "mu", "k", "step", "omega_min", "omega_max", "per_decade", "dense_min", "dense_max",
    "dense_per_decade",
]


def region_specs_from(
    data: Mapping, model: LCCModel, source: str | None = None, step: float | None = None
) -> tuple[dict[str, RegionSpec], np.ndarray]:
    """Parse ``[regions]`` (grid and frequency defaults) and ``[maps.NAME]`` tables.

    ``step`` (e.g. from the command line) overrides every grid step. Returns the specs in file
    order and the frequency grid. Errors name the dotted field and the file.
    """
    from lcc_synth.problem import (
        check_keys,
        get_int,
        get_number,
        get_number_list,
        get_str,
        get_table,
    )

    try:
        if model.kind == "fd_lcc":
            raise ConfigError(
                "system.kind", "region maps need a head vehicle (lcc, cf_lcc or ccc), not fd_lcc"
            )
        opts = get_table(data, "regions", "regions")
        check_keys(opts, _REGION_KEYS, "regions")
        d_step = get_number(opts, "step", "regions", 0.02, lo=0.0, lo_open=True)
        d_mu = get_number_list(opts, "mu", "regions", [-10.0, 10.0], length=2)
        d_k = get_number_list(opts, "k", "regions", [-10.0, 10.0], length=2)
        step_field = "--step" if step is not None else "regions.step"
        d_step_used = step if step is not None else d_step
        mu_default = grid_axis(*d_mu, d_step_used, "regions.mu", step_field)
        k_default = grid_axis(*d_k, d_step_used, "regions.k", step_field)
        w_lo = get_number(opts, "omega_min", "regions", 1e-3, lo=0.0, lo_open=True)
        w_hi = get_number(opts, "omega_max", "regions", 1e2, lo=w_lo, lo_open=True)
        per_dec = get_int(opts, "per_decade", "regions", DEFAULT_PER_DECADE, lo=10, hi=100_000)
        dn_lo = get_number(opts, "dense_min", "regions", 0.03, lo=0.0, lo_open=True)
        dn_hi = get_number(opts, "dense_max", "regions", 10.0, lo=dn_lo, lo_open=True)
        dn_per = get_int(
            opts, "dense_per_decade", "regions", DEFAULT_DENSE_PER_DECADE, lo=0, hi=100_000
        )
        omega = region_frequency_grid(w_lo, w_hi, per_dec, (dn_lo, dn_hi), dn_per)

        maps = get_table(data, "maps", "maps", required=True)
        if not maps:
            raise ConfigError("maps", "needs at least one [maps.NAME] table")
        allowed_vehicles = [i for i in model.vehicles if i != 0]
        specs: dict[str, RegionSpec] = {}
        for name, t in maps.items():
            field = f"maps.{name}"
            if not isinstance(t, dict):
                raise ConfigError(field, f"must be a table, got {t!r}")
            check_keys(
                t, ["vehicle", "gains", "semantics", "baseline", "title", "mu", "k", "step"], field
            )
            vehicle = get_int(t, "vehicle", field)
            if vehicle not in allowed_vehicles:
                raise ConfigError(
                    f"{field}.vehicle",
                    f"must be one of {allowed_vehicles} (an HDV of this m={model.m}, "
                    f"n={model.n} system), got {vehicle}",
                )
            semantics = get_str(t, "semantics", field, "added", choices=["added", "replace"])
            raw = get_table(t, "gains", f"{field}.gains")
            try:
                gains = StaticGains(raw, semantics)
                gains.check(model)
            except ConfigError as err:
                raise ConfigError(f"{field}.{err.field}", err.message) from None
            for own in (f"s_{vehicle}", f"v_{vehicle}"):
                if own in gains.gains:
                    raise ConfigError(
                        f"{field}.gains.{own}", "is the map's own axis; remove it from gains"
                    )
            if any(key in t for key in ("mu", "k", "step")):
                st = step if step is not None else get_number(
                    t, "step", field, d_step, lo=0.0, lo_open=True
                )
                sf = step_field if step is not None else f"{field}.step"
                lo_hi = get_number_list(t, "mu", field, d_mu, length=2)
                mu = grid_axis(*lo_hi, st, f"{field}.mu", sf)
                lo_hi = get_number_list(t, "k", field, d_k, length=2)
                k = grid_axis(*lo_hi, st, f"{field}.k", sf)
            else:
                mu, k = mu_default, k_default
            baseline = get_str(t, "baseline", field, None) if "baseline" in t else None
            title = get_str(t, "title", field, name)
            specs[name] = RegionSpec(name, vehicle, mu, k, gains, baseline, title)
        for name, spec in specs.items():
            if spec.baseline is None:
                continue
            base = specs.get(spec.baseline)
            if base is None:
                raise ConfigError(
                    f"maps.{name}.baseline", f"names no map; maps: {sorted(specs)}"
                )
            if (
                base.vehicle != spec.vehicle
                or base.mu.shape != spec.mu.shape
                or base.k.shape != spec.k.shape
                or not np.allclose(base.mu, spec.mu)
                or not np.allclose(base.k, spec.k)
            ):
                raise ConfigError(
                    f"maps.{name}.baseline",
                    f"map {spec.baseline!r} must have the same vehicle and grid",
                )
        return specs, omega
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None


def run_region_specs(
    model: LCCModel, specs: Mapping[str, RegionSpec], omega: np.ndarray | None = None
) -> dict[str, RegionMap]:
    """Compute every map of :func:`region_specs_from`."""
    return {
        name: region_map(model, s.vehicle, s.mu, s.k, gains=s.gains, omega=omega, name=name)
        for name, s in specs.items()
    }


def expansion(rm: RegionMap, baseline: RegionMap) -> dict[str, float | bool]:
    """How ``rm`` changes the string-stable set of ``baseline`` (same grid): fraction gained,
    fraction lost and whether the baseline region is kept entirely (Fig. 7(c)-(f))."""
    a = baseline.labels == STRING_STABLE
    b = rm.labels == STRING_STABLE
    return {
        "gained_fraction": float(np.count_nonzero(b & ~a)) / a.size,
        "lost_fraction": float(np.count_nonzero(a & ~b)) / a.size,
        "contains_baseline": bool(not np.any(a & ~b)),
    }
