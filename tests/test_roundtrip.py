"""Problem files and the Python objects are two faces of one thing: for every file under
``problems/``, load -> ``to_toml()`` -> load gives equal objects, every value the file states
is written back unchanged, and a simulation of the written file is bit for bit the original's.

Independent truth: the original file's own TOML values (read by :mod:`tomllib`, not by the
package) and the simulator run on the original objects; objects built in Python (not from a
file) survive the round trip too.
"""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import lcc_synth as lcc
from lcc_synth.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent
FILES = sorted((ROOT / "problems").glob("*.toml"))


def leaves(d, prefix=""):
    """``{dotted path: value}`` of every scalar or list of a TOML document."""
    out = {}
    if isinstance(d, dict):
        for k, v in d.items():
            out.update(leaves(v, f"{prefix}.{k}" if prefix else k))
    elif isinstance(d, list) and d and all(isinstance(x, dict) for x in d):
        for i, v in enumerate(d):
            out.update(leaves(v, f"{prefix}[{i}]"))
    else:
        out[prefix] = d
    return out


def _load(path: Path):
    return lcc.load_problem(path)


def round_trip(path: Path, tmp_path: Path):
    first = _load(path)
    text = first.to_toml()
    data = path.parent / "data"  # the recordings a problem file names, relative to it
    if data.is_dir() and not (tmp_path / "data").exists():
        (tmp_path / "data").symlink_to(data, target_is_directory=True)
    copy = tmp_path / path.name
    copy.write_text(text)
    return first, lcc.load_problem(copy), text


def test_every_problem_file_is_covered():
    assert len(FILES) >= 15
    kinds = {f.name: _load(f) for f in FILES}
    for name, objs in kinds.items():
        parts = [objs.simulation, objs.synthesis, objs.sweep, objs.suite, objs.analysis,
                 objs.regions]  # fmt: skip
        assert any(p is not None for p in parts), name


@pytest.mark.parametrize("path", FILES, ids=[f.name for f in FILES])
def test_load_to_toml_load_gives_equal_objects(path, tmp_path):
    first, second, text = round_trip(path, tmp_path)
    assert second.comparable() == first.comparable()
    assert second.to_toml() == text  # a fixed point


@pytest.mark.parametrize("path", FILES, ids=[f.name for f in FILES])
def test_every_stated_value_is_written_back(path, tmp_path):
    original = leaves(tomllib.loads(path.read_text()))
    written = leaves(tomllib.loads(round_trip(path, tmp_path)[2]))
    objs = _load(path)
    for key, value in original.items():
        if objs.suite is not None and key.startswith("metrics."):
            # a suite's top-level [metrics] is each scenario's default: written per scenario
            field = key.split(".", 1)[1]
            for name in objs.suite.scenarios:
                own = original.get(f"scenarios.{name}.metrics.{field}", value)
                assert written[f"scenarios.{name}.metrics.{field}"] == own
            continue
        if objs.regions is not None and key.startswith("regions."):
            continue  # the grid defaults of [regions]: written into every map, checked below
        assert written.get(key, "missing") == value, key
    if objs.regions is not None:
        grid = [original.get(f"regions.{k}") for k in ("mu", "k", "step")]
        assert None not in grid
        for spec in objs.regions[0].values():
            t = spec.toml_table()
            assert [t["mu"], t["k"], t["step"]] == grid


def test_the_written_file_simulates_bit_for_bit(tmp_path):
    from lcc_synth.simulation.engine import simulate_many

    first, second, _ = round_trip(ROOT / "problems/mpc_head_brake.toml", tmp_path)
    runs = []
    for objs in (first, second):
        spec = objs.simulation
        sc = replace(spec.scenario, duration=23.0)  # the head brakes from 20 s
        runs.append(simulate_many(sc, spec.controllers))
    assert list(runs[0]) == ["all_hdv", "cf_lcc_paper", "cf_lcc_added", "mpc"]
    for name, result in runs[0].items():
        np.testing.assert_array_equal(result.velocity, runs[1][name].velocity)
        np.testing.assert_array_equal(result.u_cmd, runs[1][name].u_cmd)
    assert np.nanmax(np.abs(np.diff(runs[0]["mpc"].velocity[0, :, 0]))) > 0  # the head moved


def test_objects_built_in_python_round_trip(tmp_path):
    system = lcc.system("lcc", m=1, n=2, v_star=12.0, hdv=lcc.OVM(alpha=0.5))
    nv = system.m + system.n + 2
    scenario = lcc.scenario(
        system,
        [lcc.Sine(0.3, 10.0, 5.0, 25.0, vehicle="head"),
         lcc.Profile((30.0, 31.0, 33.0), (-1.0, 0.5, 0.5), "accel", "linear", vehicle=2)],
        duration=40.0, batch=3, seed=7, heterogeneity={"alpha": 0.1}, delay=0.4,
        delay_spread=0.1, delay_model="perception", hdv_accel_noise=0.05,
        v2v=lcc.V2V(loss_rate=[0.0, 0.1, 0.0, 0.2, 0.3], latency=0.1, velocity_noise=0.01),
        hdv_values={"beta": np.array([0.9, 0.8, 0.9, 1.0, 1.1])},
    )  # fmt: skip
    controllers = {
        "hdv": lcc.hdv_controller("hdv", sample_time=0.1),
        "gain": lcc.static_controller(system, {"s_1": -0.5, "v_-1": 0.2}, "gain", "added",
                                      equilibrium="estimated", equilibrium_tau=2.0,
                                      measurement_filter=0.2),  # fmt: skip
    }
    metrics = lcc.MetricsConfig((10.0, 35.0), "all")
    objs = lcc.build_problem("built", system, scenario, controllers, metrics, "made in Python")
    path = tmp_path / "built.toml"
    path.write_text(objs.to_toml())
    back = lcc.load_problem(path)
    assert back.comparable() == objs.comparable()
    assert back.scenario.v2v.rates(nv).tolist() == [0.0, 0.1, 0.0, 0.2, 0.3]
    assert back.description == "made in Python"
    # the comparison can fail: change one gain in the text
    path.write_text(objs.to_toml().replace("s_1 = -0.5", "s_1 = -0.25"))
    assert lcc.load_problem(path).comparable() != objs.comparable()


def test_a_synthesis_built_in_python_round_trips(tmp_path):
    system = lcc.system("lcc", m=1, n=1, v_star=15.0)
    spec = lcc.h2_problem(
        system, design="string_stable", pattern=[-1, 1], weights={"head": 1.0, "q_s0": 2.0},
        semantics="added", string={"gamma": 1.0, "polish_steps": 20},
        baseline={"name": "hdv", "gains": {}},
        as_run={"equilibrium": "estimated", "equilibrium_tau": 1.5, "sample_time": 0.1},
    )  # fmt: skip
    path = tmp_path / "synth.toml"
    path.write_text(lcc.build_problem("synth", system, synthesis=spec).to_toml())
    back = lcc.load_problem(path)
    assert back.synthesis.as_dict() | {"source": None} == spec.as_dict() | {"source": None}
    assert back.synthesis.as_run.equilibrium_tau == 1.5 and back.synthesis.pattern == (-1, 1)
    with pytest.raises(ConfigError, match=r"<python>: synthesis\.weights\.q_s"):
        lcc.h2_problem(system, weights={"q_s": 0.0})


def test_what_has_no_table_form_says_so():
    system = lcc.system("fd_lcc", n=2)
    per_draw = lcc.scenario(system, hdv_values={"alpha": np.full((2, 4), 0.6)}, batch=2)
    with pytest.raises(ConfigError, match=r"scenario\.hdv_values\.alpha"):
        per_draw.toml_table()
    per_vehicle = lcc.scenario(system, delay=np.array([0.0, 0.3, 0.0, 0.4]))
    with pytest.raises(ConfigError, match=r"scenario\.delay"):
        per_vehicle.toml_table()
