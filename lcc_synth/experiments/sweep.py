"""Monte Carlo robustness sweeps on Dask (``lcc-synth sweep``).

A sweep runs ``count`` random scenarios for every controller of a problem file and reports,
per controller, the mean and the 5th / 95th percentiles of the metrics and the counts of
collisions, emergency brakings and MPC fallbacks. A run with a collision has no AAVE or fuel
(:mod:`lcc_synth.metrics`): their distributions are over the runs without one, and the
summary says how many runs each controller lost that way.

What is random
--------------
Every scenario ``i`` (``0 <= i < count``) draws, from ``(seed, i)`` only, its heterogeneous HDV
parameters (``[scenario.heterogeneity]``), its reaction delays (``[scenario.delay]``), and the
realisations of the HDV acceleration noise (``hdv_accel_noise``) and of the V2V packet losses
and measurement noise (``[scenario.v2v]``). ``hdv_accel_noise`` and the ``[scenario.v2v]``
``loss_rate``, ``latency`` and ``*_noise`` may be ranges ``[lo, hi]``: each scenario draws its
own value U[lo, hi] from ``(seed, i)`` (:func:`~lcc_synth.simulation.scenario.split_ranges`;
such scenarios are simulated one by one); a number stays fixed. This is the
simulator's own draw (:attr:`lcc_synth.simulation.scenario.Scenario.first_index`), so a scenario's
result does not depend on how scenarios are grouped into tasks, nor on the worker running it.

Execution
---------
Scenarios are cut into tasks of ``batch_size`` consecutive indices (``lcc-synth sweep``
makes them smaller when the count is small for its workers, :func:`task_size`); a task simulates its
scenarios as ONE batch per controller (the simulator's batch axis; all controllers on the same
draws) and returns the per-scenario metrics. Tasks run on a Dask cluster (a ``LocalCluster`` of
processes by default, or any scheduler address) with retries; Dask recomputes the tasks of a
worker that dies. A task whose input is bad (a :class:`~lcc_synth.errors.ConfigError` raised on
the worker) is not retried: the error comes back to the client as it is. ``h2`` controllers are
synthesised once, in the client, and ``gains_file`` controllers are read there. Workers receive
the synthesised gains as objects (:class:`~lcc_synth.models.feedback.Gains`, pickled with the
task) with the tables of how each law runs, and build (and cache, per process and thread) the
controllers with the functions ``lcc-synth run`` builds them with
(:func:`lcc_synth.experiments.deeplcc_runs.scenario_controllers`, the gain an ``h2`` table and
an MPC's ``fallback = "NAME"`` run with picked by
:func:`lcc_synth.experiments.spec.controller_gain`): no gain is read back from a table there.
The plain tables (``h2`` as its static table, fallbacks inlined) are what the results files
hold and what a resumed sweep checks. (An MPC's ``fallback_gains_file`` is read on the worker:
give it a path the workers can read.) At most a few tasks per worker thread are submitted at a
time (the next one when one finishes): the client and the scheduler hold a bounded number of
tasks whatever the count, and an interrupted sweep has little to cancel.

Finished work is kept
---------------------
What a sweep has finished is a :class:`~lcc_synth.experiments.sweep_samples.SweepProgress`:
the samples of the finished tasks and their counts. :func:`run_sweep` fills the one it is
given (``done=``), calls ``on_task`` after each task (``lcc-synth sweep`` writes the partial
results files from it, :mod:`lcc_synth.experiments.sweep_files`) and, given one that already
holds finished tasks (an interrupted sweep read back), runs only the others: the samples, the
summary and every count equal those of an uninterrupted sweep bit for bit (a task's result
depends on its scenario indices only). The cluster's side (a local cluster whose workers leave
the signals to the client, its stop, the window of tasks in flight) is in
:mod:`lcc_synth.experiments.sweep_cluster`.

The problem file's tables (``[sweep]`` ``count`` and ``batch_size``, the ``[lo, hi]`` ranges)
are in ``problems/REFERENCE.md``.
"""

from __future__ import annotations

import hashlib
import pickle
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.experiments.sweep_cluster import (
    TASKS_PER_THREAD,
    local_cluster,
    run_tasks,
    stop_cluster,
    task_size,
)
from lcc_synth.experiments.sweep_samples import (
    SWEEP_COUNTS,
    SWEEP_METRICS,
    SWEEP_SAMPLES,
    SweepProgress,
    aggregate,
    table_digest,
)
from lcc_synth.metrics import MetricsConfig, sweep_safety_rank
from lcc_synth.models.feedback import Gains
from lcc_synth.models.records import Record, system_tables
from lcc_synth.problem import Problem, System, check_top_level, load_problem, system_from
from lcc_synth.schema import declared
from lcc_synth.simulation.checks import check_ranges
from lcc_synth.simulation.scenario import Scenario, split_ranges
from lcc_synth.simulation.scenario_file import scenario_from

__all__ = [
    "SWEEP_METRICS", "SWEEP_SAMPLES", "SWEEP_COUNTS", "MAX_COUNT", "TASKS_PER_THREAD",
    "SweepSpec", "SweepResult", "SweepProgress", "load_sweep", "chunks", "scenario_metrics",
    "run_chunk", "aggregate", "run_sweep", "local_cluster", "stop_cluster", "table_digest",
    "format_summary", "task_size", "worker_controllers",
]  # fmt: skip

#: Largest ``[sweep].count`` and ``batch_size`` (declared in :mod:`lcc_synth.schema`).
MAX_COUNT = int(declared("sweep").key("count").hi)
_MAX_BATCH = int(declared("sweep").key("batch_size").hi)
@dataclass(frozen=True, repr=False)
class SweepSpec(Record):
    """A parsed sweep problem (see the module docstring)."""

    name: str
    system: System
    scenario: Scenario
    metrics: MetricsConfig
    controllers: dict[str, dict[str, Any]]
    count: int
    batch_size: int
    source: str | None = None
    #: ``{"v2v.loss_rate": (lo, hi), ...}``: settings drawn per scenario.
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    fallbacks: dict[str, dict[str, Any]] = field(default_factory=dict)  # as Suite.fallbacks

    @property
    def seed(self) -> int:
        return self.scenario.seed

    def toml_tables(self) -> dict[str, Any]:
        """The tables :func:`load_sweep` reads back into an equal spec."""
        tables = {"scenario": self.scenario.toml_table(), "metrics": self.metrics.toml_table(),
                  "sweep": {"count": self.count, "batch_size": self.batch_size}}  # fmt: skip
        for key, (lo, hi) in self.ranges.items():  # settings drawn per scenario: [lo, hi]
            *parent, leaf = key.split(".")
            t = tables["scenario"]
            for p in parent:
                t = t.setdefault(p, {})
            t[leaf] = [lo, hi]
        ctrls = {k: dict(t) for k, t in {**self.controllers, **self.fallbacks}.items()}
        return {"name": self.name, **system_tables(self.system), **tables, "controllers": ctrls}


def _count(value, field_name: str, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or not 1 <= value <= hi:
        raise ConfigError(field_name, f"must be an integer in [1, {hi}], got {value!r}")
    return int(value)


def load_sweep(
    path: str | Path | Problem, count: int | None = None, batch_size: int | None = None,
    seed: int | None = None, controllers: Sequence[str] | None = None,
    workers: int | None = None,
) -> SweepSpec:  # fmt: skip
    """Read a sweep problem file; ``count``, ``batch_size``, ``seed`` override the file.

    With ``workers`` (the worker threads the sweep will run on) and no ``batch_size``, the
    file's ``batch_size`` is the largest task: :func:`task_size` makes the tasks smaller when
    the count is small for the workers (a scenario's result does not depend on it). A given
    ``batch_size`` is taken as it is.

    Everything is checked here, in the client, before any work: every value a random draw can
    produce (:mod:`lcc_synth.simulation.checks`), the controllers' ``start`` times and the
    gains files they name.

    Raises
    ------
    ConfigError
        A bad table or value, an unknown controller name, counts out of range.
    """
    from lcc_synth.controllers.gains_files import check_gains_files
    from lcc_synth.experiments.comparison import fallback_names, select_names
    from lcc_synth.experiments.spec import check_starts
    from lcc_synth.metrics import metrics_from

    problem = path if isinstance(path, Problem) else load_problem(path)
    src = str(problem.path)
    try:
        data = problem.data
        check_top_level(data)
        system = system_from(data, src)
        nv = system.columns  # [lo, hi] settings drawn per scenario:
        sc_table, ranges = split_ranges(declared("").get(data, "scenario", ""), nv)
        scenario = scenario_from({**data, "scenario": sc_table}, system, problem.path.parent)
        check_ranges(scenario, ranges)  # the upper bounds too (the lower: just now)
        metrics = metrics_from(data, system, scenario=scenario)
        SW = declared("sweep")
        sw = declared("").get(data, "sweep", "")
        SW.check(sw, "sweep")
        n = SW.get(sw, "count", "sweep")
        bs = SW.get(sw, "batch_size", "sweep")
        if count is not None:
            n = _count(count, "--count", MAX_COUNT)
        if batch_size is not None:
            bs = _count(batch_size, "--batch-size", _MAX_BATCH)
        elif workers is not None:
            bs = task_size(n, workers, bs)
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
                raise ConfigError("--seed", f"must be an integer >= 0, got {seed!r}")
            scenario = replace(scenario, seed=int(seed))
        scenario = replace(scenario, batch=1, first_index=0, name=problem.name)
        tables = declared("").get(data, "controllers", "")
        if not tables:
            raise ConfigError("controllers", "needs at least one [controllers.NAME] table")
        names = select_names(list(tables), controllers, "--controllers")
        extra = fallback_names(tables, names)
        ctrls = {}
        for name in names + extra:
            t = tables[name]
            if not isinstance(t, dict):
                raise ConfigError(f"controllers.{name}", "must be a table")
            declared("controllers.NAME:suite").get(t, "type", f"controllers.{name}")
            if "layouts" in t:
                raise ConfigError(f"controllers.{name}.layouts", "a sweep has one layout")
            ctrls[name] = dict(t)
        check_starts({k: ctrls[k] for k in names}, scenario)
        check_gains_files(ctrls, system, src)  # read in the client, before any design
        return SweepSpec(
            name=problem.name,
            system=system,
            scenario=scenario,
            metrics=metrics,
            controllers={k: ctrls[k] for k in names},
            fallbacks={k: ctrls[k] for k in extra},
            count=n,
            batch_size=min(bs, n),
            source=src,
            ranges=ranges,
        )
    except ConfigError as err:
        raise err.with_source(src) if not err.source else err from None


def chunks(count: int, batch_size: int) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` covering ``0..count-1`` with at most ``batch_size`` each."""
    count = _count(count, "count", MAX_COUNT)
    batch_size = _count(batch_size, "batch_size", _MAX_BATCH)
    return [(s, min(s + batch_size, count)) for s in range(0, count, batch_size)]


# --------------------------------------------------------------------------------------------
# The task
# --------------------------------------------------------------------------------------------


_BATCH_FIELDS = (
    "position", "velocity", "acceleration", "spacing", "u_cmd", "aeb_active", "collided",
    "collision_time", "v_star", "s_star",
)


def _member(result, b: int):
    """Scenario ``b`` of a batched result as a batch of one (views, no copies)."""
    return replace(result, **{k: getattr(result, k)[b : b + 1] for k in _BATCH_FIELDS})


def _one(result, config: MetricsConfig) -> dict[str, float | int]:
    from lcc_synth.metrics import (
        aave,
        aeb_activations,
        collisions,
        fuel,
        jerk_limit_violation_time,
        max_abs_command,
        max_jerk_1s,
        min_spacing,
        min_time_to_collision,
        rms_jerk,
        wave_metrics,
    )

    return {
        "aave": aave(result, config.window, config.vehicles)[0],
        "fuel_ml": fuel(result, config.window, config.vehicles)[0],
        "min_spacing": np.nanmin(min_spacing(result)[0, 1:]),
        "min_ttc": np.nanmin(min_time_to_collision(result)[0, 1:]),
        "max_abs_command": max_abs_command(result)[0],
        "rms_jerk_cav": rms_jerk(result)[0],
        "max_jerk_1s_cav": max_jerk_1s(result)[0],
        "jerk_1s_over_limit_s": jerk_limit_violation_time(result)[0],
        "collisions": collisions(result)[0],
        "aeb_activations": aeb_activations(result)[0],
        **{k: x[0] for k, x in wave_metrics(result, config).items()},  # the ring benchmark's
    }


def scenario_metrics(result, config: MetricsConfig) -> dict[str, np.ndarray]:
    """Per-scenario metrics of a batched result (``(batch,)`` arrays), from
    :mod:`lcc_synth.metrics`: AAVE, fuel, worst spacing and time to collision over the
    vehicles, max |u|, CAV RMS jerk and max 1 s average jerk, the time its 1 s average jerk
    spends above ISO 15622's limit, collided vehicles and emergency-braking steps.

    Each scenario is reduced on its own, so its numbers are bit-for-bit the same whatever the
    batch it was simulated in (a reduction over a whole batch may round differently).
    """
    rows = [_one(_member(result, b), config) for b in range(result.batch)]
    out = {k: np.array([r[k] for r in rows], dtype=float)
           for k in (*SWEEP_METRICS, "jerk_1s_over_limit_s")}  # fmt: skip
    for k in ("collisions", "aeb_activations"):
        out[k] = np.array([r[k] for r in rows], dtype=np.int64)
    return out


_CACHE: dict[tuple[str, int], dict[str, Any]] = {}
_CACHE_LOCK = threading.Lock()


def _token(*parts: Any) -> str:
    return hashlib.sha256(pickle.dumps(parts)).hexdigest()


def _controllers(tables: Mapping[str, Mapping[str, Any]], system: System, source: str | None,
                 gains: Mapping[str, Gains] | None = None):  # fmt: skip
    """Controllers of ``tables`` and the gain objects ``gains`` (``{name: Gains}``), built once
    per process and thread (MPCs hold solver state)."""
    from lcc_synth.experiments.deeplcc_runs import scenario_controllers as build_controllers

    key = (_token(dict(tables), system, source, dict(gains or {})), threading.get_ident())
    with _CACHE_LOCK:
        ctrls = _CACHE.get(key)
    if ctrls is None:
        ctrls = build_controllers(tables, system, source, gains)
        for c in ctrls.values():
            if hasattr(c, "history"):
                c.record = False  # an MPC's per-step history is not needed here
        with _CACHE_LOCK:
            _CACHE[key] = ctrls
    return ctrls


def run_chunk(
    scenario: Scenario,
    system: System,
    tables: Mapping[str, Mapping[str, Any]],
    config: MetricsConfig,
    source: str | None,
    start: int,
    stop: int,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    gains: Mapping[str, Gains] | None = None,
) -> dict[str, Any]:
    """Simulate scenarios ``start .. stop - 1`` with every controller (one batch each; with
    ``ranges``, :attr:`SweepSpec.ranges`, each scenario alone with its drawn settings; a
    ``deep_lcc`` controller on each scenario's own data, :mod:`.deeplcc_runs`).

    The controllers are those of ``tables`` built with the gain objects ``gains`` (``{name:
    Gains}``, :func:`worker_controllers`: an ``h2`` table runs its synthesised gain, an MPC
    falls back to the gain its ``fallback`` names), as ``lcc-synth run`` builds them.

    Returns ``{"start", "stop", "metrics": {controller: {metric: (stop - start,) array}},
    "fallbacks": {controller: int}, "sim_time": {controller: s}, "wall_time": s}``.
    """
    from lcc_synth.experiments.deeplcc_runs import run_scenario, scenario_runs

    t0 = time.perf_counter()
    ctrls = _controllers(tables, system, source, gains)
    runs = scenario_runs(scenario, ranges, start, stop, ctrls)  # deep_lcc: one by one
    draws = [sc.draw() for sc in runs]
    metrics, fallbacks, times = {}, {}, {}
    for name, ctrl in ctrls.items():
        t1 = time.perf_counter()
        per, fallbacks[name] = [], 0
        for sc, dr in zip(runs, draws, strict=True):
            res = run_scenario(sc, ctrl, dr)
            per.append(scenario_metrics(res, config))
            fallbacks[name] += int((res.controller_stats or {}).get("fallbacks", 0) or 0)
        times[name] = time.perf_counter() - t1
        metrics[name] = {k: np.concatenate([p[k] for p in per]) for k in per[0]}
    return {
        "start": start,
        "stop": stop,
        "metrics": metrics,
        "fallbacks": fallbacks,
        "sim_time": times,
        "wall_time": time.perf_counter() - t0,
    }


def _task(*args: Any) -> dict[str, Any]:
    """:func:`run_chunk` as a Dask task: a :class:`ConfigError` (bad input, the same on every
    try) comes back as a value, ``{"config_error": (field, message, source)}``, so that Dask
    does not retry it (its retries are for failures that may pass) and the client raises it."""
    try:
        return run_chunk(*args)
    except ConfigError as err:
        return {"config_error": (err.field, err.message, err.source)}


def _raise_config_error(out: Mapping[str, Any]) -> None:
    if "config_error" in out:
        field_name, message, source = out["config_error"]
        raise ConfigError(field_name, message, source)


# --------------------------------------------------------------------------------------------
# Aggregation
# --------------------------------------------------------------------------------------------


@dataclass
class SweepResult:
    """A finished sweep.

    Attributes
    ----------
    summary : dict
        :func:`aggregate` of the samples (the ``results`` of ``--json``).
    samples : dict
        ``{controller: {metric: (count,) array}}`` in scenario order.
    fallbacks : dict
        ``{controller: MPC fallback steps}``.
    tables : dict
        The plain controller tables (``h2`` as its synthesised static table, an MPC's
        fallback inlined): the results files' and a resumed sweep's.
    designs : dict
        ``{controller: SynthesisReport}`` of the synthesised controllers.
    info : dict
        Count, batch size, tasks, seed, scheduler, wall time, throughput.
    worker_tables : dict
        The tables the workers built the controllers from, with ``gains``
        (:func:`worker_controllers`).
    gains : dict
        ``{controller: Gains}``: the gain object an ``h2`` controller or an MPC's fallback was
        built with (the synthesis report's ``gain``, the same object in the client).
    """

    summary: dict[str, dict[str, Any]]
    samples: dict[str, dict[str, np.ndarray]]
    fallbacks: dict[str, int]
    tables: dict[str, dict[str, Any]]
    designs: dict[str, Any]
    info: dict[str, Any]
    worker_tables: dict[str, dict[str, Any]] = field(default_factory=dict)
    gains: dict[str, Gains] = field(default_factory=dict)


def worker_controllers(
    spec: SweepSpec, tables: Mapping[str, Mapping[str, Any]], synthesised: Mapping[str, Gains]
) -> tuple[dict[str, dict[str, Any]], dict[str, Gains]]:
    """What the workers build the controllers from: ``(tables, gains)``.

    A controller built with a gain object (an ``h2`` table, an MPC whose ``fallback = "NAME"``
    names an ``h2`` controller; :func:`lcc_synth.experiments.spec.controller_gain` picks it
    from ``synthesised``, ``{name: Gains}`` of the synthesis reports) keeps its table as the
    file gives it (how the law runs) and its gain in ``gains``, the object itself; every other
    controller keeps its plain table of ``tables`` (:func:`run_sweep`'s, a ``gains_file``
    already read).
    """
    from lcc_synth.experiments.spec import controller_gain
    from lcc_synth.experiments.suite_tables import controller_table

    out: dict[str, dict[str, Any]] = {}
    gains: dict[str, Gains] = {}
    for name, table in tables.items():
        given = controller_table(spec.controllers[name], "sweep")
        gain = controller_gain(name, given, synthesised)
        if gain is None:
            out[name] = dict(table)
        else:
            out[name], gains[name] = given, gain
    return out, gains


def _inline_gains_file(name: str, table: Mapping[str, Any], spec: SweepSpec) -> dict[str, Any]:
    """A ``gains_file`` controller as a ``static`` table holding the file's gains, read here in
    the client (:func:`lcc_synth.controllers.gains_files.read_gains_file`): workers of a remote
    cluster need not see the file."""
    if table.get("type") != "gains_file":
        return dict(table)
    from lcc_synth.controllers.gains_files import read_gains_file
    from lcc_synth.controllers.registry import STATIC_RUN_KEYS as passed

    field_name = f"controllers.{name}"
    declared("controllers.NAME:gains_file").check(table, field_name)
    gains, doc = read_gains_file(table, field_name, spec.system, spec.source)
    out = {"type": "static", "kind": doc["kind"], "semantics": gains.semantics,
           "gains": gains.as_table()}
    for key in passed:
        if key in table:
            out[key] = table[key]
    return out


def run_sweep(
    spec: SweepSpec,
    client: Any = None,
    progress: bool = True,
    retries: int = 3,
    done: SweepProgress | None = None,
    on_task: Callable[[SweepProgress], None] | None = None,
    connect: Callable[[], Any] | None = None,
) -> SweepResult:
    """Run the sweep: synthesise ``h2`` controllers here, then every task on ``client``.

    Parameters
    ----------
    spec : SweepSpec
    client : dask.distributed.Client, optional
        Where the tasks run; ``None`` runs them one after the other in this process (the same
        task function: useful to check a cluster's results).
    progress : bool
        Progress bars on stderr (synthesis, scenarios done).
    retries : int
        Retries of a failing task (a task lost with its worker is recomputed by Dask; a
        :class:`ConfigError` is not retried).
    done : SweepProgress, optional
        Filled as tasks finish (the caller keeps what finished when the sweep is interrupted
        or fails); one that holds finished tasks (an interrupted sweep) runs only the others.
    on_task : callable, optional
        ``on_task(done)`` after each finished task (in this thread).
    connect : callable, optional
        ``connect()`` returns the client, called once the controllers are synthesised and
        built (instead of ``client``): the CLI starts its local cluster meanwhile (the
        workers' start, 2-4 s, overlaps the synthesis, 1-4 s; the results are the same).

    Raises
    ------
    ConfigError
        A controller that cannot be built, a bad input met on a worker, ``done`` of other
        controller tables.
    KeyboardInterrupt
        (:class:`~lcc_synth.errors.Interrupted`) the tasks not finished are cancelled; ``done``
        holds the finished ones.
    """
    from lcc_synth.experiments.comparison import prepare_controllers
    from lcc_synth.resources import progress_bar

    t_all = time.perf_counter()
    with progress_bar(len(spec.controllers), "controllers (synthesis)", progress) as bar:

        def step(name: str) -> None:
            bar.set_postfix_str(name)
            bar.update(1)

        synthesised: dict[str, Gains] = {}
        tables, designs = prepare_controllers(
            spec.controllers, spec.system, "sweep", spec.source, spec.name,
            on_step=step, fallbacks=spec.fallbacks, gains=synthesised,
        )
    t_design = time.perf_counter() - t_all
    tables = {name: _inline_gains_file(name, t, spec) for name, t in tables.items()}
    ran_tables, gains = worker_controllers(spec, tables, synthesised)
    # fail early, in the client, on a controller that cannot be built (deep_lcc: its settings)
    from lcc_synth.experiments.deeplcc_runs import scenario_controllers as build_controllers
    from lcc_synth.simulation.backends import check_backend
    from lcc_synth.simulation.timestep import check_time_step
    built = build_controllers(ran_tables, spec.system, spec.source, gains)
    try:  # a step too coarse for a loop, SUMO missing: error / warning here, not on the workers
        check_backend(spec.scenario)
        check_time_step(spec.scenario, built)
    except ConfigError as err:
        raise err.with_source(spec.source) if spec.source else err from None

    if connect is not None:
        client = connect()
    done = SweepProgress.new(spec) if done is None else done
    done.check(spec)
    done.set_tables(tables)
    parts = chunks(spec.count, spec.batch_size)
    todo = [p for p in parts if p not in done.tasks]
    args = (spec.scenario, spec.system, ran_tables, spec.metrics, spec.source)
    names = list(tables)
    t0 = time.perf_counter()
    with progress_bar(spec.count, "scenarios", progress) as bar:
        bar.unit = "scenario"
        bar.update(done.done)

        def store(out: dict[str, Any]) -> None:
            _raise_config_error(out)
            done.store(out)
            bar.update(out["stop"] - out["start"])
            if on_task is not None:
                on_task(done)

        if client is None:
            for s, e in todo:
                store(run_chunk(*args, s, e, spec.ranges, gains))
        elif todo:
            token = _token(args, spec.ranges, gains)[:16]

            def submit(s: int, e: int):
                return client.submit(_task, *args, s, e, spec.ranges, gains, retries=retries,
                                     pure=False, key=f"lcc-sweep-{token}-{s}-{e}")  # fmt: skip

            run_tasks(client, todo, submit, store)
    wall = time.perf_counter() - t0
    samples = done.finished_samples()
    fallbacks = done.fallbacks()
    ran = sum(e - s for s, e in todo)  # scenarios run by this call
    info = {
        "count": spec.count,
        "batch_size": spec.batch_size,
        "tasks": len(parts),
        "seed": spec.seed,
        "controllers": names,
        "scheduler": None if client is None else str(client.scheduler.address),
        "synthesis_time_s": t_design,
        "wall_time_s": wall,
        "total_time_s": time.perf_counter() - t_all,
        "task_time_s_sum": float(sum(t["wall_time"] for t in done.tasks.values())),
        "simulation_time_s": done.sim_time(),
        "scenarios_per_s": ran / wall if wall > 0 and ran else None,
        "runs_per_s": ran * len(names) / wall if wall > 0 and ran else None,
    }
    if len(todo) < len(parts):  # resumed: the earlier runs' share
        info["resumed_tasks"] = len(parts) - len(todo)
        info["earlier_wall_time_s"] = done.wall_time_s
    return SweepResult(aggregate(samples, fallbacks), samples, fallbacks, tables, designs, info,
                       ran_tables, gains)  # fmt: skip


def format_summary(summary: Mapping[str, Mapping[str, Any]]) -> str:
    """Plain-text table: one row per controller, ``mean [p5, p95]`` per metric, then counts;
    safety before efficiency: the controllers with a collided run, then those with an unsafe
    one (``unsafe_scenarios``, :func:`~lcc_synth.metrics.unsafe_reasons`; marked
    ``(unsafe in k/N)``), then those whose solver failed come after the others."""
    fmt = {"aave": ".3f", "fuel_ml": ".1f", "min_spacing": ".2f", "min_ttc": ".2f",
           "max_abs_command": ".2f", "rms_jerk_cav": ".2f", "max_jerk_1s_cav": ".2f"}

    def cell(d: Mapping[str, Any], f: str) -> str:
        if d["mean"] is None:
            return "n/a"
        return f"{d['mean']:{f}} [{d['p5']:{f}}, {d['p95']:{f}}]"

    head = ["controller", *(SWEEP_METRICS[k] for k in SWEEP_METRICS), "collisions (scen.)",
            "AEB steps (scen.)", "unsafe (scen.)", "over ISO jerk (scen.)", "MPC fallbacks"]
    rows = []

    for name, e in sorted(summary.items(), key=lambda item: sweep_safety_rank(item[1])):
        steps = int(e.get("fallbacks") or 0)  # the solver failed (fell back) on these steps
        marks = [f"unsafe in {e['unsafe_scenarios']}/{e['scenarios']}"] if (
            e.get("unsafe_scenarios") and not e["collision_scenarios"]) else []  # fmt: skip
        marks += [f"QP failed on {steps} step{'s' if steps != 1 else ''}"] if steps else []
        label = f"{name} ({', '.join(marks)})" if marks else name
        rows.append(
            [label, *(cell(e[k], fmt.get(k, ".3g")) for k in SWEEP_METRICS),
             f"{e['collisions']} ({e['collision_scenarios']})",
             f"{e['aeb_activations']} ({e['aeb_scenarios']})",
             str(e.get("unsafe_scenarios", "n/a")), str(e["jerk_scenarios"]), str(e["fallbacks"])]
        )
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True))]
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)) for r in rows]
    lines.append(
        "AAVE and fuel: over the runs without a collision (a collided run has none); "
        "collided runs: "
        + ", ".join(f"{name} {e['collision_scenarios']}/{e['scenarios']}"
                    for name, e in summary.items())
    )
    return "\n".join(lines)
