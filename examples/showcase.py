"""The showcase comparison from Python
===================================

The showcase comparison from Python: one scenario of ``problems/showcase.toml``, every
controller, the metrics table and the velocity / spacing profiles.

``lcc-synth run`` does the same for every scenario (plus files, figures and a recording); this
script shows the API underneath: ``load_suite`` -> ``run_suite`` -> table and figure.

Usage: python examples/showcase.py [SCENARIO] [--out DIR]   (default head_brake, results)
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lcc_synth.cli.arguments import add_example_out
from lcc_synth.experiments.comparison import load_suite, run_suite
from lcc_synth.experiments.tables import format_table
from lcc_synth.figures import plot_profiles

PROBLEM = Path(__file__).resolve().parents[1] / "problems" / "showcase.toml"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenario", nargs="?", default="head_brake")
    add_example_out(ap)
    args = ap.parse_args()
    suite = load_suite(PROBLEM, scenarios=[args.scenario])
    run = run_suite(suite)
    print(format_table(run.table))
    for layout, designs in run.designs.items():
        for name, rep in designs.items():
            heard = ", ".join(str(v) for v in rep.pattern)
            print(f"{layout}/{name}: hears vehicles {heard}; true H2 {rep.check.h2:.4f}")
    ss = suite.scenarios[args.scenario]
    path = plot_profiles(
        run.results[args.scenario], Path(args.out) / f"profiles_{args.scenario}.png",
        title=ss.title or args.scenario,
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
