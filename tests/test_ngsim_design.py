"""Design for the measured drivers (``problems/ngsim_lane2_design.toml``) and the followers'
velocity standard deviation: the metric against closed forms, the all-HDV row against the
calibrated replay (a second problem file, the CAV slot elsewhere), the robust H2 gain against
an independent Lyapunov evaluation over the sampled members; and the recording of a replay,
read back from the file, against the trajectory file."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.linalg import solve_continuous_lyapunov

import lcc_synth as lcc
from lcc_synth.experiments.h2_tables import synthesize_table
from lcc_synth.metrics import follower_columns, follower_velocity_std, velocity_std
from lcc_synth.models.platoon import platoon_model
from lcc_synth.simulation.results import SimResult
from lcc_synth.synthesis.config import RobustSettings, robust_members
from lcc_synth.synthesis.h2 import Weights, make_platoon_plant

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "problems" / "ngsim_lane2_design.toml"
CALIBRATED = ROOT / "problems" / "ngsim_lane2_calibrated.toml"


def _result(v, m=0, n=3, collided=None):
    """A single-CAV SimResult of hand-written velocities ``(B, T, nv)`` (dt = 1 s)."""
    v = np.asarray(v, dtype=float)
    B, T, nv = v.shape
    z = np.zeros_like(v)
    return SimResult(
        t=np.arange(T, dtype=float), position=z, velocity=v, acceleration=z,
        spacing=np.full_like(v, 20.0), u_cmd=np.zeros((B, T)),
        aeb_active=np.zeros((B, T), bool),
        collided=np.zeros((B, nv), bool) if collided is None else np.asarray(collided),
        collision_time=np.full((B, nv), np.nan), m=m, n=n, cav=m + 1,
        v_star=np.full(B, 10.0), s_star=np.full(B, 20.0), controller="test",
        controller_info={}, controller_stats={}, dt=1.0, sim_dt=1.0,
    )  # fmt: skip


# ------------------------------------------------------------------------------------------
# the metric at hand-made trajectories
# ------------------------------------------------------------------------------------------


def test_follower_velocity_std_of_whole_sine_periods_is_amplitude_over_root_two():
    # N samples of one period of c + A sin(2 pi k / N + phase): mean c, variance A^2 / 2
    # exactly (N >= 3), for any phase, so the pooled value of two such followers is A / sqrt 2.
    # The head, the vehicle ahead of the CAV and the CAV itself move wildly: not counted.
    N, A, c = 40, 1.7, 8.0
    k = np.arange(N)
    v = np.empty((1, N, 5))  # head, HDV -1, CAV, HDV 1, HDV 2
    v[0, :, 0] = 30.0 * (k % 2)
    v[0, :, 1] = 3.0 * k
    v[0, :, 2] = -5.0 * k
    v[0, :, 3] = c + A * np.sin(2 * np.pi * k / N)
    v[0, :, 4] = c + A * np.sin(2 * np.pi * k / N + 1.1)
    r = _result(v, m=1, n=2)
    assert follower_columns(r).tolist() == [3, 4]
    got = follower_velocity_std(r, (0.0, N - 1.0))[0]
    assert got == pytest.approx(A / math.sqrt(2.0), rel=1e-12)
    # the same value as velocity_std of the explicit set HDVs 1, 2
    assert got == velocity_std(r, (0.0, N - 1.0), (1, 2))[0]


def test_follower_velocity_std_pools_the_followers_means():
    # constant followers at 6 and 10 m/s: pooled {6, ..., 10, ...}, std = |10 - 6| / 2
    v = np.zeros((1, 5, 4))
    v[0, :, 2], v[0, :, 3] = 6.0, 10.0
    assert follower_velocity_std(_result(v, n=2), (0.0, 4.0))[0] == pytest.approx(2.0)


def test_follower_velocity_std_nan_without_followers_or_after_a_collision():
    tail = _result(np.ones((1, 4, 2)), n=0)  # head and the CAV only
    assert follower_columns(tail).size == 0
    assert np.isnan(follower_velocity_std(tail, (0.0, 3.0))).all()
    hit = np.zeros((2, 4), bool)
    hit[1, 3] = True
    r = _result(np.arange(32.0).reshape(2, 4, 4), n=2, collided=hit)
    out = follower_velocity_std(r, (0.0, 3.0))
    assert np.isfinite(out[0]) and np.isnan(out[1])


def test_follower_columns_of_platoons_and_rings():
    # an open platoon of 6 (column 0: the head) with CAVs at positions 2 and 4: behind the
    # first CAV, CAVs excluded; on a ring every HDV (the road closes)
    platoon = SimpleNamespace(n_vehicles=7, cav=2, cavs=(2, 4), ring=False)
    assert follower_columns(platoon).tolist() == [3, 5, 6]
    ring = SimpleNamespace(n_vehicles=6, cav=2, cavs=(2, 4), ring=True)
    assert follower_columns(ring).tolist() == [0, 1, 3, 5]


# ------------------------------------------------------------------------------------------
# the shipped design problem
# ------------------------------------------------------------------------------------------


def _run(path: Path, name: str):
    objs = lcc.load_problem(path)
    return lcc.simulate(objs.scenario, objs.controllers[name])


def test_all_hdv_row_is_the_calibrated_replay_of_the_real_followers():
    """The design's CAV slot (position 1) under ``type = "hdv"`` drives with follower 1's
    calibrated law: every vehicle's trajectory equals the calibrated problem's replay, where
    the CAV slot is the tail's; the CAV's emergency braking never acts."""
    design = _run(DESIGN, "all_hdv")
    replay = _run(CALIBRATED, "replay")
    assert design.cavs != replay.cavs  # two different layouts of the same drivers
    assert not design.aeb_active.any() and not design.collided.any()
    np.testing.assert_allclose(design.velocity, replay.velocity, rtol=0, atol=1e-9)
    np.testing.assert_allclose(design.position, replay.position, rtol=0, atol=1e-9)
    assert np.isnan(follower_velocity_std(replay, (0.0, 36.8))).all()  # CAV slot at the tail
    assert follower_velocity_std(design, (0.0, 36.8))[0] == pytest.approx(
        velocity_std(replay, (0.0, 36.8), (2, 3, 4))[0], abs=1e-9)


def _lyapunov_h2(plant, K) -> float:
    """H2 of ``u = K x`` on the open platoon's plant by scipy's Lyapunov solver (inf if
    unstable): ``J = tr((Q + r K'K) L)``, ``(A + BK) L + L (A + BK)' + Bw Bw' = 0``."""
    Acl = plant.A + plant.B @ K
    if np.linalg.eigvals(Acl).real.max() >= 0:
        return math.inf
    L = solve_continuous_lyapunov(Acl, -plant.Bw @ plant.Bw.T)
    return math.sqrt(float(np.trace((plant.Q + plant.r * K.T @ K) @ L)))


def test_robust_h2_gain_lowers_the_mean_h2_over_the_spread_of_the_fits():
    data = tomllib.loads(DESIGN.read_text())
    table = data["controllers"]["h2"]
    system = lcc.load_problem(DESIGN).system
    _, rob = synthesize_table("h2", table, system, "design_h2")
    nominal = {k: v for k, v in table.items() if k != "robust"}
    _, nom = synthesize_table("h2", nominal, system, "design_h2_nominal")
    K_rob, K_nom = np.array(rob.K), np.array(nom.K)
    # the paper's pattern: the CAV hears itself and the two drivers behind it, not the tail
    tail = [rob.state_names.index(s) for s in ("s_4", "v_4")]
    assert np.all(K_rob[:, tail] == 0) and np.all(K_nom[:, tail] == 0)
    rb = table["robust"]
    members = robust_members(system, RobustSettings(
        rb["samples"], rb["seed"], rb["objective"],
        {k: tuple(rb[k]) for k in ("alpha", "beta", "s_go")}))  # fmt: skip
    assert len(members) == 20
    w = Weights(**rob.weights)
    plants = [make_platoon_plant(platoon_model(p, warn=False), "added", w) for p in members]
    h_rob = np.array([_lyapunov_h2(p, K_rob) for p in plants])
    h_nom = np.array([_lyapunov_h2(p, K_nom) for p in plants])
    assert np.isfinite(h_rob).all() and np.isfinite(h_nom).all()  # stable on every member
    assert h_rob.mean() < h_nom.mean()
    # the report's own figures agree with the independent evaluation
    assert rob.robust["robust_design"]["mean_h2"] == pytest.approx(h_rob.mean(), rel=1e-8)
    assert rob.robust["nominal_design"]["mean_h2"] == pytest.approx(h_nom.mean(), rel=1e-8)



# ------------------------------------------------------------------------------------------
# the recording of a replay: recorded trajectories next to the simulated ones
# ------------------------------------------------------------------------------------------


def _series(path: Path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """``(times in s, values (rows, series))`` of a Scalars entity read back from the file."""
    from rerun.chunk import RrdReader

    times, values = [], []
    for ch in RrdReader(path).stream():
        if ch.entity_path != entity or ch.is_static:
            continue
        rb = ch.to_record_batch()
        col = next(n for n in rb.schema.names if n.endswith("scalars"))
        times.append(rb.column("time").cast("int64").to_numpy())
        values += rb.column(col).to_pylist()
    t = np.concatenate(times)
    order = np.argsort(t, kind="stable")
    return t[order] * 1e-9, np.array(values, dtype=float)[order]


def test_replay_recording_holds_the_recorded_trajectories(tmp_path):
    """``simulate --rrd`` of the calibrated replay: ``/<scenario>/recorded/velocity`` is every
    recorded speed of the file (leader and followers) and ``.../spacing`` every recorded
    headway minus the vehicle length, at the recorded sample times, beside the simulated
    run."""
    pytest.importorskip("rerun")
    from lcc_synth.cli.main import main
    from lcc_synth.schema.trajectories import read_trajectory

    rrd = tmp_path / "replay.rrd"
    assert main(["simulate", str(CALIBRATED), "--rrd", str(rrd), "-q"]) == 0
    tr = read_trajectory(ROOT / "problems" / "data" / "ngsim_i80" / "i80_lane2.csv")
    t, v = _series(rrd, "/ngsim_lane2_calibrated/recorded/velocity")
    np.testing.assert_allclose(t, tr.t, rtol=0, atol=1e-9)
    assert np.array_equal(v, tr.v.T)  # exactly as read
    t, s = _series(rrd, "/ngsim_lane2_calibrated/recorded/spacing")
    assert np.array_equal(s, tr.headway[1:].T - 5.0)
    _, sim = _series(rrd, "/ngsim_lane2_calibrated/replay/velocity")
    assert sim.shape[1] == v.shape[1] == 5  # one series per vehicle in both


def test_recorded_leader_without_initial_data_is_the_head_only(tmp_path):
    """Without ``initial = "data"`` the file's other vehicles are not this run's: only the
    replayed leader's speed is recorded (no spacing)."""
    from lcc_synth.recording import recorded_trajectories
    from lcc_synth.schema.trajectories import read_trajectory

    text = CALIBRATED.read_text().replace('initial = "data"\n', "").replace(
        "v_star = 6.98", "v_star = 3.3345").replace(
        'file = "data/', f'file = "{ROOT / "problems" / "data"}/')  # fmt: skip
    path = tmp_path / "p.toml"
    path.write_text(text)
    sc = lcc.load_problem(path).scenario
    data = recorded_trajectories(sc)
    tr = read_trajectory(ROOT / "problems" / "data" / "ngsim_i80" / "i80_lane2.csv")
    assert data.velocity.shape == (len(tr.t), 1) and data.spacing.shape == (len(tr.t), 0)
    assert np.array_equal(data.velocity[:, 0], tr.v[0])
    assert recorded_trajectories(lcc.load_problem(ROOT / "problems" / "paper_table2.toml")
                                 .scenario) is None  # fmt: skip
