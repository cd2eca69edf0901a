"""The sweep's hardest scenario (``lcc_synth.experiments.sweep_review``): found by its
minimum spacing, and simulated again alone it reproduces every metric the sweep measured."""

from __future__ import annotations

import numpy as np
import pytest
from test_sweep import SWEEP

from lcc_synth.errors import ConfigError
from lcc_synth.experiments.sweep import load_sweep, run_sweep, scenario_metrics
from lcc_synth.experiments.sweep_review import hardest_scenario, simulate_scenario


def _samples(spacings: dict[str, list[float]], collided: dict[str, list[int]] | None = None):
    collided = collided or {}
    return {c: {"min_spacing": np.array(s, float),
                "collisions": np.array(collided.get(c, [0] * len(s)), float)}
            for c, s in spacings.items()}  # fmt: skip


def test_smallest_spacing_wins_collisions_first_ties_to_the_lower_index():
    h = hardest_scenario(_samples({"a": [5.0, 2.0, 7.0], "b": [4.0, 3.0, 1.5]}))
    assert (h.index, h.controller, h.min_spacing, h.collided) == (2, "b", 1.5, False)
    # a collision ranks first even with a larger recorded spacing
    h = hardest_scenario(_samples({"a": [5.0, 2.0, 7.0], "b": [4.0, 3.0, 1.5]},
                                  {"a": [0, 0, 1]}))  # fmt: skip
    assert (h.index, h.controller, h.collided) == (2, "a", True)
    # equal spacings: the lower index, then the controller listed first; NaN never wins
    h = hardest_scenario(_samples({"a": [np.nan, 2.0, 2.0], "b": [2.0, 2.0, np.nan]}))
    assert (h.index, h.controller) == (0, "b")
    h = hardest_scenario(_samples({"a": [3.0, 2.0], "b": [3.0, 2.0]}))
    assert (h.index, h.controller) == (1, "a")
    with pytest.raises(ConfigError, match="no controller has a finite"):
        hardest_scenario(_samples({"a": [np.nan, np.nan]}))
    with pytest.raises(ConfigError, match="min_spacing"):
        hardest_scenario({"a": {"aave": np.ones(2)}})


@pytest.mark.parametrize("ranged", [False, True], ids=["batched", "drawn_settings"])
def test_the_scenario_alone_reproduces_the_sweep_bit_for_bit(tmp_path, ranged):
    """Scenario i ran inside a batch of the sweep (or alone with its drawn settings); simulated
    again alone, every metric of every controller is the same float."""
    text = SWEEP.replace("hdv_accel_noise = 0.2", "hdv_accel_noise = [0.1, 0.3]") if ranged \
        else SWEEP
    path = tmp_path / "p.toml"
    path.write_text(text)
    spec = load_sweep(path, count=5, batch_size=3)
    assert bool(spec.ranges) == ranged
    res = run_sweep(spec, client=None, progress=False)
    hard = hardest_scenario(res.samples)
    for index in {hard.index, 4}:  # the hardest one and one from the second, shorter task
        scenario, runs, ctrls = simulate_scenario(spec, res.tables, index)
        assert scenario.batch == 1 and set(runs) == set(res.samples)
        for name, r in runs.items():
            got = scenario_metrics(r, spec.metrics)
            for k, v in got.items():
                want = res.samples[name][k][index]
                np.testing.assert_array_equal(np.asarray(v).ravel()[0], want,
                                              err_msg=f"{name} {k} scenario {index}")
        assert callable(getattr(ctrls["mpc"], "history", None)) and ctrls["mpc"].history()
    assert res.samples[hard.controller]["min_spacing"][hard.index] == hard.min_spacing
    with pytest.raises(ConfigError, match="index"):
        simulate_scenario(spec, res.tables, 5)
