"""Per-step time of the joint platoon MPC (lcc_synth.mpc.joint) on this machine.

Run:  python benchmarks/bench_mpc_platoon.py [--horizon 50] [--ring-time 60]

1. The DeeP-LCC paper's two-CAV platoon (head + 8 vehicles, CAVs 3 and 6, heterogeneous OVM
   HDVs), N = 50, Ts = 0.1 s, in its brake scenario (head: cruise 1 s, -5 m/s^2 for 2 s,
   hold 5 s, +2 m/s^2 for 5 s, cruise to 40 s; U[-0.1, 0.1] m/s^2 noise on every follower),
   the nonlinear OVM integrated by Euler at 0.05 s by this script (400 controller steps).
2. The 20-vehicle OVM ring (alpha 0.6, beta 0.9, s_go 35, v* 15) with one AV (vehicle 20),
   N = 50, a -1 m/s velocity perturbation of vehicle 5, nonlinear OVM by Euler at 0.05 s.

Reported: the time to build the controller (CasADi formulation, Riccati; the OSQP set-up is
at reset, inside the loop), the controller's whole per-step time and OSQP's own run time
(median, p99, max, from ``stats()``), OSQP iterations, fallbacks.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

DEEPLCC = {
    "alpha": [0.45, 0.75, 0.6, 0.70, 0.50, 0.6, 0.40, 0.80],
    "beta": [0.60, 0.95, 0.9, 0.95, 0.75, 0.9, 0.80, 1.00],
    "s_go": [38.0, 31.0, 35.0, 33.0, 37.0, 35.0, 39.0, 34.0],
}


def head_velocity(t: float) -> float:
    """The DeeP-LCC brake profile of the issue."""
    v = 15.0
    v -= 5.0 * np.clip(t - 1.0, 0.0, 2.0)
    v += 2.0 * np.clip(t - 8.0, 0.0, 5.0)
    return float(v)


def run(system, ctrl, s0, v0, T: float, dt: float = 0.05, perturb=None, seed: int = 0):
    """Euler loop of the nonlinear platoon / ring with the MPC on the CAVs (zero-order hold)."""
    from types import SimpleNamespace

    from lcc_synth.controllers.base import Observation

    pl = system.platoon
    cav = np.array(pl.cavs) - 1
    rng = np.random.default_rng(seed)
    s, v = np.array(s0, float), np.array(v0, float)
    hold = int(round(ctrl.sample_time / dt))
    cols = tuple(int(c) for c in ctrl.cav_columns)
    ctx = SimpleNamespace(m=cols[0] - 1, n=system.n, batch=1, dt=dt,
                          v_star=np.full(1, pl.v_star),
                          s_star=np.full(1, pl.equilibrium_spacings[0]), a_min=-5.0, a_max=2.0,
                          hdv=system.hdv, cavs=cols, ring=pl.ring, circumference=pl.length)
    ctrl.reset(ctx)
    u = np.zeros(len(cav))
    min_gap = np.inf
    for k in range(int(round(T / dt))):
        t = k * dt
        vh = np.nan if pl.ring else head_velocity(t)
        v_ahead = np.roll(v, 1) if pl.ring else np.concatenate([[vh], v[:-1]])
        if k % hold == 0:
            cs = s if pl.ring else np.concatenate([[np.nan], s])
            cv = v if pl.ring else np.concatenate([[vh], v])
            u = np.asarray(ctrl(Observation(t, cs[None], cv[None], np.zeros((1, cs.size)))),
                           float).reshape(-1)
        a = np.array([pl.hdv[i].accel(s[i], v_ahead[i] - v[i], v[i]) for i in range(pl.size)])
        a[cav] = u
        a = np.clip(a, -5.0, 2.0)
        if perturb is None and not pl.ring:
            a = a + rng.uniform(-0.1, 0.1, pl.size)
        s = s + dt * (v_ahead - v)
        v = np.maximum(v + dt * a, 0.0)
        min_gap = min(min_gap, float(s.min()))
    return min_gap


def report(label: str, build_s: float, ctrl, extra: str = "") -> None:
    st = ctrl.stats()
    print(f"{label}")
    print(f"  build (CasADi formulation + Riccati): {build_s * 1e3:8.1f} ms"
          f"   QP: {ctrl.formulation.nz} variables, {ctrl.formulation.nc} constraints")
    for key in ("step_time_ms", "osqp_time_ms"):
        d = st[key]
        print(f"  {key:13s} median {d['median']:7.3f}  p99 {d['p99']:7.3f}  max {d['max']:7.3f}"
              f"  (n={d['count']})")
    print(f"  iterations median {st['iterations']['median']}, max {st['iterations']['max']};"
          f" slack steps {st['slack_steps']}, comfort relaxed {st['jerk_relaxed']}, "
          f"fallbacks {st['fallbacks']}, QP failures {st['qp_failures']} {extra}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--horizon", type=int, default=50)
    ap.add_argument("--ring-time", type=float, default=60.0)
    args = ap.parse_args()

    from threadpoolctl import threadpool_limits

    from lcc_synth.models.hdv import OVM
    from lcc_synth.models.platoon import Platoon
    from lcc_synth.mpc import JointMPCController
    from lcc_synth.mpc.settings import MPCSettings
    from lcc_synth.problem import System

    settings = MPCSettings(horizon=args.horizon, sample_time=0.1)
    with threadpool_limits(1):
        hdv = tuple(OVM(alpha=a, beta=b, s_go=g)
                    for a, b, g in zip(*DEEPLCC.values(), strict=True))
        pl = Platoon(hdv, (3, 6), 15.0)
        system = System("platoon", 2, 5, 15.0, OVM(), pl)
        t0 = time.perf_counter()
        ctrl = JointMPCController("mpc", settings, system)
        build = time.perf_counter() - t0
        gap = run(system, ctrl, pl.equilibrium_spacings, np.full(8, 15.0), 40.0)
        report(f"two-CAV DeeP-LCC platoon (8 vehicles, CAVs 3 and 6), N = {args.horizon}, "
               "Ts = 0.1 s, brake scenario 40 s", build, ctrl, f"; min spacing {gap:.2f} m")

        ring = Platoon(tuple([OVM()] * 20), (20,), 15.0, ring=True)
        rsys = System("ring", 19, 0, 15.0, OVM(), ring)
        t0 = time.perf_counter()
        rctrl = JointMPCController("mpc", settings, rsys)
        build = time.perf_counter() - t0
        v0 = np.full(20, 15.0)
        v0[4] -= 1.0
        gap = run(rsys, rctrl, ring.equilibrium_spacings, v0, args.ring_time, perturb="v")
        report(f"20-vehicle ring, one AV (vehicle 20), N = {args.horizon}, Ts = 0.1 s, "
               f"{args.ring_time:g} s", build, rctrl, f"; min spacing {gap:.2f} m")


if __name__ == "__main__":
    main()
