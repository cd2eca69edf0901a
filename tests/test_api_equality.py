"""Objects compare by value: ``load_problem(f) == load_problem(f)`` for the problem files, every
object a :class:`~lcc_synth.api.ProblemObjects` holds compares with ``==`` (numpy arrays and
controllers included), and a change of one value makes them differ.

Independent truth: two loads of one file (nothing changed in between), and copies changed in
one known place (one array entry by one ulp, one gain in the file's text).

The three DeeP-LCC files (``deeplcc_head_brake``, ``platoon_deeplcc_brake``,
``platoon_deeplcc_nedc``) are left out of the per-file test: loading one collects DeeP-LCC's
data (8-15 s each here); their controllers compare through the same ``as_dict()``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import lcc_synth as lcc
from lcc_synth.models.records import ValueEq, same

ROOT = Path(__file__).resolve().parent.parent
FILES = [f for f in sorted((ROOT / "problems").glob("*.toml")) if "deeplcc" not in f.name]


def test_the_files_left_out_are_the_deeplcc_ones():
    every = sorted((ROOT / "problems").glob("*.toml"))
    assert len(FILES) >= 20
    left = [f.name for f in every if f not in FILES]
    assert left == ["deeplcc_head_brake.toml", "platoon_deeplcc_brake.toml",
                    "platoon_deeplcc_nedc.toml"]  # fmt: skip


@pytest.mark.parametrize("path", FILES, ids=[f.name for f in FILES])
def test_two_loads_of_a_file_are_equal_and_so_is_each_object(path):
    a, b = lcc.load_problem(path), lcc.load_problem(path)
    assert a == b and not (a != b)
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        assert x == y and not (x != y), f.name
    assert a.scenario == b.scenario and a.metrics == b.metrics


def test_one_changed_value_makes_them_differ(tmp_path):
    path = ROOT / "problems/ring_sugiyama.toml"  # per-vehicle IDM arrays, six controllers
    a, b = lcc.load_problem(path), lcc.load_problem(path)
    values = dict(b.scenario.hdv_values)
    key = next(iter(values))
    changed = values[key].copy()
    changed[3] = np.nextafter(changed[3], np.inf)  # one entry, one ulp
    sc = replace(b.scenario, hdv_values={**values, key: changed})
    assert sc != a.scenario and not (sc == a.scenario)
    sim = replace(b.simulation, scenario=sc)
    assert sim != a.simulation
    assert replace(b, simulation=sim) != a
    # a controller: one gain of the text of Table II's file
    text = (ROOT / "problems/paper_table2.toml").read_text()
    assert text.count("v_0 = -0.5") == 2
    (tmp_path / "t2.toml").write_text(text.replace("v_0 = -0.5", "v_0 = -0.4", 1))
    t2, t2_changed = (lcc.load_problem(p) for p in (ROOT / "problems/paper_table2.toml",
                                                     tmp_path / "t2.toml"))  # fmt: skip
    assert t2.simulation != t2_changed.simulation
    assert replace(t2_changed, source=t2.source) != t2
    # the regions' arrays
    regions = lcc.load_problem(ROOT / "problems/paper_fig7_fig8_regions.toml").regions
    assert regions == lcc.load_problem(ROOT / "problems/paper_fig7_fig8_regions.toml").regions
    assert regions != lcc.Regions(regions.specs, regions.omega * (1 + 1e-15))
    assert regions != lcc.Regions(regions.specs, regions.omega[:-1])


def test_same_compares_by_value():
    nan = float("nan")
    assert same(np.array([1.0, nan]), np.array([1.0, nan]))  # NaN where NaN
    assert not same(np.array([1.0, 2.0]), np.array([1.0, 2.0 + 1e-12]))
    assert not same(np.zeros(3), np.zeros((1, 3)))  # the shape counts
    assert not same(np.zeros(3), [0.0, 0.0, 0.0])  # an array is not a list
    assert same({"a": np.arange(3)}, {"a": np.arange(3)})
    assert not same({"a": 1}, {"a": 1, "b": 2})
    assert same(1, 1.0) and same(np.float64(0.5), 0.5) and same(nan, np.float64(nan))
    assert not same([1, 2], (1, 2))  # a list is not a tuple
    assert same(lcc.hdv_controller("x"), lcc.hdv_controller("x"))  # by what defines them
    assert not same(lcc.hdv_controller("x"), lcc.hdv_controller("y"))

    @dataclasses.dataclass(frozen=True, eq=False)
    class Held(ValueEq):
        values: np.ndarray
        note: str = dataclasses.field(default="", compare=False)

    assert Held(np.ones(2), "a") == Held(np.ones(2), "b")  # compare=False left out
    assert Held(np.ones(2)) != Held(np.zeros(2))
    assert Held(np.ones(2)).__eq__(np.ones(2)) is NotImplemented
    with pytest.raises(TypeError):
        hash(Held(np.ones(2)))  # equal by value: not hashable
