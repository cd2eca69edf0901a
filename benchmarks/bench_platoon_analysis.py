"""Verdicts, decision margins and cost of the analysis of platoons and rings (several CAVs).

Prints, for the DeeP-LCC platoon (8 vehicles, CAVs 3 and 6) and OVM rings of 20 and 40 cars
with one AV: the controllability verdict and margin (ring: on the invariant hyperplane, and in
the orthonormal Householder basis for comparison; the full state), observability, and for the
platoon the head-to-tail string verdict of two local CAV laws, the agreement of Gamma by state
space and by the per-vehicle product, with the time per call.

Usage: python benchmarks/bench_platoon_analysis.py
"""

from __future__ import annotations

import time

import numpy as np

from lcc_synth.analysis.controllability import controllability_report, observability_report
from lcc_synth.analysis.staircase import kalman_decomposition
from lcc_synth.analysis.string_stability import string_stability
from lcc_synth.analysis.transfer import gamma_product, gamma_state_space
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import OVM
from lcc_synth.models.platoon import Platoon, platoon_model

DEEPLCC = {
    "alpha": [0.45, 0.75, 0.6, 0.70, 0.50, 0.6, 0.40, 0.80],
    "beta": [0.60, 0.95, 0.9, 0.95, 0.75, 0.9, 0.80, 1.00],
    "s_go": [38.0, 31.0, 35.0, 33.0, 37.0, 35.0, 39.0, 34.0],
}


def _timed(fn, repeat: int = 5):
    out = fn()
    t0 = time.perf_counter()
    for _ in range(repeat):
        fn()
    return out, (time.perf_counter() - t0) / repeat


def main() -> None:
    hdv = tuple(OVM(alpha=a, beta=b, s_go=g) for a, b, g in zip(*DEEPLCC.values(), strict=True))
    model = platoon_model(Platoon(hdv, (3, 6), 15.0))
    rep, t = _timed(lambda: controllability_report(model))
    print(
        f"DeeP-LCC platoon (16 states, CAVs 3, 6): {rep.verdict}, rank {rep.rank}/{rep.n_states}"
        f" (reachable {rep.reachable_states}: {rep.reachable_verdict}), margin "
        f"{rep.decision_margin:.3g}, outside {rep.vehicles_outside}, stabilizable "
        f"{rep.stabilizable}, closest (S) pair {rep.closest.zero_vehicle}->"
        f"{rep.closest.pole_vehicle} residual {rep.closest.residual:.3g}; {t * 1e3:.1f} ms"
    )
    ob, t = _timed(lambda: observability_report(model))
    print(f"  observability from {ob.outputs}: {ob.verdict}, rank {ob.rank}, margin "
          f"{ob.decision_margin:.3g}; {t * 1e3:.1f} ms")  # fmt: skip
    table = {"u_3": {"s_3": 0.5, "v_3": -1.2, "v_2": 0.9},
             "u_6": {"s_6": 0.4, "v_6": -1.5, "v_5": 1.1}}  # fmt: skip
    K, kh = Gains.from_table(table, model).input_feedback(model)
    w = np.logspace(-3, 2, 400)
    (ss, t_ss) = _timed(lambda: gamma_state_space(model, K, kh, w))
    prod = gamma_product(model, K, kh, w)
    print(f"  Gamma: state space vs product of vehicle TFs, max rel diff "
          f"{np.max(np.abs(ss - prod) / np.abs(prod)):.2g} on 400 frequencies "
          f"({t_ss * 1e3:.2f} ms)")  # fmt: skip
    for method in ("grid", "hamiltonian"):
        sr, t = _timed(lambda method=method: string_stability(model, K, kh, method))
        print(f"  string ({method}): {sr.verdict}, peak {sr.gamma_peak:.6f} at "
              f"{sr.gamma_peak_omega:.4f} rad/s, margin {sr.margin:+.3g}; {t * 1e3:.1f} ms")
    for N in (20, 40):
        ring = platoon_model(Platoon((OVM(),) * N, (N,), 15.0, ring=True))
        rep, t = _timed(lambda ring=ring: controllability_report(ring), 3)
        V = ring.invariant_basis()
        hh, t_hh = _timed(lambda V=V, ring=ring: kalman_decomposition(
            V.T @ ring.A @ V, V.T @ ring.B), 3)  # fmt: skip
        full, _ = _timed(lambda ring=ring: kalman_decomposition(ring.A, ring.B), 1)
        print(
            f"ring N={N} one AV: {rep.verdict} on the hyperplane, rank {rep.rank}/"
            f"{rep.n_states}, margin {rep.decision_margin:.3g}, stabilizable "
            f"{rep.stabilizable}, conserved: {rep.conserved_mode}; {t * 1e3:.1f} ms"
        )
        print(
            f"  Householder basis: rank {hh.n_c}..{hh.n_c_upper}, margin "
            f"{hh.decision_margin:.3g} ({t_hh * 1e3:.1f} ms); full state: rank {full.n_c}.."
            f"{full.n_c_upper} of {ring.nx}, margin {full.decision_margin:.3g}"
        )
        ob, t = _timed(lambda ring=ring: observability_report(ring), 3)
        print(f"  observability from {ob.outputs}: {ob.verdict}, rank {ob.rank}/{ob.n_states}, "
              f"margin {ob.decision_margin:.3g}; {t * 1e3:.1f} ms")  # fmt: skip
        hdv_ring = platoon_model(Platoon((OVM(),) * N, (), 15.0, ring=True))
        hr = controllability_report(hdv_ring)
        print(f"  all-HDV ring: rank {hr.rank}, stabilizable {hr.stabilizable} (largest "
              f"uncontrollable Re {hr.uncontrollable_max_real:+.4f}: the wave)")


if __name__ == "__main__":
    main()
