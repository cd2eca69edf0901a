"""The two tables of docs/guide/platoons.md ("Mixed platoons and the ring road"), measured.

Runs ``problems/platoon_deeplcc_brake.toml`` (every controller: fuel with the DeeP-LCC paper's
metric, its reduction against all_hdv, min spacing over the first CAV and behind) and
``problems/ring_stop_and_go.toml`` (velocity spread over the vehicles at 50 / 100 / 200 /
300 s, the lowest speed after 100 s, AAVE and fuel over 200-300 s) and prints both tables as
Markdown, with the wall time of each simulation.

    python benchmarks/bench_platoon_ring_tables.py
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from lcc_synth.experiments.spec import load_spec
from lcc_synth.metrics import summary
from lcc_synth.simulation.engine import simulate

ROOT = Path(__file__).resolve().parents[1] / "problems"


def main() -> None:
    warnings.simplefilter("ignore")
    spec = load_spec(ROOT / "platoon_deeplcc_brake.toml")
    rows = {}
    for name, ctrl in spec.controllers.items():
        t0 = time.perf_counter()
        res = simulate(spec.scenario, ctrl)
        rows[name] = (summary(res, spec.metrics), time.perf_counter() - t0)
    base = rows["all_hdv"][0]["fuel_ml"]
    print("| controller | fuel (mL) | reduction | min spacing (m) | AAVE (m/s) | run (s) |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, (s, wall) in rows.items():
        red = "(baseline)" if name == "all_hdv" else f"{100 * (1 - s['fuel_ml'] / base):.2f} %"
        print(f"| {name} | {s['fuel_ml']:.2f} | {red} | {s['min_spacing']:.2f} | "
              f"{s['aave']:.4f} | {wall:.1f} |")
    print()
    spec = load_spec(ROOT / "ring_stop_and_go.toml")
    print("| controller | std v at 50 / 100 / 200 / 300 s (m/s) | min speed after 100 s (m/s) "
          "| AAVE (m/s) | fuel (mL) | min spacing (m) | run (s) |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for name, ctrl in spec.controllers.items():
        t0 = time.perf_counter()
        res = simulate(spec.scenario, ctrl)
        wall = time.perf_counter() - t0
        s = summary(res, spec.metrics)
        std = res.velocity[0].std(axis=1)
        at = [std[int(np.argmin(np.abs(res.t - t)))] for t in (50.0, 100.0, 200.0, 300.0)]
        vmin = res.velocity[0, res.t >= 100.0].min()
        print(f"| {name} | {' / '.join(f'{x:.3g}' for x in at)} | {vmin:.2f} | {s['aave']:.4f} "
              f"| {s['fuel_ml']:.2f} | {s['min_spacing']:.2f} | {wall:.1f} |")


if __name__ == "__main__":
    main()
