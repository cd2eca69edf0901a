"""The MPC's exact active-set option (``solver.method = "daqp"``) against a second exact QP
solver (qpOASES, a primal active-set method, via CasADi), and the per-step shortcuts of
:mod:`lcc_synth.mpc.step_cache` / :func:`lcc_synth.mpc.comfort.jerk_bound` against the
expressions they replace, bit for bit."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest

from lcc_synth.errors import ConfigError
from lcc_synth.experiments.spec import load_spec
from lcc_synth.metrics import iso15622_jerk_limit
from lcc_synth.models.hdv import IDM, OVM
from lcc_synth.mpc import mpc_controller_from_table
from lcc_synth.mpc.active_set import DAQPSolver
from lcc_synth.mpc.comfort import jerk_bound
from lcc_synth.mpc.solver import OSQPSolver, solve_exact
from lcc_synth.mpc.step_cache import LastValue, clip
from lcc_synth.problem import load_problem
from lcc_synth.simulation.engine import simulate

BRAKE = Path(__file__).resolve().parents[1] / "problems" / "mpc_head_brake.toml"


def _controller(method: str, duration: float | None = None):
    spec = load_spec(BRAKE)
    table = copy.deepcopy(load_problem(BRAKE).data["controllers"]["mpc"])
    table["solver"] = {"method": method}
    ctrl = mpc_controller_from_table("mpc", table, spec.system)
    scenario = spec.scenario
    if duration is not None:
        from dataclasses import replace

        scenario = replace(scenario, duration=duration)
    return ctrl, scenario


def test_daqp_first_move_matches_an_exact_solution_on_constrained_steps():
    """The head-brake closed loop with DAQP: on every step whose exact optimum has an active
    input, spacing or comfort row, the applied first move equals qpOASES's to 1e-3 m/s^2
    (measured: 1e-9 or better); the steps of the brake are constrained."""
    ctrl, scenario = _controller("daqp", duration=30.0)
    qps = []
    orig = ctrl.formulation.bounds

    def rec(*a, **k):
        out = orig(*a, **k)
        qps.append(out)
        return out

    ctrl.formulation.bounds = rec
    simulate(scenario, ctrl)
    h = ctrl.history()
    assert set(h["status"].ravel()) == {0}  # every step solved by the QP
    assert isinstance(ctrl._members[0].solver, DAQPSolver)
    qp = ctrl._members[0].qp
    form = ctrl.formulation
    N, F = form.N, len(ctrl._families)
    rows = np.r_[0:N + F * N, N + 2 * F * N:form.nc]  # without the slack rows e >= 0
    A = qp.A.toarray()
    u_model = h["u_model"].ravel()
    constrained = 0
    for k in range(200, 300):  # t = 20 .. 30 s: the brake and the hold
        q, lo, hi = qps[k + 1]  # qps[0]: the set-up call of reset()
        if not np.isfinite(hi[form.jerk_rows][0]):
            continue
        z = solve_exact(qp, q, lo, hi, "qpoases")
        Az = A @ z
        scale = 1e-7 * (1.0 + np.abs(Az))
        active = (np.abs(Az - lo) < scale) | (np.abs(Az - hi) < scale)
        if not active[rows].any():
            continue
        constrained += 1
        assert abs(u_model[k] - z[0]) <= 1e-3, (k, u_model[k], z[0])
    assert constrained >= 10


def test_daqp_and_osqp_solve_the_same_qp():
    """One constrained QP of the brake: DAQP's and OSQP's solutions agree with qpOASES's."""
    ctrl, scenario = _controller("osqp", duration=22.5)
    qps = []
    orig = ctrl.formulation.bounds
    ctrl.formulation.bounds = lambda *a, **k: qps.append(orig(*a, **k)) or qps[-1]
    simulate(scenario, ctrl)
    qp = ctrl._members[0].qp
    settings = ctrl.settings.solver
    q, lo, hi = qps[-1]
    exact = solve_exact(qp, q, lo, hi, "qpoases")
    for cls in (OSQPSolver, DAQPSolver):
        res = cls(qp, q, lo, hi, settings).solve(q, lo, hi)
        assert res.ok and res.status == "solved"
        assert np.max(np.abs(res.z[: ctrl.formulation.N] - exact[: ctrl.formulation.N])) < 1e-4


def test_solver_method_is_validated_and_described():
    spec = load_spec(BRAKE)
    table = copy.deepcopy(load_problem(BRAKE).data["controllers"]["mpc"])
    table["solver"] = {"method": "qpoases"}
    with pytest.raises(ConfigError) as err:
        mpc_controller_from_table("mpc", table, spec.system)
    assert "solver.method" in err.value.field
    ctrl, _ = _controller("daqp")
    d = ctrl.describe()
    assert d["solver"]["name"] == "daqp" and d["qp"]["solver"].startswith("daqp ")
    ctrl, _ = _controller("osqp")
    assert ctrl.describe()["solver"]["name"] == "osqp"


def test_daqp_forced_failure_is_reported():
    ctrl, scenario = _controller("daqp", duration=21.0)
    simulate(scenario, ctrl)  # set up the members
    ctrl._members[0].solver.force_failure = True
    res = ctrl._members[0].solver.solve(*ctrl.formulation.bounds(
        ctrl._members[0].qp, ctrl.formulation.param(np.zeros(22), np.zeros(50), 0.0),
        -5.0, 2.0, np.full((1, 50), -np.inf)))
    assert not res.ok and res.status == "forced_failure"


def test_clip_is_numpy_clip_bit_for_bit():
    rng = np.random.default_rng(3)
    values = [*rng.normal(0.0, 20.0, 500), 1.0, 29.0, -0.0, 0.0, math.nan, math.inf, -math.inf]
    for lo, hi in ((1.0, 29.0), (-5.0, 2.0), (0.0, 0.0)):
        for v in values:
            want = float(np.clip(v, lo, hi))
            got = clip(v, lo, hi)
            assert (math.isnan(want) and math.isnan(got)) or (
                got == want and math.copysign(1.0, got) == math.copysign(1.0, want)), (v, lo, hi)


def test_moving_average_is_numpy_mean_bit_for_bit():
    """update_equilibrium's v_eq (sum, then one division) equals np.mean of the window bit for
    bit, through the window's start (filled with the first value) and its wrap-around."""
    from types import SimpleNamespace

    from lcc_synth.mpc.scaffold import update_equilibrium

    rng = np.random.default_rng(4)
    for W in (1, 3, 10, 30, 100):
        mem = SimpleNamespace(v_buf=np.zeros(W), v_buf_n=0, v_buf_i=0, v_eq=math.nan)
        for v in rng.normal(15.0, 5.0, 3 * W + 7) * 10.0 ** rng.uniform(-3, 3):
            update_equilibrium(mem, float(v))
            assert mem.v_eq == float(np.mean(mem.v_buf)), W
        update_equilibrium(mem, math.nan)  # not finite: v_eq unchanged
        assert mem.v_eq == float(np.mean(mem.v_buf))


def test_last_value_is_the_equilibrium_spacing():
    cache = LastValue()
    ovm, idm = OVM(), IDM()
    for hdv, v in ((ovm, 15.0), (ovm, 15.0), (ovm, 7.25), (idm, 7.25), (ovm, 7.25)):
        assert cache.get(hdv, v) == float(hdv.equilibrium_spacing(v))
    with pytest.raises(ConfigError):
        cache.get(ovm, math.nan)  # a NaN never hits the cache: the model's check raises


def test_jerk_bound_is_the_iso_limit_bit_for_bit():
    for v in (*np.linspace(-3.0, 30.0, 331), 5.0, 20.0, 12.5):
        for scale in (0.9, 1.0, 0.37):
            assert jerk_bound(scale, float(v)) == float(scale * iso15622_jerk_limit(max(v, 0.0)))
    assert jerk_bound(0.0, 10.0) == math.inf and jerk_bound(0.9, math.nan) == math.inf
