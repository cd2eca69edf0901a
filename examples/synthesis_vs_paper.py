"""Synthesised structured H2 gains against the paper's gains
=========================================================

Synthesised structured H2 gains vs the paper's Section V-B gains (FD-LCC and CF-LCC).

For each of ``problems/synth_fd_lcc_pattern.toml`` and ``problems/synth_cf_lcc_pattern.toml``:
synthesise the structured gain on the paper's pattern (CAV + HDVs 1, 2), write the gains file
(``lcc-synth synthesize --out``) under ``--out``, and compare with the paper's gain:

* linear: true H2 norm, closed-loop eigenvalues, string stability (CF-LCC);
* nonlinear: the Table II scenario of ``problems/paper_table2.toml`` (vehicle 1 brakes at
  -5 m/s^2 for 1 s) run by the package's simulator with the paper's controllers and the
  synthesised ``gains_file`` controllers: AAVE, fuel, minimum spacing.

Usage::

    python examples/synthesis_vs_paper.py [--weights q_s=0.1,q_v=1,r=1] [--out DIR] [--json]

``wrote PATH`` lines go to stdout, or to stderr with ``--json`` (stdout: the JSON object).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def parse_weights(text: str | None) -> dict[str, float]:
    if not text:
        return {}
    out = {}
    for item in text.split(","):
        key, val = item.split("=")
        out[key.strip()] = float(val)
    return out


def main() -> None:
    import sys

    from lcc_synth.cli.arguments import add_example_out
    from lcc_synth.experiments.controller_tables import controller_from_table
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.metrics import summary
    from lcc_synth.problem import load_problem
    from lcc_synth.simulation.engine import simulate
    from lcc_synth.synthesis.config import spec_from_problem
    from lcc_synth.synthesis.design import synthesize
    from lcc_synth.synthesis.gains_file import write_gains
    from lcc_synth.synthesis.h2 import Weights

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--weights", help="override weights, e.g. q_s=0.1,r=2")
    add_example_out(ap)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out_dir = Path(args.out)
    override = parse_weights(args.weights)

    sim = load_spec(ROOT / "problems" / "paper_table2.toml")
    draws = sim.scenario.draw()
    rows = {}
    linear = {}
    for kind in ("fd_lcc", "cf_lcc"):
        spec = spec_from_problem(load_problem(ROOT / "problems" / f"synth_{kind}_pattern.toml"))
        if override:
            spec = replace(spec, weights=Weights(**{**spec.weights.as_dict(), **override}))
        rep = synthesize(spec)
        path = write_gains(out_dir / f"synth_{kind}_gains.json", rep)
        print(f"wrote {path}", file=sys.stderr if args.json else sys.stdout)
        linear[kind] = {
            "synthesised": {
                "h2": rep.check.h2,
                "max_real_eig": rep.check.max_real_eig,
                "string_stable": rep.check.string_stable,
                "gamma_peak": rep.check.gamma_peak,
                "gains": {k: v for k, v in rep.gains.items() if v},
            },
            "paper": {
                k: rep.baseline[k]
                for k in ("h2", "max_real_eig", "string_stable", "gamma_peak")
            },
            "h2_unstructured": rep.h2_unstructured,
            "weights": rep.weights,
        }
        ctrl = controller_from_table(
            f"synth_{kind}", {"type": "gains_file", "file": str(path)}, sim.system, sim.source
        )
        for name, c in ((kind, sim.controllers[kind]), (f"synth_{kind}", ctrl)):
            res = simulate(sim.scenario, c, draws)
            s = summary(res, sim.metrics)
            rows[name] = {k: s[k] for k in ("aave", "fuel_ml", "min_spacing", "max_abs_command",
                                             "aeb_activations", "collisions")}
    base = simulate(sim.scenario, sim.controllers["all_hdv"], draws)
    sb = summary(base, sim.metrics)
    rows = {"all_hdv": {k: sb[k] for k in ("aave", "fuel_ml", "min_spacing", "max_abs_command",
                                           "aeb_activations", "collisions")}, **rows}
    if args.json:
        print(json.dumps({"linear": linear, "table2": rows}, indent=2, default=float))
        return
    print("Linear comparison on the paper's pattern (CAV + HDVs 1, 2), true H2 norms:")
    for kind, d in linear.items():
        s, p = d["synthesised"], d["paper"]
        extra = ""
        if s["string_stable"] is not None:
            extra = (f"  string stable: synthesised {s['string_stable']} "
                     f"(peak {s['gamma_peak']:.6f}), paper {p['string_stable']} "
                     f"(peak {p['gamma_peak']:.6f})")
        print(f"  {kind}: paper {p['h2']:.4f}  synthesised {s['h2']:.4f}  "
              f"(unstructured optimum {d['h2_unstructured']:.4f}){extra}")
        print(f"     gains: {s['gains']}")
    print("\nNonlinear Table II scenario (problems/paper_table2.toml), window 20-40 s:")
    print(f"  {'controller':<14s} {'AAVE m/s':>9s} {'fuel mL':>9s} {'min s m':>8s} "
          f"{'max|u|':>7s} {'AEB':>4s}")
    for name, r in rows.items():
        print(f"  {name:<14s} {r['aave']:9.4f} {r['fuel_ml']:9.2f} {r['min_spacing']:8.2f} "
              f"{r['max_abs_command']:7.2f} {r['aeb_activations']:4d}")


if __name__ == "__main__":
    main()
