"""Rerun recordings: read back what was recorded and compare with the simulator's arrays."""

from __future__ import annotations

import argparse
import re
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rerun")

from rerun.chunk import RrdReader  # noqa: E402

from lcc_synth import recording as R  # noqa: E402
from lcc_synth.controllers.static import HDVController, StaticGainController  # noqa: E402
from lcc_synth.errors import ConfigError  # noqa: E402
from lcc_synth.metrics import MetricsConfig  # noqa: E402
from lcc_synth.metrics import summary as metrics_summary  # noqa: E402
from lcc_synth.models.feedback import Gains  # noqa: E402
from lcc_synth.models.hdv import OVM  # noqa: E402
from lcc_synth.models.linear import model_from_hdv  # noqa: E402
from lcc_synth.simulation.engine import simulate  # noqa: E402
from lcc_synth.simulation.perturbations import Brake  # noqa: E402
from lcc_synth.simulation.scenario import Scenario  # noqa: E402

M, N = 1, 3  # one HDV ahead, three behind: every kind of vehicle column


def _scenario(duration: float = 6.0, batch: int = 1) -> Scenario:
    return Scenario(
        m=M,
        n=N,
        duration=duration,
        batch=batch,
        perturbations=(Brake(vehicle=1, start=1.0, duration=1.0),),
        name="rec_test",
    )


def _controllers():
    model = model_from_hdv("lcc", M, N, OVM(), 15.0, warn=False)
    gains = Gains.named({"v_0": -0.5, "s_1": -0.2, "v_1": 0.05}, "added")
    return [HDVController("all_hdv"), StaticGainController("lcc gains", gains, model)]


class Boom(RuntimeError):
    pass


class RaisingController:
    """A Python-loop controller (no linear law) that raises ``exc`` once t >= t_fail."""

    name = "raiser"
    sample_time = None

    def __init__(self, exc: BaseException, t_fail: float = 2.0):
        self.exc = exc
        self.t_fail = t_fail

    def reset(self, ctx):
        self.batch = ctx.batch

    def __call__(self, obs):
        if obs.t >= self.t_fail:
            raise self.exc
        return np.zeros(self.batch)

    def describe(self):
        return {"type": "test"}

    def stats(self):
        return {}


def _chunks(path: Path) -> dict[str, list]:
    out: dict[str, list] = {}
    for ch in RrdReader(path).stream():
        out.setdefault(ch.entity_path, []).append(ch)
    return out


def _views(path: Path) -> list[tuple[str, str, str]]:
    """(kind, origin, name) of every view of the file's blueprint, in the order logged."""
    reader = RrdReader(path)
    [bp] = reader.blueprints()
    views = []
    for ch in reader.stream(store=bp):
        rb = ch.to_record_batch()
        if "ViewBlueprint:space_origin" in rb.schema.names:
            views.append(tuple(rb.column(f"ViewBlueprint:{c}").to_pylist()[-1][-1]
                               for c in ("class_identifier", "space_origin", "display_name")))
    return views


def _temporal(chunks, entity: str, component: str) -> tuple[np.ndarray, list]:
    """(time in ns, values per row) of ``component`` at ``entity``, sorted by time."""
    times, values = [], []
    for ch in chunks[entity]:
        if ch.is_static:
            continue
        rb = ch.to_record_batch()
        if component not in rb.schema.names:
            continue
        times.append(rb.column("time").cast("int64").to_numpy())
        values += rb.column(component).to_pylist()
    t = np.concatenate(times)
    order = np.argsort(t, kind="stable")
    return t[order], [values[i] for i in order]


def _static(chunks, entity: str, component: str):
    """The latest static value (static data logged again replaces the earlier one)."""
    found = []
    for ch in chunks[entity]:
        rb = ch.to_record_batch()
        if ch.is_static and component in rb.schema.names:
            value = rb.column(component).to_pylist()[-1]
            found.append(value[-1] if component.endswith(":text") else value)
    if not found:
        raise KeyError((entity, component))
    return found[-1]


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    """Two controllers simulated and recorded in one file (full rate)."""
    sc = _scenario()
    results = {c.name: simulate(sc, c) for c in _controllers()}
    path = tmp_path_factory.mktemp("rec") / "two.rrd"
    bp = R.simulation_blueprint("rec test", list(results))
    with R.open_recording(path, "rec test", bp) as rec:
        for res in results.values():
            metrics = metrics_summary(res, MetricsConfig(window=(0.5, 5.0)))
            R.record_simulation(rec, res, "rec test", metrics=metrics, decimate=1)
    return path, results


def test_recorded_values_equal_simulator_arrays(table):
    path, results = table
    chunks = _chunks(path)
    for name, res in results.items():
        base = f"/rec_test/{R.entity_name(name)}"
        t_ns, vel = _temporal(chunks, f"{base}/velocity", "Scalars:scalars")
        np.testing.assert_array_equal(t_ns, np.round(res.t * 1e9).astype(np.int64))
        np.testing.assert_array_equal(np.array(vel), res.velocity[0])
        _, acc = _temporal(chunks, f"{base}/acceleration", "Scalars:scalars")
        np.testing.assert_array_equal(np.array(acc), res.acceleration[0])
        _, sp = _temporal(chunks, f"{base}/spacing", "Scalars:scalars")
        np.testing.assert_array_equal(np.array(sp), res.spacing[0, :, 1:])
        _, u = _temporal(chunks, f"{base}/cav/u_cmd", "Scalars:scalars")
        np.testing.assert_array_equal(np.array(u)[:, 0], res.u_cmd[0])
        _, aeb = _temporal(chunks, f"{base}/cav/aeb_active", "Scalars:scalars")
        np.testing.assert_array_equal(np.array(aeb)[:, 0], res.aeb_active[0].astype(float))
        # road view: x relative to the CAV, y = ROAD_Y_SCALE * velocity error (float32)
        _, road = _temporal(chunks, f"{base}/road", "Points2D:positions")
        road = np.array(road)
        cav = res.cav
        np.testing.assert_array_equal(
            road[..., 0], (res.position[0] - res.position[0, :, cav : cav + 1]).astype(np.float32)
        )
        np.testing.assert_array_equal(
            road[..., 1],  # up (a negative screen y: the viewer's y points down) is faster
            (-R.ROAD_Y_SCALE * (res.velocity[0] - 15.0)).astype(np.float32)
        )
    # the braking vehicle really braked, so the data are not trivially constant
    assert np.ptp(results["all_hdv"].velocity[0, :, M + 2]) > 3.0


def test_every_vehicle_and_controller_is_present_with_paper_colors(table):
    path, results = table
    chunks = _chunks(path)
    names = ["head", "hdv-1", "cav", "hdv1", "hdv2", "hdv3"]
    assert R.vehicle_names(M, N) == names
    for name in results:
        c = R.entity_name(name)
        series = _static(chunks, f"/rec_test/{c}/velocity", "SeriesLines:names")
        assert series == [f"{c} {v}" for v in names]
        assert _static(chunks, f"/rec_test/{c}/spacing", "SeriesLines:names") == series[1:]
        colors = _static(chunks, f"/rec_test/{c}/velocity", "SeriesLines:colors")
        rgba = [((x >> 24) & 255, (x >> 16) & 255, (x >> 8) & 255) for x in colors]
        assert rgba[0] == R.COLOR_HEAD and rgba[M + 1] == R.COLOR_CAV
        assert all(col == R.COLOR_HDV for i, col in enumerate(rgba) if i not in (0, M + 1))
        assert _static(chunks, f"/rec_test/{c}/road", "Points2D:labels") == names
        text = _static(chunks, f"/rec_test/{c}/metrics", "TextDocument:text")
        assert "aave" in text and "per vehicle" in text
        ctrl = _static(chunks, f"/rec_test/{c}/controller", "TextDocument:text")
        assert "describe" not in ctrl and "type" in ctrl
    comparison = _static(chunks, "/rec_test/metrics", "TextDocument:text")
    for name in results:
        assert R.entity_name(name) in comparison
    assert "complete" in _static(chunks, "/rec_test/status", "TextDocument:text")
    # static-gain description reaches the controller document
    assert "v_0" in _static(chunks, "/rec_test/lcc_gains/controller", "TextDocument:text")


def test_blueprint_is_in_the_file(table):
    path, results = table
    reader = RrdReader(path)
    [bp] = reader.blueprints()
    origins = set()
    kinds = set()
    for ch in reader.stream(store=bp):
        rb = ch.to_record_batch()
        if "ViewBlueprint:space_origin" in rb.schema.names:
            origins.add(rb.column("ViewBlueprint:space_origin").to_pylist()[-1][-1])
            kinds.add(rb.column("ViewBlueprint:class_identifier").to_pylist()[-1][-1])
    for name in results:
        c = R.entity_name(name)
        for q in ("velocity", "spacing", "acceleration", "road", "controller"):
            assert f"/rec_test/{c}/{q}" in origins
    assert "/rec_test/metrics" in origins
    assert {"TimeSeries", "2D", "TextDocument"} <= kinds


def test_decimation_records_every_kth_step_and_the_last(tmp_path):
    res = simulate(_scenario(duration=2.0), HDVController("hdv"))
    path = tmp_path / "dec.rrd"
    with R.open_recording(path, "dec") as rec:
        R.record_simulation(rec, res, "dec", decimate=7)
    t_ns, vel = _temporal(_chunks(path), "/dec/hdv/velocity", "Scalars:scalars")
    idx = np.r_[np.arange(0, 200, 7), 199]
    np.testing.assert_array_equal(t_ns, np.round(res.t[idx] * 1e9).astype(np.int64))
    np.testing.assert_array_equal(np.array(vel), res.velocity[0, idx])
    with pytest.raises(ConfigError, match="decimate"):
        with R.open_recording(tmp_path / "bad.rrd", "dec") as rec:
            R.record_simulation(rec, res, "dec", decimate=0)


def test_batch_member_and_controller_label(tmp_path):
    sc = Scenario(m=0, n=2, duration=1.0, batch=3, heterogeneity={"alpha": 0.1}, seed=4)
    res = simulate(sc, HDVController("hdv"))
    path = tmp_path / "batch.rrd"
    with R.open_recording(path, "b") as rec:
        for run in range(3):
            R.record_simulation(rec, res, "b", controller=f"hdv_seed{run}", run=run, decimate=1)
        with pytest.raises(ConfigError, match="run"):
            R.record_simulation(rec, res, "b", run=3, decimate=1)
    chunks = _chunks(path)
    for run in range(3):
        _, vel = _temporal(chunks, f"/b/hdv_seed{run}/velocity", "Scalars:scalars")
        np.testing.assert_array_equal(np.array(vel), res.velocity[run])


@pytest.mark.parametrize("exc", [Boom("controller failed"), KeyboardInterrupt()])
def test_interrupted_run_leaves_a_readable_file(tmp_path, exc):
    sc = _scenario(duration=4.0)
    first = simulate(sc, HDVController("all_hdv"))
    path = tmp_path / "interrupted.rrd"
    with pytest.raises(type(exc)):
        with R.open_recording(
            path, "rec test", R.simulation_blueprint("rec test", ["all_hdv", "raiser"])
        ) as rec:
            R.record_simulation(rec, first, "rec test", decimate=1)
            simulate(sc, RaisingController(exc))  # raises mid-run (t = 2 s of 4 s)
    summary = R.summarize_recording(path)  # full read of a finalised file (footer included)
    assert summary.has_blueprint and summary.finalized
    assert "/rec_test/all_hdv/velocity" in summary.entities
    assert summary.entities["/rec_test/all_hdv/velocity"].samples == len(first.t)
    assert not any("raiser" in p for p in summary.entities)
    status = summary.texts["/rec_test/status"]
    word = "**interrupted**" if isinstance(exc, KeyboardInterrupt) else "**failed**"
    assert word in status and type(exc).__name__ in status and "complete" not in status
    _, vel = _temporal(_chunks(path), "/rec_test/all_hdv/velocity", "Scalars:scalars")
    np.testing.assert_array_equal(np.array(vel), first.velocity[0])
    RrdReader(path).store()  # the footer/manifest was written


def test_summary_reports_entities_time_range_samples_and_metrics(table):
    path, results = table
    s = R.summarize_recording(path)
    assert s.application_id == R.APP_ID
    assert s.time_range == (0.0, pytest.approx(results["all_hdv"].t[-1]))
    vel = s.entities["/rec_test/all_hdv/velocity"]
    assert vel.samples == len(results["all_hdv"].t) and vel.series == M + N + 2
    assert s.entities["/rec_test/all_hdv/spacing"].series == M + N + 1
    assert s.entities["/rec_test/metrics"].static
    assert "aave" in s.texts["/rec_test/all_hdv/metrics"]
    js = s.to_json()
    assert js["entities"]["/rec_test/all_hdv/road"]["samples"] == len(results["all_hdv"].t)


def test_summary_rejects_missing_and_invalid_files(tmp_path):
    with pytest.raises(ConfigError, match="no such recording"):
        R.summarize_recording(tmp_path / "missing.rrd")
    bad = tmp_path / "bad.rrd"
    bad.write_text("not a recording\n" * 10)
    with pytest.raises(ConfigError, match="not a readable Rerun recording"):
        R.summarize_recording(bad)


def test_recording_path_and_flags():
    parser = argparse.ArgumentParser()
    R.add_recording_arguments(parser)
    now = datetime(2026, 1, 2, 3, 4, 5, tzinfo=UTC)
    assert R.recording_path(parser.parse_args([]), "paper table2", now) == Path(
        "logs/paper_table2-20260102T030405Z.rrd"
    )
    assert R.recording_path(parser.parse_args(["--no-record"]), "p") is None
    assert R.recording_path(parser.parse_args(["--rrd", "x/y.rrd"]), "p") == Path("x/y.rrd")
    with pytest.raises(ConfigError, match="--rrd"):
        R.recording_path(parser.parse_args(["--rrd", "x/y.txt"]), "p")
    with pytest.raises(ConfigError, match="--record-every"):
        R.recording_path(parser.parse_args(["--record-every", "0"]), "p")
    assert R.recording_decimation(parser.parse_args(["--record-every", "5"])) == 5
    with pytest.raises(SystemExit):
        parser.parse_args(["--rrd", "a.rrd", "--no-record"])


def test_analysis_and_synthesis_records(tmp_path):
    omega = np.logspace(-2, 1, 50)
    mag = 1.0 / np.sqrt(1.0 + (omega / 0.5) ** 2)
    classes = np.zeros((4, 5), dtype=int)
    classes[1:, 2:] = 1
    classes[2:, 3:] = 2
    mu = np.linspace(-1, 1, 5)
    k = np.linspace(-2, 2, 4)
    gains = {
        "state_names": ["s_0", "v_0", "s_1"],
        "gains": {"v_0": -0.5, "s_1": -0.2},
        "h2_true": 3.5,
    }
    path = tmp_path / "an.rrd"
    with R.open_recording(path, "analysis", R.analysis_blueprint(["case A"], ["mu_k"])) as rec:
        R.record_gamma(rec, "case A", omega, mag, {"string_stable": True})
        R.record_region_map(rec, "mu_k", classes, mu, k)
        R.record_gains(rec, "fd h2", gains)
    chunks = _chunks(path)
    strip = np.array(_static(chunks, "/analysis/gamma/case_A", "LineStrips2D:strips")[0])
    np.testing.assert_allclose(strip[:, 0], np.log10(omega), rtol=1e-6)
    np.testing.assert_allclose(-strip[:, 1], mag, rtol=1e-6)  # y up: stored as -|Gamma|
    rep = _static(chunks, "/analysis/gamma/case_A/report", "TextDocument:text")
    assert "string_stable" in rep and "True" in rep
    buf = _static(chunks, "/analysis/regions/mu_k", "SegmentationImage:buffer")
    img = np.array(buf, dtype=np.uint8).reshape(4, 5)
    np.testing.assert_array_equal(img, classes[::-1])  # k increasing upwards
    rep = _static(chunks, "/analysis/regions/mu_k/report", "TextDocument:text")
    assert "| fraction string stable | 0.2 |" in rep  # 4 of 20 points
    assert "| fraction plant stable | 0.45 |" in rep  # 9 of 20 points
    values = _static(chunks, "/synthesis/fd_h2/gains", "BarChart:values")[0]["buffer"]
    np.testing.assert_array_equal(values, [0.0, -0.5, -0.2])  # state order, missing = 0
    rep = _static(chunks, "/synthesis/fd_h2/report", "TextDocument:text")
    assert "| v_0 | -0.5 |" in rep and "| s_0 | 0 |" in rep and "h2_true" in rep
    with pytest.raises(ConfigError, match="classes"):
        with R.open_recording(tmp_path / "bad.rrd", "x") as rec:
            R.record_region_map(rec, "bad", classes[:, :3], mu, k)


def test_mpc_history_is_recorded(tmp_path):
    """The MPC controller's ``history()`` layout: (B, S, ...) arrays, offsets ``pred_time``."""
    B, S, N, V = 2, 20, 5, 3
    t = 0.1 * np.arange(S)
    rng = np.random.default_rng(1)
    hist = {
        "t": t,
        "step_time": rng.uniform(1e-3, 2e-3, (B, S)),
        "osqp_time": rng.uniform(5e-4, 1e-3, (B, S)),
        "status": rng.integers(0, 4, (B, S)),
        "plan": rng.normal(size=(B, S, N)),
        "predicted_velocity": 15 + rng.normal(size=(B, S, N + 1, V)),
        "pred_time": 0.1 * np.arange(N + 1),
    }
    path = tmp_path / "mpc.rrd"
    with R.open_recording(path, "m") as rec:
        R.record_mpc_history(rec, "/m/mpc_ctrl", hist, run=1, plan_every=2)
    chunks = _chunks(path)
    t_ns, st = _temporal(chunks, "/m/mpc_ctrl/mpc/solve_time_ms", "Scalars:scalars")
    np.testing.assert_array_equal(t_ns, np.round(t * 1e9).astype(np.int64))
    np.testing.assert_allclose(
        np.array(st), 1e3 * np.column_stack([hist["step_time"][1], hist["osqp_time"][1]])
    )
    _, status = _temporal(chunks, "/m/mpc_ctrl/mpc/status", "Scalars:scalars")
    np.testing.assert_array_equal(np.array(status)[:, 0], hist["status"][1])
    np.testing.assert_array_equal(np.array(status)[:, 1], hist["status"][1] > 0)
    t_ns, strips = _temporal(chunks, "/m/mpc_ctrl/mpc/predicted/velocity", "LineStrips2D:strips")
    np.testing.assert_array_equal(t_ns, np.round(t[::2] * 1e9).astype(np.int64))
    k = 3  # the plan recorded at controller step 6
    got = np.array(strips[k])  # (V, N + 1, 2)
    np.testing.assert_allclose(got[..., 0], np.tile(hist["pred_time"], (V, 1)), rtol=1e-6)
    np.testing.assert_allclose(-got[..., 1], hist["predicted_velocity"][1, 6].T, rtol=1e-6)
    _, u = _temporal(chunks, "/m/mpc_ctrl/mpc/predicted/u", "LineStrips2D:strips")
    np.testing.assert_allclose(-np.array(u[k])[0, :, 1], hist["plan"][1, 6], rtol=1e-6)


def test_simulation_recorder_records_as_results_arrive(tmp_path):
    """The CLI helper: opens at the first result, records each controller, then metrics."""
    import contextlib
    from types import SimpleNamespace

    parser = argparse.ArgumentParser()
    R.add_recording_arguments(parser)
    path = tmp_path / "cli.rrd"
    args = parser.parse_args(["--rrd", str(path), "--record-every", "3"])
    ctrls = {c.name: c for c in _controllers()}
    spec = SimpleNamespace(name="rec test", controllers=ctrls)
    sc = _scenario(duration=2.0)
    with pytest.raises(Boom), contextlib.ExitStack() as stack:
        recorder = R.SimulationRecorder(args, stack)
        first = simulate(sc, ctrls["all_hdv"])
        recorder(spec, "all_hdv", first)
        recorder.metrics({"all_hdv": {"aave": 1.25, "controller": {"type": "hdv"}}})
        raise Boom("interrupted after the first controller")
    s = R.summarize_recording(path)
    assert s.entities["/rec_test/all_hdv/velocity"].samples == len(range(0, 200, 3)) + 1
    assert "| aave | 1.25 |" in s.texts["/rec_test/all_hdv/metrics"]
    assert "Boom" in s.texts["/rec_test/status"]
    off = R.SimulationRecorder(parser.parse_args(["--no-record"]), contextlib.ExitStack())
    off(spec, "all_hdv", first)
    assert off.path is None and off.rec is None
    with pytest.raises(ConfigError, match="--rrd"):
        R.SimulationRecorder(parser.parse_args(["--rrd", "x.txt"]), contextlib.ExitStack())


def test_mpc_controller_history_reaches_the_recording(tmp_path):
    """A real MPC run recorded through the CLI helper: solve times and plans are in the file."""
    import contextlib
    from types import SimpleNamespace

    mpc = pytest.importorskip("lcc_synth.mpc")
    from lcc_synth.problem import system_from

    system = system_from({"system": {"kind": "fd_lcc", "m": 0, "n": 3, "v_star": 15.0}})
    ctrl = mpc.mpc_controller_from_table("mpc", {"type": "mpc", "horizon": 10}, system)
    sc = Scenario(m=0, n=3, duration=2.0, perturbations=(Brake(vehicle=1, start=0.5),))
    res = simulate(sc, ctrl)
    hist = ctrl.history()
    parser = argparse.ArgumentParser()
    R.add_recording_arguments(parser)
    path = tmp_path / "mpc_run.rrd"
    with contextlib.ExitStack() as stack:
        recorder = R.SimulationRecorder(
            parser.parse_args(["--rrd", str(path), "--record-every", "1"]), stack
        )
        recorder(SimpleNamespace(name="mpc demo", controllers={"mpc": ctrl}), "mpc", res)
    chunks = _chunks(path)
    t_ns, st = _temporal(chunks, "/mpc_demo/mpc/mpc/solve_time_ms", "Scalars:scalars")
    np.testing.assert_array_equal(t_ns, np.round(hist["t"] * 1e9).astype(np.int64))
    np.testing.assert_allclose(np.array(st)[:, 0], 1e3 * hist["step_time"][0])
    _, plans = _temporal(chunks, "/mpc_demo/mpc/mpc/predicted/u", "LineStrips2D:strips")
    assert len(plans) == len(hist["t"])
    np.testing.assert_allclose(-np.array(plans[5])[0, :, 1], hist["plan"][0, 5], rtol=1e-6)
    origins = {v["space_origin"] for v in R.summarize_recording(path).views}
    assert {"/mpc_demo/mpc/mpc", "/mpc_demo/mpc/mpc/predicted/velocity"} <= origins


SMALL_PROBLEM = """
name = "small table2"
[system]
kind = "fd_lcc"
m = 0
n = 3
v_star = 15.0
[scenario]
dt = 0.01
duration = 4.0
[[scenario.perturbations]]
type = "brake"
vehicle = 1
start = 1.0
duration = 1.0
decel = -5.0
[controllers.all_hdv]
type = "hdv"
[controllers.fd_lcc]
type = "static"
kind = "fd_lcc"
semantics = "replace"
gains = { v_0 = -0.5, s_1 = -0.2, v_1 = 0.05, s_2 = -0.1, v_2 = 0.05 }
[metrics]
window = [1.0, 4.0]
baseline = "all_hdv"
"""


def test_simulate_command_records_every_controller(tmp_path, capsys, monkeypatch):
    import json

    from lcc_synth.cli.main import main

    problem = tmp_path / "small.toml"
    problem.write_text(SMALL_PROBLEM)
    path = tmp_path / "sim.rrd"
    exact = ["--record-every", "1"]  # every step, value for value (the default is minmax)
    assert main(["simulate", str(problem), "--json", "--rrd", str(path), *exact]) == 0
    captured = capsys.readouterr()
    results = json.loads(captured.out)["results"]  # stdout: the JSON object only
    assert str(path) in captured.err
    s = R.summarize_recording(path)
    for name, entry in results.items():
        vel = s.entities[f"/small_table2/{name}/velocity"]
        assert vel.samples == 400 and vel.series == 5
        assert f"| aave | {entry['aave']:.6g} |" in s.texts[f"/small_table2/{name}/metrics"]
    assert "reduction_vs_baseline" in s.texts["/small_table2/fd_lcc/metrics"]
    assert "complete" in s.texts["/small_table2/status"]
    # --no-record writes nothing; the default path is logs/<problem>-<UTC>.rrd in the cwd
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", str(problem), "--no-record", "--json"]) == 0
    assert "recording:" not in capsys.readouterr().err and not (tmp_path / "logs").exists()
    assert main(["simulate", str(problem), "--json", "--record-every", "5"]) == 0
    [default] = (tmp_path / "logs").glob("small_table2-*Z.rrd")
    assert re.fullmatch(r"small_table2-\d{8}T\d{6}Z\.rrd", default.name)
    assert R.summarize_recording(default).entities["/small_table2/fd_lcc/velocity"].samples == 81


def test_synthesize_command_records_gains_and_gamma(tmp_path, capsys):
    """Gains bar chart = the gains file; the recorded |Gamma| curve peaks at the reported
    global peak (state-space curve vs the synthesis report's string-stability check)."""
    import json

    from lcc_synth.cli.main import main

    problem = Path(__file__).resolve().parents[1] / "problems" / "synth_cf_lcc_pattern.toml"
    if not problem.is_file():
        pytest.skip("problems/synth_cf_lcc_pattern.toml not available")
    path, gains_path = tmp_path / "syn.rrd", tmp_path / "gains.json"
    assert main(["synthesize", str(problem), "--rrd", str(path), "--out", str(gains_path)]) == 0
    doc = json.loads(gains_path.read_text())
    chunks = _chunks(path)
    name = R.entity_name(problem.stem)
    [entity] = [e for e in chunks if e.startswith("/synthesis/") and e.endswith("/gains")]
    bars = np.array(_static(chunks, entity, "BarChart:values")[0]["buffer"])  # TensorData
    np.testing.assert_allclose(bars.ravel(), [doc["gains"].get(s, 0.0) for s in doc["state_names"]])
    report = _static(chunks, entity.replace("/gains", "/report"), "TextDocument:text")
    assert "h2_true" in report and "h2_lmi_bound" in report
    [gamma] = [
        e
        for e in chunks
        if e.startswith("/analysis/gamma/") and e.count("/") == 3 and not e.endswith("unit")
    ]
    curve = np.array(_static(chunks, gamma, "LineStrips2D:strips")[0])
    # x = log10 omega on the grid of R.gamma_grid; |Gamma| never above the global peak, and
    # |Gamma(0)| = 1 for every stabilising gain (the curve starts at omega = 1e-3 rad/s)
    np.testing.assert_allclose(
        curve[:, 0], np.log10(R.gamma_grid(doc["gamma_peak_omega"])), rtol=1e-6
    )
    assert (-curve[:, 1]).max() <= doc["gamma_peak"] * (1 + 1e-6)  # y up: stored as -|Gamma|
    assert -curve[0, 1] == pytest.approx(1.0, abs=1e-3)
    if doc["gamma_peak_omega"] > 0:
        assert (-curve[:, 1]).max() == pytest.approx(doc["gamma_peak"], rel=1e-5)
    assert name in gamma or "/analysis/gamma/" in gamma
    assert str(path) in capsys.readouterr().err
    # the one synthesis blueprint (a platoon's: tests/test_recording_platoon.py): the gains,
    # the |Gamma| curves and the report (no Pareto view: a structured design)
    assert set(_views(path)) == {
        ("BarChart", f"/synthesis/{name}/gains", f"{problem.stem}: gains"),
        ("2D", "/analysis/gamma", "|Γ(jω)| vs log10 ω"),
        ("TextDocument", f"/synthesis/{name}/report", f"{problem.stem}: report"),
    }


def test_region_maps_and_gamma_curves_of_the_analysis_commands(tmp_path):
    """``record_analysis_file`` with real region maps (labels[a, b] at (mu[a], k[b])) and a
    real |Gamma| curve: the image is the labels transposed with k upwards."""
    regions = pytest.importorskip("lcc_synth.analysis.regions")
    from lcc_synth.analysis.transfer import gamma_state_space

    model = model_from_hdv("lcc", 2, 2, OVM(), 15.0, warn=False)
    mu = np.linspace(-2.0, 2.0, 9)
    k = np.linspace(-2.0, 2.0, 7)
    labels = np.zeros((mu.size, k.size), dtype=np.int8)
    labels[3:, 2:] = 1
    labels[5:, 4:] = 2
    rm = regions.RegionMap("a", -1, mu, k, labels)
    omega = R.gamma_grid()
    from lcc_synth.models.feedback import input_feedback

    K, kh = input_feedback(model, Gains.named({}, "added"))  # the CAV drives like an HDV
    mag = np.abs(gamma_state_space(model, K, kh, omega))
    path = R.record_analysis_file(
        tmp_path / "an.rrd",
        "fig7",
        gamma={"hdv only": (omega, mag, {"string_stable": False})},
        regions={"a": rm},
        region_reports={"a": {"vehicle": -1}},
        summary={"problem": "fig7", "cases": {"hdv only": {"gamma_peak": float(mag.max())}}},
    )
    chunks = _chunks(path)
    buf = _static(chunks, "/analysis/regions/a", "SegmentationImage:buffer")
    img = np.array(buf, dtype=np.uint8).reshape(k.size, mu.size)
    np.testing.assert_array_equal(img, labels.T[::-1])
    rep = _static(chunks, "/analysis/regions/a/report", "TextDocument:text")
    assert f"| fraction string stable | {_fmt_frac(labels)} |" in rep and "| vehicle | -1 |" in rep
    curve = np.array(_static(chunks, "/analysis/gamma/hdv_only", "LineStrips2D:strips")[0])
    np.testing.assert_allclose(-curve[:, 1], mag, rtol=1e-6)
    assert mag.max() > 1.0  # the paper's OVM setup is string unstable with HDVs only
    assert "gamma_peak" in _static(chunks, "/analysis/report", "TextDocument:text")
    assert R.summarize_recording(path).has_blueprint


def _fmt_frac(labels) -> str:
    return f"{np.count_nonzero(labels == 2) / labels.size:.6g}"


def test_analyze_and_regions_commands_record(tmp_path, capsys):
    """The recorded |Gamma| peaks / region fractions equal the commands' --json reports."""
    import json

    from lcc_synth.cli.main import main

    problems = Path(__file__).resolve().parents[1] / "problems"
    fig9, regions = problems / "paper_fig9_cases.toml", problems / "paper_fig7_fig8_regions.toml"
    if not (fig9.is_file() and regions.is_file()):
        pytest.skip("paper problem files not available")
    a = tmp_path / "a.rrd"
    assert main(["analyze", str(fig9), "--json", "--rrd", str(a)]) == 0
    doc = json.loads(capsys.readouterr().out)
    chunks = _chunks(a)
    for name, case in doc["cases"].items():
        if case.get("gamma_peak") is None:
            continue
        curve = np.array(_static(chunks, f"/analysis/gamma/{name}", "LineStrips2D:strips")[0])
        assert (-curve[:, 1]).max() <= case["gamma_peak"] * (1 + 1e-6)  # grid max <= global sup
        assert (-curve[:, 1]).min() > 0  # |Gamma| stored as -|Gamma| (y up)
    r = tmp_path / "r.rrd"
    assert main(["regions", str(regions), "--json", "--step", "1.0", "--rrd", str(r)]) == 0
    doc = json.loads(capsys.readouterr().out)
    chunks = _chunks(r)
    for name, entry in doc["maps"].items():
        buf = _static(chunks, f"/analysis/regions/{name}", "SegmentationImage:buffer")
        img = np.array(buf, dtype=np.uint8)
        assert np.count_nonzero(img == 2) / img.size == pytest.approx(
            entry["string_stable_fraction"]
        )
        assert np.count_nonzero(img >= 1) / img.size == pytest.approx(
            entry["plant_stable_fraction"]
        )


def test_collisions_and_emergency_braking_are_events_on_the_timeline(tmp_path):
    """A CAV that ignores a hard-braking head vehicle: AEB edges and the collision appear as
    TextLog events at the simulator's times; NaN samples after the collision stay NaN."""
    model = model_from_hdv("lcc", 1, 2, OVM(), 15.0, warn=False)
    sc = Scenario(
        m=1, n=2, duration=20.0, perturbations=(Brake(vehicle="head", start=1.0, duration=3.0),)
    )
    res = simulate(sc, StaticGainController("blind", Gains.named({}, "replace"), model))
    assert res.collided[0].any() and res.aeb_active[0].any()  # the scenario does what we need
    path = tmp_path / "crash.rrd"
    with R.open_recording(path, "crash", R.simulation_blueprint("crash", ["blind"])) as rec:
        R.record_simulation(rec, res, "crash", decimate=1)
    chunks = _chunks(path)
    t_ns, texts = _temporal(chunks, "/crash/blind/events", "TextLog:text")
    _, levels = _temporal(chunks, "/crash/blind/events", "TextLog:level")
    aeb = res.aeb_active[0].astype(int)
    edges = np.flatnonzero(np.diff(aeb, prepend=0))
    expected = sorted(
        [(round(res.t[k] * 1e9), "AEB", aeb[k]) for k in edges]
        + [
            (round(res.collision_time[0, i] * 1e9), "COL", i)
            for i in np.flatnonzero(res.collided[0])
        ]
    )
    assert list(t_ns) == [e[0] for e in expected]
    for (_, kind, _), text, level in zip(expected, texts, levels, strict=True):
        assert (kind == "COL") == ("COLLISION" in text[0]) and level[0] == (
            "ERROR" if kind == "COL" else "WARN"
        )
    _, vel = _temporal(chunks, "/crash/blind/velocity", "Scalars:scalars")
    np.testing.assert_array_equal(np.isnan(np.array(vel)), np.isnan(res.velocity[0]))
    assert "collisions: cav at t = " in R.summarize_recording(path).texts["/crash/blind/metrics"]


def test_killed_process_leaves_the_flushed_controllers_readable(tmp_path):
    """A process killed after recording a controller (no finalisation, no footer): nothing
    appears under the final name (a reader never sees a half file), and the private temporary
    file still reads back, marked not finalised, with that controller's data."""
    import subprocess
    import sys

    path = tmp_path / "killed.rrd"
    code = (
        "import os\n"
        "from lcc_synth.simulation.engine import Scenario, simulate\n"
        "from lcc_synth.controllers.static import HDVController\n"
        "from lcc_synth import recording as R\n"
        "r = simulate(Scenario(m=0, n=2, duration=3.0), HDVController('h'))\n"
        f"cm = R.open_recording({str(path)!r}, 'k')\n"
        "rec = cm.__enter__()\n"
        "R.record_simulation(rec, r, 'k', decimate=1)\n"
        "rec.flush()\n"
        "os._exit(9)  # killed: no context-manager exit\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=120)
    assert proc.returncode == 9, proc.stderr.decode()
    assert not path.exists()
    (tmp,) = tmp_path.glob(".killed.part-*.rrd")
    s = R.summarize_recording(tmp)
    assert not s.finalized
    assert s.entities["/k/h/velocity"].samples == 300
