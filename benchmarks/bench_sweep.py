"""Throughput of a Monte Carlo sweep on a local Dask cluster (``lcc-synth sweep``).

Runs ``problems/sweep_robustness.toml`` (by default issue 14's four controllers: all_hdv,
paper, h2, mpc; 10 HDVs behind a CF-LCC CAV; 40 s at dt = 0.01 s; the MPC at 0.1 s with
horizon 50) on a LocalCluster of 2 single-threaded worker processes and prints the wall time,
scenarios per second and, per controller, the simulation time summed over the workers.
``--controllers all`` runs every controller of the file (also mpc_delay and deep_lcc);
``--mpc-solver daqp`` switches the MPCs' QP solver from OSQP (the file's) to the exact
active-set option (``[controllers.mpc.solver] method``).

Usage: python benchmarks/bench_sweep.py [--count 1000] [--batch-size 50] [--workers 2]
       [--controllers all_hdv,paper,h2,mpc | all] [--mpc-solver osqp | daqp]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from dask.distributed import Client

from lcc_synth.experiments.sweep import load_sweep, local_cluster, run_sweep, stop_cluster
from lcc_synth.problem import load_problem

PROBLEM = Path(__file__).resolve().parents[1] / "problems" / "sweep_robustness.toml"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--batch-size", type=int, default=50)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--controllers", default="all_hdv,paper,h2,mpc")
    ap.add_argument("--mpc-solver", choices=("osqp", "daqp"), default=None)
    args = ap.parse_args()
    problem = load_problem(PROBLEM)
    if args.mpc_solver:
        for table in problem.data["controllers"].values():
            if table.get("type") in ("mpc", "mpc_delay"):
                table.setdefault("solver", {})["method"] = args.mpc_solver
    names = None if args.controllers == "all" else args.controllers.split(",")
    spec = load_sweep(problem, count=args.count, batch_size=args.batch_size, controllers=names)
    t0 = time.perf_counter()
    cluster = local_cluster(args.workers)
    client = Client(cluster)
    t_start = time.perf_counter() - t0
    try:
        res = run_sweep(spec, client=client, progress=False)
    finally:
        stop_cluster(cluster, client)  # and its scratch space
    info = res.info
    sc = spec.scenario
    nv = sc.n_vehicles
    print(
        f"{spec.name}: {spec.count} scenarios x {len(res.summary)} controllers, "
        f"{info['tasks']} tasks of {spec.batch_size}, {args.workers} workers; "
        f"{sc.steps} steps x {nv} vehicles per scenario"
    )
    print(f"cluster start-up   {t_start:7.1f} s")
    print(f"synthesis (client) {info['synthesis_time_s']:7.1f} s")
    print(
        f"sweep wall time    {info['wall_time_s']:7.1f} s  -> {info['scenarios_per_s']:.2f} "
        f"scenarios/s, {info['runs_per_s']:.2f} scenario-controller runs/s"
    )
    print(f"task time (sum)    {info['task_time_s_sum']:7.1f} s")
    for name, t in info["simulation_time_s"].items():
        vsteps = spec.count * sc.steps * nv / t
        print(
            f"  {name:10s} simulation {t:7.1f} s worker time, {1e3 * t / spec.count:7.1f} ms per "
            f"scenario, {vsteps / 1e6:6.2f} M vehicle-steps/s per worker"
        )
    for name, e in res.summary.items():
        print(
            f"  {name:10s} collisions {e['collisions']} ({e['collision_scenarios']} scenarios), "
            f"AEB steps {e['aeb_activations']} ({e['aeb_scenarios']} scenarios), "
            f"fallbacks {e['fallbacks']}"
        )


if __name__ == "__main__":
    main()
