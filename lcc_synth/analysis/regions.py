"""Head-to-tail string-stable regions of one vehicle's gains (Figs. 7-8), vectorised.

Over a grid of ``(mu_i, k_i)`` for one vehicle ``i``, all other gains fixed, every point is
classified as

``0`` unstable            the closed loop has an eigenvalue with ``Re >= 0``;
``1`` stable              plant stable, not head-to-tail string stable (or undecided, below);
``2`` string stable       plant stable and ``|Gamma(jw)| < Gamma(0) = 1`` for all ``w > 0``.

Decision function
-----------------
``Gamma = num/den`` (:func:`lcc_synth.analysis.transfer.gamma_polynomials`, ``den`` the closed-loop
characteristic polynomial) with ``num`` and ``den`` *affine* in ``(mu_i, k_i)``: ``num = N0 +
mu N1 + k N2``, ``den = D0 + mu D1 + k D2`` (:func:`affine_polynomials`). Every ``h_i(0) = 0``,
so ``num(0) = den(0)`` and neither depends on the map's gains (``N1, N2, D1, D2`` vanish at
``s = 0`` exactly; ``g0 = num(0)/den(0)`` is 1 up to an ulp). With ``x = w^2`` and
``p(jw) = p(0) + x e_p(x) + j w o_p(x)``,

    Ptilde(x) = (|num(jw)|^2 - g0^2 |den(jw)|^2) / x,
    (|p(jw)|^2 - p(0)^2) / x = 2 p(0) e_p + x e_p^2 + o_p^2,

i.e. the ``x^0`` coefficient (the exact double zero of ``|Gamma|^2 - g0^2`` at ``w = 0``) is
removed structurally, never by subtracting two nearly equal floats. ``Ptilde(0)`` is the
curvature numerator (``|Gamma|^2 = g0^2 + c w^2 + O(w^4)``, ``c = Ptilde(0) / den(0)^2``) and at
``w > 0`` ``Ptilde`` has the sign of ``|Gamma(jw)|^2 - g0^2``. String stable means plant stable
and ``Ptilde(x) < 0`` for every ``x >= 0``: the definition of
:mod:`lcc_synth.analysis.string_stability` (``Q = Ptilde / |den|^2``). ``x = 0`` is checked exactly,
so the low end of the frequency grid does not matter: lowering ``omega_min`` from 1e-3 to
1e-4 moved 5-30 labels per 121 x 121 paper map before (each to the wrong side: ``|Gamma|``
was compared with ``1 - 1e-9`` at the lowest grid frequency), 0 now.

Why it is fast: for a fixed row ``mu`` and frequency ``x``, ``Ptilde`` is a *quadratic in k*,
``A + B k + C k^2`` with ``A = a0 + mu a1 + mu^2 a2``, ``B = b0 + mu b1``, ``C = c0`` (vectors
over ``x``, computed once per map). Its non-negative set is at most two intervals of ``k``,
found in closed form; marking them on the ``k`` axis (``searchsorted``, a difference array and
one cumulative sum) flags every grid point at that ``x``. The work is ``O(n_mu * n_omega)``
closed-form roots plus ``O(n_mu * n_k)``, instead of ``O(n_mu * n_k * n_omega)``
evaluations, so the frequency grid can be dense. Plant stability: a vectorised Routh-Hurwitz
test on the coefficients of ``den`` (exact sign test, no eigenvalues).

Tolerance band
--------------
``S = SA + SB |k| + SC k^2`` is the sum of the absolute values of the terms of the evaluation
(the same formulas on ``|coefficients|``, ``|mu|``, ``|k|``; ``x >= 0``), the scale of its
rounding error. The decision uses the quadratic upper bound
``S <= (SA + SB/2) + (SC + SB/2) k^2`` (so the band edges stay quadratics in ``k``) and

    tau = BAND_SAFETY * (2 deg + 16) * eps      (:func:`region_band`, BAND_SAFETY = 16),

``deg`` the degree of ``den`` (``2 (m + n + 1)``): ``(2 deg + 16) eps`` bounds the roundings on
the longest path (products of the quadratic factors, the affine slopes, Horner in ``x`` of
degree ``deg/2``, the bilinear form, the ``mu``/``k`` combination), and the safety factor
covers what a count of roundings does not. For the paper's ``m = n = 2``: ``tau = 576 eps =
1.3e-13``. Measured against an exact rational reference (``tests/test_regions.py``: 1,536
evaluations on the paper's maps plus heterogeneous, CF-LCC and string-aware-design cases, at
``x = 0`` and random grid frequencies) the error of ``Ptilde`` is at most ``2.8 eps * S``,
i.e. 1/13 of the bound and 1/200 of ``tau``. A point with ``Ptilde > tau * S`` at some grid
frequency is not string stable (label 1); with ``Ptilde < -tau * S`` at every frequency it
is string stable (2); otherwise it is on the boundary: :attr:`RegionMap.boundary` is set and
the label is the conservative 1, so figures and fractions stay comparable. On the paper's
maps (Figs. 7-8, 1001 x 1001) no grid point is inside the band.

Frequency grid (:func:`region_frequency_grid`): ``x = 0`` plus a logarithmic grid,
``DEFAULT_PER_DECADE`` = 200 points per decade on ``[1e-3, 1e2]`` rad/s plus
``DEFAULT_DENSE_PER_DECADE`` = 3000 per decade on ``[0.03, 10]`` rad/s, where the resonance
peaks of the paper's maps lie (sampled peaks at 0.12-1.9 rad/s; closed-loop poles up to ~5
rad/s). Relative spacing in the dense band: 0.08 %. The grid is exact in the direction
"unstable": a flagged point has a witness frequency with ``Ptilde > tau * S``. A point whose
exceedance band is narrower than the grid spacing (only possible next to the
plant-stability boundary, for a pole with damping ratio below ~1e-3) could be reported string
stable. Below ``omega_min``, ``Ptilde`` is linear in ``x`` to ``O(x^2)``, so its sign there is
that of the end points ``x = 0`` and ``x = omega_min^2``, both checked. The tests compare the
map with the per-point verdict (:func:`~lcc_synth.analysis.string_stability.string_stability`) on
random and label-boundary grid points: on the eight full paper maps, 3,200 of 3,200 agree
(150 random and 250 boundary-adjacent points per map, none in either band).

Cost (``python benchmarks/bench_regions.py``): 0.6-1.2 s per 1,002,001-point map with 8,570
frequencies (best of 3, on a shared 2-core machine; the previous single-threshold version
took 0.8-1.9 s in the same runs). Two interval markings per frequency (the band's edges)
instead of one, but the chunks are now 20,000 points, so the working arrays stay in cache.

Open platoons
-------------
On an open platoon (``kind = "platoon"``, several CAVs behind a head vehicle) the map varies
the gains ``(mu_i, k_i)`` of one CAV ``c`` on one HDV ``i`` of its segment, every other gain
fixed. When no CAV's gain crosses into another CAV's segment, the closed loop is a cascade of
segments, each driven only by the velocity of the vehicle ahead of it, and

    Gamma = prod_j num_j / den_j,    den = prod_j den_j (the closed-loop characteristic
                                     polynomial: A_cl is block triangular by segments),

each factor the paper's one-CAV ``Gamma`` of its segment (:func:`gamma_polynomials` with the
segment's own coefficients; vehicles indexed from its CAV, the segment's input the velocity
ahead of it: the head's, or the predecessor's as ``kh`` when the CAV leads its segment).
Only the varied CAV's factor depends on ``(mu, k)``, affinely, so its three affine parts times
the fixed product of the other factors are the map's ``N0..D2``, still affine, still with
``N1(0) = N2(0) = D1(0) = D2(0) = 0`` exactly, and the decision, the band (``deg = 2 N``) and
the cost above apply unchanged. :func:`platoon_segments` places the cuts: CAV ``c``'s stretch
is ``c`` with every vehicle its added gain hears (the map's vehicle included; its
predecessor's velocity alone is the segment's input); stretches of neighbouring CAVs must not
meet, else the gain that crosses is a ConfigError naming it (``gains.u_c.STATE``), and a map
vehicle that another CAV hears names ``vehicle``. The map's vehicle is an HDV between the
CAV's neighbouring CAVs (the first CAV's segment starts at vehicle 1, the last one's ends at
the tail); a ring has no head vehicle (ConfigError ``system.kind``). The one-CAV platoon
(``cavs = [m + 1]``) gives the map of ``kind = "lcc"`` with the same ``m, n`` bit for bit
(the same per-vehicle polynomials; ``tests/test_regions_platoon.py``).

Measured on 7 OVM vehicles with CAVs at 2 and 5 (``tests/test_regions_platoon.py`` and a
one-off check): 1,600 of 1,600 grid points agree with the closed loop built from ``A, B, H``
(eigenvalues, the per-point verdict of the state space and ``|Gamma(jw)|`` on a dense grid;
four 201 x 201 maps, 150 random and 250 boundary-adjacent points each, none in either band);
the rounding error of ``Ptilde`` against exact rationals is at most 0.35 eps ``S`` (bound 44
eps, ``tau = 1.6e-13``). Cost (``python benchmarks/bench_regions.py``): 1.3-3.5 s per
1,002,001-point map with 8,570 frequencies on the shared 2-core machine (the paper's maps:
1.1-2.5 s in the same run).

Changes against the previous version on the full paper maps: 118 of 8 x 1,002,001 labels,
all from "stable" to "string stable" (Fig. 7(a): 24, i.e. 4.94 % -> 4.95 % string stable;
the other fractions move in the third decimal or less); every one of them is string stable by
the per-point verdict (curvature about -1e-3, margin ~4e-5): the old test at the lowest grid
frequency, ``|Gamma|^2 >= (1 - 1e-9)^2``, flagged every gain with ``|c| < ~2e-9 / omega_min^2``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from lcc_synth.analysis.transfer import closed_form_gains, gamma_polynomials
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains, input_feedback
from lcc_synth.models.linear import LCCModel
from lcc_synth.models.platoon import hdv_law_rows
from lcc_synth.models.records import Record

__all__ = [
    "UNSTABLE",
    "STABLE",
    "STRING_STABLE",
    "DEFAULT_PER_DECADE",
    "DEFAULT_DENSE_PER_DECADE",
    "BAND_SAFETY",
    "RegionMap",
    "region_band",
    "region_frequency_grid",
    "affine_polynomials",
    "platoon_segments",
    "hurwitz",
    "region_map",
    "region_fractions",
]

UNSTABLE, STABLE, STRING_STABLE = 0, 1, 2
DEFAULT_PER_DECADE = 200
DEFAULT_DENSE_PER_DECADE = 3000
BAND_SAFETY = 16
_AFFINE_STEP = 1024.0
_LABEL_NAMES = {UNSTABLE: "unstable", STABLE: "stable", STRING_STABLE: "string_stable"}


@dataclass(frozen=True, repr=False)
class RegionMap(Record):
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
        Size of the frequency grid used (``w > 0``; ``w = 0`` is checked in addition).
    seconds : float
        Wall time of the computation.
    boundary : numpy.ndarray
        ``(n_mu, n_k)`` bool: plant-stable points whose string-stability decision lies inside
        the rounding band (``|Ptilde| <= band * S`` at the deciding frequency, no frequency
        with ``Ptilde > band * S``). They carry the conservative label :data:`STABLE`.
    band : float
        The relative tolerance ``tau`` used (:func:`region_band`).
    cav : int or None
        An open platoon's map: the position of the CAV whose gains vary (``vehicle`` and
        ``fixed``, ``"u_3.s_1"``, in the platoon's positions); ``None`` for one CAV.
    """

    name: str
    vehicle: int
    mu: np.ndarray
    k: np.ndarray
    labels: np.ndarray
    fixed: dict = field(default_factory=dict)
    n_omega: int = 0
    seconds: float = 0.0
    boundary: np.ndarray | None = None
    band: float = 0.0
    cav: int | None = None

    def __post_init__(self):
        if self.boundary is None:
            object.__setattr__(self, "boundary", np.zeros(self.labels.shape, dtype=bool))

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
            "boundary_points": int(np.count_nonzero(self.boundary)),
            "boundary_fraction": float(np.count_nonzero(self.boundary)) / self.labels.size,
            "band": self.band,
            "n_omega": self.n_omega,
            "seconds": self.seconds,
            "labels_legend": {str(k): v for k, v in _LABEL_NAMES.items()},
        }
        if self.cav is not None:
            out["cav"] = self.cav
        if include_labels:
            out["labels"] = self.labels.tolist()
            out["boundary"] = np.argwhere(self.boundary).tolist()
        return out


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
        gains = Gains.named({})
    if isinstance(gains, Gains):
        K, kh = input_feedback(model, gains)
    else:
        K, kh = gains
    return closed_form_gains(model, K, kh)


def affine_polynomials(model: LCCModel, vehicle: int, gains=None, cav: int | None = None):
    """``(N0, N1, N2, D0, D1, D2)``: ``num = N0 + mu N1 + k N2``, ``den = D0 + mu D1 + k D2``
    for the gains ``(mu, k)`` of ``vehicle``, the other gains from ``gains``.

    Coefficients are in *ascending* powers, all padded to the degree of ``den``.
    ``gains`` is a :class:`~lcc_synth.models.feedback.Gains` or input feedback ``(K, kh)``.
    On an open platoon (``model.kind == "platoon"``) ``cav`` is the CAV position whose gains
    on ``vehicle`` vary (default: the only CAV) and the polynomials are the segment product
    of :func:`platoon_segments` (see the module docstring).
    """
    if getattr(model, "kind", None) in ("platoon", "ring"):
        return _platoon_affine(model, vehicle, gains, cav)
    if cav is not None:
        raise ConfigError("cav", f"is for a platoon; this {model.kind} model has one CAV (0)")
    if tuple(model.cavs) != (0,):
        raise ConfigError(
            "model", "region maps (Figs. 7-8) vary the paper's gains mu_i, k_i of one CAV on "
            "HDV i: give a one-CAV model with a head vehicle (kind lcc, cf_lcc or ccc), got "
            f"kind = {model.kind!r} with CAVs at {list(model.cavs)}",
        )
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

    # affine: the slopes from a power-of-two step t (exact division), so the rounding of the
    # base polynomial leaks into a slope only as eps |N0| / t
    t = _AFFINE_STEP
    (n0, d0), (n1, d1), (n2, d2) = polys(0.0, 0.0), polys(t, 0.0), polys(0.0, t)
    return n0, (n1 - n0) / t, (n2 - n0) / t, d0, (d1 - d0) / t, (d2 - d0) / t


def _platoon_feedback(model, gains) -> tuple[np.ndarray, np.ndarray]:
    """``(K_add, kh_add)``: each CAV's command on a platoon (one row per CAV) minus its HDV law
    (:func:`~lcc_synth.models.platoon.hdv_law_rows`, and ``a3 v_h`` for a CAV at position 1):
    the gains *added* to the HDV law, whatever the semantics of ``gains``."""
    if gains is None:
        gains = Gains.zero(model)
    if isinstance(gains, Gains):
        gains.check(model)
        K, kh = gains.input_feedback(model)
    else:
        K, kh = gains
    K = np.atleast_2d(np.asarray(K, dtype=float))
    kh = np.asarray(kh, dtype=float).reshape(-1)
    if K.shape != (len(model.cavs), model.nx) or kh.shape != (len(model.cavs),):
        raise ConfigError(
            "gains", f"need one row of {model.nx} entries and one head gain per CAV "
            f"{list(model.cavs)}, got K of shape {K.shape} and {kh.size} head gains",
        )
    kh0 = np.array([model.coefficients[0].alpha3 if c == 1 else 0.0 for c in model.cavs])
    return K - hdv_law_rows(model), kh - kh0


def _heard(model, row: np.ndarray, c: int) -> dict[int, str]:
    """``{position: state}`` of the vehicles CAV ``c``'s added gain row hears (the first state
    name with a non-zero gain), its predecessor left out when only its velocity is heard."""
    out = {}
    for p in model.vehicles:
        s, v = row[model.index(f"s_{p}")], row[model.index(f"v_{p}")]
        if s != 0.0 or v != 0.0:
            out[p] = f"s_{p}" if s != 0.0 else f"v_{p}"
    if out.get(c - 1) == f"v_{c - 1}":
        del out[c - 1]  # the predecessor's velocity: the segment's input
    return out


def platoon_segments(
    model, gains=None, cav: int | None = None, vehicle: int | None = None
) -> list[tuple[int, int, int]]:
    """``[(cav, first, last), ...]``: the segments of an open platoon in which ``Gamma``
    factors, front to tail, one per CAV (see the module docstring).

    Each CAV's stretch is the CAV with every vehicle its added gain hears (``vehicle`` too for
    the CAV ``cav`` of a map; its predecessor's velocity alone is the segment's input, not a
    vehicle of it); segment ``j`` starts at the first vehicle of its stretch (the first
    segment at 1) and ends before the next one. Errors (:class:`ConfigError`) name the field:
    ``system.kind`` (a ring: no head vehicle), ``system.cavs`` (no CAV), ``cav``, ``vehicle``
    (not an HDV between the neighbouring CAVs, or one another CAV hears) and
    ``gains.u_c.STATE`` (a gain that crosses into another CAV's stretch: no factorisation).
    """
    if model.ring:
        raise ConfigError(
            "system.kind", "a ring has no head vehicle: the head-to-tail Gamma of a region map "
            "is undefined; give an open platoon (kind = 'platoon')",
        )
    cavs = list(model.cavs)
    if not cavs:
        raise ConfigError("system.cavs", "a region map varies a CAV's gains: give a CAV")
    K_add, kh_add = _platoon_feedback(model, gains)
    if vehicle is not None:
        if cav is None and len(cavs) == 1:
            cav = cavs[0]
        if cav not in cavs:
            raise ConfigError("cav", f"must be the position of the CAV whose gains vary, one of "
                              f"{cavs}, got {cav!r}")  # fmt: skip
        r = cavs.index(cav)
        lo = cavs[r - 1] + 1 if r > 0 else 1
        hi = cavs[r + 1] - 1 if r + 1 < len(cavs) else model.platoon.size
        allowed = [p for p in range(lo, hi + 1) if p != cav]
        if vehicle not in allowed:
            raise ConfigError(
                "vehicle", f"must be an HDV of CAV {cav}'s segment (between the neighbouring "
                f"CAVs), one of {allowed}, got {vehicle!r}",
            )
    stretches = []  # (first, last) heard, the map's vehicle included, and without it
    for r, c in enumerate(cavs):
        heard = _heard(model, K_add[r], c)
        if kh_add[r] != 0.0 and c != 1:
            raise ConfigError(f"gains.u_{c}", "hears the head vehicle's velocity v_h: Gamma "
                              "does not factor per segment")  # fmt: skip
        own = sorted({c, *heard})
        full = sorted({c, vehicle, *heard}) if c == cav else own
        stretches.append(((full[0], full[-1]), (own[0], own[-1]), heard))
    for r in range(1, len(cavs)):
        ((_, hi_prev), (_, own_hi_prev), heard_prev) = stretches[r - 1]
        ((lo, hi), (own_lo, _), heard) = stretches[r]
        if hi_prev < lo:
            continue
        prev, c = cavs[r - 1], cavs[r]
        if own_hi_prev < own_lo:  # only the map's vehicle makes the stretches meet
            other, span = (c, (lo, hi)) if cav == prev else (prev, stretches[r - 1][0])
            raise ConfigError("vehicle", f"{vehicle} is in CAV {other}'s segment (CAV {other} "
                              f"hears vehicles {span[0]}..{span[1]}): Gamma does not factor "
                              "per segment")  # fmt: skip
        if own_lo <= prev or own_hi_prev < c:  # CAV c hears at or ahead of the previous CAV
            raise ConfigError(f"gains.u_{c}.{heard[own_lo]}", f"crosses into CAV {prev}'s "
                              f"segment (CAV {prev} hears up to vehicle {own_hi_prev}): Gamma "
                              "does not factor per segment")  # fmt: skip
        raise ConfigError(f"gains.u_{prev}.{heard_prev[own_hi_prev]}", f"crosses into CAV {c}'s"
                          f" segment (CAV {c} hears from vehicle {own_lo}): Gamma does not "
                          "factor per segment")  # fmt: skip
    firsts = [1] + [full[0] for full, _, _ in stretches[1:]]
    lasts = [f - 1 for f in firsts[1:]] + [model.platoon.size]
    return list(zip(cavs, firsts, lasts, strict=True))


def _segment_gains(model, K_add, kh_add, r: int, segment: tuple[int, int, int]):
    """The paper's one-CAV view of a platoon segment ``(cav, first, last)``: ``(coefs, mu, k,
    m, n, kh)`` for :func:`~lcc_synth.analysis.transfer.gamma_polynomials`, vehicles indexed
    from the CAV, the segment's input (``kh``, with ``m = 0``) the predecessor's velocity."""
    c, first, last = segment
    idx = range(first, last + 1)
    coefs = {i - c: model.coefficients[i - 1] for i in idx}
    mu = {i - c: float(K_add[r, model.index(f"s_{i}")]) for i in idx}
    kk = {i - c: float(K_add[r, model.index(f"v_{i}")]) for i in idx}
    kh = 0.0
    if first == c:
        kh = float(kh_add[r]) if c == 1 else float(K_add[r, model.index(f"v_{c - 1}")])
    return coefs, mu, kk, c - first, last - c, kh


def _platoon_affine(model, vehicle: int, gains, cav: int | None):
    """:func:`affine_polynomials` of an open platoon: the varied CAV's segment affine in its
    gains on ``vehicle``, times the fixed numerators / denominators of the other segments."""
    segments = platoon_segments(model, gains, cav, vehicle)
    K_add, kh_add = _platoon_feedback(model, gains)
    cav = cav if cav is not None else model.cavs[0]
    other_num, other_den = np.array([1.0]), np.array([1.0])
    for r, seg in enumerate(segments):
        if seg[0] == cav:
            varied = r
            continue
        num, den = gamma_polynomials(*_segment_gains(model, K_add, kh_add, r, seg))
        other_num, other_den = np.polymul(other_num, num), np.polymul(other_den, den)
    coefs, mu, kk, m, n, kh = _segment_gains(model, K_add, kh_add, varied, segments[varied])
    i = vehicle - cav
    deg_seg = 2 * (m + n + 1)

    def polys(a, b):
        m2, k2 = dict(mu), dict(kk)
        m2[i], k2[i] = a, b
        out = []
        for p in gamma_polynomials(coefs, m2, k2, m, n, kh):
            asc = np.zeros(deg_seg + 1)
            asc[: len(p)] = p[::-1]
            out.append(asc)
        return out

    t = _AFFINE_STEP  # as in affine_polynomials: exact division, slopes before the product
    (n0, d0), (n1, d1), (n2, d2) = polys(0.0, 0.0), polys(t, 0.0), polys(0.0, t)
    parts = (n0, (n1 - n0) / t, (n2 - n0) / t, d0, (d1 - d0) / t, (d2 - d0) / t)
    deg = 2 * len(model.vehicles)
    out = []
    for j, p in enumerate(parts):
        prod = np.convolve(p, (other_num if j < 3 else other_den)[::-1])
        asc = np.zeros(deg + 1)
        asc[: prod.size] = prod[: deg + 1]
        out.append(asc)
    return tuple(out)


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


def _x_parts(p: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Split a real polynomial ``p`` (ascending powers of ``s``) along the imaginary axis:
    ``p(jw) = p0 + x e(x) + j w o(x)`` with ``x = w^2``; returns ``(p0, e, o)``, ``e`` and
    ``o`` in ascending powers of ``x``. Exact (signs and a reshuffle of the coefficients)."""
    p = np.asarray(p, dtype=float)
    even = p[0::2] * (-1.0) ** np.arange(p[0::2].size)
    odd = p[1::2] * (-1.0) ** np.arange(p[1::2].size)
    return float(p[0]), even[1:], odd


def _horner(c: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``sum_i c[i] x^i`` by Horner's rule (``c`` ascending)."""
    out = np.zeros_like(x)
    for coef in c[::-1]:
        out = out * x + coef
    return out


def _spectra(p: np.ndarray, x: np.ndarray, absolute: bool = False):
    """``(p0, e(x), o(x))`` of :func:`_x_parts` on ``x >= 0``; with ``absolute`` every
    coefficient in absolute value (the sums of the absolute values of the terms)."""
    p0, e, o = _x_parts(p)
    if absolute:
        return abs(p0), _horner(np.abs(e), x), _horner(np.abs(o), x)
    return p0, _horner(e, x), _horner(o, x)


def _beta(p, q, x):
    """``(Re(p(jw) conj q(jw)) - p(0) q(0)) / w^2 = p0 e_q + q0 e_p + x e_p e_q + o_p o_q``
    for spectra ``p, q`` of :func:`_spectra`: the bilinear form behind ``(|p(jw)|^2 -
    p(0)^2) / w^2`` with the ``x^0`` term removed structurally (valid at ``x = 0``). On
    absolute spectra it is the sum of the absolute values of the terms."""
    (p0, pe, po), (q0, qe, qo) = p, q
    return p0 * qe + q0 * pe + x * pe * qe + po * qo


@dataclass(frozen=True)
class _MapQuadratics:
    """The decision function of one map on the frequency grid ``x = w^2`` (``x[0] = 0``),
    as polynomials in the row gain ``mu`` and the column gain ``k``:

        Ptilde(x) = (|num(jw)|^2 - g0^2 |den(jw)|^2) / x = A + B k + C k^2,
        A = a0 + mu a1 + mu^2 a2,   B = b0 + mu b1,   C = c0,

    ``g0 = num(0) / den(0)`` (both independent of ``(mu, k)``: ``h_i(0) = 0``), the ``x^0``
    coefficient ``num(0)^2 - g0^2 den(0)^2 = 0`` removed structurally. ``Ptilde(0)`` is the
    curvature numerator (``c = Ptilde(0) / den(0)^2``) and at ``w > 0`` ``Ptilde`` has the
    sign of ``|Gamma(jw)|^2 - g0^2``. ``sa*, sb*, sc0``: the same with every term in absolute
    value (``|mu|`` for ``mu``), so ``S = SA + SB |k| + SC k^2`` bounds the rounding of the
    evaluation."""

    a: tuple
    b: tuple
    c0: np.ndarray
    sa: tuple
    sb: tuple
    sc0: np.ndarray

    def rows(self, mr: np.ndarray):
        """``(A, B, C, SA, SB, SC)`` on rows ``mu = mr`` (axis 0) and ``x`` (axis 1)."""
        m = mr[:, None]
        am = np.abs(m)
        a0, a1, a2 = self.a
        s0, s1, s2 = self.sa
        A = a0 + m * (a1 + m * a2)
        B = self.b[0] + m * self.b[1]
        SA = s0 + am * (s1 + am * s2)
        SB = self.sb[0] + am * self.sb[1]
        shape = A.shape
        return (
            A, B, np.broadcast_to(self.c0, shape), SA, SB, np.broadcast_to(self.sc0, shape)
        )


def _map_quadratics(polys, x: np.ndarray) -> _MapQuadratics:
    n0, n1, n2, d0, d1, d2 = polys
    if n1[0] != 0.0 or n2[0] != 0.0 or d1[0] != 0.0 or d2[0] != 0.0:
        raise ValueError("num(0) and den(0) must not depend on the map's gains (h_i(0) = 0)")
    g2 = (n0[0] / d0[0]) ** 2 if d0[0] != 0.0 else 1.0  # den(0) = 0: unstable anyway
    N0, N1, N2, D0, D1, D2 = (_spectra(p, x) for p in polys)
    aN0, aN1, aN2, aD0, aD1, aD2 = (_spectra(p, x, absolute=True) for p in polys)

    def diff(p, q, P, Q):
        return _beta(p, q, x) - g2 * _beta(P, Q, x)

    def total(p, q, P, Q):
        return _beta(p, q, x) + g2 * _beta(P, Q, x)

    return _MapQuadratics(
        a=(diff(N0, N0, D0, D0), 2.0 * diff(N0, N1, D0, D1), diff(N1, N1, D1, D1)),
        b=(2.0 * diff(N0, N2, D0, D2), 2.0 * diff(N1, N2, D1, D2)),
        c0=diff(N2, N2, D2, D2),
        sa=(total(aN0, aN0, aD0, aD0), 2.0 * total(aN0, aN1, aD0, aD1),
            total(aN1, aN1, aD1, aD1)),
        sb=(2.0 * total(aN0, aN2, aD0, aD2), 2.0 * total(aN1, aN2, aD1, aD2)),
        sc0=total(aN2, aN2, aD2, aD2),
    )


def _row_quadratics(polys, mr: np.ndarray, x: np.ndarray):
    """``(A, B, C, SA, SB, SC)`` of :class:`_MapQuadratics` on rows ``mr`` and ``x``."""
    return _map_quadratics(polys, np.asarray(x, dtype=float)).rows(
        np.asarray(mr, dtype=float).reshape(-1)
    )


def _intervals(k: np.ndarray, A, B, C, nonfinite_all: bool = False):
    """Index ranges ``[start, stop)`` of the sorted ``k`` grid where ``A + B k + C k^2 >= 0``,
    at most two per entry: ``(s1, e1, s2, e2)`` (``e <= s``: empty). Closed-form roots; the
    rare entries with ``C == 0`` (a line) are patched separately. An entry with a non-finite
    coefficient (overflow) gives everything with ``nonfinite_all``, else nothing."""
    n = k.size
    inf = np.inf
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        disc = B * B - 4.0 * A * C
        has = disc >= 0.0
        q = -0.5 * (B + np.copysign(np.sqrt(np.where(has, disc, 0.0)), B))
        lo = np.fmin(q / C, A / q)
        hi = np.fmax(q / C, A / q)
    up = C > 0.0
    # C > 0: (-inf, r1] and [r2, inf) (everything without real roots); C < 0: [r1, r2]
    r1 = np.where(has, lo, inf)
    r2 = np.where(has, hi, np.where(up, inf, -inf))
    s1 = np.where(up, 0, np.searchsorted(k, np.where(up, -inf, r1), side="left"))
    e1 = np.searchsorted(k, np.where(up, r1, r2), side="right")
    s2 = np.where(up, np.searchsorted(k, np.where(up, r2, inf), side="left"), n)
    e2 = np.full(s2.shape, n)
    line = C == 0.0
    if np.any(line):  # B k + A >= 0
        a, b = A[line], B[line]
        with np.errstate(divide="ignore", invalid="ignore"):
            root = -a / b
        always = (b == 0.0) & (a >= 0.0)
        l_ = np.where(b > 0.0, root, np.where((b < 0.0) | always, -inf, inf))
        h_ = np.where(b < 0.0, root, np.where((b > 0.0) | always, inf, -inf))
        s1[line] = np.searchsorted(k, l_, side="left")
        e1[line] = np.searchsorted(k, h_, side="right")
        s2[line] = n
    bad = ~np.isfinite(disc)
    if np.any(bad):
        s1[bad], e1[bad], s2[bad] = 0, (n if nonfinite_all else 0), n
    return s1, e1, s2, e2


def _mark(nk: int, rows: int, ranges, where=None) -> np.ndarray:
    """``(rows, nk)`` bool: grid points inside any of the index ranges (axis 0 of the range
    arrays: rows); ``where`` restricts to a subset of entries."""
    row_off = (np.arange(rows) * (nk + 1))[:, None]
    diff = np.zeros(rows * (nk + 1))
    for start, stop in ranges:
        good = stop > start
        if where is not None:
            good &= where
        s = np.broadcast_to(row_off, good.shape)[good]
        diff += np.bincount(s + start[good], minlength=diff.size)
        diff -= np.bincount(s + stop[good], minlength=diff.size)
    return np.cumsum(diff.reshape(rows, nk + 1), axis=1)[:, :nk] > 0.5


def region_band(degree: int) -> float:
    """The relative tolerance ``tau`` of the map's decision for a closed loop whose
    characteristic polynomial has degree ``degree`` (see the module docstring):
    ``tau = BAND_SAFETY * (2 degree + 16) * eps``."""
    return float(BAND_SAFETY * (2 * int(degree) + 16) * np.finfo(float).eps)


def region_map(
    model: LCCModel,
    vehicle: int,
    mu: np.ndarray,
    k: np.ndarray,
    gains=None,
    omega: np.ndarray | None = None,
    name: str = "",
    chunk_points: int = 20_000,
    on_rows: Callable[[int], None] | None = None,
    cav: int | None = None,
) -> RegionMap:
    """Classify every ``(mu[a], k[b])`` for ``vehicle`` (see the module docstring).

    Parameters
    ----------
    model : LCCModel or PlatoonModel
        A model with a head vehicle: one CAV (``lcc``, ``cf_lcc``, ``ccc``) or an open platoon
        whose CAVs' gains do not cross segments (:func:`platoon_segments`).
    vehicle : int
        The HDV whose ``s_i``/``v_i`` gains vary (one CAV: ``i != 0``; a platoon: a position
        in the segment of ``cav``).
    mu, k : array_like
        Grid axes, ``k`` sorted increasing.
    gains : Gains or (K, kh), optional
        The other gains (those of ``vehicle`` are replaced by the grid values).
    omega : array_like, optional
        Frequency grid (``w > 0``); default :func:`region_frequency_grid`. ``w = 0`` (the
        curvature) is always checked in addition, exactly.
    chunk_points : int
        Grid points processed at once: ``chunk_points // n_k`` rows (at least one) at a time.
        Memory is about ``300 * rows * n_omega`` bytes; the default keeps the working arrays
        in cache (1.3 MB each on the paper's grid), which is faster than larger chunks.
    on_rows : callable, optional
        ``on_rows(rows)`` after each chunk, with the number of ``mu`` rows it classified (a
        progress bar).
    cav : int, optional
        A platoon only: the position of the CAV whose gains on ``vehicle`` vary (default: the
        platoon's only CAV).
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
    polys = affine_polynomials(model, vehicle, gains, cav)
    if cav is None and getattr(model, "kind", None) == "platoon":
        cav = model.cavs[0]
    d0, d1, d2 = polys[3:]
    tau = region_band(d0.size - 1)
    x = np.concatenate([[0.0], w * w])  # x = w^2; x = 0 is the curvature, exactly
    quad = _map_quadratics(polys, x)

    den_fixed = not (np.any(d1) or np.any(d2))
    stable_const = bool(hurwitz(d0[::-1])) if den_fixed else None

    labels = np.empty((mu.size, k.size), dtype=np.int8)
    boundary = np.zeros((mu.size, k.size), dtype=bool)
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
        # Ptilde = A + B k + C k^2 on (row, x); band tau * ((SA + SB/2) + (SC + SB/2) k^2)
        A, B, C, SA, SB, SC = quad.rows(mr)
        band_a = tau * (SA + 0.5 * SB)
        band_c = tau * (SC + 0.5 * SB)
        hard = _intervals(k, A - band_a, B, C - band_c)  # Ptilde > +band
        # Ptilde >= -band (contains hard; an overflow is undecided, i.e. boundary)
        soft = _intervals(k, A + band_a, B, C + band_c, nonfinite_all=True)
        violated = _mark(k.size, mr.size, ((hard[0], hard[1]), (hard[2], hard[3])))
        # undecided = violated | (soft ranges where they differ from the hard ones)
        differs = np.zeros(A.shape, dtype=bool)
        for h, s in zip(hard, soft, strict=True):
            differs |= h != s
        undecided = violated | _mark(
            k.size, mr.size, ((soft[0], soft[1]), (soft[2], soft[3])), where=differs
        )
        lab = np.where(stable, STABLE, UNSTABLE).astype(np.int8)
        lab[stable & ~undecided] = STRING_STABLE
        labels[r0 : r0 + mr.size] = lab
        boundary[r0 : r0 + mr.size] = stable & undecided & ~violated
        if on_rows is not None:
            on_rows(mr.size)
    fixed = {}
    if isinstance(gains, Gains) and cav is not None:
        fixed = {
            f"{u}.{n}": v
            for u, row in gains.as_table().items()
            for n, v in row.items()
            if not (u == f"u_{cav}" and n in (f"s_{vehicle}", f"v_{vehicle}"))
        }
    elif isinstance(gains, Gains):
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
        boundary=boundary,
        band=tau,
        cav=None if cav is None else int(cav),
    )


def region_fractions(maps: Mapping[str, RegionMap]) -> dict[str, dict[str, float]]:
    """``{name: {"plant_stable": f, "string_stable": f}}`` for a set of maps."""
    return {
        n: {"plant_stable": m.plant_stable_fraction, "string_stable": m.string_stable_fraction}
        for n, m in maps.items()
    }
