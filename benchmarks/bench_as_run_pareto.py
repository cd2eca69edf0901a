"""Pareto front of the showcase's string10 H2 gain as run: string-stability (as-run peak |Γ| and
margin, equilibrium = "estimated") against AAVE / fuel of head_brake, heterogeneous and
brake_behind, over the trade-off weight of ``[synthesis.as_run]`` (lcc_synth.synthesis.as_run).

    python benchmarks/bench_as_run_pareto.py [--weights 0,1,10,100,1000] [--tau 1.0]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from lcc_synth.experiments.comparison import load_suite, metrics_row, synthesize_table
from lcc_synth.experiments.controller_tables import controller_from_table
from lcc_synth.experiments.string_as_run import controller_loop, measured_ratio
from lcc_synth.simulation.engine import simulate

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--weights", default="0,1,10,100,1000,10000")
    ap.add_argument("--tau", type=float, default=1.0)
    ap.add_argument("--q-s0", type=float, help="weight on the CAV's own gap (default: q_s)")
    ap.add_argument("--measure", action="store_true", help="also simulate the amplitude ratio")
    ap.add_argument("--json", help="write the rows here")
    args = ap.parse_args()
    suite = load_suite(ROOT / "problems" / "showcase.toml")
    system = suite.layouts["string10"]
    base = {k: v for k, v in suite.controllers["h2"].items() if k != "layouts"}
    base.update(suite.controllers["h2"]["layouts"]["string10"])
    base["equilibrium_tau"] = args.tau
    if args.q_s0 is not None:
        base["weights"] = {**base["weights"], "q_s0": args.q_s0}
    rows = []
    for w in [float(x) for x in args.weights.split(",")]:
        table = dict(base)
        table["as_run"] = {"weight": w}
        t0 = time.perf_counter()
        static, rep = synthesize_table("h2", table, system, "pareto")
        t_syn = time.perf_counter() - t0
        ctrl = controller_from_table("h2", static, system)
        loop_rep = rep.as_run["after"]
        row = {"weight": w, "q_s0": args.q_s0, "peak": loop_rep["gamma_peak"],
               "margin": loop_rep["margin"],
               "verdict": loop_rep["verdict"], "h2": rep.as_run["h2_after"],
               "gains": {k: round(v, 4) for k, v in rep.gains.items() if v}, "synth_s": t_syn}
        for sname in ("brake_behind", "head_brake", "heterogeneous"):
            ss = suite.scenarios[sname]
            m = metrics_row(simulate(ss.scenario, ctrl), ss.metrics)
            row[sname] = {k: m[k] for k in ("aave", "fuel_ml", "min_spacing", "aeb_activations",
                                             "collisions") if k in m}
        if args.measure:
            wm = np.array([0.01, 0.03, 0.1, 0.3, 1.0])
            row["measured"] = dict(zip(wm.tolist(), measured_ratio(ctrl, system, wm).tolist(),
                                       strict=True))
            row["analysed"] = dict(zip(wm.tolist(), np.abs(
                controller_loop(ctrl, system).response(wm)).tolist(), strict=True))
        rows.append(row)
        print(json.dumps(row), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
