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
Scenarios are cut into tasks of ``batch_size`` consecutive indices; a task simulates its
scenarios as ONE batch per controller (the simulator's batch axis; all controllers on the same
draws) and returns the per-scenario metrics. Tasks run on a Dask cluster (a ``LocalCluster`` of
processes by default, or any scheduler address) with retries; Dask recomputes the tasks of a
worker that dies. A task whose input is bad (a :class:`~lcc_synth.errors.ConfigError` raised on
the worker) is not retried: the error comes back to the client as it is. ``h2`` controllers are
synthesised once, in the client, and ``gains_file`` controllers are read there; workers
receive plain controller tables and build (and cache, per process and thread) the controllers
themselves (an MPC's ``fallback_gains_file`` is read on the worker: give it a path the
workers can read). At most a few tasks per worker thread are submitted at a time (the next one
when one finishes): the client and the scheduler hold a bounded number of tasks whatever the
count, and an interrupted sweep has little to cancel.

Finished work is kept
---------------------
What a sweep has finished is a :class:`SweepProgress`: the samples of the finished tasks and
their counts. :func:`run_sweep` fills the one it is given (``done=``), calls ``on_task``
after each task (``lcc-synth sweep`` writes the partial results files from it,
:mod:`lcc_synth.experiments.sweep_files`) and, given one that already holds finished tasks
(an interrupted sweep read back), runs only the others: the samples, the summary and every
count equal those of an uninterrupted sweep bit for bit (a task's result depends on its
scenario indices only).

The problem file's tables (``[sweep]`` ``count`` and ``batch_size``, the ``[lo, hi]`` ranges)
are in ``problems/REFERENCE.md``.
"""

from __future__ import annotations

import hashlib
import json
import pickle
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.metrics import WAVE_METRICS, MetricsConfig
from lcc_synth.models.records import Record, system_tables
from lcc_synth.problem import Problem, System, check_top_level, load_problem, system_from
from lcc_synth.schema import declared
from lcc_synth.simulation.scenario import Scenario, split_ranges
from lcc_synth.simulation.scenario_file import scenario_from

__all__ = [
    "SWEEP_METRICS", "SWEEP_SAMPLES", "SWEEP_COUNTS", "MAX_COUNT", "TASKS_PER_THREAD",
    "SweepSpec", "SweepResult", "SweepProgress", "load_sweep", "chunks", "scenario_metrics",
    "run_chunk", "aggregate", "run_sweep", "local_cluster", "stop_cluster", "table_digest",
    "format_summary",
]  # fmt: skip

#: Per-scenario metrics of a sweep -> label (distributions: mean, p5, p95).
SWEEP_METRICS: dict[str, str] = {
    "aave": "AAVE (m/s)",
    "fuel_ml": "fuel (mL)",
    "min_spacing": "min spacing (m)",
    "min_ttc": "min TTC (s)",
    "max_abs_command": "max |u| (m/s²)",
    "rms_jerk_cav": "CAV RMS jerk (m/s³)",
    "max_jerk_1s_cav": "CAV max 1 s jerk (m/s³)", **WAVE_METRICS,
}
#: Every per-scenario sample of a sweep -> label (``samples.csv``'s columns, the recording).
SWEEP_SAMPLES: dict[str, str] = {
    **SWEEP_METRICS, "jerk_1s_over_limit_s": "time over ISO jerk limit (s)",
    "collisions": "collisions", "aeb_activations": "AEB steps",
}
#: Per-scenario counts of a sweep (summed over the scenarios).
SWEEP_COUNTS = ("collisions", "aeb_activations", "fallbacks")
#: Metrics whose distributions leave out the runs with a collision (no efficiency to average).
_EFFICIENCY = ("aave", "fuel_ml")
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
    hdv_table: dict[str, Any] = field(default_factory=dict)
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
) -> SweepSpec:  # fmt: skip
    """Read a sweep problem file; ``count``, ``batch_size``, ``seed`` override the file.

    Raises
    ------
    ConfigError
        A bad table or value, an unknown controller name, counts out of range.
    """
    from lcc_synth.experiments.comparison import fallback_names, select_names
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
        return SweepSpec(
            name=problem.name,
            system=system,
            scenario=scenario,
            metrics=metrics,
            controllers={k: ctrls[k] for k in names},
            fallbacks={k: ctrls[k] for k in extra},
            count=n,
            batch_size=min(bs, n),
            hdv_table=dict(declared("").get(data, "hdv", "")),
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
    import lcc_synth.metrics as mt

    return {
        "aave": mt.aave(result, config.window, config.vehicles)[0],
        "fuel_ml": mt.fuel(result, config.window, config.vehicles)[0],
        "min_spacing": np.nanmin(mt.min_spacing(result)[0, 1:]),
        "min_ttc": np.nanmin(mt.min_time_to_collision(result)[0, 1:]),
        "max_abs_command": mt.max_abs_command(result)[0],
        "rms_jerk_cav": mt.rms_jerk(result)[0],
        "max_jerk_1s_cav": mt.max_jerk_1s(result)[0],
        "jerk_1s_over_limit_s": mt.jerk_limit_violation_time(result)[0],
        "collisions": mt.collisions(result)[0],
        "aeb_activations": mt.aeb_activations(result)[0],
        **{k: x[0] for k, x in mt.wave_metrics(result, config).items()},  # the ring benchmark's
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


def _controllers(tables: Mapping[str, Mapping[str, Any]], system: System, source: str | None):
    """Controllers of ``tables``, built once per process and thread (MPCs hold solver state)."""
    from lcc_synth.experiments.deeplcc_runs import scenario_controllers as build_controllers

    key = (_token(dict(tables), system, source), threading.get_ident())
    with _CACHE_LOCK:
        ctrls = _CACHE.get(key)
    if ctrls is None:
        ctrls = build_controllers(tables, system, source)
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
) -> dict[str, Any]:
    """Simulate scenarios ``start .. stop - 1`` with every controller (one batch each; with
    ``ranges``, :attr:`SweepSpec.ranges`, each scenario alone with its drawn settings; a
    ``deep_lcc`` controller on each scenario's own data, :mod:`.deeplcc_runs`).

    Returns ``{"start", "stop", "metrics": {controller: {metric: (stop - start,) array}},
    "fallbacks": {controller: int}, "sim_time": {controller: s}, "wall_time": s}``.
    """
    from lcc_synth.experiments.deeplcc_runs import run_scenario, scenario_runs

    t0 = time.perf_counter()
    ctrls = _controllers(tables, system, source)
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
    does not retry it (its retries are for failures that may pass) and the client raises it
    (a ``ConfigError`` does not survive pickling as an exception: its arguments differ from
    its message)."""
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


def _dist(x: np.ndarray) -> dict[str, Any]:
    x = np.asarray(x, dtype=float)
    ok = x[np.isfinite(x)]
    if ok.size == 0:
        return {"mean": None, "p5": None, "p95": None, "n": 0}
    return {
        "mean": float(ok.mean()),
        "p5": float(np.percentile(ok, 5)),
        "p95": float(np.percentile(ok, 95)),
        "n": int(ok.size),
    }


def aggregate(
    samples: Mapping[str, Mapping[str, np.ndarray]], fallbacks: Mapping[str, int]
) -> dict[str, dict[str, Any]]:
    """Per controller: ``{metric: {mean, p5, p95, n}}`` over the finite per-scenario values
    (``n`` of them: a vehicle that never closes in has an infinite time to collision), AAVE
    and fuel over the scenarios WITHOUT a collision only (``collided_excluded`` of them left
    out, whatever their values), and the counts ``collisions`` (collided vehicles),
    ``collision_scenarios`` (collided runs), ``aeb_activations`` (steps), ``aeb_scenarios``,
    ``jerk_scenarios`` (scenarios whose CAV's 1 s average jerk exceeds ISO 15622's limit
    outside emergency braking), ``fallbacks`` (MPC fallback steps) and ``scenarios``."""
    out = {}
    for name, per in samples.items():
        coll = np.asarray(per["collisions"])
        entry: dict[str, Any] = {}
        for k in SWEEP_METRICS:
            if k in _EFFICIENCY:
                entry[k] = _dist(np.where(coll > 0, np.nan, np.asarray(per[k], dtype=float)))
                entry[k]["collided_excluded"] = int(np.count_nonzero(coll))
            else:
                entry[k] = _dist(per[k])
        aeb = np.asarray(per["aeb_activations"])
        entry["collisions"] = int(coll.sum())
        entry["collision_scenarios"] = int(np.count_nonzero(coll))
        entry["aeb_activations"] = int(aeb.sum())
        entry["aeb_scenarios"] = int(np.count_nonzero(aeb))
        entry["jerk_scenarios"] = int(np.count_nonzero(np.asarray(per["jerk_1s_over_limit_s"]) > 0))
        entry["fallbacks"] = int(fallbacks.get(name, 0))
        entry["scenarios"] = int(coll.size)
        out[name] = entry
    return out


def table_digest(table: Mapping[str, Any]) -> str:
    """SHA-256 of a controller table as the workers receive it (keys sorted, floats exact),
    to check that a resumed sweep runs the same controllers (e.g. the same synthesised
    ``h2`` gains) as the interrupted one."""
    from lcc_synth.experiments.tables import json_safe

    text = json.dumps(json_safe(dict(table)), sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()


_INT_SAMPLES = ("collisions", "aeb_activations")


@dataclass
class SweepProgress:
    """The finished part of a sweep: what an interrupted sweep keeps and a resumed one starts
    from.

    Attributes
    ----------
    count, batch_size : int
        The sweep's scenarios and scenarios per task.
    names : list of str
        The controllers, in order.
    samples : dict
        ``{controller: {sample: (count,) float array}}``, NaN for the scenarios not finished.
    tasks : dict
        ``{(start, stop): {"fallbacks": {controller: int}, "sim_time": {controller: s},
        "wall_time": s}}`` of the finished tasks, in the order they finished.
    digests : dict
        ``{controller: table_digest}`` of the tables the finished tasks ran (empty until
        :func:`run_sweep` has prepared them).
    tables : dict
        The controller tables (set by :func:`run_sweep`; empty before).
    wall_time_s : float
        Wall time of the earlier runs of this sweep (an interrupted one), seconds.
    """

    count: int
    batch_size: int
    names: list[str]
    samples: dict[str, dict[str, np.ndarray]]
    tasks: dict[tuple[int, int], dict[str, Any]] = field(default_factory=dict)
    digests: dict[str, str] = field(default_factory=dict)
    tables: dict[str, dict[str, Any]] = field(default_factory=dict)
    wall_time_s: float = 0.0

    @classmethod
    def new(cls, spec: SweepSpec) -> SweepProgress:
        """Nothing finished yet."""
        names = list(spec.controllers)
        samples = {c: {k: np.full(spec.count, np.nan) for k in SWEEP_SAMPLES} for c in names}
        return cls(spec.count, spec.batch_size, names, samples)

    def check(self, spec: SweepSpec) -> None:
        """Raise ``ValueError`` unless this is progress of a sweep of ``spec``'s shape."""
        got = (self.count, self.batch_size, self.names)
        want = (spec.count, spec.batch_size, list(spec.controllers))
        if got != want:
            raise ValueError(f"progress of a sweep {got}, not of this one {want}")

    def set_tables(self, tables: Mapping[str, Mapping[str, Any]]) -> None:
        """Record the digests of the controller tables; with finished tasks, check that
        ``tables`` are those the finished tasks ran.

        Raises
        ------
        ConfigError
            For ``--resume``: the controllers (e.g. a synthesised ``h2`` gain) differ.
        """
        now = {c: table_digest(tables[c]) for c in self.names}
        if self.tasks and self.digests:
            differ = [c for c in self.names if self.digests.get(c) != now[c]]
            if differ:
                raise ConfigError(
                    "--resume",
                    f"the controller tables of {', '.join(differ)} differ from those of the "
                    "interrupted sweep (e.g. a synthesised gain): its samples cannot be "
                    "continued with these",
                )
        self.digests = now
        self.tables = {c: dict(tables[c]) for c in self.names}

    def store(self, out: Mapping[str, Any]) -> None:
        """Keep a finished task's result (:func:`run_chunk`); the task counts as finished
        only once everything of it is stored."""
        s, e = int(out["start"]), int(out["stop"])
        for c in self.names:
            for k, v in out["metrics"][c].items():
                self.samples[c][k][s:e] = v
        self.tasks[(s, e)] = {
            "fallbacks": {c: int(out["fallbacks"][c]) for c in self.names},
            "sim_time": {c: float(out["sim_time"][c]) for c in self.names},
            "wall_time": float(out["wall_time"]),
        }

    @property
    def done(self) -> int:
        """Scenarios finished."""
        return sum(e - s for s, e in self.tasks)

    @property
    def finished(self) -> bool:
        """Every scenario finished."""
        return self.done == self.count

    def indices(self) -> np.ndarray:
        """The finished scenarios' indices, ascending."""
        if not self.tasks:
            return np.zeros(0, dtype=np.int64)
        return np.concatenate([np.arange(s, e) for s, e in sorted(self.tasks)])

    def fallbacks(self) -> dict[str, int]:
        """MPC fallback steps per controller over the finished tasks."""
        return {c: sum(t["fallbacks"][c] for t in self.tasks.values()) for c in self.names}

    def sim_time(self) -> dict[str, float]:
        """Simulation seconds per controller over the finished tasks."""
        return {c: float(sum(t["sim_time"][c] for t in self.tasks.values()))
                for c in self.names}  # fmt: skip

    def finished_samples(self) -> dict[str, dict[str, np.ndarray]]:
        """The samples of the finished scenarios only (in scenario order; the counts as
        integers): every scenario's when :attr:`finished`."""
        idx = None if self.finished else self.indices()
        out = {}
        for c, per in self.samples.items():
            out[c] = {}
            for k, v in per.items():
                v = v if idx is None else v[idx]
                out[c][k] = v.astype(np.int64) if k in _INT_SAMPLES else v
        return out


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
        Controller tables sent to the workers (``h2`` resolved to its gains).
    designs : dict
        ``{controller: SynthesisReport}`` of the synthesised controllers.
    info : dict
        Count, batch size, tasks, seed, scheduler, wall time, throughput.
    """

    summary: dict[str, dict[str, Any]]
    samples: dict[str, dict[str, np.ndarray]]
    fallbacks: dict[str, int]
    tables: dict[str, dict[str, Any]]
    designs: dict[str, Any]
    info: dict[str, Any]


def local_cluster(n_workers: int = 2, local_directory: str | None = None):
    """A ``LocalCluster`` of ``n_workers`` single-threaded processes on 127.0.0.1, scratch
    space of the workers and of the scheduler in ``local_directory`` (by default a temporary
    directory ``lcc-sweep-dask-*``, removed with the cluster: :func:`stop_cluster`).

    The scheduler's HTTP endpoint (health, metrics; the dashboard if bokeh is installed)
    listens on a free port of 127.0.0.1 only, never on the fixed port 8787."""
    import shutil
    import tempfile
    import weakref

    from dask.distributed import LocalCluster

    n_workers = _count(n_workers, "--workers", 256)
    scratch = None
    if local_directory is None:
        scratch = local_directory = tempfile.mkdtemp(prefix="lcc-sweep-dask-")
    try:
        cluster = LocalCluster(
            n_workers=n_workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
            local_directory=local_directory,
            scheduler_kwargs={"local_directory": local_directory},  # not $TMPDIR/dask-scratch-space
            silence_logs=40,
            preload=[__name__],  # dask_setup: the workers leave SIGINT / SIGTERM to the client
        )
    except BaseException:
        if scratch is not None:
            shutil.rmtree(scratch, True)
        raise
    # removed with the cluster object, or by stop_cluster (at once: an interrupted run leaves
    # the interpreter with os._exit, which runs no finalizer)
    cluster.lcc_scratch = (weakref.finalize(cluster, shutil.rmtree, scratch, True)
                           if scratch is not None else None)  # fmt: skip
    return cluster


def dask_setup(worker: Any) -> None:
    """Run by each worker of :func:`local_cluster` when it starts (a Dask preload): the worker
    ignores SIGINT and SIGTERM. A Ctrl-C in a terminal reaches the whole process group; the
    client stops the sweep, keeps what finished and stops the workers itself
    (:func:`stop_cluster`); a worker that died of the same Ctrl-C would print a
    ``KeyboardInterrupt`` traceback (and its nanny an error). A worker whose client dies ends
    too (Dask's parent monitor)."""
    import signal

    if threading.current_thread() is threading.main_thread():
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, signal.SIG_IGN)


def stop_cluster(cluster: Any, client: Any = None, now: bool = False) -> None:
    """Close ``client`` and the :func:`local_cluster` ``cluster`` and remove its scratch space.

    With ``now`` (an interrupted or failed sweep), first mark the nannies as closing (they do
    not restart their workers) and kill the worker processes: a worker inside a task holds a
    graceful close for seconds (measured: 4 s with a task that does not return); killed, the
    whole stop of an interrupted ``lcc-synth sweep`` took 0.13-0.45 s here. ``cluster`` may be
    ``None`` (an external scheduler: only the client is closed, the caller cancels its
    tasks). Never raises for a cluster that is already gone."""
    import gc
    import logging
    import os
    import signal

    if now and cluster is not None:
        # the scheduler logs each killed worker's broken connection (with a traceback): the
        # stop is deliberate, nothing of it is news
        names = [n for n in logging.root.manager.loggerDict if n.split(".")[0] == "distributed"]
        for name in ["distributed", *names]:
            logging.getLogger(name).setLevel(logging.CRITICAL)
        for nanny in list(getattr(cluster, "workers", {}).values()):
            try:
                nanny.close_gracefully(reason="lcc-sweep-stopped")  # no restart of its worker
                pid = nanny.pid
            except Exception:  # noqa: BLE001 - not a nanny (a worker of a thread cluster)
                continue
            if pid:
                try:
                    os.kill(pid, signal.SIGKILL)
                except OSError:
                    pass
    quick = {"timeout": 5} if now else {}
    try:
        if client is not None:
            client.close(**quick)
    except Exception:  # noqa: BLE001 - the scheduler is gone already
        pass
    try:
        if cluster is not None:
            cluster.close(**quick)
    except Exception:  # noqa: BLE001 - the cluster is closed below regardless
        pass
    finally:
        scratch = getattr(cluster, "lcc_scratch", None)
        if scratch is not None:
            scratch()
        gc.collect()  # multiprocessing's semaphores of the worker queues: released now


def _inline_gains_file(name: str, table: Mapping[str, Any], spec: SweepSpec) -> dict[str, Any]:
    """A ``gains_file`` controller as a ``static`` table holding the file's gains, read here in
    the client: workers of a remote cluster need not see the file."""
    if table.get("type") != "gains_file":
        return dict(table)
    from lcc_synth.controllers.registry import STATIC_RUN_KEYS as passed
    from lcc_synth.synthesis.gains_file import read_gains

    field_name = f"controllers.{name}"
    gf = declared("controllers.NAME:gains_file")
    gf.check(table, field_name)
    path = Path(gf.get(table, "file", field_name))
    if not path.is_absolute() and spec.source:
        path = Path(spec.source).parent / path
    try:
        gains, doc = read_gains(path)
    except ConfigError as err:
        raise ConfigError(f"{field_name}.file ({err.field})", err.message, spec.source) from None
    if (doc["m"], doc["n"]) != (spec.system.m, spec.system.n):
        raise ConfigError(
            f"{field_name}.file",
            f"{path} holds gains for m={doc['m']}, n={doc['n']}; the problem has "
            f"m={spec.system.m}, n={spec.system.n}",
            spec.source,
        )
    out = {"type": "static", "kind": doc["kind"], "semantics": gains.semantics,
           "gains": dict(gains.gains)}
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

    Raises
    ------
    ConfigError
        A controller that cannot be built, a bad input met on a worker, ``done`` of other
        controller tables.
    KeyboardInterrupt
        (:class:`~lcc_synth.errors.Interrupted`) the tasks not finished are cancelled; ``done``
        holds the finished ones.
    """
    from lcc_synth.experiments.comparison import prepare_controllers, progress_bar

    t_all = time.perf_counter()
    with progress_bar(len(spec.controllers), "controllers (synthesis)", progress) as bar:

        def step(name: str) -> None:
            bar.set_postfix_str(name)
            bar.update(1)

        tables, designs = prepare_controllers(
            spec.controllers, spec.system, "sweep", spec.hdv_table, spec.source, spec.name,
            on_step=step, fallbacks=spec.fallbacks,
        )
    t_design = time.perf_counter() - t_all
    tables = {name: _inline_gains_file(name, t, spec) for name, t in tables.items()}
    # fail early, in the client, on a controller that cannot be built (deep_lcc: its settings)
    from lcc_synth.experiments.deeplcc_runs import scenario_controllers as build_controllers
    from lcc_synth.simulation.backends import check_backend
    from lcc_synth.simulation.timestep import check_time_step
    built = build_controllers(tables, spec.system, spec.source)
    try:  # a step too coarse for a loop, SUMO missing: error / warning here, not on the workers
        check_backend(spec.scenario)
        check_time_step(spec.scenario, built)
    except ConfigError as err:
        raise err.with_source(spec.source) if spec.source else err from None

    done = SweepProgress.new(spec) if done is None else done
    done.check(spec)
    done.set_tables(tables)
    parts = chunks(spec.count, spec.batch_size)
    todo = [p for p in parts if p not in done.tasks]
    args = (spec.scenario, spec.system, tables, spec.metrics, spec.source)
    names = list(tables)
    t0 = time.perf_counter()
    with progress_bar(spec.count, "scenarios", progress) as bar:
        bar.unit = "scenario"
        bar.update(done.done)

        def store(out: dict[str, Any]) -> None:
            done.store(out)
            bar.update(out["stop"] - out["start"])
            if on_task is not None:
                on_task(done)

        if client is None:
            for s, e in todo:
                store(run_chunk(*args, s, e, spec.ranges))
        elif todo:
            _run_on(client, todo, args, spec.ranges, retries, store)
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
    return SweepResult(aggregate(samples, fallbacks), samples, fallbacks, tables, designs, info)


#: Tasks in flight per worker thread (the next one is submitted when one finishes).
TASKS_PER_THREAD = 2


def _run_on(client: Any, todo, args, ranges, retries: int, store) -> None:
    """Run the tasks ``todo`` on ``client``, at most :data:`TASKS_PER_THREAD` per worker
    thread in flight (at least 4), ``store(result)`` for each as it finishes; the tasks still
    in flight are cancelled when this ends early (an error, an interruption)."""
    from itertools import islice

    from dask.distributed import as_completed

    token = _token(args, ranges)[:16]
    queue = iter(todo)

    def submit(s: int, e: int):
        return client.submit(_task, *args, s, e, ranges, retries=retries, pure=False,
                             key=f"lcc-sweep-{token}-{s}-{e}")  # fmt: skip

    def window() -> int:
        try:
            threads = sum(client.nthreads().values())
        except Exception:  # noqa: BLE001 - the scheduler is busy: keep the window
            threads = 2
        return max(4, TASKS_PER_THREAD * threads)

    pending = {submit(s, e) for s, e in islice(queue, window())}
    flow = as_completed(list(pending))
    size, checked = len(pending), time.monotonic()
    try:
        for fut in flow:
            pending.discard(fut)
            out = fut.result()
            _raise_config_error(out)
            if time.monotonic() - checked > 5.0:  # workers may join (an external cluster)
                size, checked = window(), time.monotonic()
            for s, e in islice(queue, max(1, size - len(pending))):
                nxt = submit(s, e)
                pending.add(nxt)
                flow.add(nxt)
            store(out)
    finally:
        if pending:  # stopped early: nothing more to compute
            try:
                client.cancel(list(pending))
            except Exception:  # noqa: BLE001 - the scheduler is gone
                pass


def format_summary(summary: Mapping[str, Mapping[str, Any]]) -> str:
    """Plain-text table: one row per controller, ``mean [p5, p95]`` per metric, then counts."""
    fmt = {"aave": ".3f", "fuel_ml": ".1f", "min_spacing": ".2f", "min_ttc": ".2f",
           "max_abs_command": ".2f", "rms_jerk_cav": ".2f", "max_jerk_1s_cav": ".2f"}

    def cell(d: Mapping[str, Any], f: str) -> str:
        if d["mean"] is None:
            return "n/a"
        return f"{d['mean']:{f}} [{d['p5']:{f}}, {d['p95']:{f}}]"

    head = ["controller", *(SWEEP_METRICS[k] for k in SWEEP_METRICS), "collisions (scen.)",
            "AEB steps (scen.)", "over ISO jerk (scen.)", "MPC fallbacks"]
    rows = []
    for name, e in summary.items():
        rows.append(
            [name, *(cell(e[k], fmt.get(k, ".3g")) for k in SWEEP_METRICS),
             f"{e['collisions']} ({e['collision_scenarios']})",
             f"{e['aeb_activations']} ({e['aeb_scenarios']})", str(e["jerk_scenarios"]),
             str(e["fallbacks"])]
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
