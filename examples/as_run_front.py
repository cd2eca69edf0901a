"""A CAV that damps waves as it runs? The as-run front of the showcase's string10
==============================================================================

Designs the showcase's ``h2`` controller on string10 (gain on the pattern CAV + HDVs 1, 2,
equilibrium-estimator and measurement-filter time constants, sample time 0.1 s) on the loop
as it runs (:mod:`lcc_synth.synthesis.as_run_dynamics`) for decreasing bounds on the peak
``|Gamma|`` at V2V latency 0 and 0.1 s, finds the lowest peak the structure reaches from many
starts, simulates every point on ``head_brake`` and ``heterogeneous`` and writes the Pareto
front (peak as run against head_brake AAVE, minimum gap and 1 s jerk) under ``--out``.

Usage::

    python examples/as_run_front.py [--problem FILE] [--starts N] [--maxfev N] [--out DIR]
    (DIR/as_run_front.csv, DIR/as_run_front.png)
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    from lcc_synth.cli.arguments import add_example_out
    from lcc_synth.experiments.as_run_front import as_run_front, front_csv
    from lcc_synth.figures import plot_as_run_front
    from lcc_synth.outputs import write_text
    from lcc_synth.synthesis.as_run_dynamics import DynamicsSettings

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problem", default=str(ROOT / "problems" / "showcase.toml"))
    ap.add_argument("--starts", type=int, default=4, help="starts per bound (default 4)")
    ap.add_argument("--maxfev", type=int, default=400, help="evaluations per start (400)")
    ap.add_argument("--cert-starts", type=int, default=12,
                    help="starts of the lowest-peak search (default 12)")
    ap.add_argument("--gap-bound", type=float, default=None,
                    help="bound on the CAV's gap response |s_0/v_h| as a multiple of today's "
                    "h2 (>= 1; default none)")
    add_example_out(ap)
    args = ap.parse_args()

    st = DynamicsSettings(starts=args.starts, maxfev=args.maxfev, gap_bound=args.gap_bound)
    cert = replace(st, starts=args.cert_starts)
    front = as_run_front(args.problem, settings=st, certificate=cert, progress=print)
    cert = front.certificate
    print(f"lowest peak |Γ| as run: {cert.point.peak:.4f} (latency 0: {cert.point.peaks[0]:.4f}, "
          f"0.1 s: {cert.point.peaks[-1]:.4f}) from {cert.starts} starts "
          f"({cert.unstable_starts} unstable), {cert.evaluations} evaluations, "
          f"{cert.seconds:.0f} s; exact verdict "
          f"{'string stable' if cert.string_stable else 'not string stable'}")
    print(f"{'name':>14s} {'peak0':>7s} {'peak.1':>7s} {'ss':>3s} {'gap':>5s} {'tau':>7s} "
          f"{'tau_f':>6s} "
          f"{'AAVE hb':>8s} {'gap hb':>7s} {'jerk hb':>7s} {'AEB hb':>6s} {'AAVE he':>8s} "
          f"{'fuel he':>8s} {'gap he':>7s} {'AEB he':>6s}")
    for p in front.points:
        v = p.values()
        print(f"{p.name:>14s} {v['peak_lat0']:7.4f} {v['peak_lat01']:7.4f} "
              f"{'y' if p.string_stable else 'n':>3s} {v['gap_peak']:5.2f} "
              f"{v['equilibrium_tau']:7.3f} "
              f"{v['measurement_filter']:6.3f} {v['aave_head_brake']:8.4f} "
              f"{v['min_gap_head_brake']:7.2f} {v['jerk1s_head_brake']:7.2f} "
              f"{v['aeb_head_brake']:6d} {v['aave_heterogeneous']:8.4f} "
              f"{v['fuel_heterogeneous']:8.1f} {v['min_gap_heterogeneous']:7.2f} "
              f"{v['aeb_heterogeneous']:6d}")
        print(f"{'':>14s} gains {', '.join(f'{k} {g:.4g}' for k, g in p.point.gains.items())}")
    out = Path(args.out)
    print(f"wrote {write_text(out / 'as_run_front.csv', front_csv(front), overwrite=True)}")
    print(f"wrote {plot_as_run_front(front.points, out / 'as_run_front.png')}")


if __name__ == "__main__":
    main()
