"""Recordings of several CAVs and of the ring road: the ring drawn as a circle (angle
``2 pi p / C``), one command series per CAV, CAVs colour-coded, read back from the file."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rerun")

from rerun.chunk import RrdReader  # noqa: E402
from test_recording import _static, _views  # noqa: E402  (tests/ is on sys.path)

from lcc_synth import recording as R  # noqa: E402
from lcc_synth.experiments.spec import load_spec  # noqa: E402
from lcc_synth.recording.simulation import (  # noqa: E402
    CAV_COLORS,
    RING_V_SCALE,
    ring_view,
    vehicle_style,
)
from lcc_synth.simulation.engine import simulate  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _chunks(path: Path) -> dict[str, list]:
    out: dict[str, list] = {}
    for ch in RrdReader(path).stream():
        out.setdefault(ch.entity_path, []).append(ch)
    return out


def _temporal(chunks, entity: str, component: str) -> list:
    times, values = [], []
    for ch in chunks[entity]:
        if ch.is_static:
            continue
        rb = ch.to_record_batch()
        if component in rb.schema.names:
            times.append(rb.column("time").cast("int64").to_numpy())
            values += rb.column(component).to_pylist()
    order = np.argsort(np.concatenate(times), kind="stable")
    return [values[i] for i in order]


def _record(tmp_path, problem: str, duration: float):
    spec = load_spec(ROOT / "problems" / problem)
    sc = replace(spec.scenario, duration=duration)
    results = {n: simulate(sc, c) for n, c in spec.controllers.items()}
    path = tmp_path / f"{spec.name}.rrd"
    with R.open_recording(path, spec.name, R.simulation_blueprint(spec.name, list(results))) as rec:
        for res in results.values():
            R.record_simulation(rec, res, spec.name, decimate=1)
    return path, results, spec.name


def test_ring_road_view_is_the_circle_of_the_positions(tmp_path):
    path, results, name = _record(tmp_path, "ring_stop_and_go.toml", 60.0)
    chunks = _chunks(path)
    res = results["all_hdv"]
    C = res.circumference
    road = np.array(_temporal(chunks, f"/{name}/all_hdv/road", "Points2D:positions"))
    assert road.shape == (len(res.t), 20, 2)
    p, v = res.position[0], res.velocity[0]
    # angle 2 pi p / C (positions are not wrapped by the simulator)
    ang = np.angle(road[..., 0] - 1j * road[..., 1])  # y up: the screen y is negated
    want = 2 * np.pi * np.mod(p, C) / C
    assert np.abs(np.angle(np.exp(1j * (ang - want)))).max() < 1e-5
    radius = np.hypot(road[..., 0], road[..., 1])
    R0 = C / (2 * np.pi)
    assert np.allclose(radius, R0 * (1 + RING_V_SCALE * (v - 15.0)), rtol=1e-5)
    assert p.max() > 2 * C  # the vehicles went round more than twice (p is not wrapped)
    # the initial state: 20 m apart on the circle (an angle of 2 pi / 20 between neighbours)
    assert np.allclose(np.diff(np.unwrap(ang[0])), -2 * np.pi / 20, atol=1e-5)
    # spacing series of all 20 vehicles (column 0's gap to the last vehicle included)
    sp = np.array(_temporal(chunks, f"/{name}/all_hdv/spacing", "Scalars:scalars"))
    np.testing.assert_array_equal(sp, res.spacing[0])
    np.testing.assert_allclose(ring_view(np.array([0.0, -C / 4]), 15.0, 15.0, C),
                               [[R0, 0.0], [0.0, R0]], atol=1e-9)  # fmt: skip (y negated)


@pytest.mark.slow  # CI runs it; by default: the two-CAV ring's design recording (below)
def test_platoon_recording_has_one_command_per_cav_and_coloured_cavs(tmp_path):
    path, results, name = _record(tmp_path, "platoon_deeplcc_brake.toml", 10.0)
    chunks = _chunks(path)
    res = results["lqr"]
    u = np.array(_temporal(chunks, f"/{name}/lqr/cav/u_cmd", "Scalars:scalars"))
    np.testing.assert_array_equal(u, res.u_cmd[0])
    assert u.shape == (len(res.t), 2)
    names, colors, _ = vehicle_style(res)
    assert names == ["head", "p1", "p2", "cav3", "p4", "p5", "cav6", "p7", "p8"]
    assert tuple(colors[3]) == CAV_COLORS[0] and tuple(colors[6]) == CAV_COLORS[1]
    road = np.array(_temporal(chunks, f"/{name}/lqr/road", "Points2D:positions"))
    np.testing.assert_array_equal(
        road[..., 0], (res.position[0] - res.position[0, :, 3:4]).astype(np.float32)
    )


def test_synthesize_records_a_two_cav_ring_design_with_its_range_front(tmp_path, capsys):
    """``lcc-synth synthesize`` of a ring with two CAVs (design = "sparsity") writes a
    recording: each CAV's bar chart is its row of the gains file, the report names the chosen
    point of the range front, and the front's bars are each point's loss against the
    unstructured optimum recomputed from the JSON report (H2 / H2* - 1)."""
    import json

    from lcc_synth.cli.main import main

    text = (ROOT / "problems" / "ring_n20_cr5.toml").read_text()
    text = text.replace("cavs = [20]", "cavs = [10, 20]").replace("comm_range = 5\n", "")
    text = text.replace('design = "structured"', 'design = "sparsity"')
    problem = tmp_path / "ring2.toml"
    problem.write_text(text + "\n[synthesis.sparsity]\nmax_loss = 0.05\n")
    path, gains = tmp_path / "ring2.rrd", tmp_path / "gains.json"
    assert main(["synthesize", str(problem), "--rrd", str(path), "--out", str(gains),
                 "--json", "--no-progress"]) == 0  # fmt: skip
    cap = capsys.readouterr()
    doc, file_doc = json.loads(cap.out), json.loads(gains.read_text())
    assert f"recording: {path}" in cap.err
    chunks = _chunks(path)
    name = R.entity_name(doc["problem"])
    assert set(file_doc["gains"]) == {"u_10", "u_20"}
    for cav, row in file_doc["gains"].items():
        bars = np.array(_static(chunks, f"/synthesis/{name}/{cav}/gains", "BarChart:values")[0]
                        ["buffer"]).ravel()  # fmt: skip
        np.testing.assert_array_equal(bars, [row.get(s, 0.0) for s in doc["state_names"]])
        report = _static(chunks, f"/synthesis/{name}/{cav}/report", "TextDocument:text")
        assert "heard positions" in report
    loss = np.array(_static(chunks, f"/synthesis/{name}/pareto/loss_percent",
                            "BarChart:values")[0]["buffer"]).ravel()  # fmt: skip
    expected = [100.0 * (p["h2"] / doc["h2_unstructured"] - 1.0) for p in doc["pareto"]]
    np.testing.assert_allclose(loss, expected, rtol=1e-9)
    assert loss[-1] < 0.5 and np.all(np.diff(loss) <= 0)  # the greedy front never gets worse
    report = _static(chunks, f"/synthesis/{name}/report", "TextDocument:text")
    [chosen] = [k for k, p in enumerate(doc["pareto"]) if p["chosen"]]
    assert "range front" in report and f"| {chosen} | u_10 " in report
    assert report.count("| yes |") == 1 and "h2_unstructured" in report
    summary = R.summarize_recording(path)
    assert f"/synthesis/{name}/u_20/gains" in summary.entities
    # the one synthesis blueprint: a bar chart and a report per CAV, the front's losses, the
    # whole report; no |Gamma| view (one CAV's only)
    assert set(_views(path)) == {
        *{("BarChart", f"/synthesis/{name}/{c}/gains", f"{c}: gains") for c in ("u_10", "u_20")},
        *{("TextDocument", f"/synthesis/{name}/{c}/report", f"{c}: report")
          for c in ("u_10", "u_20")},
        ("BarChart", f"/synthesis/{name}/pareto/loss_percent",
         "range front: H2 loss % per greedy step"),
        ("TextDocument", f"/synthesis/{name}/report", f"{doc['problem']}: report"),
    }  # fmt: skip


def test_synthesize_platoon_refuses_figure_and_records_by_default(tmp_path, monkeypatch):
    """``--figure`` is refused for a platoon design (exit 2, the flag named); without ``--rrd``
    the recording goes to ``logs/<problem>-<UTC time>.rrd`` as for one CAV."""
    from lcc_synth.cli.main import main

    problem = ROOT / "problems" / "ring_n20_cr5.toml"
    monkeypatch.chdir(tmp_path)
    assert main(["synthesize", str(problem), "--figure", "x.png"]) == 2
    assert not (tmp_path / "x.png").exists()
    assert main(["synthesize", str(problem), "--no-progress"]) == 0
    [rrd] = (tmp_path / "logs").glob("ring_n20_cr5-*.rrd")
    assert "/synthesis/ring_n20_cr5/u_20/gains" in R.summarize_recording(rrd).entities


def test_run_records_a_platoon_design_row_per_cav(tmp_path):
    """``lcc-synth run`` records each synthesised design with the one synthesis recorder: the
    showcase's two-CAV platoon design gets a bar chart per CAV equal to its row of the gains
    file the run writes (never one chart of the state gains, which a row per CAV does not
    have), with those views in the run's "synthesised gains" tab."""
    import json

    from lcc_synth.cli.main import main

    path, out = tmp_path / "run.rrd", tmp_path / "out"
    assert main(["run", str(ROOT / "problems" / "showcase.toml"), "--scenarios", "platoon_brake",
                 "--controllers", "h2", "--rrd", str(path), "--out", str(out), "--no-figures",
                 "-q"]) == 0  # fmt: skip
    [gains_file] = out.glob("*/gains_platoon8_h2.json")
    doc = json.loads(gains_file.read_text())
    chunks = _chunks(path)
    name = R.entity_name("platoon8.h2")
    assert set(doc["gains"]) == {"u_3", "u_6"} and f"/synthesis/{name}/gains" not in chunks
    for cav, row in doc["gains"].items():
        bars = np.array(_static(chunks, f"/synthesis/{name}/{cav}/gains", "BarChart:values")[0]
                        ["buffer"]).ravel()  # fmt: skip
        np.testing.assert_array_equal(bars, [row.get(s, 0.0) for s in doc["state_names"]])
        assert np.abs(bars).max() > 0.1  # a stabilising feedback, not a chart of zeros
    views = set(_views(path))
    for cav in ("u_3", "u_6"):
        assert ("BarChart", f"/synthesis/{name}/{cav}/gains", f"{cav}: gains") in views
        assert ("TextDocument", f"/synthesis/{name}/{cav}/report", f"{cav}: report") in views
    assert ("TextDocument", f"/synthesis/{name}/report", "platoon8.h2: report") in views
