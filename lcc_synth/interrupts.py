"""Stopping cleanly on SIGINT and SIGTERM, also in the middle of a long native solve.

* :func:`handling` (the ``lcc-synth`` entry point) turns SIGINT (Ctrl-C) and SIGTERM (what a
  batch scheduler sends) into :class:`~lcc_synth.errors.Interrupted` in the main thread, so
  that every ``finally`` block and context manager runs: the recording is finalised with the
  status "interrupted", a sweep writes the scenarios it finished, Dask workers and scratch
  directories are removed, empty results directories too. A second signal during that
  clean-up exits at once (``128 + signum``), and so does a watchdog thread if the clean-up
  takes more than :data:`CLEANUP_DEADLINE` seconds.
* :func:`call_in_child` runs a function in a forked child process and returns its result.
  Python runs signal handlers only between bytecodes of the main thread, so a native call that
  holds the interpreter lock cannot be interrupted in-process: measured here, cvxpy + Clarabel
  held it for up to 1.6 s at once on a 60-state LMI, and for tens of seconds in total on the
  202- and 402-state designs. The parent waits for the child in :data:`POLL_S` slices, so a
  signal is handled within that time; the child is killed and reaped. The result comes back
  pickled (numpy arrays bit for bit).

  It forks only while :func:`handling` is active (the ``lcc-synth`` command), where no solver
  ever runs in the parent. Elsewhere (the Python API, the tests) the call runs in-process, as a
  fork is not safe there: Clarabel's linear algebra (faer) runs on a rayon thread pool, and a
  child forked after a solve in the parent inherits the pool's state without its threads and
  waits for them forever (seen here: the first in-process solve, then a forked one, hung).
* :func:`checkpoint`, called by the long loops (every control step of the simulator, every
  controller built and every run of a suite, every as-run analysis), raises the signal's
  exception again if it was lost. Python runs a handler between any two bytecodes, also in
  Python code that a C extension calls back, and some extensions clear whatever that raises:
  CasADi's SWIG wrappers read ``.shape`` while resolving an overload and drop the error, so a
  signal during the MPC's symbolic set-up (a few hundred ms per controller) was swallowed and
  ``run`` went on working until the watchdog's deadline (seen here: at least 6 of 59 SIGTERMs
  2.5 to 6 s into ``run``; CI's ``test_run[SIGTERM]`` failed on one; none of 60 since).
"""

from __future__ import annotations

import os
import pickle
import select
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from lcc_synth.errors import Interrupted

__all__ = ["CLEANUP_DEADLINE", "POLL_S", "handling", "held_signals", "interrupted", "deliver",
           "interruption_behind", "checkpoint", "call_in_child"]

#: Seconds the clean-up after a signal may take before the process exits regardless.
CLEANUP_DEADLINE = 20.0
#: Seconds between two checks for a signal while waiting for a child process.
POLL_S = 0.05

_STATE: dict[str, Any] = {"signum": None, "in_child": False, "active": False}


def interrupted() -> int | None:
    """The signal that stopped this run (``None`` if none arrived)."""
    return _STATE["signum"]


def _in_chain(err: BaseException | None) -> Interrupted | None:
    """The :class:`~lcc_synth.errors.Interrupted` on ``err``'s ``__cause__`` /
    ``__context__`` chain (``err`` included), else ``None``."""
    seen: set[int] = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, Interrupted):
            return err
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return None


def interruption_behind(err: BaseException) -> Interrupted | None:
    """The :class:`~lcc_synth.errors.Interrupted` that ``err`` stands for, else ``None``.

    A signal's exception can surface wrapped: when the handler raises while native code is
    about to return (a numba kernel's dispatcher), Python reports ``SystemError: ... returned
    a result with an exception set`` caused by it (seen in CI on ``run``, 1 run in ~20). This
    looks for it along ``__cause__`` / ``__context__``, and under :func:`handling`, once a
    signal has arrived, any error counts as its consequence."""
    found = _in_chain(err)
    if found is not None:
        return found
    if _STATE["active"] and _STATE["signum"] is not None:
        return Interrupted(_STATE["signum"])
    return None


def checkpoint() -> None:
    """Raise :class:`~lcc_synth.errors.Interrupted` again if a signal arrived under
    :func:`handling` and its exception was lost on the way (see the module docstring); a no-op
    otherwise, also in the clean-up that the signal's exception is unwinding through (an
    ``except`` or ``finally`` block handling it). Costs one dictionary look-up when no signal
    arrived: call it once per unit of long work (a control step, a simulation, a controller)."""
    signum = _STATE["signum"]
    if signum is None or not _STATE["active"]:
        return
    if _in_chain(sys.exc_info()[1]) is not None:  # being unwound: the clean-up is running
        return
    raise Interrupted(signum)


def _watchdog(signum: int) -> None:
    time.sleep(CLEANUP_DEADLINE)
    try:
        print(f"lcc-synth: the clean-up after {signal.Signals(signum).name} took more than "
              f"{CLEANUP_DEADLINE:g} s; exiting", file=sys.stderr, flush=True)  # fmt: skip
    finally:
        os._exit(128 + signum)


def deliver(signum: int) -> None:
    """Raise :class:`~lcc_synth.errors.Interrupted` for ``signum`` as the handler does: for a
    signal that native code caught itself (OSQP's own SIGINT handler during a solve, read back
    by :mod:`lcc_synth.mpc.solver`). Under :func:`handling` a second signal exits at once and
    the clean-up gets :data:`CLEANUP_DEADLINE` seconds."""
    if _STATE["active"]:
        if _STATE["signum"] is not None:  # a second signal: the user insists
            os._exit(128 + signum)
        _STATE["signum"] = signum
        threading.Thread(target=_watchdog, args=(signum,), daemon=True,
                         name="lcc-deadline").start()  # fmt: skip
    raise Interrupted(signum)


def _handler(signum: int, frame: Any) -> None:
    deliver(signum)


@contextmanager
def handling() -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`~lcc_synth.errors.Interrupted` in the main thread
    while the block runs (the previous handlers come back after it). Only from the main
    thread; elsewhere a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    _STATE["signum"] = None
    _STATE["active"] = True
    for s in old:
        signal.signal(s, _handler)
    try:
        yield
    finally:
        _STATE["active"] = False
        for s, h in old.items():
            signal.signal(s, h)


@contextmanager
def held_signals() -> Iterator[None]:
    """A SIGINT or SIGTERM that arrives while the block runs is held until it ends; then the
    handler that was installed runs (under :func:`handling`: it raises
    :class:`~lcc_synth.errors.Interrupted`); a second one exits at once, as after the first.

    For a block that cannot be stopped half-way: the start of a Dask cluster (1-3 s), whose
    object could not be closed at all if the signal arrived before it reached the caller. (The
    handler must be Python's: blocking the signals in this thread would not hold them, the
    native threads of the numerical libraries would take them.) A no-op outside the main
    thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list[int] = []

    def hold(signum: int, frame: Any) -> None:
        if got:
            os._exit(128 + signum)
        got.append(signum)

    old = {s: signal.signal(s, hold) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        if got and callable(old[got[0]]):
            old[got[0]](got[0], None)
        elif got and old[got[0]] == signal.SIG_DFL:
            os.kill(os.getpid(), got[0])


def _child(fn: Callable[..., Any], args: tuple, kwargs: dict, fd: int) -> None:
    """In the forked child: run, send ``(ok, value)`` pickled, exit without clean-up."""
    code = 0
    _STATE["in_child"] = True  # a nested call_in_child runs in this process
    try:
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, signal.SIG_DFL)
        try:
            payload = (True, fn(*args, **kwargs))
        except BaseException as err:  # noqa: BLE001 - every failure goes back to the parent
            payload = (False, err)
        try:
            data = pickle.dumps(payload, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as err:  # noqa: BLE001 - an unpicklable result or exception
            data = pickle.dumps((False, RuntimeError(f"{type(err).__name__}: {err}")))
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
    except BaseException:  # noqa: BLE001
        code = 1
    finally:
        os._exit(code)


def call_in_child(fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``fn(*args, **kwargs)`` computed in a forked child process, so that a signal stops it
    at once (see the module docstring). Its exceptions are raised here; its result must be
    picklable. Runs in-process outside :func:`handling` (see the module docstring), where
    ``os.fork`` does not exist, in a thread other than the main one (only the main thread
    handles signals), or inside such a child already."""
    if (not _STATE["active"] or not hasattr(os, "fork") or _STATE["in_child"]
            or threading.current_thread() is not threading.main_thread()):  # fmt: skip
        return fn(*args, **kwargs)
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child (coverage does not follow it)
        os.close(r)
        _child(fn, args, kwargs, w)
    os.close(w)
    chunks: list[bytes] = []
    done = False
    try:
        while True:
            ready, _, _ = select.select([r], [], [], POLL_S)
            if ready:
                data = os.read(r, 1 << 20)
                if not data:
                    break
                chunks.append(data)
        _, status = os.waitpid(pid, 0)
        done = True
    finally:
        os.close(r)
        if not done:  # interrupted (or failed) while the child runs: stop it
            try:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
            except OSError:
                pass
    if not chunks:
        raise RuntimeError(f"the child process computing {getattr(fn, '__name__', fn)} ended "
                           f"without a result (wait status {status})")  # fmt: skip
    ok, value = pickle.loads(b"".join(chunks))
    if ok:
        return value
    raise value
