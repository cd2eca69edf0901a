"""Min/max-preserving decimation of recordings (``record_simulation(decimate="minmax")``,
the default of ``lcc-synth run``) and the one-screen ``review --summary``.

Independent truth: the simulated arrays themselves (the recording's extremes must equal them
exactly), a brute-force loop over every bucket, and a spike placed between two grid rows that
naive striding provably drops.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rerun")

from rerun.chunk import RrdReader  # noqa: E402

from lcc_synth import recording as R  # noqa: E402
from lcc_synth.cli.main import main  # noqa: E402
from lcc_synth.experiments.spec import load_spec  # noqa: E402
from lcc_synth.recording.decimate import VIEWER_TOLERANCE, minmax_rows  # noqa: E402
from lcc_synth.recording.summary import MAX_LINES, full_lines, summary_lines  # noqa: E402
from lcc_synth.simulation.engine import simulate_many  # noqa: E402

# The showcase's hard head brake among noisy heterogeneous HDVs, on a 4-HDV string: the
# paper's gain with a fixed v* needs emergency braking (AEB), so events are exercised too.
PROBLEM = """
name = "dec"
[system]
kind = "cf_lcc"
m = 0
n = 4
v_star = 15.0
[scenario]
dt = 0.01
duration = 30.0
seed = 3
hdv_accel_noise = 0.1
heterogeneity = { alpha = 0.1, beta = 0.1, s_go = 5.0 }
delay = { mean = 0.4, spread = 0.1 }
v2v = { loss_rate = 0.2, latency = 0.1, spacing_noise = 0.1, velocity_noise = 0.05 }
[[scenario.perturbations]]
type = "brake_profile"
start = 5.0
decel = -5.0
decel_time = 2.0
hold_time = 5.0
accel = 2.0
accel_time = 5.0
[controllers.all_hdv]
type = "hdv"
[controllers.paper]
type = "static"
kind = "cf_lcc"
semantics = "replace"
gains = { s_0 = 0.1, v_0 = -0.5, s_1 = -0.2, v_1 = 0.05, s_2 = -0.1, v_2 = 0.05 }
[metrics]
window = [5.0, 30.0]
"""


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("dec")
    problem = tmp / "dec.toml"
    problem.write_text(PROBLEM)
    spec = load_spec(problem)
    results = simulate_many(spec.scenario, spec.controllers)
    paths = {}
    for how in ("minmax", 1):
        paths[how] = tmp / f"dec_{how}.rrd"
        with R.open_recording(paths[how], "dec") as rec:
            for name, res in results.items():
                R.record_simulation(rec, res, "dec", controller=name, decimate=how)
    return results, paths


def _entity(path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """``(times s, values (rows, series))`` of a Scalars / Points2D entity read back."""
    times, values = [], []
    for chunk in RrdReader(path).stream():
        if str(chunk.entity_path) != entity or chunk.is_static:
            continue
        rb = chunk.to_record_batch()
        for comp in ("Scalars:scalars", "Points2D:positions"):
            if comp in rb.schema.names:
                col = rb.column(comp).to_pylist()
                values += [np.asarray(v, dtype=np.float64).reshape(len(v), -1) for v in col]
                times += (rb.column("time").cast("int64").to_numpy() / 1e9).tolist()
    order = np.argsort(times, kind="stable")
    return np.asarray(times)[order], np.stack(values)[order]


def test_recorded_extremes_equal_the_simulated_ones_exactly(recorded):
    results, paths = recorded
    for name, res in results.items():
        t_sp, sp = _entity(paths["minmax"], f"/dec/{name}/spacing")
        true_sp = np.asarray(res.spacing)[0, :, 1:]
        assert np.nanmin(sp) == np.nanmin(true_sp)  # the minimum spacing, exactly
        np.testing.assert_array_equal(np.nanmin(sp[..., 0], axis=0), np.nanmin(true_sp, axis=0))
        _, u = _entity(paths["minmax"], f"/dec/{name}/cav/u_cmd")
        assert np.max(np.abs(u)) == np.max(np.abs(res.u_cmd[0]))  # max |u|, exactly
        _, acc = _entity(paths["minmax"], f"/dec/{name}/acceleration")
        np.testing.assert_array_equal(acc[..., 0].max(axis=0), res.acceleration[0].max(axis=0))
        np.testing.assert_array_equal(acc[..., 0].min(axis=0), res.acceleration[0].min(axis=0))
        # the recorded rows are simulated rows, at their own times
        k = np.round(t_sp / res.dt).astype(int) - int(round(res.t[0] / res.dt))
        np.testing.assert_array_equal(sp[..., 0], true_sp[k])
        # outside emergency braking (full rate) smooth series keep about one row in ten
        t_v, _ = _entity(paths["minmax"], f"/dec/{name}/velocity")
        aeb = int(np.asarray(res.aeb_active).sum())
        assert len(t_v) < len(res.t) / 6 + 1.5 * aeb, (name, len(t_v), aeb)


def test_emergency_braking_is_recorded_at_full_rate(recorded):
    results, paths = recorded
    res = results["paper"]
    aeb = np.asarray(res.aeb_active)[0].astype(bool)
    assert aeb.sum() > 10  # the fixed-v* paper gain needs AEB after the head's brake
    for entity in ("cav/aeb_active", "acceleration", "cav/u_cmd", "spacing"):
        t, _ = _entity(paths["minmax"], f"/dec/paper/{entity}")
        kept = set(np.round(t / res.dt).astype(int).tolist())
        assert set(np.round(res.t[aeb] / res.dt).astype(int).tolist()) <= kept, entity


def test_minmax_rows_keep_every_bucket_extreme_and_a_spike_striding_drops():
    rng = np.random.default_rng(0)
    T, b = 2003, 20
    v = np.cumsum(rng.normal(size=(T, 3)), axis=0) + rng.normal(scale=3.0, size=(T, 3))
    v[1010, 1] += 500.0  # a spike between two grid rows (1000, 1020)
    v[1500:1530, 2] = np.nan  # a gap (a collided vehicle)
    idx = minmax_rows(v, b)
    assert 1010 in idx and 1010 not in range(0, T, b)  # striding would drop the spike
    assert {1499, 1500, 1529, 1530} <= set(idx.tolist()) and {0, T - 1} <= set(idx.tolist())
    tol = VIEWER_TOLERANCE * (np.nanmax(v) - np.nanmin(v))
    kept = np.zeros(T, bool)
    kept[idx] = True
    for start in range(0, T - 1, b):  # brute force over every bucket and series
        sl = slice(start, min(start + b, T - 1) + 1)
        for j in range(3):
            x, k = v[sl, j], kept[sl]
            if np.isnan(x).all():
                continue
            assert np.nanmax(x[k]) >= np.nanmax(x) - tol
            assert np.nanmin(x[k]) <= np.nanmin(x) + tol
    for j in range(3):
        assert np.nanmax(v[idx, j]) == np.nanmax(v[:, j])
        assert np.nanmin(v[idx, j]) == np.nanmin(v[:, j])
    assert len(idx) < T / 2


def test_summary_fits_one_screen_and_full_holds_everything(recorded, tmp_path, capsys):
    """A recording shaped like the default ``lcc-synth run``'s: 4 scenarios x 4 runs, 13 |Γ|
    reports (its full summary: 1318 lines)."""
    results, _ = recorded
    path = tmp_path / "big.rrd"
    w = np.logspace(-2, 1, 50)
    with R.open_recording(path, "big") as rec:
        for scenario in ("brake_behind", "head_sine", "head_brake", "heterogeneous"):
            for copy in ("a", "b"):
                for name, res in results.items():
                    R.record_simulation(
                        rec,
                        res,
                        scenario,
                        controller=f"{name}_{copy}",
                        decimate="minmax",
                        metrics={"aave": 1.0, "fuel_ml": 2.0},
                    )
        for case in range(13):
            R.record_gamma(rec, f"case{case}", w, 1.0 / (1.0 + w), {"gamma_peak": 1.0})
    s = R.summarize_recording(path)
    short, full = summary_lines(s), full_lines(s)
    assert len(short) <= MAX_LINES < len(full)
    for entity in s.entities:  # --full names every entity and every document line
        assert any(line.strip().startswith(entity + " ") for line in full)
    for p, text in s.texts.items():
        if p.endswith(("/metrics", "/status", "/report")):
            assert all(line in full for line in text.rstrip().splitlines())
    assert main(["review", "--summary", str(path)]) == 0
    assert capsys.readouterr().out.splitlines() == short
    assert main(["review", "--summary", "--full", str(path)]) == 0
    assert capsys.readouterr().out.splitlines() == full
    assert main(["review", "--full", str(path)]) == 2  # --full only with --summary
