"""Figs. 10 and 12: velocity and spacing profiles of Section V-A
=============================================================

Figs. 10 and 12 of the paper (Section V-A, Appendix B): velocity and spacing profiles of the
m = n = 2 string when the head vehicle oscillates, for Table I's cases A-D (and HDV only).

Runs ``problems/paper_sec5a.toml`` through the package's API, prints the peak velocity
deviation of the CAV and the two HDVs behind per case (it shrinks from case A to case D) and
writes two PNGs under ``--out``.

Usage: python examples/fig10_fig12_sec5a_profiles.py [--out DIR]   (default results)
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lcc_synth.cli.arguments import add_example_out
from lcc_synth.experiments.spec import load_spec
from lcc_synth.figures import plot_case_grid
from lcc_synth.metrics import max_abs_velocity_error
from lcc_synth.simulation.engine import simulate_many

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_example_out(ap)
    out = Path(ap.parse_args().out)
    spec = load_spec(PROBLEMS / "paper_sec5a.toml")
    res = simulate_many(spec.scenario, spec.controllers)
    print("peak |v - v*| (m/s)   head   HDV-2  HDV-1    CAV   HDV1   HDV2")
    for name, r in res.items():
        row = " ".join(f"{x:6.3f}" for x in max_abs_velocity_error(r)[0])
        print(f"{name:<20} {row}")
    cases = {k: v for k, v in res.items() if k.startswith("case_")}
    a = plot_case_grid(cases, out / "sec5a_fig10_velocity.png", "velocity",
                       title="Fig. 10: velocity, head sine 0.2 m/s² from t = 20 s")  # fmt: skip
    b = plot_case_grid(cases, out / "sec5a_fig12_spacing.png", "spacing",
                       title="Fig. 12: spacing, head sine 0.2 m/s² from t = 20 s")  # fmt: skip
    print(f"wrote {a}\nwrote {b}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
