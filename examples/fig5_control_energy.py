"""Fig. 5: control energy against the number of HDVs
=================================================

Fig. 5 of the paper: control energy of FD-LCC against the number of HDVs behind the CAV.

lambda_min(W(t)) and tr(W(t)^-1) for t = 10, 20, 30 s with the paper's OVM parameters
(alpha 0.6, beta 0.9, v_max 30, s_st 5, s_go 35, v* 15), for n = 1..30: the paper stops at small
n because W(t) is numerically singular in double precision (float64 here stops at n = 5 / 6 / 6);
the multiprecision Gramian (``method="mp"``, 10 significant digits asked, mpmath) goes on to
n = 30 (cond(W) up to ~1e153). The plot draws both: lines multiprecision, circles float64.
About a minute.

Usage: python examples/fig5_control_energy.py [--out DIR] [--n-max N]   (writes
DIR/fig5_control_energy.png, default results; --n-max, default 30, the longest string)
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lcc_synth.analysis.energy import energy_vs_size
from lcc_synth.cli.arguments import add_example_out
from lcc_synth.figures import plot_control_energy
from lcc_synth.models.hdv import OVM, linear_coefficients


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_example_out(ap)
    ap.add_argument("--n-max", type=int, default=30, help="longest string n (default 30)")
    args = ap.parse_args()
    if not 1 <= args.n_max <= 60:
        ap.error(f"--n-max must be an integer in [1, 60], got {args.n_max}")
    out = Path(args.out) / "fig5_control_energy.png"
    coef = linear_coefficients(
        OVM(alpha=0.6, beta=0.9, v_max=30.0, s_st=5.0, s_go=35.0), v_star=15.0
    )
    horizons = (10.0, 20.0, 30.0)
    double = energy_vs_size(coef, horizons=horizons, n_max=args.n_max, kind="fd_lcc")
    sweep = energy_vs_size(coef, horizons=horizons, n_max=args.n_max, kind="fd_lcc", method="mp")
    print(f"alpha1 = {coef.alpha1:.6f}, alpha2 = {coef.alpha2:g}, alpha3 = {coef.alpha3:g}")
    for t, reports in sweep.reports.items():
        print(f"t = {t:g} s")
        print(f"  {'n':>3} {'lambda_min(W)':>14} {'tr(W^-1)':>12} {'cond(W)':>10} "
              f"{'est. digits':>11} {'float64 lambda_min':>18}")
        for r, d in zip(reports, double.reports[t] + [None] * len(reports), strict=False):
            f64 = f"{d.lambda_min:18.10e}" if d else f"{'singular':>18}"
            print(f"  {r.n:>3} {r.lambda_min:14.4e} {r.trace_inv:12.4e} {r.condition:10.3e} "
                  f"{r.digits:11.1f} {f64}")
        err = double.singular[t]
        if err is not None:
            print(f"  float64 stopped: {err}")
    path = plot_control_energy(sweep, out, reference=double)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
