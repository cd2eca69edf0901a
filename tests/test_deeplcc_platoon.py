"""The DeeP-LCC paper's NEDC test on the two-CAV platoon (problems/platoon_deeplcc_nedc.toml)
and the per-phase fuel of ``[metrics] phases``, against the issue's piecewise definitions."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lcc_synth.errors import ConfigError
from lcc_synth.experiments.spec import load_spec
from lcc_synth.metrics import fuel
from lcc_synth.simulation.engine import simulate

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"
NEDC = PROBLEMS / "platoon_deeplcc_nedc.toml"
KMH = 1 / 3.6
#: The issue's modified NEDC segment: (tau_start, tau_end, km/h at start, km/h at end).
SEGMENT = ((0, 10, 70, 70), (10, 18, 70, 50), (18, 38, 50, 50), (38, 51, 50, 70),
           (51, 71, 70, 70), (71, 106, 70, 100), (106, 126, 100, 100), (126, 136, 100, 70),
           (136, 156, 70, 70))  # fmt: skip
PHASES = {"70-50": (60.0, 88.0), "50-70": (88.0, 121.0), "70-100": (121.0, 166.0),
          "100-70": (166.0, 196.0)}  # fmt: skip


def head_speed(t: float) -> float:
    """The issue's head speed (m/s) at simulation time t: 70 km/h to 50 s, then the segment."""
    tau = t - 50.0
    if tau <= 0:
        return 70 * KMH
    for a, b, v0, v1 in SEGMENT:
        if a <= tau <= b:
            return (v0 + (v1 - v0) * (tau - a) / (b - a)) * KMH
    raise ValueError(t)


@pytest.fixture(scope="module")
def spec():
    return load_spec(NEDC)


@pytest.fixture(scope="module")
def all_hdv(spec):
    return simulate(spec.scenario, spec.controllers["all_hdv"], spec.scenario.draw())


def test_nedc_head_follows_the_issues_piecewise_profile(spec, all_hdv):
    """Plateaus (70, 50, 70, 100, 70 km/h) and every ramp's midpoint (60, 60, 85, 85 km/h)."""
    sc = spec.scenario
    assert sc.v_star == pytest.approx(70 * KMH, rel=1e-15) and sc.duration == 206.0
    checks = {10.0: 70, 49.0: 70, 55.0: 70, 64.0: 60, 78.0: 50, 94.5: 60, 111.0: 70,
              138.5: 85, 166.0: 100, 181.0: 85, 196.0: 70, 205.0: 70}  # fmt: skip
    res = all_hdv
    for t, kmh in checks.items():
        assert head_speed(t) == pytest.approx(kmh * KMH, rel=1e-12)
        k = int(round((t - res.t[0]) / res.dt))
        assert res.t[k] == pytest.approx(t)
        assert res.velocity[0, k, 0] == pytest.approx(kmh * KMH, abs=1e-9), t
    # every sample, not only the chosen ones
    want = np.array([head_speed(t) for t in res.t])
    np.testing.assert_allclose(res.velocity[0, :, 0], want, atol=1e-9)
    # every vehicle starts at its own equilibrium at 70 km/h and the platoon is quiet then
    assert np.allclose(res.velocity[0, 0], 70 * KMH)
    assert not res.collided.any()


def test_phase_windows_and_the_total_add_up(spec, all_hdv):
    """The total over 50-206 s is the sum over a partition of it, less the boundary samples the
    closed windows share (each counted twice), and the file's phases are those windows."""
    cfg = spec.metrics
    assert cfg.window == (50.0, 206.0) and dict(cfg.phases) == PHASES
    cut = [50.0, 60.0, 88.0, 121.0, 166.0, 196.0, 206.0]
    args = (cfg.vehicles, cfg.accel_smoothing)
    parts = sum(fuel(all_hdv, (a, b), *args)[0] for a, b in zip(cut[:-1], cut[1:], strict=True))
    shared = sum(fuel(all_hdv, (t, t), *args)[0] for t in cut[1:-1])
    total = fuel(all_hdv, cfg.window, *args)[0]
    assert shared > 0 and total == pytest.approx(parts - shared, rel=1e-12)
    # the phases are a fair share of the total: nothing is dropped or doubled
    ph = sum(fuel(all_hdv, w, *args)[0] for w in PHASES.values())
    assert 0.5 * total < ph < total


def test_per_phase_fuel_json_shape(tmp_path, capsys):
    """``simulate --json`` reports fuel_ml_phases per controller (equal to the metric on each
    window) and fuel_phases_pct versus the baseline (0 for a copy of it)."""
    from lcc_synth.cli.main import main

    text = NEDC.read_text()
    text = text[: text.index("[controllers.mpc]")] + '[controllers.copy]\ntype = "hdv"\n'
    path = tmp_path / "nedc_hdv.toml"
    path.write_text(text)
    assert main(["simulate", str(path), "--json", "--no-record"]) == 0
    rep = json.loads(capsys.readouterr().out)
    rep = rep.get("results", rep)
    assert set(rep) >= {"all_hdv", "copy"}
    spec = load_spec(path)
    res = simulate(spec.scenario, spec.controllers["all_hdv"], spec.scenario.draw())
    for name in ("all_hdv", "copy"):
        phases = rep[name]["fuel_ml_phases"]
        assert list(phases) == list(PHASES)
        for p, w in PHASES.items():
            want = fuel(res, w, "first_cav_and_behind", 9)[0]
            assert phases[p] == pytest.approx(want, rel=1e-12)
    red = rep["copy"]["reduction_vs_baseline"]
    assert red["fuel_phases_pct"] == {p: 0.0 for p in PHASES}
    assert "reduction_vs_baseline" not in rep["all_hdv"]


@pytest.mark.parametrize(
    ("phases", "field"),
    [({"bad": [10.0, 5.0]}, "metrics.phases.bad"), ({"late": [100.0, 300.0]},
     "metrics.phases.late"), ({"x": "50-60"}, "metrics.phases.x"), ([1, 2], "metrics.phases")],
)  # fmt: skip
def test_bad_phases_are_named_field_errors(spec, phases, field):
    import tomllib

    from lcc_synth.metrics import metrics_from

    data = tomllib.loads(NEDC.read_text())
    data["metrics"]["phases"] = phases
    with pytest.raises(ConfigError) as err:
        metrics_from(data, spec.system, list(spec.controllers), spec.scenario)
    assert err.value.field == field


@pytest.mark.slow
def test_mpc_and_deep_lcc_beat_all_hdv_on_nedc_fuel(spec, all_hdv, tmp_path_factory):
    """Both predictive controllers (on from 30 s) use less fuel than all-HDV over 50-206 s and
    in the braking phases (70 -> 50, 100 -> 70 km/h), with no collision or emergency braking."""
    from lcc_synth.experiments.controller_tables import controller_from_table
    from lcc_synth.metrics import summary

    cache = tmp_path_factory.mktemp("deeplcc_nedc")
    table = {"type": "deep_lcc", "start": 30.0, "data": {"cache_dir": str(cache)}}
    deep = controller_from_table("deep_lcc", table, spec.system, str(NEDC), spec.scenario)
    draws = spec.scenario.draw()
    runs = {"mpc": simulate(spec.scenario, spec.controllers["mpc"], draws),
            "deep_lcc": simulate(spec.scenario, deep, draws)}  # fmt: skip
    base = summary(all_hdv, spec.metrics)
    for name, res in runs.items():
        s = summary(res, spec.metrics)
        assert s["collisions"] == 0 and s["aeb_activations"] == 0, name
        assert s["fuel_ml"] < 0.99 * base["fuel_ml"], (name, s["fuel_ml"], base["fuel_ml"])
        for p in ("70-50", "100-70"):
            assert s["fuel_ml_phases"][p] < base["fuel_ml_phases"][p], (name, p)
        # before the switch at 30 s the CAVs drive as HDVs: the run equals all-HDV's
        k = int(round(30.0 / res.dt))
        np.testing.assert_array_equal(res.velocity[0, :k], all_hdv.velocity[0, :k])


def test_brake_file_has_deep_lcc_with_defaults():
    from lcc_synth.deeplcc.settings import DeePLCCSettings

    spec = load_spec(PROBLEMS / "platoon_deeplcc_brake.toml")
    c = spec.controllers["deep_lcc"]
    d = DeePLCCSettings()
    assert c.cavs == (3, 6)
    assert replace(c.settings, data=d.data) == d


def test_data_collection_shows_a_progress_bar_only_when_slow(monkeypatch, capsys):
    """The bar appears on stderr once the collection has run BAR_DELAY s and counts every
    simulation step: with a delay no run reaches, nothing; with 0, the whole bar."""
    from lcc_synth.deeplcc import data as D
    from lcc_synth.simulation.scenario import Scenario

    settings = D.DataSettings(T=300, cache=False)
    sc = D.collection_scenario(Scenario(m=0, n=4, dt=0.05, duration=1.0), settings)
    monkeypatch.setattr(D, "BAR_DELAY", 1e9)
    D.collect(sc, settings)
    assert "deep_lcc data" not in capsys.readouterr().err
    monkeypatch.setattr(D, "BAR_DELAY", 0.0)
    D.collect(sc, settings)
    err = capsys.readouterr().err
    assert "deep_lcc data" in err and f"{sc.steps}/{sc.steps}" in err


def test_recording_of_the_joint_mpc_history(tmp_path):
    """The joint MPC's per-CAV status (B, S, n_cav) is recorded as the worst of the step and
    its plan (B, S, N, n_cav) as one strip per CAV (recording it used to raise)."""
    pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    from lcc_synth import recording as R
    from lcc_synth.experiments.controller_tables import controller_from_table

    spec = load_spec(PROBLEMS / "platoon_deeplcc_brake.toml")
    sc = replace(spec.scenario, duration=3.0)
    ctrl = controller_from_table("mpc", {"type": "mpc"}, spec.system)
    res = simulate(sc, ctrl)
    h = ctrl.history()
    assert h["status"].ndim == 3 and h["plan"].ndim == 4 and "pred_time" not in h
    path = tmp_path / "mpc.rrd"
    with R.open_recording(path, "p", R.simulation_blueprint("p", ["mpc"])) as rec:
        R.record_simulation(rec, res, "p", mpc_history=h)
    seen = {ch.entity_path for ch in RrdReader(path).stream()}
    assert any(e.endswith("/mpc/status") for e in seen)
    assert any(e.endswith("/mpc/predicted/u") for e in seen)
