"""The flat API (``import lcc_synth as lcc``): the README snippet, Table II through the API,
the explicit metric window, results as records, and lazy imports.

Independent truth: the paper's Table II (AAVE 0.8928 / 0.5805 / 0.8129 m/s, fuel 392.86 /
321.94 / 340.56 mL), the CLI's own path for the same problem file (load_spec / simulate_many,
spec_from_problem / synthesize), Theorem 2 (FD-LCC is controllable for the paper's OVM) and
Table I case D (string stable), and a fresh interpreter for what importing loads.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import lcc_synth as lcc
from lcc_synth.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent
TABLE2 = {"all_hdv": (0.8928, 392.86), "fd_lcc": (0.5805, 321.94), "cf_lcc": (0.8129, 340.56)}
PAPER_GAINS = {"s_0": 0.1, "v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}
HEAVY = ("cvxpy", "casadi", "rerun", "osqp", "clarabel", "control", "matplotlib", "dask")


def readme_snippet() -> str:
    """The python block of README.md's "From Python" section."""
    text = (ROOT / "README.md").read_text()
    section = text.split("## From Python", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    assert len(blocks) == 1, "the From Python section has one python block"
    return blocks[0]


def test_readme_snippet_reproduces_table2_and_the_cli_synthesis():
    code = readme_snippet()
    assert len(code.strip().splitlines()) <= 15
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "README.md", "exec"), {"__name__": "readme"})
    lines = out.getvalue().splitlines()
    assert lines[0] == "CF-LCC: AAVE 0.8129 m/s, fuel 340.56 mL"  # Table II, CF-LCC row
    # the same synthesis by the CLI's path: the shipped problem file (its baseline aside)
    from lcc_synth.problem import load_problem
    from lcc_synth.synthesis.config import spec_from_problem
    from lcc_synth.synthesis.design import synthesize

    rep = synthesize(spec_from_problem(load_problem(ROOT / "problems/synth_cf_lcc_pattern.toml")))
    expected = {k: round(g, 3) for k, g in rep.gains.items() if g}
    assert set(expected) <= {"s_0", "v_0", "s_1", "v_1", "s_2", "v_2"}  # the pattern
    assert lines[1] == (
        f"H2: norm {rep.check.h2:.4f}, string stable {rep.check.string_stable}, {expected}"
    )
    # and what README shows as the output is what it prints
    shown = (ROOT / "README.md").read_text().split("## From Python", 1)[1]
    shown = re.findall(r"```text\n(.*?)```", shown, re.S)[0].splitlines()
    assert shown == lines


def test_the_guide_shows_the_readme_snippet():
    """The guide's "From Python" (docs/guide/getting_started.md) shows the same code and output
    as README's, which the test above runs."""
    readme = (ROOT / "README.md").read_text().split("## From Python", 1)[1].split("\n## ", 1)[0]
    guide = (ROOT / "docs" / "guide" / "getting_started.md").read_text()
    guide = guide.split("## From Python", 1)[1].split("\n## ", 1)[0]
    for fence in ("python", "text"):
        pattern = rf"```{fence}\n(.*?)```"
        assert re.findall(pattern, guide, re.S) == re.findall(pattern, readme, re.S), fence


def table2_system():
    return lcc.system("fd_lcc", n=10, v_star=15.0)


def table2_runs():
    string = table2_system()
    brake = lcc.scenario(string, [lcc.Brake(vehicle=1, start=20.0, duration=1.0, decel=-5.0)],
                         t_start=0.01)  # fmt: skip
    fd = {k: v for k, v in PAPER_GAINS.items() if k != "s_0"}
    ctrls = {
        "all_hdv": lcc.hdv_controller(),
        "fd_lcc": lcc.static_controller(string, fd, "fd_lcc", "replace"),
        "cf_lcc": lcc.static_controller(string, PAPER_GAINS, "cf_lcc", "replace", "cf_lcc"),
    }
    return {k: lcc.simulate(brake, c) for k, c in ctrls.items()}


@pytest.fixture(scope="module")
def runs():
    return table2_runs()


def test_table2_through_the_api_matches_the_paper_and_the_problem_file(runs):
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.simulation.engine import simulate_many

    spec = load_spec(ROOT / "problems/paper_table2.toml")
    cli = simulate_many(spec.scenario, spec.controllers)
    for name, (aave, fuel) in TABLE2.items():
        m = lcc.metrics(runs[name], window=lcc.TABLE2_WINDOW)
        assert (round(m["aave"], 4), round(m["fuel_ml"], 2)) == (aave, fuel)
        np.testing.assert_array_equal(runs[name].velocity, cli[name].velocity)


def test_metric_window_is_explicit(runs):
    r = runs["cf_lcc"]
    with pytest.raises(TypeError):
        lcc.metrics(r)  # no silent (20, 40)
    with pytest.raises(TypeError):
        lcc.aave(r)
    wide = lcc.metrics(r, window=(20.0, 60.0))
    table = lcc.metrics(r, window=(20.0, 40.0))
    assert wide["aave"] < table["aave"]  # the wave has died down after 40 s
    assert float(lcc.aave(r, window=(20, 40))[0]) == table["aave"]
    assert float(lcc.fuel(r, window=(20, 40))[0]) == table["fuel_ml"]
    with pytest.raises(ConfigError, match="metrics.window"):
        lcc.metrics(r, window=(40.0, 20.0))


def _fresh_json(code: str):
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)  # fmt: skip
    return json.loads(out.stdout)


SIGNATURES = {  # what the functions are declared with, written here from api.py's source
    "metrics": ["result", "window", "vehicles"],
    "mpc": ["system", "name", "settings"],
    "system": ["kind", "m", "n", "v_star", "hdv", "size", "cavs", "hdv_values",
               "circumference", "vehicle_length"],
}  # fmt: skip


@pytest.mark.parametrize("order", ["modules_first", "names_first"])
def test_metrics_and_mpc_are_the_api_functions_whichever_python_bound_first(order):
    """Python binds ``lcc_synth.metrics`` (the module) on the package when it is imported; the
    top-level names stay the API's functions, with their own help and signature, and the
    modules still import by their path."""
    modules = "import lcc_synth.metrics, lcc_synth.mpc, lcc_synth.mpc.controller; "
    names = "lcc.metrics, lcc.mpc; "
    code = (
        "import inspect, json, pydoc, sys; import lcc_synth as lcc; "
        + (modules + names if order == "modules_first" else names + modules)
        + "from lcc_synth import api; from lcc_synth.metrics import summary; "
        "from lcc_synth.mpc import MPCController; "
        "print(json.dumps({n: {'is_api': getattr(lcc, n) is getattr(api, n), "
        "'function': inspect.isfunction(getattr(lcc, n)), "
        "'params': list(inspect.signature(getattr(lcc, n)).parameters), "
        "'help': pydoc.render_doc(getattr(lcc, n), renderer=pydoc.plaintext)} "
        "for n in ('metrics', 'mpc', 'system')} | "
        "{'modules': [type(sys.modules[m]).__name__ for m in ('lcc_synth.metrics', "
        "'lcc_synth.mpc')], 'summary': summary.__module__, 'mpc_class': MPCController.__name__}))"
    )
    out = _fresh_json(code)
    for name, params in SIGNATURES.items():
        assert out[name]["is_api"] and out[name]["function"], name
        assert out[name]["params"] == params, name
    assert "Every metric of a run" in out["metrics"]["help"]
    assert "Performance and safety metrics" not in out["metrics"]["help"]  # the module's
    assert "The safety-constrained MPC" in out["mpc"]["help"]
    assert "Safety-constrained model predictive control" not in out["mpc"]["help"]
    assert out["modules"] == ["module", "module"]  # plain modules, not made callable
    assert out["summary"] == "lcc_synth.metrics" and out["mpc_class"] == "MPCController"


def test_metrics_and_mpc_work_as_functions():
    from lcc_synth import api

    r = table2_runs()["all_hdv"]
    same = [json.dumps(f(r, window=(20, 40)), sort_keys=True) for f in (lcc.metrics, api.metrics)]
    assert same[0] == same[1]  # (NaN spacing of the head: compare the text)
    ctrl = lcc.mpc(table2_system(), horizon=20, n_model=4)
    assert ctrl.settings.horizon == 20 and ctrl.settings.n_model == 4
    with pytest.raises(ConfigError, match=r"controllers\.mpc\.horizn"):
        lcc.mpc(table2_system(), horizn=20)
    with pytest.raises(ConfigError, match=r"metrics\.window"):
        lcc.metrics(r, window=("a", 40))


def test_no_code_reaches_a_shadowed_module_through_the_package():
    """``import lcc_synth.metrics as m``, ``from lcc_synth import mpc`` and
    ``lcc_synth.mpc.<name>`` give the API's function, not the module: no code of the
    repository may use them (``from lcc_synth.metrics import ...`` is the way)."""
    import ast

    shadowed = ("metrics", "mpc")

    def through_package(node) -> bool:
        if isinstance(node, ast.Import):  # import lcc_synth.metrics as m
            return any(a.asname and a.name.split(".")[:2] in [["lcc_synth", s] for s in shadowed]
                       for a in node.names)  # fmt: skip
        if isinstance(node, ast.ImportFrom):  # from lcc_synth import metrics
            return node.module == "lcc_synth" and any(a.name in shadowed for a in node.names)
        if isinstance(node, ast.Attribute):  # lcc_synth.mpc.controller
            inner = node.value
            return (isinstance(inner, ast.Attribute) and inner.attr in shadowed
                    and isinstance(inner.value, ast.Name) and inner.value.id == "lcc_synth")
        return False

    found = [
        f"{path.relative_to(ROOT)}:{node.lineno}"
        for folder in ("lcc_synth", "tests", "examples", "benchmarks", "docs")
        for path in sorted((ROOT / folder).rglob("*.py"))
        for node in ast.walk(ast.parse(path.read_text(), str(path)))
        if through_package(node)
    ]
    probe = "import lcc_synth.metrics as mt\nfrom lcc_synth import mpc\nlcc_synth.mpc.controller\n"
    assert [through_package(n) for n in ast.walk(ast.parse(probe))].count(True) == 3
    assert found == []


def test_analysis_functions_agree_with_the_paper():
    rep = lcc.controllability(lcc.model("fd_lcc", n=10))
    assert rep.controllable  # Theorem 2, the paper's OVM at v* = 15
    case_d = {"s_-2": 1.0, "v_-2": -1.0, "s_-1": 1.0, "v_-1": -1.0,
              "s_1": -1.0, "v_1": -1.0, "s_2": -1.0, "v_2": -1.0}  # fmt: skip
    ss = lcc.string_stability(lcc.model("lcc", 2, 2), lcc.gains(case_d, semantics="added"))
    assert ss.plant_stable and ss.string_stable  # Table I, case D
    hdv = lcc.string_stability(lcc.model("lcc", 2, 2), lcc.gains({}, semantics="added"))
    assert not hdv.string_stable and hdv.gamma_peak == pytest.approx(1.13, abs=0.01)  # README
    short, long = (lcc.control_energy(lcc.model("fd_lcc", n=2), t) for t in (10.0, 20.0))
    assert 0 < short.lambda_min < long.lambda_min  # W(t) grows with the horizon
    assert short.trace_inv > long.trace_inv


def test_bad_input_names_the_field():
    with pytest.raises(ConfigError, match=r"system\.m"):
        lcc.system("fd_lcc", m=1, n=10)
    with pytest.raises(ConfigError, match=r"system\.v_star"):
        lcc.system("lcc", m=1, n=1, v_star=45.0)
    with pytest.raises(ConfigError, match=r"gains\.x_1"):
        lcc.gains({"x_1": 1.0}, semantics="added")
    with pytest.raises(ConfigError, match=r"semantics: must be one of \['added', 'replace'\]"):
        lcc.gains({"s_1": 1.0}, semantics="add")


def test_gains_state_their_semantics_wherever_a_user_gives_them():
    """Table II's CF-LCC gain is the whole command ("replace": string stable, the paper's
    Sec. V-B); read as "added" to the HDV law the same numbers give the opposite verdict, so
    a plain mapping (which does not say which) is refused with the way to say it."""
    cf = lcc.model("cf_lcc", n=10)
    replace = lcc.string_stability(cf, lcc.gains(PAPER_GAINS, semantics="replace"))
    added = lcc.string_stability(cf, lcc.gains(PAPER_GAINS, semantics="added"))
    assert replace.string_stable and not added.string_stable
    assert added.gamma_peak == pytest.approx(1.136, abs=5e-4)  # the measurement
    refused = 'write lcc.gains({...}, semantics="added"|"replace")'
    for call in (
        lambda: lcc.string_stability(cf, PAPER_GAINS),
        lambda: lcc.string_stability(cf, {}),
        lambda: lcc.region_map(lcc.model("lcc", 1, 1), 1, [0.0], [0.0], {"s_-1": 1.0}),
    ):
        with pytest.raises(ConfigError) as err:
            call()
        assert err.value.field == "gain" and refused in str(err.value)
        assert "\n" not in str(err.value)  # one line
    for call in (
        lambda: lcc.gains(PAPER_GAINS),
        lambda: lcc.static_controller(table2_system(), PAPER_GAINS, kind="cf_lcc"),
    ):
        with pytest.raises(ConfigError, match=r'^semantics: must be given with gains: "added"'):
            call()
    with pytest.raises(ConfigError, match="'added' contradicts the gains' 'replace'"):
        lcc.gains(lcc.gains(PAPER_GAINS, semantics="replace"), semantics="added")
    # a declared mapping (semantics=) or a gains object builds the same controller
    a = lcc.static_controller(table2_system(), PAPER_GAINS, semantics="replace", kind="cf_lcc")
    b = lcc.static_controller(table2_system(), lcc.gains(PAPER_GAINS, semantics="replace"),
                              kind="cf_lcc")  # fmt: skip
    assert a.as_dict() == b.as_dict() and a.gains.semantics == "replace"


def test_results_are_records_with_as_dict_and_a_short_repr(runs):
    r = runs["cf_lcc"]
    text = repr(r)
    assert text.startswith("SimResult(") and "\n" not in text and len(text) < 2000
    assert "shape=(1, 10000, 12)" in text
    sc = lcc.scenario(table2_system(), [lcc.Brake(vehicle=1)])
    d = sc.as_dict()
    assert d["perturbations"] == [{"vehicle": 1, "start": 20.0, "duration": 1.0, "decel": -5.0}]
    assert json.loads(json.dumps(d)) == d  # plain values
    ss = lcc.string_stability(lcc.model("lcc", 1, 1), lcc.gains({}, semantics="added"))
    assert repr(ss).startswith("StringStabilityReport(plant_stable=")
    assert json.dumps(ss.as_dict())
    assert repr(lcc.OVM()) == "OVM(alpha=0.6, beta=0.9, s_st=5, s_go=35, v_max=30, name='ovm')"
    assert repr(lcc.model("lcc", 2, 2)).startswith(
        "LCCModel(kind='lcc', m=2, n=2, A=array(shape=(10, 10), dtype=float64)"
    )


def test_record_writes_every_run(tmp_path, runs):
    from lcc_synth.recording import summarize_recording

    string = table2_system()
    mpc = lcc.mpc(string, n_model=4)
    short = lcc.scenario(string, [lcc.Brake(vehicle=1)], duration=22.0)
    results = {"all_hdv": runs["all_hdv"], "cf_lcc": runs["cf_lcc"],
               "mpc": lcc.simulate(short, mpc)}  # fmt: skip
    path = lcc.record(tmp_path / "t2.rrd", results, name="table2", window=(20, 22),
                      controllers={"mpc": mpc})  # fmt: skip
    entities = set(summarize_recording(path).entities)
    for name in results:
        assert f"/table2/{name}/velocity" in entities and f"/table2/{name}/metrics" in entities
    assert "/table2/mpc/mpc/solve_time_ms" in entities  # the MPC's own history
    assert not any(e.startswith("/table2/cf_lcc/mpc") for e in entities)


def _fresh(code: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)  # fmt: skip
    return json.loads(out.stdout)


def test_import_is_lazy():
    loaded = _fresh(
        "import json, sys; import lcc_synth; "
        f"print(json.dumps([m for m in {list(HEAVY) + ['numpy', 'lcc_synth.api']!r} "
        "if m in sys.modules]))"
    )
    assert loaded == []  # import lcc_synth: only lcc_synth.errors
    loaded = _fresh(
        "import json, sys; import lcc_synth as lcc; lcc.system; lcc.load_problem; "
        f"print(json.dumps([m for m in {list(HEAVY)!r} if m in sys.modules]))"
    )
    assert loaded == []  # the API itself: numpy and scipy.linalg only
    assert set(lcc.__all__) <= set(dir(lcc))
    with pytest.raises(AttributeError):
        lcc.no_such_name  # noqa: B018


def test_no_api_name_is_shadowed_by_a_module():
    import importlib
    import pkgutil
    import types

    from lcc_synth import api

    for info in pkgutil.iter_modules(lcc.__path__):  # Python binds each on the package
        importlib.import_module(f"lcc_synth.{info.name}")
    for name in api.__all__:
        obj = getattr(lcc, name)
        assert obj is getattr(api, name) and not isinstance(obj, types.ModuleType), name


@pytest.mark.slow  # CI runs it (and the docs build runs the example); by default: README's snippet
def test_paper_walkthrough_uses_only_the_top_level_api_and_prints_what_it_wrote(tmp_path):
    import ast

    script = ROOT / "examples/paper_walkthrough.py"
    for node in ast.walk(ast.parse(script.read_text())):
        if isinstance(node, ast.ImportFrom):
            assert not (node.module or "").startswith("lcc_synth"), node.module
        if isinstance(node, ast.Import):
            assert all(a.name == "lcc_synth" or "lcc_synth" not in a.name for a in node.names)
    env = {**__import__("os").environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    out = subprocess.run([sys.executable, str(script), "--out", str(tmp_path)], env=env,
                         capture_output=True, text=True, check=True).stdout  # fmt: skip
    wrote = [Path(line.split("wrote ", 1)[1]) for line in out.splitlines() if "wrote " in line]
    assert sorted(p.name for p in wrote) == ["walkthrough.json", "walkthrough.rrd",
                                             "walkthrough.toml"]  # fmt: skip
    assert all(p.is_file() and p.parent == tmp_path for p in wrote)
    assert "cf_lcc: AAVE 0.8129 m/s, fuel 340.56 mL" in out  # Table II, CF-LCC
    assert " all_hdv: AAVE 0.8928 m/s, fuel 392.86 mL" in out  # Table II, all HDVs
    objs = lcc.load_problem(tmp_path / "walkthrough.toml")  # a file the CLI runs
    assert list(objs.controllers) == ["all_hdv", "cf_lcc", "h2", "mpc"]
