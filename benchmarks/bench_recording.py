"""Recording overhead and file size for the Table II problem (``problems/paper_table2.toml``).

Measures, after a warm-up run (numba compilation, Rerun's first-call conversions, the ~1 s
``import rerun`` are excluded and reported separately):

* the simulation wall time of the three controllers (``simulate_many``),
* the wall time of recording them (open + three ``record_simulation`` calls + finalise, i.e.
  everything ``lcc-synth simulate`` adds), for several decimations,
* the resulting file size;

and then, for the simulations of the default ``lcc-synth run`` (``problems/showcase.toml``: 16
runs), the file size at full rate and with the min/max-preserving decimation ``run`` records
with (``decimate="minmax"``), with the largest contributors (entity kinds, Arrow MB).

Usage: ``python benchmarks/bench_recording.py [--repeats 5] [--problem PATH] [--no-showcase]``
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problem", default=str(ROOT / "problems" / "paper_table2.toml"))
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--every", type=int, nargs="*", default=[1, 2, 5, 10])
    ap.add_argument("--no-showcase", action="store_true", help="skip the default-run sizes")
    args = ap.parse_args()

    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.metrics import summary
    from lcc_synth.simulation.engine import simulate_many

    spec = load_spec(args.problem)
    simulate_many(spec.scenario, spec.controllers)  # warm-up (numba)
    sims = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        results = simulate_many(spec.scenario, spec.controllers)
        sims.append(time.perf_counter() - t0)
    sim, sim_min = statistics.median(sims), min(sims)
    metrics = {name: summary(res, spec.metrics) for name, res in results.items()}

    t0 = time.perf_counter()
    import rerun  # noqa: F401

    from lcc_synth import recording as R

    t_import = time.perf_counter() - t0

    res0 = next(iter(results.values()))
    steps, nv = res0.velocity.shape[1], res0.velocity.shape[2]
    print(
        f"{spec.name}: {len(results)} controllers x {nv} vehicles x {steps} steps; "
        f"simulation {sim * 1e3:.1f} ms median, {sim_min * 1e3:.1f} ms min of {args.repeats}; "
        f"import rerun {t_import:.2f} s (once per process, not counted)"
    )
    print(
        f"{'every':>5}  {'record ms (med/min)':>19}  {'ratio (med/min)':>15}  "
        f"{'file MB':>7}  {'MB/ctrl':>7}"
    )
    with tempfile.TemporaryDirectory() as tmp:

        def record(every: int, path: Path) -> float:
            t0 = time.perf_counter()
            bp = R.simulation_blueprint(spec.name, list(results))
            with R.open_recording(path, spec.name, bp) as rec:
                for name, res in results.items():
                    R.record_simulation(rec, res, spec.name, metrics=metrics[name], decimate=every)
            return time.perf_counter() - t0

        record(1, Path(tmp) / "warmup.rrd")
        for every in args.every:
            times = []
            for i in range(args.repeats):
                path = Path(tmp) / f"e{every}_{i}.rrd"
                times.append(record(every, path))
            rec_t, rec_min = statistics.median(times), min(times)
            size = path.stat().st_size / 1e6
            print(
                f"{every:>5}  {rec_t * 1e3:>9.1f} / {rec_min * 1e3:>7.1f}  "
                f"{rec_t / sim:>6.2f} / {rec_min / sim_min:>6.2f}  {size:>7.2f}  "
                f"{size / len(results):>7.2f}"
            )

    if not args.no_showcase:
        showcase_sizes()


def _contributors(path: Path) -> list[tuple[float, int, str]]:
    """``(Arrow MB, rows, kind)`` per entity kind (the path below ``/<scenario>/<controller>``)."""
    from collections import Counter

    from rerun.chunk import RrdReader

    size: Counter = Counter()
    rows: Counter = Counter()
    reader = RrdReader(path)
    for chunk in reader.stream(store=reader.recordings()[0]):
        parts = str(chunk.entity_path).split("/")
        kind = "/".join(parts[3:]) if len(parts) > 3 else str(chunk.entity_path)
        size[kind] += chunk.to_record_batch().nbytes
        rows[kind] += chunk.num_rows
    return sorted(((b / 1e6, rows[k], k) for k, b in size.items()), reverse=True)


def showcase_sizes() -> None:
    """Record the default run's 16 simulations at full rate and min/max-decimated."""
    from lcc_synth import recording as R
    from lcc_synth.experiments.comparison import load_suite, run_suite

    suite = load_suite(ROOT / "problems" / "showcase.toml", None, None)
    runs = []

    def keep(scenario, name, res, row, ctrl):
        history = ctrl.history() if hasattr(ctrl, "history") else None
        runs.append((scenario, name, res, row, history or None))

    run_suite(suite, progress=False, on_result=keep)
    print(f"\nshowcase (default `lcc-synth run`): {len(runs)} simulations")
    print(f"{'decimate':>8}  {'record s':>8}  {'file MB':>7}  largest (Arrow MB, rows)")
    with tempfile.TemporaryDirectory() as tmp:
        for how in (1, "minmax"):
            path = Path(tmp) / f"showcase_{how}.rrd"
            t0 = time.perf_counter()
            with R.open_recording(path, suite.name) as rec:
                for scenario, name, res, row, history in runs:
                    R.record_simulation(rec, res, scenario, controller=name, metrics=row,
                                        decimate=how, mpc_history=history)  # fmt: skip
            wall = time.perf_counter() - t0
            top = ", ".join(f"{k} {mb:.2f} ({n})" for mb, n, k in _contributors(path)[:6])
            print(f"{how!s:>8}  {wall:>8.2f}  {path.stat().st_size / 1e6:>7.2f}  {top}")
    print("(`lcc-synth run` adds ~1.4 MB of |Γ| curves, gains, reports and the layout)")


if __name__ == "__main__":
    main()
