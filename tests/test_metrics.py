"""Metric definitions against hand-computed cases (no simulation involved)."""

from __future__ import annotations

import numpy as np
import pytest

from lcc_synth.errors import ConfigError
from lcc_synth.metrics import (
    MetricsConfig,
    aave,
    aeb_activations,
    bowyer_fuel_rate,
    collisions,
    fuel,
    max_abs_command,
    max_abs_velocity_error,
    min_spacing,
    min_time_to_collision,
    rms_jerk,
    summary,
    vehicle_columns,
    window_mask,
)
from lcc_synth.simulation.results import SimResult


def make_result(v, a=None, s=None, dt=0.5, t0=0.0, m=0, n=2, u=None, aeb=None, v_star=15.0):
    """A SimResult from hand-written arrays ``(B, T, nv)``."""
    v = np.asarray(v, dtype=float)
    B, T, nv = v.shape
    a = np.zeros_like(v) if a is None else np.asarray(a, dtype=float)
    if s is None:
        s = np.full_like(v, 20.0)
    s = np.array(s, dtype=float)
    s[:, :, 0] = np.nan
    t = t0 + dt * np.arange(T)
    return SimResult(
        t=t,
        position=np.zeros_like(v),
        velocity=v,
        acceleration=a,
        spacing=s,
        u_cmd=np.zeros((B, T)) if u is None else np.asarray(u, float),
        aeb_active=np.zeros((B, T), bool) if aeb is None else np.asarray(aeb, bool),
        collided=np.zeros((B, nv), bool),
        collision_time=np.full((B, nv), np.nan),
        m=m,
        n=n,
        cav=m + 1,
        v_star=np.full(B, v_star),
        s_star=np.full(B, 20.0),
        controller="test",
        controller_info={},
        controller_stats={},
        dt=dt,
        sim_dt=dt,
    )


def test_bowyer_fuel_rate_branches():
    # a = 0, v = 10: R = 0.333 + 0.108 = 0.441; f = 0.444 + 0.09 * 0.441 * 10 = 0.8409
    assert bowyer_fuel_rate(10.0, 0.0) == pytest.approx(0.8409)
    # a = 1 > 0 adds 0.054 a^2 v: R = 0.441 + 1.2 = 1.641; f = 0.444 + 1.4769 + 0.54
    assert bowyer_fuel_rate(10.0, 1.0) == pytest.approx(0.444 + 0.09 * 1.641 * 10 + 0.54)
    # hard braking: R = 0.441 - 6 <= 0 -> idle rate
    assert bowyer_fuel_rate(10.0, -5.0) == pytest.approx(0.444)
    # R exactly 0 counts as idle (R <= 0 branch)
    a0 = -(0.333 + 0.00108 * 100.0) / 1.2
    assert bowyer_fuel_rate(10.0, a0 - 1e-12) == pytest.approx(0.444)


def test_window_is_closed_interval():
    r = make_result(np.zeros((1, 101, 4)), dt=0.01, t0=0.0)
    mask = window_mask(r, (0.2, 0.4))
    assert mask.sum() == 21  # 0.20, 0.21, ..., 0.40 inclusive
    with pytest.raises(ConfigError, match="metrics.window"):
        window_mask(r, (5.0, 6.0))


def test_aave_hand_computed():
    # 1 scenario, 5 samples (dt 0.5 s), head + CAV + 2 HDVs behind; window [0, 2] s = 5 samples
    v = np.full((1, 5, 4), 15.0)
    v[0, :, 1] = 16.0  # CAV: error 1 everywhere
    v[0, 2, 3] = 13.0  # last HDV: error 2 at one sample
    v[0, :, 0] = 99.0  # head: excluded from cav_and_behind
    r = make_result(v)
    # sum |err| dt = (5 * 1 + 2) * 0.5 = 3.5; / window length 2 / 3 vehicles
    assert aave(r, (0.0, 2.0))[0] == pytest.approx(3.5 / 2.0 / 3.0)
    # explicit vehicle list: only vehicle 2 (the tail): 2 * 0.5 / 2 / 1
    assert aave(r, (0.0, 2.0), vehicles=[2])[0] == pytest.approx(0.5)
    # window [1, 2] keeps samples 2..4: CAV 3 * 1 + tail 2 = 5 -> 5 * 0.5 / 1 / 3
    assert aave(r, (1.0, 2.0))[0] == pytest.approx(2.5 / 3.0)


def test_fuel_hand_computed():
    v = np.full((1, 3, 3), 10.0)
    a = np.zeros((1, 3, 3))
    a[0, 1, 1] = 1.0
    a[0, 2, 2] = -5.0
    r = make_result(v, a, dt=0.1, n=1)
    f0 = bowyer_fuel_rate(10.0, 0.0)
    expected = (4 * f0 + bowyer_fuel_rate(10.0, 1.0) + 0.444) * 0.1  # CAV + 1 HDV, 3 samples
    assert fuel(r, (0.0, 0.2))[0] == pytest.approx(expected)


def test_safety_metrics_hand_computed():
    v = np.full((2, 4, 3), 15.0)
    s = np.full((2, 4, 3), 20.0)
    # scenario 0: the HDV behind the CAV closes in at 2 m/s with 10 m gap at sample 1
    v[0, 1, 2] = 17.0
    s[0, 1, 2] = 10.0
    s[0, 3, 1] = 4.0  # CAV's spacing dips to 4 m (no closing speed)
    v[1, 2, 0] = 12.0  # scenario 1: head slower by 3 m/s, CAV closes in with 20 m gap
    r = make_result(v, s=s, n=1)
    ms = min_spacing(r)
    assert np.isnan(ms[:, 0]).all()
    assert ms[0, 1:].tolist() == [4.0, 10.0]
    ttc = min_time_to_collision(r)
    assert ttc[0, 2] == pytest.approx(5.0) and np.isinf(ttc[0, 1])
    assert ttc[1, 1] == pytest.approx(20.0 / 3.0)
    mv = max_abs_velocity_error(r)
    assert mv[0].tolist() == [0.0, 0.0, 2.0] and mv[1].tolist() == [3.0, 0.0, 0.0]


def test_cav_command_jerk_aeb_collisions():
    T = 6
    a = np.zeros((1, T, 3))
    a[0, :, 1] = 0.1 * np.arange(T)  # ramp: jerk = 0.1 / dt = 1 m/s^3 everywhere
    u = np.array([[0.0, -3.0, 1.0, 0.5, 0.0, 0.0]])
    aeb = np.array([[0, 1, 1, 0, 1, 0]], bool)
    r = make_result(np.full((1, T, 3), 15.0), a, dt=0.1, n=1, u=u, aeb=aeb)
    assert rms_jerk(r)[0] == pytest.approx(1.0)
    assert max_abs_command(r)[0] == 3.0
    assert aeb_activations(r)[0] == 3
    r.collided[0, 2] = True
    assert collisions(r)[0] == 1


def test_vehicle_sets():
    r = make_result(np.zeros((1, 2, 6)), m=2, n=2)
    assert vehicle_columns(r, "cav_and_behind").tolist() == [3, 4, 5]
    assert vehicle_columns(r, "all").tolist() == [0, 1, 2, 3, 4, 5]
    assert vehicle_columns(r, "hdvs").tolist() == [1, 2, 4, 5]
    assert vehicle_columns(r, [-2, 0, "head"]).tolist() == [1, 3, 0]
    with pytest.raises(ConfigError, match="metrics.vehicles"):
        vehicle_columns(r, [3])
    with pytest.raises(ConfigError, match="metrics.window"):
        MetricsConfig(window=(40.0, 20.0))


def test_summary_batch_statistics():
    v = np.full((2, 5, 3), 15.0)
    v[0, :, 1] = 16.0  # scenario 0: CAV error 1
    r = make_result(v, n=1)
    s = summary(r, MetricsConfig(window=(0.0, 2.0)))
    a_all = [5 * 0.5 / 2.0 / 2.0, 0.0]
    assert s["aave_all"] == pytest.approx(a_all)
    assert s["aave"] == pytest.approx(np.mean(a_all))
    assert s["aave_std"] == pytest.approx(np.std(a_all))
    assert s["per_vehicle"]["max_abs_velocity_error"] == [0.0, 1.0, 0.0]
    ms = s["per_vehicle"]["min_spacing"]
    assert len(ms) == 3 and np.isnan(ms[0])


def test_summary_skips_collided_scenarios_and_counts_them():
    v = np.full((3, 5, 3), 15.0)
    v[1, :, 1] = 17.0
    v[2, 3:] = np.nan  # scenario 2 collided at sample 2: NaN afterwards
    r = make_result(v, n=1)
    r.collided[2, 1] = True
    s = summary(r, MetricsConfig(window=(0.0, 2.0)))
    assert np.isnan(s["aave_all"][2])
    assert s["aave"] == pytest.approx(np.mean(s["aave_all"][:2]))
    assert s["scenarios_with_collision"] == 1 and s["collisions"] == 1
    r.collided[:, 1] = True
    r.velocity[:] = np.nan
    s = summary(r, MetricsConfig(window=(0.0, 2.0)))
    assert np.isnan(s["aave"]) and s["scenarios_with_collision"] == 3
