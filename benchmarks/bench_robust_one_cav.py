"""Robust multi-model H2 design of one-CAV strings (``[synthesis.robust]`` on kind = "lcc",
"cf_lcc", "ccc"; :mod:`lcc_synth.synthesis.robust_string`): time and value.

Per string (OVM defaults at 15 m/s, q_s = 0.5, q_v = 1, r = 0.7, head = 0.5, unit acceleration
noise; members: alpha 0.6 +- 0.15, beta 0.9 +- 0.2, s_go 35 +- 3 per vehicle, ``--samples``
members, seed 0) and objective (mean, worst), one BLAS thread as ``synthesize`` runs:

* ``time``     :func:`~lcc_synth.synthesis.design.synthesize` end to end (best of ``--repeat``);
* ``iters``    descent iterations of the robust stage;
* the members' mean and worst true H2 of the nominal structured gain and of the robust gain;
* ``vs platoon`` the largest difference between the CAV's whole command of the string's gain
  (in its semantics, :func:`~lcc_synth.models.feedback.cav_feedback`) and the gain the same
  robust design gives on the equivalent ``kind = "platoon"`` file.

Usage::

    python benchmarks/bench_robust_one_cav.py [--samples 20] [--repeat 3]
"""

from __future__ import annotations

import argparse
import math
import time
import tomllib
from pathlib import Path

import numpy as np

HDV = '[hdv]\nmodel = "ovm"\n'
WEIGHTS = "[synthesis.weights]\nq_s = 0.5\nq_v = 1.0\nr = 0.7\nhead = 0.5\naccel = 1.0\n"

#: name -> (the [system] table, m, n, semantics, the one-CAV pattern or None for all)
STRINGS = {
    "cf_lcc n=10 [1, 2]": ('kind = "cf_lcc"\nn = 10', 0, 10, "replace", [1, 2]),
    "lcc m=2 n=8 all": ('kind = "lcc"\nm = 2\nn = 8', 2, 8, "added", None),
    "ccc m=5 [-2, -1]": ('kind = "ccc"\nm = 5', 5, 0, "added", [-2, -1]),
}


def _spec(system: str, synthesis: str, robust: str):
    from lcc_synth.problem import Problem
    from lcc_synth.synthesis.config import spec_from_problem

    text = (f'name = "b"\n{HDV}[system]\n{system}\nv_star = 15.0\n[synthesis]\n'
            f'design = "structured"\n{synthesis}\n{WEIGHTS}{robust}')
    return spec_from_problem(Problem(Path("b.toml"), tomllib.loads(text)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    from lcc_synth.models.feedback import cav_feedback
    from lcc_synth.synthesis.design import synthesize

    print(f"{'string':<20s} {'objective':<9s} {'time':>7s} {'iters':>5s}  "
          f"{'nominal mean/worst':>20s}  {'robust mean/worst':>20s}  vs platoon")
    for label, (system, m, n, sem, pattern) in STRINGS.items():
        pat = "" if pattern is None else f"pattern = {pattern}"
        for objective in ("mean", "worst"):
            robust = (f'[synthesis.robust]\nsamples = {args.samples}\nseed = 0\nobjective = '
                      f'"{objective}"\nalpha = [0.45, 0.75]\nbeta = [0.7, 1.1]\n'
                      "s_go = [32.0, 38.0]\n")
            spec = _spec(system, f'semantics = "{sem}"\n{pat}', robust)
            best, rep = math.inf, None
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                rep = synthesize(spec)
                best = min(best, time.perf_counter() - t0)
            cav = m + 1
            heard = ("" if pattern is None else
                     f"[synthesis.patterns]\nu_{cav} = {[v + cav for v in pattern]}\n")
            prep = synthesize(_spec(f'kind = "platoon"\nsize = {m + n + 1}\ncavs = [{cav}]',
                                    f'semantics = "replace"\n{heard}', robust))
            whole, _ = cav_feedback(spec.system.linear_model(warn=False), rep.gain)
            diff = float(np.max(np.abs(whole - np.asarray(prep.K[0], float))))
            rb = rep.robust
            nom, rob = rb["nominal_design"], rb["robust_design"]
            print(f"{label:<20s} {objective:<9s} {best:7.3f} {rb['iterations']:>5d}  "
                  f"{nom['mean_h2']:9.5f}/{nom['worst_h2']:<10.5f}  "
                  f"{rob['mean_h2']:9.5f}/{rob['worst_h2']:<10.5f}  {diff:.1e}")


if __name__ == "__main__":
    main()
