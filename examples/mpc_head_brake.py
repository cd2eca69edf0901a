"""The safety-constrained MPC in the head-vehicle brake scenario
=============================================================

The safety-constrained MPC in the head-vehicle brake scenario, next to the paper's gains.

Runs ``problems/mpc_head_brake.toml`` (or the heterogeneous / noisy / lossy variant, or one of
the Table II MPC problems) through the package's API, prints per controller: AAVE, fuel, minimum
spacing and time-to-collision, violations of the absolute bound s_0 >= 5 m + 0.8 s * v_0 at
every simulation step, emergency-braking activations, MPC fallbacks and the per-step solve time;
writes the velocity/spacing profiles and the MPC's predicted trajectories as PNGs under
``--out`` (default results).

Usage: python examples/mpc_head_brake.py [--problem PATH] [--out DIR]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lcc_synth.cli.arguments import add_example_out
from lcc_synth.cli.simulate import report
from lcc_synth.experiments.spec import load_spec
from lcc_synth.figures import plot_mpc_predictions, plot_profiles
from lcc_synth.mpc.report import safety_summary
from lcc_synth.simulation.engine import simulate_many

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problem", default=str(PROBLEMS / "mpc_head_brake.toml"))
    add_example_out(ap)
    args = ap.parse_args()

    spec = load_spec(args.problem)
    results = simulate_many(spec.scenario, spec.controllers)
    rep = report(spec, results)
    mpc_names = [n for n, r in results.items() if r.controller_info.get("type") == "mpc"]
    s_min, t_gap = 5.0, 0.8
    if mpc_names:
        c = results[mpc_names[0]].controller_info["constraints"]
        s_min, t_gap = c["s_min"], c["t_gap"]

    print(f"{spec.name}: batch {spec.scenario.batch}; bound s0 >= {s_min:g} m + {t_gap:g} s * v0")
    head = (f"{'controller':<14} {'AAVE':>7} {'fuel mL':>8} {'min s':>6} {'min TTC':>7} "
            f"{'viol. steps':>11} {'max viol.':>9} {'AEB':>5} {'coll.':>5} {'fallb.':>6} "
            f"{'step ms med/p99/max':>22}")  # fmt: skip
    print(head)
    for name, res in results.items():
        e = rep[name]
        s = safety_summary(res, s_min, t_gap)
        fb = str(s.get("fallbacks", "-"))
        tm = s.get("step_time_ms")
        tms = f"{tm['median']:.2f}/{tm['p99']:.2f}/{tm['max']:.2f}" if tm else "-"
        print(f"{name:<14} {e['aave']:7.3f} {e['fuel_ml']:8.2f} {e['min_spacing']:6.2f} "
              f"{e['min_ttc']:7.2f} {s['bound_violation_steps']:11d} "
              f"{s['max_bound_violation_m']:9.3f} {s['aeb_activations']:5d} "
              f"{s['collisions']:5d} {fb:>6} {tms:>22}")  # fmt: skip

    out = Path(args.out)
    print(f"wrote {plot_profiles(results, out / f'{spec.name}_profiles.png', spec.name)}")
    for name in mpc_names:
        ctrl = spec.controllers[name]
        path = plot_mpc_predictions(
            results[name], ctrl.history(), out / f"{spec.name}_{name}_predictions.png",
            every=1.0, window=(15.0, 45.0), s_min=s_min, t_gap=t_gap,
            title=f"{spec.name}: {name} predictions every 1 s",
        )  # fmt: skip
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
