"""What the commands use: ``--rrd`` / ``--no-record`` / ``--record-every`` and the recorder
that records each controller of a problem as its result arrives."""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from lcc_synth.errors import ConfigError
from lcc_synth.recording.core import (
    entity_name,
    open_recording,
)
from lcc_synth.recording.layout import simulation_blueprint
from lcc_synth.recording.simulation import record_metrics, record_simulation


def add_recording_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--rrd PATH``, ``--no-record`` and ``--record-every N`` to a command's parser."""
    group = parser.add_argument_group("recording (Rerun .rrd, see `lcc-synth review`)")
    excl = group.add_mutually_exclusive_group()
    excl.add_argument(
        "--rrd",
        metavar="PATH",
        help="write the recording to PATH (default: logs/<problem>-<UTC timestamp>.rrd)",
    )
    excl.add_argument("--no-record", action="store_true", help="do not write a recording")
    group.add_argument(
        "--record-every",
        type=int,
        default=1,
        metavar="N",
        help="record every N-th simulation step (decimation; default 1 = every step)",
    )


def recording_path(
    args: argparse.Namespace, problem_name: str, now: datetime | None = None
) -> Path | None:
    """Where the command records: ``None`` with ``--no-record``, ``--rrd`` when given, else
    ``logs/<problem>-<UTC timestamp>.rrd`` (relative to the working directory)."""
    if getattr(args, "no_record", False):
        return None
    recording_decimation(args)  # validate early, before any work is done
    given = getattr(args, "rrd", None)
    if given:
        path = Path(given)
        if path.suffix != ".rrd":
            raise ConfigError("--rrd", f"must be a path ending in .rrd, got {given!r}")
        if path.exists() and path.is_dir():
            raise ConfigError("--rrd", f"is a directory, expected a file path: {given!r}")
        return path
    stamp = (now or datetime.now(UTC)).strftime("%Y%m%dT%H%M%SZ")
    return Path("logs") / f"{entity_name(problem_name)}-{stamp}.rrd"


def recording_decimation(args: argparse.Namespace) -> int:
    """The validated ``--record-every`` value (>= 1)."""
    every = getattr(args, "record_every", 1)
    if isinstance(every, bool) or not isinstance(every, int) or every < 1:
        raise ConfigError("--record-every", f"must be an integer >= 1, got {every!r}")
    return every


class SimulationRecorder:
    """Record the controllers of one problem as their results arrive (for CLI commands).

    The recording opens at the first result (its default path needs the problem name), inside
    ``stack`` so that it is finalised however the command ends; each call records one
    controller at once, so an interrupted command keeps every controller finished before.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed flags of :func:`add_recording_arguments` (validated here, before any work).
    stack : contextlib.ExitStack
        Owns the open recording.

    Examples
    --------
    >>> with ExitStack() as stack:                                        # doctest: +SKIP
    ...     recorder = SimulationRecorder(args, stack)
    ...     for name, result in ...:
    ...         recorder(spec, name, result)
    ...     recorder.metrics({name: metrics_dict, ...})
    """

    def __init__(self, args: argparse.Namespace, stack: Any):
        self.args = args
        self.stack = stack
        self.enabled = not getattr(args, "no_record", False)
        self.every = recording_decimation(args)
        if self.enabled:
            recording_path(args, "check")  # a bad --rrd fails before the simulation runs
        self.path: Path | None = None
        self.rec: Any = None
        self.scenario: str | None = None

    def __call__(self, spec: Any, name: str, result: Any) -> None:
        """Record controller ``name``'s ``result`` of ``spec`` (``spec.name``,
        ``spec.controllers``); MPC controllers' ``history()`` is recorded too."""
        if not self.enabled:
            return
        if self.rec is None:
            self.scenario = spec.name
            self.path = recording_path(self.args, spec.name)
            mpc = [
                n
                for n, c in dict(spec.controllers).items()
                if callable(getattr(c, "history", None))
            ]
            blueprint = simulation_blueprint(spec.name, list(spec.controllers), mpc)
            self.rec = self.stack.enter_context(open_recording(self.path, spec.name, blueprint))
        controller = dict(spec.controllers).get(name)
        history = None
        if callable(getattr(controller, "history", None)):
            history = controller.history() or None
        record_simulation(
            self.rec, result, self.scenario, controller=name, decimate=self.every,
            mpc_history=history,
        )  # fmt: skip

    def metrics(self, report: Mapping[str, Mapping[str, Any]]) -> None:
        """Write each controller's final metrics (``{name: metrics}``) and the comparison."""
        if self.rec is None:
            return
        for name, entry in report.items():
            record_metrics(self.rec, self.scenario, name, entry)
