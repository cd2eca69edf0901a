"""The problem-file schema: one declaration drives the loaders, their errors and the reference.

Independent truths: the code's own dataclasses and constants (the MPC settings, the H2
weights, the synthesis spec, the model families...), the loaders' behaviour on files built
from the declaration (every bound, choice and key name checked through the real loaders), the
shipped problem files (every declared key is read by some loader while loading them and a small
coverage corpus), and the source itself (no loader reads a key around the schema).
"""

from __future__ import annotations

import ast
import json
import re
import tomllib
from dataclasses import MISSING, fields
from pathlib import Path

import pytest
from test_strict_problems import PROBLEMS, ROOT
from test_strict_problems import (
    test_shipped_problem_files_load_with_every_reader as load_with_every_reader,
)

from lcc_synth import schema
from lcc_synth.errors import ConfigError
from lcc_synth.problem import Problem, load_problem, system_from
from lcc_synth.schema import READS, TABLES, Derived, Key, Table, UndeclaredKeyError, declared
from lcc_synth.schema.readers import REQUIRED, fmt_range

PACKAGE = ROOT / "lcc_synth"
REFERENCE = PROBLEMS / "REFERENCE.md"

# --------------------------------------------------------------------------------------------
# The reference page
# --------------------------------------------------------------------------------------------


def test_committed_reference_is_current():
    """``problems/REFERENCE.md`` is what ``python -m lcc_synth.schema`` prints now."""
    assert REFERENCE.read_text() == schema.reference_markdown(), (
        "problems/REFERENCE.md is stale: python -m lcc_synth.schema > problems/REFERENCE.md"
    )


def test_reference_lists_every_table_and_key_with_its_meaning():
    text = schema.reference_markdown()
    for t in TABLES.values():
        assert t.meaning.strip(), t.id
        for k in (*t.keys, *([t.any_key] if t.any_key else [])):
            row = [line for line in text.splitlines() if line.startswith(f"| `{k.name}` |")]
            assert any(k.meaning.replace("|", "\\|") in line for line in row), (t.id, k.name)


def test_h2_weight_defaults_are_documented():
    """The issue's example: q_s = 1, q_a = 0 in code, written nowhere before."""
    from lcc_synth.synthesis.h2 import Weights

    text = REFERENCE.read_text()
    section = text[text.index("## `[synthesis.weights]`") :]
    section = section[: section.index("\n## ")]
    assert f"| `q_s` | number | `{Weights().q_s!r}` |" in section
    assert f"| `q_a` | number | `{Weights().q_a!r}` |" in section


def test_a_key_without_meaning_cannot_be_declared():
    with pytest.raises(ValueError, match="meaning"):
        Key("x", "number", " ")
    with pytest.raises(ValueError, match="type"):
        Key("x", "float", "A number.")
    with pytest.raises(ValueError, match="twice"):
        Table("t", "T.", ("simulate",), (Key("x", "number", "X."), Key("x", "number", "X.")))


# --------------------------------------------------------------------------------------------
# A key cannot be read without being declared
# --------------------------------------------------------------------------------------------


def test_reading_an_undeclared_key_raises():
    with pytest.raises(UndeclaredKeyError, match="newkey"):
        declared("scenario").get({"newkey": 1.0}, "newkey", "scenario")
    with pytest.raises(UndeclaredKeyError):
        declared("scenario").raw({}, "newkey")
    with pytest.raises(UndeclaredKeyError):
        declared("no_such_table")


def test_only_derived_values_may_be_passed_by_a_loader():
    sc = declared("scenario")
    with pytest.raises(TypeError, match="declared in the schema"):
        sc.get({}, "dt", "scenario", default=0.02)
    with pytest.raises(TypeError, match="derived"):
        declared("scenario.perturbations:sine").get({}, "end", "p")
    assert declared("scenario.perturbations:sine").get({}, "end", "p", default=5.0, lo=1.0) == 5.0


_READERS = {"get_number", "get_int", "get_bool", "get_str", "get_table", "get_number_list",
            "check_keys", "get_number_range"}  # fmt: skip
#: Functions outside the schema allowed to call a reader: generic helpers with no key of their own.
_ALLOWED = {("problem.py", "table"), ("problem.py", "check_keys")}


def _direct_reads(source: str, name: str = "<src>") -> list[str]:
    """Calls of the typed readers in ``source`` (outside the allowed helpers)."""
    found = []

    def visit(node, func: str):
        for child in ast.iter_child_nodes(node):
            inner = child.name if isinstance(child, ast.FunctionDef) else func
            if isinstance(child, ast.Call):
                f = child.func
                called = f.id if isinstance(f, ast.Name) else getattr(f, "attr", None)
                if called in _READERS and (name, func) not in _ALLOWED:
                    found.append(f"{name}:{child.lineno} {called}() in {func or 'module'}")
            visit(child, inner)

    visit(ast.parse(source), "")
    return found


def test_the_reader_scan_finds_a_direct_read():
    """The scan below would catch a loader reading a new key around the schema."""
    src = 'def load(t):\n    return get_number(t, "newkey", "scenario", 1.0, lo=0.0)\n'
    assert _direct_reads(src) == ["<src>:2 get_number() in load"]
    assert _direct_reads("x = problem.get_int(t, 'n', 's', 0)\n") == ["<src>:1 get_int() in module"]


def test_no_loader_reads_a_key_around_the_schema():
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE)
        if rel.parts[0] == "schema":
            continue
        found += _direct_reads(path.read_text(), str(rel))
    assert not found, found


def _table_candidates(node: ast.AST) -> list[str] | None:
    """The declared table ids a ``declared(...)`` call can name (an f-string: every match)."""
    if not (isinstance(node, ast.Call) and getattr(node.func, "id", None) == "declared"):
        return None
    arg = node.args[0]
    if isinstance(arg, ast.Constant):
        return [arg.value] if arg.value in TABLES else []
    if isinstance(arg, ast.JoinedStr):
        pattern = "".join(
            re.escape(v.value) if isinstance(v, ast.Constant) else ".+" for v in arg.values
        )
        return [i for i in TABLES if re.fullmatch(pattern, i)]
    return []


def _undeclared_names(source: str, name: str = "<src>") -> tuple[list[str], int]:
    """``declared(ID)`` calls naming no table and ``T.get(table, "key", ...)`` /
    ``T.raw(table, "key")`` calls naming a key ``T`` does not declare; and how many were
    checked."""
    checked, bad, seen = 0, [], set()
    tree = ast.parse(source)
    funcs = [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)]
    for func in [*reversed(funcs), tree]:  # innermost first
        bound: dict[str, list[str]] = {}
        for node in ast.walk(func):
            if isinstance(node, ast.Assign) and len(node.targets) == 1:
                ids = _table_candidates(node.value)
                if ids is not None and isinstance(node.targets[0], ast.Name):
                    bound[node.targets[0].id] = ids
        for node in ast.walk(func):
            if id(node) in seen:  # checked in its innermost function
                continue
            seen.add(id(node))
            ids = _table_candidates(node)
            if ids is not None and not ids:
                bad.append(f"{name}:{node.lineno}: declared() names no table")
            if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)):
                continue
            if node.func.attr not in ("get", "raw") or len(node.args) < 2:
                continue
            owner = node.func.value
            ids = bound.get(owner.id) if isinstance(owner, ast.Name) else _table_candidates(owner)
            key = node.args[1]
            if not ids or not isinstance(key, ast.Constant):
                continue
            checked += 1
            if not any(key.value in TABLES[i].names for i in ids):
                bad.append(f"{name}:{node.lineno}: {key.value!r} not in {ids}")
    return bad, checked


def test_the_key_scan_finds_an_undeclared_key():
    src = (
        'def load(sc):\n    S = declared("scenario")\n    S.get(sc, "dt", "scenario")\n'
        '    return S.get(sc, "newkey", "scenario"), declared("nope")\n'
    )
    bad, checked = _undeclared_names(src)
    assert checked == 2
    assert sorted(bad) == [
        "<src>:4: 'newkey' not in ['scenario']",
        "<src>:4: declared() names no table",
    ]


def test_every_key_a_loader_names_is_declared():
    """Statically, also on branches no file reaches: ``declared(ID)`` names a table and
    ``T.get(table, "key", ...)`` / ``T.raw(table, "key")`` a key of it."""
    checked, bad = 0, []
    for path in sorted(PACKAGE.rglob("*.py")):
        b, c = _undeclared_names(path.read_text(), path.name)
        bad += b
        checked += c
    assert not bad, bad
    assert checked > 100  # the loaders are really scanned


# --------------------------------------------------------------------------------------------
# Every declared key is read by a loader (no dead declaration)
# --------------------------------------------------------------------------------------------

#: Tables whose keys a loader outside the schema reads by their own rules.
_READ_ELSEWHERE = {
    "hdv": "lcc_synth.models.hdv.model_from_dict (declared from the model dataclasses, below)",
    "controllers.NAME.layouts.LAYOUT": "merged into the controller, then read as its type",
    "controllers.NAME.gains": "state names checked by Gains against the model",
}

_COVERAGE_SIMULATE = """
[system]
kind = "cf_lcc"
n = 2
[scenario]
duration = 45.0
[scenario.hdv_values]
alpha = [0.6, 0.6]
[scenario.v2v]
loss_rate = [0.0, 0.0, 0.1, 0.1]
[[scenario.perturbations]]
type = "accel_profile"
times = [20.0, 22.0]
values = [-1.0, 0.0]
interpolation = "linear"
[[scenario.perturbations]]
type = "speed_profile"
vehicle = 1
times = [20.0, 25.0]
values = [15.0, 14.0]
[[scenario.perturbations]]
type = "speed_profile"
vehicle = 2
csv = "speed.csv"
[controllers.est]
type = "static"
semantics = "replace"
gains = { s_0 = 0.1, v_0 = -0.5, s_1 = -0.2, v_1 = 0.05, s_2 = -0.1, v_2 = 0.05 }
equilibrium = "estimated"
equilibrium_tau = 2.0
[controllers.file]
type = "gains_file"
file = "gains.json"
equilibrium = "estimated"
equilibrium_tau = 1.0
"""

_COVERAGE_SYNTHESIZE = """
[system]
kind = "cf_lcc"
n = 2
[synthesis]
pattern = [1, 2]
[synthesis.as_run]
equilibrium = "estimated"
equilibrium_tau = 1.0
sample_time = 0.1
dt = 0.01
latency = 0.0
measurement_filter = 0.0
margin = 1e-3
weight = 0.0
polish_steps = 10
"""

_COVERAGE_RECORDED = """
[system]
kind = "platoon"
size = 2
cavs = [2]
v_star = 10.0
vehicle_length = 5.0
[scenario]
duration = 0.3
dt = 0.01
initial = "data"
[[scenario.perturbations]]
type = "trajectory"
vehicle = "head"
file = "platoon.csv"
column = "v0"
interpolation = "previous"
start = 0.0
[metrics]
window = [0.0, 0.2]
[controllers.replay]
type = "hdv"
"""

_COVERAGE_REGIONS = """
[system]
kind = "lcc"
m = 1
n = 1
[maps.a]
vehicle = 1
mu = [-1.0, 1.0]
k = [-1.0, 1.0]
step = 0.5
"""


def _load_coverage_corpus(tmp: Path) -> None:
    from lcc_synth.analysis.region_specs import region_specs_from
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.synthesis.config import spec_from_problem

    (tmp / "speed.csv").write_text("t,v\n20,15\n25,14\n")
    gains = {"kind": "cf_lcc", "m": 0, "n": 2, "semantics": "replace",
             "state_names": ["s_0", "v_0", "s_1", "v_1", "s_2", "v_2"],
             "K": [0.1, -0.5, -0.2, 0.0, 0.0, 0.0],  # a gains file's K is required (issue 28)
             "gains": {"s_0": 0.1, "v_0": -0.5, "s_1": -0.2}}  # fmt: skip
    (tmp / "gains.json").write_text(json.dumps(gains))
    for name, text in (("sim", _COVERAGE_SIMULATE), ("syn", _COVERAGE_SYNTHESIZE),
                       ("reg", _COVERAGE_REGIONS)):  # fmt: skip
        (tmp / f"{name}.toml").write_text(text)
    (tmp / "platoon.csv").write_text("t,v0,headway0,v1,headway1,v2,headway2\n"
                                     "0.0,10,0,10,30,10,30\n0.1,10,0,10,30,10,30\n"
                                     "0.2,10,0,10,30,10,30\n")
    (tmp / "rec.toml").write_text(_COVERAGE_RECORDED)
    assert load_spec(tmp / "rec.toml").scenario.initial_state[0][1:] == (25.0, 25.0)
    spec = load_spec(tmp / "sim.toml")
    assert spec.scenario.v2v.loss_rate[3] == 0.1 and len(spec.scenario.perturbations) == 3
    assert spec_from_problem(load_problem(tmp / "syn.toml")).as_run.polish_steps == 10
    prob = load_problem(tmp / "reg.toml")
    model = system_from(prob.data).linear_model(warn=False)
    specs, _ = region_specs_from(prob.data, model)
    assert len(specs["a"].mu) == 5
    platoon = {"system": {"kind": "platoon", "size": 4, "cavs": [2, 4]},
               "maps": {"b": {"cav": 4, "vehicle": 3, "gains": {"u_2": {"s_1": 0.5}}}}}
    model = system_from(platoon).linear_model(warn=False)
    assert region_specs_from(platoon, model)[0]["b"].cav == 4
    from lcc_synth.controllers.baseline_tables import baseline_from_table

    for kind, table in (
        ("follower_stopper", {"U": 7.5, "dx0": [4.5, 5.25, 6.0], "d": [1.5, 1.0, 0.5]}),
        ("pi_saturation", {"window": 38.0, "g_l": 7.0, "g_u": 30.0, "v_catch": 1.0,
                           "gamma": 2.0, "dx_s_min": 4.0}),
        ("acc", {"k_s": 0.23, "k_v": 0.07, "h": 1.1, "s0": 2.0}),
        ("cacc", {"h": 0.7, "k_p": 0.2, "k_d": 0.7, "r": 2.0}),
    ):
        table = {"type": kind, "sample_time": 0.1, "length": 0.0, **table}
        assert baseline_from_table("b", kind, table).kind == kind
    platoon = {"kind": "platoon", "size": 3, "cavs": [2], "hdv_values": {"alpha": [0.5, 0.6, 0.7]}}
    assert system_from({"system": platoon}).platoon.cavs == (2,)
    ring = {"kind": "ring", "size": 4, "circumference": 80.0}
    assert system_from({"system": ring}).platoon.length == 80.0
    robust = {"samples": 3, "seed": 1, "objective": "worst", "alpha": [0.5, 0.7],
              "beta": [0.8, 1.0], "s_go": [33.0, 37.0]}  # fmt: skip
    syn = {"name": "cov", "system": {"kind": "platoon", "size": 4, "cavs": [2]},
           "synthesis": {"patterns": {"u_2": [1, 3]}, "robust": robust}}  # fmt: skip
    assert spec_from_problem(Problem(tmp / "p.toml", syn)).patterns == {2: (1, 2, 3)}


def test_every_declared_key_is_read_by_a_loader(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # DeeP-LCC's data cache (results/deeplcc) goes here, not the repo
    for path in sorted(PROBLEMS.glob("*.toml")):
        load_with_every_reader(path)
    _load_coverage_corpus(tmp_path)
    read = set()
    for t in TABLES.values():
        for k in (*t.keys, *([t.any_key] if t.any_key else [])):
            if (t.id, k.name) in READS:
                read.add(id(k))  # a key shared by several tables is read once
    dead = [
        f"{t.id}.{k.name}"
        for t in TABLES.values()
        if t.id not in _READ_ELSEWHERE
        for k in (*t.keys, *([t.any_key] if t.any_key else []))
        if id(k) not in read
    ]
    assert not dead, f"declared but read by no loader: {dead}"


def test_hdv_declaration_is_the_models():
    from lcc_synth.models.hdv import MODELS
    from lcc_synth.simulation.scenario import MODEL_PARAMS

    hdv = declared("hdv")
    assert set(hdv.key("model").choices) == set(MODELS)
    params = {f.name: f.default for cls in MODELS.values() for f in fields(cls) if f.name != "name"}
    assert {k.name: k.default for k in hdv.keys if k.name != "model"} == params
    assert {p for ps in MODEL_PARAMS.values() for p in ps} == set(params)


# --------------------------------------------------------------------------------------------
# The declaration agrees with the code it documents
# --------------------------------------------------------------------------------------------


def _dataclass_defaults(cls) -> dict:
    out = {}
    for f in fields(cls):
        if f.default is not MISSING:
            out[f.name] = f.default
        elif f.default_factory is not MISSING:
            out[f.name] = f.default_factory()
    return out


def test_mpc_defaults_are_the_settings_dataclasses():
    from lcc_synth.mpc import settings as ms

    for sub, cls in (("weights", ms.Weights), ("constraints", ms.Constraints),
                     ("prediction", ms.Prediction), ("solver", ms.SolverSettings)):  # fmt: skip
        t = declared(f"controllers.NAME.{sub}:mpc")
        declared_defaults = {k.name: k.default for k in t.keys}
        declared_defaults = {k: tuple(v) if isinstance(v, list) else v
                             for k, v in declared_defaults.items()}  # fmt: skip
        assert declared_defaults == _dataclass_defaults(cls), sub
    top = declared("controllers.NAME:mpc")
    d = _dataclass_defaults(ms.MPCSettings)
    for key in ("sample_time", "horizon", "n_model", "fallback_gains_file"):
        assert top.key(key).default == d[key], key
    assert {"weights", "constraints", "prediction", "solver"} <= set(d) & set(top.names)
    assert set(declared("controllers.NAME.weights:mpc").key("input_on").choices) == set(
        ms.INPUT_ON
    )
    assert set(declared("controllers.NAME.prediction:mpc").key("head").choices) == set(
        ms.HEAD_PREDICTIONS
    )
    assert set(declared("controllers.NAME.prediction:mpc").key("equilibrium").choices) == set(
        ms.EQUILIBRIA
    )


def test_synthesis_defaults_are_the_code():
    from lcc_synth.synthesis.as_run import AsRunSettings
    from lcc_synth.synthesis.config import SynthesisSpec
    from lcc_synth.synthesis.h2 import Weights

    w = declared("synthesis.weights")
    assert {k.name: k.default for k in w.keys} == _dataclass_defaults(Weights)
    spec = _dataclass_defaults(SynthesisSpec)
    syn = declared("synthesis")
    for key in ("tol", "max_iter", "band"):
        assert syn.key(key).default == spec[key], key
    # cross_check: the dataclass's default is one CAV's; a platoon or ring opts in
    assert isinstance(syn.key("cross_check").default, Derived) and spec["cross_check"] is True
    string = declared("synthesis.string")
    assert string.key("gamma").default == spec["string_gamma"]
    assert string.key("polish_steps").default == spec["polish_steps"]
    assert string.key("margin").default == spec["string_margin"]
    ar = _dataclass_defaults(AsRunSettings)
    for k in declared("synthesis.as_run").keys:
        if k.name in ar and k.name not in ("equilibrium_tau",):
            assert k.default == ar[k.name], k.name


def test_choices_are_the_code_constants():
    from lcc_synth.analysis.regions import DEFAULT_DENSE_PER_DECADE, DEFAULT_PER_DECADE
    from lcc_synth.controllers.registry import STATIC_RUN_KEYS
    from lcc_synth.controllers.static import EQUILIBRIA
    from lcc_synth.experiments.comparison import SUITE_TYPES
    from lcc_synth.experiments.controller_tables import CONTROLLER_TYPES
    from lcc_synth.metrics import VEHICLE_SETS
    from lcc_synth.models.feedback import SEMANTICS
    from lcc_synth.models.linear import KINDS
    from lcc_synth.models.platoon import PLATOON_KINDS

    assert declared("system").key("kind").choices == (*KINDS, *PLATOON_KINDS)
    assert declared("controllers.NAME:static").key("kind").choices == (*KINDS, *PLATOON_KINDS)
    assert set(declared("controllers.NAME").key("type").choices) == set(CONTROLLER_TYPES)
    assert set(declared("controllers.NAME:suite").key("type").choices) == set(SUITE_TYPES)
    for tid in ("controllers.NAME:static", "synthesis", "synthesis.baseline", "cases.NAME",
                "maps.NAME"):  # fmt: skip
        assert set(declared(tid).key("semantics").choices) == set(SEMANTICS), tid
    assert set(declared("controllers.NAME:static").key("equilibrium").choices) == set(EQUILIBRIA)
    for tid in ("controllers.NAME:static", "controllers.NAME:gains_file", "controllers.NAME:h2"):
        assert set(STATIC_RUN_KEYS) <= set(declared(tid).names), tid
    assert all(v in declared("metrics").key("vehicles").meaning for v in VEHICLE_SETS)
    regions = declared("regions")
    assert regions.key("per_decade").default == DEFAULT_PER_DECADE
    assert regions.key("dense_per_decade").default == DEFAULT_DENSE_PER_DECADE
    pert = declared("scenario.perturbations").key("type").choices
    assert {i.split(":")[1] for i in TABLES if i.startswith("scenario.perturbations:")} == set(
        pert
    )


# --------------------------------------------------------------------------------------------
# The loaders' validation and messages come from the declaration
# --------------------------------------------------------------------------------------------


def _base(name: str) -> dict:
    return tomllib.loads((PROBLEMS / name).read_text())


def _loader(tid: str):
    """``(run(table), field prefix)``: a real loader fed ``table`` as the table ``tid``."""
    from lcc_synth.analysis.cases import analysis_options_from
    from lcc_synth.analysis.region_specs import region_specs_from
    from lcc_synth.experiments.sweep import load_sweep
    from lcc_synth.metrics import metrics_from
    from lcc_synth.mpc.settings import settings_from_table
    from lcc_synth.simulation.scenario_file import scenario_from
    from lcc_synth.synthesis.config import spec_from_problem

    if tid in ("scenario", "scenario.delay", "scenario.v2v", "system"):
        def run(t):
            data = _base("paper_table2.toml")
            if tid == "system":
                data["system"] = {"kind": "lcc", "m": 1, "n": 1, **t}
                return system_from(data)
            sc = data["scenario"]
            if tid == "scenario":
                sc.update(t)
            else:
                sc[tid.split(".")[1]] = t
            return scenario_from(data, system_from(data))
        return run, tid
    if tid == "metrics":
        data = _base("paper_table2.toml")
        return (lambda t: metrics_from({"metrics": t}, system_from(data))), "metrics"
    if tid == "sweep":
        def run(t):
            data = _base("sweep_robustness.toml")
            data["sweep"] = t
            return load_sweep(Problem(PROBLEMS / "sweep_robustness.toml", data))
        return run, "sweep"
    if tid.endswith(":mpc"):
        sub = tid.split(":")[0].split(".")[2:]

        def run(t):
            table = {"type": "mpc", sub[0]: t} if sub else {"type": "mpc", **t}
            return settings_from_table(table, "controllers.mpc")
        return run, "controllers.mpc" + "".join(f".{s}" for s in sub)
    if tid.startswith("synthesis"):
        def run(t):
            data = _base("synth_cf_lcc_pattern.toml")
            syn = data["synthesis"]
            if tid == "synthesis":
                syn.update(t)
            else:
                syn[tid.split(".")[1]] = t
            return spec_from_problem(Problem(PROBLEMS / "synth_cf_lcc_pattern.toml", data))
        return run, tid
    if tid == "analysis":
        return (lambda t: analysis_options_from({"analysis": t})), "analysis"
    if tid == "regions":
        data = {"system": {"kind": "lcc", "m": 1, "n": 1}, "maps": {"a": {"vehicle": 1}}}
        model = system_from(data).linear_model(warn=False)
        return (lambda t: region_specs_from({**data, "regions": t}, model, step=0.5)), "regions"
    return None, None


_CHECKED = ["system", "scenario", "scenario.delay", "scenario.v2v", "metrics", "sweep",
            "controllers.NAME:mpc", "controllers.NAME.weights:mpc",
            "controllers.NAME.constraints:mpc", "controllers.NAME.prediction:mpc",
            "controllers.NAME.solver:mpc", "synthesis", "synthesis.weights", "synthesis.sparsity",
            "synthesis.string", "synthesis.as_run", "analysis", "regions"]  # fmt: skip


def _outside(k: Key):
    """Values just outside ``k``'s declared bounds."""
    step = 1 if k.type == "integer" else 1.0
    out = []
    if isinstance(k.lo, int | float):
        out.append(k.lo if k.lo_open else k.lo - step)
    if isinstance(k.hi, int | float):
        out.append(k.hi if k.hi_open else k.hi + step)
    return out


@pytest.mark.parametrize("tid", _CHECKED)
def test_bounds_choices_and_names_of_every_key_reach_the_loader(tid):
    """Each declared bound, choice list and key name is what the real loader enforces: a value
    just outside a bound, a string outside the choices and a misspelt key are ConfigErrors
    naming the dotted field, with the declared range, choices or the key as suggestion."""
    run, prefix = _loader(tid)
    run({})  # every default is valid
    t = declared(tid)
    bounds = choices = 0
    for k in t.keys:
        if k.name == "type":  # checked by controller_from_table before the MPC's loader runs
            continue
        field = f"{prefix}.{k.name}"
        if k.type in ("number", "integer") and k.name != "spread":
            for bad in _outside(k):
                with pytest.raises(ConfigError) as e:
                    run({k.name: bad})
                lo = k.lo if isinstance(k.lo, int | float) else None
                hi = k.hi if isinstance(k.hi, int | float) else None
                expect = fmt_range(lo, hi, k.lo_open if k.type == "number" else 0,
                                   k.hi_open if k.type == "number" else 0)  # fmt: skip
                assert e.value.field == field and expect in e.value.message, (field, bad)
                bounds += 1
        if k.type == "string" and isinstance(k.choices, tuple):
            with pytest.raises(ConfigError) as e:
                run({k.name: "no_such_choice"})
            assert e.value.field == field, field
            assert str(sorted(k.choices)) in e.value.message, field
            choices += 1
        if k.default is REQUIRED or isinstance(k.default, Derived):
            continue
        with pytest.raises(ConfigError) as e:
            run({f"{k.name}x": 1.0})
        assert e.value.field == f"{prefix}.{k.name}x", k.name
        assert f"did you mean {k.name!r}?" in e.value.message, (k.name, e.value.message)
    assert bounds + choices > 0 or tid in ("metrics", "synthesis.sparsity")


# --------------------------------------------------------------------------------------------
# The hand-written examples name only declared keys
# --------------------------------------------------------------------------------------------


def _tables_for(header: str) -> list[Table]:
    """The declared tables a concrete header (``controllers.all_hdv.weights``) can be."""
    parts = header.split(".") if header else []
    out = []
    for t in TABLES.values():
        pat = t.path.split(".") if t.path else []
        if len(pat) == len(parts) and all(
            p == q or p.isupper() for p, q in zip(pat, parts, strict=True)
        ):
            out.append(t)
    return out


def _example_keys(markdown: str) -> list[tuple[str, str]]:
    """``(table, key)`` of every ``key = value`` line in the TOML blocks of ``markdown``."""
    out = []
    for block in re.findall(r"```toml\n(.*?)```", markdown, flags=re.S):
        header = ""
        for line in block.splitlines():
            if m := re.match(r"\[\[?([\w.]+)\]?\]", line):
                header = m.group(1)
            elif m := re.match(r"([A-Za-z_]\w*)\s*=", line):
                out.append((header, m.group(1)))
    return out


@pytest.mark.parametrize("page", ["problems/README.md", "docs/guide/*.md"])
def test_every_key_of_the_examples_is_declared(page):
    pairs = _example_keys("\n".join(p.read_text() for p in sorted(ROOT.glob(page))))
    assert len(pairs) > 20
    bad = []
    for header, key in pairs:
        tables = _tables_for(header)
        names = set()
        for t in tables:
            names |= set(t.names) | {n for i in t.includes for n in TABLES[i].names}
        if not any(t.any_key for t in tables) and key not in names:
            bad.append(f"[{header}] {key}")
    assert not bad, f"{page} shows keys the schema does not declare: {bad}"
