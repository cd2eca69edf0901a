"""Failed runs rank last (issue 20): a run with a collision has NaN AAVE and fuel (``null`` in
JSON), every table marks it and puts it after the scenario's other rows, ``run`` and
``simulate`` say which runs collided, and a sweep's means leave it out."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from test_metrics import make_result

from lcc_synth.cli.main import main
from lcc_synth.experiments.comparison import load_suite, run_suite
from lcc_synth.experiments.sweep import (
    SWEEP_METRICS,
    aggregate,
    format_summary,
    load_sweep,
    run_sweep,
)
from lcc_synth.experiments.tables import format_table, markdown_table, write_csv, write_json
from lcc_synth.metrics import MetricsConfig, aave, fuel, summary

# problems/mpc_head_brake.toml without the MPC and without the CAV's emergency braking: the
# paper's CF-LCC gains (u = their sum alone) drive the CAV into the braking head vehicle.
HDV = '[hdv]\nmodel = "ovm"\n'
BRAKE = """
type = "brake_profile"
vehicle = "head"
start = 20.0
"""
CONTROLLERS = """
[controllers.all_hdv]
type = "hdv"

[controllers.paper]
type = "static"
kind = "cf_lcc"
semantics = "replace"
gains = { s_0 = 0.1, v_0 = -0.5, s_1 = -0.2, v_1 = 0.05, s_2 = -0.1, v_2 = 0.05 }

[controllers.added]
type = "static"
kind = "cf_lcc"
semantics = "added"
gains = { s_1 = -0.2, v_1 = 0.05, s_2 = -0.1, v_2 = 0.05 }
"""
SIMULATE = (
    HDV
    + '[system]\nkind = "cf_lcc"\nm = 0\nn = 10\nv_star = 15.0\n'
    + "[scenario]\nduration = 60.0\ncav_aeb = false\n"
    + "[[scenario.perturbations]]"
    + BRAKE
    + '[metrics]\nwindow = [20.0, 60.0]\nbaseline = "all_hdv"\n'
    + CONTROLLERS
)
SUITE = (
    'name = "crash"\n'
    + HDV
    + "[metrics]\nwindow = [20.0, 60.0]\n"
    + '[layouts.string10]\nkind = "cf_lcc"\nm = 0\nn = 10\nv_star = 15.0\n'
    + '[scenarios.brake]\nlayout = "string10"\nduration = 60.0\ncav_aeb = false\n'
    + "[[scenarios.brake.perturbations]]"
    + BRAKE
    + CONTROLLERS
)
SWEEP = (
    HDV
    + '[system]\nkind = "cf_lcc"\nm = 0\nn = 10\nv_star = 15.0\n'
    + "[scenario]\nduration = 60.0\ncav_aeb = false\n"
    + "[[scenario.perturbations]]"
    + BRAKE
    + "[metrics]\nwindow = [20.0, 60.0]\n[sweep]\ncount = 2\nbatch_size = 2\n"
    + CONTROLLERS
)


def _strict_json(text: str):
    """Parse JSON rejecting NaN / Infinity tokens (not JSON, though Python writes them)."""

    def bad(token):
        raise AssertionError(f"non-JSON number {token}")

    return json.loads(text, parse_constant=bad)


def test_collided_scenario_has_nan_aave_and_fuel_whenever_it_collided():
    v = np.full((2, 5, 3), 15.0)
    v[:, :, 1] = 16.0
    r = make_result(v, n=1)
    r.collided[1, 2] = True  # a collision after the window: the velocities there are finite
    a, f = aave(r, (0.0, 1.0)), fuel(r, (0.0, 1.0))
    assert np.isfinite(a[0]) and np.isfinite(f[0])
    assert np.isnan(a[1]) and np.isnan(f[1])
    s = summary(r, MetricsConfig(window=(0.0, 1.0)))
    assert s["fuel_ml"] == f[0] and s["scenarios_with_collision"] == 1


@pytest.fixture(scope="module")
def crash_suite(tmp_path_factory):
    path = tmp_path_factory.mktemp("crash") / "crash.toml"
    path.write_text(SUITE)
    return path, run_suite(load_suite(path), progress=False)


def test_suite_table_marks_the_collided_run_and_ranks_it_last(crash_suite, tmp_path):
    _, run = crash_suite
    rows = run.table["brake"]
    assert list(rows) == ["all_hdv", "added", "paper"]  # file order, the failed run last
    assert rows["paper"]["collided"] and rows["paper"]["collisions"] == 1
    assert math.isnan(rows["paper"]["aave"]) and math.isnan(rows["paper"]["fuel_ml"])
    assert not rows["all_hdv"]["collided"] and rows["all_hdv"]["fuel_ml"] > 700
    # terminal and Markdown: the marker on the last row
    assert format_table(run.table).splitlines()[-1].split()[:2] == ["paper", "(collided)"]
    md = markdown_table(run.table).strip().splitlines()
    assert md[-1].startswith("| brake | paper (collided) | nan | nan |")
    # CSV: empty AAVE / fuel, a collided column, last
    with write_csv(run.table, tmp_path / "t.csv").open() as fh:
        csv_rows = list(csv.DictReader(fh))
    assert [r["controller"] for r in csv_rows] == ["all_hdv", "added", "paper"]
    assert (csv_rows[-1]["aave"], csv_rows[-1]["fuel_ml"], csv_rows[-1]["collided"]) == (
        "", "", "true"
    )
    assert csv_rows[0]["collided"] == "false"
    # JSON: valid (null, not NaN), same order
    doc = _strict_json(write_json(run.table, tmp_path / "t.json").read_text())
    row = doc["results"]["brake"]["paper"]
    assert (row["aave"], row["fuel_ml"], row["collided"]) == (None, None, True)
    assert list(doc["results"]["brake"]) == ["all_hdv", "added", "paper"]


def test_the_writers_rank_any_table(crash_suite):
    _, run = crash_suite
    shuffled = {"brake": {c: run.table["brake"][c] for c in ("paper", "all_hdv", "added")}}
    assert format_table(shuffled) == format_table(run.table)
    assert markdown_table(shuffled) == markdown_table(run.table)


def test_run_prints_which_runs_collided(crash_suite, tmp_path, capsys):
    path, _ = crash_suite
    argv = ["run", str(path), "--no-record", "--no-figures", "--no-progress", "--out",
            str(tmp_path)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "collided: brake/paper: the CAV hit the head vehicle at t = 23.17 s" in out
    assert main([*argv, "--json"]) == 0
    cap = capsys.readouterr()
    res = _strict_json(cap.out)["results"]["brake"]
    assert list(res) == ["all_hdv", "added", "paper"] and res["paper"]["fuel_ml"] is None
    assert "collided: brake/paper" in cap.err


def test_simulate_marks_ranks_and_prints_the_collided_run(tmp_path, capsys):
    path = tmp_path / "crash.toml"
    path.write_text(SIMULATE)
    assert main(["simulate", str(path), "--no-record"]) == 0
    lines = capsys.readouterr().out.splitlines()
    table = [ln for ln in lines[2:] if ln and not ln.startswith(("collided", " "))]
    assert [ln.split()[0] for ln in table] == ["all_hdv", "added", "paper"]
    assert table[-1].split()[1:4] == ["(collided)", "nan", "nan"]
    assert "collided: paper: the CAV hit the head vehicle at t = 23.17 s" in lines
    assert main(["simulate", str(path), "--no-record", "--json"]) == 0
    cap = capsys.readouterr()
    res = _strict_json(cap.out)["results"]
    assert list(res) == ["all_hdv", "added", "paper"]
    assert (res["paper"]["aave"], res["paper"]["fuel_ml"], res["paper"]["collided"]) == (
        None, None, True
    )
    assert res["paper"]["reduction_vs_baseline"]["scenarios"] == 0
    assert "collided: paper" in cap.err


def test_sweep_counts_collided_runs_and_leaves_them_out_of_the_means():
    # hand-made: run 1 collided, yet its fuel is finite: it must not enter the mean
    per = {k: np.array([1.0, 0.1, 3.0]) for k in SWEEP_METRICS}
    per["collisions"] = np.array([0, 1, 0])
    per["aeb_activations"] = np.zeros(3, dtype=int)
    per["jerk_1s_over_limit_s"] = np.zeros(3)
    agg = aggregate({"x": per}, {"x": 0})["x"]
    for k in ("aave", "fuel_ml"):
        assert agg[k]["mean"] == 2.0 and agg[k]["n"] == 2 and agg[k]["collided_excluded"] == 1
    assert agg["min_spacing"]["n"] == 3  # safety metrics keep every run
    assert agg["collision_scenarios"] == 1
    assert "over the runs without a collision" in format_summary({"x": agg})
    assert "collided runs: x 1/3" in format_summary({"x": agg})


def test_sweep_of_a_crashing_controller(tmp_path):
    path = tmp_path / "sweep.toml"
    path.write_text(SWEEP)
    res = run_sweep(load_sweep(path), client=None, progress=False)
    paper = res.summary["paper"]
    assert paper["collision_scenarios"] == 2 and paper["fuel_ml"]["mean"] is None
    assert paper["aave"]["n"] == 0 and paper["fuel_ml"]["collided_excluded"] == 2
    assert res.summary["all_hdv"]["fuel_ml"]["n"] == 2
    assert np.isnan(res.samples["paper"]["fuel_ml"]).all()
    assert "paper 2/2" in format_summary(res.summary)
