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
    for entity in ("acceleration", "cav/u_cmd", "spacing"):
        t, _ = _entity(paths["minmax"], f"/dec/paper/{entity}")
        kept = set(np.round(t / res.dt).astype(int).tolist())
        assert set(np.round(res.t[aeb] / res.dt).astype(int).tolist()) <= kept, entity
    # the AEB flag is a step signal: its breakpoints alone redraw it exactly (every sample)
    t, flag = _entity(paths["minmax"], "/dec/paper/cav/aeb_active")
    assert len(t) < len(res.t) / 4  # the flag chatters here: 512 breakpoints of 3000 rows
    k = np.round((t - res.t[0]) / res.dt)  # recorded step indices
    np.testing.assert_array_equal(np.interp(np.arange(len(res.t)), k, flag[:, 0, 0]), aeb)


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


def _redraw(idx: np.ndarray, v: np.ndarray) -> np.ndarray:
    """What a line chart draws from the rows ``idx`` of ``v`` (``(T, k)``), at every row."""
    T = v.shape[0]
    out = np.full(v.shape, np.nan)
    for j in range(v.shape[1]):
        ok = np.isfinite(v[idx, j])
        out[:, j] = np.interp(np.arange(T), idx[ok], v[idx[ok], j])
    return out


def test_linear_rows_redraw_every_sample_within_the_tolerance():
    """Brute force: the line through the kept rows vs every sample of every series."""
    rng = np.random.default_rng(4)
    T = 5000
    t = 0.01 * np.arange(T)
    v = np.column_stack([np.sin(0.7 * t), np.where(t < 20, 15.0, 15.0 - np.exp(-(t - 20))),
                         np.cumsum(rng.normal(scale=0.01, size=T)), np.full(T, 3.0)])  # fmt: skip
    v[2000:2100, 1] = np.nan  # a gap
    idx = R.decimate.linear_rows(v, VIEWER_TOLERANCE)
    tol = VIEWER_TOLERANCE * (np.nanmax(v) - np.nanmin(v))
    err = np.abs(_redraw(idx, v) - v)[np.isfinite(v)]
    assert err.max() <= tol * (1 + 1e-9)
    assert len(idx) < T / 4  # smooth: far fewer than the 0.2 s grid's T / 20 rows per ...
    assert {0, T - 1, 1999, 2000, 2099, 2100} <= set(idx.tolist())
    for j in range(4):  # global extremes exactly
        assert np.nanmax(v[idx, j]) == np.nanmax(v[:, j])
        assert np.nanmin(v[idx, j]) == np.nanmin(v[:, j])
    flat = np.full(T, 15.0)  # a cruise: its two ends
    assert R.decimate.linear_rows(flat).tolist() == [0, T - 1]
    steps = np.repeat([0.0, 1.0, 0.0, 3.0], [10, 5, 20, 7])  # a flag / status: exact
    k = R.decimate.linear_rows(steps, 0.0)
    assert k.tolist() == [0, 9, 10, 14, 15, 34, 35, 41]
    np.testing.assert_array_equal(np.interp(np.arange(42), k, steps[k]), steps)


def test_viewer_rows_keep_a_noise_band_per_second_and_smooth_signals_as_lines():
    rng = np.random.default_rng(5)
    T, b = 7000, 20
    t = 0.01 * np.arange(T)
    after = np.clip(t - 20.0, 0.0, None)  # a cruise, then a decaying wave from t = 20 s
    smooth = np.column_stack([15 - np.exp(-0.1 * after) * np.sin(0.2 * (j + 1) * after)
                              for j in range(12)])  # fmt: skip
    idx = R.decimate.viewer_rows(smooth, b)
    assert len(idx) == len(R.decimate.linear_rows(smooth)) < len(minmax_rows(smooth, b))
    noisy = smooth + rng.normal(scale=0.05, size=smooth.shape)
    forced = np.zeros(T, bool)
    forced[3000:3100] = True  # e.g. emergency braking: full rate
    idx = R.decimate.viewer_rows(noisy, b, forced=forced)
    wide = 5 * b  # NOISY_BUCKET_S / VIEWER_BUCKET_S
    assert R.decimate.NOISY_BUCKET_S == 5 * R.decimate.VIEWER_BUCKET_S
    np.testing.assert_array_equal(idx, minmax_rows(noisy, wide, forced=forced))
    assert set(range(3000, 3100)) <= set(idx.tolist())
    assert len(idx) < len(minmax_rows(noisy, b, forced=forced)) / 2
    kept = np.zeros(T, bool)
    kept[idx] = True
    tol = VIEWER_TOLERANCE * (noisy.max() - noisy.min())
    for start in range(0, T - 1, wide):  # every series' band, exact per wide bucket
        sl = slice(start, min(start + wide, T - 1) + 1)
        for j in range(12):
            x, k = noisy[sl, j], kept[sl]
            assert x[k].max() >= x.max() - tol and x[k].min() <= x.min() + tol


def test_frames_plans_and_strips():
    """The road's frames skip what did not move; plans skip repeats; strips keep the points
    that draw them within the tolerance."""
    T = 1000
    pts = np.zeros((T, 4))
    pts[500:600, 0] = np.linspace(0.0, 10.0, 100)  # one vehicle moves, then stands again
    pts[600:, 0] = 10.0
    idx = R.decimate.frame_rows(pts, 20)
    assert idx.tolist()[:2] == [0, 520] and idx[-1] == T - 1
    assert set(idx.tolist()) <= set(range(0, T, 20)) | {T - 1}
    assert len(idx) <= 8  # 500..600 moved (5 frames) + first + last
    plans = np.zeros((40, 51, 3))
    plans[10:20] += 1.0 + np.arange(10)[:, None, None]  # the plan changes during 10..19 only
    k = R.decimate.plan_rows(plans, 5)
    assert k.tolist() == [0, 10, 15, 20, 39]
    x = 0.1 * np.arange(51)
    strips = np.stack([15 - np.exp(-x), 15 - 0.1 * x, np.r_[np.full(25, 15.0), np.full(26, 14.0)]])
    keep = R.decimate.strip_points(x, strips)
    assert keep[1].sum() == 2 and keep[2].sum() == 4 and keep[0].sum() <= 25
    tol = VIEWER_TOLERANCE * (strips.max() - strips.min())
    for s in range(3):
        drawn = np.interp(x, x[keep[s]], strips[s, keep[s]])
        assert np.abs(drawn - strips[s]).max() <= tol * (1 + 1e-9)
