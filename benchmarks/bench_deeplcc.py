"""Per-step time of DeeP-LCC (lcc_synth.deeplcc) next to the MPC's, on this machine.

Run:  python benchmarks/bench_deeplcc.py [--full-steps 5] [--no-two-cav]

1. One CAV, n = 10 (``problems/deeplcc_head_brake.toml``, T = 2000, Tini = 20, N = 50,
   1200 controller steps at 0.05 s through the brake): the controller's own per-step time
   (rings, parameter vector, bounds, warm-started OSQP solve, checks) and OSQP's run time from
   ``controller.stats()``, next to the MPC of the same file; plus the one-off costs (data
   collection without cache, the exact reduction and the CasADi formulation).
2. The unreduced QP in ``g`` (1931 variables for T = 2000), OSQP set up once on its dense
   Hessian and solved for the first ``--full-steps`` recorded steps: what the reduction saves.
3. Two CAVs in the DeeP-LCC paper's 8-vehicle platoon (CAVs 3 and 6; hand-made
   ``ControlContext`` with ``cavs``): data (T = 2000) and the closed loop from the exact ZOH
   linear platoon model with U[-0.1, 0.1] acceleration noise (the multi-CAV nonlinear
   simulator is not needed), head braking -5 m/s^2 for 2 s, 800 steps.
4. The same platoon in the nonlinear simulator: ``problems/platoon_deeplcc_brake.toml`` (its
   scenario: heterogeneous OVM HDVs, uniform acceleration noise) with a default ``deep_lcc``
   controller, data collected on that scenario; per-step wall and CPU times, how many steps
   OSQP stopped at its iteration cap and DAQP solved exactly, and the metrics against the
   file's all-HDV baseline.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def dist(ms) -> str:
    ms = np.asarray(ms, float)
    return (f"median {np.median(ms):8.3f}  p99 {np.percentile(ms, 99):8.3f}  "
            f"max {ms.max():8.3f}  mean {ms.mean():8.3f}  (n={ms.size})")


def one_cav(full_steps: int) -> None:
    from lcc_synth.deeplcc.build import deep_lcc_controller_from_table
    from lcc_synth.deeplcc.data import collect, collection_scenario
    from lcc_synth.deeplcc.settings import deep_settings_from_table
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.mpc.solver import OSQPSolver
    from lcc_synth.problem import load_problem
    from lcc_synth.simulation.engine import simulate

    path = ROOT / "problems" / "deeplcc_head_brake.toml"
    spec = load_spec(path)
    table = load_problem(path).data["controllers"]["deep_lcc"]
    settings = deep_settings_from_table(table, "controllers.deep_lcc")
    sc_data = collection_scenario(spec.scenario, settings.data)
    t0 = time.perf_counter()
    collect(sc_data, settings.data)
    t_collect = time.perf_counter() - t0
    recorded = []
    original = OSQPSolver.solve

    cpu: list[float] = []

    def recording(self, q, l, u, warm_z=None, warm_y=None):
        recorded.append((l.copy(), u.copy()))
        c0 = time.thread_time()
        out = original(self, q, l, u, warm_z, warm_y)
        cpu.append((time.thread_time() - c0) * 1e3)
        return out

    OSQPSolver.solve = recording
    try:
        deep = deep_lcc_controller_from_table("deep_lcc", table, spec.system, str(path),
                                              spec.scenario)  # fmt: skip
        deep = deep.controller()  # collected (from the cache) and set up here
        res = simulate(spec.scenario, deep)
    finally:
        OSQPSolver.solve = original
    st = res.controller_stats
    print("1. one CAV, n = 10, T = 2000, Tini = 20, N = 50 (problems/deeplcc_head_brake.toml)")
    print(f"   data collection (2000 samples, no cache): {t_collect:.2f} s; reduction + "
          f"CasADi formulation: {deep.setup_time:.2f} s; QP: {deep.qp.n_var} "
          f"variables, {3 * deep.qp.n_w} constraints (g has {deep.data_columns})")
    print("   deep_lcc step ms ", dist(np.array(deep._st["step_time"]) * 1e3))
    print("   deep_lcc OSQP ms ", dist(np.array(deep._st["osqp_time"]) * 1e3))
    print("   OSQP solve CPU ms", dist(cpu))
    print(f"   iterations median {st['iterations']['median']:.0f} max {st['iterations']['max']}"
          f", QP failures {st['qp_failures']}, fallbacks {st['fallbacks']}")
    mres = simulate(spec.scenario, spec.controllers["mpc"])
    mpc = spec.controllers["mpc"]
    print("   mpc step ms      ", dist(np.array(mpc._st["step_time"]) * 1e3),
          f"(sample time {mpc.sample_time} s, {mres.controller_stats['steps']} steps)")
    if full_steps > 0:
        full_qp_steps(deep, recorded[:full_steps])


def full_qp_steps(deep, recorded) -> None:
    """The QP in g with OSQP set up once (module docstring, item 2)."""
    import osqp
    import scipy.sparse as sp

    from lcc_synth.deeplcc.hankel import windows

    print(f"2. the unreduced QP in g ({deep.data_columns} variables), OSQP set up once:")
    st = deep.settings
    data = deep.data
    win = windows(data, st.t_ini, st.horizon)
    w = st.weights
    N = st.horizon
    q = np.concatenate([np.full(deep.nv - 1, w.velocity), np.full(deep.n_c, w.spacing)])
    B = np.vstack([np.sqrt(np.tile(q, N))[:, None] * win.Yf,
                   np.sqrt(w.input) * win.Uf, np.sqrt(w.lambda_y) * win.Yp])  # fmt: skip
    K = win.Up.shape[1]
    H = 2 * (B.T @ B + w.lambda_g * np.eye(K))
    A = np.vstack([win.Up, win.Ep, win.Ef, win.Uf, deep.spacing_rows @ win.Yf])
    nA = win.Up.shape[0] + win.Ep.shape[0] + win.Ef.shape[0]
    n_w = deep.qp.n_w
    # slack columns
    P = sp.block_diag([sp.csc_matrix(np.triu(H)), 2 * w.slack_quadratic * sp.eye(n_w)]).tocsc()
    Aw = sp.bmat([[sp.csc_matrix(A), sp.vstack([sp.csc_matrix((nA + n_w, n_w)), sp.eye(n_w)])],
                  [None, sp.eye(n_w)]]).tocsc()  # fmt: skip
    qv = np.concatenate([np.zeros(K), np.full(n_w, w.slack)])
    t0 = time.perf_counter()
    m = osqp.OSQP()
    lo = np.concatenate([np.zeros(nA), np.full(n_w, -5.0), np.full(n_w, -np.inf), np.zeros(n_w)])
    hi = np.concatenate([np.zeros(nA), np.full(n_w, 2.0), np.full(2 * n_w, np.inf)])
    m.setup(P, qv, Aw, lo, hi, eps_abs=1e-6, eps_rel=1e-6, verbose=False, max_iter=10000)
    print(f"   setup (factorisation of the dense KKT system): {time.perf_counter() - t0:.2f} s")
    times = []
    for _ in recorded:  # the first step's QP, solved again (warm): a lower bound per step
        t0 = time.perf_counter()
        res = m.solve()
        times.append((time.perf_counter() - t0) * 1e3)
    print("   full QP solve ms ", dist(times), f"status {res.info.status}")


def two_cav(steps: int = 800) -> None:
    from lcc_synth.controllers.base import ControlContext, Observation
    from lcc_synth.deeplcc.controller import DeePLCCController
    from lcc_synth.deeplcc.hankel import DataSet
    from lcc_synth.deeplcc.settings import DeePLCCSettings
    from lcc_synth.models.hdv import OVM
    from lcc_synth.models.platoon import Platoon, platoon_model

    @dataclass(frozen=True)
    class Ctx(ControlContext):
        cavs: tuple[int, ...] = (3, 6)

    alpha = [0.45, 0.75, 0.6, 0.70, 0.50, 0.6, 0.40, 0.80]
    beta = [0.60, 0.95, 0.9, 0.95, 0.75, 0.9, 0.80, 1.00]
    s_go = [38.0, 31.0, 35.0, 33.0, 37.0, 35.0, 39.0, 34.0]
    hdv = tuple(OVM(alpha=a, beta=b, s_go=g) for a, b, g in zip(alpha, beta, s_go, strict=True))
    cavs = (3, 6)
    model = platoon_model(Platoon(hdv, cavs, 15.0))
    Ts = 0.05
    Ad, Bd, Hd = model.discretize(Ts)
    rng = np.random.default_rng(0)
    nv = 9
    names = [f"v_{i}" for i in range(1, nv)] + [f"s_{c}" for c in cavs]
    C = model.output_matrix(names)
    T = 2000
    u = rng.uniform(-1, 1, (T, 2))
    e = rng.uniform(-1, 1, T)
    x = np.zeros(model.nx)
    y = np.empty((T, C.shape[0]))
    hdv_rows = [model.index(f"v_{i}") for i in range(1, nv) if i not in cavs]
    for k in range(T):
        x = Ad @ x + Bd @ u[k] + Hd[:, 0] * e[k]
        x[hdv_rows] += Ts * rng.uniform(-0.1, 0.1, len(hdv_rows))
        y[k] = C @ x
    st = DeePLCCSettings()
    t0 = time.perf_counter()
    ctrl = DeePLCCController("deep_lcc", st, DataSet(u, e, y, Ts), "platoon", OVM(), 15.0, nv,
                             cavs)  # fmt: skip
    setup = time.perf_counter() - t0
    s_star = OVM().equilibrium_spacing(15.0)
    ctx = Ctx(0, nv - 2, 1, Ts, np.array([15.0]), np.array([s_star]), -5.0, 2.0, OVM())
    ctrl.reset(ctx)
    s_eq = np.array([np.nan] + [h.equilibrium_spacing(15.0) for h in hdv])
    x = np.zeros(model.nx)
    v_head = 15.0
    cpu: list[float] = []
    for k in range(steps):
        t = k * Ts
        e_k = v_head - 15.0
        spacing = (s_eq + np.concatenate([[0.0], x[0::2]]))[None]
        vel = (15.0 + np.concatenate([[e_k], x[1::2]]))[None]
        obs = Observation(t, spacing, vel, np.zeros_like(vel))
        c0 = time.thread_time()
        cmd = ctrl(obs).reshape(-1)
        cpu.append((time.thread_time() - c0) * 1e3)
        x = Ad @ x + Bd @ cmd + Hd[:, 0] * e_k
        a_head = -5.0 if 5.0 <= t < 7.0 else (2.0 if 12.0 <= t < 17.0 else 0.0)
        v_head += Ts * a_head
    stt = ctrl.stats()
    print(f"3. two CAVs (positions 3, 6 of 8), T = 2000: reduction + formulation {setup:.2f} s, "
          f"QP {ctrl.qp.n_var} variables (g has {ctrl.data_columns})")
    print("   deep_lcc step ms ", dist(np.array(ctrl._st["step_time"]) * 1e3))
    print("   deep_lcc CPU ms  ", dist(cpu))
    print(f"   iterations median {stt['iterations']['median']:.0f} max "
          f"{stt['iterations']['max']}, OSQP stopped {stt['qp_failures']}, solved exactly by "
          f"DAQP {stt['exact_solves']}, fallbacks {stt['fallbacks']}")


def two_cav_nonlinear() -> None:
    from lcc_synth.deeplcc.build import deep_lcc_controller_from_table
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.metrics import summary
    from lcc_synth.simulation.engine import simulate

    path = ROOT / "problems" / "platoon_deeplcc_brake.toml"
    spec = load_spec(path)
    ctrl = deep_lcc_controller_from_table("deep_lcc", {"type": "deep_lcc"}, spec.system,
                                          str(path), spec.scenario).controller()  # fmt: skip
    draws = spec.scenario.draw()
    cpu: list[float] = []
    call = type(ctrl).__call__

    def timed(self, obs):  # the controller's CPU time per step (the wall time is shared)
        c0 = time.thread_time()
        out = call(self, obs)
        cpu.append((time.thread_time() - c0) * 1e3)
        return out

    type(ctrl).__call__ = timed
    try:
        res = simulate(spec.scenario, ctrl, draws)
    finally:
        type(ctrl).__call__ = call
    base = simulate(spec.scenario, spec.controllers["all_hdv"], draws)
    st = res.controller_stats
    m, b = summary(res, spec.metrics), summary(base, spec.metrics)
    print(f"4. two CAVs, nonlinear (problems/platoon_deeplcc_brake.toml): QP {ctrl.qp.n_var} "
          f"variables; AAVE {m['aave']:.3f} (all-HDV {b['aave']:.3f}) m/s, fuel "
          f"{m['fuel_ml']:.1f} ({b['fuel_ml']:.1f}) mL, min spacing {m['min_spacing']:.2f} m, "
          f"collisions {m['collisions']}")
    print("   deep_lcc step ms ", dist(np.array(ctrl._st["step_time"]) * 1e3))
    print("   deep_lcc CPU ms  ", dist(cpu))
    print(f"   iterations median {st['iterations']['median']:.0f} max {st['iterations']['max']}"
          f", OSQP stopped {st['qp_failures']}, solved exactly by DAQP {st['exact_solves']}, "
          f"fallbacks {st['fallbacks']}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full-steps", type=int, default=5)
    ap.add_argument("--no-two-cav", action="store_true")
    args = ap.parse_args()
    one_cav(args.full_steps)
    if not args.no_two_cav:
        two_cav()
        two_cav_nonlinear()


if __name__ == "__main__":
    main()
