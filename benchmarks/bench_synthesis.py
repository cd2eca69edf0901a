"""Synthesis time vs string length: CF-LCC with n = 5, 10, 20, 40 HDVs behind (12..82 states).

Columns (wall-clock seconds, best of ``--repeat``):

* ``riccati``      unstructured H2 optimum by the CARE (scipy);
* ``lmi_dense``    the plain full-state H2 LMI (one dense PSD cone, Clarabel) -- only up to
                   ``--dense-max-n`` because it grows steeply (about 100 s at 82 states);
* ``restr_dense``  structured convex restriction (pattern CAV + HDVs 1, 2) with the Lyapunov LMI
                   as one dense cone (zeros built into X and Z) -- also up to ``--dense-max-n``;
* ``restr_chordal`` the same restriction with the chordal decomposition (what ``synthesize``
                   uses);
* ``polish``       Anderson-Moore polishing on the true H2 cost (two Lyapunov solves per step);
* ``structured``   the whole structured design (restriction + polishing), as ``synthesize`` runs;
* ``direct``       structured design without SDP (truncated Riccati start + polishing);

plus the true H2 norms (unstructured, structured) and the LMI bound.

Usage::

    python benchmarks/bench_synthesis.py [--sizes 5 10 20 40] [--repeat 1] [--dense-max-n 20]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def best_time(fn, repeat):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[5, 10, 20, 40])
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--dense-max-n", type=int, default=20)
    args = ap.parse_args()

    import cvxpy  # noqa: F401  (import cost outside the timings)

    from lcc_synth.models.hdv import OVM
    from lcc_synth.models.linear import model_from_hdv
    from lcc_synth.synthesis.h2 import Weights, h2_norm, make_plant, riccati_gain
    from lcc_synth.synthesis.lmi import lmi_full_state
    from lcc_synth.synthesis.structured import (
        convex_restriction,
        pattern_mask,
        polish,
        structured_h2,
    )

    hdv = OVM(alpha=0.6, beta=0.9, s_st=5.0, s_go=35.0, v_max=30.0)
    w = Weights(q_s=0.1, q_v=1.0, q_a=3.0, r=1.0, accel=1.0)
    # warm-up (cvxpy's first canonicalisation)
    p0 = make_plant(model_from_hdv("cf_lcc", 0, 2, hdv, 15.0), "replace", w)
    convex_restriction(p0, pattern_mask(p0, [1]))

    cols = ["n", "states", "riccati", "lmi_dense", "restr_dense", "restr_chordal", "polish",
            "structured", "direct", "H2_full", "H2_struct", "LMI_bound"]
    print(" ".join(f"{c:>13s}" for c in cols))
    for n in args.sizes:
        p = make_plant(model_from_hdv("cf_lcc", 0, n, hdv, 15.0), "replace", w)
        mask = pattern_mask(p, [1, 2])
        t_ric, (g_ric, _) = best_time(lambda p=p: riccati_gain(p), args.repeat)
        if n <= args.dense_max_n:
            t_lmi, _ = best_time(lambda p=p: lmi_full_state(p), args.repeat)
            t_rd, _ = best_time(
                lambda p=p, m=mask: convex_restriction(p, m, chordal=False), args.repeat
            )
        else:
            t_lmi = t_rd = float("nan")
        t_rc, restr = best_time(lambda p=p, m=mask: convex_restriction(p, m), args.repeat)
        t_pol, _ = best_time(lambda p=p, m=mask, r=restr: polish(p, r.g, m), args.repeat)
        t_st, st = best_time(lambda p=p: structured_h2(p, [1, 2], "lmi"), args.repeat)
        t_di, di = best_time(lambda p=p: structured_h2(p, [1, 2], "direct"), args.repeat)
        assert abs(st.h2 - di.h2) <= 1e-5 * st.h2
        row = [n, p.nx, t_ric, t_lmi, t_rd, t_rc, t_pol, t_st, t_di, h2_norm(p, g_ric), st.h2,
               st.h2_lmi_bound]
        print(" ".join(f"{v:>13d}" if isinstance(v, int) else f"{v:>13.4g}" for v in row),
              flush=True)


if __name__ == "__main__":
    main()
