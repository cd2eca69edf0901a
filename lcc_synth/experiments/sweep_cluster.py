"""The Dask side of a sweep: a local cluster that leaves signals to the client, a stop that
does not wait for running tasks, and a bounded window of tasks in flight.

* :func:`local_cluster`: single-threaded worker processes on 127.0.0.1, the scratch space of
  the workers and the scheduler in one temporary directory ``lcc-sweep-dask-*``; its workers
  ignore SIGINT and SIGTERM (:func:`dask_setup`, a Dask preload): the client handles them.
  Its processes run with :data:`LOCAL_CLUSTER_CONFIG`: no statistical profiler in the workers
  and fewer event-loop wake-ups, which take the GIL from the task that computes.
* :func:`stop_cluster`: closes the client and the cluster and removes the scratch space; for an
  interrupted sweep, at once (the workers are killed first).
* :func:`run_tasks`: the tasks of a sweep, a few per worker thread at a time.
* :func:`task_size`: scenarios per task from the count and the workers, so that every worker
  has work and the progress bar moves (``--count 10`` on 2 workers: 10 tasks of one scenario,
  where one task of 10 left a worker idle and the bar at 0/10 until the end).

Used by :func:`lcc_synth.experiments.sweep.run_sweep` and ``lcc-synth sweep``; also
importable from :mod:`lcc_synth.experiments.sweep`.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from lcc_synth.errors import ConfigError

__all__ = ["TASKS_PER_THREAD", "TASKS_PER_WORKER", "LOCAL_CLUSTER_CONFIG", "local_cluster",
           "dask_setup", "stop_cluster", "run_tasks", "task_size"]  # fmt: skip

#: How ``distributed.worker`` logs a heartbeat that did not reach the scheduler.
HEARTBEAT_FAILURE = "Failed to communicate with scheduler during heartbeat"

#: Tasks in flight per worker thread (the next one is submitted when one finishes).
TASKS_PER_THREAD = 2

#: Tasks per worker that :func:`task_size` aims at (smaller tasks balance the workers and move
#: the progress bar; a task costs a few ms of Dask overhead, a scenario of
#: ``problems/sweep_robustness.toml`` seconds).
TASKS_PER_WORKER = 8


#: Dask settings of :func:`local_cluster`'s scheduler, nannies and workers. Dask's defaults
#: sample every worker's stack every 10 ms (the dashboard's profile, which this cluster does not
#: serve), check the event loop's responsiveness every 20 ms and the worker's memory every
#: 100 ms: each wake-up takes the GIL from the task. Measured, 120 scenarios of
#: ``problems/sweep_robustness.toml`` on 2 workers (2026-12-04, two runs each): 43.6-44.8 s wall
#: and 65-67 s CPU of the workers with the defaults, 42.1-42.6 s / 63-64 s without the profiler,
#: 40.9-41.5 s / 62 s with the longer intervals too (-6 % wall). The memory monitor, which
#: pauses and restarts a worker over its limit, looks once a second instead of ten times.
LOCAL_CLUSTER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "500ms",
    "distributed.worker.memory.monitor-interval": "1s",
}


def task_size(count: int, workers: int, batch_size: int) -> int:
    """Scenarios per task of a sweep of ``count`` scenarios on ``workers`` worker threads:
    ``batch_size`` at most (the file's ``[sweep] batch_size``), and at most
    ``count // (workers * TASKS_PER_WORKER)`` so that each worker gets about
    :data:`TASKS_PER_WORKER` tasks, at least 1. A pure function of its arguments; a scenario's
    result does not depend on it (:mod:`lcc_synth.experiments.sweep`).

    Raises
    ------
    ConfigError
        ``count``, ``workers`` or ``batch_size`` not a positive integer.
    """
    for name, value in (("count", count), ("--workers", workers), ("batch_size", batch_size)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ConfigError(name, f"must be an integer >= 1, got {value!r}")
    return max(1, min(batch_size, count // (workers * TASKS_PER_WORKER)))


def local_cluster(n_workers: int = 2, local_directory: str | None = None):
    """A ``LocalCluster`` of ``n_workers`` single-threaded processes on 127.0.0.1, scratch
    space of the workers and of the scheduler in ``local_directory`` (by default a temporary
    directory ``lcc-sweep-dask-*``, removed with the cluster: :func:`stop_cluster`).

    The scheduler's HTTP endpoint (health, metrics; the dashboard if bokeh is installed)
    listens on a free port of 127.0.0.1 only, never on the fixed port 8787."""
    import shutil
    import tempfile
    import weakref

    import dask
    from dask.distributed import LocalCluster

    if isinstance(n_workers, bool) or not isinstance(n_workers, int) or not 1 <= n_workers <= 256:
        raise ConfigError("--workers", f"must be an integer in [1, 256], got {n_workers!r}")
    scratch = None
    if local_directory is None:
        scratch = local_directory = tempfile.mkdtemp(prefix="lcc-sweep-dask-")
    try:
        with dask.config.set(LOCAL_CLUSTER_CONFIG):  # the nannies keep it for a restarted worker
            cluster = LocalCluster(
                n_workers=n_workers,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address="127.0.0.1:0",
                local_directory=local_directory,
                # not $TMPDIR/dask-scratch-space
                scheduler_kwargs={"local_directory": local_directory},
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
    too (Dask's parent monitor).

    The worker also drops its log record of a failed heartbeat: when a sweep ends, Dask stops
    the scheduler before the workers, and a worker whose heartbeat fell in between logged it
    with a ``CommClosedError`` traceback on the user's terminal (seen once in a CI run). The
    worker handles that failure itself (it retries, and closes when the scheduler is gone);
    a failed task still reaches the client as its exception."""
    import logging
    import signal

    logging.getLogger("distributed.worker").addFilter(_not_a_heartbeat_failure)
    if threading.current_thread() is threading.main_thread():
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, signal.SIG_IGN)


def _not_a_heartbeat_failure(record: Any) -> bool:
    """A logging filter: False for a worker's record of a heartbeat that did not reach the
    scheduler (an ``OSError``, which the worker handles itself); every other record passes."""
    return not str(record.msg).startswith(HEARTBEAT_FAILURE)


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


def run_tasks(client: Any, todo: Sequence[tuple[int, int]], submit: Callable[[int, int], Any],
              store: Callable[[Any], None]) -> None:  # fmt: skip
    """Run the tasks ``todo`` (``(start, stop)`` ranges) on ``client``: ``submit(start, stop)``
    submits one and returns its future; at most :data:`TASKS_PER_THREAD` per worker thread
    are in flight (at least 4; the cluster's threads are counted again every 5 s: workers may
    join), the next one submitted when one finishes; ``store(result)`` for each result as it
    arrives. The tasks still in flight are cancelled when this ends early (an error, an
    interruption)."""
    from itertools import islice

    from dask.distributed import as_completed

    queue = iter(todo)

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
