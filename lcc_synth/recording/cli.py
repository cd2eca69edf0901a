"""What the commands use: ``--rrd`` / ``--no-record`` / ``--record-every`` /
``--max-recording-size``, the recorder that records each controller of a problem as its result
arrives, and the check of a recording's estimated size before the work
(:func:`check_recording`)."""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.recording.context import context_markdown, first_event
from lcc_synth.recording.core import (
    entity_name,
    open_recording,
    record_provenance,
    record_text,
    set_status,
    written_path,
)
from lcc_synth.recording.layout import (
    merge_ranges,
    plot_ranges,
    seed_entity,
    seeds_blueprint,
    simulation_blueprint,
)
from lcc_synth.recording.simulation import (
    record_metrics,
    record_recorded,
    record_simulation,
    recorded_trajectories,
)

__all__ = [
    "SimulationRecorder",
    "add_recording_arguments",
    "check_recording",
    "check_recording_limit",
    "check_recording_space",
    "parse_record_seeds",
    "record_seed_count",
    "recording_decimation",
    "recording_limit",
    "recording_path",
]


def add_recording_arguments(parser: argparse.ArgumentParser, steps: bool = True) -> None:
    """Add ``--rrd PATH``, ``--no-record`` and (``steps``: for commands that record simulation
    steps) ``--record-every N`` and ``--max-recording-size SIZE`` to a command's parser."""
    group = parser.add_argument_group("recording (Rerun .rrd, see `lcc-synth review`)")
    excl = group.add_mutually_exclusive_group()
    excl.add_argument(
        "--rrd",
        metavar="PATH",
        help="write the recording to PATH (default: logs/<problem>-<UTC timestamp>.rrd)",
    )
    excl.add_argument("--no-record", action="store_true", help="do not write a recording")
    if not steps:
        return
    group.add_argument(
        "--record-every",
        type=_record_every,
        default=None,  # not given: the command's default (record_every_default, else minmax)
        metavar="N|minmax",
        help="'minmax' (the default): what the viewer draws at about a pixel, every visible "
        "peak and dip, the exact extremes and full rate around emergency braking and "
        "collisions, a fraction of the size; or every N-th simulation step (1 = every step: "
        "the exact recording, value for value)",
    )
    group.add_argument(
        "--max-recording-size",
        type=_size,
        default=None,
        metavar="SIZE",
        help="refuse, before the work, a run whose recording is estimated above SIZE "
        "(default 1GB; e.g. 500MB, 3GB)",
    )


def _size(text: str) -> int:
    """``--max-recording-size``: a size such as ``2GB``."""
    from lcc_synth.recording.size import parse_size

    try:
        return parse_size(text)
    except ConfigError as err:
        raise argparse.ArgumentTypeError(err.message) from None


def _record_every(text: str) -> int | str:
    """``--record-every``: a positive integer or ``minmax``."""
    if text.strip().lower() == "minmax":
        return "minmax"
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected an integer >= 1 or 'minmax', got {text!r}"
        ) from None


def recording_path(
    args: argparse.Namespace, problem_name: str, now: datetime | None = None
) -> Path | None:
    """Where the command records: ``None`` with ``--no-record``, ``--rrd`` when given, else
    ``logs/<problem>-<UTC timestamp>.rrd`` (relative to the working directory).

    Checked here, before any work (:func:`lcc_synth.outputs.check_file` /
    :func:`~lcc_synth.outputs.check_directory`): the suffix, an existing ``--rrd`` (refused
    unless ``--overwrite``), a directory that cannot be written. The default name is made
    unique when the file is published (``-2``, ``-3``... if another run took it)."""
    from lcc_synth.outputs import check_directory, check_file, path_part

    if getattr(args, "no_record", False):
        return None
    recording_decimation(args)  # validate early, before any work is done
    given = getattr(args, "rrd", None)
    if given:
        path = Path(given)
        if path.suffix != ".rrd":
            raise ConfigError("--rrd", f"must be a path ending in .rrd, got {given!r}")
        return check_file(path, "--rrd", overwrite=bool(getattr(args, "overwrite", False)))
    stamp = (now or datetime.now(UTC)).strftime("%Y%m%dT%H%M%SZ")
    check_directory("logs", "--rrd (default logs/)")
    return Path("logs") / f"{path_part(problem_name)}-{stamp}.rrd"


def recording_decimation(args: argparse.Namespace) -> int | str:
    """The validated ``--record-every`` value (an integer >= 1 or ``"minmax"``); when it is
    not given, the command's default (``record_every_default``, else ``"minmax"``: every
    command records the min/max-preserving decimation unless ``--record-every N`` is given;
    ``1`` is the exact recording)."""
    every = getattr(args, "record_every", None)
    if every is None:
        every = getattr(args, "record_every_default", "minmax")
    if every == "minmax":
        return every
    if isinstance(every, bool) or not isinstance(every, int) or every < 1:
        raise ConfigError("--record-every", f"must be an integer >= 1 or 'minmax', got {every!r}")
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
        self.record_seeds: str | None = getattr(args, "record_seeds", None)
        self.seeds: list[int] = []  # study scenarios recorded (several-seed recordings)
        self.ranges: dict[str, Any] = {}
        self._layout: tuple = ()
        self._recorded: Any = None  # what the scenario replays (recorded_trajectories)
        #: the run's provenance document, recorded at ``/provenance`` when the file opens
        self.provenance: dict[str, Any] | None = None

    @property
    def written(self) -> Path | None:
        """The file the recording was published as (after the stack closed it; ``None``
        before, without a recording, or when it could not be written)."""
        return None if self.rec is None else written_path(self.rec)

    def status(self, status: str, detail: str = "") -> None:
        """How the run ended, recorded when the file closes normally
        (:func:`~lcc_synth.recording.core.set_status`: ``partial``, ``failed``)."""
        if self.rec is not None:
            set_status(self.rec, status, detail)

    def __call__(self, spec: Any, name: str, result: Any, offset: int = 0) -> None:
        """Record controller ``name``'s ``result`` of ``spec`` (``spec.name``,
        ``spec.controllers``); MPC controllers' ``history()`` is recorded too.

        A study of one scenario records the controller as ``name``; a study of several
        (``spec.scenario.batch > 1``) records each selected scenario ``k`` (``--record-seeds``,
        default all) as ``<name>_seed<k>``; ``result`` holds scenarios ``offset ..`` (a seed
        chunk)."""
        if not self.enabled:
            return
        batch = int(getattr(getattr(spec, "scenario", None), "batch", 1))  # study size
        if self.rec is None:
            self.scenario = spec.name
            self.path = recording_path(self.args, spec.name)
            self.seeds = parse_record_seeds(self.record_seeds, batch)
            mpc = [
                n
                for n, c in dict(spec.controllers).items()
                if callable(getattr(c, "history", None))
            ]
            self.ranges = plot_ranges(result)
            self.event = first_event(getattr(spec, "scenario", None))
            self._layout = (spec.name, list(spec.controllers), mpc, batch > 1)
            source = getattr(spec, "source", None)
            self._recorded = recorded_trajectories(getattr(spec, "scenario", None),
                                                   Path(source).parent if source else None)
            self.rec = self.stack.enter_context(
                open_recording(self.path, spec.name, self._blueprint(),
                               overwrite=bool(getattr(self.args, "overwrite", False)))
            )
            if self.provenance is not None:
                record_provenance(self.rec, self.provenance)
            if getattr(spec, "scenario", None) is not None and hasattr(spec, "to_toml"):
                record_text(self.rec, f"/{entity_name(spec.name)}/context",
                            context_markdown(spec))  # fmt: skip
            if self._recorded is not None:
                record_recorded(self.rec, spec.name, self._recorded, result)
        else:
            self.ranges = merge_ranges(self.ranges, plot_ranges(result))
        controller = dict(spec.controllers).get(name)
        history = None
        if callable(getattr(controller, "history", None)):
            history = controller.history() or None
        if batch == 1:
            runs = [(name, 0)]
        else:
            members = int(np.asarray(result.velocity).shape[0])
            runs = [(seed_entity(name, k), k - offset) for k in self.seeds
                    if offset <= k < offset + members]  # fmt: skip
        for entity, run in runs:
            record_simulation(
                self.rec, result, self.scenario, controller=entity, decimate=self.every,
                mpc_history=history, run=run,
            )  # fmt: skip

    def _blueprint(self):
        scenario, controllers, mpc, several = self._layout
        ranges = {**self.ranges, "event": self.event}  # the time panel opens on the event
        if several:
            return seeds_blueprint(scenario, controllers, self.seeds, mpc, ranges)
        return simulation_blueprint(scenario, controllers, mpc, ranges,
                                    recorded=self._recorded is not None)

    def metrics(
        self, report: Mapping[str, Mapping[str, Any]], per: Mapping[str, Any] | None = None
    ) -> None:
        """Write each controller's final metrics (``{name: metrics}``) and the comparison; in a
        several-seed recording each recorded seed gets its own metrics from ``per``
        (``{name: per-scenario arrays}``, :func:`lcc_synth.metrics.per_scenario`)."""
        if self.rec is None:
            return
        several = self._layout[3]
        for name, entry in report.items():
            if not several:
                record_metrics(self.rec, self.scenario, name, entry)
                continue
            arrays = (per or {}).get(name, {})
            for k in self.seeds:
                one = {key: _item(v, k) for key, v in arrays.items()}
                one = {key: v for key, v in one.items() if v is not None}
                record_metrics(self.rec, self.scenario, seed_entity(name, k),
                               {"seed": k, **one})  # fmt: skip
        # The opening view ranges now cover every controller's run (re-sent as default).
        self.rec.send_blueprint(self._blueprint(), make_active=True, make_default=True)


def _item(values: Any, k: int):
    """Scenario ``k``'s value of a per-scenario metric array (``None`` if not one)."""
    x = np.asarray(values)
    if x.ndim == 0 or k >= x.shape[0]:
        return None
    v = x[k]
    return v.item() if np.ndim(v) == 0 else v.tolist()


def parse_record_seeds(value: str | None, batch: int) -> list[int]:
    """The scenarios ``--record-seeds`` selects (``"0,3"``, ``"2-5"``, ``"all"``) of a study of
    ``batch`` scenarios; ``None`` = all of them."""
    if value is None or str(value).strip().lower() == "all":
        return list(range(batch))
    out: set[int] = set()
    for part in str(value).split(","):
        part = part.strip()
        try:
            if "-" in part:
                a, b = (int(x) for x in part.split("-", 1))
                chosen = range(a, b + 1)
            else:
                chosen = [int(part)]
        except ValueError:
            raise ConfigError(
                "--record-seeds", f"expected seed indices like 0,3 or 2-5, got {value!r}"
            ) from None
        for k in chosen:
            if not 0 <= k < batch:
                raise ConfigError(
                    "--record-seeds", f"seed {k} is not in [0, {batch - 1}] (--seeds {batch})"
                )
            out.add(k)
    if not out:
        raise ConfigError("--record-seeds", f"selects no seed: {value!r}")
    return sorted(out)


def record_seed_count(value: str | None, batch: int) -> int:
    """How many scenarios ``--record-seeds`` selects of a study of ``batch`` (the same checks
    and errors as :func:`parse_record_seeds`, without listing them: a study of 10^8 seeds is
    counted, not enumerated)."""
    if value is None or str(value).strip().lower() == "all":
        return int(batch)
    spans: list[tuple[int, int]] = []
    for part in str(value).split(","):
        part = part.strip()
        try:
            a, b = (int(x) for x in part.split("-", 1)) if "-" in part else (int(part),) * 2
        except ValueError:
            raise ConfigError(
                "--record-seeds", f"expected seed indices like 0,3 or 2-5, got {value!r}"
            ) from None
        if a > b:
            continue  # an empty range, as parse_record_seeds
        if a < 0 or b >= batch:  # the first seed of the range outside the study
            k = a if a < 0 else max(a, batch)
            raise ConfigError(
                "--record-seeds", f"seed {k} is not in [0, {batch - 1}] (--seeds {batch})"
            )
        spans.append((a, b))
    if not spans:
        raise ConfigError("--record-seeds", f"selects no seed: {value!r}")
    count, end = 0, -1
    for a, b in sorted(spans):
        if b > end:
            count += b - max(a, end + 1) + 1
            end = b
    return count


def recording_limit(args: argparse.Namespace) -> int:
    """``--max-recording-size`` in bytes (default
    :data:`~lcc_synth.recording.size.DEFAULT_LIMIT`, 1 GB)."""
    from lcc_synth.recording.size import DEFAULT_LIMIT

    limit = getattr(args, "max_recording_size", None)
    return DEFAULT_LIMIT if limit is None else int(limit)


def check_recording(args: argparse.Namespace, estimate: Any, field: str, fixes: str) -> None:
    """Refuse, before the work, a recording estimated above ``--max-recording-size``
    (:func:`check_recording_limit`) or above the free space where it will be written
    (:func:`check_recording_space`).

    Parameters
    ----------
    args : argparse.Namespace
        The command's flags (nothing is checked with ``--no-record``).
    estimate : lcc_synth.recording.size.RecordingEstimate
        The recording's estimated size.
    field : str
        What makes it large (``--seeds``, ``scenario.batch``...): the error's field.
    fixes : str
        What to change, e.g. ``"record fewer seeds (--record-seeds 0,3), --no-record"``
        (``--max-recording-size`` is always offered).

    Raises
    ------
    ConfigError
        For ``field``: over the limit; for ``--rrd``: not enough free space.
    """
    check_recording_limit(args, estimate, field, fixes)
    check_recording_space(args, estimate)


def check_recording_limit(
    args: argparse.Namespace, estimate: Any, field: str, fixes: str
) -> None:
    """The limit part of :func:`check_recording` (same parameters)."""
    if getattr(args, "no_record", False):
        return
    from lcc_synth.recording.size import format_size

    limit = recording_limit(args)
    if estimate.bytes > limit:
        flag = "the limit of --max-recording-size" if getattr(
            args, "max_recording_size", None) is not None else "the default limit"
        raise ConfigError(
            field,
            f"the recording would be about {format_size(estimate.bytes)} ({estimate.what}), "
            f"over {flag} ({format_size(limit)}): {fixes}, or raise --max-recording-size "
            f"(e.g. --max-recording-size {_suggest(estimate.bytes)})",
        )  # fmt: skip


def check_recording_space(args: argparse.Namespace, estimate: Any) -> None:
    """The free-space part of :func:`check_recording`: the directory of the recording
    (``--rrd``, else ``logs/``) can take ``estimate``
    (:func:`lcc_synth.outputs.check_directory`: a :class:`ConfigError` for ``--rrd``)."""
    if getattr(args, "no_record", False):
        return
    from lcc_synth.outputs import check_directory

    path = recording_path(args, "check")
    if path is not None:
        check_directory(path.parent, "--rrd", estimate.bytes, "the recording")


def _suggest(size: float) -> str:
    """A round ``--max-recording-size`` above ``size``: ``3GB``, ``200MB``."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if size >= scale or unit == "MB":
            return f"{int(size * 1.5 // scale) + 1}{unit}"
    return "1GB"  # pragma: no cover
