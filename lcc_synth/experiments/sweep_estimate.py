"""What a sweep will cost, before it runs: memory, disk, run time (``lcc-synth sweep``).

The estimate scales per-unit costs measured on this project's reference machine (2 shared
cores, Python 3.11, numpy 2.4, ``problems/sweep_robustness.toml``: 10 HDVs, 4000 steps of
0.01 s per scenario). ``lcc-synth sweep`` refuses a sweep whose memory or disk estimate does
not fit (exit 2, one line naming ``--count`` or ``[sweep].count``), before the cluster starts,
and prints the estimate first (one line on stderr) when it expects the sweep to run longer
than :data:`LONG_S`.

Memory (the client)
    ``count x controllers x samples`` values (:data:`~lcc_synth.experiments.sweep.SWEEP_SAMPLES`,
    13) at :data:`BYTES_PER_VALUE` each (:data:`BYTES_PER_VALUE_RECORDED` with the recording),
    plus :data:`BASE_BYTES` (:data:`BASE_BYTES_RECORDED`). Measured as the peak RSS of the
    sweep's bookkeeping and outputs (the samples, their summary, ``samples.csv`` written
    twice, the figure and, for the second figure, the recording of the samples) above the RSS
    before them, for 0.1, 0.4 and 1 million scenarios x 2 controllers and 0.2 million x 6:
    peaks of 76, 156 and 317 MiB without the recording (10.8 bytes more per value, 8 of them
    the float64 samples), 207, 471, 886 and 563 MiB with it (27.9 bytes more per value:
    Rerun's copies). The Dask tasks in flight are bounded
    (:data:`~lcc_synth.experiments.sweep.TASKS_PER_THREAD` per worker thread) whatever the
    count.
Disk (the results directory)
    ``samples.csv``: a row per scenario and controller of ``len(index) + len(name) + 2 +
    samples x`` :data:`CSV_BYTES_PER_VALUE` bytes (measured: 18.0-18.1 bytes per sample,
    its text and the comma, for the random floats above; a real sweep's counts are shorter:
    13.8 on 120 scenarios x 2 controllers of the reference), counted twice (a partial
    ``samples.csv`` is replaced atomically: the old and the new file exist together for a
    moment), plus ``sweep.json`` (:data:`JSON_BYTES_PER_TASK` per task and controller of the
    partial file, :data:`JSON_BYTES_PER_CONTROLLER`; measured 292 bytes per task with 2
    controllers and 543 with 6, 5.1 and 12.5 kB besides) and the figure
    (:data:`FIGURE_BYTES`; measured 97 kB with 2 controllers, 140 kB with 6). The recording
    (``--rrd``, in ``logs/``: measured 13 bytes per value) is not counted here.
Run time
    ``count x`` the seconds per scenario of each controller ``/ workers``: per simulated step
    (scaled by the vehicles) for the controllers without an optimisation (:data:`STEP_S`;
    measured 4.5 us for ``hdv``, 6.2 for the static gain with an estimated equilibrium, 3.6 for
    ``h2``), and per controller period for an MPC (:data:`MPC_SOLVE_S`; measured 1.52 ms,
    1.39 with a delay model) and DeeP-LCC (:data:`DEEPLCC_SOLVE_S`; measured 1.96 ms, its
    data collection and set-up per scenario included), or with their QP solved by DAQP
    (``solver.method = "daqp"``: :data:`MPC_DAQP_SOLVE_S`, :data:`DEEPLCC_DAQP_SOLVE_S`); the
    ``h2`` synthesis in the client is not counted. Measured in one process (one BLAS
    thread) on 6 scenarios of the reference sweep, whose settings drawn per scenario make it
    simulate them one by one: the slower way (a batch of 6 without drawn settings took
    0.5-0.75 of the time).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lcc_synth.errors import ConfigError
from lcc_synth.experiments.sweep import SWEEP_SAMPLES, SweepSpec, chunks
from lcc_synth.mpc.settings import table_solver_method

__all__ = [
    "BYTES_PER_VALUE", "BYTES_PER_VALUE_RECORDED", "BASE_BYTES", "BASE_BYTES_RECORDED",
    "CSV_BYTES_PER_VALUE", "JSON_BYTES_PER_TASK",
    "JSON_BYTES_PER_CONTROLLER", "FIGURE_BYTES", "STEP_S", "MPC_SOLVE_S", "DEEPLCC_SOLVE_S",
    "MPC_DAQP_SOLVE_S", "DEEPLCC_DAQP_SOLVE_S",
    "LONG_S", "SweepEstimate", "estimate_sweep",
]  # fmt: skip

#: Peak client memory per sample value (scenario x controller x sample), bytes.
BYTES_PER_VALUE = 11.0
#: The same with the sweep's recording (Rerun's copies of the samples).
BYTES_PER_VALUE_RECORDED = 28.0
#: Client memory of a sweep's outputs beyond the samples, bytes.
BASE_BYTES = 64 << 20
#: The same with the recording.
BASE_BYTES_RECORDED = 200 << 20
#: Mean bytes of one sample in ``samples.csv`` (its text and the comma).
CSV_BYTES_PER_VALUE = 18.0
#: Bytes of one finished task's entry in a partial ``sweep.json``, per controller and one more.
JSON_BYTES_PER_TASK = 150.0
#: Bytes of one controller's summary (and the rest) in ``sweep.json``.
JSON_BYTES_PER_CONTROLLER = 3000.0
#: Bytes of ``distributions.png`` (measured: 140 kB with 6 controllers).
FIGURE_BYTES = 200_000.0
#: Seconds per simulated step (times vehicle columns / 12: the reference's head, CAV, 10 HDVs)
#: of a controller without an optimisation (hdv, static, h2, gains_file, the baselines).
STEP_S = 6.5e-6
#: Seconds per MPC period (its QP and the simulation of the steps in between).
MPC_SOLVE_S = 1.6e-3
#: Seconds per DeeP-LCC period (its QP, its data collection and set-up spread over the run).
DEEPLCC_SOLVE_S = 2.0e-3
#: :data:`MPC_SOLVE_S` with ``solver.method = "daqp"`` (measured 0.24 ms per period where
#: OSQP took 1.2 ms, same process and load).
MPC_DAQP_SOLVE_S = 3e-4
#: :data:`DEEPLCC_SOLVE_S` with ``solver.method = "daqp"`` (measured 0.68 ms where OSQP, with
#: its exact re-solves, took 1.9 ms; 0.44 ms once the data's reduction factored the 890 x 890
#: ``lambda_g I + B B'`` instead of the 1931 x 1931 Hessian, 24 scenarios).
DEEPLCC_DAQP_SOLVE_S = 5e-4
#: Estimated run time from which ``lcc-synth sweep`` prints the estimate first, seconds.
LONG_S = 60.0

_REFERENCE_COLUMNS = 12  # the head vehicle, the CAV, 10 HDVs


@dataclass(frozen=True)
class SweepEstimate:
    """A sweep's estimated cost.

    Attributes
    ----------
    count, controllers, workers : int
    memory : float
        Peak memory of the client, bytes.
    csv : float
        Size of ``samples.csv``, bytes.
    disk : float
        Bytes the results directory needs at its peak (``samples.csv`` twice, ``sweep.json``,
        the figure).
    per_scenario : dict
        ``{controller: seconds per scenario}``.
    seconds : float
        Run time of the simulations on ``workers`` worker threads.
    """

    count: int
    controllers: int
    workers: int
    memory: float
    csv: float
    disk: float
    per_scenario: dict[str, float]
    seconds: float

    @property
    def values(self) -> int:
        """Sample values the sweep holds (``count x controllers x samples``)."""
        return self.count * self.controllers * len(SWEEP_SAMPLES)

    def require_memory(self, field: str, hint: str = "lower the count") -> None:
        """Raise :class:`ConfigError` for ``field`` (``--count`` or ``sweep.count``) when the
        memory estimate exceeds the share of the available memory a run may plan on
        (:func:`lcc_synth.resources.require_memory`); ``hint``: what to change."""
        from lcc_synth.resources import MEMORY_FRACTION, require_memory

        require_memory(field, self.memory,
                       f"{self.count} scenarios x {self.controllers} controllers x "
                       f"{len(SWEEP_SAMPLES)} samples",
                       f"a run may plan on {MEMORY_FRACTION:.0%} of it: {hint}")  # fmt: skip

    def require_disk(self, field: str, directory: str | Path) -> None:
        """Raise :class:`ConfigError` for ``field`` when the file system of ``directory``
        (or its nearest existing ancestor) has less free space than the disk estimate
        (with :data:`lcc_synth.outputs.SPACE_MARGIN` and ``SPACE_FLOOR``)."""
        from lcc_synth.outputs import SPACE_FLOOR, SPACE_MARGIN, free_bytes
        from lcc_synth.resources import format_bytes

        need = self.disk * SPACE_MARGIN + SPACE_FLOOR
        free = free_bytes(directory)
        if free < need:
            raise ConfigError(
                field,
                f"the sweep writes about {format_bytes(self.disk)} in {directory} (samples.csv "
                f"{format_bytes(self.csv)}: {self.count} scenarios x {self.controllers} "
                f"controllers, and a partial copy while it runs) but only {format_bytes(free)} "
                "is free there: lower the count or write elsewhere (--out)",
            )

    def describe(self) -> str:
        """One line: run time, memory, samples.csv."""
        from lcc_synth.resources import format_bytes

        per = sum(self.per_scenario.values())
        slow = sorted(self.per_scenario.items(), key=lambda kv: -kv[1])[:3]
        parts = ", ".join(f"{k} {v:.2g} s" for k, v in slow)
        return (f"about {_duration(self.seconds)} on {self.workers} worker"
                f"{'s' if self.workers != 1 else ''} ({self.count} scenarios x {per:.2g} s: "
                f"{parts}), {format_bytes(self.memory)} of memory, samples.csv "
                f"{format_bytes(self.csv)}")  # fmt: skip


def _duration(s: float) -> str:
    if s < 120:
        return f"{s:.0f} s"
    if s < 2 * 3600:
        return f"{s / 60:.0f} min"
    if s < 2 * 86400:
        return f"{s / 3600:.1f} h"
    return f"{s / 86400:.0f} days"


def _per_scenario(table: dict[str, Any], steps: float, duration: float, scale: float) -> float:
    kind = table.get("type")
    daqp = table_solver_method(table) == "daqp"
    if kind == "mpc":
        period = float(table.get("sample_time") or 0.1)
        return duration / period * (MPC_DAQP_SOLVE_S if daqp else MPC_SOLVE_S) * scale
    if kind == "deep_lcc":
        data = table.get("data") if isinstance(table.get("data"), dict) else {}
        period = float(data.get("dt") or 0.05)
        return duration / period * (DEEPLCC_DAQP_SOLVE_S if daqp else DEEPLCC_SOLVE_S) * scale
    return steps * STEP_S * scale


def estimate_sweep(spec: SweepSpec, workers: int, record: bool = True) -> SweepEstimate:
    """The estimated memory, disk and run time of ``spec`` on ``workers`` worker threads,
    with or without the sweep's recording (see the module docstring for the figures and
    what they count)."""
    names = list(spec.controllers)
    n, c, k = spec.count, len(names), len(SWEEP_SAMPLES)
    if record:
        memory = BASE_BYTES_RECORDED + n * c * k * BYTES_PER_VALUE_RECORDED
    else:
        memory = BASE_BYTES + n * c * k * BYTES_PER_VALUE
    digits = len(str(max(n - 1, 0)))
    row = sum(digits + len(name) + 2 + k * CSV_BYTES_PER_VALUE for name in names)
    csv = len(",".join(["scenario", "controller", *SWEEP_SAMPLES])) + 1 + n * row
    tasks = len(chunks(n, spec.batch_size))
    json_bytes = tasks * (c + 1) * JSON_BYTES_PER_TASK + c * JSON_BYTES_PER_CONTROLLER
    disk = 2 * csv + json_bytes + FIGURE_BYTES
    sc = spec.scenario
    steps = sc.duration / sc.dt
    scale = max(spec.system.columns, 1) / _REFERENCE_COLUMNS
    per = {name: _per_scenario(spec.controllers[name], steps, sc.duration, scale)
           for name in names}  # fmt: skip
    workers = max(int(workers), 1)
    seconds = n * sum(per.values()) / workers
    return SweepEstimate(n, c, workers, memory, csv, disk, per, seconds)
