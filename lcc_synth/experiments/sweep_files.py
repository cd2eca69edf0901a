"""The files of a sweep's results directory, complete or partial, and resuming a sweep.

``lcc-synth sweep`` writes into its results directory (``results/<problem>-<UTC>/``, created
exclusively before the cluster starts, :func:`lcc_synth.outputs.new_directory`):

* ``samples.csv``: the header ``scenario,controller,<samples>``
  (:data:`~lcc_synth.experiments.sweep.SWEEP_SAMPLES`), then one row per scenario and
  controller (the controllers in order, the scenarios ascending). Floats are written in their
  shortest round-trip form, so reading the file back gives the samples bit for bit.
* ``sweep.json``: ``{"results": summary, "sweep": info, "provenance": ...}`` (the ``--json``
  document, :func:`lcc_synth.provenance.provenance`). A **partial** one (a sweep that is
  running, was interrupted or failed) holds what finished only and says so:
  ``"partial": true``, ``"status"`` (``running``, ``interrupted by SIGTERM``, ``failed: ...``),
  ``"done"`` (scenarios finished, and each finished task with its counts: MPC fallbacks,
  simulation and wall times) and ``"resume"`` (what a resumed sweep must match: the problem
  file's SHA-256, count, batch size, seed, controllers, ranges and the digests of the
  controller tables).
* ``distributions.png``: complete sweeps only.

While a sweep runs, :class:`ResultsWriter` writes the partial pair after the first finished
task and then at most every :data:`PARTIAL_EVERY_S` seconds (and never more than a fifth of
the time: the interval grows with the time a write takes), so that even a ``SIGKILL`` loses
little. Every file is written atomically (:func:`lcc_synth.outputs.writing`: a reader, or a
process killed while writing, sees the previous file or the new one, never half of one), and
``samples.csv`` before ``sweep.json``, so that ``sweep.json`` never lists a task whose rows
``samples.csv`` lacks. When the sweep is interrupted or fails, the pair is written once more
with everything that finished.

:func:`read_partial` reads a partial directory back (``lcc-synth sweep --resume DIR``):
:meth:`PartialSweep.check` refuses a sweep that differs from the interrupted one (one line
naming what differs), :meth:`PartialSweep.progress` gives the
:class:`~lcc_synth.experiments.sweep_samples.SweepProgress` that
:func:`~lcc_synth.experiments.sweep.run_sweep` continues from, to the same samples, summary
and counts as an uninterrupted sweep, bit for bit.
"""

from __future__ import annotations

import csv
import itertools
import json
import os
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError, FileError
from lcc_synth.experiments.sweep import (
    SWEEP_SAMPLES,
    SweepProgress,
    SweepResult,
    SweepSpec,
    aggregate,
    chunks,
)

__all__ = [
    "PARTIAL_EVERY_S",
    "SAMPLES",
    "SUMMARY",
    "write_samples",
    "complete_doc",
    "partial_doc",
    "PartialSweep",
    "read_partial",
    "ResultsWriter",
]

#: Seconds between two writes of the partial results while a sweep runs (at least).
PARTIAL_EVERY_S = 2.0
#: File names in the results directory.
SAMPLES, SUMMARY = "samples.csv", "sweep.json"
#: Rows converted to text at a time (bounded memory whatever the count).
_ROWS = 1 << 15
_INT = ("collisions", "aeb_activations")


def write_samples(path: str | Path, done: SweepProgress) -> Path:
    """Write the finished scenarios of ``done`` as ``samples.csv`` at ``path``, atomically
    (over a previous file: the results directory is the run's own).

    Raises
    ------
    FileError
        The file cannot be written (a full disk: the previous file stays).
    """
    from lcc_synth.outputs import writing

    idx = done.indices()
    samples = done.finished_samples()
    keys = list(SWEEP_SAMPLES)
    with writing(path, overwrite=True) as out:
        with open(out.tmp, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(["scenario", "controller", *keys])
            for c in done.names:
                for a in range(0, idx.size, _ROWS):
                    cols = [samples[c][k][a : a + _ROWS].tolist() for k in keys]
                    w.writerows(zip(idx[a : a + _ROWS].tolist(), itertools.repeat(c), *cols))
            fh.flush()
            os.fsync(fh.fileno())
    return out.path


def _provenance(spec: SweepSpec, tables: Mapping[str, Any]) -> dict[str, Any]:
    from lcc_synth.provenance import provenance

    return provenance(
        spec.source, backend=spec.scenario.backend,
        seeds={"seed": spec.seed, "draws": spec.count}, controllers=tables,
    )  # fmt: skip


def complete_doc(spec: SweepSpec, result: SweepResult) -> dict[str, Any]:
    """``sweep.json`` of a complete sweep (and ``--json``): results, sweep, provenance."""
    from lcc_synth.experiments.tables import json_safe

    return json_safe({"results": result.summary, "sweep": result.info,
                      "provenance": _provenance(spec, result.tables)})  # fmt: skip


def partial_doc(spec: SweepSpec, done: SweepProgress, status: str,
                wall_time_s: float = 0.0) -> dict[str, Any]:  # fmt: skip
    """``sweep.json`` of a partial sweep: what finished, marked ``"partial": true``.

    Parameters
    ----------
    spec : SweepSpec
    done : SweepProgress
        What finished.
    status : str
        ``running``, ``interrupted by SIGINT``, ``failed: ...``.
    wall_time_s : float
        Wall time of this run so far (added to that of earlier runs).
    """
    from lcc_synth.experiments.tables import json_safe
    from lcc_synth.provenance import file_sha256

    order = sorted(done.tasks)
    tasks = [{"start": s, "stop": e, **done.tasks[(s, e)]} for s, e in order]
    summary = aggregate(done.finished_samples(), done.fallbacks()) if done.tasks else {}
    total = len(chunks(spec.count, spec.batch_size))
    return json_safe({
        "partial": True,
        "status": status,
        "done": {"scenarios": done.done, "of": spec.count, "tasks": len(tasks),
                 "of_tasks": total, "finished": tasks},
        "results": summary,
        "sweep": {"count": spec.count, "batch_size": spec.batch_size, "tasks": total,
                  "seed": spec.seed, "controllers": list(done.names),
                  "wall_time_s": done.wall_time_s + wall_time_s},
        "resume": {"problem": spec.source, "problem_sha256": file_sha256(spec.source)
                   if spec.source else None, "count": spec.count,
                   "batch_size": spec.batch_size, "seed": spec.seed,
                   "controllers": list(done.names),
                   "ranges": {k: list(v) for k, v in spec.ranges.items()},
                   "tables": dict(done.digests)},
        "provenance": _provenance(spec, done.tables),
    })  # fmt: skip


@dataclass
class PartialSweep:
    """A partial results directory read back (:func:`read_partial`).

    Attributes
    ----------
    directory : Path
    doc : dict
        Its ``sweep.json``.
    """

    directory: Path
    doc: dict[str, Any]

    @property
    def resume(self) -> dict[str, Any]:
        """What the resumed sweep must match (the ``"resume"`` entry)."""
        return self.doc["resume"]

    def overrides(self) -> dict[str, Any]:
        """``count``, ``batch_size``, ``seed``, ``controllers`` of the interrupted sweep: the
        values a resumed sweep takes where its command line gives none."""
        r = self.resume
        return {"count": r["count"], "batch_size": r["batch_size"], "seed": r["seed"],
                "controllers": list(r["controllers"])}  # fmt: skip

    def check(self, spec: SweepSpec, problem: str | Path) -> None:
        """Refuse to continue with a sweep that differs from the interrupted one.

        Raises
        ------
        ConfigError
            For ``--resume``, one line naming what differs: the problem file (SHA-256 of its
            bytes), the count, batch size, seed, controllers or ranges.
        """
        from lcc_synth.provenance import file_sha256

        r, flag = self.resume, "--resume"
        sha = file_sha256(problem)
        if sha != r["problem_sha256"]:
            raise ConfigError(flag, f"the problem file {str(problem)!r} differs from the one "
                              f"the sweep in {self.directory} ran ({r['problem']}): SHA-256 "
                              f"{(sha or 'unreadable')[:12]}... instead of "
                              f"{str(r['problem_sha256'])[:12]}...")  # fmt: skip
        ranges = {k: list(v) for k, v in spec.ranges.items()}
        for what, now, then in (
            ("count", spec.count, r["count"]),
            ("batch size", spec.batch_size, r["batch_size"]),
            ("seed", spec.seed, r["seed"]),
            ("controllers", list(spec.controllers), list(r["controllers"])),
            ("ranges", ranges, r["ranges"]),
        ):
            if now != then:
                verb = "differ" if what.endswith("s") else "differs"
                raise ConfigError(flag, f"{what} {verb} from the interrupted sweep's in "
                                  f"{self.directory}: {_show(now)} instead of {_show(then)}")

    def progress(self, spec: SweepSpec) -> SweepProgress:
        """The finished tasks and their samples (read from ``samples.csv``), to continue.

        Raises
        ------
        ConfigError
            For ``--resume``: ``samples.csv`` missing, unreadable or without the rows of a
            task ``sweep.json`` lists.
        """
        done = SweepProgress.new(spec)
        done.digests = dict(self.resume.get("tables") or {})
        done.wall_time_s = float(self.doc.get("sweep", {}).get("wall_time_s") or 0.0)
        tasks = {}
        for t in self.doc["done"]["finished"]:
            tasks[(int(t["start"]), int(t["stop"]))] = {
                "fallbacks": {c: int(t["fallbacks"][c]) for c in done.names},
                "sim_time": {c: float(t["sim_time"][c]) for c in done.names},
                "wall_time": float(t["wall_time"]),
            }
        valid = set(chunks(spec.count, spec.batch_size))
        if not set(tasks) <= valid:
            raise ConfigError("--resume", f"{self.directory / SUMMARY} lists tasks that are not "
                              "tasks of this sweep")  # fmt: skip
        want = np.zeros(spec.count, dtype=bool)
        for s, e in tasks:
            want[s:e] = True
        _read_samples(self.directory / SAMPLES, done, want)
        done.tasks = tasks
        return done


def _show(value: Any) -> str:
    if isinstance(value, list):
        return ",".join(map(str, value)) or "none"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {v}" for k, v in value.items()) + "}"
    return str(value)


def _read_samples(path: Path, done: SweepProgress, want: np.ndarray) -> None:
    """Fill ``done.samples`` with the rows of ``path`` whose scenario ``want`` selects; every
    one of them must be there for every controller."""
    keys = list(SWEEP_SAMPLES)
    seen = {c: np.zeros(want.size, dtype=bool) for c in done.names}
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = csv.reader(fh)
            if next(rows, None) != ["scenario", "controller", *keys]:
                raise ConfigError("--resume", f"{path} is not a sweep's samples.csv (header)")
            for n, row in enumerate(rows, start=2):
                try:
                    i, c = int(row[0]), row[1]
                    if c not in seen or not 0 <= i < want.size or not want[i]:
                        continue
                    for k, text in zip(keys, row[2:], strict=True):
                        done.samples[c][k][i] = int(text) if k in _INT else float(text)
                except (ValueError, IndexError):
                    raise ConfigError("--resume", f"{path}, line {n}: not a row of samples "
                                      "(scenario, controller, numbers)") from None  # fmt: skip
                seen[c][i] = True
    except OSError as err:
        raise ConfigError("--resume", f"cannot read {path}: {err.strerror or err}") from None
    for c in done.names:
        missing = np.flatnonzero(want & ~seen[c])
        if missing.size:
            raise ConfigError("--resume", f"{path} lacks scenario {missing[0]} of {c} (and "
                              f"{missing.size - 1} more) that {SUMMARY} lists as finished")


def read_partial(directory: str | Path) -> PartialSweep:
    """Read the partial results directory ``directory`` (its ``sweep.json``).

    Raises
    ------
    ConfigError
        For ``--resume``: not a directory, no readable ``sweep.json``, or a complete sweep.
    """
    directory = Path(directory)
    path = directory / SUMMARY
    if not directory.is_dir():
        raise ConfigError("--resume", f"{str(directory)!r} is not a directory")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise ConfigError("--resume", f"cannot read {path}: {err.strerror or err} (the "
                          "results directory of an interrupted sweep holds it)") from None
    except ValueError as err:
        raise ConfigError("--resume", f"{path} is not JSON: {err}") from None
    if not isinstance(doc, dict) or "results" not in doc:
        raise ConfigError("--resume", f"{path} is not a sweep's sweep.json")
    if not doc.get("partial"):
        raise ConfigError("--resume", f"the sweep in {directory} is complete: nothing to resume")
    if not isinstance(doc.get("resume"), dict) or not isinstance(doc.get("done"), dict):
        raise ConfigError("--resume", f"{path} does not say what finished (written by another "
                          "version?)")  # fmt: skip
    return PartialSweep(directory, doc)


class ResultsWriter:
    """Writes a sweep's results directory: the partial files while it runs
    (:meth:`on_task`, throttled) and after it stopped (:meth:`partial`), the complete ones at
    the end (:meth:`complete`).

    Parameters
    ----------
    directory : Path
        The results directory (the run's own: files are replaced atomically).
    spec : SweepSpec
    every : float
        Seconds between two partial writes while the sweep runs, at least (and at least four
        times the duration of the previous write).
    """

    def __init__(self, directory: str | Path, spec: SweepSpec, every: float = PARTIAL_EVERY_S):
        self.directory = Path(directory)
        self.spec = spec
        self.every = float(every)
        self.t0 = time.perf_counter()
        self._next = 0.0  # the first finished task is written at once
        self._written = -1  # scenarios in the partial files on disk (-1: none written)
        self.warned = False

    def on_task(self, done: SweepProgress) -> None:
        """After a finished task: write the partial files if the last write is old enough.
        A write that fails (a full disk) is one warning line; the sweep goes on."""
        now = time.perf_counter()
        if now < self._next or done.finished:
            return
        self.partial(done, "running", quiet=True)
        took = time.perf_counter() - now
        self._next = time.perf_counter() + max(self.every, 4 * took)

    def partial(self, done: SweepProgress, status: str, quiet: bool = False) -> bool:
        """Write ``samples.csv`` and a partial ``sweep.json`` with what finished (nothing if
        no task finished); returns whether the files on disk now hold it. A failure is one
        line on stderr (once, with ``quiet``)."""
        if not done.tasks:
            return False
        try:
            write_samples(self.directory / SAMPLES, done)
            doc = partial_doc(self.spec, done, status, time.perf_counter() - self.t0)
            _write_json(self.directory / SUMMARY, doc)
        except FileError as err:
            if not (quiet and self.warned):
                print(f"lcc-synth sweep: warning: the partial results were not written: {err}",
                      file=sys.stderr, flush=True)  # fmt: skip
            self.warned = True
            return False
        self._written = done.done
        return True

    @property
    def written(self) -> int:
        """Scenarios in the partial files on disk (-1: none written)."""
        return self._written

    def complete(self, done: SweepProgress, doc: Mapping[str, Any]) -> list[Path]:
        """Write the complete ``samples.csv`` (of ``done``: every scenario finished) and
        ``sweep.json`` (``doc``, :func:`complete_doc`) over the partial ones; returns the
        paths.

        Raises
        ------
        FileError
            A file that cannot be written (the partial files stay as they were).
        """
        paths = [write_samples(self.directory / SAMPLES, done)]
        paths.append(_write_json(self.directory / SUMMARY, doc))
        return paths


def _write_json(path: Path, doc: Mapping[str, Any]) -> Path:
    from lcc_synth.outputs import write_text

    return write_text(path, json.dumps(doc, indent=2) + "\n", overwrite=True)
