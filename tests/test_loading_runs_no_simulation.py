"""Loading a problem file runs no simulation (issue 29): a ``type = "deep_lcc"`` controller
collects its data when it is first used, once, not while the file is parsed."""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path

import pytest

import lcc_synth.deeplcc.build as build
import lcc_synth.deeplcc.data as data
import lcc_synth.simulation.backends as backends
import lcc_synth.simulation.engine as engine

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"


def _deep_lcc_files() -> list[Path]:
    """Every problem file with a ``type = "deep_lcc"`` controller table (read as TOML here,
    not by the package)."""
    out = []
    for path in sorted(PROBLEMS.glob("*.toml")):
        tables = tomllib.loads(path.read_text()).get("controllers", {})
        if any(isinstance(t, dict) and t.get("type") == "deep_lcc" for t in tables.values()):
            out.append(path)
    return out


def test_there_are_deep_lcc_files():
    names = {p.name for p in _deep_lcc_files()}
    assert {"deeplcc_head_brake.toml", "platoon_deeplcc_brake.toml",
            "platoon_deeplcc_nedc.toml"} <= names  # fmt: skip


def _forbid_simulation(monkeypatch) -> None:
    def refuse(*args, **kwargs):
        raise AssertionError("a simulation ran while a problem file was loaded")

    monkeypatch.setattr(data, "collect", refuse)
    monkeypatch.setattr(build, "load_or_collect", refuse)  # not even the data cache is read
    monkeypatch.setattr(backends, "run_scenario", refuse)
    monkeypatch.setattr(engine, "simulate", refuse)


@pytest.mark.parametrize("path", _deep_lcc_files(), ids=lambda p: p.stem)
def test_load_problem_runs_no_simulation(path, monkeypatch):
    from lcc_synth.api import load_problem

    _forbid_simulation(monkeypatch)
    problem = load_problem(path)
    problem.comparable()  # every controller described as data, still without its data
    if problem.simulation is not None:
        deep = [c for c in problem.simulation.controllers.values()
                if isinstance(getattr(c, "inner", c), build.DeferredDeePLCC)]  # fmt: skip
        assert deep and not any(getattr(c, "inner", c).built for c in deep)


def test_the_data_are_collected_once_at_first_use(monkeypatch):
    """Two runs of the loaded controller collect (or read from the cache) once, and the data
    key the loaded controller reports before it collects is the one of its data."""
    from lcc_synth.experiments.spec import load_spec

    calls = []
    original = build.load_or_collect

    def counting(base, settings):
        calls.append(settings.field)
        return original(base, settings)

    monkeypatch.setattr(build, "load_or_collect", counting)
    spec = load_spec(PROBLEMS / "deeplcc_head_brake.toml")
    ctrl = spec.controllers["deep_lcc"]
    assert calls == [] and not ctrl.built
    key = ctrl.as_dict()["data_key"]
    sc = replace(spec.scenario, duration=2.0)
    first = engine.simulate(sc, ctrl)
    second = engine.simulate(sc, ctrl)
    assert calls == ["controllers.deep_lcc.data"] and ctrl.built
    assert ctrl.controller().data_key == key == ctrl.describe()["data_key"]
    assert (first.acceleration == second.acceleration).all()


def test_deep_lcc_builder_reads_no_file(monkeypatch):
    """The builder takes the problem's scenario as an object: the problem file named in its
    errors is never opened (here it does not exist), and the data key is that of the scenario
    it was given, the loaded file's."""
    import lcc_synth.problem as problem
    from lcc_synth.experiments.spec import load_spec

    spec = load_spec(PROBLEMS / "platoon_deeplcc_brake.toml")

    def refuse(*args, **kwargs):
        raise AssertionError("the builder read a problem file")

    monkeypatch.setattr(problem, "load_problem", refuse)
    table = {"type": "deep_lcc"}
    missing = str(PROBLEMS / "no_such_problem.toml")
    ctrl = build.deep_lcc_controller_from_table("deep_lcc", table, spec.system, missing,
                                                spec.scenario)  # fmt: skip
    assert ctrl.as_dict() == spec.controllers["deep_lcc"].as_dict()
    nominal = build.deep_lcc_controller_from_table("deep_lcc", table, spec.system, missing)
    assert nominal.base.perturbations == () and nominal.as_dict() != ctrl.as_dict()
