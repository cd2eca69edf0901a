"""A synthesised gain reaches its controllers as the object itself, never through a table.

``lcc-synth run``, ``simulate`` and ``sweep`` synthesise an ``h2`` gain and run it as a static
controller and as an MPC's ``fallback = "h2"``. Independent truth: object identity (``is``)
between the synthesis report's :class:`~lcc_synth.models.feedback.Gains` and the gain each
controller holds (a gain read back from a table would be another object), with the readers of
gain tables (``Gains.from_mapping``, ``Gains.from_table``) made to fail while the controllers
are built; and the MPC's fallback command on a forced QP failure evaluated here, from the
report's plain gains and the observed errors, with no library feedback code. A sweep's
per-scenario samples built from the objects equal bit for bit those of its plain tables (the
results files' form), run again with the table readers.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_mpc_controller import _ctx, _obs, _system
from test_mpc_fallback import _command

from lcc_synth.controllers.registry import static_controller
from lcc_synth.controllers.static import StaticGainController
from lcc_synth.controllers.switch import SwitchedOn
from lcc_synth.errors import ConfigError
from lcc_synth.experiments import sweep as sweep_module
from lcc_synth.experiments.comparison import load_suite, run_suite
from lcc_synth.experiments.h2_tables import synthesize_table
from lcc_synth.experiments.spec import load_spec
from lcc_synth.experiments.sweep import load_sweep, run_chunk, run_sweep
from lcc_synth.models.feedback import Gains
from lcc_synth.mpc.build import mpc_controller_from_table

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"


@pytest.fixture
def no_gain_tables(monkeypatch):
    """``Gains.from_mapping`` and ``Gains.from_table`` raise: no gain is read from a table."""

    def refuse(*args, **kwargs):
        raise AssertionError("a gain was read back from a table")

    monkeypatch.setattr(Gains, "from_mapping", classmethod(refuse))
    monkeypatch.setattr(Gains, "from_table", classmethod(refuse))


def test_run_builds_h2_and_the_mpc_fallback_from_the_synthesised_object(no_gain_tables):
    suite = load_suite(PROBLEMS / "showcase.toml", ["head_brake"], ["h2", "mpc"])
    run = run_suite(suite, progress=False)
    gain = run.designs["string10"]["h2"].gain
    h2, mpc = run.controllers["string10"]["h2"], run.controllers["string10"]["mpc"]
    assert isinstance(gain, Gains) and isinstance(h2, StaticGainController)
    assert h2.gains is gain and mpc.fallback is gain
    assert mpc.fallback_source == "controller h2"
    # the plain form written to the results is the same gain, entry for entry
    assert run.tables["string10"]["h2"]["gains"] == run.designs["string10"]["h2"].gains
    assert np.array_equal(gain.K[0], [run.designs["string10"]["h2"].gains[s]
                                      for s in gain.states])  # fmt: skip
    # the MPC predicts 4 HDVs; the gain, on all 10, hears only HDVs 1 and 2: on a forced QP
    # failure it applies the synthesised gain to its own error state
    rep = run.designs["string10"]["h2"]
    assert {int(s[2:]) for s, g in rep.gains.items() if g != 0.0} <= {0, 1, 2}
    mpc.reset(_ctx(0, 10))
    for mem in mpc._members:
        mem.solver.force_failure = True
    rng = np.random.default_rng(3)
    for k in range(4):
        x = rng.normal(scale=0.5, size=22)
        u = mpc(_obs(0.1 * k, x, 0, 0.0))[0]
        assert u == pytest.approx(_command(rep.gains, x), abs=1e-12)
    assert mpc.stats()["fallback_static"] == 4


@pytest.mark.parametrize(("problem", "name", "mpcs"),
                         [("platoon_deeplcc_brake.toml", "h2", ("mpc", "mpc_equilibrium")),
                          ("ring_stop_and_go.toml", "av", ("mpc",))])  # fmt: skip
def test_simulate_builds_h2_and_the_mpc_fallbacks_from_one_object(problem, name, mpcs):
    spec = load_spec(PROBLEMS / problem)  # its static lqr table is read as a table: no patch
    h2 = spec.controllers[name]
    assert isinstance(h2, StaticGainController) and isinstance(h2.gains, Gains)
    for mpc in mpcs:  # one object: no table in between
        assert spec.controllers[mpc].fallback is h2.gains
        assert spec.controllers[mpc].fallback_source == f"controller {name}"


def test_a_fallback_gain_on_a_vehicle_the_mpc_does_not_predict_is_refused():
    system = _system(n=6)  # the MPC below predicts 3 of the 6 HDVs
    ok = Gains.named({"s_0": 0.1, "v_0": -0.5, "s_5": 0.0, "v_6": 0.0}, "replace")
    ctrl = mpc_controller_from_table("mpc", {"type": "mpc", "horizon": 5, "n_model": 3,
                                             "fallback": "paper"}, system, fallback=ok)
    assert ctrl.fallback is ok
    assert ctrl.describe()["fallback"]["gains"] == {"s_0": 0.1, "v_0": -0.5}
    bad = Gains.named({"s_0": 0.1, "v_5": -0.2}, "replace")
    with pytest.raises(ConfigError, match="v_5") as err:
        mpc_controller_from_table("mpc", {"type": "mpc", "horizon": 5, "n_model": 3,
                                          "fallback": "paper"}, system, fallback=bad)
    assert err.value.field.startswith("controllers.mpc.fallback")


def test_h2_switches_on_at_its_start_on_both_paths(tmp_path):
    """``start`` of an ``h2`` table is kept: by the controller built from the object
    (``simulate``) and in the plain table (sweeps, result files)."""
    text = """
[system]
kind = "cf_lcc"
m = 0
n = 3
[scenario]
duration = 10.0
[metrics]
window = [0.0, 10.0]
[controllers.h2]
type = "h2"
pattern = [1]
start = 4.0
"""
    path = tmp_path / "h2_start.toml"
    path.write_text(text)
    spec = load_spec(path)
    ctrl = spec.controllers["h2"]
    assert isinstance(ctrl, SwitchedOn) and ctrl.start == 4.0
    assert isinstance(ctrl.inner, StaticGainController)
    table, rep = synthesize_table("h2", {"type": "h2", "pattern": [1], "start": 4.0},
                                  spec.system, "t")  # fmt: skip
    assert table["start"] == 4.0 and table["gains"] == rep.gains
    assert ctrl.inner.gains == rep.gain  # the same design, solved again


def test_a_gain_object_on_another_layout_names_the_controller():
    gain = Gains.named({"s_0": 0.1, "v_5": -0.2}, "replace")  # vehicle 5: the string has 3
    with pytest.raises(ConfigError, match="v_5") as err:
        static_controller("h2", gain, {"type": "h2"}, _system(), "p.toml")
    assert err.value.field.startswith("controllers.h2.gains") and err.value.source == "p.toml"
    with pytest.raises(ConfigError) as err:
        static_controller("h2", Gains.named({"v_0": -0.5}, "replace"),
                          {"type": "h2", "equilibrium_tau": 1.0}, _system())  # fmt: skip
    assert err.value.field == "controllers.h2.equilibrium_tau"


def test_sweep_workers_build_h2_and_the_mpc_fallback_from_the_synthesised_object(
    no_gain_tables, monkeypatch
):
    spec = load_sweep(PROBLEMS / "sweep_robustness.toml", count=2, batch_size=1,
                      controllers=["h2", "mpc"])  # fmt: skip
    built, real = [], sweep_module._controllers  # what each task's run_chunk builds
    monkeypatch.setattr(sweep_module, "_controllers",
                        lambda *args: built.append(real(*args)) or built[-1])  # fmt: skip
    res = run_sweep(spec, client=None, progress=False)  # the workers' task, in this process
    gain = res.designs["h2"].gain
    assert isinstance(gain, Gains) and res.gains["h2"] is gain and res.gains["mpc"] is gain
    assert len(built) == 2  # two tasks, each with the synthesised object itself, twice
    for ctrls in built:
        assert isinstance(ctrls["h2"], StaticGainController) and ctrls["h2"].gains is gain
        assert ctrls["mpc"].fallback is gain and ctrls["mpc"].fallback_source == "controller h2"
    assert res.worker_tables["h2"]["type"] == "h2"  # how the law runs, the file's table
    assert res.worker_tables["mpc"]["fallback"] == "h2"
    # the plain tables (results files, resume) still hold the same gain, entry for entry
    assert res.tables["h2"]["type"] == "static" and res.tables["h2"]["gains"] == res.designs[
        "h2"].gains  # fmt: skip
    assert res.tables["mpc"]["fallback"]["controller"] == "h2"
    monkeypatch.undo()  # the second method: the plain tables, read by the table readers
    plain = run_chunk(spec.scenario, spec.system, res.tables, spec.metrics, spec.source, 0,
                      spec.count, spec.ranges)  # fmt: skip
    for name in ("h2", "mpc"):
        for metric, values in plain["metrics"][name].items():
            assert np.array_equal(values, res.samples[name][metric], equal_nan=True), metric
    assert plain["fallbacks"] == res.fallbacks
