"""Static gains with ``equilibrium = "estimated"``: errors from a low-pass estimate of the
equilibrium velocity (the velocity of the vehicle ahead of the CAV) instead of the fixed v*.

Truths: the fixed run when the vehicle ahead cruises at v* (bit for bit), the closed-form step
response ``1 - exp(-t / tau)`` of a first-order low-pass, the nominal model's equilibrium
spacing, and the showcase head brake where the fixed v* needs emergency braking. The compiled
loop and the Python ``__call__`` path agree: tests/test_simulation.py
(``test_compiled_law_equals_python_call_under_v2v_effects``)."""

from __future__ import annotations

import copy
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lcc_synth.cli.main import main
from lcc_synth.controllers.registry import build_controller
from lcc_synth.controllers.static import StaticGainController
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.spec import load_spec
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import IDM, OVM
from lcc_synth.models.linear import model_from_hdv
from lcc_synth.problem import System, load_problem
from lcc_synth.simulation.engine import simulate
from lcc_synth.simulation.perturbations import Profile
from lcc_synth.simulation.scenario import Scenario

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"
PAPER_CF = {"s_0": 0.1, "v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}


def static(gains, kind="cf_lcc", m=0, n=10, semantics="replace", hdv=None, **kw):
    model = model_from_hdv(kind, m, n, hdv or OVM(), 15.0, warn=False)
    return StaticGainController("g", Gains.named(gains, semantics), model, **kw)


class Slow(StaticGainController):
    linear_law = None  # hide the compiled law: the Python __call__ path


def test_constant_head_gives_the_fixed_run_bit_for_bit():
    """Table II (vehicle 1 brakes, the head cruises at exactly v*): the estimate never moves,
    so the whole run and the Table II metrics are those of the fixed v*, in both paths."""
    spec = load_spec(PROBLEMS / "paper_table2.toml")
    sc = spec.scenario
    fixed = simulate(sc, static(PAPER_CF))
    est = simulate(sc, static(PAPER_CF, equilibrium="estimated", equilibrium_tau=1.0))
    for key in ("position", "velocity", "acceleration", "spacing", "u_cmd"):
        np.testing.assert_array_equal(getattr(est, key), getattr(fixed, key), err_msg=key)
    assert np.abs(fixed.u_cmd).max() > 0.5  # the brake behind the CAV does excite the gain
    # the Python path too (it sums in another order than the compiled loop: compared with
    # its own fixed run)
    gains = Gains.named(PAPER_CF, "replace")
    slow_fixed = simulate(sc, Slow("g", gains, est_model()))
    slow = simulate(sc, Slow("g", gains, est_model(), equilibrium="estimated"))
    np.testing.assert_array_equal(slow.u_cmd, slow_fixed.u_cmd)
    np.testing.assert_array_equal(slow.velocity, slow_fixed.velocity)


def est_model():
    return model_from_hdv("cf_lcc", 0, 10, OVM(), 15.0, warn=False)


def step_scenario(**kw):
    """The head steps from 15 to 10 m/s at t = 5 s (limits wide enough for a one-step jump)."""
    prof = Profile((5.0, 60.0), (10.0, 10.0), "speed", "step")
    return Scenario(m=0, n=2, dt=0.01, duration=12.0, a_min=-1000.0, cav_aeb=False,
                    perturbations=(prof,), **kw)  # fmt: skip


@pytest.mark.parametrize("tau, sample_time", [(1.0, None), (0.5, None), (2.0, 0.1)])
def test_estimate_converges_with_time_constant_tau(tau, sample_time):
    """Gain k on the CAV's own (exact) velocity only: u = k (v_0 - v_hat), so the command gives
    the estimate, which must follow 10 + 5 exp(-(t - t1) / tau) after the head's step at t1."""
    sc = step_scenario()
    k = -1.0
    r = simulate(sc, static({"v_0": k}, n=2, sample_time=sample_time,
                            equilibrium="estimated", equilibrium_tau=tau))  # fmt: skip
    vh = r.velocity[0, :, 0]
    k1 = int(np.flatnonzero(vh < 14.0)[0])
    assert vh[k1] == pytest.approx(10.0, abs=1e-9) and np.all(np.abs(vh[k1:] - 10.0) < 1e-9)
    ratio = 1 if sample_time is None else int(round(sample_time / sc.dt))
    ks = np.arange(0, len(r.t), ratio)  # controller samples
    v_hat = r.velocity[0, ks, 1] - r.u_cmd[0, ks] / k
    t1 = r.t[int(math.ceil(k1 / ratio)) * ratio]  # first sample that measures the new speed
    expected = np.where(r.t[ks] <= t1, 15.0, 10.0 + 5.0 * np.exp(-(r.t[ks] - t1) / tau))
    np.testing.assert_allclose(v_hat, expected, atol=1e-9)
    # after one tau the estimate has covered 1 - 1/e of the step
    i = np.argmin(np.abs(r.t[ks] - (t1 + tau)))
    assert (15.0 - v_hat[i]) / 5.0 == pytest.approx(1.0 - math.exp(-1.0), abs=1e-9)


@pytest.mark.parametrize("hdv", [OVM(), IDM()], ids=["ovm", "idm"])
def test_spacing_reference_moves_with_the_equilibrium_spacing(hdv):
    """Gain g on the CAV's own spacing only: u = g (s_0 - s_e(v_hat)), s_e the nominal model's
    equilibrium spacing (hdv.equilibrium_spacing), v_hat from the velocity run."""
    sc = replace(step_scenario(), hdv=hdv)
    kw = dict(n=2, hdv=hdv, equilibrium="estimated", equilibrium_tau=1.0)
    rv = simulate(sc, static({"v_0": -1.0}, **kw))
    v_hat = rv.velocity[0, :, 1] + rv.u_cmd[0]
    rs = simulate(sc, static({"s_0": 0.3}, **kw))
    expected = 0.3 * (rs.spacing[0, :, 1] - hdv.equilibrium_spacing(v_hat))
    np.testing.assert_allclose(rs.u_cmd[0], expected, atol=1e-9)
    assert hdv.equilibrium_spacing(v_hat[-1]) < sc.s_star - 3.0  # the reference did move


def test_estimate_is_clipped_into_the_models_range():
    """The head stops (15 -> 0 m/s at -5 m/s^2): v_hat -> 0, clipped at 1 % of v_max (s_e
    stays defined). The CAV keeps its HDV law (``added``) so that it stops safely too:
    u = F_hdv + k (v_0 - v_hat), F_hdv recomputed from the recorded (ideal-link) state."""
    prof = Profile((2.0, 5.0, 60.0), (15.0, 0.0, 0.0), "speed", "linear")
    sc = Scenario(m=0, n=2, dt=0.01, duration=20.0, hdv_aeb=True, perturbations=(prof,))
    k = -0.2
    r = simulate(sc, static({"v_0": k}, n=2, semantics="added", equilibrium="estimated",
                            equilibrium_tau=1.0))  # fmt: skip
    assert not r.collided.any() and r.velocity[0, -1, 0] == 0.0
    s, v = r.spacing[0], r.velocity[0]
    f_hdv = OVM().accel(s[:, 1], v[:, 0] - v[:, 1], v[:, 1])
    v_hat = v[:, 1] - (r.u_cmd[0] - f_hdv) / k
    assert v_hat[-1] == pytest.approx(0.01 * OVM().v_max, abs=1e-9)
    assert np.isfinite(r.u_cmd).all()


@pytest.fixture(scope="module")
def showcase_brake():
    """paper and h2 on the showcase head brake, with the file's estimate and with a fixed v*."""
    from lcc_synth.experiments.comparison import load_suite, run_suite
    from lcc_synth.problem import Problem

    base = load_problem(PROBLEMS / "showcase.toml")
    out = {}
    for eq in ("estimated", "fixed"):
        data = copy.deepcopy(base.data)
        for c in ("paper", "h2"):
            over = data["controllers"][c]["layouts"]["string10"]
            assert over["equilibrium"] == "estimated"  # what the showcase runs
            if eq == "fixed":
                over.pop("equilibrium"), over.pop("equilibrium_tau", None)
        suite = load_suite(Problem(base.path, data), ["head_brake", "heterogeneous"],
                           ["paper", "h2"])  # fmt: skip
        out[eq] = run_suite(suite, progress=False).table
    return out


def test_showcase_head_brake_needs_no_emergency_braking_with_the_estimate(showcase_brake):
    est, fixed = showcase_brake["estimated"], showcase_brake["fixed"]
    for scen in ("head_brake", "heterogeneous"):
        # the fixed v*: both gains close in on the vehicle ahead, held only by AEB
        for c in ("paper", "h2"):
            assert fixed[scen][c]["aeb_activations"] > 200 and fixed[scen][c]["min_spacing"] < 0.5
        # the estimate: the H2 gain needs no AEB, keeps > 5 m and commands a feasible accel
        h2 = est[scen]["h2"]
        assert h2["aeb_activations"] == 0 and h2["min_spacing"] > 5.0, h2
        assert h2["max_abs_command"] < 6.0 and h2["collisions"] == 0
        # the paper's soft gains (0.1 on the own gap, no relative-speed term) still lag the
        # -5 m/s^2 brake: far less AEB than with the fixed v*, but not none (see showcase.toml)
        p, pf = est[scen]["paper"], fixed[scen]["paper"]
        assert p["collisions"] == 0 and p["min_spacing"] > 1.0
        assert p["aeb_activations"] < pf["aeb_activations"] / 4


# --------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------

SYSTEM = System("cf_lcc", 0, 2, 15.0, OVM())


def table(**kw):
    return {"type": "static", "kind": "cf_lcc", "gains": {"s_0": 0.1, "v_0": -0.5}, **kw}


@pytest.mark.parametrize(
    "extra, field",
    [
        ({"equilibrium": "moving"}, "controllers.g.equilibrium"),
        ({"equilibrium": 1}, "controllers.g.equilibrium"),
        ({"equilibrium": "estimated", "equilibrium_tau": 0.0}, "controllers.g.equilibrium_tau"),
        ({"equilibrium": "estimated", "equilibrium_tau": -1.0}, "controllers.g.equilibrium_tau"),
        ({"equilibrium": "estimated", "equilibrium_tau": "1"}, "controllers.g.equilibrium_tau"),
        ({"equilibrium": "estimated", "equilibrium_tau": True}, "controllers.g.equilibrium_tau"),
        ({"equilibrium": "estimated", "equilibrium_tau": float("inf")},
         "controllers.g.equilibrium_tau"),
        ({"equilibrium_tau": 1.0}, "controllers.g.equilibrium_tau"),  # without "estimated"
    ],
)
def test_bad_values_name_the_field(extra, field):
    with pytest.raises(ConfigError) as err:
        build_controller("g", table(**extra), SYSTEM)
    assert err.value.field == field


def test_fd_lcc_cannot_estimate_and_describe_reports_the_option(tmp_path):
    fd = {"type": "static", "kind": "fd_lcc", "gains": {"v_0": -0.5}, "equilibrium": "estimated"}
    with pytest.raises(ConfigError, match="vehicle ahead") as err:
        build_controller("g", fd, System("fd_lcc", 0, 2, 15.0, OVM()))
    assert err.value.field == "controllers.g.equilibrium"
    with pytest.raises(ConfigError) as err:
        static({"v_0": -0.5}, kind="fd_lcc", n=2, equilibrium="estimated")
    assert err.value.field == "equilibrium"
    c = build_controller("g", table(equilibrium="estimated"), SYSTEM)
    assert c.describe()["equilibrium"] == "estimated" and c.describe()["equilibrium_tau"] == 1.0
    d = build_controller("g", table(), SYSTEM).describe()
    assert d["equilibrium"] == "fixed" and "equilibrium_tau" not in d
    # gains files take the same keys
    path = tmp_path / "g.json"
    path.write_text('{"kind": "cf_lcc", "m": 0, "n": 2, "semantics": "replace", '
                    '"state_names": ["s_0", "v_0", "s_1", "v_1", "s_2", "v_2"], '
                    '"K": [0.1, -0.5, 0, 0, 0, 0], '  # a gains file's K is required
                    '"gains": {"s_0": 0.1, "v_0": -0.5}}')  # fmt: skip
    gf = {"type": "gains_file", "file": str(path), "equilibrium": "estimated",
          "equilibrium_tau": 2.5}  # fmt: skip
    assert build_controller("g", gf, SYSTEM).describe()["equilibrium_tau"] == 2.5
    with pytest.raises(ConfigError) as err:
        build_controller("g", {**gf, "equilibrium_tau": 0}, SYSTEM)
    assert err.value.field == "controllers.g.equilibrium_tau"


def test_cli_exits_2_naming_the_field(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(
        '[system]\nkind = "cf_lcc"\nm = 0\nn = 2\n[scenario]\nduration = 5.0\n'
        '[metrics]\nwindow = [0.0, 5.0]\n'
        '[controllers.g]\ntype = "static"\ngains = { s_0 = 0.1, v_0 = -0.5 }\n'
        'equilibrium = "estimated"\nequilibrium_tau = -2.0\n'
    )
    assert main(["simulate", str(bad), "--no-record"]) == 2
    err = capsys.readouterr().err
    assert "controllers.g.equilibrium_tau" in err and err.count("\n") == 1
    bad.write_text(bad.read_text().replace("equilibrium_tau = -2.0\n", ""))
    assert main(["simulate", str(bad), "--no-record"]) == 0
