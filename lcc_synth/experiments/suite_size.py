"""The size of ``lcc-synth run``'s recording and its run time, before the work.

* Recording: the suite's scenarios with the controllers that run in each
  (:func:`~lcc_synth.experiments.suite_tables.applies`) handed to
  :func:`lcc_synth.recording.size.estimate_suite_recording`, and the check ``run`` calls
  (:func:`check_suite_recording`: ``--max-recording-size``, the free space).
* Run time (:func:`estimate_suite`, the line ``run`` prints first): the work counted from the
  tables, times per-unit costs.

  - controllers: :data:`DESIGN_S` per ``h2`` design and per predictive controller (its
    set-up) and layout;
  - simulations: per scenario and controller, ``batch x steps x vehicles`` vehicle-steps at
    :data:`lcc_synth.resources.VEHICLE_STEP_S`, plus, for a controller that is not compiled,
    its controller steps (``duration / sample_time``) at
    :func:`~lcc_synth.resources.qp_step_seconds` (by the QP solver, scaled by ``horizon / 50``)
    or :data:`~lcc_synth.resources.STEP_S` (a baseline);
  - string stability as run (:func:`~lcc_synth.experiments.comparison.gamma_settings`): per
    linear controller and setting :data:`CURVE_S`; per other controller one simulation of
    ``MEASURE_SETTLE_RUN + 2 pi / min(MEASURE_OMEGA)`` s (20,570 steps at ``dt = 0.01``) at
    :data:`MEASURE_STEP_S` per step (scaled by ``horizon / 50``);
  - the recording: :data:`~lcc_synth.resources.RECORD_RUN_S` per run plus
    :data:`~lcc_synth.resources.RECORD_BYTE_S` per byte of its estimated size.

  Measured on ``problems/showcase.toml`` (this 2-core machine, shared, 2026-12-03):
  controllers 3.1-4.9 s, simulations 14.2-14.9 s, string stability as run 5.8 s (30.8 s
  before the measurements solved their QPs with DAQP). Limits: an order of magnitude, as
  :mod:`lcc_synth.resources`: solver iterations and machine load move the predictive
  controllers' steps by 2-5x; DeeP-LCC's data collection is not counted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from lcc_synth.experiments.comparison import Suite, applies, controller_table, gamma_settings
from lcc_synth.mpc.settings import table_solver_method

__all__ = [
    "DESIGN_S",
    "CURVE_S",
    "MEASURE_STEP_S",
    "SuiteEstimate",
    "check_suite_recording",
    "estimate_suite",
    "suite_recording_estimate",
]

#: Seconds per ``h2`` design or predictive controller set-up and layout (the showcase's four
#: designs and seven set-ups: 3.8 s measured; one MPC on string10 alone: 1.3-4.1 s).
DESIGN_S = 0.5
#: Seconds per as-run |Gamma| curve of a linear controller (measured 0.05-0.09 s on string10).
CURVE_S = 0.1
#: Seconds per simulator step of the small-signal measurement of a predictive controller at
#: horizon 50, its QP solved by DAQP (:func:`lcc_synth.mpc.active_set.exact_qp`; the
#: showcase's six measurements, 20,570 steps each: 0.37-0.82 s for an MPC, 1.7 s for
#: DeeP-LCC, 5.2 s together, 42 us per step; with OSQP they took 24 s).
MEASURE_STEP_S = 4e-5
#: Controller types whose loop is linear (an as-run curve, no measurement).
_LINEAR = ("hdv", "static", "gains_file", "h2")


@dataclass(frozen=True)
class SuiteEstimate:
    """The work of ``lcc-synth run`` on a suite and its estimated run time.

    Attributes
    ----------
    scenarios : int
    controllers : tuple of int
        The fewest and most controllers that run in one scenario.
    runs : int
        Scenario-controller simulations.
    curves : int
        As-run |Gamma| curves (linear controllers) and measurements (the others).
    seconds : dict
        ``{"controllers", "simulations", "string_stability", "recording"}`` (s).
    """

    scenarios: int
    controllers: tuple[int, int]
    runs: int
    curves: int
    seconds: dict[str, float]

    @property
    def total(self) -> float:
        """The estimated run time (s)."""
        return sum(self.seconds.values())

    def line(self) -> str:
        """``6 scenarios × 3–6 controllers (24 runs, 16 |Γ| curves), about 56 s``."""
        from lcc_synth.resources import format_duration

        lo, hi = self.controllers
        per = f"{lo}" if lo == hi else f"{lo}–{hi}"

        def plural(k: int, word: str) -> str:
            return f"{k} {word}" + ("" if k == 1 else "s")

        return (f"{plural(self.scenarios, 'scenario')} × {per} controller"
                f"{'' if hi == 1 else 's'} ({plural(self.runs, 'run')}, "
                f"{plural(self.curves, '|Γ| curve')}), about "
                f"{format_duration(self.total)}")  # fmt: skip


def _horizon(table: dict[str, Any]) -> int:
    return max(1, int(table.get("horizon", 50) or 50))


def _per_step(table: dict[str, Any], per_step_50: float) -> float:
    return per_step_50 * _horizon(table) / 50.0


def _controller_steps(table: dict[str, Any], scenario: Any) -> int:
    ts = table.get("sample_time")
    if not ts:
        return int(scenario.steps)
    return math.ceil(int(scenario.steps) * float(scenario.dt) / float(ts))


def estimate_suite(suite: Suite, recording: Any = None) -> SuiteEstimate:
    """The run time of ``lcc-synth run`` on ``suite`` from the work its tables count (module
    docstring); ``recording``: the run's
    :class:`~lcc_synth.recording.size.RecordingEstimate` (``None``: no recording)."""
    from lcc_synth.experiments.string_as_run import MEASURE_OMEGA, MEASURE_SETTLE_RUN
    from lcc_synth.resources import (
        RECORD_BYTE_S,
        RECORD_RUN_S,
        SCENARIO_STEP_S,
        STEP_S,
        VEHICLE_STEP_S,
        qp_step_seconds,
    )

    designs = sum(1 for lname in suite.layouts_used() for t in suite.controllers.values()
                  if applies(t, lname) and controller_table(t, lname).get("type")
                  in ("h2", "mpc", "deep_lcc"))  # fmt: skip
    sim, runs, counts = 0.0, 0, []
    for sname, ss in suite.scenarios.items():
        sc = ss.scenario
        tables = [controller_table(t, ss.layout) for t in suite.controllers.values()
                  if applies(t, ss.layout, sname)]  # fmt: skip
        counts.append(len(tables))
        for t in tables:
            runs += 1
            sim += sc.batch * sc.steps * sc.n_vehicles * VEHICLE_STEP_S
            kind = t.get("type")
            if kind in _LINEAR:
                continue
            steps = _controller_steps(t, sc)
            if kind in ("mpc", "deep_lcc"):
                sim += steps * sc.batch * qp_step_seconds(kind, table_solver_method(t), _horizon(t))
            else:
                sim += steps * (STEP_S + sc.batch * SCENARIO_STEP_S)
    string, curves = 0.0, 0
    duration = MEASURE_SETTLE_RUN + 2.0 * math.pi / min(MEASURE_OMEGA)
    for lname, rows in gamma_settings(suite).items():
        nv = suite.layouts[lname].m + suite.layouts[lname].n + 2
        for _suffix, dt, _lat, snames in rows:
            for t in suite.controllers.values():
                if not any(applies(t, lname, s) for s in snames):
                    continue
                curves += 1
                table = controller_table(t, lname)
                if table.get("type") in _LINEAR:
                    string += CURVE_S
                else:
                    steps = duration / dt
                    string += steps * (_per_step(table, MEASURE_STEP_S) + nv * VEHICLE_STEP_S)
    record = 0.0
    if recording is not None:
        record = recording.runs * RECORD_RUN_S + float(recording.bytes) * RECORD_BYTE_S
    seconds = {"controllers": designs * DESIGN_S, "simulations": sim,
               "string_stability": string, "recording": record}  # fmt: skip
    return SuiteEstimate(len(suite.scenarios), (min(counts, default=0), max(counts, default=0)),
                         runs, curves, seconds)  # fmt: skip


def suite_recording_estimate(suite: Suite, decimate: int | str = "minmax") -> Any:
    """The estimated size of ``lcc-synth run``'s recording of ``suite``
    (:func:`lcc_synth.recording.size.estimate_suite_recording`): every scenario with the
    controllers that run in it (:func:`~lcc_synth.experiments.suite_tables.applies`, their tables
    for its layout), the |Gamma| curves and gains of every layout; ``decimate`` as
    ``--record-every``. Returns a :class:`~lcc_synth.recording.size.RecordingEstimate`."""
    from lcc_synth.recording.size import estimate_suite_recording

    entries = [
        (ss.scenario, [controller_table(t, ss.layout) for t in suite.controllers.values()
                       if applies(t, ss.layout, sname)])
        for sname, ss in suite.scenarios.items()
    ]  # fmt: skip
    documents = len(suite.layouts) * (len(suite.controllers) + 1)
    return estimate_suite_recording(entries, len(suite.controllers), documents, decimate)


def check_suite_recording(args: Any, suite: Suite) -> Any:
    """What ``lcc-synth run`` calls before the work: :func:`suite_recording_estimate` checked
    against ``--max-recording-size`` and the free space
    (:func:`lcc_synth.recording.cli.check_recording`: a one-line
    :class:`~lcc_synth.errors.ConfigError` naming ``--scenarios`` and what to change, or
    ``--rrd``); returns the estimate (``None`` with ``--no-record``)."""
    if getattr(args, "no_record", False):
        return None
    from lcc_synth.recording.cli import check_recording, recording_decimation

    every = recording_decimation(args)
    estimate = suite_recording_estimate(suite, every)
    check_recording(
        args, estimate, "--scenarios", "run fewer scenarios (--scenarios a,b) or controllers "
        "(--controllers a,b), " + ("--record-every minmax, " if every != "minmax" else "")
        + "--no-record",
    )  # fmt: skip
    return estimate
