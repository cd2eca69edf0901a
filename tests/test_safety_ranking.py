"""Issue 33: safety before efficiency. A run that needed emergency braking, or came within
2 m or 1 s of the vehicle ahead, is marked unsafe and ranked after every safe run in every
table (``run``, ``simulate``, ``sweep``, the recording), its AAVE and fuel still shown.

The truth the verdicts are checked against is the run's own metrics: on
``problems/mpc_head_brake.toml`` the paper's CF-LCC gain (``cf_lcc_paper``) has the best AAVE
of the table (2.12 m/s) but reaches 0.096 m with 297 emergency-braking steps."""

from __future__ import annotations

import math

import numpy as np
import pytest
from cli_subprocess import PROBLEMS, run_cli

from lcc_synth.experiments.sweep import format_summary
from lcc_synth.experiments.sweep_samples import aggregate
from lcc_synth.experiments.tables import (
    format_table,
    json_rows,
    rank_failed_last,
    row_label,
    unsafe_lines,
    write_csv,
)
from lcc_synth.metrics import UNSAFE_MIN_SPACING, UNSAFE_MIN_TTC, unsafe_reasons
from lcc_synth.recording import summarize_recording

SAFE = {"aave": 1.0, "fuel_ml": 100.0, "min_spacing": 10.0, "min_ttc": 5.0,
        "aeb_activations": 0, "collisions": 0, "failed_steps": 0}  # fmt: skip


def test_thresholds_are_strict_and_nan_judges_nothing():
    assert unsafe_reasons({**SAFE, "min_spacing": UNSAFE_MIN_SPACING}) == []
    assert unsafe_reasons({**SAFE, "min_ttc": UNSAFE_MIN_TTC}) == []
    below = np.nextafter(UNSAFE_MIN_SPACING, 0.0)
    assert unsafe_reasons({**SAFE, "min_spacing": below}) == ["min spacing 2.00 m < 2 m"]
    assert unsafe_reasons({**SAFE, "min_ttc": 0.5}) == ["min TTC 0.50 s < 1 s"]
    assert unsafe_reasons({**SAFE, "aeb_activations": 1}) == ["emergency braking on 1 step"]
    nan = float("nan")
    assert unsafe_reasons({"min_spacing": nan, "min_ttc": nan, "aeb_activations": nan}) == []
    assert unsafe_reasons({"min_ttc": math.inf}) == []  # a vehicle that never closes in
    assert unsafe_reasons({}) == []  # a controller that did not run has no metrics


def test_every_kind_of_row_ranks_after_the_safe_ones():
    per = {
        "not_run": {"failed": "synthesis infeasible", "collided": False, "failed_steps": 0},
        "collided": {**SAFE, "collisions": 1, "aave": math.nan, "min_spacing": -0.1},
        "unsafe_fast": {**SAFE, "aave": 0.1, "aeb_activations": 40, "min_spacing": 0.5},
        "unsafe_qp": {**SAFE, "aave": 0.2, "min_ttc": 0.8, "failed_steps": 3},
        "qp_failed": {**SAFE, "failed_steps": 5},
        "safe_slow": {**SAFE, "aave": 3.0},
        "safe": dict(SAFE),
    }
    order = list(rank_failed_last({"s": per})["s"])
    assert order == ["safe_slow", "safe", "qp_failed", "unsafe_fast", "unsafe_qp", "collided",
                     "not_run"]  # fmt: skip
    assert row_label("unsafe_fast", per["unsafe_fast"]) == "unsafe_fast (unsafe)"
    assert row_label("unsafe_qp", per["unsafe_qp"]) == "unsafe_qp (unsafe, QP failed on 3 steps)"
    assert row_label("collided", per["collided"]) == "collided (collided)"  # not also "unsafe"
    text = format_table({"s": per})
    assert text.index("safe_slow") < text.index("unsafe_fast (unsafe)")
    lines = unsafe_lines({"s": per})
    assert lines[0] == ("unsafe: s/unsafe_fast: emergency braking on 40 steps, "
                        "min spacing 0.50 m < 2 m")  # fmt: skip
    assert lines[1] == "unsafe: s/unsafe_qp: min TTC 0.80 s < 1 s"
    assert lines[-1].startswith("(unsafe:") and len(lines) == 3
    rows = json_rows({"s": per})["s"]
    assert rows["safe"]["unsafe"] == [] and rows["unsafe_qp"]["unsafe"] == [
        "min TTC 0.80 s < 1 s"]  # fmt: skip


def test_csv_has_the_reasons(tmp_path):
    per = {"a": dict(SAFE), "b": {**SAFE, "aeb_activations": 2, "min_ttc": 0.9}}
    text = write_csv({"s": per}, tmp_path / "t.csv").read_text().splitlines()
    head = text[0].split(",")
    assert head[-1] == "unsafe"
    assert text[1].startswith("s,a,") and text[1].endswith(",")
    assert text[2].startswith("s,b,")
    assert text[2].endswith("emergency braking on 2 steps; min TTC 0.90 s < 1 s")


def test_sweep_counts_unsafe_scenarios_and_ranks_by_them():
    n = 4

    def samples(**over):
        base = {k: np.full(n, v, dtype=float) for k, v in
                {"aave": 1.0, "fuel_ml": 10.0, "min_spacing": 9.0, "min_ttc": 4.0,
                 "max_abs_command": 1.0, "rms_jerk_cav": 0.1, "max_jerk_1s_cav": 0.5,
                 "velocity_std": 0.1, "mean_speed": 15.0, "braking_events": 0.0,
                 "jerk_1s_over_limit_s": 0.0, "collisions": 0.0,
                 "aeb_activations": 0.0}.items()}  # fmt: skip
        base.update(over)
        return base

    spacing = np.array([9.0, 1.5, np.nan, 9.0])  # one scenario under 2 m; NaN judges nothing
    aeb = np.array([0.0, 0.0, 0.0, 3.0])  # another with emergency braking
    summary = aggregate({"first": samples(min_spacing=spacing, aeb_activations=aeb),
                         "second": samples()}, {})  # fmt: skip
    assert summary["first"]["unsafe_scenarios"] == 2
    assert summary["second"]["unsafe_scenarios"] == 0
    text = format_summary(summary)
    lines = text.splitlines()
    assert lines[2].startswith("second ")
    assert lines[3].startswith("first (unsafe in 2/4)")


@pytest.fixture(scope="module")
def head_brake(tmp_path_factory, mpc_head_brake_run):
    doc, rrd = mpc_head_brake_run
    tmp = tmp_path_factory.mktemp("hb")
    text = run_cli(["simulate", PROBLEMS / "mpc_head_brake.toml", "--no-record"], cwd=tmp)
    assert text.returncode == 0, text.stderr
    return doc, text.stdout, rrd


def test_mpc_head_brake_ranks_the_run_emergency_braking_saved_last(head_brake):
    doc, text, _ = head_brake
    rows = doc["results"] if "results" in doc else doc
    paper = rows["cf_lcc_paper"]
    # the metrics that make it unsafe, and its AAVE that would otherwise rank it first
    assert paper["aeb_activations"] > 0 and paper["min_spacing"] < UNSAFE_MIN_SPACING
    assert all(paper["aave"] < rows[n]["aave"] for n in ("all_hdv", "cf_lcc_added", "mpc"))
    assert paper["unsafe"] == unsafe_reasons(paper) != []
    assert all(rows[n]["unsafe"] == [] for n in ("all_hdv", "cf_lcc_added", "mpc"))
    names = [n for n in rows if isinstance(rows[n], dict) and "unsafe" in rows[n]]
    assert names[-1] == "cf_lcc_paper"
    lines = text.split("MPC solver")[0].splitlines()[2:]  # after the title and the header
    table = [line for line in lines if line.startswith(("all_hdv", "cf_lcc", "mpc"))]
    assert len(table) == 4
    assert table[-1].startswith("cf_lcc_paper (unsafe)")
    assert "unsafe: cf_lcc_paper: emergency braking on" in text


def test_the_recording_ranks_it_last_and_says_why(head_brake):
    _, _, rrd = head_brake
    s = summarize_recording(rrd)
    (table,) = [v for k, v in s.texts.items() if k.endswith("mpc_head_brake/metrics")]
    head, safety = table.splitlines()[2], table.splitlines()[4]
    assert head.rstrip(" |").endswith("cf_lcc_paper")
    assert safety.startswith("| safety | safe | safe | safe | unsafe: emergency braking on")
    # labelled with units and rounded as the run table rounds them; nothing-carrying rows out
    rows = {line.split(" | ")[0].lstrip("| "): line for line in table.splitlines()[4:]}
    assert rows["AAVE (m/s)"].startswith("| AAVE (m/s) | 2.5057 | 2.4343 |")
    assert "min spacing (m)" in rows and "batch" not in rows and "AAVE std over the batch (m/s)"\
        not in rows and "collided" not in rows  # fmt: skip
    proc = run_cli(["review", rrd, "--summary"], cwd=rrd.parent)
    assert proc.returncode == 0, proc.stderr
    last = [line for line in proc.stdout.splitlines() if "cf_lcc_paper" in line]
    assert "cf_lcc_paper (unsafe)" in last[-1] and "AAVE (m/s)" in proc.stdout


def test_values_at_round_off_are_shown_as_such():
    from lcc_synth.metrics import format_metric

    assert format_metric(2.66e12, ".2f") == ">= 1e6"  # a closing speed at round-off
    assert format_metric(6e-12, ".3f") == "0.000" and format_metric(-6e-12, ".3f") == "0.000"
    assert format_metric(-0.0005, ".4f") == "-0.0005"
    assert format_metric(0.01, "iso") == "over 0.01 s" and format_metric(None, ".2f") == "n/a"
