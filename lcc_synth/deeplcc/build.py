"""The DeeP-LCC controller of a ``[controllers.NAME]`` table (``type = "deep_lcc"``): its
settings (:mod:`lcc_synth.deeplcc.settings`), the data-collection scenario and the data
(:mod:`lcc_synth.deeplcc.data`, cached).

The collection's base scenario is given by the caller: the problem file's own ``[scenario]``
(HDV parameters, heterogeneity, reaction delays, acceleration noise, limits; its perturbations
are replaced by the excitation) for ``simulate`` (:func:`lcc_synth.experiments.spec.load_spec`),
each scenario with its drawn HDVs for ``run`` and ``sweep``
(:mod:`lcc_synth.experiments.deeplcc_runs`), else the nominal string of the system
(:func:`lcc_synth.simulation.scenario_file.nominal_scenario`). Nothing here reads a file.

Reading a table collects nothing: :func:`deep_lcc_controller_from_table` checks the settings
and returns a :class:`DeferredDeePLCC`, which collects (or reads from the cache) its data and
sets up the controller once, when it is first used (reset by the simulator, or described).
Loading a problem file therefore runs no simulation.
"""

from __future__ import annotations

from typing import Any

from lcc_synth.controllers.base import ControlContext, Observation
from lcc_synth.deeplcc.controller import NO_RING, DeePLCCController
from lcc_synth.deeplcc.data import collection_key, load_or_collect
from lcc_synth.deeplcc.settings import DeePLCCSettings, deep_settings_from_table
from lcc_synth.errors import ConfigError
from lcc_synth.simulation.scenario_file import nominal_scenario

__all__ = ["DeferredDeePLCC", "build_deep_lcc", "deep_lcc_controller_from_table",
           "deep_lcc_on_data"]


def _cavs(base) -> tuple[int, ...]:
    cavs = getattr(base, "cavs", None)
    return tuple(cavs) if cavs is not None else (base.cav,)


def deep_lcc_on_data(name: str, settings: DeePLCCSettings, system, base,
                     source: str | None = None) -> DeePLCCController:  # fmt: skip
    """DeeP-LCC on the data of ``settings.data`` collected on ``base`` (read from the cache
    when there): this runs the collection.

    Parameters
    ----------
    name : str
        Controller name (errors name ``controllers.NAME``).
    settings : DeePLCCSettings
    system : lcc_synth.problem.System
    base : lcc_synth.simulation.scenario.Scenario
        The collection's base scenario (:func:`lcc_synth.deeplcc.data.collection_scenario`).
    source : str, optional
        The problem file (errors name it).

    Raises
    ------
    ConfigError
        The data are not persistently exciting, the collection collided or braked, or the
        data do not fit the string (``controllers.NAME.data...``).
    """
    field_name = f"controllers.{name}"
    try:
        data, key, _ = load_or_collect(base, settings.data)
        try:
            return DeePLCCController(name, settings, data, system.kind, system.hdv,
                                     system.v_star, base.n_vehicles, _cavs(base), key)  # fmt: skip
        except ConfigError as err:
            if err.field.startswith(field_name):
                raise
            raise ConfigError(f"{field_name}.{err.field}", err.message) from None
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None


class DeferredDeePLCC:
    """A DeeP-LCC controller whose data are collected when it is first used.

    It drives as the :class:`DeePLCCController` that :func:`deep_lcc_on_data` builds, built
    once at the first :meth:`reset` (or :meth:`describe`, :meth:`controller`); until then it
    holds only its settings, so building it from a problem file collects nothing.

    Parameters
    ----------
    name : str
    settings : DeePLCCSettings
    system : lcc_synth.problem.System
    base : lcc_synth.simulation.scenario.Scenario
        The collection's base scenario.
    source : str, optional
        The problem file (errors name it).
    """

    def __init__(self, name: str, settings: DeePLCCSettings, system, base,
                 source: str | None = None):  # fmt: skip
        self.name = name
        self.settings = settings
        self.system = system
        self.base = base
        self.source = source
        self._record = True
        self._built: DeePLCCController | None = None

    @property
    def sample_time(self) -> float:
        """The controller's period (the data's sample time)."""
        return self.settings.sample_time

    @property
    def cavs(self) -> tuple[int, ...]:
        """Array columns of the CAVs (the data's input order)."""
        return tuple(int(c) for c in _cavs(self.base))

    @property
    def record(self) -> bool:
        """Keep the per-step history (passed on to the built controller)."""
        return self._record

    @record.setter
    def record(self, value: bool) -> None:
        self._record = bool(value)
        if self._built is not None:
            self._built.record = self._record

    @property
    def built(self) -> bool:
        """Whether the data have been collected and the controller set up."""
        return self._built is not None

    def controller(self) -> DeePLCCController:
        """The DeeP-LCC controller, built on first call (this collects the data)."""
        if self._built is None:
            ctrl = deep_lcc_on_data(self.name, self.settings, self.system, self.base,
                                    self.source)  # fmt: skip
            ctrl.record = self._record
            self._built = ctrl
        return self._built

    def reset(self, ctx: ControlContext) -> None:
        """Build the controller (first call only) and reset it."""
        self.controller().reset(ctx)

    def __call__(self, obs: Observation):
        if self._built is None:
            raise RuntimeError(f"{self.name}: call reset(ctx) before the first step")
        return self._built(obs)

    def stats(self) -> dict[str, Any]:
        """The built controller's statistics (empty before it is built)."""
        return {} if self._built is None else self._built.stats()

    def history(self) -> dict[str, Any]:
        """The built controller's per-step history (empty before it is built)."""
        return {} if self._built is None else self._built.history()

    def describe(self) -> dict[str, Any]:
        """:meth:`DeePLCCController.describe` (builds the controller)."""
        return self.controller().describe()

    def as_dict(self) -> dict[str, Any]:
        """:meth:`DeePLCCController.as_dict`, without collecting: the data key is the hash of
        the collection scenario and the data settings
        (:func:`lcc_synth.deeplcc.data.collection_key`)."""
        base = self.base
        return {"type": "deep_lcc", "name": self.name, "kind": self.system.kind,
                "cavs": list(self.cavs), "n_vehicles": int(base.n_vehicles),
                "data_key": collection_key(base, self.settings.data),
                **self.settings.as_dict()}  # fmt: skip

    def toml_table(self) -> dict[str, Any]:
        """The ``[controllers.NAME]`` table that builds this controller."""
        return self.settings.toml_table()


def deep_lcc_controller_from_table(name: str, table, system, source: str | None = None,
                                   scenario=None) -> DeferredDeePLCC:
    """The DeeP-LCC controller of a ``[controllers.NAME]`` table: its settings checked now,
    its data collected when it is first used (:class:`DeferredDeePLCC`).

    Parameters
    ----------
    name : str
        Controller name (table key).
    table : mapping
        The table (keys: :mod:`lcc_synth.deeplcc.settings`).
    system : lcc_synth.problem.System
    source : str, optional
        The problem file (errors name it).
    scenario : lcc_synth.simulation.scenario.Scenario, optional
        The collection's base scenario (module docstring; default: the nominal string of
        ``system``, :func:`~lcc_synth.simulation.scenario_file.nominal_scenario`).
    """
    field_name = f"controllers.{name}"
    try:
        if system.ring:  # before the data collection, whose head brake a ring cannot take
            raise ConfigError(field_name, NO_RING)
        settings = deep_settings_from_table(dict(table), field_name)
        base = nominal_scenario(system) if scenario is None else scenario
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None
    return DeferredDeePLCC(name, settings, system, base, source)


def build_deep_lcc(system, name: str = "deep_lcc", scenario=None, **settings):
    """DeeP-LCC for ``system`` with the keys of a ``type = "deep_lcc"`` table as keyword
    arguments (``t_ini``, ``horizon``, ``weights = {...}``, ``constraints``, ``solver``,
    ``data = {...}``); ``scenario`` is the collection's base (default: the nominal string).
    The data are collected at its first use (:class:`DeferredDeePLCC`)."""
    table = {k: v for k, v in settings.items() if v is not None}
    return deep_lcc_controller_from_table(name, {"type": "deep_lcc", **table}, system,
                                          scenario=scenario)
