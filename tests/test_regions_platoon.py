"""Region maps (Figs. 7-8) on open platoons: the segment product against the closed loop.

Truths: the closed loop built from the platoon model's ``A, B, H`` and the gain at a grid point
(eigenvalues for plant stability, the exact per-point verdict of the state space for string
stability, ``|Gamma(jw)|`` of the state space on a dense grid), and the paper's one-CAV string,
which *is* the one-CAV platoon (the same map bit for bit).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_subprocess import PAPER_HDV, run_cli
from test_regions import boundary_points

from lcc_synth.analysis.region_specs import grid_axis, region_specs_from
from lcc_synth.analysis.regions import (
    STABLE,
    STRING_STABLE,
    UNSTABLE,
    affine_polynomials,
    platoon_segments,
    region_map,
)
from lcc_synth.analysis.string_stability import string_stability
from lcc_synth.analysis.transfer import closed_loop_eigenvalues, gamma_state_space
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import general_lcc
from lcc_synth.models.platoon import Platoon, platoon_model

PAPER = OVM().linear_coefficients(15.0)
AXIS = grid_axis(-10.0, 10.0, 0.5)
#: CAVs at 2 and 5 of 7: segments [1, 4] (HDV 1 ahead of CAV 2, 3 and 4 behind) and [5, 7]
TWO = platoon_model(Platoon((OVM(),) * 7, (2, 5), 15.0), warn=False)
FIXED = {"u_2": {"s_3": -1.0, "v_3": -1.0}, "u_5": {"s_6": 0.5, "v_6": -0.5}}
DENSE = np.logspace(-3, 2, 4000)


def platoon_gain(model, fixed: dict, cav: int, vehicle: int, mu: float, k: float) -> Gains:
    """The fixed per-CAV gains with ``(mu, k)`` of CAV ``cav`` on ``vehicle`` ("added")."""
    table = {u: dict(row) for u, row in fixed.items()}
    table.setdefault(f"u_{cav}", {}).update({f"s_{vehicle}": mu, f"v_{vehicle}": k})
    return Gains.from_table(table, model, "added")


def direct_label(model, gain: Gains) -> int | None:
    """The label of the closed loop built from ``A, B, H``; ``None`` when too close to call."""
    K, kh = gain.input_feedback(model)
    Acl = model.A + model.B @ K
    max_re = float(np.max(closed_loop_eigenvalues(Acl).real))
    rep = string_stability(model, K, kh)
    if abs(max_re) < 1e-9 or rep.verdict == "boundary":
        return None
    if max_re > 0:
        return UNSTABLE
    peak = float(np.max(np.abs(gamma_state_space(model, K, kh, DENSE))))
    if rep.verdict == "string_stable":
        assert peak <= 1.0 + 1e-12, peak  # the dense grid never contradicts the verdict
        return STRING_STABLE
    assert rep.verdict == "string_unstable", rep.verdict
    return STABLE


@pytest.mark.parametrize(
    ("cav", "vehicle", "seed"), [(2, 1, 1), (2, 4, 2), (5, 7, 3)]
)  # fmt: skip
def test_two_cav_map_matches_the_closed_loop(cav, vehicle, seed):
    fixed = {u: {n: g for n, g in row.items() if n not in (f"s_{vehicle}", f"v_{vehicle}")}
             for u, row in FIXED.items()}  # fmt: skip
    rm = region_map(TWO, vehicle, AXIS, AXIS, Gains.from_table(fixed, TWO, "added"), cav=cav)
    assert rm.cav == cav and rm.as_dict()["cav"] == cav
    assert rm.band > 0 and rm.labels.shape == (AXIS.size, AXIS.size)
    rng = np.random.default_rng(seed)
    pts = [tuple(p) for p in rng.integers(0, rm.labels.shape, size=(12, 2))]
    bnd = boundary_points(rm.labels)
    pts += [tuple(p) for p in bnd[rng.choice(len(bnd), min(18, len(bnd)), replace=False)]]
    decided = 0
    for a, b in pts:
        want = direct_label(TWO, platoon_gain(TWO, fixed, cav, vehicle, rm.mu[a], rm.k[b]))
        if want is None or rm.boundary[a, b]:
            continue
        assert rm.labels[a, b] == want, (cav, vehicle, rm.mu[a], rm.k[b])
        decided += 1
    assert decided >= 0.8 * len(pts)
    if vehicle > cav:  # a vehicle behind moves the poles: all three labels appear
        assert set(np.unique(rm.labels)) == {UNSTABLE, STABLE, STRING_STABLE}


def test_segment_product_is_gamma_of_the_state_space():
    """(N0 + mu N1 + k N2) / (D0 + mu D1 + k D2) at s = jw is Gamma of the closed loop."""
    rng = np.random.default_rng(7)
    drivers = [OVM(alpha=a, beta=b) for a, b in rng.uniform((0.4, 0.6), (1.0, 1.2), (6, 2))]
    model = platoon_model(Platoon(tuple(drivers), (1, 4), 15.0), warn=False)
    fixed = {"u_1": {"s_2": 0.3, "v_3": -0.4}, "u_4": {"v_4": 0.2, "s_6": -0.3}}
    s = 1j * np.array([0.05, 0.3, 1.0, 3.0])
    for cav, vehicle in ((1, 3), (4, 5)):
        polys = affine_polynomials(model, vehicle, Gains.from_table(fixed, model, "added"), cav)
        for mu, k in rng.uniform(-2.0, 2.0, size=(3, 2)):
            n0, n1, n2, d0, d1, d2 = polys
            num, den = n0 + mu * n1 + k * n2, d0 + mu * d1 + k * d2
            K, kh = platoon_gain(model, fixed, cav, vehicle, mu, k).input_feedback(model)
            want = gamma_state_space(model, K, kh, s.imag)
            np.testing.assert_allclose(np.polyval(num[::-1], s) / np.polyval(den[::-1], s),
                                       want, rtol=1e-10)  # fmt: skip
            # den is the closed loop's characteristic polynomial det(sI - A_cl)
            Acl = model.A + model.B @ K
            dets = [np.linalg.det(z * np.eye(model.nx) - Acl) for z in s]
            np.testing.assert_allclose(np.polyval(den[::-1], s), dets, rtol=1e-9)


@pytest.mark.parametrize(("m", "n"), [(2, 2), (0, 2)])
def test_one_cav_platoon_is_the_paper_map_bit_for_bit(m, n):
    """kind = "platoon" with cavs = [m + 1] and kind = "lcc" (m, n): the same A, B, H, the same
    per-vehicle polynomials, hence the same labels, boundary and band, bit for bit."""
    lcc = general_lcc(m, n, PAPER)
    one = platoon_model(Platoon((OVM(),) * (m + n + 1), (m + 1,), 15.0), warn=False)
    for v in [*range(-m, 0), *range(1, n + 1)]:
        fixed = {"s_1": -1.0, "v_1": -1.0} if v != 1 else {"s_2": 0.5}
        table = {f"u_{m + 1}": {f"{nm[0]}_{int(nm[2:]) + m + 1}": g for nm, g in fixed.items()}}
        g_lcc, g_pl = Gains.named(fixed), Gains.from_table(table, one, "added")
        a = affine_polynomials(lcc, v, g_lcc)
        b = affine_polynomials(one, v + m + 1, g_pl)
        assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
        ax = AXIS[::2]  # the polynomials are equal bit for bit: a coarse grid suffices
        r1 = region_map(lcc, v, ax, ax, g_lcc)
        r2 = region_map(one, v + m + 1, ax, ax, g_pl)
        assert np.array_equal(r1.labels, r2.labels) and np.array_equal(r1.boundary, r2.boundary)
        assert r1.band == r2.band and r2.cav == m + 1 and r1.cav is None


def test_segments_follow_the_gains():
    assert platoon_segments(TWO) == [(2, 1, 4), (5, 5, 7)]
    # CAV 5 hears HDV 4 ahead of it: the cut moves to 3 | 4
    g = Gains.from_table({"u_5": {"s_4": 0.2}}, TWO, "added")
    assert platoon_segments(TWO, g) == [(2, 1, 3), (5, 4, 7)]
    # the map's vehicle belongs to its CAV's stretch
    assert platoon_segments(TWO, None, 5, 3) == [(2, 1, 2), (5, 3, 7)]
    # a CAV's predecessor's velocity alone is the segment's input, not a vehicle of it
    g = Gains.from_table({"u_5": {"v_4": 0.3}, "u_2": {"s_4": -0.5}}, TWO, "added")
    assert platoon_segments(TWO, g) == [(2, 1, 4), (5, 5, 7)]


def _toml(maps: str, cavs: str = "[2, 5]", kind: str = "platoon") -> dict:
    import tomllib

    text = f'[system]\nkind = "{kind}"\nsize = 7\ncavs = {cavs}\nv_star = 15.0\n{maps}'
    return tomllib.loads(text)


@pytest.mark.parametrize(
    ("maps", "field", "words"),
    [
        ("[maps.a]\ncav = 5\nvehicle = 2\n", "maps.a.vehicle", "one of [3, 4, 6, 7]"),
        ("[maps.a]\ncav = 5\nvehicle = 5\n", "maps.a.vehicle", "HDV of CAV 5's segment"),
        ("[maps.a]\nvehicle = 3\n", "maps.a.cav", "one of [2, 5]"),
        ("[maps.a]\ncav = 3\nvehicle = 4\n", "maps.a.cav", "one of [2, 5]"),
        ("[maps.a]\ncav = 5\nvehicle = 6\ngains = { u_5 = { s_3 = 1.0 }, u_2 = { v_3 = 1.0 } }\n",
         "maps.a.gains.u_5.s_3", "crosses into CAV 2's segment"),
        ("[maps.a]\ncav = 5\nvehicle = 6\ngains = { u_2 = { v_6 = 1.0 } }\n",
         "maps.a.gains.u_2.v_6", "crosses into CAV 5's segment"),
        ("[maps.a]\ncav = 5\nvehicle = 3\ngains = { u_2 = { s_3 = 1.0 } }\n",
         "maps.a.vehicle", "CAV 2's segment"),
        ("[maps.a]\ncav = 5\nvehicle = 6\ngains = { u_5 = { v_6 = 1.0 } }\n",
         "maps.a.gains.u_5.v_6", "own axis"),
        ("[maps.a]\ncav = 5\nvehicle = 6\ngains = { s_6 = 1.0 }\n",
         "maps.a.gains.s_6", "not a CAV input"),
    ],
)  # fmt: skip
def test_platoon_map_refusals_name_the_field(maps, field, words):
    data = _toml(maps)
    model = platoon_model(Platoon((OVM(),) * 7, (2, 5), 15.0), warn=False)
    with pytest.raises(ConfigError) as err:
        region_specs_from(data, model)
    assert err.value.field == field and words in err.value.message


def test_ring_and_paper_models_refuse_platoon_keys():
    ring = platoon_model(Platoon((OVM(),) * 7, (2, 5), 15.0, ring=True), warn=False)
    with pytest.raises(ConfigError, match="no head vehicle") as err:
        region_specs_from(_toml("[maps.a]\ncav = 5\nvehicle = 6\n"), ring)
    assert err.value.field == "system.kind"
    with pytest.raises(ConfigError) as err:
        region_map(ring, 6, AXIS, AXIS, cav=5)
    assert err.value.field == "system.kind"
    lcc = general_lcc(2, 2, PAPER)
    with pytest.raises(ConfigError) as err:
        region_specs_from({"maps": {"a": {"vehicle": 1, "cav": 0}}}, lcc)
    assert err.value.field == "maps.a.cav"
    with pytest.raises(ConfigError) as err:
        region_map(lcc, 1, AXIS, AXIS, cav=0)
    assert err.value.field == "cav"


def test_platoon_spec_round_trips_through_its_toml_table():
    data = _toml(
        "[regions]\nstep = 2.0\n[maps.a]\ncav = 5\nvehicle = 7\n"
        "gains = { u_2 = { s_3 = -1.0 }, u_5 = { v_6 = -0.5 } }\n"
        "[maps.b]\ncav = 5\nvehicle = 7\nbaseline = 'a'\n"
    )
    specs, _ = region_specs_from(data, TWO)
    table = specs["a"].toml_table()
    assert table["cav"] == 5 and table["gains"] == {"u_2": {"s_3": -1.0}, "u_5": {"v_6": -0.5}}
    table = {key: v for key, v in table.items() if v is not None}  # TOML has no null
    again, _ = region_specs_from({**data, "maps": {"a": table}}, TWO)
    assert again["a"].gains == specs["a"].gains and again["a"].cav == 5
    assert np.array_equal(again["a"].mu, specs["a"].mu)
    data["maps"]["b"]["cav"] = 2
    data["maps"]["b"]["vehicle"] = 3
    with pytest.raises(ConfigError, match="same vehicle, CAV and grid"):
        region_specs_from(data, TWO)


PLATOON_PROBLEM = PAPER_HDV + """
[system]
kind = "platoon"
size = 5
cavs = [2, 4]
v_star = 15.0

[regions]
step = 2.0
per_decade = 20
dense_per_decade = 100

[maps.behind]
cav = 4
vehicle = 5
gains = { u_2 = { s_3 = -1.0, v_3 = -1.0 } }
"""


def test_cli_regions_on_a_platoon(tmp_path):
    (tmp_path / "p.toml").write_text(PLATOON_PROBLEM)
    out = run_cli(["regions", "p.toml", "--json", "--no-record"], tmp_path)
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    entry = doc["maps"]["behind"]
    assert entry["cav"] == 4 and entry["vehicle"] == 5 and entry["shape"] == [11, 11]
    assert entry["fixed_gains"] == {"u_2.s_3": -1.0, "u_2.v_3": -1.0}
    assert {"plant_stable_fraction", "string_stable_fraction", "boundary_points", "band",
            "us_per_point", "title"} <= set(entry)  # fmt: skip
    assert doc["system"]["kind"] == "platoon"
    bad = PLATOON_PROBLEM.replace("vehicle = 5", "vehicle = 1")
    (tmp_path / "bad.toml").write_text(bad)
    out = run_cli(["regions", "bad.toml", "--no-record"], tmp_path)
    assert out.returncode == 2 and out.stdout == ""
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "maps.behind.vehicle" in lines[0] and "[3, 5]" in lines[0]


def test_segment_product_decision_function_within_the_band():
    """The rounding error of Ptilde on the segment product against exact rationals (the
    product of the segments' exact polynomials, ``tests/test_regions.py``'s reference),
    relative to the sum of the absolute values of the terms: within ``(2 deg + 16) eps``,
    the bound the band ``tau = 16 (2 deg + 16) eps`` is built on (``deg = 2 N``)."""
    from fractions import Fraction
    from types import SimpleNamespace

    from test_regions import _pmul, exact_gamma_polynomials, exact_ptilde

    from lcc_synth.analysis.regions import _row_quadratics, region_band, region_frequency_grid

    rng = np.random.default_rng(5)
    eps = np.finfo(float).eps
    w = region_frequency_grid()
    xs = np.concatenate([[0.0], w[rng.choice(w.size, 8, replace=False)] ** 2])
    drivers = [OVM(alpha=a, beta=b) for a, b in rng.uniform((0.4, 0.6), (1.0, 1.2), (7, 2))]
    model = platoon_model(Platoon(tuple(drivers), (2, 5), 15.0), warn=False)
    deg = 2 * model.platoon.size
    worst = 0.0
    for cav, vehicle in ((2, 1), (2, 4), (5, 7)):
        fixed = {"u_2": {"s_3": -1.0, "v_3": -1.0}, "u_5": {"v_4": 0.5, "s_6": 0.5}}
        fixed = {u: {n: g for n, g in row.items() if not (u == f"u_{cav}" and n[2:] ==
                                                          str(vehicle))}
                 for u, row in fixed.items()}  # fmt: skip
        polys = affine_polynomials(model, vehicle, Gains.from_table(fixed, model, "added"), cav)
        for mu, k in rng.uniform(-5, 5, size=(3, 2)):
            A, B, C, SA, SB, SC = (a[0] for a in _row_quadratics(polys, np.array([mu]), xs))
            got, scale = A + B * k + C * k * k, SA + SB * abs(k) + SC * k * k
            table = platoon_gain(model, fixed, cav, vehicle, mu, k).as_table()
            num, den = [Fraction(1)], [Fraction(1)]
            for c, first, last in platoon_segments(model, None, cav, vehicle):
                row = table.get(f"u_{c}", {})
                seg = SimpleNamespace(m=c - first, n=last - c, coefficients={
                    i - c: model.coefficients[i - 1] for i in range(first, last + 1)})
                mus = {i - c: row.get(f"s_{i}", 0.0) for i in range(first, last + 1)}
                kks = {i - c: row.get(f"v_{i}", 0.0) for i in range(first, last + 1)}
                kh = row.get(f"v_{c - 1}", 0.0) if first == c else 0.0
                n_, d_ = exact_gamma_polynomials(seg, mus, kks, kh)
                num, den = _pmul(num, n_), _pmul(den, d_)
            for j, x in enumerate(xs):
                want = exact_ptilde(num, den, Fraction(float(x)))
                err = abs(Fraction(float(got[j])) - want) / Fraction(float(scale[j]))
                worst = max(worst, float(err) / eps)
    assert worst <= 2 * deg + 16, worst  # measured 0.35 eps
    assert region_band(deg) == pytest.approx(16 * (2 * deg + 16) * eps)


def test_flat_api_maps_a_platoon():
    import lcc_synth as lcc

    system = lcc.system(size=7, cavs=[2, 5])
    g = lcc.gains({"u_2": {"s_3": -1.0, "v_3": -1.0}}, semantics="added", model=system)
    ax = AXIS[::4]
    a = lcc.region_map(system, 7, ax, ax, g, cav=5)
    b = region_map(TWO, 7, ax, ax, Gains.from_table({"u_2": {"s_3": -1.0, "v_3": -1.0}}, TWO,
                                                    "added"), cav=5)  # fmt: skip
    assert np.array_equal(a.labels, b.labels) and a.cav == 5
    assert a.fixed == {"u_2.s_3": -1.0, "u_2.v_3": -1.0}
