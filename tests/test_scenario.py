"""Problem files -> scenario and controllers, and the errors bad files get."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lcc_synth.controllers.base import ControlContext, Observation
from lcc_synth.controllers.registry import build_controller
from lcc_synth.controllers.static import HDVController, StaticGainController
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.spec import load_spec
from lcc_synth.models.hdv import OVM
from lcc_synth.problem import load_problem, system_from
from lcc_synth.simulation.perturbations import Brake, BrakeProfile, Profile, Sine, overrides
from lcc_synth.simulation.scenario import V2V, Scenario

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"

BASE = """
[system]
kind = "lcc"
m = 1
n = 2
v_star = 15.0

[controllers.hdv]
type = "hdv"
"""


def write(tmp_path, text, name="p.toml"):
    path = tmp_path / name
    path.write_text(BASE + text)
    return path


def test_paper_problem_files_load():
    t2 = load_spec(PROBLEMS / "paper_table2.toml")
    assert list(t2.controllers) == ["all_hdv", "fd_lcc", "cf_lcc"]
    assert t2.scenario.t_start == 0.01 and t2.scenario.steps == 10000
    assert t2.scenario.perturbations == (Brake(1, 20.0, 1.0, -5.0),)
    assert t2.metrics.baseline == "all_hdv"
    sa = load_spec(PROBLEMS / "paper_sec5a.toml")
    assert list(sa.controllers) == ["hdv_only", "case_a", "case_b", "case_c", "case_d"]
    assert sa.scenario.perturbations == (Sine(0.2, 12.0, 20.0, 32.0, "head"),)
    d = sa.controllers["case_d"].describe()
    assert d["semantics"] == "added" and d["gains"]["v_2"] == -1.0
    ac = load_spec(PROBLEMS / "paper_appendix_c.toml", seeds=7)
    assert ac.scenario.batch == 7
    assert dict(ac.scenario.heterogeneity) == {"alpha": 0.1, "beta": 0.1, "s_go": 5.0}
    assert ac.scenario.delay == 0.4 and ac.scenario.delay_spread == 0.1
    assert ac.scenario.delay_model == "perception"


def test_full_scenario_table(tmp_path):
    csv = tmp_path / "prof.csv"
    csv.write_text("t,a\n10,-1\n12,0.5\n14,0\n")
    path = write(tmp_path, """
[scenario]
dt = 0.02
duration = 30.0
hdv_aeb = true
hdv_accel_noise = 0.1
record_every = 5
[scenario.v2v]
loss_rate = [0, 0.1, 0, 0.2, 0.3]
latency = 0.1
velocity_noise = 0.05
[[scenario.perturbations]]
type = "brake_profile"
start = 5.0
[[scenario.perturbations]]
type = "accel_profile"
vehicle = -1
csv = "prof.csv"
[[scenario.perturbations]]
type = "speed_profile"
vehicle = 2
times = [1.0, 3.0]
values = [15.0, 14.0]
interpolation = "linear"
[metrics]
window = [5.0, 25.0]
vehicles = [0, 1, 2]
""")
    spec = load_spec(path)
    sc = spec.scenario
    assert sc.dt == 0.02 and sc.hdv_aeb and sc.record_every == 5
    assert sc.v2v.rates(5).tolist() == [0, 0.1, 0, 0.2, 0.3]
    bp, ap, sp = sc.perturbations
    assert isinstance(bp, BrakeProfile) and bp.start == 5.0
    assert ap == Profile((10.0, 12.0, 14.0), (-1.0, 0.5, 0.0), "accel", "step", -1)
    assert sp.target == "speed" and sp.vehicle == 2
    assert spec.metrics.vehicles == (0, 1, 2) and spec.metrics.window == (5.0, 25.0)


def test_perturbation_overrides_table():
    t = 0.01 * np.arange(3000)
    acc, spd = overrides(
        [Sine(0.2, 12.0, 20.0), Brake(1, 5.0, 1.0),
         Profile((1.0, 2.0), (3.0, 4.0), "speed", "linear")],
        t, 0.01, 0, 2,
    )  # fmt: skip
    on = ~np.isnan(acc[:, 2])
    assert on.sum() == 99 and np.all(acc[on, 2] == -5.0)  # 5 < t < 6, open interval
    k = 2300  # t = 23: 0.2 cos(2 pi 3 / 12) = 0
    assert acc[k, 0] == pytest.approx(0.2 * np.cos(np.pi / 2), abs=1e-12)
    assert acc[2100, 0] == pytest.approx(0.2 * np.cos(2 * np.pi / 12 * 1.0))
    assert np.isnan(acc[2000, 0]) and not np.isnan(acc[2999, 0])
    # speed profile: the target of sample k is the profile at t_{k+1}
    assert spd[100, 0] == pytest.approx(3.01)
    assert np.isnan(spd[200, 0]) and np.isnan(spd[99, 0])


@pytest.mark.parametrize(
    "text, field",
    [
        ("[scenario]\ndt = 0.0", "scenario.dt"),
        ("[scenario]\ndt = -0.01", "scenario.dt"),
        ("[scenario]\nduration = 0", "scenario.duration"),
        ("[scenario]\na_min = 1.0", "scenario.a_min"),
        ("[scenario]\ndtt = 0.1", "scenario.dtt"),
        ("[scenario.delay]\nmean = -0.1", "scenario.delay.mean"),
        ("[scenario.delay]\nmean = 0.1\nspread = 0.2", "scenario.delay.spread"),
        ("[scenario.delay]\nmean = 0.1\nmodel = \"late\"", "scenario.delay.model"),
        ("[scenario.v2v]\nloss_rate = 1.5", "scenario.v2v.loss_rate"),
        ("[scenario.v2v]\nloss_rate = -0.1", "scenario.v2v.loss_rate"),
        ("[scenario.v2v]\nloss_rate = [0.1, 0.2]", "scenario.v2v.loss_rate"),
        ("[scenario.v2v]\nlatency = -1", "scenario.v2v.latency"),
        ("[scenario]\nhdv_accel_noise = -1", "scenario.hdv_accel_noise"),
        ("[scenario.heterogeneity]\ngamma = 0.1", "scenario.heterogeneity.gamma"),
        ("[scenario.heterogeneity]\nalpha = -0.1", "scenario.heterogeneity.alpha"),
        ("[[scenario.perturbations]]\ntype = \"wobble\"", "scenario.perturbations[0].type"),
        ("[[scenario.perturbations]]\ntype = \"brake\"\nvehicle = 5",
         "scenario.perturbations[0].vehicle"),
        ("[[scenario.perturbations]]\ntype = \"sine\"\nperiod = 0",
         "scenario.perturbations[0].period"),
        ("[[scenario.perturbations]]\ntype = \"accel_profile\"\ntimes = [2, 1]\nvalues = [0, 1]",
         "scenario.perturbations[0].times"),
        ("[[scenario.perturbations]]\ntype = \"speed_profile\"\ncsv = \"missing.csv\"",
         "scenario.perturbations[0].csv"),
        ("[metrics]\nwindow = [40, 20]", "metrics.window"),
        ("[metrics]\nbaseline = \"nope\"", "metrics.baseline"),
        ("[metrics]\nvehicles = \"some\"", "metrics.vehicles"),
        ("[controllers.x]\ntype = \"magic\"", "controllers.x.type"),
        ("[controllers.x]\ntype = \"static\"\ngains = { s_7 = 1.0 }", "controllers.x"),
        ("[controllers.x]\ntype = \"static\"\ngains = { s_1 = 1.0 }\nsample_time = -0.1",
         "controllers.x.sample_time"),
        ("[controllers.x]\ntype = \"static\"\nsemantics = \"both\"\ngains = {}",
         "controllers.x.semantics"),
        ("[controllers.x]\ntype = \"gains_file\"\nfile = \"none.json\"", "controllers.x.file"),
    ],
)
def test_bad_problem_files_name_the_field(tmp_path, text, field):
    with pytest.raises(ConfigError) as err:
        load_spec(write(tmp_path, "\n" + text + "\n"))
    assert err.value.field.startswith(field), err.value
    assert err.value.source and err.value.source.endswith("p.toml")


def test_scenario_validation_in_python():
    with pytest.raises(ConfigError, match="scenario.dt"):
        Scenario(m=0, n=1, dt=0.0)
    with pytest.raises(ConfigError, match="scenario.delay"):
        Scenario(m=0, n=1, delay=-0.2)
    with pytest.raises(ConfigError, match="loss_rate"):
        V2V(loss_rate=1.2)
    with pytest.raises(ConfigError, match="scenario.batch"):
        Scenario(m=0, n=1, batch=0)
    with pytest.raises(ConfigError, match="v_star"):
        Scenario(m=0, n=1, v_star=40.0)
    # s_go can fall below s_st: refused as a bound, before any draw (issue 28)
    with pytest.raises(ConfigError, match="heterogeneity.s_go: must be < 30"):
        Scenario(m=0, n=2, heterogeneity={"s_go": 40.0})


def test_gains_file_controller(tmp_path):
    names = ["s_-1", "v_-1", "s_0", "v_0", "s_1", "v_1", "s_2", "v_2"]
    gains = {"kind": "lcc", "m": 1, "n": 2, "semantics": "added", "state_names": names,
             "K": [0.2, -0.3, 0, 0, 0, 0, 0, 0.1],  # the gains file's K (issue 28: required)
             "gains": {"s_-1": 0.2, "v_-1": -0.3, "v_2": 0.1}, "h2_true": 1.0}  # fmt: skip
    (tmp_path / "g.json").write_text(json.dumps(gains))
    path = write(tmp_path, '[controllers.h2]\ntype = "gains_file"\nfile = "g.json"\n')
    spec = load_spec(path)
    c = spec.controllers["h2"]
    assert isinstance(c, StaticGainController)
    assert c.describe()["gains"] == gains["gains"] and c.describe()["semantics"] == "added"
    gains["n"] = 3
    (tmp_path / "g.json").write_text(json.dumps(gains))
    with pytest.raises(ConfigError, match="m=1, n=3"):
        load_spec(path)
    (tmp_path / "g.json").write_text("{not json")
    with pytest.raises(ConfigError, match="not valid JSON"):
        load_spec(path)


def test_linear_law_and_python_call_agree():
    """The law the compiled loop runs equals what __call__ computes (hand-built observation)."""
    system = system_from(load_problem(PROBLEMS / "paper_sec5a.toml").data)
    table = {"type": "static", "semantics": "added",
             "gains": {"s_-2": 1.0, "v_-2": -1.0, "s_1": -0.5, "v_2": 0.3}}  # fmt: skip
    c = build_controller("c", table, system)
    ctx = ControlContext(2, 2, 1, 0.01, np.array([15.0]), np.array([20.0]), -5, 2, OVM())
    c.reset(ctx)
    rng = np.random.default_rng(0)
    s = 20 + rng.normal(size=(1, 6))
    s[0, 0] = np.nan
    v = 15 + rng.normal(size=(1, 6))
    u = c(Observation(0.0, s, v, np.zeros((1, 6))))
    law = c.linear_law(ctx)
    hdv = OVM().accel(s[0, 3], v[0, 2] - v[0, 3], v[0, 3])
    by_hand = hdv + 1.0 * (s[0, 1] - 20) - 1.0 * (v[0, 1] - 15) - 0.5 * (s[0, 4] - 20) + 0.3 * (
        v[0, 5] - 15
    )
    assert u[0] == pytest.approx(by_hand)
    assert law.hdv_law and law.Ks[1] == 1.0 and law.Kv[5] == 0.3
    h = HDVController("h")
    h.reset(ctx)
    assert h(Observation(0.0, s, v, np.zeros((1, 6))))[0] == pytest.approx(hdv)


def test_mpc_type_is_built_lazily(tmp_path):
    """type = "mpc" goes to lcc_synth.mpc.mpc_controller_from_table (owned by the MPC helper);
    a bad MPC table is a ConfigError naming the controller."""
    path = write(tmp_path, '[controllers.m]\ntype = "mpc"\nhorizon_typo = 3\n')
    with pytest.raises(ConfigError) as err:
        load_spec(path)
    assert err.value.field.startswith("controllers.m")


def test_explicit_per_hdv_values(tmp_path):
    spec = load_spec(write(tmp_path, "[scenario.hdv_values]\nalpha = [0.5, 0.7, 0.8]\n"))
    d = spec.scenario.draw()
    assert d.hdv_values["alpha"][0].tolist() == [0.6, 0.5, 0.6, 0.7, 0.8]  # head, -1, CAV, 1, 2
    with pytest.raises(ConfigError, match="scenario.hdv_values.alpha"):
        load_spec(write(tmp_path, "[scenario.hdv_values]\nalpha = [0.5, 0.7]\n"))
    with pytest.raises(ConfigError, match="scenario.hdv_values.v0"):
        load_spec(write(tmp_path, "[scenario.hdv_values]\nv0 = [1, 2, 3]\n"))
