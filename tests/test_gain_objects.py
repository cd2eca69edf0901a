"""A synthesised gain reaches its controllers as the object itself, never through a table.

``lcc-synth run`` and ``simulate`` synthesise an ``h2`` gain and run it as a static controller
and as an MPC's ``fallback = "h2"``. Independent truth: object identity (``is``) between the
synthesis report's :class:`~lcc_synth.models.feedback.Gains` and the gain each controller
holds (a gain read back from a table would be another object), with the readers of gain tables
(``Gains.from_mapping``, ``Gains.from_table``) made to fail while the controllers are built;
and the MPC's fallback command on a forced QP failure evaluated here, from the report's plain
gains and the observed errors, with no library feedback code.
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
from lcc_synth.experiments.comparison import load_suite, run_suite
from lcc_synth.experiments.h2_tables import synthesize_table
from lcc_synth.experiments.spec import load_spec
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
