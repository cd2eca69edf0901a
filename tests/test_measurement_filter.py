"""The measurement filter of static gains (``measurement_filter``): a first-order low-pass
``tau dy_f/dt = y - y_f`` on every received spacing and velocity the law reads, discretised
exactly at the controller's sample time.

Truths: the closed-form step response ``y_f(t) = y1 + (y0 - y1) exp(-(t - t1) / tau)`` of the
continuous filter sampled at the controller's samples (exact for a held input), the compiled
loop against the Python ``__call__`` path, lower CAV jerk on a noisy run, and Table II and
Section V-A unchanged bit for bit (the filter is off by default)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from lcc_synth.controllers.registry import build_controller
from lcc_synth.controllers.static import StaticGainController
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.spec import load_spec
from lcc_synth.metrics import max_jerk_1s, rms_jerk
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import model_from_hdv
from lcc_synth.problem import System
from lcc_synth.simulation.engine import simulate
from lcc_synth.simulation.perturbations import Profile
from lcc_synth.simulation.scenario import V2V, Scenario

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"
H2_CF = {"s_0": 0.283, "v_0": -2.633, "s_1": -1.401, "v_1": -0.0096, "s_2": -1.246, "v_2": 0.081}


def static(gains, n=2, semantics="replace", cls=StaticGainController, **kw):
    model = model_from_hdv("cf_lcc", 0, n, OVM(), 15.0, warn=False)
    return cls("g", Gains.named(gains, semantics), model, **kw)


class Slow(StaticGainController):
    linear_law = None  # hide the compiled law: the Python __call__ path


@pytest.mark.parametrize("tau, sample_time", [(0.3, None), (1.0, None), (0.5, 0.1)])
@pytest.mark.parametrize("cls", [StaticGainController, Slow], ids=["compiled", "python"])
def test_step_response_is_the_sampled_continuous_one(tau, sample_time, cls):
    """HDV 1 (behind the CAV) steps from 15 to 14 m/s at t = 5 s; a gain 1 on its velocity
    only: u = y_f - 15, the filtered received velocity, which must be 15 before the first
    sample that receives 14 m/s (t1) and 14 + exp(-(t - t1) / tau) from then on."""
    prof = Profile((5.0, 60.0), (14.0, 14.0), "speed", "step", vehicle=1)
    sc = Scenario(m=0, n=2, dt=0.01, duration=12.0, a_min=-1000.0, cav_aeb=False,
                  perturbations=(prof,))  # fmt: skip
    r = simulate(sc, static({"v_1": 1.0}, cls=cls, sample_time=sample_time,
                            measurement_filter=tau))  # fmt: skip
    v1 = r.velocity[0, :, 2]
    k1 = int(np.flatnonzero(v1 < 14.5)[0])  # first sample at 14 m/s
    ratio = 1 if sample_time is None else int(round(sample_time / sc.dt))
    ks = np.arange(0, len(r.t), ratio)  # controller samples
    t1 = r.t[ks[ks >= k1][0]]
    y_f = 15.0 + r.u_cmd[0, ks]
    expected = np.where(r.t[ks] <= t1, 15.0, 14.0 + np.exp(-(r.t[ks] - t1) / tau))
    np.testing.assert_allclose(y_f, expected, rtol=0, atol=1e-9)
    off = simulate(sc, static({"v_1": 1.0}, cls=cls, sample_time=sample_time))
    assert off.u_cmd[0, ks[ks >= k1][0]] == pytest.approx(-1.0)  # unfiltered: the step itself


def noisy_scenario(**kw):
    """The CAV among HDVs behind it, the head braking, V2V noise as the showcase's."""
    prof = Profile((10.0, 12.0, 20.0, 25.0), (-5.0, 0.0, 2.0, 0.0), "accel", "step")
    v2v = V2V(loss_rate=0.2, latency=0.1, spacing_noise=0.1, velocity_noise=0.05)
    return Scenario(m=0, n=4, dt=0.01, duration=40.0, v2v=v2v, perturbations=(prof,), **kw)


def test_compiled_law_equals_python_call_with_the_filter():
    sc = noisy_scenario()
    kw = dict(n=4, sample_time=0.05, equilibrium="estimated", equilibrium_tau=1.0,
              measurement_filter=0.3)  # fmt: skip
    a, b = simulate(sc, static(H2_CF, **kw)), simulate(sc, static(H2_CF, cls=Slow, **kw))
    np.testing.assert_allclose(a.velocity, b.velocity, rtol=0, atol=1e-10)
    np.testing.assert_allclose(a.u_cmd, b.u_cmd, rtol=0, atol=1e-10)
    kw["measurement_filter"] = 0.0
    assert np.abs(simulate(sc, static(H2_CF, **kw)).u_cmd - a.u_cmd).max() > 1e-2


def test_filtered_noisy_run_has_lower_jerk():
    sc = noisy_scenario()
    kw = dict(n=4, equilibrium="estimated", equilibrium_tau=1.0)
    raw = simulate(sc, static(H2_CF, **kw))
    filt = simulate(sc, static(H2_CF, measurement_filter=0.3, **kw))
    assert rms_jerk(filt)[0] < 0.2 * rms_jerk(raw)[0]  # the noise, applied every 0.01 s
    assert max_jerk_1s(filt)[0] < max_jerk_1s(raw)[0]
    assert not filt.collided.any() and not filt.aeb_active.any()


def test_off_by_default_and_validated():
    system = System(kind="cf_lcc", m=0, n=2, v_star=15.0, hdv=OVM())
    table = {"type": "static", "gains": {"s_0": 0.1, "v_0": -0.5}}
    c = build_controller("g", table, system)
    assert c.measurement_filter == 0.0 and c.linear_law(_ctx()).measurement_filter == 0.0
    assert c.describe()["measurement_filter"] == 0.0
    c = build_controller("g", {**table, "measurement_filter": 0.25}, system)
    assert c.linear_law(_ctx()).measurement_decay(0.01) == pytest.approx(np.exp(-0.04))
    for bad in (-0.1, float("inf"), "0.2", True):
        with pytest.raises(ConfigError) as err:
            build_controller("g", {**table, "measurement_filter": bad}, system)
        assert err.value.field == "controllers.g.measurement_filter"


def _ctx():
    from lcc_synth.controllers.base import ControlContext

    return ControlContext(0, 2, 1, 0.01, np.array([15.0]), np.array([20.0]), -5.0, 2.0, OVM())


#: sha256 (first 16 hex digits) of every trajectory of Table II and Section V-A, and their AAVE
#: and fuel, as computed before the measurement filter existed (commit 90afcf4).
UNCHANGED = {
    ("paper_table2.toml", "all_hdv"): ("ce737b1813ad5fa5", 0.8927866884756681, 392.8567713124266),
    ("paper_table2.toml", "fd_lcc"): ("9a8cc26c62fc4f3b", 0.5805352527771985, 321.9393449756827),
    ("paper_table2.toml", "cf_lcc"): ("d43dafbf1cd35e65", 0.8128612039753581, 340.5611818348631),
    ("paper_sec5a.toml", "hdv_only"): ("e4f2603e4b0f453b", 0.08468470138668964, 146.83159779134925),
    ("paper_sec5a.toml", "case_a"): ("0a15a1c101a6fd8f", 0.07865210492402509, 146.78316229953805),
    ("paper_sec5a.toml", "case_b"): ("8bf672286cdc488e", 0.07101507816472294, 146.72860386492388),
    ("paper_sec5a.toml", "case_c"): ("89b1cea692e1add3", 0.052465027057186676, 146.6395515334448),
    ("paper_sec5a.toml", "case_d"): ("b2d60fb1074ed299", 0.04225463982867353, 146.61991316681627),
}


@pytest.mark.parametrize("problem", ["paper_table2.toml", "paper_sec5a.toml"])
def test_table2_and_sec5a_unchanged_bit_for_bit(problem):
    from lcc_synth.metrics import summary

    spec = load_spec(PROBLEMS / problem)
    draws = spec.scenario.draw()
    for name, ctrl in spec.controllers.items():
        assert getattr(ctrl, "measurement_filter", 0.0) == 0.0
        r = simulate(spec.scenario, ctrl, draws)
        h = hashlib.sha256()
        for k in ("position", "velocity", "acceleration", "spacing", "u_cmd", "aeb_active"):
            h.update(np.ascontiguousarray(getattr(r, k)).tobytes())
        s = summary(r, spec.metrics)
        assert (h.hexdigest()[:16], s["aave"], s["fuel_ml"]) == UNCHANGED[(problem, name)], name
