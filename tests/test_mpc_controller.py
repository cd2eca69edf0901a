"""The MPC controller: settings validation, the fallback chain, closed-loop constraint
satisfaction on the linear model, robustness to bad observations, reports."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lcc_synth.controllers.base import ControlContext, Observation
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.controller_tables import controller_from_table
from lcc_synth.models.feedback import Gains, cav_feedback
from lcc_synth.models.hdv import OVM
from lcc_synth.mpc import MPCController, mpc_controller_from_table
from lcc_synth.mpc.formulation import linearize
from lcc_synth.mpc.settings import MPCSettings
from lcc_synth.problem import System

HDV = OVM()
S_STAR = HDV.equilibrium_spacing(15.0)


def _system(kind="cf_lcc", m=0, n=3):
    return System(kind, m, n, 15.0, HDV)


def _ctx(m, n, batch=1):
    return ControlContext(
        m, n, batch, 0.1, np.full(batch, 15.0), np.full(batch, S_STAR), -5.0, 2.0, HDV
    )


def _obs(t, x, m, vh_err):
    """Observation of a string whose error state (model order) is ``x``."""
    nv = x.size // 2 + 1
    s = np.full(nv, np.nan)
    v = np.empty(nv)
    v[0] = 15.0 + vh_err
    s[1:] = S_STAR + x[0::2]
    v[1:] = 15.0 + x[1::2]
    p = np.concatenate([[0.0], -np.cumsum(s[1:])])
    return Observation(t, s[None], v[None], p[None])


# ------------------------------------------------------------------------------ settings


@pytest.mark.parametrize(
    "table,field",
    [
        ({"horizon": 0}, "controllers.mpc.horizon"),
        ({"horizon": -3}, "controllers.mpc.horizon"),
        ({"sample_time": 0.0}, "controllers.mpc.sample_time"),
        ({"constraints": {"a_min": 2.0, "a_max": 2.0}}, "controllers.mpc.constraints.a_min"),
        ({"constraints": {"a_min": 1.0, "a_max": 3.0}}, "controllers.mpc.constraints.a_min"),
        ({"weights": {"velocity": -1.0}}, "controllers.mpc.weights.velocity"),
        ({"weights": {"spacing": -0.1}}, "controllers.mpc.weights.spacing"),
        ({"weights": {"input": 0.0}}, "controllers.mpc.weights.input"),
        ({"weights": {"slack": -5.0}}, "controllers.mpc.weights.slack"),
        ({"weights": {"input_on": "both"}}, "controllers.mpc.weights.input_on"),
        ({"weights": {"velocty": 1.0}}, "controllers.mpc.weights.velocty"),
        ({"constraints": {"t_gap": -1.0}}, "controllers.mpc.constraints.t_gap"),
        ({"constraints": {"behind": [5]}}, "controllers.mpc.constraints.behind"),
        ({"constraints": {"behind": "1"}}, "controllers.mpc.constraints.behind"),
        ({"prediction": {"head": "psychic"}}, "controllers.mpc.prediction.head"),
        ({"prediction": {"equilibrium_window": 0.0}},
         "controllers.mpc.prediction.equilibrium_window"),
        ({"solver": {"eps_abs": 1e-2}}, "controllers.mpc.solver.eps_abs"),
        ({"solver": {"max_iter": 0}}, "controllers.mpc.solver.max_iter"),
        ({"n_model": 7}, "controllers.mpc.n_model"),
        ({"fallback_gains_file": "nope.json"}, "controllers.mpc.fallback_gains_file"),
        ({"horizn": 5}, "controllers.mpc.horizn"),
    ],
)
def test_bad_settings_are_config_errors_naming_the_field(table, field):
    with pytest.raises(ConfigError) as err:
        mpc_controller_from_table("mpc", {"type": "mpc", **table}, _system())
    assert err.value.field == field


def test_settings_dataclass_validates_directly():
    with pytest.raises(ConfigError, match="horizon"):
        MPCSettings(horizon=0)


def test_the_controllers_package_builds_no_mpc():
    """controllers.registry builds the types of its own package; an MPC table there is a
    ConfigError naming the type and the entry that builds it (the package imports no MPC)."""
    from lcc_synth.controllers.registry import build_controller

    with pytest.raises(ConfigError) as err:
        build_controller("mpc", {"type": "mpc"}, _system())
    assert err.value.field == "controllers.mpc.type"
    assert "controller_tables.controller_from_table" in err.value.message


def test_controller_from_table_makes_an_mpc(tmp_path):
    ctrl = controller_from_table("mpc", {"type": "mpc", "horizon": 10}, _system(),
                                 str(tmp_path / "p"))  # fmt: skip
    assert isinstance(ctrl, MPCController)
    assert ctrl.sample_time == 0.1
    desc = ctrl.describe()
    json.dumps(desc)
    assert desc["horizon"] == 10 and desc["type"] == "mpc" and desc["solver"]["name"] == "osqp"
    assert desc["qp"]["variables"] == 20  # 10 inputs + 10 slacks of the spacing constraint


def test_fallback_gains_file_relative_to_problem(tmp_path):
    gains = {"kind": "cf_lcc", "m": 0, "n": 3, "semantics": "replace",
             "state_names": [f"{q}_{i}" for i in range(4) for q in "sv"],
             "K": [0.0, -0.7, -0.1, 0.0, 0.0, 0.0, 0.0, 0.0],  # required (issue 28)
             "gains": {"v_0": -0.7, "s_1": -0.1}}
    (tmp_path / "g.json").write_text(json.dumps(gains))
    ctrl = mpc_controller_from_table(
        "mpc", {"type": "mpc", "fallback_gains_file": "g.json"}, _system(),
        source=str(tmp_path / "problem.toml"),
    )
    assert ctrl.describe()["fallback"]["gains"] == {"v_0": -0.7, "s_1": -0.1}
    bad = dict(gains, gains={"v_7": 1.0})
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    with pytest.raises(ConfigError) as err:
        mpc_controller_from_table(
            "mpc", {"type": "mpc", "fallback_gains_file": "bad.json"}, _system(),
            source=str(tmp_path / "problem.toml"),
        )
    assert err.value.field.startswith("controllers.mpc")


# ------------------------------------------------------------------------------ closed loop


def _linear_closed_loop(kind, n, head_accel, T=25.0, table=None, s_min=7.0, t_gap=1.0):
    """The discrete linear LCC model (exact ZOH at 0.1 s) driven by the MPC; the head vehicle
    follows ``head_accel(t)`` (not known to the MPC, which holds the head velocity).

    Returns the controller, the commands and ``s0 - (s_min + t_gap v0)`` at every sample. With
    the default bound (22 m at 15 m/s, above s* = 20 m) the constraint binds from the start.
    """
    tbl = {"type": "mpc", "horizon": 30, "prediction": {"equilibrium": "fixed"},
           "constraints": {"s_min": s_min, "t_gap": t_gap}}
    for key, value in (table or {}).items():
        tbl[key] = {**tbl.get(key, {}), **value}
    ctrl = mpc_controller_from_table("mpc", tbl, _system(kind, 0, n))
    lin = linearize(kind, 0, n, HDV, 15.0, ctrl.settings)
    ctrl.reset(_ctx(0, n))
    x = np.zeros(lin.model.nx)
    vh = 0.0
    cmds, rows = [], []
    for k in range(int(T / 0.1)):
        t = k * 0.1
        u = float(ctrl(_obs(t, x, 0, vh))[0])
        cmds.append(u)
        rows.append((S_STAR + x[0]) - (s_min + t_gap * (15.0 + x[1])))
        u_model = u - (float(lin.K_law @ x) + lin.k_h * vh)
        x = lin.Ad @ x + lin.Bd * u_model + lin.Hd * vh
        vh += 0.1 * head_accel(t)
    return ctrl, np.array(cmds), np.array(rows)


def _head_brake(t):
    return -5.0 if 8.0 <= t < 10.0 else 0.0


def test_closed_loop_linear_model_keeps_the_constraints():
    """The absolute bound s0 >= 7 + 1.0 v0 starts violated (22 m needed, 20 m held); the MPC
    opens the gap within 3 s and then keeps it at every sample, through a head brake at
    -5 m/s^2 for 2 s (15 -> 5 m/s) that it does not predict; its acceleration stays in
    [-5, 2] and the QP is solved at every step (no fallback)."""
    ctrl, u, rows = _linear_closed_loop("cf_lcc", 4, _head_brake)
    st = ctrl.stats()
    assert st["fallbacks"] == 0 and st["qp_failures"] == {}
    assert u.min() >= -5.0 - 1e-9 and u.max() <= 2.0 + 1e-9
    assert rows[0] == pytest.approx(-2.0)
    assert rows[30:].min() >= -1e-6
    assert st["slack_steps"] > 0  # the initial violation cannot vanish in one step


def test_without_the_constraint_the_same_loop_violates_it():
    """Control experiment for the test above: the bound is not met by the cost alone."""
    _, _, rows = _linear_closed_loop(
        "cf_lcc", 4, _head_brake, table={"constraints": {"spacing_ahead": False}}
    )
    assert rows[30:].min() < -1.0


# ------------------------------------------------------------------------------ fallbacks


def test_solver_failure_uses_the_static_gain_then_nothing_raises():
    """max_iter = 1: OSQP reports 'maximum iterations reached' every step; with no plan yet the
    paper's CF-LCC gain is applied (clipped), and every failure is counted."""
    ctrl = mpc_controller_from_table(
        "mpc",
        {"type": "mpc", "horizon": 10, "solver": {"max_iter": 1, "polish": False},
         "prediction": {"equilibrium": "fixed"}},
        _system("cf_lcc", 0, 3),
    )
    ctrl.reset(_ctx(0, 3))
    rng = np.random.default_rng(0)
    lin = linearize("cf_lcc", 0, 3, HDV, 15.0, ctrl.settings)
    K, kh = cav_feedback(lin.model, Gains.named(
        {"s_0": 0.1, "v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}, "replace"
    ))
    for k in range(5):
        x = rng.normal(size=lin.model.nx)
        u = ctrl(_obs(0.1 * k, x, 0, 0.3))
        assert u[0] == pytest.approx(np.clip(K @ x + kh * 0.3, -5.0, 2.0), abs=1e-12)
    st = ctrl.stats()
    assert st["fallback_static"] == 5 and st["fallback_shifted"] == 0
    assert sum(st["qp_failures"].values()) == 5
    assert "maximum iterations reached" in st["qp_failures"]


def test_fallback_chain_shifted_plan_then_static_gain():
    N = 8
    ctrl = mpc_controller_from_table(
        "mpc", {"type": "mpc", "horizon": N}, _system("fd_lcc", 0, 3)
    )
    ctrl.reset(_ctx(0, 3))
    x = np.zeros(8)
    x[2] = 3.0  # HDV 1 far behind
    obs = _obs(0.0, x, 0, 0.0)
    u0 = ctrl(obs)[0]
    plan = ctrl.history()["plan"][0, -1]
    assert u0 == pytest.approx(plan[0])
    for mem in ctrl._members:
        mem.solver.force_failure = True
    shifted = [ctrl(obs)[0] for _ in range(N - 1)]
    np.testing.assert_allclose(shifted, np.clip(plan[1:], -5.0, 2.0), atol=1e-12)
    static = ctrl(obs)[0]
    # paper FD-LCC gain: -0.2 s_1 (the other errors are zero)
    assert static == pytest.approx(-0.2 * 3.0)
    st = ctrl.stats()
    assert st["fallback_shifted"] == N - 1 and st["fallback_static"] == 1
    assert st["qp_failures"] == {"forced_failure": N}
    assert list(ctrl.history()["status"][0]) == [0] + [1] * (N - 1) + [2]


def test_nan_observation_never_raises_and_returns_a_finite_command():
    ctrl = mpc_controller_from_table("mpc", {"type": "mpc", "horizon": 10}, _system())
    ctrl.reset(_ctx(0, 3, batch=2))
    x = np.zeros(8)
    o = _obs(0.0, x, 0, 0.0)
    s = np.repeat(o.spacing, 2, axis=0)
    v = np.repeat(o.velocity, 2, axis=0)
    p = np.repeat(o.position, 2, axis=0)
    v[1, 2] = np.nan  # member 1 lost vehicle 1 entirely
    u = ctrl(Observation(0.0, s, v, p))
    assert np.all(np.isfinite(u))
    st = ctrl.stats()
    assert st["steps"] == 1 and st["solves"] == 1  # member 0 solved, member 1 fell back
    assert st["fallback_hold"] + st["fallback_static"] == 1


def test_stats_and_history_shapes():
    ctrl = mpc_controller_from_table("mpc", {"type": "mpc", "horizon": 10}, _system())
    ctrl.reset(_ctx(0, 3, batch=2))
    for k in range(4):
        x = np.full(8, 0.1 * k)
        o = _obs(0.1 * k, x, 0, -0.2)
        ctrl(Observation(o.t, *(np.repeat(a, 2, axis=0) for a in (o.spacing, o.velocity,
                                                                  o.position))))
    st = ctrl.stats()
    json.dumps(st)
    assert st["steps"] == 4 and st["solves"] == 8
    assert st["step_time_ms"]["count"] == 8 and st["step_time_ms"]["max"] > 0
    h = ctrl.history()
    assert h["u"].shape == (2, 4) and h["plan"].shape == (2, 4, 10)
    assert h["predicted_states"].shape == (2, 4, 11, 8)
    assert h["predicted_velocity"].shape == (2, 4, 11, 4)
    # predicted trajectory starts at the measured state, absolute units
    ramp = 0.1 * np.arange(4)
    np.testing.assert_allclose(h["predicted_velocity"][:, :, 0, 0], [15.0 + ramp] * 2)
    np.testing.assert_allclose(h["predicted_spacing"][:, :, 0, 0], [S_STAR + ramp] * 2)


# ------------------------------------------------------------------------------ options


def test_relinearization_updates_the_same_solver_with_new_matrices(monkeypatch):
    """When v_eq drifts past the threshold the HDV model is re-linearised and the SAME OSQP
    workspace gets the new matrix values: its solution equals an exact solve of the QP at the
    new equilibrium and differs from the one at the old equilibrium."""
    from lcc_synth.mpc import solver as mpc_solver
    from lcc_synth.mpc.solver import solve_exact

    calls = []
    original = mpc_solver.OSQPSolver.solve

    def spy(self, q, l, u, warm_z=None, warm_y=None):
        res = original(self, q, l, u, warm_z, warm_y)
        calls.append((q.copy(), l.copy(), u.copy(), res))
        return res

    monkeypatch.setattr(mpc_solver.OSQPSolver, "solve", spy)
    ctrl = mpc_controller_from_table(
        "mpc",
        {"type": "mpc", "horizon": 15,
         "prediction": {"relinearize": True, "relinearize_threshold": 0.5,
                        "equilibrium_window": 0.1}},
        _system("cf_lcc", 0, 3),
    )
    ctrl.reset(_ctx(0, 3))
    solver_before = ctrl._members[0].solver
    qp_before = ctrl._members[0].qp
    x = np.array([0.2, 0.1, -0.3, 0.2, 0.3, -0.1, 0.0, 0.4])
    ctrl(_obs(0.0, x, 0, 0.0))
    assert ctrl.stats()["relinearizations"] == 0
    # the head (and with a 0.1 s window, v_eq) drops to 6 m/s: spacings follow s*(6)
    s6 = HDV.equilibrium_spacing(6.0)
    o = _obs(0.1, x, 0, -9.0)
    o.spacing[0, 1:] += s6 - S_STAR
    o.velocity[0, 1:] -= 9.0
    ctrl(o)
    mem = ctrl._members[0]
    assert ctrl.stats()["relinearizations"] == 1
    assert mem.lin.v_lin == pytest.approx(6.0)
    assert mem.solver is solver_before
    q, lo, hi, res = calls[-1]
    new_qp = ctrl.formulation.matrices(linearize("cf_lcc", 0, 3, HDV, 6.0, ctrl.settings))
    z_new = solve_exact(new_qp, q, lo, hi)
    z_old = solve_exact(qp_before, q, lo, hi)
    assert res.z[0] == pytest.approx(z_new[0], abs=1e-6)
    assert abs(z_old[0] - z_new[0]) > 1e-4
    # the cached matrices of the old equilibrium are untouched by OSQP's in-place updates
    fresh_old = ctrl.formulation.matrices(linearize("cf_lcc", 0, 3, HDV, 15.0, ctrl.settings))
    np.testing.assert_array_equal(qp_before.P.data, fresh_old.P.data)
    np.testing.assert_array_equal(qp_before.A.data, fresh_old.A.data)


def test_pattern_change_is_refused():
    from lcc_synth.mpc.formulation import Formulation
    from lcc_synth.mpc.solver import OSQPSolver

    ctrl = mpc_controller_from_table("mpc", {"type": "mpc", "horizon": 6}, _system())
    ctrl.reset(_ctx(0, 3))
    other = Formulation("cf_lcc", 8, MPCSettings(horizon=6, weights=ctrl.settings.weights),
                        np.ones(8), [])
    qp_other = other.matrices(ctrl._members[0].lin)
    solver: OSQPSolver = ctrl._members[0].solver
    with pytest.raises(RuntimeError, match="sparsity pattern"):
        solver.update_matrices(qp_other)


def test_head_accel_prediction_holds_the_measured_acceleration():
    ctrl = mpc_controller_from_table(
        "mpc",
        {"type": "mpc", "horizon": 20,
         "prediction": {"head": "accel", "head_accel_hold": 1.0, "equilibrium": "fixed"}},
        _system("cf_lcc", 0, 3),
    )
    ctrl.reset(_ctx(0, 3))
    x = np.zeros(8)
    ctrl(_obs(0.0, x, 0, 0.0))
    ctrl(_obs(0.1, x, 0, -0.5))  # head: -0.5 m/s in 0.1 s = -5 m/s^2
    d = ctrl.history()["d"][0, -1]
    k = np.arange(20)
    np.testing.assert_allclose(d, -0.5 - 5.0 * np.minimum(0.1 * k, 1.0), atol=1e-9)


def test_batch_members_are_independent_through_relinearization():
    """Member 1 re-linearises (its head drops to 6 m/s); member 0 must give exactly what a
    single-member controller gives on the same observations (shared caches, private solvers)."""
    table = {"type": "mpc", "horizon": 15,
             "prediction": {"relinearize": True, "relinearize_threshold": 0.5,
                            "equilibrium_window": 0.1}}
    pair = mpc_controller_from_table("mpc", table, _system("cf_lcc", 0, 3))
    single = mpc_controller_from_table("mpc", table, _system("cf_lcc", 0, 3))
    pair.reset(_ctx(0, 3, batch=2))
    single.reset(_ctx(0, 3, batch=1))
    rng = np.random.default_rng(5)
    s6 = HDV.equilibrium_spacing(6.0)
    for k in range(6):
        x = 0.3 * rng.normal(size=8)
        a = _obs(0.1 * k, x, 0, 0.0)
        b = _obs(0.1 * k, x, 0, -9.0 if k >= 2 else 0.0)
        if k >= 2:
            b.spacing[0, 1:] += s6 - S_STAR
            b.velocity[0, 1:] -= 9.0
        both = Observation(a.t, *(np.vstack([u, w]) for u, w in
                                  ((a.spacing, b.spacing), (a.velocity, b.velocity),
                                   (a.position, b.position))))
        u_pair = pair(both)
        u_single = single(a)
        assert u_pair[0] == u_single[0]
    assert pair.stats()["relinearizations"] == 1
    assert single.stats()["relinearizations"] == 0


def test_pickle_round_trip_drops_the_run_state():
    import pickle

    ctrl = mpc_controller_from_table("mpc", {"type": "mpc", "horizon": 10}, _system())
    ctrl.reset(_ctx(0, 3))
    x = np.array([0.5, -0.2, 0.1, 0.3, -0.4, 0.0, 0.2, 0.1])
    u = ctrl(_obs(0.0, x, 0, 0.0))
    copy = pickle.loads(pickle.dumps(ctrl))
    with pytest.raises(RuntimeError, match="reset"):
        copy(_obs(0.0, x, 0, 0.0))
    copy.reset(_ctx(0, 3))
    assert copy(_obs(0.0, x, 0, 0.0))[0] == pytest.approx(u[0], abs=1e-12)
