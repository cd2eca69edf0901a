"""Sweep settings drawn per scenario: ``hdv_accel_noise`` and the V2V ``loss_rate``,
``latency`` and noises given as ``[lo, hi]`` are drawn U[lo, hi] by every scenario from
``(seed, i)`` only; a number stays fixed.

Independent truth: a sweep whose scenario ``i`` has the same setting as a plain number (the
U[lo, hi] draw recomputed here with numpy from ``(seed, i, tag)``) gives bit-for-bit the same
metrics; regrouping scenarios into tasks changes nothing.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_sweep import SWEEP

from lcc_synth.cli.main import main
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.sweep import load_sweep, run_chunk, run_sweep
from lcc_synth.simulation.scenario import RANGE_FIELDS, split_ranges

FIXED_V2V = "v2v = { loss_rate = 0.3, latency = 0.05, spacing_noise = 0.2, velocity_noise = 0.1 }"
RANGED = SWEEP.replace(
    FIXED_V2V,
    "v2v = { loss_rate = [0.0, 0.4], latency = [0.0, 0.1], spacing_noise = 0.2, "
    "velocity_noise = [0.05, 0.15] }",
).replace("hdv_accel_noise = 0.2", "hdv_accel_noise = [0.1, 0.3]")
SEED = 11  # [scenario] seed of SWEEP


def _uniform(key: str, lo: float, hi: float, i: int) -> float:
    return float(np.random.default_rng([SEED, i, RANGE_FIELDS[key][2]]).uniform(lo, hi))


def _spec(tmp_path, text, name="p.toml", **kw):
    path = tmp_path / name
    path.write_text(text)
    return load_sweep(path, **kw)


def _chunk(spec, start, stop):
    from lcc_synth.experiments.comparison import prepare_controllers

    tables, _ = prepare_controllers(spec.controllers, spec.system, "sweep",
                                    spec.source, spec.name)  # fmt: skip
    return run_chunk(spec.scenario, spec.system, tables, spec.metrics, spec.source, start, stop,
                     spec.ranges)  # fmt: skip


def test_ranges_are_parsed_and_scalars_stay_fixed(tmp_path):
    spec = _spec(tmp_path, RANGED, controllers=["all_hdv"])
    assert spec.ranges == {"hdv_accel_noise": (0.1, 0.3), "v2v.loss_rate": (0.0, 0.4),
                           "v2v.latency": (0.0, 0.1), "v2v.velocity_noise": (0.05, 0.15)}
    assert spec.scenario.v2v.spacing_noise == 0.2  # a number: fixed for every scenario
    assert _spec(tmp_path, SWEEP, "fixed.toml").ranges == {}
    # a per-vehicle list of loss rates (one per vehicle, head..tail) is not a range
    table, ranges = split_ranges({"v2v": {"loss_rate": [0.1, 0.2, 0.3, 0.4, 0.5]}}, 5)
    assert ranges == {} and table["v2v"]["loss_rate"] == [0.1, 0.2, 0.3, 0.4, 0.5]


def test_scenario_i_equals_a_fixed_sweep_with_its_drawn_values(tmp_path):
    ranged = _spec(tmp_path, RANGED, controllers=["all_hdv", "paper"])
    got = _chunk(ranged, 2, 5)
    for i in range(2, 5):
        loss = _uniform("v2v.loss_rate", 0.0, 0.4, i)
        lat = _uniform("v2v.latency", 0.0, 0.1, i)
        vn = _uniform("v2v.velocity_noise", 0.05, 0.15, i)
        noise = _uniform("hdv_accel_noise", 0.1, 0.3, i)
        text = SWEEP.replace(FIXED_V2V, f"v2v = {{ loss_rate = {loss!r}, latency = {lat!r}, "
                             f"spacing_noise = 0.2, velocity_noise = {vn!r} }}")  # fmt: skip
        text = text.replace("hdv_accel_noise = 0.2", f"hdv_accel_noise = {noise!r}")
        fixed = _spec(tmp_path, text, f"fixed{i}.toml", controllers=["all_hdv", "paper"])
        want = _chunk(fixed, i, i + 1)
        for c in ("all_hdv", "paper"):
            for k, v in want["metrics"][c].items():
                np.testing.assert_array_equal(got["metrics"][c][k][i - 2 : i - 1], v, f"{c}.{k}")


def test_draws_depend_on_seed_and_index_only(tmp_path):
    spec = _spec(tmp_path, RANGED, controllers=["all_hdv", "paper"])
    whole = run_sweep(spec, client=None, progress=False).samples
    for bs in (1, 5):
        other = run_sweep(_spec(tmp_path, RANGED, f"b{bs}.toml", controllers=["all_hdv", "paper"],
                                batch_size=bs), client=None, progress=False).samples  # fmt: skip
        for c in whole:
            for k in ("aave", "fuel_ml", "min_spacing", "rms_jerk_cav"):
                np.testing.assert_array_equal(whole[c][k], other[c][k], f"{c}.{k}")
    # the per-scenario draw varies the outcome more than the fixed setting alone does
    fixed = run_sweep(_spec(tmp_path, SWEEP, "f.toml", controllers=["all_hdv", "paper"]),
                      client=None, progress=False).samples  # fmt: skip
    assert not np.array_equal(whole["paper"]["rms_jerk_cav"], fixed["paper"]["rms_jerk_cav"])
    reseeded = run_sweep(_spec(tmp_path, RANGED, "s.toml", controllers=["all_hdv"], seed=12),
                         client=None, progress=False).samples  # fmt: skip
    assert not np.array_equal(whole["all_hdv"]["aave"], reseeded["all_hdv"]["aave"])


@pytest.mark.parametrize(
    ("old", "new", "field", "needs"),
    [
        ("loss_rate = 0.3", "loss_rate = [0.2, 1.5]", "scenario.v2v.loss_rate", "<= 1"),
        ("loss_rate = 0.3", "loss_rate = [0.3, 0.1]", "scenario.v2v.loss_rate", "lo <= hi"),
        ("latency = 0.05", "latency = [-0.1, 0.1]", "scenario.v2v.latency", "0 <= lo"),
        ("hdv_accel_noise = 0.2", "hdv_accel_noise = [0.1]", "scenario.hdv_accel_noise",
         "[lo, hi]"),
        ("hdv_accel_noise = 0.2", 'hdv_accel_noise = [0.1, "x"]', "scenario.hdv_accel_noise",
         "two numbers"),
    ],
)  # fmt: skip
def test_bad_ranges_name_the_field_and_exit_2(tmp_path, capsys, old, new, field, needs):
    path = tmp_path / "bad.toml"
    path.write_text(SWEEP.replace(old, new))
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        load_sweep(path)
    assert main(["sweep", str(path), "--count", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "bad.toml" in err and field in err and needs in err and "\n" not in err
