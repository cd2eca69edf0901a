"""Resource guards, estimates and progress lines shared by the commands.

* :func:`require_memory` compares an estimate of what a run will allocate with the memory
  available now (``psutil``) and raises a one-line :class:`~lcc_synth.errors.ConfigError`
  naming the field that makes it large, BEFORE anything is allocated.
* :func:`estimate_simulation` estimates a simulation's run time and peak memory from the
  per-unit costs below (:class:`WorkEstimate`); :func:`announce` prints it as one line on
  stderr before a run estimated to take more than :data:`LONG_RUN_S`.
* :func:`progress` prints one line on stderr (``lcc-synth: synthesis: ...``) for long work
  that has no progress bar (synthesis stages, LMI solves, sparsity sweep); commands switch it
  on through :func:`set_progress`.
* :func:`single_thread_blas` limits BLAS/LAPACK to one thread (a context manager, or a
  decorator of a function): the package's matrices are small, and OpenBLAS's threads on two
  busy cores cost far more than they gain (measured: an 82-state structured polish 9.8 s with
  the default threads, 0.5 s with one; the MPC's 22-state Riccati solve 2-40 ms with a stall
  of 1.9 s, ~2 ms with one).
* :func:`lazy_exports` makes a subpackage load each public name's submodule on first use
  (PEP 562): a command that refuses its input ends before the stacks it would have used
  (recording, SciPy, CVXPY, the QP) are imported.
* :func:`progress_bar` is the one progress bar of the package (tqdm on stderr, with a count);
  :func:`notice` prints one line on stderr (a command's estimate). ``--quiet`` (alias
  ``--no-progress``) of every command sets :func:`set_quiet`: no bar, no progress line, no
  estimate line (results on stdout and errors stay).

Per-unit costs (``benchmarks/bench_recording_size.py``, this 2-core machine, shared with other
work while measured, so times vary by up to 3x; the constants take the high end)
------------------------------------------------------------------------------------------
Time. The compiled loop: 32-80 ns per vehicle-step; with the metrics of every scenario 176 ns
(``lcc-synth simulate problems/paper_appendix_c.toml --seeds 200 --no-record``: 15 s, 1.8 s of
it starting up): :data:`VEHICLE_STEP_S`. A controller that is not compiled: 66 us per
controller step for the engine's loop and observation (:data:`STEP_S`, a FollowerStopper)
plus 2.4 us per scenario (:data:`SCENARIO_STEP_S`); the MPC 0.7-2.0 ms per controller step and
scenario at horizon 50, its setup included (:data:`MPC_STEP_S`), DeeP-LCC 0.8-1.2 ms
(:data:`DEEPLCC_STEP_S`), both taken proportional to the horizon; with their QP solved by
DAQP about a quarter of that (:func:`qp_step_seconds`). Recording: 36-62 ms per run
alone, 97 ms per run of the 200-seed study above (600 runs, 155 MB: 58 s more than without
recording), :data:`RECORD_RUN_S`, plus 0.013-0.02 s per MB written (:data:`RECORD_BYTE_S`).

Memory. A result of ``B x T x n`` samples as
:func:`simulation_bytes` counts it, 1.75 times for the metrics'
temporaries (:data:`RESULT_PEAK`; the study above without recording peaked 1.26-1.32 GiB above
the interpreter for a 786 MB result); a scenario's random draws 705 B with 12 vehicles and its
random generator 390 B while drawing (:data:`DRAW_VEHICLE_BYTES`,
:data:`DRAW_SCENARIO_BYTES`); the per-scenario metrics a seed study keeps, 384 B per scenario
and controller with 12 vehicles (:data:`METRIC_VEHICLE_BYTES`; doubled when the chunks are
joined); an MPC's history 19.0 kB per controller step and scenario at horizon 50 with 12
vehicles (:data:`HISTORY_POINT_BYTES` per predicted vehicle-point); a recording's layout 18.6 kB
of Python objects per view, built twice (:data:`VIEW_OBJECT_BYTES`), and the stream's buffers
(:data:`RECORDER_BYTES`).

Estimates against the real command (section 6 of the benchmark; memory: peak resident above
the interpreter's 0.19 GiB): the 200-seed study with its recording estimated 78 s and
1.57 GiB, measured 61-73 s and 1.47 GiB; without it 13 s and 1.29 GiB, measured 15 s and
1.26 GiB; ``mpc_head_brake`` 2 s, measured 3.5 s (and 0.1 GiB of casadi and OSQP). Limits:
the time is an order of magnitude (machine load, solver iterations; DeeP-LCC's data
collection and the synthesis of ``h2`` controllers are not counted); the memory counts what
grows with the study (a seed chunk's results, draws, histories, metrics, the layout), not the
interpreter and its libraries (already in use when :func:`available_memory` is read).
"""

from __future__ import annotations

import functools
import importlib
import math
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from lcc_synth.errors import ConfigError

__all__ = [
    "lazy_exports",
    "MEMORY_FRACTION",
    "LONG_RUN_S",
    "VEHICLE_STEP_S",
    "STEP_S",
    "SCENARIO_STEP_S",
    "MPC_STEP_S",
    "DEEPLCC_STEP_S",
    "MPC_DAQP_STEP_S",
    "DEEPLCC_DAQP_STEP_S",
    "qp_step_seconds",
    "RECORD_RUN_S",
    "RECORD_BYTE_S",
    "RESULT_PEAK",
    "DRAW_VEHICLE_BYTES",
    "DRAW_SCENARIO_BYTES",
    "METRIC_VEHICLE_BYTES",
    "HISTORY_POINT_BYTES",
    "VIEW_OBJECT_BYTES",
    "RECORDER_BYTES",
    "WorkEstimate",
    "announce",
    "available_memory",
    "estimate_simulation",
    "format_bytes",
    "format_duration",
    "format_size",
    "require_memory",
    "progress",
    "progress_bar",
    "notice",
    "single_thread_blas",
    "quiet",
    "set_progress",
    "set_quiet",
    "simulation_bytes",
]

#: fraction of the available memory a single run may plan to use
MEMORY_FRACTION = 0.8
#: a run estimated to take longer than this (s) prints its estimate first (:func:`announce`)
LONG_RUN_S = 10.0

#: seconds per vehicle-step of the compiled simulation loop and the metrics (measured 176 ns)
VEHICLE_STEP_S = 1.8e-7
#: seconds per controller step of a controller that is not compiled (engine loop, observation)
STEP_S = 7e-5
#: ... and per scenario of the batch (a vectorised Python controller)
SCENARIO_STEP_S = 3e-6
#: seconds per controller step and scenario of the MPC at horizon 50 (proportional to it)
MPC_STEP_S = 2e-3
#: seconds per controller step and scenario of DeeP-LCC at horizon 50 (proportional to it)
DEEPLCC_STEP_S = 1.2e-3
#: :data:`MPC_STEP_S` with ``solver.method = "daqp"`` (the showcase's 24 simulations took
#: 3.0 s with DAQP, 11-15 s with OSQP: a quarter)
MPC_DAQP_STEP_S = 5e-4
#: :data:`DEEPLCC_STEP_S` with ``solver.method = "daqp"`` (its set-up is the larger part)
DEEPLCC_DAQP_STEP_S = 4e-4
#: seconds per recorded run (decimation, Arrow conversion, documents; measured 37-97 ms)
RECORD_RUN_S = 0.1
#: seconds per recorded byte (0.02 s per MB)
RECORD_BYTE_S = 2e-8
#: peak memory of a result and its metrics, in results (the metrics' temporaries)
RESULT_PEAK = 1.75
#: bytes of a scenario's random draws per vehicle (every model parameter, delay, spacing)
DRAW_VEHICLE_BYTES = 64
#: ... and per scenario (its random generator while drawing)
DRAW_SCENARIO_BYTES = 400
#: bytes of the per-scenario metrics kept per scenario, controller and vehicle
METRIC_VEHICLE_BYTES = 32
#: bytes of an MPC's history per controller step, scenario and predicted vehicle-point
HISTORY_POINT_BYTES = 32
#: bytes of Python objects per view of a recording's layout (built twice by the recorder)
VIEW_OBJECT_BYTES = 20_000
#: bytes the recording stream holds besides the layout (measured: a 200-seed study peaked
#: 0.21 GiB higher with its recording than without)
RECORDER_BYTES = 1.5e8

_PROGRESS = {"enabled": False, "quiet": False}


def _read_int(path: str) -> int | None:
    try:
        with open(path) as fh:
            text = fh.read().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None  # "max": no limit


def _container_room() -> int | None:
    """Bytes this process may still allocate under its container's (cgroup v2 or v1) memory
    limit and its address-space limit (``RLIMIT_AS``); ``None`` when neither is set."""
    import resource

    rooms = []
    for limit, used in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                        ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                         "/sys/fs/cgroup/memory/memory.usage_in_bytes")):  # fmt: skip
        cap, now = _read_int(limit), _read_int(used)
        if cap is not None and now is not None and cap < (1 << 60):  # v1: "no limit" is huge
            rooms.append(max(cap - now, 0))
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        try:
            import psutil

            rooms.append(max(soft - psutil.Process().memory_info().vms, 0))
        except Exception:  # pragma: no cover - psutil is a dependency
            pass
    return min(rooms) if rooms else None


def available_memory() -> int:
    """Bytes of memory available now: the machine's (``psutil``; ``/proc/meminfo`` as a
    fallback), or less when a container's memory limit (cgroup) or this process's
    address-space limit leaves less room."""
    try:
        import psutil

        avail = int(psutil.virtual_memory().available)
    except Exception:  # pragma: no cover - psutil is a dependency
        avail = 1 << 62
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
    room = _container_room()
    return avail if room is None else min(avail, room)


def format_bytes(n: float) -> str:
    """``n`` bytes as ``"1.2 GiB"``."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.3g} PiB"  # pragma: no cover


def require_memory(field: str, needed: float, what: str, hint: str = "") -> None:
    """Raise :class:`ConfigError` for ``field`` when ``needed`` bytes cannot fit.

    ``what`` says what the estimate counts (e.g. ``"6000001 steps x 12 vehicles x 1
    scenario"``); ``hint`` what to change.
    """
    avail = available_memory()
    if needed > MEMORY_FRACTION * avail:
        raise ConfigError(
            field,
            f"the run needs about {format_bytes(needed)} of memory ({what}) but only "
            f"{format_bytes(avail)} is available{'; ' + hint if hint else ''}",
        )


def set_progress(enabled: bool) -> None:
    """Switch the progress lines of :func:`progress` on or off (off by default)."""
    _PROGRESS["enabled"] = bool(enabled)


def set_quiet(value: bool) -> None:
    """Silence (``True``) or restore every bar, progress line and estimate line of the process
    (``--quiet``; the commands set it for their run and clear it after)."""
    _PROGRESS["quiet"] = bool(value)


def quiet() -> bool:
    """Whether ``--quiet`` silenced the progress output (:func:`set_quiet`)."""
    return _PROGRESS["quiet"]


def progress(message: str) -> None:
    """One progress line on stderr when enabled and not quiet (flushed at once)."""
    if _PROGRESS["enabled"] and not _PROGRESS["quiet"]:
        print(f"lcc-synth: {message}", file=sys.stderr, flush=True)


def notice(command: str, message: str) -> None:
    """``lcc-synth COMMAND: MESSAGE`` on stderr unless quiet (:func:`set_quiet`), flushed at
    once: a command's estimate, or the stage it starts when the stage has no bar."""
    if not _PROGRESS["quiet"]:
        print(f"lcc-synth {command}: {message}", file=sys.stderr, flush=True)


def progress_bar(
    total: int, desc: str, enabled: bool = True, unit: str = "run", delay: float = 0.0
):
    """A progress bar with a count on stderr (tqdm); a silent one when ``enabled`` is false or
    the process is quiet (:func:`set_quiet`). ``delay``: seconds before it appears (a quick
    job prints nothing)."""
    from tqdm import tqdm

    return tqdm(
        total=total,
        desc=desc,
        file=sys.stderr,
        disable=not enabled or _PROGRESS["quiet"],
        leave=True,
        dynamic_ncols=True,
        unit=unit,
        delay=delay,
    )


def simulation_bytes(sc: Any) -> int:
    """Bytes :func:`~lcc_synth.simulation.engine.simulate` allocates for the scenario ``sc``:
    the time grid and the perturbation overrides (``steps x (1 + 2 vehicles)``), the recorded
    samples (``batch x kept samples x (4 vehicles + 1 per CAV)`` floats) and the delay ring
    buffer."""
    import numpy as np

    T, nv, B = sc.steps, sc.n_vehicles, sc.batch
    kept = (T - 1) // sc.record_every + 1
    nc = len(sc.cav_columns)
    delay = float(np.max(np.asarray(sc.delay, dtype=float), initial=0.0)) + sc.delay_spread
    delay = max(delay if np.isfinite(delay) else 0.0, sc.v2v.latency, 0.0)
    ring = (int(delay / sc.dt) + 2) * B * nv * 16
    return 8 * T * (1 + 2 * nv) + B * kept * (8 * (4 * nv + nc) + nc) + ring


def format_size(n: float) -> str:
    """``n`` bytes in decimal units (those of ``--max-recording-size``): ``"1.9 GB"``,
    ``"640 kB"``."""
    for unit, scale in (("PB", 1e15), ("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if abs(n) >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} B"


def format_duration(seconds: float) -> str:
    """``"40 s"``, ``"12 min"``, ``"3.2 h"``, ``"4.1 days"``, ``"37 years"``."""
    s = float(seconds)
    if s < 90:
        return f"{s:.2g} s" if s < 10 else f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    if s < 2 * 86400:
        return f"{s / 3600:.2g} h"
    if s < 730 * 86400:
        return f"{s / 86400:.2g} days"
    return f"{s / (365.25 * 86400):.3g} years"


@dataclass(frozen=True)
class WorkEstimate:
    """Run time and peak memory of a run, before it starts (:func:`estimate_simulation`).

    Attributes
    ----------
    seconds : float
        Estimated run time (an order of magnitude: see the module docstring).
    memory : float
        Estimated peak of what the run allocates (bytes).
    what : str
        What it counts, e.g. ``"200 draws x 3 controllers"``.
    recording : float, optional
        Estimated size of the recording (bytes), when there is one.
    """

    seconds: float
    memory: float
    what: str
    recording: float | None = None

    def line(self, command: str) -> str:
        """``lcc-synth simulate: estimate: 200 draws x 3 controllers, ~40 s, recording ~1.9 GB``
        (memory too when it is above 1 GB)."""
        parts = [self.what, f"~{format_duration(self.seconds)}"]
        if self.memory >= 1e9:
            parts.append(f"memory ~{format_bytes(self.memory)}")
        if self.recording is not None:
            parts.append(f"recording ~{format_size(self.recording)}")
        return f"lcc-synth {command}: estimate: {', '.join(parts)}"


def _step_costs(controller: Any) -> tuple[float, float]:
    """``(seconds per controller step, seconds per controller step and scenario)`` of a
    controller that is not compiled; ``(0, 0)`` for one that is (``linear_law``)."""
    if callable(getattr(controller, "linear_law", None)):
        return 0.0, 0.0
    settings = getattr(controller, "settings", None)
    horizon = getattr(settings, "horizon", None)
    if horizon is None:
        return STEP_S, SCENARIO_STEP_S
    kind = "deep_lcc" if "deep" in type(controller).__name__.lower() else "mpc"
    method = getattr(getattr(settings, "solver", None), "method", "osqp")
    return STEP_S, qp_step_seconds(kind, method, int(horizon))


def qp_step_seconds(kind: str, method: str = "osqp", horizon: int = 50) -> float:
    """Seconds per controller step and scenario of a predictive controller (``kind`` ``"mpc"``
    or ``"deep_lcc"``) solving its QP with ``method`` (``"osqp"``, ``"daqp"``), proportional
    to the ``horizon`` (:data:`MPC_STEP_S`, :data:`DEEPLCC_STEP_S`,
    :data:`MPC_DAQP_STEP_S`, :data:`DEEPLCC_DAQP_STEP_S`)."""
    daqp = method == "daqp"
    if kind == "deep_lcc":
        per = DEEPLCC_DAQP_STEP_S if daqp else DEEPLCC_STEP_S
    else:
        per = MPC_DAQP_STEP_S if daqp else MPC_STEP_S
    return per * max(1, int(horizon)) / 50.0


def _history_bytes(controller: Any, nv: int) -> float:
    """Bytes of a predictive controller's history per controller step and scenario."""
    if not callable(getattr(controller, "history", None)):
        return 0.0
    horizon = int(getattr(getattr(controller, "settings", None), "horizon", 50) or 50)
    return float(HISTORY_POINT_BYTES * (horizon + 1) * nv)


def estimate_simulation(
    scenario: Any,
    controllers: Mapping[str, Any],
    *,
    chunk: int | None = None,
    recording: Any = None,
) -> WorkEstimate:
    """Run time and peak memory of simulating every controller on ``scenario`` (all of its
    ``batch`` draws), from the per-unit costs of the module docstring.

    Parameters
    ----------
    scenario : lcc_synth.simulation.scenario.Scenario
    controllers : mapping of str to Controller
        Built controllers (compiled laws, MPC, DeeP-LCC and Python controllers cost
        differently).
    chunk : int, optional
        Scenarios simulated at once (``lcc-synth simulate`` runs large studies in chunks;
        default: the whole batch).
    recording : lcc_synth.recording.size.RecordingEstimate, optional
        The recording written meanwhile.

    Returns
    -------
    WorkEstimate
    """
    from dataclasses import replace

    B, T, nv = int(scenario.batch), int(scenario.steps), int(scenario.n_vehicles)
    b = max(1, min(B, int(chunk or B)))
    seconds, peak = 0.0, 0.0
    part = replace(scenario, batch=b, first_index=scenario.first_index)
    sim = float(simulation_bytes(part))
    draws = b * (DRAW_VEHICLE_BYTES * nv + DRAW_SCENARIO_BYTES)
    for ctrl in controllers.values():
        ts = getattr(ctrl, "sample_time", None)
        steps = T if not ts else math.ceil(T * float(scenario.dt) / float(ts))
        per_step, per_scenario = _step_costs(ctrl)
        seconds += B * T * nv * VEHICLE_STEP_S + steps * (per_step + B * per_scenario)
        peak = max(peak, RESULT_PEAK * sim + b * steps * _history_bytes(ctrl, nv))
    n = len(controllers)
    metrics = 2.0 * B * n * METRIC_VEHICLE_BYTES * nv
    memory = peak + draws + metrics
    rec_bytes = None
    if recording is not None:
        rec_bytes = float(recording.bytes)
        seconds += recording.runs * RECORD_RUN_S + rec_bytes * RECORD_BYTE_S
        memory += 2 * recording.views * VIEW_OBJECT_BYTES + RECORDER_BYTES
    what = f"{B} draws x {n} controllers" if B > 1 else f"{n} controllers"
    return WorkEstimate(seconds, memory, what, rec_bytes)


def announce(command: str, estimate: WorkEstimate, threshold: float = LONG_RUN_S) -> bool:
    """Print ``estimate`` as one line on stderr when it is above ``threshold`` seconds;
    returns whether it did."""
    if estimate.seconds <= threshold or _PROGRESS["quiet"]:
        return False
    print(estimate.line(command), file=sys.stderr, flush=True)
    return True


_BLAS_CONTROLLER: Any = None


class _OneBlasThread:
    """What :func:`single_thread_blas` returns: a context manager and a decorator."""

    def __enter__(self):
        global _BLAS_CONTROLLER
        from threadpoolctl import ThreadpoolController

        if _BLAS_CONTROLLER is None:  # inspecting the loaded libraries once: ~10 ms
            _BLAS_CONTROLLER = ThreadpoolController()
        self._limit = _BLAS_CONTROLLER.limit(limits=1, user_api="blas")
        return self._limit.__enter__()

    def __exit__(self, *exc):
        return self._limit.__exit__(*exc)

    def __call__(self, fn):
        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            with _OneBlasThread():
                return fn(*args, **kwargs)

        return wrapper


def single_thread_blas(fn=None):
    """BLAS/LAPACK limited to one thread (threadpoolctl): ``with single_thread_blas(): ...``,
    or ``@single_thread_blas`` on a function (module docstring)."""
    return _OneBlasThread() if fn is None else _OneBlasThread()(fn)


def lazy_exports(
    package: str, sources: Mapping[str, str]
) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """The module ``__getattr__`` and ``__dir__`` (PEP 562) of a subpackage whose public names
    are defined in its submodules, each imported the first time its name is asked for.

    A package whose ``__init__`` imported every submodule made each command pay for all of
    them (the recording stack; SciPy and CVXPY through the synthesis and MPC modules) before
    it could refuse a bad input. With these, ``package.NAME``, ``from package import NAME``
    and ``dir(package)`` work as before; a name is bound on the package once loaded.

    Parameters
    ----------
    package : str
        The subpackage's ``__name__``.
    sources : Mapping[str, str]
        ``{public name: submodule}``: the submodule (relative to ``package``) that defines it.

    Returns
    -------
    tuple
        ``(__getattr__, __dir__)``, to assign at the subpackage's top level.
    """
    module = sys.modules[package]

    def __getattr__(name: str) -> object:
        sub = sources.get(name)
        if sub is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{sub}"), name)
        setattr(module, name, value)
        return value

    def __dir__() -> list[str]:
        return sorted({*vars(module), *sources})

    return __getattr__, __dir__
