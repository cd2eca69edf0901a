"""The paper in order, with the flat API
=====================================

The paper in order, with the flat API only (``import lcc_synth as lcc``).

Model (Sec. II) -> controllability (Sec. III) -> control energy (Fig. 5) -> string stability
and its regions (Sec. IV, Table I, Fig. 7) -> H2 synthesis -> MPC -> simulation of Table II's
brake (Sec. V-B) -> metrics -> a Rerun recording. Writes under ``--out`` (default ``results/``):
``walkthrough.toml`` (the simulated problem, which ``lcc-synth simulate`` runs),
``walkthrough.json`` (every result's ``as_dict()``) and ``walkthrough.rrd``
(``lcc-synth review``), and prints what it wrote. About 7 s on 2 cores.

Usage: python examples/paper_walkthrough.py [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import lcc_synth as lcc

PAPER_GAINS = {"s_0": 0.1, "v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}
CASE_D = {"s_-2": 1.0, "v_-2": -1.0, "s_-1": 1.0, "v_-1": -1.0,
          "s_1": -1.0, "v_1": -1.0, "s_2": -1.0, "v_2": -1.0}  # fmt: skip


def _json(x):
    if isinstance(x, dict):
        return {k: _json(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_json(v) for v in x]
    return None if isinstance(x, float) and not math.isfinite(x) else x


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results", help="output directory (default: results/)")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    saved: dict[str, object] = {}

    # Sec. II: the linearised model of a CAV with m HDVs ahead and n behind (eq. 8-14)
    general = lcc.model("lcc", m=2, n=2, v_star=15.0)
    print(f"1. model: general LCC m = n = 2, {len(general.state_names)} states "
          f"{list(general.state_names)}")  # fmt: skip

    # Sec. III: controllability (Theorems 1-3)
    for kind, m, n in (("lcc", 2, 2), ("fd_lcc", 0, 10), ("ccc", 2, 0)):
        rep = lcc.controllability(lcc.model(kind, m=m, n=n))
        saved[f"controllability_{kind}"] = rep.as_dict()
        print(f"2. controllability: {kind} m={m} n={n}: {rep.verdict} (rank {rep.rank}/"
              f"{rep.n_states})")  # fmt: skip

    # Sec. III-C, Fig. 5: minimum control energy grows with the number of HDVs behind
    for n in (1, 2, 4):
        e = lcc.control_energy(lcc.model("fd_lcc", n=n), 20.0)
        saved[f"energy_fd_lcc_n{n}"] = e.as_dict()
        print(f"3. control energy: FD-LCC n = {n}, t = 20 s: lambda_min(W) = {e.lambda_min:.3e},"
              f" tr(W^-1) = {e.trace_inv:.3e}")  # fmt: skip

    # Sec. IV: head-to-tail string stability, Table I case D vs all HDVs; Fig. 7(a) coarsely
    for label, gains in (("all HDV", {}), ("case D", CASE_D)):
        ss = lcc.string_stability(general, lcc.gains(gains, semantics="added"))
        saved[f"string_{label.replace(' ', '_')}"] = ss.as_dict()
        print(f"4. string stability, {label}: peak |Gamma| = {ss.gamma_peak:.3f} at "
              f"{ss.gamma_peak_omega:.3g} rad/s -> {ss.verdict}")  # fmt: skip
    grid = [-10.0 + 0.5 * i for i in range(41)]
    region = lcc.region_map(general, -1, grid, grid, name="fig7a_coarse")
    saved["region_fig7a_coarse"] = region.as_dict()
    print(f"4. region map Fig. 7(a), 41 x 41 gains (mu_-1, k_-1): string stable "
          f"{region.string_stable_fraction:.1%}, plant stable {region.plant_stable_fraction:.1%}")

    # H2 synthesis: a CF-LCC gain that hears only HDVs 1 and 2 (the showcase's weights)
    string = lcc.system("fd_lcc", n=10, v_star=15.0)
    h2 = lcc.synthesize_h2(lcc.system("cf_lcc", n=10), pattern=[1, 2], semantics="replace",
                           weights={"q_s": 0.1, "q_v": 1.0, "q_a": 3.0, "r": 1.0})  # fmt: skip
    saved["synthesis"] = h2.as_dict()
    print(f"5. H2 synthesis: true H2 norm {h2.check.h2:.4f} (unstructured optimum "
          f"{h2.h2_unstructured:.4f}), string stable: {h2.check.string_stable}")  # fmt: skip

    # The safety-constrained MPC (predicts the 4 HDVs behind it)
    mpc = lcc.mpc(string, name="mpc", n_model=4)
    print(f"6. MPC: sample time {mpc.settings.sample_time} s, horizon {mpc.settings.horizon}, "
          f"predicts {mpc.settings.n_model} HDVs")  # fmt: skip

    # Sec. V-B, Table II: HDV 1 brakes at -5 m/s^2 for 1 s from t = 20 s
    brake = lcc.scenario(string, [lcc.Brake(vehicle=1, start=20.0, duration=1.0, decel=-5.0)],
                         duration=60.0)  # fmt: skip
    controllers = {
        "all_hdv": lcc.hdv_controller("all_hdv"),
        "cf_lcc": lcc.static_controller(string, PAPER_GAINS, "cf_lcc", "replace", "cf_lcc"),
        "h2": lcc.static_controller(string, h2.gains, "h2", "replace", "cf_lcc"),
        "mpc": mpc,
    }
    results = {name: lcc.simulate(brake, c) for name, c in controllers.items()}
    print(f"7. simulated {len(results)} controllers on {brake.steps} steps of {brake.dt} s")

    # Table II's metrics: the window is explicit
    for name, r in results.items():
        m = lcc.metrics(r, window=lcc.TABLE2_WINDOW)
        saved[f"metrics_{name}"] = {k: v for k, v in m.items() if not isinstance(v, dict | list)}
        print(f"8. {name:>8}: AAVE {m['aave']:.4f} m/s, fuel {m['fuel_ml']:.2f} mL, "
              f"min spacing {m['min_spacing']:.2f} m")  # fmt: skip

    # The problem file of what was simulated, the results, and a recording
    problem = lcc.build_problem("walkthrough", string, brake, controllers,
                                lcc.MetricsConfig(lcc.TABLE2_WINDOW),
                                "Table II's brake with the paper's, an H2 and the MPC controller")
    toml_path = out / "walkthrough.toml"
    toml_path.write_text(problem.to_toml())
    json_path = out / "walkthrough.json"
    json_path.write_text(json.dumps(_json(saved), indent=1))
    rrd = lcc.record(out / "walkthrough.rrd", results, name="walkthrough",
                     window=lcc.TABLE2_WINDOW, controllers=controllers)  # fmt: skip
    for path in (toml_path, json_path, rrd):
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
