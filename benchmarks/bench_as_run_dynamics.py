"""Cost of one evaluation of the dynamic as-run design (lcc_synth.synthesis.as_run_dynamics) on
the showcase's string10: the sampled loops at latency 0 and 0.1 s, their peak |Γ| on the grid,
the continuous-limit H2 and gap response, against the exact verdict and the sampled-data H2.

    python benchmarks/bench_as_run_dynamics.py [--repeat 20] [--sample-time 0.1]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from lcc_synth.analysis.as_run import as_run_loop, as_run_report, law_of_gains
from lcc_synth.analysis.as_run_h2 import as_run_h2
from lcc_synth.experiments.comparison import load_suite
from lcc_synth.synthesis.as_run_dynamics import DynamicsSettings, evaluate_point
from lcc_synth.synthesis.h2 import Weights, make_plant

ROOT = Path(__file__).resolve().parents[1]

#: today's h2 gain of the showcase on string10 (rounded; lcc-synth run designs it)
H2_GAINS = {"s_0": 0.2829, "v_0": -2.633, "s_1": -1.401, "v_1": -0.009594, "s_2": -1.246,
            "v_2": 0.0808}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--sample-time", type=float, default=0.1)
    args = ap.parse_args()
    suite = load_suite(ROOT / "problems" / "showcase.toml", scenarios=["head_brake"],
                       controllers=["paper"])  # fmt: skip
    model = suite.layouts["string10"].linear_model(warn=False)
    plant = make_plant(model, "replace", Weights(q_s=0.1, q_v=1.0, q_a=3.0, r=1.0, accel=1.0))
    g = np.array([H2_GAINS.get(nm, 0.0) for nm in plant.state_names])
    st = DynamicsSettings()
    T = args.sample_time
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(args.repeat):
        p = evaluate_point(plant, g, 1.0, 0.3, T, st)
    t_eval = (time.perf_counter() - t0) / args.repeat
    c_eval = (time.process_time() - c0) / args.repeat
    law = law_of_gains(model, plant.gains(g))
    t0 = time.perf_counter()
    reps = [as_run_report(as_run_loop(model, law, T, lat, 1.0, 0.3)) for lat in st.latencies]
    t_rep = time.perf_counter() - t0
    t0 = time.perf_counter()
    h2s = as_run_h2(as_run_loop(model, law, T, 0.0, 1.0, 0.3), plant.Bw, plant.Q, plant.r)
    t_h2s = time.perf_counter() - t0
    print(f"T = {T:g} s, {st.points} frequencies: one evaluation {1e3 * t_eval:.1f} ms "
          f"(CPU {1e3 * c_eval:.1f} ms) "
          f"(peaks {', '.join(f'{x:.4f}' for x in p.peaks)}, H2 continuous {p.h2:.4f}, "
          f"gap response {p.gap_peak:.3f} s)")
    print(f"exact verdicts {1e3 * t_rep:.0f} ms (peaks "
          f"{', '.join(f'{r.gamma_peak:.4f}' for r in reps)}); sampled-data H2 {h2s:.4f} in "
          f"{1e3 * t_h2s:.0f} ms")


if __name__ == "__main__":
    main()
