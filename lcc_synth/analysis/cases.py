"""Problem-file tables of the ``analyze`` command: ``[analysis]`` options and ``[cases.NAME]``.

``[cases.NAME]`` names a static gain of eq. (23) to analyse (Table I's cases A-D in
``problems/paper_fig9_cases.toml``); ``[analysis]`` chooses the observability outputs, the
peak-search method of :func:`lcc_synth.analysis.string_stability.string_stability` and the plotted
frequency grid (Fig. 9). Errors name ``cases.NAME.<field>`` / ``analysis.<key>`` and the file.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.models.linear import LCCModel
from lcc_synth.models.platoon import PLATOON_KINDS, PlatoonModel
from lcc_synth.models.records import Record

__all__ = ["AnalysisOptions", "analysis_options_from", "GainCase", "cases_from"]


@dataclass(frozen=True, repr=False)
class AnalysisOptions(Record):
    """The ``[analysis]`` table: observability outputs, peak-search method, plot grid."""

    outputs: tuple[str, ...] | None = None
    method: str = "grid"
    omega_min: float = 1e-3
    omega_max: float = 10.0
    points: int = 400

    def toml_table(self) -> dict:
        """The ``[analysis]`` table (what :func:`analysis_options_from` reads)."""
        outputs = None if self.outputs is None else list(self.outputs)
        return {"outputs": outputs, "method": self.method, "omega_min": self.omega_min,
                "omega_max": self.omega_max, "points": self.points}  # fmt: skip

    def omega(self) -> np.ndarray:
        """Logarithmic frequency grid for plotted responses (Fig. 9)."""
        return np.logspace(np.log10(self.omega_min), np.log10(self.omega_max), self.points)


def analysis_options_from(data: Mapping, source: str | None = None) -> AnalysisOptions:
    """Parse the optional ``[analysis]`` table (see :func:`cases_from`)."""
    from lcc_synth.schema import declared

    try:
        A = declared("analysis")
        t = declared("").get(data, "analysis", "")
        A.check(t, "analysis")
        outputs = None
        raw = A.raw(t, "outputs")
        if raw is not None:
            if not isinstance(raw, list) or not raw or not all(isinstance(x, str) for x in raw):
                raise ConfigError(
                    "analysis.outputs", f"must be a non-empty list of state names, got {raw!r}"
                )
            outputs = tuple(raw)
        method = A.get(t, "method", "analysis")
        lo = A.get(t, "omega_min", "analysis")
        hi = A.get(t, "omega_max", "analysis", lo=lo)
        points = A.get(t, "points", "analysis")
        return AnalysisOptions(outputs, method, lo, hi, points)
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None


@dataclass(frozen=True, repr=False)
class GainCase(Record):
    """One ``[cases.NAME]`` table: a named static gain (eq. 23) to analyse."""

    name: str
    gains: Gains
    label: str
    table: dict | None = None  # platoon / ring: the per-CAV gains table as read

    def toml_table(self) -> dict:
        """The ``[cases.NAME]`` table (what :func:`cases_from` reads)."""
        gains = dict(self.gains.gains) if self.table is None else self.table
        return {"semantics": self.gains.semantics, "gains": gains, "label": self.label}


def cases_from(
    data: Mapping, model: LCCModel | PlatoonModel, source: str | None = None
) -> dict[str, GainCase]:
    """Parse ``[cases.NAME]`` tables into :class:`GainCase` (in file order).

    Each table: ``semantics = "added" | "replace"`` (default ``"added"``), ``gains = { s_-2 =
    1.0, v_-2 = -1.0, ... }`` (state name -> gain, missing states 0) and an optional ``label``.
    On a platoon or ring (:class:`~lcc_synth.models.platoon.PlatoonModel`) ``gains`` holds one
    table per CAV input, ``[cases.NAME.gains.u_3]`` with ``s_i`` / ``v_i`` gains
    (:meth:`~lcc_synth.models.feedback.Gains.from_table`). Errors name
    ``cases.NAME.<field>`` and the file.
    """
    from lcc_synth.problem import warn_large_gains
    from lcc_synth.schema import declared

    out = {}
    try:
        C = declared("cases.NAME")
        cases = declared("").get(data, "cases", "")
        for name, table in cases.items():
            field = f"cases.{name}"
            if not isinstance(table, dict):
                raise ConfigError(field, f"must be a table, got {table!r}")
            C.check(table, field)
            semantics = C.get(table, "semantics", field)
            raw = C.get(table, "gains", field)
            warn_large_gains(raw, f"{field}.gains")
            label = C.get(table, "label", field, default=name)
            if model.kind in PLATOON_KINDS:  # the platoon vocabulary: a table per CAV input
                for u, row in raw.items():
                    if isinstance(row, dict):
                        warn_large_gains(row, f"{field}.gains.{u}")
                pg = Gains.from_table(raw, model, semantics, field=f"{field}.gains")
                out[name] = GainCase(name, pg, label, pg.as_table())
                continue
            try:
                gains = Gains.named(raw, semantics)
                gains.check(model)
            except ConfigError as err:
                raise ConfigError(f"{field}.{err.field}", err.message) from None
            out[name] = GainCase(name, gains, label)
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None
    return out
