"""``lcc-synth run``'s recording, read back from the saved file: every scenario tab carries the
context document that ``simulate`` records (``/<scenario>/context``), written from the suite
file, and its "problem file that reproduces this run" loads back (``load_suite``) into the
same scenario with the controllers that ran in it."""

from __future__ import annotations

import tomllib

import pytest
from cli_subprocess import PAPER_HDV

from lcc_synth.cli.main import main
from lcc_synth.experiments.comparison import load_suite
from lcc_synth.recording import summarize_recording

SUITE = """
name = "tiny_suite"
description = "Two short scenarios on one string, for the recording's context documents."

""" + PAPER_HDV + """
[layouts.tail2]
kind = "cf_lcc"
m = 0
n = 2
v_star = 15.0

[scenarios.brake]
layout = "tail2"
title = "the HDV behind brakes"
duration = 8.0
metrics = { window = [2.0, 8.0] }

[[scenarios.brake.perturbations]]
type = "brake"
vehicle = 1
start = 3.0
duration = 1.0
decel = -4.0

[scenarios.sine]
layout = "tail2"
duration = 6.0
metrics = { window = [1.0, 6.0] }

[[scenarios.sine.perturbations]]
type = "sine"
amplitude = 0.5
period = 4.0
start = 1.5

[controllers.all_hdv]
type = "hdv"

[controllers.paper]
type = "static"
kind = "cf_lcc"
semantics = "replace"
gains = { s_0 = 0.1, v_0 = -0.5, s_1 = -0.2, v_1 = 0.05 }
only_scenarios = ["brake"]
"""


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("run_rec")
    problem = tmp / "tiny.toml"
    problem.write_text(SUITE)
    rrd = tmp / "tiny.rrd"
    code = main(["run", str(problem), "--rrd", str(rrd), "--out", str(tmp / "results"),
                 "--no-figures", "--no-progress", "--json"])  # fmt: skip
    assert code == 0
    return problem, rrd


def test_every_scenario_tab_has_its_context_document(recorded, tmp_path):
    problem, rrd = recorded
    texts = summarize_recording(rrd).texts
    suite = load_suite(problem)
    expected = {"brake": ["all_hdv", "paper"], "sine": ["all_hdv"]}
    for sname, ss in suite.scenarios.items():
        text = texts[f"/{sname}/context"]
        assert text.startswith(f"# {sname}: context")
        assert "Two short scenarios on one string" in text  # the suite's description
        assert f"Scenario `{sname}` of the suite `tiny_suite`, on its layout `tail2`" in text
        p = ss.scenario.perturbations[0]
        assert f"- {type(p).__name__}: " in text and f"start = {p.start:g}" in text
        assert f"- first event at t = {p.start:g} s\n" in text  # no claim on the time panel
        w = ss.metrics.window
        assert f"window {w[0]:g} s ≤ t ≤ {w[1]:g} s" in text
        listed = [ln[2:].split(":")[0] for ln in text.split("## controllers")[1].split("##")[0]
                  .splitlines() if ln.startswith("- ")]  # fmt: skip
        assert listed == expected[sname]
        toml = text.split("```toml\n")[1].split("```")[0]
        alone = tmp_path / f"{sname}.toml"
        alone.write_text(toml)
        again = load_suite(alone)  # a suite file of this scenario alone: it reproduces the run
        assert list(again.scenarios) == [sname] and list(again.controllers) == expected[sname]
        assert again.scenarios[sname].scenario == ss.scenario
        assert again.scenarios[sname].metrics == ss.metrics
        assert tomllib.loads(toml)["name"] == "tiny_suite"
    assert texts["/brake/context"].split("\n")[2] == "the HDV behind brakes"  # the title


def test_every_tab_plots_its_own_run(recorded):
    """Each scenario's time plots open on that scenario's run (8 s and 6 s here), not on the
    recording's longest timeline, each on its own axis."""
    import rerun.blueprint.components as bpc
    from test_recording_context import time_axes

    _, rrd = recorded
    axes = time_axes(rrd)
    ends = {"brake": 7.99, "sine": 5.99}  # duration - dt: the last sample
    assert {o.split("/")[1] for o in axes} == set(ends)
    for origin, (link, view_range) in axes.items():
        end = ends[origin.split("/")[1]]
        assert link == [bpc.LinkAxis.Independent.value], origin
        assert view_range == [{"start": 0, "end": round(end * 1e9)}], origin


def test_every_road_view_holds_its_runs(recorded):
    """``run`` sends its layout once, when the runs are done (however they end), each
    scenario's road views bounded around every vehicle of its runs (without bounds the vehicles
    sat as a line at the view's edge and left it during the event). One layout only: each
    costs about 2 MB of the showcase's recording (740 small blueprint chunks)."""
    from rerun.chunk import RrdReader
    from test_recording_context import assert_road_views_hold_every_vehicle

    _, rrd = recorded
    assert len(list(RrdReader(rrd).blueprints())) == 1
    bounds = assert_road_views_hold_every_vehicle(rrd, ["all_hdv", "paper"])
    assert {o.split("/")[1] for o in bounds} == {"brake", "sine"}
    assert "/sine/paper/road" not in bounds  # only_scenarios: not run there, no view
