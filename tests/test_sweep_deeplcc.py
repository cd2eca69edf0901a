"""DeeP-LCC in a sweep (``lcc_synth.experiments.deeplcc_runs``): every scenario's controller
is built on data collected among THAT scenario's HDVs, and adding it changes no other
controller's samples.

Independent truth: the collection scenario's own draw (``Scenario.draw``, HDV parameters,
reaction delays, initial spacings) equals the draw of the sweep scenario it serves; the other
controllers' samples equal those of the sweep without DeeP-LCC (one batch, no per-scenario
runs); a second run reads the per-scenario cache and gives the same samples bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_sweep import SWEEP

from lcc_synth.errors import ConfigError
from lcc_synth.experiments.deeplcc_runs import ScenarioDeePLCC, collection_base
from lcc_synth.experiments.sweep import SWEEP_METRICS, load_sweep, run_sweep
from lcc_synth.simulation.scenario import scenario_variant

KEYS = (*SWEEP_METRICS, "collisions", "aeb_activations")
# small data (T = 400 > the 2 x 21 rows of the input Hankel matrix, PE ratio ~0.4) and a short
# horizon keep the test to a few seconds
DEEP = """
[controllers.deep_lcc]
type = "deep_lcc"
t_ini = 5
horizon = 10
weights = {{ spacing = 0.1 }}
data = {{ T = 400, cache_dir = "{cache}" }}
"""
RANGED = SWEEP.replace("hdv_accel_noise = 0.2", "hdv_accel_noise = [0.1, 0.3]").replace(
    "latency = 0.05", "latency = [0.0, 0.1]")


def _file(tmp_path, text, cache):
    path = tmp_path / "deep.toml"
    path.write_text(text + DEEP.format(cache=cache))
    return path


@pytest.fixture(scope="module")
def ranged(tmp_path_factory):
    cache = tmp_path_factory.mktemp("deeplcc_cache")
    path = _file(tmp_path_factory.mktemp("ranged"), RANGED, cache)
    spec = load_sweep(path, count=3, batch_size=2, controllers=["paper", "deep_lcc"])
    return spec, run_sweep(spec, client=None, progress=False), cache


def test_each_scenario_collects_among_its_own_hdvs(ranged):
    from lcc_synth.deeplcc.data import collection_scenario

    spec, res, cache = ranged
    for k in KEYS:
        assert np.all(np.isfinite(res.samples["deep_lcc"][k])), k
    assert res.summary["deep_lcc"]["collisions"] == 0
    wrapper = ScenarioDeePLCC("deep_lcc", spec.controllers["deep_lcc"], spec.system, spec.source)
    keys = []
    for i in range(3):
        sc = scenario_variant(spec.scenario, spec.ranges, i)
        run, data = sc.draw(), collection_scenario(collection_base(sc), wrapper.settings.data)
        got = data.draw()
        for name, v in run.hdv_values.items():
            np.testing.assert_array_equal(got.hdv_values[name], v, err_msg=name)
        np.testing.assert_array_equal(got.delay, run.delay)
        np.testing.assert_array_equal(got.initial_spacing, run.initial_spacing)
        assert data.hdv_accel_noise == sc.hdv_accel_noise  # its drawn noise level
        keys.append(wrapper.for_scenario(sc).data_key)
    assert len(set(keys)) == 3  # keyed per scenario
    assert {p.name for p in cache.iterdir()} == {f"deeplcc-{k}.npz" for k in keys}
    again = run_sweep(spec, client=None, progress=False)  # from the cache
    for k in KEYS:
        np.testing.assert_array_equal(again.samples["deep_lcc"][k], res.samples["deep_lcc"][k])


def test_other_controllers_keep_their_samples(tmp_path, ranged):
    spec, res, _ = ranged
    alone = run_sweep(load_sweep(spec.source, count=3, controllers=["paper"]), client=None,
                      progress=False)  # fmt: skip
    for k in KEYS:
        np.testing.assert_array_equal(res.samples["paper"][k], alone.samples["paper"][k])
    # without ranges the sweep runs one batch per task; with deep_lcc scenario by scenario
    fixed = _file(tmp_path, SWEEP, tmp_path / "cache")
    batched = run_sweep(load_sweep(fixed, count=3, controllers=["paper"]), client=None,
                        progress=False)  # fmt: skip
    with_deep = run_sweep(load_sweep(fixed, count=3, controllers=["paper", "deep_lcc"]),
                          client=None, progress=False)  # fmt: skip
    for k in KEYS:
        np.testing.assert_array_equal(with_deep.samples["paper"][k], batched.samples["paper"][k])
    assert np.all(np.isfinite(with_deep.samples["deep_lcc"]["aave"]))


def test_bad_deep_lcc_settings_fail_in_the_client(tmp_path):
    path = _file(tmp_path, SWEEP, tmp_path / "cache")
    path.write_text(path.read_text().replace("t_ini = 5", "t_ini = 0"))
    with pytest.raises(ConfigError) as info:
        run_sweep(load_sweep(path, count=1), client=None, progress=False)
    assert info.value.field == "controllers.deep_lcc.t_ini"
    assert info.value.source == str(path)
