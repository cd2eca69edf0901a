"""The problem file of ``lcc-synth simulate``: one scenario, its controllers and metrics
(format: ``problems/README.md``)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from lcc_synth.controllers.base import Controller
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.controller_tables import controller_from_table
from lcc_synth.experiments.h2_tables import synthesize_h2_tables
from lcc_synth.metrics import MetricsConfig, metrics_from
from lcc_synth.models.feedback import Gains
from lcc_synth.models.records import Record, ValueEq, system_tables, toml_text
from lcc_synth.problem import Problem, System, load_problem, system_from
from lcc_synth.schema import declared
from lcc_synth.simulation.checks import check_start
from lcc_synth.simulation.scenario import Scenario
from lcc_synth.simulation.scenario_file import scenario_from
from lcc_synth.simulation.timestep import check_time_step

__all__ = ["SimulationSpec", "check_starts", "controller_gain", "controllers_from",
           "drop_failed_fallbacks", "fallback_target", "load_spec", "resolve_fallbacks"]


@dataclass(frozen=True, eq=False, repr=False)
class SimulationSpec(ValueEq, Record):
    """Everything ``lcc-synth simulate`` needs from a problem file. Equal (``==``) to another
    when every field is (:func:`~lcc_synth.models.records.same`: the controllers by what
    defines them, their ``as_dict()``)."""

    name: str
    system: System
    scenario: Scenario
    controllers: dict[str, Controller]
    metrics: MetricsConfig
    source: str
    #: controllers that could not be built (``{name: why}``, e.g. a failed synthesis): the
    #: others run, and ``simulate`` reports these and exits 1
    failed: dict[str, str] = field(default_factory=dict)
    #: the problem file's ``description`` (free text for the recording's context document;
    #: not compared: the same run with other words is the same run)
    description: str = field(default="", compare=False)

    def toml_tables(self) -> dict[str, Any]:
        """``name``, ``[hdv]``, ``[system]``, ``[scenario]``, ``[controllers.*]`` and
        ``[metrics]``: the tables :func:`load_spec` reads back into equal objects."""
        return {
            "name": self.name,
            **system_tables(self.system),
            "scenario": self.scenario.toml_table(),
            "controllers": {k: getattr(c, "source_table", None) or c.toml_table()
                            for k, c in self.controllers.items()},  # fmt: skip
            "metrics": self.metrics.toml_table(),
        }

    def to_toml(self) -> str:
        """This spec as a problem file (:meth:`toml_tables`)."""
        return toml_text(self.toml_tables())


def fallback_target(
    tables: Mapping[str, Any], name: str, source: str | None = None
) -> str | None:
    """The controller that MPC ``name`` falls back to (``fallback = "NAME"``), ``None`` when
    ``name`` is no MPC or has no such key.

    Raises
    ------
    ConfigError
        ``controllers.NAME.fallback`` is not the name of another controller of ``tables``.
    """
    table = tables.get(name)
    if not isinstance(table, Mapping) or table.get("type") != "mpc" or (
        table.get("fallback") is None
    ):
        return None
    try:
        target = declared("controllers.NAME:mpc").get(table, "fallback", f"controllers.{name}")
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None
    if target not in tables or target == name:
        others = [n for n in tables if n != name]
        raise ConfigError(f"controllers.{name}.fallback", f"must name another controller of "
                          f"the file {others}, got {target!r}", source)  # fmt: skip
    return target


def check_starts(
    tables: Mapping[str, Any], scenario: Scenario, where: str = ""
) -> None:
    """Every controller's ``start`` (its switch-on time) must come before the last sample of
    ``scenario`` (:func:`~lcc_synth.simulation.checks.check_start`), else it would never
    drive: a ConfigError naming ``controllers.NAME.start`` (``where``, e.g. ``" in scenario
    X"``, says which run). Tables of an unknown type are left to the loaders' own error."""
    from lcc_synth.schema import TABLES

    for name, table in tables.items():
        if not isinstance(table, Mapping) or table.get("start") is None:
            continue
        T = TABLES.get(f"controllers.NAME:{table.get('type')}")
        if T is None:
            continue
        field = f"controllers.{name}"
        start = T.get(table, "start", field)
        check_start(f"{field}.start", start, scenario, f"controller {name!r}{where}")


def _nonzero(gains: Mapping[str, Any]) -> dict[str, Any]:
    """The non-zero gains of a single-CAV table ``{state: g}`` or a platoon table
    ``{u_i: {state: g}}`` (one row per CAV, every row kept)."""
    return {k: _nonzero(v) if isinstance(v, Mapping) else float(v) for k, v in gains.items()
            if isinstance(v, Mapping) or float(v) != 0.0}  # fmt: skip


def controller_gain(
    name: str, table: Mapping[str, Any], gains: Mapping[str, Gains]
) -> Gains | None:  # fmt: skip
    """The gain object that controller ``name`` is built with, from ``gains`` (``{name:
    Gains}``: the gains synthesised for the ``h2`` controllers,
    :attr:`~lcc_synth.synthesis.report.SynthesisReport.gain`), ``None`` if none.

    ``table`` is the controller's table as the file states it: an ``h2`` table is built from
    its own synthesised gain, an MPC whose ``fallback = "NAME"`` names a synthesised controller
    from NAME's gain (:func:`lcc_synth.experiments.controller_tables.controller_from_table`'s
    ``gains``), the same object: no table of the gain is written and read back.
    """
    if not isinstance(table, Mapping):
        return None
    if table.get("type") == "h2":
        return gains.get(name)
    if table.get("type") == "mpc" and isinstance(table.get("fallback"), str):
        return gains.get(table["fallback"])
    return None


def resolve_fallbacks(
    tables: Mapping[str, Mapping[str, Any]], system: System, source: str | None = None
) -> dict[str, dict[str, Any]]:
    """Controller tables with every MPC's ``fallback = "NAME"`` replaced by NAME's static gain.

    NAME is a ``static`` controller of the same file, or an ``h2`` one once synthesised (``run``
    and ``sweep`` replace it by a static table first). The gain becomes plain data in the MPC's
    table (``{"controller", "kind", "semantics", "gains"}``, zero gains dropped; a platoon or
    ring: the platoon form ``{u_i: {state: gain}}`` that :mod:`lcc_synth.mpc.build` reads): the
    form written to result files. :mod:`lcc_synth.mpc.build` makes it
    the MPC's static fallback, applied to the MPC's own error state when the QP fails and no
    previous plan is left. (``run``, ``simulate`` and the workers of ``sweep`` build an MPC
    falling back to a synthesised gain from the gain object itself, :func:`controller_gain`;
    this table is then only checked and reported.)

    Raises
    ------
    ConfigError
        ``controllers.MPC.fallback`` names no controller, or one without a static gain, or a
        gain for another kind of string, or is given with ``fallback_gains_file``.
    """
    out = {name: dict(t) for name, t in tables.items()}
    for name, table in out.items():
        target = fallback_target(tables, name, source)
        if target is None:
            continue
        field = f"controllers.{name}.fallback"
        if "fallback_gains_file" in table:
            raise ConfigError(field, "give fallback or fallback_gains_file, not both", source)
        gain = tables[target]
        if gain.get("type") != "static" or not isinstance(gain.get("gains"), Mapping):
            raise ConfigError(field, f"{target!r} is a {gain.get('type')!r} controller; the "
                              "fallback must be a static or h2 controller", source)  # fmt: skip
        kind = gain.get("kind", system.kind)
        if kind != system.kind:
            raise ConfigError(field, f"{target!r} is a {kind} gain; the MPC controls "
                              f"{system.kind}", source)  # fmt: skip
        table["fallback"] = {
            "controller": target,
            "kind": kind,
            "semantics": gain.get("semantics", "added"),
            "gains": _nonzero(gain["gains"]),
        }
    return out


def drop_failed_fallbacks(
    tables: Mapping[str, Mapping[str, Any]], failures: dict[str, str],
    source: str | None = None,
) -> dict[str, dict[str, Any]]:  # fmt: skip
    """``tables`` without the MPCs whose ``fallback = "NAME"`` is a controller of
    ``failures`` (it could not be designed): each is added to ``failures`` in turn."""
    out = {k: dict(t) for k, t in tables.items()}
    for name in list(out):
        target = fallback_target({**out, **dict.fromkeys(failures, {})}, name, source)
        if target is not None and target in failures:
            failures[name] = f"its fallback {target!r} could not be designed"
            del out[name]
    return out


def controllers_from(
    data: Mapping[str, Any], system: System, source: str | None = None, label: str = "problem",
    failures: dict[str, str] | None = None, scenario: Scenario | None = None,
):  # fmt: skip
    """Every ``[controllers.NAME]`` table, built in file order: ``type = "h2"`` synthesised
    for ``system`` first (:func:`lcc_synth.experiments.h2_tables.synthesize_h2_tables`, the
    code path of ``run``; problem names ``LABEL_NAME``), then the MPC fallbacks resolved (and
    checked, :func:`resolve_fallbacks`). A synthesised controller, and an MPC falling back to
    one, are built from the synthesised gain object and the file's table
    (:func:`controller_gain`). A synthesised controller, and an MPC with ``fallback = "NAME"``,
    keep the table the file states as ``source_table`` (what :meth:`SimulationSpec.toml_tables`
    writes back).

    With ``failures`` (a dict), a controller whose synthesis fails, and an MPC that falls back
    to it, are left out and recorded there (``{name: why}``); without it the error propagates.
    ``scenario``: the problem's scenario, on which a ``deep_lcc`` controller collects its data.
    """
    tables = declared("").get(data, "controllers", "")
    if not tables:
        raise ConfigError("controllers", "needs at least one [controllers.NAME] table")
    if all(isinstance(t, Mapping) for t in tables.values()):
        given = tables
        tables, designs = synthesize_h2_tables(tables, system, source, label, failures)
        if failures:
            tables = drop_failed_fallbacks(tables, failures, source)
        tables = resolve_fallbacks(tables, system, source)
        synthesised = {name: rep.gain for name, rep in designs.items()}
        built = {}
        for name, t in tables.items():
            gain = controller_gain(name, given[name], synthesised)
            built[name] = controller_from_table(name, t if gain is None else given[name], system,
                                                source, scenario, gain)  # fmt: skip
        for name in designs:  # written back as stated (a reload synthesises the same gain)
            built[name].source_table = dict(given[name])
        for name, t in given.items():  # an MPC's fallback = "NAME" is written back as stated
            if name in built and t.get("type") == "mpc" and isinstance(t.get("fallback"), str):
                built[name].source_table = {**built[name].toml_table(), "fallback": t["fallback"]}
        return built
    return {name: controller_from_table(name, t, system, source, scenario)
            for name, t in tables.items()}  # fmt: skip


def load_spec(
    path: str | Path | Problem, seeds: int | None = None, keep_going: bool = False
) -> SimulationSpec:
    """Read a problem file for simulation; ``seeds`` overrides ``[scenario].batch``.

    With ``keep_going``, a controller that cannot be designed (a failed synthesis) is left out
    and named in :attr:`SimulationSpec.failed`, so that the others still run (``simulate``);
    without it the :class:`~lcc_synth.synthesis.h2.SynthesisError` propagates."""
    problem = path if isinstance(path, Problem) else load_problem(path)
    source = str(problem.path)
    try:
        system = system_from(problem.data, source)
        scenario = scenario_from(problem.data, system, problem.path.parent)
        if seeds is not None:
            if seeds < 1:
                raise ConfigError("--seeds", f"must be >= 1, got {seeds}")
            scenario = replace(scenario, batch=int(seeds))
        check_starts(declared("").get(problem.data, "controllers", ""), scenario)  # no design yet
        failed: dict[str, str] | None = {} if keep_going else None
        controllers = controllers_from(problem.data, system, source, problem.name, failed,
                                       scenario)  # fmt: skip
        check_time_step(scenario, controllers)
        metrics = metrics_from(problem.data, system, controllers, scenario)
        description = problem.data.get("description", "")
        return SimulationSpec(problem.name, system, scenario, controllers, metrics, source,
                              dict(failed or {}), description if isinstance(description, str)
                              else "")  # fmt: skip
    except ConfigError as err:
        raise err.with_source(source) if not err.source else err from None
