"""Issue 33: a recording opens on what matters and says what it is.

The saved blueprint is read back (``rerun.chunk.RrdReader``, the blueprint store) and its time
panel checked: expanded, on the simulated ``time`` timeline, paused, its selection from the
perturbation's start (the problem file says 20 s) to the end of the run. The context document
is checked against the problem file it came from."""

from __future__ import annotations

import re
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
def head_brake(mpc_head_brake_run):
    return mpc_head_brake_run[1]


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
    assert "first event at t = 20 s (the time panel's selection starts there)" in text
    assert "window 20 s ≤ t ≤ 60 s" in text and "reductions against all_hdv" in text
    assert "alpha = 0.6, beta = 0.9, s_st = 5, s_go = 35, v_max = 30" in text
    for name, table in problem["controllers"].items():
        assert f"- {name}: {table['type']}" in text
    toml = text.split("```toml\n")[1].split("```")[0]
    again = tomllib.loads(toml)  # the embedded problem is the problem
    assert again["controllers"]["mpc"]["horizon"] == problem["controllers"]["mpc"]["horizon"]
    assert again["scenario"]["perturbations"] == [
        {**p, "vehicle": p.get("vehicle", "head")} for p in problem["scenario"]["perturbations"]]


def _series_colors(path):
    """``{entity: [0xRRGGBBAA, ...]}`` of every coloured entity of a recording."""
    out = {}
    for ch in RrdReader(path).stream():
        rb = ch.to_record_batch()
        entity = (rb.schema.metadata or {}).get(b"rerun:entity_path", b"").decode()
        for name in rb.schema.names:
            if name.endswith(":colors"):
                out.setdefault(entity, rb.column(name).to_pylist()[0])
    return out


def test_colours_never_share_meaning(head_brake):
    """The alarm red is AEB flags and "fallback used" only; each controller's command has its
    own colour, none of them the alarm red, the CAV blue, the head yellow or the HDV grey."""
    from lcc_synth.recording.core import COLOR_ALARM, COLOR_CAV, COLOR_HDV, COLOR_HEAD

    def packed(rgb):
        return (rgb[0] << 24) | (rgb[1] << 16) | (rgb[2] << 8) | 0xFF

    colors = _series_colors(head_brake)
    red = packed(COLOR_ALARM)
    alarms = {e for e, cs in colors.items() if red in cs}
    assert alarms == {e for e in colors if e.endswith("/cav/aeb_active")} | {
        "/mpc_head_brake/mpc/mpc/status"}  # fmt: skip
    assert colors["/mpc_head_brake/mpc/mpc/status"][-1] == red  # "fallback used", last series
    commands = {e: cs[0] for e, cs in colors.items() if e.endswith("/cav/u_cmd")}
    assert len(commands) == 4 and len(set(commands.values())) == 4
    fixed = {packed(c) for c in (COLOR_ALARM, COLOR_CAV, COLOR_HDV, COLOR_HEAD)}
    assert not fixed & set(commands.values())
    times = colors["/mpc_head_brake/mpc/mpc/solve_time_ms"]
    assert red not in times and len(set(times)) == len(times)


def test_the_blueprint_has_the_key_and_the_context_first(head_brake):
    reader = RrdReader(head_brake)
    names, origins = [], []
    for bp in reader.blueprints():
        for ch in reader.stream(store=bp):
            rb = ch.to_record_batch()
            if "ViewBlueprint:space_origin" in rb.schema.names:
                origins.append(rb.column("ViewBlueprint:space_origin").to_pylist()[-1][-1])
                has = "ViewBlueprint:display_name" in rb.schema.names
                names.append(rb.column("ViewBlueprint:display_name").to_pylist()[-1][-1]
                             if has else "")  # fmt: skip
    assert "/mpc_head_brake/key" in origins and "/mpc_head_brake/context" in origins
    text = summarize_recording(head_brake).texts["/mpc_head_brake/key"]
    assert "t (s)" in text and "up = faster" in text and "AEB** red" in text
    # titles short enough to fit a quarter of the screen: controller and quantity with its unit
    plots = [n for n in names if n and n.split(": ")[-1] in ("v (m/s)", "s (m)", "a (m/s²)")]
    assert len(set(plots)) == 12 and max(map(len, plots)) <= 24  # (sent twice: opened, final)


def test_mpc_predictions_on_axes_next_to_what_happened(head_brake):
    """The MPC's velocity predicted 1 s ahead, recorded at the time it predicts, equals the
    history's plan value (independent: the controller's own history, re-run here), and the
    MPC's views come first in its reports."""
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.simulation.engine import simulate

    spec = load_spec(PROBLEMS / "mpc_head_brake.toml")
    mpc = spec.controllers["mpc"]
    simulate(spec.scenario, mpc)
    hist = mpc.history()
    cav = [str(n) for n in hist["state_names"][1::2]].index("v_0")
    j = round(1.0 / (hist["pred_time"][1] - hist["pred_time"][0]))
    want_t = hist["t"] + hist["pred_time"][j]
    reached = want_t <= hist["t"][-1]
    want = dict(zip((round(x * 1e9) for x in want_t[reached]),
                    hist["predicted_velocity"][0, :, j, cav][reached], strict=True))  # fmt: skip
    got_t, got = _series(head_brake, "/mpc_head_brake/mpc/mpc/lookahead/velocity/ahead_1s")
    # decimated (drawn within 0.2 % of the span): simulated rows, their values, the extremes
    assert 10 < len(got) < len(want) and set(got_t) <= set(want)
    assert all(abs(v - want[k]) <= 1e-12 * abs(want[k]) for k, v in zip(got_t, got, strict=True))
    assert min(got) == min(want.values()) and max(got) == max(want.values())


def _series(path, entity):
    times, values = [], []
    for ch in RrdReader(path).stream():
        rb = ch.to_record_batch()
        if (rb.schema.metadata or {}).get(b"rerun:entity_path", b"").decode() != entity:
            continue
        if "Scalars:scalars" in rb.schema.names:
            times += [int(x.value) if hasattr(x, "value") else int(x) for x in
                      rb.column("time").cast("int64").to_pylist()]  # fmt: skip
            values += [v[0] for v in rb.column("Scalars:scalars").to_pylist()]
    return times, values


def test_a_reader_that_stops_early_ends_quietly(head_brake):
    import subprocess

    from cli_subprocess import cli_command, cli_env

    cmd = [*cli_command(), "review", str(head_brake), "--summary", "--full"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=cli_env())
    proc.stdout.close()  # the reader is gone before the first line (as `| head -0`)
    err = proc.stderr.read().decode()
    assert proc.wait(60) == 141 and "Traceback" not in err, err


@pytest.mark.slow  # CI runs it; by default: one recording's context (the other tests here)
def test_two_recordings_side_by_side(head_brake, tmp_path):
    """``review A.rrd B.rrd``: one file holding both under their labels, every common run's
    plots A left and B right; the data are the recordings' own (the same samples)."""
    import shutil

    from lcc_synth.errors import ConfigError
    from lcc_synth.recording import rerun_binary
    from lcc_synth.recording.compare import comparison_labels, side_by_side

    other = tmp_path / "hb.rrd"  # the same name in another directory
    shutil.copy(head_brake, other)
    labels = comparison_labels(head_brake, other)
    assert labels == ("A_hb", "B_hb")
    out = side_by_side(head_brake, other, tmp_path / "both.rrd", rerun_binary())
    s = summarize_recording(out)
    for lab in labels:
        assert f"/{lab}/mpc_head_brake/mpc/velocity" in s.entities
    a = _series(head_brake, "/mpc_head_brake/mpc/mpc/lookahead/velocity/measured")
    b = _series(out, "/B_hb/mpc_head_brake/mpc/mpc/lookahead/velocity/measured")
    assert a == b and a[0]
    origins = {v["space_origin"] for v in s.views}
    for c in ("all_hdv", "cf_lcc_paper", "cf_lcc_added", "mpc"):
        for lab in labels:
            assert f"/{lab}/mpc_head_brake/{c}/velocity" in origins
    proc = run_cli(["review", head_brake, other, "--summary"], cwd=tmp_path)
    assert proc.returncode == 2 and "--summary" in proc.stderr
    proc = run_cli(["review", head_brake, other, other], cwd=tmp_path)
    assert proc.returncode == 2 and "two side by side" in proc.stderr
    table2 = tmp_path / "t2.rrd"
    assert run_cli(["simulate", PROBLEMS / "paper_table2.toml", "--rrd", table2],
                   cwd=tmp_path).returncode == 0  # fmt: skip
    with pytest.raises(ConfigError, match="no simulation run in common"):
        side_by_side(head_brake, table2, tmp_path / "none.rrd", rerun_binary())


def _blueprint_values(path):
    """``{entity: {field: latest value}}`` of the saved blueprint."""
    reader = RrdReader(path)
    out: dict = {}
    for bp in reader.blueprints():
        for ch in reader.stream(store=bp):
            rb = ch.to_record_batch()
            entity = (rb.schema.metadata or {}).get(b"rerun:entity_path", b"").decode()
            fields = out.setdefault(entity, {})
            for name in rb.schema.names:
                if ":" in name:
                    fields[name.split(":", 1)[1]] = rb.column(name).to_pylist()[-1]
    return out


def _series_names(path, prefixes):
    """The ``SeriesLines`` names of every entity under one of ``prefixes``."""
    names = set()
    for ch in RrdReader(path).stream():
        rb = ch.to_record_batch()
        entity = (rb.schema.metadata or {}).get(b"rerun:entity_path", b"").decode()
        if any(entity.startswith(p) for p in prefixes) and "SeriesLines:names" in rb.schema.names:
            names.update(rb.column("SeriesLines:names").to_pylist()[0])
    return names


#: Legend rows the viewer showed in the command view at 1920x1080 when that view had 1/5 of the
#: right column's height (web viewer, ``benchmarks/screenshot_review.py``): 4 (of 8 entries).
_ROWS_AT_ONE_FIFTH = 4


def test_the_command_legend_has_room_for_every_controller(head_brake):
    """One legend entry per controller's command and one shared AEB entry (the viewer's legend
    has one entry per distinct series name and cuts what does not fit), in a view tall enough
    for them by the measured rows per height."""
    from lcc_synth.recording.simulation import AEB_SERIES

    values = _blueprint_values(head_brake)
    views = [e for e, d in values.items()
             if d.get("display_name") == ["CAV command u_cmd (m/s²) and AEB"]]  # fmt: skip
    assert views  # the blueprint is saved as opened and as final: both are checked
    problem = tomllib.loads((PROBLEMS / "mpc_head_brake.toml").read_text())
    for view in views:
        query = values[f"{view}/ViewContents"]["query"]
        names = _series_names(head_brake, [q[2:].removesuffix("**") for q in query])
        assert names == {f"{c} u_cmd" for c in problem["controllers"]} | {AEB_SERIES}
        ref = "view/" + view.split("/")[-1]
        (box,) = [d for d in values.values() if ref in (d.get("contents") or [])]
        shares = box["row_shares"]
        share = shares[box["contents"].index(ref)] / sum(shares)
        assert len(names) <= int(_ROWS_AT_ONE_FIFTH * share / 0.2)


def test_flags_are_drawn_as_steps_never_averaged(head_brake):
    """The AEB flags and the MPC status are piecewise constant: the viewer draws them as steps.
    No line's points are averaged by the viewer (an averaged chattering flag took values it
    never has; the head's acceleration, recorded as 0 at 0 s and 20.00 s and -5 m/s² from
    20.01 s, was drawn as a 20 s ramp to -2.5): the recording holds the rows that draw it."""
    import rerun.components as rc

    styled = {}
    for ch in RrdReader(head_brake).stream():
        rb = ch.to_record_batch()
        entity = (rb.schema.metadata or {}).get(b"rerun:entity_path", b"").decode()
        if "SeriesLines:names" in rb.schema.names:
            get = {n: rb.column(f"SeriesLines:{n}").to_pylist()[0] if f"SeriesLines:{n}" in
                   rb.schema.names else None for n in ("aggregation_policy", "interpolation_mode")}
            styled[entity] = get
    flags = {e for e in styled if e.endswith(("/cav/aeb_active", "/mpc/status"))}
    assert len(flags) == 5
    for e, got in styled.items():
        if e in flags:
            assert got == {"aggregation_policy": [rc.AggregationPolicy.Off.value],
                           "interpolation_mode": [rc.InterpolationMode.StepAfter.value]}, e
        else:
            assert got == {"aggregation_policy": [rc.AggregationPolicy.Off.value],
                           "interpolation_mode": None}, e  # fmt: skip


def time_axes(path):
    """``{space_origin: (link, view_range)}`` of every time-series view of the saved
    blueprint (the final one: the views are sent as opened and at the end)."""
    values = _blueprint_values(path)
    out = {}
    for entity, fields in values.items():
        if fields.get("class_identifier") == ["TimeSeries"]:
            axis = values.get(f"{entity}/TimeAxis", {})
            out[fields["space_origin"][0]] = (axis.get("link"), axis.get("view_range"))
    return out


def test_every_time_plot_opens_on_the_whole_run_on_its_own_axis(head_brake):
    """Linked axes (``LinkToGlobal``) ignore a view's range in Rerun 0.41 and open a run longer
    than 60 s on the time cursor +- 30 s: every plot has its own axis on the whole run."""
    import rerun.blueprint.components as bpc

    problem = tomllib.loads((PROBLEMS / "mpc_head_brake.toml").read_text())
    sc = problem["scenario"]
    t0 = sc.get("t_start", 0.0)
    whole = [{"start": round(t0 * 1e9), "end": round((t0 + sc["duration"] - sc["dt"]) * 1e9)}]
    axes = time_axes(head_brake)
    assert len(axes) >= 4 * 3 + 1 + 3 + 1  # 4 controllers x 3 rows, u_cmd, MPC predictions
    for origin, (link, view_range) in axes.items():
        assert link == [bpc.LinkAxis.Independent.value], origin
        assert view_range == whole, origin


def test_an_mpc_run_opens_on_its_predictions_and_its_solver(head_brake):
    """The first screen of an MPC run: the reports tab opens (its saved active tab) on the
    CAV's predicted velocity, spacing and input next to what happened, each a time plot with
    data (the measured series and the predictions); the solve time and status come next, then
    the plans of the moment."""
    values = _blueprint_values(head_brake)
    s = summarize_recording(head_brake)
    reports = [d for d in values.values() if d.get("display_name") == ["reports"]]
    assert reports  # the blueprint as opened and as final: both are checked
    base = "/mpc_head_brake/mpc/mpc"
    for box in reports:
        first, solver, plans = box["contents"][:3]
        assert box["active_tab"] == [first]
        predictions = values[f"/{first}"]
        assert predictions["display_name"] == ["mpc: predictions"]
        views = [values[f"/{v}"] for v in predictions["contents"]]
        assert [v["space_origin"] for v in views] == [
            [f"{base}/lookahead/{q}"] for q in ("velocity", "spacing", "u")]  # fmt: skip
        assert all(v["class_identifier"] == ["TimeSeries"] for v in views)
        for v in views:
            series = {e.rsplit("/", 1)[1] for e in s.entities
                      if e.startswith(v["space_origin"][0] + "/")}  # fmt: skip
            assert {"measured", "ahead_1s"} <= series
        assert values[f"/{solver}"]["space_origin"] == [base]
        assert values[f"/{solver}"]["class_identifier"] == ["TimeSeries"]
        assert values[f"/{plans}"]["space_origin"] == [f"{base}/predicted/velocity"]


def test_review_summary_shows_round_off_values_as_such(tmp_path):
    """``review --summary`` (the real CLI) on a recording whose metrics are at round-off: a
    time to collision of 2.66e12 s (the vehicle is not closing in) and a command of 6e-12
    m/s² are shown as the tables show them (``>= 1e6``, ``0.000``), under labels with units."""
    from lcc_synth import recording as R
    from lcc_synth.controllers.static import HDVController
    from lcc_synth.simulation.engine import simulate
    from lcc_synth.simulation.scenario import Scenario

    res = simulate(Scenario(m=0, n=2, duration=2.0), HDVController("all_hdv"))
    path = tmp_path / "flat.rrd"
    metrics = {"aave": 0.0, "min_ttc": 2.66e12, "max_abs_command": 6e-12, "min_spacing": 20.0,
               "aeb_activations": 0, "collisions": 0}  # fmt: skip
    with R.open_recording(path, "flat", R.simulation_blueprint("flat", ["all_hdv"])) as rec:
        R.record_simulation(rec, res, "flat", metrics=metrics, decimate=1)
    proc = run_cli(["review", path, "--summary"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    (head,) = [ln for ln in lines if ln.strip().startswith("scenario")]
    (row,) = [ln for ln in lines if ln.strip().startswith("flat ")]
    cells = dict(zip(re.split(r"\s{2,}", head.strip()), re.split(r"\s{2,}", row.strip()),
                     strict=True))  # fmt: skip
    assert cells["min TTC (s)"] == ">= 1e6"
    assert cells["max |u| (m/s²)"] == "0.000"
    assert cells["controller"] == "all_hdv"  # safe: no emergency braking, 20 m, no TTC
    assert "e+12" not in proc.stdout and "e-12" not in proc.stdout


def test_every_time_plot_names_its_unit(head_brake):
    """Rerun 0.41's plot axes carry no label (``ScalarAxis``: range and zoom lock only): every
    time-series view's title names its quantity's unit instead; the x axes are the simulated
    time in seconds, which the key above the plots says."""
    values = _blueprint_values(head_brake)
    titles = [d["display_name"][0] for d in values.values()
              if d.get("class_identifier") == ["TimeSeries"]]  # fmt: skip
    assert len(titles) >= 2 * (4 * 3 + 1 + 3 + 1)  # as opened and final
    units = re.compile(r"\((m/s|m|m/s²|ms)\)")
    assert [t for t in titles if not units.search(t)] == []
    key = summarize_recording(head_brake).texts["/mpc_head_brake/key"]
    assert "x axes: simulated time t (s)" in key


def road_views(path):
    """``{space_origin: VisualBounds2D range or None}`` of every road view of the blueprint the
    viewer opens (the last one sent: the latest ``log_time``), and ``{entity: (container kind,
    number of views)}`` of the containers holding them."""
    reader = RrdReader(path)
    stores = []
    for bp in reader.blueprints():
        values, last = {}, 0
        for ch in reader.stream(store=bp):
            rb = ch.to_record_batch()
            entity = (rb.schema.metadata or {}).get(b"rerun:entity_path", b"").decode()
            if "log_time" in rb.schema.names:  # nanoseconds since the epoch
                ns = rb.column("log_time").cast("int64").to_numpy(zero_copy_only=False)
                last = max(last, int(ns.max()))
            fields = values.setdefault(entity, {})
            for name in rb.schema.names:
                if ":" in name:
                    fields[name.split(":", 1)[1]] = rb.column(name).to_pylist()[-1]
        stores.append((last, values))
    values = max(stores, key=lambda s: s[0])[1]
    views = {e: d["space_origin"][0] for e, d in values.items()
             if d.get("class_identifier") == ["2D"] and d["space_origin"][0].endswith("/road")}
    bounds = {origin: (values.get(f"{e}/VisualBounds2D", {}).get("range") or [None])[0]
              for e, origin in views.items()}  # fmt: skip
    holders = {e: (d["container_kind"], len(d["contents"])) for e, d in values.items()
               if any(f"view/{v.split('/')[-1]}" in (d.get("contents") or []) for v in views)}
    return bounds, holders


def road_points(path):
    """``{entity: (k, 2) array}``: every road position recorded (all rows, all vehicles), and
    ``{entity: radii}`` of its dots."""
    import numpy as np

    points, radii = {}, {}
    for ch in RrdReader(path).stream():
        rb = ch.to_record_batch()
        entity = (rb.schema.metadata or {}).get(b"rerun:entity_path", b"").decode()
        if not entity.endswith("/road"):
            continue
        if "Points2D:positions" in rb.schema.names:
            rows = [r for r in rb.column("Points2D:positions").to_pylist() if r]
            if rows:
                xy = np.array([p for r in rows for p in r], dtype=float)
                points[entity] = np.vstack([points.get(entity, np.empty((0, 2))), xy])
        if "Points2D:radii" in rb.schema.names:
            radii[entity] = rb.column("Points2D:radii").to_pylist()[-1]
    return points, radii


def assert_road_views_hold_every_vehicle(path, controllers):
    """Every road view of the opening blueprint has visual bounds that contain every vehicle
    position recorded for it over the whole run, and the views are tabs (one per controller)."""
    bounds, holders = road_views(path)
    points, _ = road_points(path)
    assert set(bounds) == set(points)  # a view for every recorded road, and only those
    assert {c for o in bounds for c in [o.split("/")[2]]} == set(controllers)
    for origin, box in bounds.items():
        assert box is not None, f"{origin}: no visual bounds"
        xy = points[origin]
        assert len(xy) > 10 and xy[:, 1].max() > xy[:, 1].min()  # frames of a moving string
        (x0, x1), (y0, y1) = box["x_range"], box["y_range"]
        assert x0 <= xy[:, 0].min() and xy[:, 0].max() <= x1, origin
        assert y0 <= xy[:, 1].min() and xy[:, 1].max() <= y1, origin
    import rerun.blueprint.components as bpc

    # one tab per road view, each the whole column's height (stacked views were 45 px tall)
    assert {kind[0] for kind, _ in holders.values()} == {bpc.ContainerKind.Tabs.value}
    assert sum(n for _, n in holders.values()) == len(bounds)
    return bounds


def test_the_road_view_holds_every_vehicle_over_the_run(head_brake):
    """Stacked road views were 45 px tall (the dots under a pixel). The road is one tab per
    controller, opening on bounds that contain every recorded position (the CAV and the head
    during the brake too); its dots are sized in UI points (a zoom never shrinks them to
    nothing), the CAV's and the head's larger than the HDVs'."""
    import numpy as np
    import rerun.blueprint.components as bpc

    from lcc_synth.recording.simulation import ROAD_DOT_PT

    problem = tomllib.loads((PROBLEMS / "mpc_head_brake.toml").read_text())
    assert_road_views_hold_every_vehicle(head_brake, problem["controllers"])
    _, holders = road_views(head_brake)
    tabs = [bpc.ContainerKind.Tabs.value]
    assert list(holders.values()) == [(tabs, len(problem["controllers"]))]
    _, radii = road_points(head_brake)
    for entity, r in radii.items():
        r = -np.asarray(r)  # Rerun stores UI points as negative radii
        assert (r > 0).all(), entity
        assert len(r) == problem["system"]["m"] + problem["system"]["n"] + 2, entity
        head, cav = r[0], r[problem["system"]["m"] + 1]  # head, HDVs ahead, the CAV, ...
        assert r.min() == ROAD_DOT_PT and cav == r.max() > head > r.min(), entity
