"""Fig. 9: head-to-tail frequency response of Table I's cases
==========================================================

Fig. 9 of the paper: the head-to-tail magnitude of Gamma(jw) for Table I's gain cases (m = n = 2).

Reads ``problems/paper_fig9_cases.toml`` (OVM alpha 0.6, beta 0.9, v_max 30, s_st 5, s_go 35,
v* 15; the CAV's HDV law plus the added gains of Table I), prints each case's plant stability,
string-stability verdict and peak ``|Gamma|`` (global search), and writes the frequency response.

Usage: python examples/fig9_frequency_response.py [--out DIR] [--problem PROBLEM.toml]
       (writes DIR/fig9_frequency_response.png, default results; problems/paper_fig9_cases.toml)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from lcc_synth.analysis.cases import analysis_options_from, cases_from
from lcc_synth.analysis.string_stability import string_stability
from lcc_synth.analysis.transfer import gamma_state_space
from lcc_synth.cli.arguments import add_example_out
from lcc_synth.figures import plot_gamma_curves
from lcc_synth.models.feedback import input_feedback
from lcc_synth.problem import load_problem, system_from

DEFAULT = Path(__file__).resolve().parents[1] / "problems" / "paper_fig9_cases.toml"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_example_out(ap)
    ap.add_argument("--problem", default=str(DEFAULT))
    args = ap.parse_args()
    out = Path(args.out) / "fig9_frequency_response.png"
    problem = load_problem(args.problem)
    system = system_from(problem.data, str(problem.path))
    model = system.linear_model()
    options = analysis_options_from(problem.data, str(problem.path))
    omega = options.omega()
    curves = {}
    print(f"{'case':<10} {'plant':<9} {'string':<10} {'peak |Gamma|':>12} {'at w (rad/s)':>13}")
    for name, case in cases_from(problem.data, model, str(problem.path)).items():
        K, kh = input_feedback(model, case.gains)
        rep = string_stability(model, K, kh, method=options.method)
        curves[case.label] = (np.abs(gamma_state_space(model, K, kh, omega)), rep)
        print(
            f"{name:<10} {'stable' if rep.plant_stable else 'UNSTABLE':<9} "
            f"{'stable' if rep.string_stable else 'unstable':<10} "
            f"{rep.gamma_peak:12.6f} {rep.gamma_peak_omega:13.4f}"
        )
    path = plot_gamma_curves(curves, omega, out, title="Head-to-tail |Γ(jω)|, Table I (Fig. 9)")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
