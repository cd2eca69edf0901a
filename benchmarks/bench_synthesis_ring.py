"""Ring-road H2 synthesis time and value: one AV (the last vehicle, semantics "replace"), OVM
defaults at 15 m/s, q_s = 0.03, q_v = 0.15, r = 1, unit acceleration noise on every vehicle
(the problem files ``problems/ring_n20_*.toml``, ``ring_n40_cr5.toml``).

Per ring size N and communication range R (wall-clock seconds, best of ``--repeat``, one BLAS
thread as ``synthesize`` runs):

* ``riccati``  full-information optimum (CARE on the 2N - 1 reduced states);
* ``start``    truncated Riccati gain modulo c (or the penalty continuation), stability check;
* ``polish``   Newton descent on the true H2 with the pattern's mask;
* ``total``    :func:`~lcc_synth.synthesis.design.synthesize` end to end
               (model, plant, every stage, checks, report);

with the true H2 norm after each stage. ``--lmi`` also times the plain full-state H2 LMI
(Clarabel, one dense cone) on the reduced ring and, per range, ``method = "lmi"`` of the
structured design (the convex restriction: its time, bound and gain's H2, then the polish).
``--sparsity`` times ``design = "sparsity"`` (the greedy range front) per size. ``--robust``
runs the robust mean design (N = 20, R = 5, 20 members, alpha 0.6 +- 0.15, beta 0.9 +- 0.2,
s_go 35 +- 3) and prints the per-member summary. ``--cli`` times ``lcc-synth synthesize
problems/ring_n20_cr5.toml --json`` (a fresh process: imports included).

Usage::

    python benchmarks/bench_synthesis_ring.py [--sizes 20 40] [--ranges 5 -1] [--repeat 3]
        [--lmi] [--sparsity] [--robust] [--cli]

(``--ranges -1`` = full information.)
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _spec(N: int, R: int, robust: str = "", design: str | None = None):
    import tomllib

    from lcc_synth.problem import Problem
    from lcc_synth.synthesis.config import spec_from_problem

    design = design or ('design = "full_state"' if R < 0
                        else f'design = "structured"\ncomm_range = {R}')  # fmt: skip
    text = (f'name = "ring"\n[hdv]\nmodel = "ovm"\n[system]\nkind = "ring"\nsize = {N}\n'
            f'cavs = [{N}]\nv_star = 15.0\n[synthesis]\n{design}\nsemantics = "replace"\n'
            '[synthesis.weights]\nq_s = 0.03\nq_v = 0.15\nr = 1.0\naccel = 1.0\n' + robust)
    return spec_from_problem(Problem(Path("ring.toml"), tomllib.loads(text)))


def run_case(N: int, R: int, repeat: int) -> dict:
    from lcc_synth.synthesis.design import synthesize

    best, rep = math.inf, None
    for _ in range(repeat):
        spec = _spec(N, R)
        t0 = time.perf_counter()
        rep = synthesize(spec)
        best = min(best, time.perf_counter() - t0)
    stages = {s["stage"].split()[0]: s for s in rep.stages}
    return {"N": N, "R": "full" if R < 0 else R, "states": 2 * N - 1, "total": best,
            "stages": stages, "h2": rep.check.h2, "polish": rep.polish}  # fmt: skip


def time_lmi(N: int) -> tuple[float, float]:
    """Plain full-state H2 LMI on the reduced ring (Clarabel): solve time and its gain's H2."""
    from lcc_synth.models.hdv import OVM
    from lcc_synth.models.platoon import Platoon, platoon_model
    from lcc_synth.synthesis.h2 import Weights, make_platoon_plant, platoon_h2
    from lcc_synth.synthesis.lmi import lmi_full_state

    M = platoon_model(Platoon((OVM(),) * N, (N,), 15.0, ring=True), warn=False)
    p = make_platoon_plant(M, "replace", Weights(q_s=0.03, q_v=0.15, r=1.0, accel=1.0))
    t0 = time.perf_counter()
    res = lmi_full_state(p)
    dt = time.perf_counter() - t0
    return dt, platoon_h2(p, res.g)


def time_restriction(N: int, R: int) -> dict:
    """``design = "structured"`` with ``method = "lmi"``: the convex restriction's solve time,
    bound and gain's true H2, the start chosen, the total and the final H2."""
    from lcc_synth.synthesis.design import synthesize

    spec = _spec(N, R, design=f'design = "structured"\ncomm_range = {R}\nmethod = "lmi"')
    t0 = time.perf_counter()
    rep = synthesize(spec)
    return {"total": time.perf_counter() - t0, "lmi": rep.timings["lmi"],
            "bound": rep.h2_lmi_bound, "restriction": rep.h2_restriction,
            "start": rep.polish["start"], "h2": rep.check.h2,
            "largest_cone": rep.solver["largest_cone"]}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[20, 40])
    ap.add_argument("--ranges", type=int, nargs="+", default=[5, -1])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--lmi", action="store_true")
    ap.add_argument("--sparsity", action="store_true")
    ap.add_argument("--robust", action="store_true")
    ap.add_argument("--cli", action="store_true")
    args = ap.parse_args()

    print(f"{'N':>4s} {'R':>5s} {'states':>6s} {'riccati':>8s} {'start':>8s} {'polish':>8s} "
          f"{'total':>8s}  {'H2 riccati':>11s} {'H2 start':>10s} {'H2 final':>10s}  iters")
    for N in args.sizes:
        for R in args.ranges:
            r = run_case(N, R, args.repeat)
            s = r["stages"]

            def t(k, s=s):
                return f"{s[k]['time']:8.4f}" if k in s else f"{'-':>8s}"

            def h(k, w, s=s):
                return f"{s[k]['h2']:{w}.6f}" if k in s else f"{'-':>{w}s}"

            print(f"{N:>4d} {r['R']!s:>5s} {r['states']:>6d} {t('riccati')} {t('start')} "
                  f"{t('polish')} {r['total']:8.4f}  {h('riccati', 11)} {h('start', 10)} "
                  f"{r['h2']:10.6f}  {r['polish'].get('iterations', '-')}")
    if args.lmi:
        for N in args.sizes:
            dt, hl = time_lmi(N)
            print(f"full-state H2 LMI (Clarabel, dense) N = {N}: {dt:.2f} s, its gain's H2 "
                  f"{hl:.6f}")
            for R in (r for r in args.ranges if r >= 0):
                x = time_restriction(N, R)
                print(f"structured method = 'lmi' N = {N}, R = {R}: restriction {x['lmi']:.2f} s "
                      f"(largest cone {x['largest_cone']}), bound {x['bound']:.6f}, its gain's "
                      f"H2 {x['restriction']:.6f}, start {x['start']}, final H2 {x['h2']:.6f}, "
                      f"total {x['total']:.2f} s")
    if args.sparsity:
        from lcc_synth.synthesis.design import synthesize

        for N in args.sizes:
            spec = _spec(N, 0, design='design = "sparsity"')
            t0 = time.perf_counter()
            rep = synthesize(spec)
            dt = time.perf_counter() - t0
            front = ", ".join(f"{p['ranges'][f'u_{N}']}:{p['h2']:.4f}" for p in rep.pareto)
            pick = next(p for p in rep.pareto if p["chosen"])
            print(f"sparsity front N = {N} ({len(rep.pareto)} points, {dt:.2f} s): R:H2 {front}; "
                  f"chosen R = {pick['ranges'][f'u_{N}']} (loss {100 * pick['loss']:.3f}%)")
    if args.robust:
        from lcc_synth.synthesis.design import synthesize

        spec = _spec(20, 5, "[synthesis.robust]\nsamples = 20\nseed = 0\n"
                     "alpha = [0.45, 0.75]\nbeta = [0.7, 1.1]\ns_go = [32.0, 38.0]\n")
        t0 = time.perf_counter()
        rep = synthesize(spec)
        dt = time.perf_counter() - t0
        rb = rep.robust
        print(f"robust mean design, ring N = 20, R = 5, 20 members ({dt:.2f} s, "
              f"{rb['iterations']} iterations):")
        for key in ("nominal_design", "robust_design"):
            d = rb[key]
            hs = np.array([m["h2"] for m in d["members"]])
            print(f"  {key:<15s} mean {d['mean_h2']:.6f}  worst {d['worst_h2']:.6f}  best "
                  f"{d['best_h2']:.6f}  std {hs.std():.6f}  stable {d['n_stable']}/20  "
                  f"nominal-model H2 {d['h2_nominal']:.6f}")
    if args.cli:
        best = math.inf
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "lcc_synth.cli.main", "synthesize",
                            str(ROOT / "problems" / "ring_n20_cr5.toml"), "--json",
                            "--no-record", "--no-progress"], check=True,
                           capture_output=True)  # fmt: skip
            best = min(best, time.perf_counter() - t0)
        print(f"lcc-synth synthesize problems/ring_n20_cr5.toml --json: {best:.2f} s wall "
              "(fresh process)")


if __name__ == "__main__":
    main()
