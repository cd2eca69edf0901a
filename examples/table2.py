"""Table II: AAVE and fuel of looking ahead only, FD-LCC and CF-LCC
================================================================

Table II of the paper (Section V-B): AAVE and fuel of "looking ahead only", FD-LCC, CF-LCC.

Runs ``problems/paper_table2.toml`` through the package's API, prints the table with the paper's
numbers beside ours and writes a bar chart under ``--out``. With ``--appendix-c N`` it also runs the
heterogeneous, delayed Appendix C scenario over N random draws and prints the mean and spread
of the reductions (the paper reports one draw).

Usage: python examples/table2.py [--out DIR] [--appendix-c N]   (DIR/table2.png, default results)
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lcc_synth.cli.arguments import add_example_out
from lcc_synth.cli.simulate import report
from lcc_synth.experiments.spec import load_spec
from lcc_synth.figures import plot_metric_bars
from lcc_synth.simulation.engine import simulate_many

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"
PAPER = {"all_hdv": (0.89, 392.86), "fd_lcc": (0.58, 321.94), "cf_lcc": (0.81, 340.56)}
PAPER_C = {"fd_lcc": (23.0, 17.55), "cf_lcc": (8.77, 13.72)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_example_out(ap)
    ap.add_argument("--appendix-c", type=int, default=0, metavar="N")
    args = ap.parse_args()

    spec = load_spec(PROBLEMS / "paper_table2.toml")
    rep = report(spec, simulate_many(spec.scenario, spec.controllers))
    print(f"{'controller':<10} {'AAVE':>8} {'paper':>6} {'fuel (mL)':>10} {'paper':>8} "
          f"{'AAVE red.':>10} {'fuel red.':>10}")  # fmt: skip
    for name, e in rep.items():
        red = e.get("reduction_vs_baseline")
        ra = f"{red['aave_pct']:.2f} %" if red else "/"
        rf = f"{red['fuel_pct']:.2f} %" if red else "/"
        pa, pf = PAPER[name]
        print(f"{name:<10} {e['aave']:8.4f} {pa:6.2f} {e['fuel_ml']:10.3f} {pf:8.2f} "
              f"{ra:>10} {rf:>10}")  # fmt: skip
    title = "Table II: vehicle 1 brakes at t = 20 s"
    out = plot_metric_bars(rep, Path(args.out) / "table2.png", title)
    print(f"wrote {out}")

    if args.appendix_c:
        spec_c = load_spec(PROBLEMS / "paper_appendix_c.toml", seeds=args.appendix_c)
        rep_c = report(spec_c, simulate_many(spec_c.scenario, spec_c.controllers))
        print(f"\nAppendix C over {args.appendix_c} draws (mean ± std of the paired reductions):")
        for name, (pa, pf) in PAPER_C.items():
            r = rep_c[name]["reduction_vs_baseline"]
            print(f"  {name}: AAVE -{r['aave_pct']:.2f} ± {r['aave_pct_std']:.2f} % "
                  f"(paper -{pa} %), fuel -{r['fuel_pct']:.2f} ± {r['fuel_pct_std']:.2f} % "
                  f"(paper -{pf} %)")  # fmt: skip
        out_c = Path(args.out) / "table2_appendix_c.png"
        plot_metric_bars(rep_c, out_c, f"Appendix C: {args.appendix_c} heterogeneous draws")
        print(f"wrote {out_c}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
