"""ISO 15622's 1 s average jerk of the CAV against closed forms (no simulation involved)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from test_metrics import make_result

from lcc_synth.metrics import (
    iso15622_jerk_limit,
    jerk_1s,
    jerk_limit_margin,
    jerk_limit_violation_time,
    max_jerk_1s,
    summary,
)

DT = 0.01


def _cav_result(a_cav, v_cav=15.0, aeb=None):
    """A CF-LCC string (head, CAV, 2 HDVs) whose CAV has acceleration ``a_cav`` at DT."""
    a_cav = np.asarray(a_cav, dtype=float)
    T = a_cav.size
    v = np.full((1, T, 4), 15.0)
    v[0, :, 1] = v_cav
    a = np.zeros((1, T, 4))
    a[0, :, 1] = a_cav
    return make_result(v, a, dt=DT, aeb=None if aeb is None else aeb[None])


def test_iso_limit_interpolates_linearly_in_speed():
    v = [0.0, 5.0, 8.0, 12.5, 20.0, 35.0, np.nan]
    expected = [5.0, 5.0, 4.5, 3.75, 2.5, 2.5, np.nan]
    np.testing.assert_allclose(iso15622_jerk_limit(v), expected, rtol=0, atol=1e-12)


def test_sine_acceleration_closed_form():
    # a = A sin(w t): (a(t) - a(t - 1)) / 1 s = 2 A sin(w / 2) cos(w (t - 1/2))
    A, w = 1.5, 2.0
    t = DT * np.arange(6001)
    r = _cav_result(A * np.sin(w * t))
    j = jerk_1s(r)[0]
    assert np.isnan(j[:100]).all()  # the first second has no full window
    expected = 2 * A * np.sin(w / 2) * np.cos(w * (t[100:] - 0.5))
    np.testing.assert_allclose(j[100:], expected, rtol=0, atol=1e-12)
    peak = 2 * A * np.sin(w / 2)  # reached: 60 s hold ~19 periods
    assert max_jerk_1s(r)[0] == pytest.approx(peak, abs=1e-6 * peak)
    # at 15 m/s the limit is 10/3 m/s^3
    assert jerk_limit_margin(r)[0] == pytest.approx(10 / 3 - peak, abs=1e-6)
    assert jerk_limit_violation_time(r)[0] == 0.0


def test_ramp_closed_form_and_time_over_the_limit():
    # a ramps at c = 4 m/s^3 from t1 = 10 s for D = 1.5 s, then holds; the CAV at 12.5 m/s
    # (limit 3.75). j1(t) = c * overlap([t - 1, t], [t1, t1 + D]): c on [t1 + 1, t1 + D],
    # above the limit where the overlap exceeds 3.75 / 4, for D + 1 - 2 * 3.75 / 4 s.
    c, t1, D = 4.0, 10.0, 1.5
    t = DT * np.arange(3001)
    a = c * np.clip(t - t1, 0.0, D)
    r = _cav_result(a, v_cav=12.5)
    j = jerk_1s(r)[0]
    overlap = np.clip(np.minimum(t, t1 + D) - np.maximum(t - 1.0, t1), 0.0, None)
    np.testing.assert_allclose(j[100:], c * overlap[100:], rtol=0, atol=1e-9)
    assert max_jerk_1s(r)[0] == pytest.approx(c)
    assert jerk_limit_margin(r)[0] == pytest.approx(3.75 - c)
    over = D + 1.0 - 2 * 3.75 / c
    assert jerk_limit_violation_time(r)[0] == pytest.approx(over, abs=DT)


def test_emergency_braking_and_the_second_after_it_are_excluded():
    t = DT * np.arange(2001)
    a = np.where(t >= 5.0 - 1e-9, -5.0, 0.0)  # a step: j1 = -5 m/s^3 during 5 <= t < 6
    aeb = np.abs(t - 5.0) < 1e-9  # ... that emergency braking made, at t = 5 s only
    assert max_jerk_1s(_cav_result(a))[0] == pytest.approx(5.0)
    r = _cav_result(a, aeb=aeb)
    j = jerk_1s(r)[0]
    excluded = np.isnan(j) & (t >= 1.0)
    np.testing.assert_array_equal(t[excluded], t[(t >= 5.0 - 1e-9) & (t <= 6.0 + 1e-9)])
    assert max_jerk_1s(r)[0] == 0.0
    assert jerk_limit_violation_time(r)[0] == 0.0


def test_undefined_rows_are_nan_without_warnings():
    r = _cav_result(np.full(500, np.nan))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isnan(max_jerk_1s(r)[0]) and np.isnan(jerk_limit_margin(r)[0])
        assert jerk_limit_violation_time(r)[0] == 0.0


def test_summary_reports_the_worst_scenario():
    t = DT * np.arange(4001)
    r1 = _cav_result(np.sin(t))
    r2 = _cav_result(3.0 * np.sin(t))
    both = make_result(np.concatenate([r1.velocity, r2.velocity]),
                       np.concatenate([r1.acceleration, r2.acceleration]), dt=DT)  # fmt: skip
    s = summary(both)
    assert s["max_jerk_1s_cav"] == pytest.approx(max_jerk_1s(r2)[0])
    assert s["jerk_1s_margin_cav"] == pytest.approx(jerk_limit_margin(r2)[0])
    assert s["jerk_1s_over_limit_s"] == pytest.approx(jerk_limit_violation_time(r2)[0])
