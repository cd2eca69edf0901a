"""Simulator throughput (issue 3 targets: >= 5e6 vehicle-steps/s for a heterogeneous batch with
static gains on 2 cores; one Table II run, 12 vehicles x 10,000 steps, well under 0.2 s), and
the platoon with two CAVs and the ring road of issue 11.

Run: ``/work/venv/bin/python benchmarks/bench_simulator.py [--batch B] [--repeat R]``.
The first call compiles (or loads from numba's cache) the kernels; it is timed separately.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numba

from lcc_synth.controllers.static import HDVController
from lcc_synth.experiments.spec import load_spec
from lcc_synth.metrics import summary
from lcc_synth.simulation.engine import simulate

ROOT = Path(__file__).resolve().parents[1]


def best_of(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--batch", type=int, default=400)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(f"numba {numba.__version__}, threads {numba.get_num_threads()}")

    spec = load_spec(ROOT / "problems" / "paper_table2.toml")
    sc = spec.scenario
    nveh = sc.n_vehicles
    t0 = time.perf_counter()
    simulate(sc, spec.controllers["fd_lcc"])
    print(f"first call (compile or cache load): {time.perf_counter() - t0:.3f} s")

    for name, ctrl in spec.controllers.items():
        t = best_of(lambda c=ctrl: simulate(sc, c), args.repeat)
        print(
            f"Table II single run [{name}]: {nveh} vehicles x {sc.steps} steps: {t * 1e3:.1f} ms "
            f"({nveh * sc.steps / t / 1e6:.1f} M vehicle-steps/s)"
        )
    res = simulate(sc, spec.controllers["fd_lcc"])
    t = best_of(lambda: summary(res, spec.metrics), args.repeat)
    print(f"Table II metrics summary of one run: {t * 1e3:.1f} ms")

    # heterogeneous batch (Appendix C: parameter draws and reaction delays) with static gains
    spec_c = load_spec(ROOT / "problems" / "paper_appendix_c.toml", seeds=args.batch)
    ctrl = spec_c.controllers["fd_lcc"]
    for every in (100, 1):
        scb = replace(spec_c.scenario, record_every=every)
        draws = scb.draw()
        simulate(scb, ctrl, draws)
        t = best_of(lambda s=scb, d=draws: simulate(s, ctrl, d), args.repeat)
        work = scb.batch * scb.n_vehicles * scb.steps
        print(
            f"heterogeneous batch of {scb.batch} (delays, static gains), record_every={every}: "
            f"{t:.3f} s for {work / 1e6:.1f} M vehicle-steps = "
            f"{work / t / 1e6:.1f} M vehicle-steps/s"
        )

    # the same batch through the Python-controller path (one call per controller sample)
    class PyHDV(HDVController):
        linear_law = None  # hide the compiled law: exercise the per-sample Python path

    for ts in (0.1, None):
        py = PyHDV("py_hdv", sample_time=ts)
        scb = replace(spec.scenario, batch=1)
        t = best_of(lambda p=py, s=scb: simulate(s, p), args.repeat)
        per = scb.steps if ts is None else int(round(scb.duration / ts))
        print(
            f"Python controller path, single Table II run, sample_time={ts}: {t * 1e3:.0f} ms "
            f"({t / per * 1e6:.1f} us per controller call incl. simulation)"
        )

    # several CAVs and the ring (issue 11): the shipped platoon and ring files
    for fname, cname, batch in (("platoon_deeplcc_brake.toml", "lqr", 1),
                                ("platoon_deeplcc_brake.toml", "lqr", args.batch),
                                ("ring_stop_and_go.toml", "all_hdv", 1),
                                ("ring_stop_and_go.toml", "av", 1)):  # fmt: skip
        sp = load_spec(ROOT / "problems" / fname, seeds=batch)
        scp, ctrl = sp.scenario, sp.controllers[cname]
        draws = scp.draw()
        simulate(scp, ctrl, draws)
        t = best_of(lambda s=scp, c=ctrl, d=draws: simulate(s, c, d), args.repeat)
        work = scp.batch * scp.n_vehicles * scp.steps
        print(
            f"{sp.name} [{cname}] ({len(scp.cav_columns)} CAV(s){', ring' if scp.ring else ''}), "
            f"batch {scp.batch}, {scp.n_vehicles} vehicles x {scp.steps} steps: {t * 1e3:.1f} ms "
            f"({work / t / 1e6:.1f} M vehicle-steps/s)"
        )


if __name__ == "__main__":
    main()
