"""The Sugiyama ring benchmark (issue 22): vehicle length in gap coordinates, a controller
switched on at a time, the wave metrics, the wave in simulation and the benchmark's ordering."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from lcc_synth.cli.main import main
from lcc_synth.controllers.baselines import BaselineController, FollowerStopperParams
from lcc_synth.controllers.static import HDVController
from lcc_synth.controllers.switch import SwitchedOn, switch_step
from lcc_synth.experiments.spec import load_spec
from lcc_synth.metrics import braking_events, mean_speed, summary, velocity_std
from lcc_synth.simulation.engine import simulate

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"
BENCH = PROBLEMS / "ring_sugiyama.toml"


def _fake(velocity, acceleration, dt=1.0):
    """A ring result of hand-made trajectories: ``(1, T, nv)`` arrays, samples at k dt."""
    v = np.asarray(velocity, dtype=float)[None]
    T, nv = v.shape[1:]
    return SimpleNamespace(
        t=np.arange(T) * dt, dt=dt, sim_dt=dt, velocity=v,
        acceleration=np.asarray(acceleration, dtype=float)[None],
        collided=np.zeros((1, nv), dtype=bool), n_vehicles=nv, cav=nv - 1, cavs=(nv - 1,),
        ring=True,
    )  # fmt: skip


# ------------------------------------------------------------------------------------------
# metrics at hand-made trajectories
# ------------------------------------------------------------------------------------------


def test_velocity_std_pools_vehicles_and_samples():
    # vehicle 0: 1, 3; vehicle 1: 2, 2 -> pooled {1, 3, 2, 2}: mean 2, std sqrt(1/2).
    # (mean of the per-vehicle stds: 0.5; mean of the per-sample stds: 0.5)
    r = _fake([[1.0, 2.0], [3.0, 2.0]], np.zeros((2, 2)))
    assert velocity_std(r, (0.0, 1.0))[0] == pytest.approx(math.sqrt(0.5), rel=1e-15)
    assert mean_speed(r, (0.0, 1.0))[0] == pytest.approx(2.0, rel=1e-15)
    # the window: only sample 1 -> {3, 2}: std 0.5
    assert velocity_std(r, (1.0, 1.0 + 1e-9))[0] == pytest.approx(0.5, rel=1e-15)


def test_braking_events_count_downward_crossings_of_minus_one():
    a = [0.0, -1.5, -0.5, -1.0, -2.0, -2.0, 0.0, -1.01]
    # crossings: 0 -> -1.5, -1.0 -> -2.0 (-1.0 itself is not below), 0 -> -1.01; staying below
    # (-2 -> -2) and rising back are none
    r = _fake(np.ones((len(a), 1)), np.array(a)[:, None])
    assert braking_events(r, (0.0, 7.0))[0] == 3
    assert braking_events(r, (2.0, 7.0))[0] == 2  # pairs with both samples in the window
    two = _fake(np.ones((len(a), 2)), np.stack([a, a], axis=1))
    assert braking_events(two, (0.0, 7.0))[0] == 6  # summed over the vehicles


# ------------------------------------------------------------------------------------------
# vehicle length: gap coordinates
# ------------------------------------------------------------------------------------------


def _bench_scenario(duration=120.0, **kw):
    spec = load_spec(BENCH)
    return spec, replace(spec.scenario, duration=duration, **kw)


def test_length_on_c_equals_point_vehicles_on_c_minus_n_l():
    spec, sc = _bench_scenario(60.0)
    assert sc.vehicle_length == 5.0 and sc.circumference == pytest.approx(230.0 - 22 * 5.0)
    point = replace(sc, vehicle_length=0.0)  # point vehicles on the 120 m ring
    a = simulate(sc, HDVController("all_hdv"))
    b = simulate(point, HDVController("all_hdv"), sc.draw())
    np.testing.assert_array_equal(a.velocity, b.velocity)
    np.testing.assert_array_equal(a.spacing, b.spacing)  # gaps, bumper to bumper
    cols = np.arange(22)
    np.testing.assert_array_equal(a.position, b.position - 5.0 * cols)
    assert a.circumference == 230.0 and b.circumference == pytest.approx(120.0)
    # the front-to-front distance of the road is the gap plus one length
    front = a.position[0, :, :-1] - a.position[0, :, 1:]
    np.testing.assert_allclose(front, a.spacing[0, :, 1:] + 5.0, rtol=0, atol=1e-9)
    # the equilibrium is that of 120 m of gaps: IDM's s*(v) = 120 / 22
    s_eq = (2.0 + 1.0 * spec.system.v_star) / math.sqrt(1 - (spec.system.v_star / 30.0) ** 4)
    assert s_eq == pytest.approx(120.0 / 22, rel=1e-9)


# ------------------------------------------------------------------------------------------
# the switch-on time
# ------------------------------------------------------------------------------------------


def test_switch_step_rounds_up_to_the_controller_period():
    assert switch_step(300.0, 0.0, 0.025, 1, 24000) == 12000
    assert switch_step(300.01, 0.0, 0.025, 4, 24000) == 12004  # 12001 -> next multiple of 4
    assert switch_step(-5.0, 0.0, 0.025, 4, 24000) == 0
    assert switch_step(1e9, 0.0, 0.025, 1, 24000) == 24000


@pytest.mark.slow  # CI runs it; by default: switch_step's arithmetic (above)
def test_switched_controller_drives_as_an_hdv_before_start_then_takes_over():
    _, sc = _bench_scenario(80.0)
    draws = sc.draw()
    hdv = simulate(sc, HDVController("all_hdv"), draws)
    fs = BaselineController("fs", "follower_stopper", FollowerStopperParams(U=3.0))
    sw = simulate(sc, SwitchedOn(fs, 40.0), draws)
    k = int(round(40.0 / sc.dt)) // sc.record_every  # recorded sample of the switch
    # before the switch every vehicle moves exactly as in the all-HDV run
    np.testing.assert_array_equal(sw.velocity[:, : k + 1], hdv.velocity[:, : k + 1])
    assert not np.array_equal(sw.velocity[:, k + 2 :], hdv.velocity[:, k + 2 :])
    # the wrapped controller was called from the switch on only: (80 - 40) / dt samples
    assert sw.controller_stats["samples"] == int(round(40.0 / sc.dt))
    assert sw.controller_info["start"] == 40.0
    # start at or before t_start: the wrapped controller alone, bit for bit
    fs2 = BaselineController("fs", "follower_stopper", FollowerStopperParams(U=3.0))
    alone = simulate(sc, fs2, draws)
    early = simulate(sc, SwitchedOn(BaselineController(
        "fs", "follower_stopper", FollowerStopperParams(U=3.0)), 0.0), draws)  # fmt: skip
    np.testing.assert_array_equal(alone.velocity, early.velocity)


def test_switched_linear_law_runs_compiled_and_matches_python_path():
    """A static gain switched on runs in the compiled loop; the same gain as a Python
    controller (no linear_law) gives the same trajectory to rounding."""
    spec = load_spec(BENCH)
    _, sc = _bench_scenario(360.0)
    h2 = spec.controllers["h2"]
    assert isinstance(h2, SwitchedOn) and callable(getattr(h2, "linear_law", None))
    inner = h2.inner

    class Py:  # the same law, called from Python each step
        name, sample_time = "py", None

        def reset(self, ctx):
            self.law = inner.linear_law(ctx)
            self.ctx = ctx

        def __call__(self, obs):
            law, ctx = self.law, self.ctx
            s_ref = ctx.spacing_reference()
            u = (np.asarray(law.Ks).reshape(-1) * (obs.spacing - s_ref)).sum(axis=1)
            u += (np.asarray(law.Kv).reshape(-1) * (obs.velocity - ctx.v_star[:, None])).sum(1)
            assert law.hdv_law  # "added": the AV's own IDM law plus the gains
            s, v, v_lead = obs.spacing[:, 21], obs.velocity[:, 21], obs.velocity[:, 20]
            return u + ctx.cav_models[0].accel(s, v_lead - v, v)

        def describe(self):
            return {}

        def stats(self):
            return {}

    draws = sc.draw()
    a = simulate(sc, h2, draws)
    b = simulate(sc, SwitchedOn(Py(), 300.0), draws)
    assert a.wall_time < 60  # compiled; not a timing claim, a sanity bound on the path
    np.testing.assert_allclose(a.velocity, b.velocity, rtol=0, atol=1e-9)


# ------------------------------------------------------------------------------------------
# the wave and the benchmark
# ------------------------------------------------------------------------------------------


def test_all_hdv_idm_ring_forms_a_wave_in_simulation():
    spec = load_spec(BENCH)
    r = simulate(spec.scenario, spec.controllers["all_hdv"])
    early = velocity_std(r, (0.0, 100.0))[0]
    late = velocity_std(r, (400.0, 600.0))[0]
    assert early < 0.3 and late > 2.0 and late > 10 * early  # noise -> stop-and-go wave
    assert braking_events(r, (400.0, 600.0))[0] > 100
    assert np.nanmin(r.velocity[:, r.t > 400]) < 0.5  # vehicles nearly stop in the wave


def test_benchmark_ordering_claims():
    """What holds of the benchmark (the issue's goals, measured): the H2 AV cuts velocity_std
    by more than Stern et al.'s 80.8 %, beats PI with saturation on velocity_std and fuel,
    beats FollowerStopper on velocity_std on this draw, keeps the ring at its equilibrium
    speed (mean speed above all-HDV's and FollowerStopper's)
    and burns less fuel per km than both field controllers; no run collides. FollowerStopper
    with U = the wave's mean speed (2.3 m/s, Stern et al.'s choice) damps the wave as well but
    holds the ring 1 m/s slower: over a fixed window it burns less fuel in total."""
    spec = load_spec(BENCH)
    draws = spec.scenario.draw()
    rows = {}
    for name in ("all_hdv", "follower_stopper", "pi_saturation", "h2"):
        r = simulate(spec.scenario, spec.controllers[name], draws)
        rows[name] = summary(r, spec.metrics)
        t0, t1 = spec.metrics.window
        km = rows[name]["mean_speed"] * (t1 - t0) * 22e-3  # every vehicle's distance, km
        rows[name]["per_km"] = rows[name]["fuel_ml"] / km
    base, h2, fs, pi = (rows[k] for k in ("all_hdv", "h2", "follower_stopper", "pi_saturation"))
    assert 1 - h2["velocity_std"] / base["velocity_std"] > 0.808
    assert h2["velocity_std"] < pi["velocity_std"] and h2["fuel_ml"] < pi["fuel_ml"]
    assert h2["mean_speed"] >= base["mean_speed"] and h2["mean_speed"] > fs["mean_speed"] + 1.0
    assert h2["per_km"] < fs["per_km"] and h2["per_km"] < pi["per_km"]
    assert h2["braking_events"] < 0.05 * base["braking_events"]
    assert fs["velocity_std"] < 0.1 * base["velocity_std"]  # FollowerStopper damps it too
    # on the shipped draw (15 of the next 19 draws too, docs/guide/benchmark.md) h2 damps it
    # further
    assert h2["velocity_std"] < fs["velocity_std"]
    assert fs["fuel_ml"] < h2["fuel_ml"]  # ... driving slower: the goal on fuel_ml is missed
    assert all(r["collisions"] == 0 for r in rows.values())


# ------------------------------------------------------------------------------------------
# bad input: named field, exit 2
# ------------------------------------------------------------------------------------------


def _edit(text: str, old: str, new: str) -> str:
    assert old in text
    return text.replace(old, new, 1)


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ("vehicle_length = 5.0", "vehicle_length = -1.0", "system.vehicle_length"),
        ("vehicle_length = 5.0", "vehicle_length = 11.0", "system.circumference"),  # 242 > 230
        ("vehicle_length = 5.0", "vehicle_length = 10.4545", "system.circumference"),
        ('type = "acc"\n', 'type = "acc"\nh = 0.0\n', "controllers.acc.h"),
        ('type = "acc"\n', 'type = "acc"\nh = -1.0\n', "controllers.acc.h"),
        ("U = 2.3", "U = -0.5", "controllers.follower_stopper.U"),
        ("start = 300.0\n", 'start = "late"\n', "controllers.follower_stopper.start"),
    ],
)
def test_bad_input_names_the_field_and_exits_2(tmp_path, capsys, old, new, field):
    path = tmp_path / "bad.toml"
    path.write_text(_edit(BENCH.read_text(), old, new))
    assert main(["simulate", str(path), "--no-record"]) == 2
    assert field in capsys.readouterr().err


def test_switched_static_law_starts_its_estimate_and_filter_at_the_switch(tmp_path):
    """Before ``start`` the CAV drives with its HDV law on the values as received, exactly as
    the all-HDV run: a static law's equilibrium estimate and measurement filter start at the
    switch (they used to run, and filter the HDV law's inputs, from t = 0)."""
    path = tmp_path / "switched.toml"
    path.write_text("""
[hdv]
model = "ovm"

[system]
kind = "cf_lcc"
m = 0
n = 4
v_star = 15.0

[scenario]
dt = 0.01
duration = 20.0
seed = 3
hdv_accel_noise = 0.1
v2v = { loss_rate = 0.2, latency = 0.1, spacing_noise = 0.1, velocity_noise = 0.05 }

[[scenario.perturbations]]
type = "brake"
vehicle = "head"
start = 2.0
duration = 2.0
decel = -3.0

[metrics]
window = [0.0, 20.0]

[controllers.all_hdv]
type = "hdv"

[controllers.p]
type = "static"
kind = "cf_lcc"
semantics = "added"
gains = { s_0 = 0.1, v_0 = -0.5, s_1 = -0.2, v_1 = 0.05 }
equilibrium = "estimated"
equilibrium_tau = 1.0
measurement_filter = 0.3
start = 10.0
""")
    spec = load_spec(path, seeds=2)
    sc = spec.scenario
    draws = sc.draw()
    hdv = simulate(sc, spec.controllers["all_hdv"], draws)
    sw = simulate(sc, spec.controllers["p"], draws)
    k = int(round(10.0 / sc.dt)) // sc.record_every
    np.testing.assert_array_equal(sw.velocity[:, : k + 1], hdv.velocity[:, : k + 1])
    assert not np.array_equal(sw.velocity[:, k + 2 :], hdv.velocity[:, k + 2 :])
