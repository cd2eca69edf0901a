"""``lcc-synth sweep PROBLEM.toml``: Monte Carlo robustness sweep on Dask.

Runs ``[sweep] count`` random scenarios for every controller (see
:mod:`lcc_synth.experiments.sweep`), prints mean and 5th / 95th percentiles of the metrics and
the counts of collisions, emergency brakings and MPC fallbacks, and writes under
``results/<problem>-<UTC timestamp>/``: ``sweep.json`` (the ``--json`` document, with its
provenance), ``samples.csv`` (every scenario's metrics) and ``distributions.png``
(``--format pdf|svg``: ``.pdf``, ``.svg``; :mod:`lcc_synth.experiments.sweep_files`); and a
Rerun recording (``logs/<problem>-<UTC timestamp>.rrd``, ``--rrd PATH`` / ``--no-record``) of
every scenario's metrics per controller and the summary (:mod:`lcc_synth.recording.sweep`),
with beside it
``<stem>-scenario<i>.rrd``: the hardest scenario simulated again with every controller
(:mod:`lcc_synth.experiments.sweep_review`).

By default the tasks run on a local Dask cluster (``--workers`` single-threaded processes, no
dashboard, scratch space in a temporary directory); ``--scheduler ADDRESS`` uses an existing
cluster instead (its workers need the same ``lcc_synth`` installed).

Before the work (exit 2, one line): the sweep's memory and disk estimate
(:mod:`lcc_synth.experiments.sweep_estimate`) must fit, naming ``--count`` (or
``[sweep].count``) otherwise; the results directory is created (exclusively) and a file is
written in it, and ``--rrd``'s directory is probed, before the cluster starts. A sweep
estimated to run longer than a minute prints its estimate first (one line on stderr); the
hardest scenario's second simulation has its own progress bar; ``--quiet`` silences both.

Nothing finished is lost: the partial ``samples.csv`` and ``sweep.json`` (``"partial":
true``) are written while the sweep runs (after the first task, then every few seconds) and
once more when it is interrupted (SIGINT, SIGTERM: the workers are stopped, the scratch space
removed, exit 130 / 143) or fails; ``--resume DIR`` continues that sweep in ``DIR`` to the
results of an uninterrupted one, bit for bit. The recording is written for a complete sweep
only. A results file that cannot be written at the end (a full disk) is one line naming it
(exit 1), after the summary is printed.
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
        "--batch-size", type=int, metavar="B",
        help="scenarios per Dask task (default: [sweep] batch_size at most, fewer when the "
        "count is small for the workers, so that every worker has tasks)",
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
    parser.add_argument(
        "--resume", metavar="DIR",
        help="continue the interrupted sweep whose results directory is DIR, in DIR (the same "
        "problem file; --count, --batch-size, --seed and --controllers default to its own and "
        "must match it)",
    )  # fmt: skip
    add_output_arguments(parser, "the sweep", "the distributions figure")
    add_recording(parser, steps=False)


def _client(args, into: dict) -> None:
    """The Dask client (and the local cluster) in ``into["client"]`` (``into["cluster"]``),
    each stored as soon as it exists, so that a failure in between still closes the other."""
    from dask.distributed import Client

    from lcc_synth.errors import ConfigError

    if args.scheduler:
        try:
            into["client"] = Client(args.scheduler, timeout="15s")
            return
        except (OSError, TimeoutError, ValueError) as err:
            raise ConfigError(
                "--scheduler", f"cannot connect to the Dask scheduler {args.scheduler!r}: {err}"
            ) from None
    from lcc_synth.experiments.sweep import local_cluster

    into["cluster"] = local_cluster(2 if args.workers is None else args.workers)
    into["client"] = Client(into["cluster"])


def _start_client(args, into: dict):
    """Start :func:`_client` in a thread (``into["starting"]``); return ``connect()``, which
    waits for it and returns the client or raises what the start raised.

    The local cluster's workers start (2-4 s, mostly their imports, in their own processes)
    while the calling thread synthesises the controllers; the thread stores the cluster and
    the client in ``into`` as soon as each exists, so the caller's clean-up (after joining
    ``into["starting"]``) closes whatever was made, also after an interrupt of the synthesis.
    """
    import threading

    failed: list[BaseException] = []

    def start() -> None:
        try:
            _client(args, into)
        except BaseException as err:  # handed to the caller's thread by connect()
            failed.append(err)

    thread = threading.Thread(target=start, name="lcc-sweep-cluster-start", daemon=True)
    into["starting"] = thread
    thread.start()

    def connect():
        thread.join()
        if failed:
            raise failed[0]
        return into["client"]

    return connect


def _lock(directory) -> int:
    """An exclusive lock on the results directory for this run (two runs resuming the same
    directory would write over each other); released when the process ends."""
    import fcntl
    import os

    from lcc_synth.errors import ConfigError

    fd = os.open(directory, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise ConfigError("--resume", f"{directory} is being written by another lcc-synth "
                          "sweep right now") from None  # fmt: skip
    return fd


def _settings(args, partial):
    """``count, batch_size, seed, controllers`` of the command line, where it gives none
    those of the interrupted sweep (``--resume``)."""
    names = None if args.controllers is None else args.controllers.split(",")
    got = {"count": args.count, "batch_size": args.batch_size, "seed": args.seed,
           "controllers": names}  # fmt: skip
    if partial is not None:
        got = {k: (v if v is not None else partial.overrides()[k]) for k, v in got.items()}
    return got


def run(args: argparse.Namespace) -> int:
    import os
    import threading
    from datetime import UTC, datetime

    from lcc_synth.errors import ConfigError, FileError
    from lcc_synth.experiments.sweep import (
        SWEEP_METRICS,
        SweepProgress,
        format_summary,
        load_sweep,
        run_sweep,
        stop_cluster,
    )
    from lcc_synth.experiments.sweep_estimate import LONG_S, estimate_sweep
    from lcc_synth.experiments.sweep_files import ResultsWriter, complete_doc, read_partial
    from lcc_synth.outputs import check_directory, new_directory, writing
    from lcc_synth.recording import recording_path
    from lcc_synth.resources import notice

    if args.scheduler is not None and args.workers is not None:
        raise ConfigError("--workers", "does not apply with --scheduler (its cluster has its own)")
    if args.workers is not None and not 1 <= args.workers <= 256:
        raise ConfigError("--workers", f"must be an integer in [1, 256], got {args.workers}")
    partial = read_partial(args.resume) if args.resume else None
    got = _settings(args, partial)
    workers = None if args.scheduler else (2 if args.workers is None else args.workers)
    spec = load_sweep(args.problem, got["count"], got["batch_size"], got["seed"],
                      got["controllers"], workers)  # fmt: skip
    if partial is not None:
        partial.check(spec, args.problem)
    rrd = recording_path(args, spec.name)  # a bad --rrd fails before the sweep runs
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    log = sys.stderr if args.json else sys.stdout
    progress = not args.quiet

    # before the work: memory, disk, a results directory that takes files
    estimate = estimate_sweep(spec, 2 if args.workers is None else args.workers, rrd is not None)
    count_field = "--count" if args.count is not None else "sweep.count"
    hint = "lower the count"
    if rrd is not None:
        from lcc_synth.resources import format_bytes

        plain = estimate_sweep(spec, estimate.workers, record=False).memory
        hint += f", or pass --no-record (the recording copies the samples; {format_bytes(plain)}"
        hint += " without it)"
    estimate.require_memory(count_field, hint)
    if partial is not None:
        out_dir = check_directory(partial.directory, "--resume")
        estimate.require_disk(count_field, out_dir)
    else:
        check_directory(args.out, "--out")
        estimate.require_disk(count_field, args.out)
        out_dir = check_directory(new_directory(args.out, spec.name, stamp), "--out")
    from lcc_synth.synthesis.h2 import SynthesisError  # after the checks: they need no solver

    done = SweepProgress.new(spec)
    start = -1  # scenarios finished when this run started (-1: a new results directory)
    writer = ResultsWriter(out_dir, spec)
    handles: dict = {}
    result = None
    try:
        lock = _lock(out_dir)
        if rrd is not None:
            check_directory(rrd.parent, "--rrd")
        if partial is not None:
            done = partial.progress(spec)
            start = done.done
        if estimate.seconds > LONG_S and not args.scheduler:
            notice("sweep", f"estimate: {estimate.describe()}")
        from lcc_synth.interrupts import held_signals

        where = args.scheduler or f"a local cluster of {estimate.workers} workers"
        notice("sweep", f"starting the Dask client on {where}")  # 2-10 s here, before any bar
        connect = None
        if args.scheduler:
            with held_signals():
                _client(args, handles)
            if estimate.seconds > LONG_S:
                threads = sum(handles["client"].nthreads().values()) or 1
                again = estimate_sweep(spec, threads, rrd is not None)
                notice("sweep", f"estimate: {again.describe()}")
        else:  # the local workers start while this thread synthesises the controllers
            connect = _start_client(args, handles)
        result = run_sweep(spec, client=handles.get("client"), progress=progress, done=done,
                           on_task=writer.on_task, connect=connect)  # fmt: skip
    except SynthesisError as err:
        _keep(writer, done, args, out_dir, start, "failed: synthesis")
        print(f"lcc-synth sweep: synthesis failed: {err}", file=sys.stderr)
        return 1
    except BaseException as err:
        _keep(writer, done, args, out_dir, start, _status(err))
        raise
    finally:
        if "starting" in handles:  # a cluster still starting: it exists before it is stopped
            handles["starting"].join()
        if result is None:
            stop_cluster(handles.get("cluster"), handles.get("client"), now=True)

    # the workers close (1-3 s) while this thread writes the results, the figure and the
    # recordings; every way out of run() waits for them
    stopping = threading.Thread(target=stop_cluster, name="lcc-sweep-cluster-stop",
                                args=(handles.get("cluster"), handles.get("client")))
    stopping.start()
    try:
        failure = None
        notice("sweep", "writing the results" + ("" if args.no_figures else " and the figure"))
        try:
            doc = complete_doc(spec, result)
            writer.complete(done, doc)
            if not args.no_figures:
                from lcc_synth.figures import plot_sweep_distributions

                with writing(out_dir / f"distributions.{args.format}", overwrite=True) as png:
                    plot_sweep_distributions(
                        result.samples, png.tmp, metrics=SWEEP_METRICS,
                        title=f"{spec.name}: {spec.count} scenarios (box 25-75 %, whiskers 5-95 %, "
                        "dot = mean)",
                    )
        except FileError as err:
            failure = err
        except BaseException as err:  # interrupted while writing: keep what is on disk usable
            _keep(writer, done, args, out_dir, start, _status(err))
            raise
        info = result.info
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
            f"({_rate(info['scenarios_per_s'])} scenarios/s, {_rate(info['runs_per_s'])} "
            f"scenario-controller runs/s); synthesis {info['synthesis_time_s']:.1f} s",
            file=log,
        )
        if failure is None:
            print(f"results: {out_dir}", file=log)
        failed = _failure_lines(result.summary)
        for line in failed:
            print(f"lcc-synth sweep: {line}", file=sys.stderr)
        sys.stdout.flush()
        if rrd is not None:
            try:
                _record(rrd, spec, result, doc.get("provenance"), "\n".join(failed))
            except FileError as err:
                if failure is None:
                    raise
                print(f"lcc-synth sweep: the recording was not written either: {err}",
                      file=sys.stderr)  # fmt: skip
        if failure is not None:
            if writer.written > 0:
                print(f"lcc-synth sweep: {out_dir} keeps the partial results of "
                      f"{writer.written} of {spec.count} scenarios", file=sys.stderr)  # fmt: skip
            raise failure
        os.close(lock)
        return 1 if failed else 0
    finally:
        stopping.join()


def _failure_lines(summary) -> list[str]:
    """``failed: NAME: ...`` for every controller whose solver failed (fell back) on some step
    of some scenario: what makes the sweep exit 1."""
    return [f"failed: {name}: its solver failed on {e['fallbacks']} steps (MPC fallbacks) "
            "over the scenarios" for name, e in summary.items() if e.get("fallbacks")]


def _rate(x) -> str:
    return "-" if x is None else f"{x:.3g}"


def _status(err: BaseException) -> str:
    from lcc_synth.interrupts import interruption_behind

    stop = interruption_behind(err)
    if stop is not None:
        return f"interrupted by {stop.signame}"
    if isinstance(err, KeyboardInterrupt):
        return "interrupted"
    return f"failed: {type(err).__name__}: {err}"


def _remove_empty(directory) -> None:
    from lcc_synth.outputs import remove_if_empty

    remove_if_empty(directory)


def _keep(writer, done, args, out_dir, start: int, status: str) -> None:
    """A sweep that stopped (``status``): write what finished as the partial results and say
    how to continue it. ``start``: the scenarios finished when this run started (-1: its
    results directory is new, and removed if it stays empty)."""
    stopped = status.startswith("interrupted")
    if done.done > max(start, 0):
        ok = writer.partial(done, status)
        kept = done.done if ok else writer.written
    else:  # nothing new: the files on disk are as they were
        kept = start
        if start < 0:
            _remove_empty(out_dir)
    if kept > 0 and (stopped or done.done > max(start, 0)):
        print(f"lcc-synth sweep: kept {kept} of {done.count} scenarios in {out_dir} "
              f"(samples.csv, sweep.json: partial); continue with: lcc-synth sweep "
              f"{args.problem} --resume {out_dir} (the recording is written when the sweep "
              "is complete)", file=sys.stderr, flush=True)  # fmt: skip
    elif stopped and kept <= 0:
        print("lcc-synth sweep: no scenario had finished: nothing to keep", file=sys.stderr)


def _record(rrd, spec, result, provenance=None, failed: str = "") -> None:
    """The sweep's recording at ``rrd`` and, next to it (``<stem>-scenario<i>.rrd``), a
    simulation recording of its hardest scenario with every controller
    (:mod:`lcc_synth.experiments.sweep_review`); both carry the ``provenance`` and say
    ``failed`` (the solver failures) in their status."""
    from contextlib import ExitStack

    from lcc_synth.experiments.sweep import SWEEP_SAMPLES
    from lcc_synth.experiments.sweep_review import hardest_scenario, simulate_scenario
    from lcc_synth.metrics import summary
    from lcc_synth.recording import SimulationRecorder, record_sweep_file
    from lcc_synth.resources import notice

    hard = hardest_scenario(result.samples)
    second = rrd.with_name(f"{rrd.stem}-scenario{hard.index}.rrd")
    what = (f"scenario {hard.index}: {hard.controller} "
            f"{'collided' if hard.collided else f'min spacing {hard.min_spacing:.3g} m'}")
    info = {**result.info, "hardest scenario": what, "its recording": str(second)}
    notice("sweep", "writing the recording")
    rrd = record_sweep_file(rrd, spec.name, result.samples, SWEEP_SAMPLES, result.summary, info,
                            provenance=provenance, failed=failed)  # fmt: skip
    print(f"recording: {rrd} (lcc-synth review {rrd})", file=sys.stderr)
    scenario, runs, ctrls = simulate_scenario(spec, result.worker_tables, hard.index, progress=True,
                                              gains=result.gains)  # fmt: skip
    view = argparse.Namespace(rrd=str(second), no_record=False, record_every="minmax")
    one = argparse.Namespace(name=f"{spec.name}_scenario{hard.index}", controllers=ctrls,
                             scenario=scenario)  # fmt: skip
    with ExitStack() as stack:
        recorder = SimulationRecorder(view, stack)
        recorder.provenance = provenance
        for name, res in runs.items():
            recorder(one, name, res)
        recorder.metrics({name: summary(res, spec.metrics) for name, res in runs.items()})
        if failed:
            recorder.status("partial", failed)
    second = recorder.written or second
    print(f"hardest {what}; every controller on it: {second} (lcc-synth review {second})",
          file=sys.stderr)
