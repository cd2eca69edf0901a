"""What a sweep measures per scenario, its summary, and what it keeps of an unfinished run.

:data:`SWEEP_METRICS` and :data:`SWEEP_SAMPLES` are a scenario's numbers (``samples.csv``'s
columns), :func:`aggregate` their summary per controller, and :class:`SweepProgress` the
finished part of a sweep: the samples of its finished tasks and their counts, which
:func:`~lcc_synth.experiments.sweep.run_sweep` fills (and continues from, ``--resume``) and
:mod:`lcc_synth.experiments.sweep_files` writes and reads. All are also importable from
:mod:`lcc_synth.experiments.sweep`.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.metrics import UNSAFE_MIN_SPACING, UNSAFE_MIN_TTC, WAVE_METRICS

__all__ = ["SWEEP_METRICS", "SWEEP_SAMPLES", "SWEEP_COUNTS", "aggregate", "table_digest",
           "SweepProgress"]  # fmt: skip

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
    outside emergency braking), ``unsafe_scenarios`` (runs with emergency braking, a spacing
    or a time to collision under the thresholds of
    :func:`lcc_synth.metrics.unsafe_reasons`, collisions included), ``fallbacks``
    (MPC fallback steps) and ``scenarios``."""
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
        with np.errstate(invalid="ignore"):  # NaN (a head's spacing) judges nothing
            unsafe = ((aeb > 0) | (np.asarray(per["min_spacing"], dtype=float) < UNSAFE_MIN_SPACING)
                      | (np.asarray(per["min_ttc"], dtype=float) < UNSAFE_MIN_TTC))  # fmt: skip
        entry["unsafe_scenarios"] = int(np.count_nonzero(unsafe))
        entry["fallbacks"] = int(fallbacks.get(name, 0))
        entry["scenarios"] = int(coll.size)
        out[name] = entry
    return out


def table_digest(table: Mapping[str, Any]) -> str:
    """SHA-256 of a controller's plain table, the results files' form (keys sorted, floats
    exact; an ``h2`` controller as its synthesised static table), to check that a resumed
    sweep runs the same controllers (e.g. the same synthesised ``h2`` gains) as the
    interrupted one."""
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
        :func:`~lcc_synth.experiments.sweep.run_sweep` has prepared them).
    tables : dict
        The controller tables (set by :func:`~lcc_synth.experiments.sweep.run_sweep`; empty before).
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
    def new(cls, spec: Any) -> SweepProgress:
        """Nothing finished yet."""
        names = list(spec.controllers)
        samples = {c: {k: np.full(spec.count, np.nan) for k in SWEEP_SAMPLES} for c in names}
        return cls(spec.count, spec.batch_size, names, samples)

    def check(self, spec: Any) -> None:
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
        """Keep a finished task's result (:func:`~lcc_synth.experiments.sweep.run_chunk`);
        the task counts as finished only once everything of it is stored."""
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
