"""The field's baseline controllers (lcc_synth.controllers.baselines) against their published
equations, evaluated by hand at chosen gaps and speeds, and at every region boundary."""

from __future__ import annotations

import numpy as np
import pytest

from lcc_synth.controllers.base import ControlContext, Observation
from lcc_synth.controllers.baselines import (
    ACCParams,
    BaselineController,
    CACCParams,
    FollowerStopperParams,
    PISaturationParams,
    acc_accel,
    cacc_step,
    follower_stopper_velocity,
    pi_saturation_step,
)
from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import OVM


def test_follower_stopper_regions_by_hand():
    # U = 10, v = 8, v_lead = 6: dv- = -2, boundaries 4.5 + 4/3, 5.25 + 2, 6 + 4; w = 6
    x1, x2, x3 = 4.5 + 4 / 3, 7.25, 10.0
    cmd = follower_stopper_velocity(np.array([5.0, 6.5, 8.0, 12.0]), 8.0, 6.0, 10.0)
    expect = [0.0, 6 * (6.5 - x1) / (x2 - x1), 6 + 4 * (8 - x2) / (x3 - x2), 10.0]
    assert cmd == pytest.approx(expect, rel=1e-15)
    # continuous at every boundary: 0 at dx_1, w at dx_2, U at dx_3
    at = follower_stopper_velocity(np.array([x1, x2, x3]), 8.0, 6.0, 10.0)
    assert at == pytest.approx([0.0, 6.0, 10.0], abs=1e-12)
    # approaching from above is continuous too
    eps = 1e-9
    above = follower_stopper_velocity(np.array([x1, x2, x3]) + eps, 8.0, 6.0, 10.0)
    assert above == pytest.approx([0.0, 6.0, 10.0], abs=1e-6)
    # a faster leader: dv- = 0, boundaries the offsets; w = min(v_lead, U)
    assert follower_stopper_velocity(5.25, 5.0, 12.0, 10.0) == pytest.approx(10.0)
    assert follower_stopper_velocity(4.875, 5.0, 12.0, 10.0) == pytest.approx(5.0)


def test_pi_saturation_by_hand():
    p = PISaturationParams()
    # dx = 20: v_target = U + 13/23, dx_s = 4, alpha = 1, beta = 1/2
    got = pi_saturation_step(20.0, 10.0, 11.0, 10.5, 10.0, p)
    assert got == pytest.approx(0.5 * (10.5 + 13 / 23) + 0.5 * 10.0, rel=1e-15)
    # dx = 5: below g_l (v_target = U), alpha = 1/2, beta = 3/4
    got = pi_saturation_step(5.0, 10.0, 11.0, 10.5, 10.0, p)
    assert got == pytest.approx(0.75 * (0.5 * 10.5 + 0.5 * 11.0) + 0.25 * 10.0, rel=1e-15)
    # closing fast: dx_s = 2 (v_lead - v) = 12 > dx: alpha = 0, beta = 1: follow the leader
    assert pi_saturation_step(10.0, 4.0, 10.0, 8.0, 3.0, p) == pytest.approx(10.0)
    # above g_u the catch-up saturates at v_catch
    got = pi_saturation_step(40.0, 10.0, 10.0, 10.0, 10.0, p)
    assert got == pytest.approx(0.5 * 11.0 + 0.5 * 10.0)


def test_acc_and_cacc_by_hand():
    assert acc_accel(30.0, 20.0, 19.0, ACCParams()) == pytest.approx(0.23 * 6 - 0.07)
    p = CACCParams()
    # e = 20 - 2 - 0.7 * 15 = 7.5, de = 1 - 0.7 * 0.3 = 0.79
    got = cacc_step(0.5, 20.0, 15.0, 16.0, 0.3, 0.2, 0.1, p)
    assert got == pytest.approx(0.5 + 0.1 / 0.7 * (-0.5 + 0.2 * 7.5 + 0.7 * 0.79 + 0.2))


def _ctx(batch=1, m=0, n=2):
    return ControlContext(m, n, batch, 0.1, np.full(batch, 15.0), np.full(batch, 20.0),
                          -5.0, 2.0, OVM())  # fmt: skip


def test_velocity_commands_are_tracked_within_one_period_and_clipped():
    c = BaselineController("fs", "follower_stopper", FollowerStopperParams(U=10.0), 0.1)
    c.reset(_ctx())
    # column 1 is the CAV, column 0 the vehicle ahead; gap 8 m, v = 8, v_lead = 6
    obs = Observation(0.0, np.array([[np.nan, 8.0, 20.0, 20.0]]),
                      np.array([[6.0, 8.0, 8.0, 8.0]]), np.zeros((1, 4)))  # fmt: skip
    v_cmd = follower_stopper_velocity(8.0, 8.0, 6.0, 10.0)
    a = c(obs)
    assert a.shape == (1,)
    assert a[0] == pytest.approx(np.clip((v_cmd - 8.0) / 0.1, -5.0, 2.0))
    # PI: U starts at the AV's speed; a steady follower at 15 m/s with a long gap catches up
    pi = BaselineController("pi", "pi_saturation", PISaturationParams(), 0.5)
    pi.reset(_ctx())
    obs = Observation(0.0, np.array([[np.nan, 40.0, 20.0, 20.0]]),
                      np.full((1, 4), 15.0), np.zeros((1, 4)))  # fmt: skip
    a = pi(obs)
    assert a[0] == pytest.approx((0.5 * 16.0 + 0.5 * 15.0 - 15.0) / 0.5)  # 1 m/s², unclipped


@pytest.mark.parametrize(
    ("kind", "params", "field"),
    [
        ("follower_stopper", dict(U=-1.0), "U"),
        ("follower_stopper", dict(U=5.0, dx0=(5.0, 4.0, 6.0)), "dx0"),
        ("acc", dict(h=0.0), "h"),
        ("acc", dict(h=-1.0), "h"),
        ("cacc", dict(h=0.0), "h"),
        ("pi_saturation", dict(g_u=5.0), "g_u"),
        ("pi_saturation", dict(window=0.0), "window"),
    ],
)
def test_bad_parameters_name_the_field(kind, params, field):
    from lcc_synth.controllers.baselines import BASELINE_TYPES

    with pytest.raises(ConfigError) as err:
        BASELINE_TYPES[kind](**params)
    assert err.value.field == field


def test_problem_file_baselines_run_in_the_simulator_within_the_limits(tmp_path):
    """Every baseline type builds from a problem file and runs the head-brake scenario: the
    applied CAV acceleration stays in the limits, nothing collides, and FollowerStopper never
    lets the gap fall below its first boundary's offset (it commands 0 m/s there)."""
    from pathlib import Path

    import numpy as np

    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.simulation.engine import simulate_many

    text = (Path(__file__).parents[1] / "problems" / "mpc_head_brake.toml").read_text()
    text = text[: text.index("# Looking ahead only")] + "".join(
        f'[controllers.{k}]\ntype = "{k}"\n{extra}\n'
        for k, extra in (("follower_stopper", "U = 15.0"), ("pi_saturation", ""), ("acc", ""),
                         ("cacc", "sample_time = 0.1"))
    )  # fmt: skip
    (tmp_path / "b.toml").write_text(text)
    spec = load_spec(tmp_path / "b.toml")
    res = simulate_many(spec.scenario, spec.controllers)
    for name, r in res.items():
        a = r.acceleration[0, :, r.cav]
        assert np.nanmin(a) >= -5.0 - 1e-12 and np.nanmax(a) <= 2.0 + 1e-12, name
        assert not r.collided.any(), name
    fs = res["follower_stopper"]
    assert np.nanmin(fs.spacing[0, :, fs.cav]) >= 4.5
