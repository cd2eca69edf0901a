"""Per-unit costs behind the estimates of :mod:`lcc_synth.recording.size` and
:func:`lcc_synth.resources.estimate_simulation`, measured here, and the estimates against the
real files.

Measures and prints:

1. **Bytes per unit** of a recording: the Arrow size (LZ4 IPC, as Rerun writes it) of every
   chunk of an exact recording (``--record-every 1``) by entity: bytes per row of an all-zero
   flag (the row overhead), per float64 value and per road point above it, the fixed bytes of
   a run (static styles, documents), the bytes per view of the layout.
2. **Rows per simulated second** of every entity kind with ``minmax``.
3. **Estimate vs real size** of ``lcc-synth simulate`` recordings (exact and minmax) of
   ``paper_table2``, ``paper_appendix_c`` (3 seeds), ``mpc_head_brake``, the DeeP-LCC platoon
   and the ring; with ``--showcase`` also the default ``lcc-synth run`` (about a minute).
4. **Time per unit** of a simulation: a vehicle-step of the compiled loop (one scenario, and
   a batch of 64 on every core), a controller step of the MPC and of DeeP-LCC per scenario,
   recording a run (per run and per MB).
5. **Memory per unit**: the per-scenario metrics a seed study keeps (bytes per scenario and
   controller), the random draws of a scenario (per scenario, its random generator included),
   an MPC's history (bytes per scenario and controller step).
6. **Time and memory estimates vs the real command** (``lcc-synth simulate`` in a subprocess:
   wall time and peak resident memory) for a 200-seed study with and without its recording
   and for the MPC problem; ``--quick`` skips the 200-seed runs (about 90 s).

Usage: ``python benchmarks/bench_recording_size.py [--showcase] [--quick] [--repeats 3]``
"""

from __future__ import annotations

import argparse
import collections
import json
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ROOT / "problems"


def chunk_bytes(path: Path, blueprint: bool = False) -> dict[str, list]:
    """``{entity: [static bytes, temporal bytes, rows, values]}`` of a recording (Arrow IPC
    with LZ4, the size Rerun stores per chunk)."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    reader = RrdReader(str(path))
    stores = reader.blueprints() if blueprint else [None]
    out: dict[str, list] = collections.defaultdict(lambda: [0, 0, 0, 0])
    opts = pa.ipc.IpcWriteOptions(compression="lz4")
    for store in stores:
        for ch in reader.stream(store=store) if store is not None else reader.stream():
            rb = ch.to_record_batch()
            sink = pa.BufferOutputStream()
            with pa.ipc.new_stream(sink, rb.schema, options=opts) as w:
                w.write_batch(rb)
            size = sink.getvalue().size
            e = out[str(ch.entity_path)]
            if ch.is_static or store is not None:
                e[0] += size
                continue
            e[1] += size
            e[2] += ch.num_rows
            for name in rb.schema.names:
                if name.endswith((":scalars", ":positions", ":strips")):
                    col = rb.column(name)
                    while pa.types.is_list(col.type) or pa.types.is_fixed_size_list(col.type):
                        col = col.flatten()
                    e[3] += len(col)
    return out


def simulate_cli(problem: Path, rrd: Path, *extra: str) -> None:
    import contextlib
    import io

    from lcc_synth.cli.main import main

    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = main(["simulate", str(problem), "--json", "--rrd", str(rrd), *extra])
    if code != 0:
        raise SystemExit(f"simulate {problem.name} {extra} exited {code}")


def unit_bytes(tmp: Path) -> None:
    print("== 1. bytes per unit (exact recordings: --record-every 1)")
    rows = []
    for name, extra in (("paper_table2.toml", ()), ("paper_appendix_c.toml", ("--seeds", "2")),
                        ("ring_stop_and_go.toml", ())):  # fmt: skip
        rrd = tmp / f"exact_{name}.rrd"
        simulate_cli(PROBLEMS / name, rrd, "--record-every", "1", *extra)
        per = chunk_bytes(rrd)
        flag = [v[1] / v[2] for e, v in per.items() if e.endswith("/cav/aeb_active") and v[2]]
        row = float(np.median(flag))
        kinds = collections.defaultdict(list)
        for e, (_, te, n, vals) in per.items():
            kind = e.rsplit("/", 1)[-1]
            if n and vals and kind in ("velocity", "spacing", "acceleration", "road"):
                kinds[kind].append((te - row * n) / vals * (2 if kind == "road" else 1))
        fixed = sum(v[0] for v in per.values())
        runs = sum(1 for e in per if e.endswith("/velocity"))
        file = rrd.stat().st_size
        arrow = sum(v[0] + v[1] for v in per.values())
        bp = sum(v[0] for v in chunk_bytes(rrd, blueprint=True).values())
        from lcc_synth.recording import summarize_recording

        views = len(summarize_recording(rrd).views)
        rows.append((name, row, kinds, fixed / runs, bp, views, file, arrow))
        print(f"{name}: row {row:.1f} B; per float64 value "
              + ", ".join(f"{k} {min(v):.2f}-{max(v):.2f} B" for k, v in kinds.items() if
                          k != "road")
              + f"; per road point {min(kinds['road']):.2f}-{max(kinds['road']):.2f} B; "
              f"static per run {fixed / runs / 1e3:.1f} kB; layout {bp / 1e3:.0f} kB for "
              f"{views} views ({bp / max(views, 1) / 2 / 1e3:.1f} kB per view, written twice); "
              f"file / Arrow {file / (arrow + bp):.3f}")  # fmt: skip


def minmax_rates(tmp: Path, showcase: Path | None) -> None:
    print("== 2. rows per simulated second with minmax")
    files = []
    for name, extra in (("paper_table2.toml", ()), ("paper_appendix_c.toml", ("--seeds", "2")),
                        ("mpc_head_brake.toml", ())):  # fmt: skip
        rrd = tmp / f"minmax_{name}.rrd"
        simulate_cli(PROBLEMS / name, rrd, *extra)
        files.append(rrd)
    if showcase is not None:
        files.append(showcase)
    from lcc_synth.recording import summarize_recording

    rates = collections.defaultdict(list)
    points = collections.defaultdict(list)
    for rrd in files:
        s = summarize_recording(rrd)
        per = chunk_bytes(rrd)
        for e, (_, _, n, vals) in per.items():
            ent = s.entities.get(e)
            if not n or ent is None or ent.t_max is None:
                continue
            parts = e.strip("/").split("/")
            kind = "/".join(parts[2:])
            scen = parts[0]
            dur = ent.t_max - ent.t_min if "predicted" not in kind else None
            if dur is None:
                vel = s.entities.get("/".join(e.split("/")[:3]) + "/velocity")
                dur = vel.t_max - vel.t_min if vel else 0.0
            if dur > 0:
                rates[kind].append((n / dur, scen))
            if "predicted" in kind:
                points[kind].append(vals / max(n, 1))
    for kind, v in sorted(rates.items()):
        r = [x for x, _ in v]
        print(f"  {kind:26s} {min(r):6.2f} .. {max(r):6.2f} rows/s (median {np.median(r):.2f}, "
              f"most: {max(v)[1]})")  # fmt: skip
    for kind, v in sorted(points.items()):
        print(f"  {kind:26s} {np.mean(v):.1f} points per plan (all strips)")


def estimates(tmp: Path, showcase: Path | None) -> None:
    print("== 3. estimate vs real size")
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.recording.size import estimate_simulation_recording, format_size

    cases = [("paper_table2.toml", 1, "minmax"), ("paper_table2.toml", 1, 1),
             ("paper_table2.toml", 1, 10), ("paper_appendix_c.toml", 3, "minmax"),
             ("paper_appendix_c.toml", 3, 1), ("mpc_head_brake.toml", 1, "minmax"),
             ("mpc_head_brake.toml", 1, 1), ("platoon_deeplcc_brake.toml", 1, "minmax"),
             ("ring_stop_and_go.toml", 1, "minmax"), ("ring_stop_and_go.toml", 1, 1)]
    for name, seeds, how in cases:
        rrd = tmp / f"est_{name}_{seeds}_{how}.rrd"
        extra = ["--record-every", str(how)] + (["--seeds", str(seeds)] if seeds > 1 else [])
        t0 = time.perf_counter()
        simulate_cli(PROBLEMS / name, rrd, *extra)
        wall = time.perf_counter() - t0
        spec = load_spec(PROBLEMS / name, seeds=seeds if seeds > 1 else None)
        est = estimate_simulation_recording(spec.scenario, spec.controllers, seeds, how)
        real = rrd.stat().st_size
        print(f"  {name:28s} seeds {seeds} {str(how):6s}: real {format_size(real):>8s}, "
              f"estimate {format_size(est.bytes):>8s} = {est.bytes / real:.2f} x "
              f"({wall:.1f} s)")  # fmt: skip
    if showcase is not None:
        from lcc_synth.cli.run import default_problem
        from lcc_synth.experiments.comparison import load_suite
        from lcc_synth.experiments.suite_size import suite_recording_estimate

        est = suite_recording_estimate(load_suite(default_problem()))
        real = showcase.stat().st_size
        print(f"  lcc-synth run (showcase)          minmax: real {format_size(real)}, "
              f"estimate {format_size(est.bytes)} = {est.bytes / real:.2f} x")


def unit_times(repeats: int) -> None:
    print("== 4. time per unit")
    from dataclasses import replace

    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.simulation.engine import simulate

    spec = load_spec(PROBLEMS / "paper_table2.toml")
    ctrl = spec.controllers["cf_lcc"]
    sc = spec.scenario
    simulate(sc, ctrl)  # numba warm-up
    for batch in (1, 64):
        scb = replace(sc, batch=batch)
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            simulate(scb, ctrl)
            ts.append(time.perf_counter() - t0)
        vs = batch * sc.steps * sc.n_vehicles
        print(f"  compiled loop, batch {batch:3d}: {min(ts) / vs * 1e9:.2f} ns per vehicle-step "
              f"({vs / min(ts) / 1e6:.0f} M/s)")
    for name, label in (("mpc_head_brake.toml", "MPC"), ("deeplcc_head_brake.toml", "DeeP-LCC")):
        path = PROBLEMS / name
        if not path.is_file():
            continue
        spec = load_spec(path)
        for cname, c in spec.controllers.items():
            deep = "deep" in type(c).__name__.lower()
            if not callable(getattr(c, "history", None)) or deep != (label == "DeeP-LCC"):
                continue
            scs = replace(spec.scenario, duration=min(spec.scenario.duration, 20.0))
            t0 = time.perf_counter()
            simulate(scs, c)
            wall = time.perf_counter() - t0
            steps = int(round(scs.duration / c.sample_time))
            print(f"  {label} {cname} (horizon {c.settings.horizon}): {wall / steps * 1e3:.2f} ms "
                  f"per controller step and scenario ({steps} steps, {scs.n_vehicles} vehicles, "
                  "setup included)")  # fmt: skip
            break
    from lcc_synth import recording as R
    from lcc_synth.simulation.engine import simulate_many

    spec = load_spec(PROBLEMS / "paper_table2.toml")
    results = simulate_many(spec.scenario, spec.controllers)
    for how in ("minmax", 1):
        with tempfile.TemporaryDirectory() as d:
            path = Path(d) / "t.rrd"
            t0 = time.perf_counter()
            with R.open_recording(path, "t") as rec:
                for name, res in results.items():
                    R.record_simulation(rec, res, "t", controller=name, decimate=how)
            wall = time.perf_counter() - t0
            mb = path.stat().st_size / 1e6
        print(f"  recording {how!s:6s}: {wall / len(results) * 1e3:.0f} ms per run "
              f"({mb / len(results):.2f} MB per run, {wall / mb:.3f} s per MB)")


def unit_memory() -> None:
    print("== 5. memory per unit")
    from dataclasses import replace

    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.metrics import per_scenario
    from lcc_synth.simulation.engine import simulate

    spec = load_spec(PROBLEMS / "paper_appendix_c.toml")
    sc = replace(spec.scenario, batch=200, duration=5.0)
    tracemalloc.start()
    a = tracemalloc.take_snapshot()
    draws = sc.draw()
    b = tracemalloc.take_snapshot()
    tracemalloc.stop()
    used = sum(s.size_diff for s in b.compare_to(a, "filename"))
    print(f"  draws: {used / sc.batch:.0f} B per scenario ({sc.n_vehicles} vehicles, "
          "random generators freed)")
    import sys

    rng = np.random.default_rng([0, 1])
    state = json.dumps(rng.bit_generator.state)
    print(f"  a random generator: {sys.getsizeof(rng) + len(state)} B (object + state)")
    res = simulate(sc, spec.controllers["fd_lcc"], draws)
    per = per_scenario(res, replace(spec.metrics, window=(1.0, 5.0)))
    nbytes = sum(np.asarray(v).nbytes for v in per.values())
    print(f"  per-scenario metrics: {nbytes / sc.batch:.0f} B per scenario and controller "
          f"({len(per)} arrays, {sc.n_vehicles} vehicles)")
    path = PROBLEMS / "mpc_head_brake.toml"
    spec = load_spec(path)
    for c in spec.controllers.values():
        if callable(getattr(c, "history", None)):
            scs = replace(spec.scenario, duration=5.0)
            simulate(scs, c)
            h = c.history()
            nb = sum(np.asarray(v).nbytes for v in h.values() if hasattr(v, "nbytes"))
            steps = len(h["t"])
            print(f"  MPC history (horizon {c.settings.horizon}, {scs.n_vehicles} vehicles): "
                  f"{nb / steps:.0f} B per controller step and scenario")
            break


def run_estimates(quick: bool) -> None:
    print("== 6. time and memory: estimate vs the real command")
    import contextlib
    import io
    import resource
    import subprocess
    import sys

    from lcc_synth.cli.main import build_parser
    from lcc_synth.cli.simulate import check_simulation
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.resources import format_bytes

    script = Path(sys.executable).with_name("lcc-synth")
    cases = [(["mpc_head_brake.toml"], None)]
    if not quick:
        cases += [(["paper_appendix_c.toml", "--seeds", "200", "--no-record"], 200),
                  (["paper_appendix_c.toml", "--seeds", "200"], 200)]  # fmt: skip
    base = None
    for argv, seeds in [(["paper_table2.toml", "--no-record"], None), *cases]:
        with tempfile.TemporaryDirectory() as d:
            full = ["simulate", str(PROBLEMS / argv[0]), *argv[1:], "--json"]
            args = build_parser().parse_args(full)
            with contextlib.chdir(d), contextlib.redirect_stderr(io.StringIO()):
                est = check_simulation(args, load_spec(PROBLEMS / argv[0], seeds=seeds))
            t0 = time.perf_counter()
            subprocess.run([str(script), *full], cwd=d, capture_output=True, check=True)
            wall = time.perf_counter() - t0
            rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
        if base is None:  # the interpreter and its libraries: not in the estimates
            base = rss
            print(f"  a small run: {wall:.1f} s, peak resident {format_bytes(rss)} (the "
                  "interpreter and libraries)")
            continue
        print(f"  simulate {' '.join(argv)}: estimated {est.seconds:.0f} s and "
              f"{format_bytes(est.memory)}; measured {wall:.1f} s and {format_bytes(rss - base)}"
              " above the interpreter")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--showcase", action="store_true", help="also the default lcc-synth run")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="skip the 200-seed runs of section 6")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        showcase = None
        if args.showcase:
            import contextlib
            import io

            from lcc_synth.cli.main import main as cli

            showcase = tmp / "showcase.rrd"
            t0 = time.perf_counter()
            with contextlib.redirect_stdout(io.StringIO()):
                cli(["run", "--rrd", str(showcase), "--out", str(tmp / "res"), "--no-figures",
                     "--no-progress"])  # fmt: skip
            print(f"lcc-synth run: {time.perf_counter() - t0:.0f} s, "
                  f"{showcase.stat().st_size / 1e6:.2f} MB")
        unit_bytes(tmp)
        minmax_rates(tmp, showcase)
        estimates(tmp, showcase)
    unit_times(args.repeats)
    unit_memory()
    run_estimates(args.quick)


if __name__ == "__main__":
    main()
