"""Co-simulation in SUMO (``scenario.backend = "sumo"``, :mod:`lcc_synth.simulation.sumo`).

The cross-check: the same scenario in SUMO and in the built-in simulator (same IDM parameters,
same dt, same draws) agrees within tolerances measured here (dt = 0.01 s, v* = 15 m/s, the
head-brake profile, the CAV and 10 HDVs behind):

================== ================== ================== =========== ==========
SUMO step method   max |dv| (m/s)     max |ds| (m)       AAVE rel.   fuel rel.
================== ================== ================== =========== ==========
euler (default)    0.021-0.023        0.051-0.077        0.8-1.3e-3  2.6-3.5e-4
ballistic          0.011              0.025-0.038        0.4-0.6e-3  1.3-1.7e-4
================== ================== ================== =========== ==========

(all_hdv / h2 / mpc.) Why they differ, and why these bounds: SUMO reproduces its own scheme
(the built-in IDM law, SUMO's position update) to 1e-10 (:func:`test_sumo_is_its_own_scheme`),
so the whole difference is the position update: explicit Euler in the built-in simulator,
semi-implicit Euler (ballistic: the mean speed) in SUMO. For the same speeds the positions then
differ by ``dt (v_k - v_0)`` (half of it ballistic), each gap by ``dt`` times the relative speed
(<= 0.05 m here, up to 10 m/s between neighbours), which the string's feedback carries on; the
difference is first order in dt (x 5 at dt = 0.05 s, :func:`test_difference_is_first_order`).
The tolerances are about 1.3-1.5 x the largest value measured.

Skipped when libsumo is not importable, except in CI (``CI=true``), where a missing SUMO fails.
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lcc_synth.cli.main import main
from lcc_synth.controllers.static import HDVController
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.spec import load_spec
from lcc_synth.metrics import per_scenario
from lcc_synth.models.hdv import IDM, OVM
from lcc_synth.simulation.backends import run_scenario
from lcc_synth.simulation.perturbations import overrides, perturbation_from_table
from lcc_synth.simulation.scenario import V2V, Scenario
from lcc_synth.simulation.sumo import merge_stats
from lcc_synth.simulation.sumo_net import SumoSettings

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"
PROBLEM = PROBLEMS / "sumo_head_brake.toml"

needs_sumo = pytest.mark.sumo  # skipped without libsumo, except in CI (conftest.py)

#: Measured tolerances (module docstring): max |dv| m/s, max |ds| m, AAVE and fuel relative.
TOL = {"euler": (0.03, 0.1, 2e-3, 5e-4), "ballistic": (0.015, 0.05, 1e-3, 2.5e-4)}

BRAKE = {"type": "brake_profile", "start": 20.0, "decel": -5.0, "decel_time": 2.0,
         "hold_time": 5.0, "accel": 2.0, "accel_time": 5.0}  # fmt: skip


def _head_brake(**keys) -> Scenario:
    pert = perturbation_from_table(BRAKE, "p", 0, 10, None)
    base = {"m": 0, "n": 10, "hdv": IDM(), "v_star": 15.0, "dt": 0.01, "duration": 70.0,
            "perturbations": (pert,), "backend": "sumo"}  # fmt: skip
    return Scenario(**{**base, **keys})


def _diff(a, b) -> tuple[float, float]:
    return (float(np.nanmax(np.abs(a.velocity - b.velocity))),
            float(np.nanmax(np.abs(a.spacing - b.spacing))))  # fmt: skip


def test_sumo_installed_in_ci():
    """In CI (``.ci/run`` installs the ``sumo`` extra) SUMO must be importable."""
    from conftest import IN_CI, have_sumo

    if IN_CI:
        assert have_sumo(), 'CI=true but libsumo is not importable: pip install -e ".[sumo]"'


@needs_sumo
@pytest.mark.parametrize("method", ["euler", "ballistic"])
def test_cross_check_all_hdv_idm_head_brake(method):
    """All-HDV IDM string, head brake: SUMO and the built-in simulator agree (module
    docstring); neither collides, and both see the same minimum spacing within the bound."""
    from lcc_synth.metrics import MetricsConfig

    sc = _head_brake(sumo=SumoSettings(step_method=method))
    ctrl = HDVController("all_hdv")
    draws = sc.draw()
    rs = run_scenario(sc, ctrl, draws)
    rb = run_scenario(replace(sc, backend="builtin"), ctrl, draws)
    assert rs.position.shape == rb.position.shape == (1, 7000, 12)
    assert not rs.collided.any() and not rb.collided.any()
    dv_tol, ds_tol, aave_tol, fuel_tol = TOL[method]
    dv, ds = _diff(rs, rb)
    assert dv < dv_tol and ds < ds_tol
    assert dv > 0.2 * dv_tol  # a real difference (the integration scheme), measured above
    cfg = MetricsConfig(window=(20.0, 60.0))
    ms, mb = per_scenario(rs, cfg), per_scenario(rb, cfg)
    assert abs(ms["aave"][0] / mb["aave"][0] - 1) < aave_tol
    assert abs(ms["fuel_ml"][0] / mb["fuel_ml"][0] - 1) < fuel_tol
    assert abs(np.nanmin(rs.spacing) - np.nanmin(rb.spacing)) < ds_tol
    # the recorded acceleration is what SUMO applied: the head's brake profile exactly
    assert np.allclose(rs.acceleration[0, 2001:2199, 0], -5.0, atol=1e-9)


@needs_sumo
@pytest.mark.parametrize("method", ["euler", "ballistic"])
def test_sumo_is_its_own_scheme(method):
    """SUMO's IDM string equals the built-in IDM law integrated with SUMO's position update
    (semi-implicit Euler, or the mean speed) to 1e-9: the vType mapping (v0, T, s0, a, b,
    delta; minGap, length, speed factor) is exact and the integration is the only difference."""
    sc = _head_brake(duration=40.0, sumo=SumoSettings(step_method=method))
    res = run_scenario(sc, HDVController("all_hdv"))
    acc, _ = overrides(sc.perturbations, sc.times(), sc.dt, 0, 10)
    idm, dt = sc.hdv, sc.dt
    p = -np.cumsum(np.nan_to_num(sc.draw().initial_spacing[0], nan=0.0))
    v = np.full(sc.n_vehicles, sc.v_star)
    for k in range(sc.steps):
        assert np.max(np.abs(res.position[0, k] - p)) < 1e-8
        assert np.max(np.abs(res.velocity[0, k] - v)) < 1e-9
        a = np.zeros_like(v)
        a[1:] = np.clip(idm.accel(p[:-1] - p[1:], v[:-1] - v[1:], v[1:]), sc.a_min, sc.a_max)
        if np.isfinite(acc[k, 0]):
            a[0] = acc[k, 0]
        v_next = np.maximum(v + dt * a, 0.0)
        p = p + dt * (v_next if method == "euler" else 0.5 * (v + v_next))
        v = v_next


@needs_sumo
def test_difference_is_first_order():
    """At dt = 0.05 s the velocity difference is about 5 x that at 0.01 s (first order)."""
    ctrl = HDVController("all_hdv")
    out = []
    for dt in (0.01, 0.05):
        sc = _head_brake(dt=dt, duration=40.0)
        out.append(_diff(run_scenario(sc, ctrl), run_scenario(replace(sc, backend="builtin"),
                                                                ctrl))[0])  # fmt: skip
    assert 3.5 < out[1] / out[0] < 6.5


@pytest.mark.slow  # CI runs it; by default: SUMO's platoon cross-check (test_sumo_ring)
@needs_sumo
def test_sumo_head_brake_cli_json_and_ranking(tmp_path, capfd):
    """``lcc-synth simulate problems/sumo_head_brake.toml --json`` prints the usual results
    (one JSON object on stdout: nothing from SUMO), and all_hdv / h2 / mpc rank the same on
    AAVE in SUMO and in the built-in simulator, within the cross-check's tolerances."""
    assert main(["simulate", str(PROBLEM), "--json", "--no-record"]) == 0
    sumo = json.loads(capfd.readouterr().out)["results"]
    builtin_file = tmp_path / "builtin_head_brake.toml"
    builtin_file.write_text(PROBLEM.read_text().replace('backend = "sumo"', 'backend = "builtin"'))
    assert main(["simulate", str(builtin_file), "--json", "--no-record"]) == 0
    builtin = json.loads(capfd.readouterr().out)["results"]
    assert set(sumo) == set(builtin) == {"all_hdv", "h2", "mpc"}

    def rank(res):
        return sorted(res, key=lambda name: res[name]["aave"])

    assert rank(sumo) == rank(builtin) == ["mpc", "h2", "all_hdv"]
    for name in sumo:
        s, b = sumo[name], builtin[name]
        assert s["collisions"] == b["collisions"] == 0
        assert abs(s["aave"] / b["aave"] - 1) < TOL["euler"][2]
        assert abs(s["fuel_ml"] / b["fuel_ml"] - 1) < TOL["euler"][3]
        assert abs(s["min_spacing"] - b["min_spacing"]) < TOL["euler"][1]
    assert sumo["mpc"]["controller_stats"]["fallbacks"] == 0


@needs_sumo
def test_v2v_and_hdv_perturbation_as_builtin():
    """The CAV's V2V model (loss, latency, noise) and a perturbation on an HDV (Table II's
    brake of HDV 1) run in SUMO as in the built-in simulator, within the cross-check bounds."""
    spec = load_spec(PROBLEM)
    h2 = spec.controllers["h2"]
    v2v = V2V(0.2, 0.1, 0.1, 0.05, 0.0)
    pb = perturbation_from_table(
        {"type": "brake", "vehicle": 1, "start": 20.0, "duration": 1.0, "decel": -5.0},
        "p", 0, 10, None,
    )
    for sc in (replace(spec.scenario, v2v=v2v, duration=40.0),
               replace(spec.scenario, perturbations=(pb,), duration=40.0)):  # fmt: skip
        rs = run_scenario(sc, h2)
        rb = run_scenario(replace(sc, backend="builtin"), h2)
        dv, ds = _diff(rs, rb)
        assert dv < TOL["euler"][0] and ds < TOL["euler"][1]
    # HDV 1 (column 2) followed its brake exactly while it lasted, then SUMO's IDM again
    k = slice(2001, 2099)
    assert np.allclose(rs.acceleration[0, k, 2], -5.0, atol=1e-9)
    assert not np.allclose(rs.acceleration[0, 2200:2300, 2], 0.0, atol=1e-6)


class _Push:
    """A CAV controller that always commands +2 m/s^2 (into the head vehicle)."""

    name = "push"
    sample_time = None

    def reset(self, ctx):
        self.batch = ctx.batch

    def __call__(self, obs):
        return np.full(self.batch, 2.0)

    def describe(self):
        return {"type": "push"}

    def stats(self):
        return {}


@needs_sumo
def test_collision_and_aeb_from_sumo():
    """The CAV's emergency braking (eq. 29) acts on SUMO's state and stops a CAV that pushes
    into the head; without it SUMO reports the collision at the built-in simulator's time and
    the scenario stops there (later samples NaN)."""
    sc = replace(_head_brake(duration=30.0), perturbations=())
    res = run_scenario(sc, _Push())
    assert res.aeb_active.any() and not res.collided.any()
    sc = replace(sc, cav_aeb=False)
    rs, rb = run_scenario(sc, _Push()), run_scenario(replace(sc, backend="builtin"), _Push())
    assert rs.collided[0, 1] and rb.collided[0, 1] and rs.collided.sum() == 1
    assert abs(rs.collision_time[0, 1] - rb.collision_time[0, 1]) <= 0.05
    k = int(round(rs.collision_time[0, 1] / sc.dt))
    assert np.isfinite(rs.spacing[0, k, 1]) and rs.spacing[0, k, 1] <= 0.0
    assert np.isnan(rs.velocity[0, k + 1:]).all() and np.isnan(rs.u_cmd[0, k:]).all()


@needs_sumo
def test_batch_runs_scenario_by_scenario():
    """A batch of heterogeneous draws runs one SUMO per scenario; each row matches the
    built-in simulator's row on the same draws."""
    sc = _head_brake(duration=35.0, batch=2, heterogeneity={"T": 0.2, "s0": 0.5})
    draws = sc.draw()
    ctrl = HDVController("all_hdv")
    rs = run_scenario(sc, ctrl, draws)
    rb = run_scenario(replace(sc, backend="builtin"), ctrl, draws)
    assert rs.velocity.shape == (2, 3500, 12)
    for b in range(2):
        assert np.nanmax(np.abs(rs.velocity[b] - rb.velocity[b])) < TOL["euler"][0]
    assert np.nanmax(np.abs(rs.velocity[0] - rs.velocity[1])) > 0.05  # different draws


@needs_sumo
@pytest.mark.parametrize("model", ["EIDM", "Krauss"])
def test_other_sumo_models_run(model):
    """EIDM and Krauss take the IDM parameters (module docstring of sumo_net) and run."""
    sc = _head_brake(duration=30.0, sumo=SumoSettings(car_following=model, sigma=0.2))
    res = run_scenario(sc, HDVController("all_hdv"))
    assert np.isfinite(res.velocity).all() and not res.collided.any()


@needs_sumo
def test_ring_road_network(tmp_path):
    """:func:`ring_road` builds a closed single-lane ring of the asked circumference."""
    import sumolib

    from lcc_synth.simulation.sumo_net import ring_road

    net = sumolib.net.readNet(str(ring_road(260.0, 30.0, tmp_path)))
    edges = net.getEdges()
    assert len(edges) == 4 and all(e.getLaneNumber() == 1 for e in edges)
    assert abs(sum(e.getLength() for e in edges) - 260.0) < 1e-3
    for e in edges:  # each edge leads into the next: a closed ring
        assert len(e.getOutgoing()) == 1


# ------------------------------------------------------------------------------ errors


def test_missing_sumo_is_a_named_error(monkeypatch, capsys):
    """backend = "sumo" without libsumo: ConfigError naming scenario.backend and the install
    command; the CLI exits 2."""
    monkeypatch.setitem(sys.modules, "libsumo", None)  # import libsumo -> ImportError
    with pytest.raises(ConfigError) as err:
        run_scenario(_head_brake(duration=1.0), HDVController("all_hdv"))
    assert err.value.field == "scenario.backend"
    assert 'pip install -e ".[sumo]"' in err.value.message
    assert main(["simulate", str(PROBLEM), "--no-record"]) == 2
    assert 'scenario.backend' in capsys.readouterr().err


def test_missing_sumo_fails_run_and_sweep_early(monkeypatch, tmp_path, capsys):
    """``run`` and ``sweep`` check the simulator before any synthesis or task: exit 2 naming
    the scenario's backend field."""
    monkeypatch.setitem(sys.modules, "libsumo", None)
    suite = tmp_path / "suite.toml"
    suite.write_text(_SUITE.replace("BACKEND", "sumo"))
    argv = ["run", str(suite), "--no-record", "--no-figures", "--no-progress",
            "--out", str(tmp_path / "results")]  # fmt: skip
    assert main(argv) == 2
    assert "scenarios.brake.backend" in capsys.readouterr().err
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(_SWEEP.replace("BACKEND", "sumo"))
    from lcc_synth.experiments.sweep import load_sweep, run_sweep

    with pytest.raises(ConfigError, match="scenario.backend"):
        run_sweep(load_sweep(sweep), client=None, progress=False)


def test_missing_netconvert_is_a_named_error(monkeypatch):
    """No netconvert (neither sumolib's nor on PATH): ConfigError naming scenario.backend."""
    import shutil

    from lcc_synth.simulation.sumo_net import netconvert_binary

    monkeypatch.setitem(sys.modules, "sumolib", None)
    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(ConfigError, match="scenario.backend") as err:
        netconvert_binary()
    assert 'pip install -e ".[sumo]"' in err.value.message


def test_bad_car_following_model_is_named(tmp_path):
    """An unknown SUMO model name is a ConfigError naming scenario.sumo.car_following."""
    bad = tmp_path / "bad.toml"
    bad.write_text(PROBLEM.read_text().replace('car_following = "IDM"',
                                               'car_following = "Wiedemann"'))  # fmt: skip
    with pytest.raises(ConfigError) as err:
        load_spec(bad)
    assert err.value.field == "scenario.sumo.car_following"
    assert "IDM" in err.value.message and "Krauss" in err.value.message


@pytest.mark.parametrize(
    ("keys", "field"),
    [
        ({"hdv": OVM()}, "hdv.model"),
        ({"delay": 0.3}, "scenario.delay.mean"),
        ({"hdv_accel_noise": 0.1, "sumo": SumoSettings(car_following="Krauss")},
         "scenario.hdv_accel_noise"),  # with SUMO's IDM it runs (tests/test_sumo_sugiyama.py)
        ({"dt": 0.0125}, "scenario.dt"),  # SUMO steps in whole milliseconds
        ({"hdv_aeb": True}, "scenario.hdv_aeb"),
        ({"backend": "vissim"}, "scenario.backend"),
    ],
)
def test_what_sumo_cannot_reproduce_is_an_error(keys, field):
    """Reaction delays, white acceleration noise with a SUMO model other than the IDM, HDV
    emergency braking, the OVM and a step SUMO cannot take have no SUMO counterpart: an error
    naming the field, never silently ignored."""
    with pytest.raises(ConfigError) as err:
        _head_brake(**keys)
    assert err.value.field == field


def test_sumo_settings_checks():
    with pytest.raises(ConfigError, match="scenario.sumo.sigma"):
        SumoSettings(sigma=0.5)  # the IDM has no imperfection
    with pytest.raises(ConfigError, match="scenario.sumo.step_method"):
        SumoSettings(step_method="rk4")
    with pytest.raises(ConfigError, match="scenario.sumo.vehicle_length"):
        SumoSettings(vehicle_length=0.0)
    assert SumoSettings(car_following="Krauss", sigma=0.5).toml_table()["sigma"] == 0.5


def test_merge_stats():
    """Per-scenario controller statistics of a batch: counts summed (samples counted once, as
    in a batch run together), maxima kept, other numbers averaged, lists joined."""
    a = {"steps": 10, "max_slack_m": 0.5, "t": {"median": 1.0, "count": 3}, "msgs": ["x"]}
    b = {"steps": 5, "max_slack_m": 0.2, "t": {"median": 3.0, "count": 2}, "msgs": []}
    a["solves"], b["solves"] = 10, 5
    assert merge_stats([a, b]) == {
        "steps": 10, "max_slack_m": 0.5, "t": {"median": 2.0, "count": 5}, "msgs": ["x"],
        "solves": 15,
    }
    assert merge_stats([{}, {}]) == {} and merge_stats([a]) == a


# ------------------------------------------------------------------ run and sweep in SUMO

_SUITE = """
name = "sumo_suite"
[hdv]
model = "idm"
[metrics]
window = [20.0, 30.0]
[layouts.string4]
kind = "cf_lcc"
n = 4
v_star = 15.0
[scenarios.brake]
layout = "string4"
duration = 30.0
backend = "BACKEND"
[[scenarios.brake.perturbations]]
type = "brake"
vehicle = "head"
start = 20.0
duration = 1.0
decel = -5.0
[controllers.all_hdv]
type = "hdv"
"""

_SWEEP = """
name = "sumo_sweep"
[hdv]
model = "idm"
[system]
kind = "cf_lcc"
n = 4
v_star = 15.0
[scenario]
backend = "BACKEND"
duration = 30.0
heterogeneity = { T = 0.2 }
[[scenario.perturbations]]
type = "brake"
vehicle = "head"
start = 20.0
duration = 1.0
decel = -5.0
[metrics]
window = [20.0, 30.0]
[sweep]
count = 3
batch_size = 2
[controllers.all_hdv]
type = "hdv"
"""


@needs_sumo
def test_run_suite_in_sumo(tmp_path, capfd):
    """``lcc-synth run`` on a suite whose scenario says backend = "sumo" runs it in SUMO."""
    rows = {}
    for backend in ("sumo", "builtin"):
        path = tmp_path / f"suite_{backend}.toml"
        path.write_text(_SUITE.replace("BACKEND", backend))
        argv = ["run", str(path), "--json", "--no-record", "--no-figures", "--no-progress",
                "--out", str(tmp_path / "results")]  # fmt: skip
        assert main(argv) == 0
        rows[backend] = json.loads(capfd.readouterr().out)["results"]["brake"]["all_hdv"]
        (details,) = (tmp_path / "results").glob("sumo_suite-*/details.json")
        assert json.loads(details.read_text())["scenarios"]["brake"]["backend"] == backend
        details.unlink()
    assert rows["sumo"]["aave"] != rows["builtin"]["aave"]  # a different simulator ran
    assert abs(rows["sumo"]["aave"] / rows["builtin"]["aave"] - 1) < TOL["euler"][2]


@needs_sumo
def test_sweep_in_sumo(tmp_path):
    """``sweep`` with backend = "sumo": every drawn scenario runs in SUMO (chunks of 2, one
    SUMO per scenario) and agrees with the built-in sweep on the same draws."""
    from lcc_synth.experiments.sweep import load_sweep, run_sweep

    out = {}
    for backend in ("sumo", "builtin"):
        path = tmp_path / f"sweep_{backend}.toml"
        path.write_text(_SWEEP.replace("BACKEND", backend))
        res = run_sweep(load_sweep(path), client=None, progress=False)
        out[backend] = np.asarray(res.samples["all_hdv"]["aave"])
    assert out["sumo"].shape == (3,) and np.unique(out["sumo"]).size == 3
    assert not np.array_equal(out["sumo"], out["builtin"])
    np.testing.assert_allclose(out["sumo"], out["builtin"], rtol=TOL["euler"][2])


def test_vehicle_type_mapping():
    """The [hdv] IDM parameters as SUMO's vType attributes (module docstring of sumo_net)."""
    from lcc_synth.simulation.sumo_net import vehicle_types

    idm = {"v0": 30.0, "T": 1.5, "s0": 2.0, "a": 1.0, "b": 1.5, "delta": 4.0}
    t = vehicle_types(SumoSettings(), idm, 0.01, -5.0)
    assert t == {
        "carFollowModel": "IDM", "length": 5.0, "minGap": 2.0, "maxSpeed": 30.0, "accel": 1.0,
        "decel": 1.5, "emergencyDecel": 5.0, "tau": 1.5, "speedFactor": 1.0, "speedDev": 0.0,
        "collisionMinGapFactor": 0.0, "delta": 4.0, "stepping": 0.01,
    }  # fmt: skip
    k = vehicle_types(SumoSettings(car_following="Krauss", sigma=0.3), idm, 0.01, -5.0)
    assert k["carFollowModel"] == "Krauss" and k["sigma"] == 0.3 and "delta" not in k
    e = vehicle_types(SumoSettings(car_following="EIDM"), idm, 0.01, -5.0)
    assert e["carFollowModel"] == "EIDM" and e["delta"] == 4.0 and e["sigma"] == 0.0


def test_route_file_and_head_travel(tmp_path):
    """Every vehicle departs at time 0 at its given state without insertion checks; the road
    covers the head's prescribed motion."""
    import xml.etree.ElementTree as ET

    from lcc_synth.simulation.sumo import head_travel
    from lcc_synth.simulation.sumo_net import route_file

    path = route_file(tmp_path / "r.rou.xml", [{"accel": 1.0}, {"accel": 2.0}],
                      [(100.0, 15.0), (69.7, 15.0)])  # fmt: skip
    root = ET.parse(path).getroot()
    veh = root.findall("vehicle")
    assert [v.get("id") for v in veh] == ["v0", "v1"]
    assert veh[1].get("departPos") == "69.700000000000003" and veh[1].get("depart") == "0"
    assert all(v.get("insertionChecks") == "none" for v in veh)
    sc = _head_brake()
    acc, spd = overrides(sc.perturbations, sc.times(), sc.dt, 0, 10)
    # the head's own run in the built-in simulator (it starts at 0), one step further
    head = run_scenario(replace(sc, backend="builtin"), HDVController("x"))
    end = head.position[0, -1, 0] + sc.dt * head.velocity[0, -1, 0]
    assert head_travel(acc, spd, 15.0, 0.01, -5.0, 2.0) == pytest.approx(end, abs=0.2)
    assert 960.0 < end < 970.0  # 70 s at 15 m/s less about 85 m lost in the brake profile


@needs_sumo
def test_sumo_run_is_recorded(tmp_path):
    """A SUMO run goes into the usual Rerun recording: every controller's trajectories."""
    from lcc_synth.recording.reader import summarize_recording

    short = tmp_path / "short.toml"
    short.write_text(PROBLEM.read_text().replace("duration = 70.0", "duration = 25.0")
                     .replace("window = [20.0, 60.0]", "window = [20.0, 25.0]"))  # fmt: skip
    rrd = tmp_path / "sumo.rrd"
    assert main(["simulate", str(short), "--rrd", str(rrd), "--record-every", "1"]) == 0
    summary = summarize_recording(rrd)
    assert summary.finalized
    for name in ("all_hdv", "h2", "mpc"):
        entity = summary.entities[f"/sumo_head_brake/{name}/velocity"]
        assert entity.samples == 2500


@needs_sumo
def test_guide_sumo_snippet(capsys):
    """The python block of the guide's SUMO page (docs/guide/sumo.md) prints what it shows."""
    import re

    text = (Path(__file__).resolve().parents[1] / "docs" / "guide" / "sumo.md").read_text()
    code = re.search(r"```python\n(.*?)```", text, flags=re.S).group(1)
    shown = re.search(r"```text\n(.*?)```", text, flags=re.S).group(1)
    exec(compile(code, "docs/guide/sumo.md", "exec"), {"__name__": "guide"})
    assert capsys.readouterr().out == shown


@needs_sumo
def test_vehicle_length_changes_nothing():
    """Spacings are SUMO's bumper-to-bumper gaps: a 0.5 m or a 5 m vehicle, the same run."""
    ctrl = HDVController("all_hdv")
    a = run_scenario(_head_brake(duration=30.0), ctrl)
    b = run_scenario(_head_brake(duration=30.0, sumo=SumoSettings(vehicle_length=0.5)), ctrl)
    dv, ds = _diff(a, b)
    assert dv < 1e-9 and ds < 1e-8
