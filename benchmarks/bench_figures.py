"""CPU time of the figures of ``lcc-synth run`` (``problems/showcase.toml``): one
:func:`~lcc_synth.figures.plot_profiles` per scenario and one
:func:`~lcc_synth.figures.plot_gamma_curves` per layout with a head vehicle, drawn from the
real results of the showcase, the way ``lcc-synth run`` calls them.

The results (the suite's simulations and the as-run |Γ| curves, about 30 s CPU) are computed
once and kept in a pickle (``--data``, default in the system's temporary directory); the
figures are then written ``--repeats`` times each into a temporary directory and the median
CPU time (``time.process_time``) of each is printed, with the total. A warm-up figure
(matplotlib's font cache, the first Agg draw) is excluded.

Run it against another checkout with ``PYTHONPATH=/path/to/checkout`` (the script only calls
the public ``lcc_synth.figures`` API) to compare before / after on the same data.

Usage: ``python benchmarks/bench_figures.py [--data PATH] [--repeats 3] [--format png]
[--out DIR]`` (``--out`` keeps the figures to look at)
"""

from __future__ import annotations

import argparse
import pickle
import statistics
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The frequencies of the |Γ| figures of ``lcc-synth run`` (``np.logspace(*_OMEGA)``).
OMEGA = (-3.0, 1.5, 500)


def showcase_data(problem: Path) -> dict:
    """``{"profiles": {scenario: (title, {controller: SimResult})}, "gamma": {layout: (title,
    curves)}, "omega": omega}`` of ``problem``: what ``lcc-synth run`` draws."""
    import numpy as np

    from lcc_synth.experiments.comparison import (
        applies,
        gamma_curves,
        gamma_settings,
        load_suite,
        run_suite,
    )

    suite = load_suite(problem)
    result = run_suite(suite, progress=False)
    omega = np.logspace(*OMEGA)
    profiles = {s: (suite.scenarios[s].title or s, per) for s, per in result.results.items()
                if per}  # fmt: skip
    gamma = {}
    for lname, rows in gamma_settings(suite).items():
        curves = {}
        for suffix, dt, lat, snames in rows:
            for c, k in result.controllers[lname].items():
                if any(applies(suite.controllers[c], lname, s) for s in snames):
                    per = gamma_curves({c: k}, suite.layouts[lname], omega, dt, lat)
                    curves.update({f"{n}{suffix}": v for n, v in per.items()})
        if curves:
            sy = suite.layouts[lname]
            size = (f"m={sy.m}, n={sy.n}" if sy.platoon is None else
                    f"size {sy.platoon.size}, CAVs {', '.join(map(str, sy.platoon.cavs))}")
            gamma[lname] = (f"|Γ(jω)| on layout {lname} ({sy.kind}, {size})", curves)
    return {"profiles": profiles, "gamma": gamma, "omega": omega}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problem", default=str(ROOT / "problems" / "showcase.toml"))
    ap.add_argument("--data", default=str(Path(tempfile.gettempdir()) / "bench_figures.pkl"),
                    help="pickle of the showcase's results (computed when missing)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--format", default="png", choices=("png", "pdf", "svg"))
    ap.add_argument("--out", default=None, help="keep the figures in this folder")
    args = ap.parse_args()

    data_path = Path(args.data)
    if data_path.exists():
        data = pickle.loads(data_path.read_bytes())
    else:
        t0 = time.process_time()
        data = showcase_data(Path(args.problem))
        data_path.write_bytes(pickle.dumps(data))
        print(f"showcase results computed in {time.process_time() - t0:.1f} s CPU -> {data_path}")

    from lcc_synth.figures import plot_gamma_curves, plot_profiles

    jobs = [(f"profiles_{s}", plot_profiles, (per,), {"title": title})
            for s, (title, per) in data["profiles"].items()]  # fmt: skip
    jobs += [(f"gamma_{lname}", plot_gamma_curves, (curves, data["omega"]), {"title": title})
             for lname, (title, curves) in data["gamma"].items()]  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out) if args.out else Path(tmp)
        name, func, a, kw = jobs[0]
        func(*a, out / f"warmup.{args.format}", **kw)
        total = 0.0
        print(f"{'figure':32s} {'CPU median (s)':>15s} {'min':>7s}   ({args.repeats} repeats, "
              f"{args.format})")  # fmt: skip
        for name, func, a, kw in jobs:
            times = []
            for _ in range(args.repeats):
                t0 = time.process_time()
                func(*a, out / f"{name}.{args.format}", **kw)
                times.append(time.process_time() - t0)
            med = statistics.median(times)
            total += med
            print(f"{name:32s} {med:15.3f} {min(times):7.3f}")
        print(f"{'total':32s} {total:15.3f}")


if __name__ == "__main__":
    main()
