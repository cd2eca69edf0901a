"""Fig. 5 of the paper: control energy of FD-LCC against the number of HDVs behind the CAV.

lambda_min(W(t)) and tr(W(t)^-1) for t = 10, 20, 30 s with the paper's OVM parameters
(alpha 0.6, beta 0.9, v_max 30, s_st 5, s_go 35, v* 15). Each curve stops at the size where the
Gramian becomes numerically singular in double precision, and the script says where.

Usage: python examples/fig5_control_energy.py [--out DIR]   (writes DIR/fig5_control_energy.png,
default results)
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
    out = Path(ap.parse_args().out) / "fig5_control_energy.png"
    coef = linear_coefficients(
        OVM(alpha=0.6, beta=0.9, v_max=30.0, s_st=5.0, s_go=35.0), v_star=15.0
    )
    sweep = energy_vs_size(coef, horizons=(10.0, 20.0, 30.0), n_max=30, kind="fd_lcc")
    print(f"alpha1 = {coef.alpha1:.6f}, alpha2 = {coef.alpha2:g}, alpha3 = {coef.alpha3:g}")
    for t, reports in sweep.reports.items():
        print(f"t = {t:g} s")
        print(f"  {'n':>3} {'lambda_min(W)':>14} {'tr(W^-1)':>12} {'cond(W)':>10}")
        for r in reports:
            print(f"  {r.n:>3} {r.lambda_min:14.4e} {r.trace_inv:12.4e} {r.condition:10.3e}")
        err = sweep.singular[t]
        if err is not None:
            print(f"  stopped: {err}")
    path = plot_control_energy(sweep, out)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
