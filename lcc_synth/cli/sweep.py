"""``lcc-synth sweep PROBLEM.toml``: Monte Carlo robustness sweep on Dask.

Runs ``[sweep] count`` random scenarios for every controller (see
:mod:`lcc_synth.experiments.sweep`), prints mean and 5th / 95th percentiles of the metrics and
the counts of collisions, emergency brakings and MPC fallbacks, and writes under
``results/<problem>-<UTC timestamp>/``: ``sweep.json`` (the ``--json`` document),
``samples.csv`` (every scenario's metrics) and ``distributions.png``; and a Rerun recording
(``logs/<problem>-<UTC timestamp>.rrd``, ``--rrd PATH`` / ``--no-record``) of every scenario's
metrics per controller and the summary (:mod:`lcc_synth.recording.sweep`), with beside it
``<stem>-scenario<i>.rrd``: the hardest scenario simulated again with every controller
(:mod:`lcc_synth.experiments.sweep_review`).

By default the tasks run on a local Dask cluster (``--workers`` single-threaded processes, no
dashboard, scratch space in a temporary directory); ``--scheduler ADDRESS`` uses an existing
cluster instead (its workers need the same ``lcc_synth`` installed).
"""

from __future__ import annotations

import argparse
import json
import sys

from lcc_synth.cli.arguments import add_output_arguments, add_problem_arguments, add_recording

HELP = "Monte Carlo robustness sweep of every controller on a Dask cluster"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_problem_arguments(parser, "sweep problem file (TOML) with a [sweep] table")
    parser.add_argument("--count", type=int, metavar="N", help="scenarios (overrides [sweep])")
    parser.add_argument(
        "--batch-size", type=int, metavar="B", help="scenarios per Dask task (overrides [sweep])"
    )
    parser.add_argument("--seed", type=int, metavar="S", help="base seed (overrides [scenario])")
    parser.add_argument(
        "--scheduler", metavar="ADDRESS",
        help="address of an existing Dask scheduler (e.g. tcp://10.0.0.5:8786); default: a "
        "local cluster on this machine",
    )
    parser.add_argument(
        "--workers", type=int, default=None, metavar="N",
        help="worker processes of the local cluster (default 2; not with --scheduler)",
    )
    add_output_arguments(parser, "the sweep", "the PNG")
    add_recording(parser, steps=False)


def _client(args):
    from dask.distributed import Client

    from lcc_synth.errors import ConfigError

    if args.scheduler:
        try:
            return Client(args.scheduler, timeout="15s"), None
        except (OSError, TimeoutError, ValueError) as err:
            raise ConfigError(
                "--scheduler", f"cannot connect to the Dask scheduler {args.scheduler!r}: {err}"
            ) from None
    from lcc_synth.experiments.sweep import local_cluster

    cluster = local_cluster(2 if args.workers is None else args.workers)
    return Client(cluster), cluster


def run(args: argparse.Namespace) -> int:
    import csv
    from datetime import UTC, datetime

    from lcc_synth.errors import ConfigError
    from lcc_synth.experiments.sweep import (
        SWEEP_METRICS,
        SWEEP_SAMPLES,
        format_summary,
        load_sweep,
        run_sweep,
    )
    from lcc_synth.experiments.tables import json_safe, run_directory
    from lcc_synth.recording import recording_path
    from lcc_synth.synthesis.h2 import SynthesisError

    if args.scheduler is not None and args.workers is not None:
        raise ConfigError("--workers", "does not apply with --scheduler (its cluster has its own)")
    if args.workers is not None and not 1 <= args.workers <= 256:
        raise ConfigError("--workers", f"must be an integer in [1, 256], got {args.workers}")
    names = None if args.controllers is None else args.controllers.split(",")
    spec = load_sweep(args.problem, args.count, args.batch_size, args.seed, names)
    rrd = recording_path(args, spec.name)  # a bad --rrd fails before the sweep runs
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    log = sys.stderr if args.json else sys.stdout
    progress = not args.no_progress

    client, cluster = _client(args)
    try:
        try:
            result = run_sweep(spec, client=client, progress=progress)
        except SynthesisError as err:
            print(f"lcc-synth sweep: synthesis failed: {err}", file=sys.stderr)
            return 1
    finally:
        client.close()
        if cluster is not None:
            cluster.close()

    doc = json_safe({"results": result.summary, "sweep": result.info})
    out_dir = run_directory(args.out, spec.name, stamp)
    (out_dir / "sweep.json").write_text(json.dumps(doc, indent=2) + "\n")
    with (out_dir / "samples.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        keys = list(SWEEP_SAMPLES)
        w.writerow(["scenario", "controller", *keys])
        for c, per in result.samples.items():
            for i in range(spec.count):
                w.writerow([i, c, *(per[k][i] for k in keys)])
    written = [out_dir / "sweep.json", out_dir / "samples.csv"]
    if not args.no_figures:
        from lcc_synth.figures import plot_sweep_distributions

        written.append(
            plot_sweep_distributions(
                result.samples, out_dir / "distributions.png", metrics=SWEEP_METRICS,
                title=f"{spec.name}: {spec.count} scenarios (box 25-75 %, whiskers 5-95 %, "
                "dot = mean)",
            )
        )
    info = result.info
    if rrd is not None:
        _record(rrd, spec, result)
    if args.json:
        print(json.dumps(doc))
    else:
        print(
            f"{spec.name}: {spec.count} scenarios x {len(result.summary)} controllers, "
            f"seed {spec.seed}, {info['tasks']} tasks of <= {spec.batch_size}; mean [p5, p95]"
        )
        print(format_summary(result.summary))
    print(
        f"time: {info['wall_time_s']:.1f} s on {info['scheduler']} "
        f"({info['scenarios_per_s']:.1f} scenarios/s, {info['runs_per_s']:.1f} "
        f"scenario-controller runs/s); synthesis {info['synthesis_time_s']:.1f} s",
        file=log,
    )
    print(f"results: {out_dir}", file=log)
    return 0


def _record(rrd, spec, result) -> None:
    """The sweep's recording at ``rrd`` and, next to it (``<stem>-scenario<i>.rrd``), a
    simulation recording of its hardest scenario with every controller
    (:mod:`lcc_synth.experiments.sweep_review`)."""
    from contextlib import ExitStack

    from lcc_synth.experiments.sweep import SWEEP_SAMPLES
    from lcc_synth.experiments.sweep_review import hardest_scenario, simulate_scenario
    from lcc_synth.metrics import summary
    from lcc_synth.recording import SimulationRecorder, record_sweep_file

    hard = hardest_scenario(result.samples)
    second = rrd.with_name(f"{rrd.stem}-scenario{hard.index}.rrd")
    what = (f"scenario {hard.index}: {hard.controller} "
            f"{'collided' if hard.collided else f'min spacing {hard.min_spacing:.3g} m'}")
    info = {**result.info, "hardest scenario": what, "its recording": str(second)}
    record_sweep_file(rrd, spec.name, result.samples, SWEEP_SAMPLES, result.summary, info)
    print(f"recording: {rrd} (lcc-synth review {rrd})", file=sys.stderr)
    scenario, runs, ctrls = simulate_scenario(spec, result.tables, hard.index)
    view = argparse.Namespace(rrd=str(second), no_record=False, record_every="minmax")
    one = argparse.Namespace(name=f"{spec.name}_scenario{hard.index}", controllers=ctrls,
                             scenario=scenario)  # fmt: skip
    with ExitStack() as stack:
        recorder = SimulationRecorder(view, stack)
        for name, res in runs.items():
            recorder(one, name, res)
        recorder.metrics({name: summary(res, spec.metrics) for name, res in runs.items()})
    print(f"hardest {what}; every controller on it: {second} (lcc-synth review {second})",
          file=sys.stderr)
