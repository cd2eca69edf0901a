"""Comparison suites: several scenarios x several controllers -> one metrics table.

A *suite* problem file (``lcc-synth run``, e.g. ``problems/showcase.toml``) describes

* ``[hdv]``: the nominal HDV model shared by everything;
* ``[layouts.NAME]``: strings of vehicles, each a ``[system]`` table (``kind, m, n, v_star``).
  Controllers are built -- and H2 gains synthesised -- **per layout**: a gain designed for one
  string cannot drive another (its state names and its closed loop belong to one ``m, n``);
* ``[scenarios.NAME]``: ``layout = "..."``, optional ``title``, every key of a ``[scenario]``
  table of ``lcc-synth simulate`` (``duration``, ``perturbations``, ``heterogeneity``, ``delay``,
  ``v2v``...) and an optional ``metrics`` table overriding the file's ``[metrics]``;
* ``[controllers.NAME]``: the controller tables of ``lcc-synth simulate`` (``type = "hdv" |
  "static" | "gains_file" | "mpc"``), plus ``type = "h2"``: a gain synthesised for each layout
  by :mod:`lcc_synth.synthesis`, whose other keys are those of the ``[synthesis]`` table of
  ``lcc-synth synthesize`` (``design``, ``pattern``, ``weights``...) plus the optional
  ``sample_time``, ``equilibrium``, ``equilibrium_tau`` and ``measurement_filter`` of the
  static controller.
  ``[controllers.NAME.layouts.LAYOUT]`` overrides keys for one layout (merged recursively),
  e.g. the paper's gains, which differ between the Table II string and the Section V-A string;
  ``only_layouts = [...]`` names the layouts a controller is for (absent: every layout; on
  the others it has no row, :func:`applies`), ``only_scenarios = [...]`` the scenarios (absent:
  every scenario of those layouts; it is built only for the layouts of the selected ones).

A layout may be a mixed platoon or a ring (``kind = "platoon" | "ring"``, ``size``, ``cavs``,
``circumference``, ``[layouts.NAME.hdv_values]``): its ``h2`` controllers are platoon designs
(:mod:`lcc_synth.synthesis.design`, a gain row per CAV), its MPCs the joint MPC of
every CAV, an MPC's ``fallback`` the platoon gain table.

Every controller runs on every scenario with the same random draws (``simulate(..., draws)``);
the metrics are those of :func:`lcc_synth.metrics.summary` (:data:`SUITE_METRICS`). A
``deep_lcc`` controller collects its data on each scenario it drives (its HDVs, delays, noise;
:mod:`lcc_synth.experiments.deeplcc_runs`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.controllers.base import Controller
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.controller_tables import CONTROLLER_TYPES, controller_from_table
from lcc_synth.experiments.h2_tables import synthesize_table
from lcc_synth.experiments.suite_tables import applies, check_suite_controllers, controller_table
from lcc_synth.experiments.tables import SUITE_METRICS, rank_failed_last
from lcc_synth.interrupts import checkpoint
from lcc_synth.metrics import MetricsConfig, metrics_from
from lcc_synth.models.feedback import Gains
from lcc_synth.models.records import Record, system_tables, toml_text
from lcc_synth.problem import Problem, System, check_top_level, load_problem, system_from
from lcc_synth.resources import progress_bar
from lcc_synth.schema import declared
from lcc_synth.simulation.results import SimResult
from lcc_synth.simulation.scenario import Scenario
from lcc_synth.simulation.scenario_file import scenario_from

__all__ = [
    "SUITE_TYPES", "SuiteScenario", "Suite", "SuiteRun", "load_suite", "select_names",
    "controller_table", "synthesize_table", "applies", "layout_controllers",
    "prepare_controllers", "fallback_names", "build_controllers", "metrics_row", "run_suite",
    "gamma_curves", "gamma_settings",
]  # fmt: skip

#: Controller types of a suite file: those of ``lcc-synth simulate`` plus synthesised ``h2``.
SUITE_TYPES = (*CONTROLLER_TYPES, "h2")

# --------------------------------------------------------------------------------------------
# Suite file
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, repr=False)
class SuiteScenario(Record):
    """One scenario of a suite: its layout, simulator scenario and metric settings."""

    name: str
    layout: str
    scenario: Scenario
    metrics: MetricsConfig
    title: str = ""


@dataclass(frozen=True, repr=False)
class Suite(Record):
    """A parsed suite problem file (see the module docstring)."""

    name: str
    description: str
    layouts: dict[str, System]
    scenarios: dict[str, SuiteScenario]
    controllers: dict[str, dict[str, Any]]
    source: str | None = None
    #: controllers left out by ``--controllers`` that a selected MPC falls back to
    #: (``fallback = "NAME"``): designed for it, not run (:func:`fallback_names`)
    fallbacks: dict[str, dict[str, Any]] = field(default_factory=dict)

    def toml_tables(self) -> dict[str, Any]:
        """``name``, ``description``, ``[hdv]``, ``[layouts.*]``, ``[scenarios.*]`` (each with
        its whole ``metrics`` table) and the controller tables: what :func:`load_suite` reads
        back into an equal suite."""
        hdv = next(iter(self.layouts.values())).hdv.toml_table()
        return {
            "name": self.name,
            "description": self.description,
            "hdv": hdv,
            "layouts": {k: system_tables(s)["system"] for k, s in self.layouts.items()},
            "scenarios": {
                k: {"layout": s.layout, "title": s.title, **s.scenario.toml_table(),
                    "metrics": s.metrics.toml_table()}
                for k, s in self.scenarios.items()
            },  # fmt: skip
            "controllers": {k: dict(t) for k, t in {**self.controllers, **self.fallbacks}.items()},
        }

    def to_toml(self) -> str:
        """This suite as a problem file (:meth:`toml_tables`)."""
        return toml_text(self.toml_tables())

    def layouts_used(self) -> list[str]:
        """Layouts of the selected scenarios, in file order."""
        used = {s.layout for s in self.scenarios.values()}
        return [name for name in self.layouts if name in used]


def _check_only_scenarios(only, layouts, scenarios: Mapping[str, Any], f: str):
    """``only_scenarios``: a non-empty list of the file's scenario names, each on a layout of
    ``only_layouts`` (when given). Returns the layouts of those scenarios (or None)."""
    if only is None:
        return None
    if not isinstance(only, list) or not only:
        raise ConfigError(f"{f}.only_scenarios", f"must be a non-empty list of scenario names "
                          f"{list(scenarios)}, got {only!r}")  # fmt: skip
    for sname in only:
        if not isinstance(sname, str) or sname not in scenarios:
            raise ConfigError(f"{f}.only_scenarios", f"unknown scenario {sname!r}; "
                              f"available: {list(scenarios)}")  # fmt: skip
        lname = scenarios[sname].get("layout") if isinstance(scenarios[sname], dict) else None
        if layouts is not None and lname not in layouts:
            raise ConfigError(f"{f}.only_scenarios", f"scenario {sname!r} is on layout "
                              f"{lname!r}, which only_layouts {layouts} leaves out")  # fmt: skip
    named = [scenarios[s].get("layout") if isinstance(scenarios[s], dict) else None for s in only]
    return list(dict.fromkeys(lname for lname in named if isinstance(lname, str)))


def select_names(available: Sequence[str], wanted: Sequence[str] | None, field: str) -> list[str]:
    """``wanted`` (in the file's order) after checking every name exists; ``None`` = all."""
    if wanted is None:
        return list(available)
    wanted = [w.strip() for w in wanted if w.strip()]
    if not wanted:
        raise ConfigError(field, f"must name at least one of {list(available)}")
    unknown = [w for w in wanted if w not in available]
    if unknown:
        raise ConfigError(field, f"unknown name(s) {unknown}; available: {list(available)}")
    return [a for a in available if a in wanted]


def fallback_names(tables: Mapping[str, Any], names: Sequence[str]) -> list[str]:
    """The controllers that the MPCs among ``names`` fall back to (``fallback = "NAME"``) but
    that ``names`` leaves out: they are designed for the MPC, not run.

    Raises
    ------
    ConfigError
        ``controllers.MPC.fallback`` is not the name of another controller of the file.
    """
    from lcc_synth.experiments.spec import fallback_target

    out: list[str] = []
    for name in names:
        target = fallback_target(tables, name)
        if target is not None and target not in names and target not in out:
            out.append(target)
    return out


def load_suite(
    path: str | Path | Problem,
    scenarios: Sequence[str] | None = None,
    controllers: Sequence[str] | None = None,
) -> Suite:
    """Read a suite problem file, keeping only the named scenarios / controllers.

    Every scenario of the file is read and checked, selected or not (a value that only a
    scenario left out by ``--scenarios`` would use is still an error), and so are the
    controllers' ``start`` times in every scenario they drive and the gains files they name,
    all before any design or simulation.

    Raises
    ------
    ConfigError
        A bad table, an unknown layout, scenario or controller name.
    """
    problem = path if isinstance(path, Problem) else load_problem(path)
    src = str(problem.path)
    try:
        data = problem.data
        check_top_level(data)
        top = declared("")
        hdv_table = top.get(data, "hdv", "")
        layouts_t = top.get(data, "layouts", "")
        if not layouts_t:
            raise ConfigError("layouts", "needs at least one [layouts.NAME] table")
        layouts: dict[str, System] = {}
        for lname, table in layouts_t.items():
            if not isinstance(table, dict):
                raise ConfigError(f"layouts.{lname}", "must be a table (kind, m, n, v_star)")
            try:
                layouts[lname] = system_from({"hdv": hdv_table, "system": table})
            except ConfigError as err:
                raise ConfigError(
                    err.field.replace("system", f"layouts.{lname}", 1), err.message
                ) from None

        scen_t = top.get(data, "scenarios", "")
        S = declared("scenarios.NAME")
        if not scen_t:
            raise ConfigError("scenarios", "needs at least one [scenarios.NAME] table")
        chosen = select_names(list(scen_t), scenarios, "--scenarios")
        every: dict[str, SuiteScenario] = {}  # selected or not: every scenario is checked
        for sname in scen_t:
            f = f"scenarios.{sname}"
            table = scen_t[sname]
            if not isinstance(table, dict):
                raise ConfigError(f, "must be a table")
            lname = S.get(table, "layout", f, choices=list(layouts))
            title = S.get(table, "title", f)
            sc_table = {k: v for k, v in table.items() if k not in S.names}
            system = layouts[lname]
            try:
                sc = scenario_from({"scenario": sc_table}, system, problem.path.parent)
            except ConfigError as err:
                raise ConfigError(err.field.replace("scenario", f, 1), err.message) from None
            mt = dict(top.get(data, "metrics", ""))
            mt.update(S.get(table, "metrics", f))
            try:
                mcfg = metrics_from({"metrics": mt}, system, scenario=sc)
            except ConfigError as err:
                fld = err.field.replace("metrics", f"{f}.metrics", 1)
                raise ConfigError(fld, err.message) from None
            if mcfg.baseline is not None:
                raise ConfigError(f"{f}.metrics.baseline", "is not used by a suite; remove it")
            sc = replace(sc, name=sname)
            every[sname] = SuiteScenario(sname, lname, sc, mcfg, title)
        suite_scenarios = {sname: every[sname] for sname in chosen}

        ctrl_t = top.get(data, "controllers", "")
        C = declared("controllers.NAME:suite")
        if not ctrl_t:
            raise ConfigError("controllers", "needs at least one [controllers.NAME] table")
        names = select_names(list(ctrl_t), controllers, "--controllers")
        extra = fallback_names(ctrl_t, names)
        ctrls: dict[str, dict[str, Any]] = {}
        for cname in names + extra:
            table = ctrl_t[cname]
            f = f"controllers.{cname}"
            if not isinstance(table, dict):
                raise ConfigError(f, "must be a table")
            C.get(table, "type", f)
            only = C.raw(table, "only_layouts")
            if only is not None and (not isinstance(only, list) or not only):
                raise ConfigError(f"{f}.only_layouts", f"must be a non-empty list of layout "
                                  f"names {list(layouts)}, got {only!r}")  # fmt: skip
            for lname in only or ():
                if lname not in layouts:
                    raise ConfigError(f"{f}.only_layouts", f"unknown layout {lname!r}; "
                                      f"available: {list(layouts)}")  # fmt: skip
            lay = _check_only_scenarios(C.raw(table, "only_scenarios"), only, scen_t, f)
            if only is None and lay is not None:  # applies(table, layout) knows them too
                table = {**table, "only_layouts": lay}
            over = C.get(table, "layouts", f)
            for lname, t in over.items():
                if lname not in layouts:
                    raise ConfigError(
                        f"{f}.layouts.{lname}", f"unknown layout; available: {list(layouts)}"
                    )
                if not isinstance(t, dict):
                    raise ConfigError(f"{f}.layouts.{lname}", "must be a table")
                if "type" in t and t["type"] != table["type"]:
                    raise ConfigError(f"{f}.layouts.{lname}.type", "cannot change the type")
            ctrls[cname] = dict(table)
        check_suite_controllers(ctrls, names, extra, every, layouts, src)
        for sname, ss in suite_scenarios.items():  # only_layouts / only_scenarios leave none
            if not any(applies(ctrls[c], ss.layout, sname) for c in names):
                raise ConfigError("--controllers" if controllers else f"scenarios.{sname}",
                                  f"no controller of {names} runs in scenario {sname!r} "
                                  "(only_layouts, only_scenarios): select --scenarios too")
        return Suite(
            name=problem.name,
            description=str(top.raw(data, "description")),
            layouts=layouts,
            scenarios=suite_scenarios,
            controllers={k: ctrls[k] for k in names},
            source=src,
            fallbacks={k: ctrls[k] for k in extra},
        )
    except ConfigError as err:
        raise err.with_source(src) if not err.source else err from None


# --------------------------------------------------------------------------------------------
# Controllers per layout
# --------------------------------------------------------------------------------------------


def layout_controllers(suite: Suite, layout: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """The controllers of ``suite`` that run in at least one of its scenarios on ``layout``
    (:func:`applies`), and the controllers those MPCs fall back to (``fallback = "NAME"``),
    as ``(run, fallbacks)``."""
    names = [s for s, ss in suite.scenarios.items() if ss.layout == layout]
    run = {k: t for k, t in suite.controllers.items()
           if any(applies(t, layout, s) for s in names)}  # fmt: skip
    every = {**suite.controllers, **suite.fallbacks}
    return run, {k: every[k] for k in fallback_names(every, list(run))}


def prepare_controllers(
    controllers: Mapping[str, Mapping[str, Any]],
    system: System,
    layout: str,
    source: str | None = None,
    label: str = "suite",
    on_step: Callable[[str], None] | None = None,
    fallbacks: Mapping[str, Mapping[str, Any]] | None = None,
    failures: dict[str, str] | None = None,
    gains: dict[str, Gains] | None = None,
):
    """Controller tables of one layout, ``h2`` entries replaced by their synthesised gains and
    the MPCs' ``fallback = "NAME"`` by NAME's gain.

    With ``failures`` (a dict), a controller whose synthesis fails, and an MPC falling back to
    it, are left out and recorded there (``{name: why}``), so that the others still run;
    without it the :class:`~lcc_synth.synthesis.h2.SynthesisError` propagates.

    With ``gains`` (a dict), the synthesised gain objects are put there (``{name: Gains}``,
    the fallbacks' included): the objects the controllers are built from in memory
    (:func:`lcc_synth.experiments.spec.controller_gain`, as :func:`run_suite` does), where the
    returned tables are their plain form (result files).

    Returns ``(tables, designs)``: ``{name: table}`` with only the types of
    :data:`lcc_synth.experiments.controller_tables.CONTROLLER_TYPES`, and
    ``{name: SynthesisReport}``, for the names of ``controllers`` that apply to ``layout``
    (:func:`applies`; ``fallbacks``: more tables, designed only to resolve the MPCs' fallbacks,
    :attr:`Suite.fallbacks`).
    """
    tables: dict[str, dict[str, Any]] = {}
    designs: dict[str, Any] = {}
    controllers = {k: t for k, t in controllers.items() if applies(t, layout)}
    for name, raw in {**controllers, **(fallbacks or {})}.items():
        if not applies(raw, layout):
            continue
        if on_step is not None and name in controllers:
            on_step(name)
        table = controller_table(raw, layout)
        if table.get("type") == "h2":
            from lcc_synth.synthesis.h2 import SynthesisError  # here: loading a suite needs none

            try:
                table, rep = synthesize_table(
                    name, table, system, f"{label}_{layout}_{name}", source
                )
            except SynthesisError as err:
                if failures is None:
                    raise
                failures[name] = f"synthesis failed: {err}"
                continue
            designs[name] = rep
            if gains is not None:
                gains[name] = rep.gain
        tables[name] = table
    from lcc_synth.experiments.spec import drop_failed_fallbacks, resolve_fallbacks

    if failures:
        tables = drop_failed_fallbacks(tables, failures, source)
    resolved = resolve_fallbacks(tables, system, source)
    return {k: resolved[k] for k in controllers if k in resolved}, {
        k: designs[k] for k in designs if k in controllers}


def build_controllers(
    tables: Mapping[str, Mapping[str, Any]], system: System, source: str | None = None
) -> dict[str, Controller]:
    """:func:`lcc_synth.experiments.controller_tables.controller_from_table` for every table."""
    return {name: controller_from_table(name, dict(t), system, source)
            for name, t in tables.items()}  # fmt: skip


# --------------------------------------------------------------------------------------------
# Running a suite
# --------------------------------------------------------------------------------------------


def metrics_row(result: SimResult, config: MetricsConfig) -> dict[str, Any]:
    """The :data:`SUITE_METRICS` of one result (batch means / worst cases, as ``summary``)
    and ``collided``: a scenario of the run had a collision (its AAVE and fuel are NaN, the
    tables rank it last)."""
    from lcc_synth.experiments.tables import failed_steps
    from lcc_synth.metrics import summary

    s = summary(result, config)
    row: dict[str, Any] = {key: s[key] for key in SUITE_METRICS}
    row["collided"] = s["scenarios_with_collision"] > 0
    row["failed_steps"] = failed_steps(result.controller_stats)
    return row


@dataclass
class SuiteRun:
    """Everything a suite run produced.

    Attributes
    ----------
    table : dict
        ``{scenario: {controller: {metric: value}}}`` (:data:`SUITE_METRICS` and
        ``collided``; within a scenario the collided runs come last).
    results : dict
        ``{scenario: {controller: SimResult}}``.
    tables : dict
        ``{layout: {controller: table}}`` the controller tables actually built (``h2`` resolved).
    designs : dict
        ``{layout: {controller: SynthesisReport}}``.
    controllers : dict
        ``{layout: {controller: Controller}}``.
    timings : dict
        Wall times (s) of the stages.
    failures : dict
        ``{layout: {controller: why}}``: the controllers that could not be built (a failed
        synthesis, an MPC falling back to it); their rows in :attr:`table` say so.
    """

    suite: Suite
    table: dict[str, dict[str, dict[str, Any]]]
    results: dict[str, dict[str, SimResult]]
    tables: dict[str, dict[str, dict[str, Any]]]
    designs: dict[str, dict[str, Any]]
    controllers: dict[str, dict[str, Controller]]
    timings: dict[str, float]
    failures: dict[str, dict[str, str]] = field(default_factory=dict)


def run_suite(
    suite: Suite,
    progress: bool = True,
    on_result: Callable[[str, str, SimResult, dict[str, Any], Controller], None] | None = None,
) -> SuiteRun:
    """Build the controllers of every layout (synthesising ``h2`` gains) and run every
    controller on every scenario of ``suite``.

    Parameters
    ----------
    suite : Suite
    progress : bool
        Show a progress bar per stage on stderr.
    on_result : callable, optional
        ``on_result(scenario, name, result, row, controller)`` right after each simulation
        (e.g. to record it while the suite goes on; an MPC still holds that run's history).
    """
    import time

    from lcc_synth.experiments.deeplcc_runs import run_scenario, scenario_controllers
    from lcc_synth.experiments.spec import controller_gain
    from lcc_synth.simulation.backends import check_backend

    for sname, ss in suite.scenarios.items():  # the simulator is installed: before any design
        try:
            check_backend(ss.scenario)
        except ConfigError as err:
            err = ConfigError(f"scenarios.{sname}.backend", err.message, suite.source)
            raise err from None
    timings: dict[str, float] = {}
    layouts = suite.layouts_used()
    failures: dict[str, dict[str, str]] = {lname: {} for lname in layouts}
    tables: dict[str, dict[str, dict[str, Any]]] = {}
    designs: dict[str, dict[str, Any]] = {}
    built: dict[str, dict[str, Controller]] = {}
    t0 = time.perf_counter()
    what = "controllers (synthesis, MPC set-up)"
    per_layout = {lname: layout_controllers(suite, lname) for lname in layouts}
    n_built = sum(len(run) for run, _ in per_layout.values())
    with progress_bar(n_built, what, progress) as bar:
        for lname in layouts:
            system = suite.layouts[lname]

            def starting(cname: str, lname=lname) -> None:
                bar.set_postfix_str(f"{lname}/{cname}")

            synthesised: dict[str, Gains] = {}
            tables[lname], designs[lname] = prepare_controllers(
                per_layout[lname][0], system, lname, suite.source, suite.name,
                on_step=starting, fallbacks=per_layout[lname][1], failures=failures[lname],
                gains=synthesised,
            )
            bar.update(len([c for c in failures[lname] if c in per_layout[lname][0]]))
            built[lname] = {}
            for cname, table in tables[lname].items():
                checkpoint()  # a signal lost in CasADi's set-up of the last MPC (interrupts)
                starting(cname)
                given = controller_table(suite.controllers[cname], lname)
                gain = controller_gain(cname, given, synthesised)  # built from the object
                try:  # deep_lcc: its settings here, its data per scenario (deeplcc_runs)
                    built[lname][cname] = scenario_controllers(
                        {cname: table if gain is None else given}, system, suite.source,
                        {cname: gain},
                    )[cname]
                except ConfigError as err:
                    raise ConfigError(
                        f"{err.field} (layout {lname})", err.message, err.source
                    ) from None
                bar.update(1)
    timings["controllers"] = time.perf_counter() - t0
    from lcc_synth.simulation.timestep import check_time_step

    runs = {s: {c: k for c, k in built[ss.layout].items() if applies(suite.controllers[c],
                                                                   ss.layout, s)}
            for s, ss in suite.scenarios.items()}  # fmt: skip
    for sname, ss in suite.scenarios.items():  # a step too coarse for a loop: before any run
        try:
            check_time_step(ss.scenario, runs[sname], f"scenarios.{sname}.dt")
        except ConfigError as err:
            raise err.with_source(suite.source) if suite.source else err from None

    table: dict[str, dict[str, dict[str, Any]]] = {}
    results: dict[str, dict[str, SimResult]] = {}
    t0 = time.perf_counter()
    with progress_bar(sum(len(r) for r in runs.values()), "simulations", progress) as bar:
        for sname, ss in suite.scenarios.items():
            draws = ss.scenario.draw()
            table[sname] = {}
            results[sname] = {}
            for cname, why in failures[ss.layout].items():  # a row saying why it did not run
                if cname in suite.controllers and applies(suite.controllers[cname], ss.layout,
                                                          sname):  # fmt: skip
                    table[sname][cname] = {**dict.fromkeys(SUITE_METRICS), "collided": False,
                                           "failed_steps": 0, "failed": why}  # fmt: skip
            for cname, ctrl in runs[sname].items():
                checkpoint()
                bar.set_postfix_str(f"{sname}/{cname}")
                res = run_scenario(ss.scenario, ctrl, draws)
                row = metrics_row(res, ss.metrics)
                table[sname][cname] = row
                results[sname][cname] = res
                if on_result is not None:
                    on_result(sname, cname, res, row, ctrl)
                bar.update(1)
    timings["simulations"] = time.perf_counter() - t0
    table = rank_failed_last(table)  # failed runs rank last in every form of the table
    return SuiteRun(suite, table, results, tables, designs, built, timings,
                    {k: v for k, v in failures.items() if v})  # fmt: skip


def gamma_curves(
    controllers: Mapping[str, Controller],
    system: System,
    omega: np.ndarray,
    dt: float = 0.01,
    latency: float = 0.0,
    measure_omega: Sequence[float] | None = None,
) -> dict[str, tuple[np.ndarray, Any]]:
    """``|Gamma(j omega)|`` and the string-stability report of every controller **as it runs**
    on ``system`` with simulator step ``dt`` and V2V ``latency``
    (:func:`lcc_synth.experiments.string_as_run.gamma_curves`): a linear controller's loop
    holds its equilibrium estimator, sample-and-hold, latency and measurement filter; a
    controller that is not linear (MPC) gets the simulated small-signal amplitude ratio at
    ``measure_omega`` (default :data:`~lcc_synth.experiments.string_as_run.MEASURE_OMEGA`).
    Layouts without a head vehicle (``fd_lcc``) give ``{}``.
    """
    from lcc_synth.experiments.string_as_run import MEASURE_OMEGA
    from lcc_synth.experiments.string_as_run import gamma_curves as as_run_curves

    wm = MEASURE_OMEGA if measure_omega is None else measure_omega
    return as_run_curves(controllers, system, omega, dt, latency, wm)


def gamma_settings(suite: Suite) -> dict[str, list[tuple[str, float, float, list[str]]]]:
    """Per layout with a head vehicle (one CAV, or an open platoon: every CAV in the loop; not
    ``fd_lcc`` or a ring, which have none), the distinct ``(dt, V2V latency)`` of its
    scenarios:
    ``{layout: [(label suffix, dt, latency, scenario names)]}``; the suffix is ``""`` for the
    first (ideal links first), else e.g. ``" @ 0.1 s latency"``."""
    out: dict[str, list[tuple[str, float, float, list[str]]]] = {}
    for lname in suite.layouts_used():
        if suite.layouts[lname].kind in ("fd_lcc", "ring"):  # no head vehicle
            continue
        pairs: dict[tuple[float, float], list[str]] = {}
        for sname, ss in suite.scenarios.items():
            if ss.layout == lname:
                key = (float(ss.scenario.dt), float(ss.scenario.v2v.latency))
                pairs.setdefault(key, []).append(sname)
        rows = []
        for k, ((dt, lat), names) in enumerate(sorted(pairs.items(), key=lambda p: p[0][1])):
            suffix = "" if k == 0 else f" @ {lat:g} s latency" + (f", dt {dt:g} s" if dt != 0.01
                                                                   else "")
            rows.append((suffix, dt, lat, names))
        out[lname] = rows
    return out
