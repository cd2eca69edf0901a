"""Fig. 11: snapshots of the string after vehicle 1 brakes
=======================================================

Fig. 11 of the paper (Section V-B): snapshots of the string after vehicle 1 brakes, looking
ahead only (upper rows) versus FD-LCC and CF-LCC (lower rows).

Runs ``problems/paper_table2.toml`` through the package's API and writes one PNG per LCC
variant under ``--out``. With ``--appendix-c`` it draws the heterogeneous, delayed Appendix C
scenario (first draw) instead (Fig. 15).

Usage: python examples/fig11_snapshots.py [--out DIR] [--appendix-c]   (default results)
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lcc_synth.cli.arguments import add_example_out
from lcc_synth.experiments.spec import load_spec
from lcc_synth.figures import plot_snapshots
from lcc_synth.simulation.engine import simulate_many

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"
TIMES = (20.5, 22.0, 25.0, 28.0, 32.0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_example_out(ap)
    ap.add_argument("--appendix-c", action="store_true")
    args = ap.parse_args()
    problem = "paper_appendix_c.toml" if args.appendix_c else "paper_table2.toml"
    spec = load_spec(PROBLEMS / problem, seeds=1 if args.appendix_c else None)
    res = simulate_many(spec.scenario, spec.controllers)
    prefix = "fig15" if args.appendix_c else "fig11"
    for name in ("fd_lcc", "cf_lcc"):
        out = plot_snapshots(
            res["all_hdv"], res[name], TIMES, Path(args.out) / f"{prefix}_{name}.png",
            title=f"{spec.name}: vehicle 1 brakes at t = 20 s",
            labels=("looking ahead only", name.replace("_", "-").upper()),
        )  # fmt: skip
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
