"""The comparison suite (``lcc-synth run``) on a shortened problem: every number of its table
must equal a direct ``simulate`` + ``metrics`` call with independently built controllers."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from cli_subprocess import PAPER_HDV

from lcc_synth.cli.main import main
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.comparison import controller_table, load_suite, run_suite
from lcc_synth.experiments.controller_tables import controller_from_table
from lcc_synth.experiments.tables import (
    SUITE_METRICS,
    format_table,
    markdown_table,
    write_csv,
    write_json,
)
from lcc_synth.metrics import (
    aave,
    aeb_activations,
    collisions,
    fuel,
    max_abs_command,
    min_spacing,
    min_time_to_collision,
)
from lcc_synth.problem import Problem, load_problem
from lcc_synth.simulation.engine import simulate

SHORT = """
name = "short_suite"

""" + PAPER_HDV + """
[metrics]
window = [5.0, 20.0]

[layouts.tail3]
kind = "cf_lcc"
m = 0
n = 3
v_star = 15.0

[layouts.mid]
kind = "lcc"
m = 1
n = 1
v_star = 15.0

[scenarios.brake]
layout = "tail3"
duration = 20.0
metrics = { window = [5.0, 15.0] }

[[scenarios.brake.perturbations]]
type = "brake"
vehicle = 1
start = 5.0
duration = 1.0
decel = -5.0

[scenarios.sine]
layout = "mid"
duration = 20.0

[[scenarios.sine.perturbations]]
type = "sine"
amplitude = 0.5
period = 6.0
start = 5.0

[scenarios.noisy]
layout = "tail3"
duration = 20.0
seed = 3
hdv_accel_noise = 0.2
heterogeneity = { alpha = 0.1 }
delay = { mean = 0.3, spread = 0.1 }
v2v = { loss_rate = 0.3, latency = 0.05 }

[[scenarios.noisy.perturbations]]
type = "brake_profile"
start = 5.0
decel = -4.0
decel_time = 1.0
hold_time = 2.0
accel = 2.0
accel_time = 2.0

[controllers.all_hdv]
type = "hdv"

[controllers.paper]
type = "static"

[controllers.paper.layouts.tail3]
kind = "cf_lcc"
semantics = "replace"
gains = { s_0 = 0.1, v_0 = -0.5, s_1 = -0.2, v_1 = 0.05 }

[controllers.paper.layouts.mid]
semantics = "added"
gains = { s_-1 = 1.0, v_-1 = -1.0, s_1 = -1.0, v_1 = -1.0 }

[controllers.h2]
type = "h2"
design = "structured"
semantics = "replace"
pattern = [1]

[controllers.h2.weights]
q_s = 0.1
q_v = 1.0
accel = 1.0

[controllers.h2.layouts.mid]
semantics = "added"
weights = { head = 1.0 }

[controllers.mpc]
type = "mpc"
sample_time = 0.1
horizon = 15
"""


@pytest.fixture(scope="module")
def problem_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("suite") / "short.toml"
    path.write_text(SHORT)
    return path


@pytest.fixture(scope="module")
def suite_run(problem_file):
    suite = load_suite(problem_file)
    return suite, run_suite(suite, progress=False)


def _direct_h2(problem_file: Path, layout: str):
    """The h2 gain synthesised straight from the synthesis package (no comparison code)."""
    from lcc_synth.synthesis.config import spec_from_problem
    from lcc_synth.synthesis.design import synthesize

    data = load_problem(problem_file).data
    synth = {"design": "structured", "semantics": "replace", "pattern": [1],
             "weights": {"q_s": 0.1, "q_v": 1.0, "accel": 1.0}}
    if layout == "mid":
        synth["semantics"] = "added"
        synth["weights"] = {**synth["weights"], "head": 1.0}
    prob = Problem(problem_file, {"name": "direct", "hdv": data["hdv"],
                                  "system": data["layouts"][layout], "synthesis": synth})
    return synthesize(spec_from_problem(prob))


def test_suite_table_equals_direct_simulation(suite_run, problem_file):
    suite, run = suite_run
    data = load_problem(problem_file).data
    assert list(run.table) == ["brake", "sine", "noisy"]
    for per in run.table.values():
        assert list(per) == ["all_hdv", "paper", "h2", "mpc"]
    for sname, ss in suite.scenarios.items():
        layout = data["scenarios"][sname]["layout"]
        system = suite.layouts[layout]
        rep = _direct_h2(problem_file, layout)
        paper = dict(data["controllers"]["paper"]["layouts"][layout], type="static")
        direct = {
            "all_hdv": controller_from_table("all_hdv", {"type": "hdv"}, system),
            "paper": controller_from_table("paper", paper, system),
            "h2": controller_from_table(
                "h2",
                {"type": "static", "kind": rep.kind, "semantics": rep.semantics,
                 "gains": rep.gains},
                system,
            ),
            "mpc": controller_from_table(
                "mpc", {"type": "mpc", "sample_time": 0.1, "horizon": 15}, system
            ),
        }
        w = tuple(data["scenarios"][sname].get("metrics", {}).get("window", [5.0, 20.0]))
        for cname, ctrl in direct.items():
            res = simulate(ss.scenario, ctrl)  # its own draws: identical by seed
            row = run.table[sname][cname]
            expect = {
                "aave": float(aave(res, w)[0]),
                "fuel_ml": float(fuel(res, w)[0]),
                "min_spacing": float(np.nanmin(min_spacing(res)[0, 1:])),
                "min_ttc": float(np.nanmin(min_time_to_collision(res)[0, 1:])),
                "max_abs_command": float(max_abs_command(res)[0]),
                "aeb_activations": int(aeb_activations(res)[0]),
                "collisions": int(collisions(res)[0]),
            }
            assert set(row) == {*SUITE_METRICS, "collided", "failed_steps"}
            stats = res.controller_stats or {}  # the MPC's fallbacks and errors, 0 for the rest
            assert row["failed_steps"] == stats.get("fallbacks", 0) + stats.get("errors", 0)
            for key, value in expect.items():
                assert row[key] == pytest.approx(value, rel=1e-12, abs=0), (sname, cname, key)


def test_controllers_are_built_per_layout(suite_run):
    suite, run = suite_run
    # the paper's gains come from each layout's override, the h2 gain is designed per layout
    assert run.tables["tail3"]["paper"]["gains"] == {"s_0": 0.1, "v_0": -0.5, "s_1": -0.2,
                                                      "v_1": 0.05}
    assert run.tables["mid"]["paper"]["semantics"] == "added"
    d_tail, d_mid = run.designs["tail3"]["h2"], run.designs["mid"]["h2"]
    assert (d_tail.m, d_tail.n, d_tail.kind) == (0, 3, "cf_lcc")
    assert (d_mid.m, d_mid.n, d_mid.kind) == (1, 1, "lcc")
    # the pattern (CAV + HDV 1) is respected exactly: zeros elsewhere
    for d in (d_tail, d_mid):
        for state, g in d.gains.items():
            vehicle = int(state.split("_", 1)[1])
            if vehicle not in (0, 1):
                assert g == 0.0, state
    assert run.controllers["mid"]["mpc"].m == 1


def test_controller_table_merges_recursively():
    table = {"type": "h2", "weights": {"q_s": 0.1, "accel": 1.0},
             "layouts": {"a": {"weights": {"head": 1.0}, "semantics": "added"}}}
    assert controller_table(table, "a") == {
        "type": "h2", "weights": {"q_s": 0.1, "accel": 1.0, "head": 1.0}, "semantics": "added"
    }
    assert controller_table(table, "b") == {"type": "h2", "weights": {"q_s": 0.1, "accel": 1.0}}


def test_writers_round_trip(suite_run, tmp_path):
    _, run = suite_run
    path = write_csv(run.table, tmp_path / "t.csv")
    with path.open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 12
    for r in rows:
        src = run.table[r["scenario"]][r["controller"]]
        for key in SUITE_METRICS:
            v = src[key]
            if isinstance(v, float) and math.isnan(v):
                assert r[key] == ""
            else:
                assert float(r[key]) == pytest.approx(float(v), rel=1e-15)
    doc = json.loads(write_json(run.table, tmp_path / "t.json").read_text())
    assert list(doc) == ["results"]
    assert doc["results"]["sine"]["paper"]["aave"] == run.table["sine"]["paper"]["aave"]
    md = markdown_table(run.table)
    assert md.count("\n") == 2 + 12
    assert "| brake | h2 |" in md
    # every row has as many columns as the header ("max |u|" must not add columns)
    n_cols = {line.replace("\\|", "").count("|") for line in md.strip().splitlines()}
    assert n_cols == {len(SUITE_METRICS) + 3}
    text = format_table(run.table)
    assert "AAVE (m/s)" in text and "mpc" in text


def test_selection_and_bad_names(problem_file):
    suite = load_suite(problem_file, scenarios=["sine", "brake"], controllers=["paper"])
    assert list(suite.scenarios) == ["brake", "sine"]  # file order
    assert list(suite.controllers) == ["paper"]
    assert suite.layouts_used() == ["tail3", "mid"]
    with pytest.raises(ConfigError, match="--scenarios.*unknown name.*nope"):
        load_suite(problem_file, scenarios=["nope"])
    with pytest.raises(ConfigError, match="--controllers.*unknown name"):
        load_suite(problem_file, controllers=["paper", "lqr"])
    with pytest.raises(ConfigError, match="--controllers"):
        load_suite(problem_file, controllers=[""])


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ('layout = "mid"', 'layout = "nowhere"', "scenarios.sine.layout"),
        ("[controllers.paper.layouts.mid]", "[controllers.paper.layouts.other]",
         "controllers.paper.layouts.other"),
        ('type = "hdv"', 'type = "lqr"', "controllers.all_hdv.type"),
        ("duration = 20.0\nmetrics", "duration = -1.0\nmetrics", "scenarios.brake.duration"),
        ("n = 3", "n = 0", "layouts.tail3.n"),
        ("q_s = 0.1", "q_s = -0.1", "controllers.h2.weights.q_s"),
    ],
)
def test_bad_suite_files(tmp_path, old, new, field):
    path = tmp_path / "bad.toml"
    assert old in SHORT
    path.write_text(SHORT.replace(old, new, 1))
    with pytest.raises(ConfigError) as info:
        suite = load_suite(path)
        run_suite(suite, progress=False)  # synthesis keys are checked when synthesising
    assert info.value.field.startswith(field), info.value.field
    assert info.value.source == str(path)


def test_cli_bad_input_exits_2(problem_file, capsys, tmp_path):
    assert main(["run", str(problem_file), "--scenarios", "nope", "--no-record"]) == 2
    err = capsys.readouterr().err
    assert "--scenarios" in err and "nope" in err
    assert main(["run", str(tmp_path / "missing.toml"), "--no-record"]) == 2
    assert main(["run", str(problem_file), "--controllers", "x", "--no-record"]) == 2


def test_cli_run_json_files_and_recording(problem_file, capsys, tmp_path):
    from lcc_synth.recording import summarize_recording

    rrd = tmp_path / "suite.rrd"
    code = main([
        "run", str(problem_file), "--json", "--scenarios", "brake,sine",
        "--controllers", "all_hdv,paper", "--out", str(tmp_path / "res"), "--rrd", str(rrd),
        "--no-progress", "--record-every", "10",
    ])
    assert code == 0
    out = capsys.readouterr().out
    doc = json.loads(out)  # exactly one JSON object on stdout
    assert list(doc) == ["results", "provenance", "string_stability"]
    # every controller's as-run verdict on every layout with a head vehicle: the peak of the
    # analysed |Γ(jω)| of the loop as run, where it is, and the verdict that peak implies
    ss = doc["string_stability"]
    assert set(ss) == {"tail3", "mid"}
    for per in ss.values():
        assert set(per) == {"all_hdv", "paper"}
        for rep in per.values():
            assert rep["verdict"] in {"string_stable", "string_unstable", "boundary"}
            assert (rep["verdict"] == "string_stable") == (rep["gamma_peak"] <= 1.0 + 1e-9)
            assert rep["gamma_peak"] >= 1.0 - 1e-9  # |Γ(0)| = 1 for every stabilising loop
    assert ss["tail3"]["paper"]["as_run"]["equilibrium"]
    assert set(doc["results"]) == {"brake", "sine"}
    assert set(doc["results"]["sine"]) == {"all_hdv", "paper"}
    assert set(doc["results"]["sine"]["paper"]) == {*SUITE_METRICS, "collided", "failed_steps",
                                                    "unsafe"}  # fmt: skip
    assert doc["results"]["sine"]["paper"]["unsafe"] == []  # issue 33: the reasons, none here
    prov = doc["provenance"]  # the file's own bytes, hashed independently
    import hashlib

    assert prov["problem"]["sha256"] == hashlib.sha256(problem_file.read_bytes()).hexdigest()
    assert prov["backend"] == {"brake": "builtin", "sine": "builtin"}
    assert set(prov["solvers"]) >= {"all_hdv", "paper"} and prov["solvers"]["paper"] is None
    from lcc_synth import __version__

    assert prov["version"] == __version__
    (run_dir,) = (tmp_path / "res").iterdir()
    assert run_dir.name.startswith("short_suite-")
    names = {p.name for p in run_dir.iterdir()}
    assert {"table.md", "table.csv", "table.json", "details.json", "profiles_brake.png",
            "profiles_sine.png", "gamma_tail3.png", "gamma_mid.png"} <= names
    assert json.loads((run_dir / "table.json").read_text()) == doc
    summary = summarize_recording(rrd)
    paths = set(summary.entities)
    for s in ("brake", "sine"):
        for c in ("all_hdv", "paper"):
            assert any(p.startswith(f"/{s}/{c}/velocity") for p in paths), (s, c)
    assert any(p.startswith("/analysis/gamma/mid.paper") for p in paths)


def test_default_problem_is_the_showcase_and_reproduces_table_ii():
    from lcc_synth.cli.run import default_problem

    path = default_problem()
    assert path == Path(__file__).resolve().parents[1] / "problems" / "showcase.toml"
    full = load_suite(path)
    assert list(full.scenarios) == ["brake_behind", "head_sine", "head_brake", "heterogeneous",
                                    "platoon_brake", "ring_wave"]
    assert list(full.controllers) == ["all_hdv", "paper", "h2", "mpc", "mpc_delay", "deep_lcc"]
    assert {s.layout for s in full.scenarios.values()} == {"string10", "sec5a", "platoon8",
                                                            "ring20"}
    suite = load_suite(path, scenarios=["brake_behind"], controllers=["all_hdv", "paper"])
    table = run_suite(suite, progress=False).table["brake_behind"]
    # Table II of the paper: "all HDVs" and CF-LCC columns
    assert round(table["all_hdv"]["aave"], 2) == 0.89
    assert round(table["all_hdv"]["fuel_ml"], 2) == 392.86
    assert round(table["paper"]["aave"], 2) == 0.81
    assert round(table["paper"]["fuel_ml"], 2) == 340.56


# ------------------------------------------------------------------------- only_scenarios
ONLY = SHORT + """
[controllers.hdv_noisy]
type = "hdv"
only_scenarios = ["noisy"]
"""


def test_only_scenarios_runs_the_controller_in_those_scenarios_only(tmp_path):
    path = tmp_path / "only.toml"
    path.write_text(ONLY)
    suite = load_suite(path, controllers=["all_hdv", "hdv_noisy"])
    from lcc_synth.experiments.comparison import applies

    # its layouts are those of its scenarios: applies() knows it without the scenario too
    t = suite.controllers["hdv_noisy"]
    assert applies(t, "tail3") and not applies(t, "mid")
    assert applies(t, "tail3", "noisy") and not applies(t, "tail3", "brake")
    run = run_suite(suite, progress=False)
    assert list(run.table["noisy"]) == ["all_hdv", "hdv_noisy"]
    assert list(run.table["brake"]) == ["all_hdv"] and list(run.table["sine"]) == ["all_hdv"]
    # the same law on the same draws: the same row, bit for bit
    assert run.table["noisy"]["hdv_noisy"] == run.table["noisy"]["all_hdv"]
    # built only for the layouts of its scenarios
    assert "hdv_noisy" in run.controllers["tail3"] and "hdv_noisy" not in run.controllers["mid"]
    other = run_suite(load_suite(path, scenarios=["brake", "sine"]), progress=False)
    assert all("hdv_noisy" not in per for per in other.controllers.values())
    assert all("hdv_noisy" not in per for per in other.table.values())
    assert other.table["brake"]["all_hdv"] == run.table["brake"]["all_hdv"]
    # a selection that leaves a scenario without any controller is refused, naming the option
    assert list(load_suite(path, ["noisy"], ["hdv_noisy"]).scenarios) == ["noisy"]
    with pytest.raises(ConfigError, match="no controller of \\['hdv_noisy'\\] runs in scenario "
                       "'brake'") as info:
        load_suite(path, controllers=["hdv_noisy"])
    assert info.value.field == "--controllers"


@pytest.mark.parametrize(
    ("new", "match"),
    [
        ('only_scenarios = "noisy"', "non-empty list"),
        ("only_scenarios = []", "non-empty list"),
        ('only_scenarios = ["noisy", "nowhere"]', "unknown scenario 'nowhere'"),
        ('only_scenarios = ["sine"]\nonly_layouts = ["tail3"]', "scenario 'sine' is on layout"),
    ],
)
def test_only_scenarios_errors_name_the_field(tmp_path, new, match):
    path = tmp_path / "bad.toml"
    path.write_text(ONLY.replace('only_scenarios = ["noisy"]', new))
    with pytest.raises(ConfigError, match=match) as info:
        load_suite(path)
    assert info.value.field == "controllers.hdv_noisy.only_scenarios"
    assert info.value.source == str(path)
    assert main(["run", str(path), "--no-record", "--out", str(tmp_path)]) == 2


def test_showcase_heterogeneous_gains_the_predictive_rows_only(tmp_path, monkeypatch):
    """``mpc_delay`` and ``deep_lcc`` run in ``heterogeneous`` only (only_scenarios); the
    rows of the other controllers are those of a run without them, bit for bit; the new rows
    are pinned (README's showcase table)."""
    from lcc_synth.cli.run import default_problem

    monkeypatch.chdir(tmp_path)  # deep_lcc's data cache: results/deeplcc of the working dir
    path = default_problem()
    full = load_suite(path)
    assert list(full.controllers) == ["all_hdv", "paper", "h2", "mpc", "mpc_delay", "deep_lcc"]
    for name in ("mpc_delay", "deep_lcc"):
        assert full.controllers[name]["only_scenarios"] == ["heterogeneous"]
    new = run_suite(load_suite(path, scenarios=["heterogeneous"],
                               controllers=["h2", "mpc", "mpc_delay", "deep_lcc"]),
                    progress=False).table["heterogeneous"]  # fmt: skip
    old = run_suite(load_suite(path, scenarios=["heterogeneous"], controllers=["h2", "mpc"]),
                    progress=False).table["heterogeneous"]  # fmt: skip
    assert new["h2"] == old["h2"] and new["mpc"] == old["mpc"]
    assert list((tmp_path / "results" / "deeplcc").glob("deeplcc-*.npz"))  # cached there
    pins = {  # AAVE (m/s), fuel (mL), min spacing (m), RMS jerk (m/s^3)
        "mpc_delay": (2.33696743290055, 808.0796740429348, 8.901991470416192, 8.744364382058116),
        "deep_lcc": (2.4564786582815095, 820.4635510170015, 8.744036008923416, 3.2804467885341424),
    }
    for name, (aave_, fuel_, gap, jerk) in pins.items():
        row = new[name]
        got = (row["aave"], row["fuel_ml"], row["min_spacing"], row["rms_jerk_cav"])
        assert got == pytest.approx((aave_, fuel_, gap, jerk), rel=1e-6), name
        assert (row["aeb_activations"], row["collisions"], row["collided"]) == (0, 0, False)
    # the delay-aware MPC beats both h2 and the delay-free MPC here; DeeP-LCC does not
    assert new["mpc_delay"]["aave"] < min(new["h2"]["aave"], new["mpc"]["aave"])
    assert new["deep_lcc"]["aave"] > new["h2"]["aave"]
