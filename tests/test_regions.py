"""String-stable region maps (Figs. 7-8): vectorised map vs the exact per-point check."""

from __future__ import annotations

import numpy as np
import pytest

from lcc_synth.analysis.regions import (
    STABLE,
    STRING_STABLE,
    UNSTABLE,
    affine_polynomials,
    grid_axis,
    hurwitz,
    region_map,
)
from lcc_synth.analysis.string_stability import string_stability
from lcc_synth.analysis.transfer import closed_form_gains, gamma_polynomials
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import StaticGains, input_feedback
from lcc_synth.models.hdv import OVM, LinearCoefficients
from lcc_synth.models.linear import cf_lcc, general_lcc

PAPER = OVM().linear_coefficients(15.0)
MODEL = general_lcc(2, 2, PAPER)
AXIS = grid_axis(-10.0, 10.0, 0.5)  # coarse version of the paper's grid


def exact_label(model, vehicle, mu, k, fixed=None) -> int:
    g = dict(fixed or {})
    g[f"s_{vehicle}"], g[f"v_{vehicle}"] = mu, k
    K, kh = input_feedback(model, StaticGains(g))
    rep = string_stability(model, K, kh)
    if not rep.plant_stable:
        return UNSTABLE
    return STRING_STABLE if rep.string_stable else STABLE


def boundary_points(labels: np.ndarray) -> np.ndarray:
    """Grid points with a 4-neighbour of a different label (the hardest to classify)."""
    b = np.zeros(labels.shape, bool)
    b[1:] |= labels[1:] != labels[:-1]
    b[:-1] |= labels[1:] != labels[:-1]
    b[:, 1:] |= labels[:, 1:] != labels[:, :-1]
    b[:, :-1] |= labels[:, 1:] != labels[:, :-1]
    return np.argwhere(b)


def check_against_exact(model, rm, fixed, rng, n_random=25, n_boundary=25):
    pts = [tuple(p) for p in rng.integers(0, rm.labels.shape, size=(n_random, 2))]
    bnd = boundary_points(rm.labels)
    if len(bnd):
        pts += [tuple(p) for p in bnd[rng.choice(len(bnd), min(n_boundary, len(bnd)), False)]]
    for a, b in pts:
        want = exact_label(model, rm.vehicle, rm.mu[a], rm.k[b], fixed)
        assert rm.labels[a, b] == want, (rm.vehicle, rm.mu[a], rm.k[b], fixed)


@pytest.mark.parametrize("vehicle", [-2, -1, 1, 2])
def test_map_matches_exact_per_point_check(vehicle):
    rm = region_map(MODEL, vehicle, AXIS, AXIS)
    assert rm.labels.shape == (AXIS.size, AXIS.size)
    assert set(np.unique(rm.labels)) <= {UNSTABLE, STABLE, STRING_STABLE}
    check_against_exact(MODEL, rm, {}, np.random.default_rng(vehicle + 10))


def test_map_with_fixed_gains_matches_exact():
    fixed = {"s_1": -1.0, "v_1": -1.0}
    rm = region_map(MODEL, -1, AXIS, AXIS, gains=StaticGains(fixed))
    assert rm.fixed == fixed
    check_against_exact(MODEL, rm, fixed, np.random.default_rng(4))


def test_dense_boundary_of_fine_grid_matches_exact():
    """Accuracy of the frequency grid where it matters: boundary points of a finer map."""
    ax = grid_axis(-3.0, 3.0, 0.05)
    rng = np.random.default_rng(8)
    for vehicle in (-2, 2):
        rm = region_map(MODEL, vehicle, ax, ax)
        check_against_exact(MODEL, rm, {}, rng, n_random=5, n_boundary=40)


def test_heterogeneous_and_cf_lcc_maps_match_exact():
    rng = np.random.default_rng(12)
    coefs = [LinearCoefficients(0.8, 1.6, 0.7), LinearCoefficients(1.1, 1.4, 1.0),
             LinearCoefficients(0.6, 1.9, 0.5)]
    model = general_lcc(1, 2, coefs, cav=LinearCoefficients(0.9, 1.5, 0.8))
    ax = grid_axis(-4.0, 4.0, 0.4)
    fixed = {"s_-1": 0.5, "v_-1": -0.5}
    rm = region_map(model, 2, ax, ax, gains=StaticGains(fixed))
    check_against_exact(model, rm, fixed, rng)
    model = cf_lcc(2, PAPER)
    rm = region_map(model, 1, ax, ax)
    check_against_exact(model, rm, {}, rng)


def test_affine_polynomials_are_exact():
    rng = np.random.default_rng(2)
    fixed = StaticGains({"s_-2": 1.0, "v_-2": -1.0, "s_1": -0.5})
    for vehicle in (-2, -1, 1, 2):
        n0, n1, n2, d0, d1, d2 = affine_polynomials(MODEL, vehicle, fixed)
        for mu, k in rng.uniform(-10, 10, size=(5, 2)):
            g = dict(fixed.gains)
            g[f"s_{vehicle}"], g[f"v_{vehicle}"] = mu, k
            K, kh = input_feedback(MODEL, StaticGains(g))
            m, kk, khx = closed_form_gains(MODEL, K, kh)
            num, den = gamma_polynomials(PAPER, m, kk, 2, 2, khx)
            got_n = (n0 + mu * n1 + k * n2)[: len(num)][::-1]
            got_d = (d0 + mu * d1 + k * d2)[::-1]
            assert np.allclose(got_n, num, rtol=1e-12, atol=1e-10)
            assert np.allclose(got_d, den, rtol=1e-12, atol=1e-10)
        if vehicle < 0:  # looking ahead never changes the closed-loop poles
            assert not np.any(d1) and not np.any(d2)


def test_hurwitz_matches_roots():
    rng = np.random.default_rng(0)
    polys = []
    for deg in (1, 2, 3, 6, 10):
        for _ in range(200):  # real roots
            roots = rng.normal(size=deg) * 2 - 0.3
            polys.append((np.poly(roots), np.all(roots < 0)))
        for _ in range(200):  # complex pairs
            re = rng.normal(size=deg) - 0.2
            im = rng.normal(size=deg)
            c = np.real(np.poly(np.concatenate([re + 1j * im, re - 1j * im])))
            polys.append((c, np.all(re < 0)))
    for c, want in polys:
        assert bool(hurwitz(c)) == want
    batch = np.array([np.poly([-1.0, -2.0, -3.0]), np.poly([-1.0, 2.0, -3.0])])
    assert hurwitz(batch).tolist() == [True, False]
    assert not hurwitz(np.poly([-1.0, 1j, -1j]).real)  # marginal: not asymptotically stable


def test_paper_facts_looking_behind_beats_looking_ahead():
    """Figs. 7(a)(b) vs 8: larger string-stable areas when the CAV looks behind; Fig. 7(c)-(f):
    adding mu_1 = k_1 = -1 or mu_2 = k_2 = -1 expands the looking-ahead regions and keeps the
    original ones."""
    ax = grid_axis(-10.0, 10.0, 0.25)
    maps = {v: region_map(MODEL, v, ax, ax) for v in (-2, -1, 1, 2)}
    ahead = max(maps[-1].string_stable_fraction, maps[-2].string_stable_fraction)
    behind = min(maps[1].string_stable_fraction, maps[2].string_stable_fraction)
    assert ahead > 0.02 and behind > 2 * ahead
    # looking ahead never destabilises the plant; looking behind can (dashed areas of Fig. 8)
    assert maps[-1].plant_stable_fraction == 1.0 and maps[-2].plant_stable_fraction == 1.0
    assert maps[1].plant_stable_fraction < 1.0 and maps[2].plant_stable_fraction < 1.0
    # HDV-only (origin) is string unstable in every map
    zero = np.argmin(np.abs(ax))
    assert all(m.labels[zero, zero] == STABLE for m in maps.values())
    for extra in ({"s_1": -1.0, "v_1": -1.0}, {"s_2": -1.0, "v_2": -1.0}):
        for v in (-1, -2):
            grown = region_map(MODEL, v, ax, ax, gains=StaticGains(extra))
            before = maps[v].labels == STRING_STABLE
            after = grown.labels == STRING_STABLE
            assert after.mean() > 3 * before.mean()
            assert not np.any(before & ~after)


def test_region_map_summary_and_errors():
    rm = region_map(MODEL, 1, AXIS[:5], AXIS)
    d = rm.as_dict()
    assert d["shape"] == [5, AXIS.size] and d["points"] == 5 * AXIS.size
    total = d["unstable_fraction"] + d["stable_not_string_stable_fraction"]
    assert total + d["string_stable_fraction"] == pytest.approx(1.0)
    assert d["plant_stable_fraction"] == pytest.approx(1.0 - d["unstable_fraction"])
    assert "labels" not in d and len(rm.as_dict(include_labels=True)["labels"]) == 5
    with pytest.raises(ConfigError, match="vehicle"):
        region_map(MODEL, 0, AXIS, AXIS)
    with pytest.raises(ConfigError, match="vehicle"):
        region_map(MODEL, 3, AXIS, AXIS)
    with pytest.raises(ConfigError, match="increasing"):
        region_map(MODEL, 1, AXIS, AXIS[::-1])
    with pytest.raises(ConfigError, match="step"):
        grid_axis(-1.0, 1.0, 0.0)
    assert grid_axis(-10, 10, 0.02).size == 1001
