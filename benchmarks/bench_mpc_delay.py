"""Cost of the delay states (``prediction.delay``, :mod:`lcc_synth.mpc.delay`) in the MPC, on
this machine.

Run:  python benchmarks/bench_mpc_delay.py [--delay 0.4]

The closed loop of ``problems/mpc_head_brake.toml`` (CF-LCC, n = 10, N = 50, 600 controller
steps) with every HDV of the scenario delayed ``--delay`` s, for the delay-free MPC and the
delay-aware one, each predicting all 10 HDVs and (as ``problems/sweep_robustness.toml``) the 4
right behind: the model's state count, the one-off build of the CasADi formulation, one
evaluation of the QP matrices (what a re-linearisation costs), the controller's per-step time
and OSQP's run time (``controller.stats()``), and the AAVE over the window.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--delay", type=float, default=0.4)
    args = ap.parse_args()

    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.metrics import summary
    from lcc_synth.mpc import build_mpc
    from lcc_synth.simulation.engine import simulate

    spec = load_spec(ROOT / "problems" / "mpc_head_brake.toml")
    scenario = replace(spec.scenario, delay=args.delay)
    print(f"head brake, every HDV delayed {args.delay} s; CF-LCC, N = 50, Ts = 0.1 s")
    print(f"{'n_model':>7} {'predicted delay':>15} {'states':>6} {'build s':>8} "
          f"{'matrices ms':>11} {'step ms med / p99 / max':>24} {'osqp ms med / p99':>18} "
          f"{'AAVE':>6}")  # fmt: skip
    for n_model in (10, 4):
        for delay in (0.0, args.delay):
            t0 = time.perf_counter()
            ctrl = build_mpc(spec.system, n_model=n_model, prediction={"delay": delay},
                             weights={"spacing_cav": 0.1} if n_model == 4 else None)
            build = time.perf_counter() - t0
            lin = ctrl._lin0
            reps = []
            for _ in range(5):
                t0 = time.perf_counter()
                ctrl.formulation.matrices(lin)
                reps.append(time.perf_counter() - t0)
            res = simulate(scenario, ctrl)
            st = res.controller_stats
            step, osqp = st["step_time_ms"], st["osqp_time_ms"]
            aave = summary(res, spec.metrics)["aave"]
            print(f"{n_model:>7} {delay:>15.2f} {lin.Ad.shape[0]:>6} {build:>8.2f} "
                  f"{1e3 * np.median(reps):>11.1f} "
                  f"{step['median']:>8.2f} /{step['p99']:>6.2f} /{step['max']:>6.1f} "
                  f"{osqp['median']:>8.2f} /{osqp['p99']:>6.2f} {aave:>6.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
