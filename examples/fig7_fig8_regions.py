"""Figs. 7 and 8: string-stable regions of one vehicle's gains
===========================================================

Figs. 7 and 8 of the paper: head-to-tail string-stable regions of one vehicle's gains.

Reads ``problems/paper_fig7_fig8_regions.toml`` (m = n = 2, OVM at v* = 15 m/s, the paper's
grid mu, k in [-10, 10] step 0.02: 1001 x 1001 points per map, eight maps), prints the fraction
of each grid that is plant stable and string stable and, for Fig. 7(c)-(f), the area gained
over Fig. 7(a)(b), and writes all maps in one PNG.

Usage: python examples/fig7_fig8_regions.py [--out DIR] [--step STEP]
       (writes DIR/fig7_fig8_regions.png, default results; the file's step 0.02 unless given,
       e.g. --step 0.1 for a quick run)
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lcc_synth.analysis.region_specs import expansion, region_specs_from, run_region_specs
from lcc_synth.cli.arguments import add_example_out
from lcc_synth.figures import plot_region_maps
from lcc_synth.problem import load_problem, system_from

PROBLEM = Path(__file__).resolve().parents[1] / "problems" / "paper_fig7_fig8_regions.toml"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_example_out(ap)
    ap.add_argument("--step", type=float, help="grid step of every map (default: the file's)")
    args = ap.parse_args()
    out, step = Path(args.out) / "fig7_fig8_regions.png", args.step
    problem = load_problem(PROBLEM)
    system = system_from(problem.data, str(problem.path))
    model = system.linear_model()
    specs, omega = region_specs_from(problem.data, model, str(problem.path), step=step)
    maps = run_region_specs(model, specs, omega)
    print(f"{'map':<7} {'vehicle':>7} {'points':>9} {'plant stable':>13} {'string stable':>14}"
          f" {'gained':>8} {'time':>7}")
    for name, rm in maps.items():
        base = specs[name].baseline
        gained = f"{100 * expansion(rm, maps[base])['gained_fraction']:7.2f}%" if base else ""
        print(
            f"{name:<7} {rm.vehicle:>7} {rm.points:>9} {100 * rm.plant_stable_fraction:12.2f}% "
            f"{100 * rm.string_stable_fraction:13.2f}% {gained:>8} {rm.seconds:6.2f}s"
        )
    baselines = {n: maps[s.baseline] for n, s in specs.items() if s.baseline}
    path = plot_region_maps(maps, out, baselines, {n: s.title for n, s in specs.items()})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
