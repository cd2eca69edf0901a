"""Fig. 5 in multiprecision: the digits achieved, and the time, for n = 1..30 (FD-LCC, paper's
parameters, t = 10, 20, 30 s).

For every size: the float64 values where they exist; ``lambda_min`` and ``tr(W^-1)`` at fixed
50 and 100 working digits (the digits they agree on show what a fixed precision keeps: about
``50 - log10(cond)``); and the adaptive precision of ``energy_vs_size(method="mp")`` against
50 more digits, compared as multiprecision numbers (not rounded to float64), next to the
estimate ``digits`` that the report states.

Usage: python benchmarks/bench_fig5_digits.py [N_MAX]   (default 30; several minutes at 30)
"""

from __future__ import annotations

import math
import sys
import time

import mpmath as mp

from lcc_synth.analysis.energy import energy_vs_size, gramians_mp
from lcc_synth.models.hdv import OVM, linear_coefficients
from lcc_synth.models.linear import build_model

HORIZONS = (10.0, 20.0, 30.0)


def agreed(a, b) -> float:
    """Significant digits on which ``a`` agrees with the reference ``b`` (capped at 99)."""
    with mp.workdps(600):
        a, b = mp.mpf(a), mp.mpf(b)
        return 99.0 if a == b else min(99.0, float(-mp.log10(abs(a - b) / abs(b))))


def metrics(model, dps: int):
    """``[(lambda_min, tr(W^-1))]`` per horizon, as mpmath numbers at ``dps`` digits."""
    out = []
    for W in gramians_mp(model.A, model.B, HORIZONS, dps):
        with mp.workdps(dps):
            lam = sorted(mp.eigsy(W, eigvals_only=True))
            out.append((+lam[0], mp.fsum(1 / x for x in lam)))
    return out


def main(argv: list[str]) -> int:
    n_max = int(argv[0]) if argv else 30
    coef = linear_coefficients(
        OVM(alpha=0.6, beta=0.9, v_max=30.0, s_st=5.0, s_go=35.0), v_star=15.0
    )
    t0 = time.perf_counter()
    sweep = energy_vs_size(coef, HORIZONS, n_max=n_max, method="mp", digits=10)
    print(f"energy_vs_size(method='mp') n = 1..{n_max}, 3 horizons: "
          f"{time.perf_counter() - t0:.1f} s")
    dbl = energy_vs_size(coef, HORIZONS, n_max=n_max)
    print(f"{'t':>4} {'n':>3} {'cond':>9} | {'float64 lam/tr':>14} | {'50 vs 100 lam/tr':>16} | "
          f"{'dps':>4} {'estimate':>8} {'vs +50 lam/tr':>13}")
    for n in range(1, n_max + 1):
        model = build_model("fd_lcc", 0, n, coef)
        reps = [sweep.reports[t][n - 1] for t in HORIZONS]
        work = round(max(r.digits + math.log10(r.condition) + 1 for r in reps))
        m50, m100 = metrics(model, 50), metrics(model, 100)
        ma, mb = metrics(model, work), metrics(model, work + 50)
        for i, (t, r) in enumerate(zip(HORIZONS, reps, strict=True)):
            d = dbl.reports[t][n - 1] if n <= len(dbl.reports[t]) else None
            f64 = (f"{agreed(d.lambda_min, mb[i][0]):6.1f} {agreed(d.trace_inv, mb[i][1]):5.1f}"
                   if d else f"{'singular':>12}")
            fix = f"{agreed(m50[i][0], m100[i][0]):6.1f} {agreed(m50[i][1], m100[i][1]):5.1f}"
            ada = f"{agreed(ma[i][0], mb[i][0]):6.1f} {agreed(ma[i][1], mb[i][1]):5.1f}"
            print(f"{t:4g} {n:3d} {r.condition:9.2e} | {f64:>14} | {fix:>16} | {work:4d} "
                  f"{r.digits:8.1f} {ada:>13}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
