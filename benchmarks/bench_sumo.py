"""SUMO versus the built-in simulator on ``problems/sumo_head_brake.toml``: the table of both
(AAVE, fuel, minimum spacing per controller), their differences, and the wall time of each run
(median of ``--repeat`` runs, after one warm-up run that compiles the built-in kernels).
Also the cross-check's figures for both SUMO step methods and at dt = 0.05 s.

    python benchmarks/bench_sumo.py [--repeat 3] [--json rows.json]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from lcc_synth.experiments.spec import load_spec
from lcc_synth.metrics import aggregate, per_scenario
from lcc_synth.simulation.backends import run_scenario

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", help="write the rows here")
    args = ap.parse_args()
    spec = load_spec(ROOT / "problems" / "sumo_head_brake.toml")
    rows = []
    for method in ("euler", "ballistic"):
        for dt in (0.01, 0.05):
            sumo = replace(spec.scenario, dt=dt, sumo=replace(spec.scenario.sumo,
                                                              step_method=method))  # fmt: skip
            builtin = replace(sumo, backend="builtin")
            for name, ctrl in spec.controllers.items():
                res, wall = {}, {}
                for tag, sc in (("sumo", sumo), ("builtin", builtin)):
                    run_scenario(sc, ctrl)  # warm-up (numba compilation, netconvert)
                    times = []
                    for _ in range(args.repeat):
                        t0 = time.perf_counter()
                        res[tag] = run_scenario(sc, ctrl)
                        times.append(time.perf_counter() - t0)
                    wall[tag] = float(np.median(times))
                m = {k: aggregate(per_scenario(r, spec.metrics)) for k, r in res.items()}
                row = {
                    "method": method, "dt": dt, "controller": name,
                    "max_dv": float(np.nanmax(np.abs(res["sumo"].velocity
                                                     - res["builtin"].velocity))),
                    "max_ds": float(np.nanmax(np.abs(res["sumo"].spacing
                                                     - res["builtin"].spacing))),
                    **{f"{k}_{tag}": float(m[tag][k]) for tag in m
                       for k in ("aave", "fuel_ml", "min_spacing")},
                    "wall_sumo_s": wall["sumo"], "wall_builtin_s": wall["builtin"],
                }  # fmt: skip
                rows.append(row)
                print(
                    f"{method:9s} dt={dt:<5g} {name:8s} max|dv| {row['max_dv']:.4f} m/s  "
                    f"max|ds| {row['max_ds']:.4f} m  AAVE {row['aave_sumo']:.4f} / "
                    f"{row['aave_builtin']:.4f}  fuel {row['fuel_ml_sumo']:.2f} / "
                    f"{row['fuel_ml_builtin']:.2f}  min s {row['min_spacing_sumo']:.2f} / "
                    f"{row['min_spacing_builtin']:.2f}  wall {wall['sumo']:.3f} / "
                    f"{wall['builtin']:.3f} s (SUMO / built-in)",
                    flush=True,
                )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
