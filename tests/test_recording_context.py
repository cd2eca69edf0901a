"""Issue 33: a recording opens on what matters and says what it is.

The saved blueprint is read back (``rerun.chunk.RrdReader``, the blueprint store) and its time
panel checked: expanded, on the simulated ``time`` timeline, paused, its selection from the
perturbation's start (the problem file says 20 s) to the end of the run. The context document
is checked against the problem file it came from."""

from __future__ import annotations

import tomllib

import pytest
from cli_subprocess import PROBLEMS, run_cli
from rerun.chunk import RrdReader

from lcc_synth.recording import summarize_recording


def _time_panel(path):
    reader = RrdReader(path)
    values = {}
    for bp in reader.blueprints():
        for ch in reader.stream(store=bp):
            rb = ch.to_record_batch()
            for name in rb.schema.names:
                if name.startswith("TimePanelBlueprint:"):
                    values[name.split(":")[1]] = rb.column(name).to_pylist()[-1][-1]
    return values


@pytest.fixture(scope="module")
def head_brake(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ctx")
    rrd = tmp / "hb.rrd"
    proc = run_cli(["simulate", PROBLEMS / "mpc_head_brake.toml", "--rrd", rrd], cwd=tmp)
    assert proc.returncode == 0, proc.stderr
    return rrd


def test_the_time_panel_opens_paused_on_the_event(head_brake):
    import rerun.blueprint.components as bpc

    panel = _time_panel(head_brake)
    problem = tomllib.loads((PROBLEMS / "mpc_head_brake.toml").read_text())
    start = problem["scenario"]["perturbations"][0]["start"]
    duration = problem["scenario"]["duration"]
    dt = problem["scenario"]["dt"]
    assert panel["timeline"] == "time"
    assert panel["state"] == bpc.PanelState.Expanded.value
    assert panel["play_state"] == bpc.PlayState.Paused.value
    sel = panel["time_selection"]
    assert sel["min"] == round(start * 1e9)
    assert sel["max"] == round((duration - dt) * 1e9)  # the last recorded sample


def test_the_context_document_says_what_was_run(head_brake):
    text = summarize_recording(head_brake).texts["/mpc_head_brake/context"]
    problem = tomllib.loads((PROBLEMS / "mpc_head_brake.toml").read_text())
    assert problem["description"].split("\n")[0] in text
    assert "n = 10 behind" in text and "v* = 15 m/s" in text
    assert "BrakeProfile: start = 20, decel = -5" in text
    assert "window 20 s ≤ t ≤ 60 s" in text and "reductions against all_hdv" in text
    assert "alpha = 0.6, beta = 0.9, s_st = 5, s_go = 35, v_max = 30" in text
    for name, table in problem["controllers"].items():
        assert f"- {name}: {table['type']}" in text
    toml = text.split("```toml\n")[1].split("```")[0]
    again = tomllib.loads(toml)  # the embedded problem is the problem
    assert again["controllers"]["mpc"]["horizon"] == problem["controllers"]["mpc"]["horizon"]
    assert again["scenario"]["perturbations"] == [
        {**p, "vehicle": p.get("vehicle", "head")} for p in problem["scenario"]["perturbations"]]
