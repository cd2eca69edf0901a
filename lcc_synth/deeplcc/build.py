"""The DeeP-LCC controller of a ``[controllers.NAME]`` table (``type = "deep_lcc"``): its
settings (:mod:`lcc_synth.deeplcc.settings`), the data-collection scenario and the data
(:mod:`lcc_synth.deeplcc.data`, cached).

The collection scenario is the problem file's own ``[scenario]`` (HDV parameters,
heterogeneity, reaction delays, acceleration noise, limits; its perturbations are replaced by
the excitation) when the file has one, else the nominal string of ``[hdv]`` + ``[system]``
(a ``run`` / ``sweep`` suite, or no file).
"""

from __future__ import annotations

from lcc_synth.deeplcc.controller import DeePLCCController
from lcc_synth.deeplcc.data import load_or_collect
from lcc_synth.deeplcc.settings import deep_settings_from_table
from lcc_synth.errors import ConfigError

__all__ = ["base_scenario", "deep_lcc_controller_from_table", "build_deep_lcc"]


def base_scenario(system, source: str | None = None):
    """The scenario the data are collected on (module docstring)."""
    from pathlib import Path

    from lcc_synth.problem import load_problem
    from lcc_synth.simulation.scenario_file import scenario_from

    if source:
        problem = load_problem(source)
        if "scenario" in problem.data:
            return scenario_from(problem.data, system, Path(source).parent)
    return scenario_from({"scenario": {}}, system)  # the [scenario] defaults on this string


def deep_lcc_controller_from_table(name: str, table, system, source: str | None = None,
                                   scenario=None) -> DeePLCCController:
    """Build a :class:`DeePLCCController` from a ``[controllers.NAME]`` table.

    Parameters
    ----------
    name : str
        Controller name (table key).
    table : mapping
        The table (keys: :mod:`lcc_synth.deeplcc.settings`).
    system : lcc_synth.problem.System
    source : str, optional
        The problem file (errors name it; its ``[scenario]`` is the collection's base).
    scenario : lcc_synth.simulation.scenario.Scenario, optional
        The collection's base scenario instead of the file's.
    """
    field_name = f"controllers.{name}"
    try:
        settings = deep_settings_from_table(dict(table), field_name)
        base = scenario if scenario is not None else base_scenario(system, source)
        data, key, _ = load_or_collect(base, settings.data)
        cavs = getattr(base, "cavs", None)
        cavs = tuple(cavs) if cavs is not None else (base.cav,)
        try:
            return DeePLCCController(name, settings, data, system.kind, system.hdv,
                                     system.v_star, base.n_vehicles, cavs, key)  # fmt: skip
        except ConfigError as err:
            if err.field.startswith(field_name):
                raise
            raise ConfigError(f"{field_name}.{err.field}", err.message) from None
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None


def build_deep_lcc(system, name: str = "deep_lcc", scenario=None, **settings):
    """DeeP-LCC for ``system`` with the keys of a ``type = "deep_lcc"`` table as keyword
    arguments (``t_ini``, ``horizon``, ``weights = {...}``, ``constraints``, ``solver``,
    ``data = {...}``); ``scenario`` is the collection's base (default: the nominal string)."""
    table = {k: v for k, v in settings.items() if v is not None}
    return deep_lcc_controller_from_table(name, {"type": "deep_lcc", **table}, system,
                                          scenario=scenario)
