"""DeeP-LCC in sweeps and suites: every scenario's controller on that scenario's own data.

DeeP-LCC predicts from data collected in the traffic it drives (Wang et al. 2023,
Section V): in a sweep (:mod:`lcc_synth.experiments.sweep`) every scenario ``i`` draws its own
HDVs from ``(seed, i)`` (parameters, reaction delays) and its own acceleration-noise level, and
a suite's scenarios (:mod:`lcc_synth.experiments.comparison`) have their own HDVs too, so
a ``type = "deep_lcc"`` controller of ``sweep`` and ``run`` is built **per scenario**: its
data are collected
(:func:`lcc_synth.deeplcc.data.load_or_collect`) on :func:`collection_base`, the scenario with
its drawn HDVs made explicit (``hdv_values``, per-vehicle ``delay``; no heterogeneity or
delay spread left to draw) and its drawn noise level. The collection's own random streams
(excitation, noise) are those of the data table's ``seed``; the data cache key
(:func:`lcc_synth.deeplcc.data.data_key`) hashes the explicit HDVs, so it is per scenario.

Measured on ``problems/sweep_robustness.toml`` (10-HDV string, T = 2000 at 0.05 s, CPU time
of one process with one BLAS thread, as a Dask worker has, 8 draws, 2026-12-04): per scenario
0.085 s to collect the data (0.6 s for the first, compiling the simulator), 0.13 s to set up
the controller (the persistency check and the exact reduction of the data,
:func:`lcc_synth.deeplcc.hankel.reduce`, 0.12 s; 0.21 s before it factored the 890 x 890
``lambda_g I + B B'`` instead of the 1931 x 1931 Hessian) and 0.2-0.25 s to drive the 40 s
run (800 QPs). The set-up always runs with one BLAS thread, also in ``run`` and in the
client, where two threads had cost 2.0-3.2 s on the loaded machine and rounded differently
from the workers. A cached data file is 0.22 MB.

The rest is unchanged: :func:`scenario_controllers` builds every other table as
:func:`lcc_synth.experiments.controller_tables.controller_from_table` does and a
:class:`ScenarioDeePLCC` for each ``deep_lcc`` table (its settings checked, named-field errors,
before any task); :func:`run_scenario` builds its controller for the scenario it runs;
:func:`scenario_runs` runs scenarios one by one when a :class:`ScenarioDeePLCC` is among the
controllers (a batch has one data set; every other controller's result is bit-for-bit the same
either way, :mod:`lcc_synth.experiments.sweep`). After a run a :class:`ScenarioDeePLCC` drives
as the controller of its last scenario (``run``'s string-stability measurement, history).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from lcc_synth.errors import ConfigError

__all__ = ["ScenarioDeePLCC", "collection_base", "scenario_controllers", "scenario_runs",
           "run_scenario"]  # fmt: skip


def collection_base(scenario, draws=None):
    """``scenario`` (a batch of one) with its drawn HDV parameters and reaction delays
    explicit: the base of its DeeP-LCC data collection (module docstring)."""
    if scenario.batch != 1:
        raise ValueError("collection_base needs a batch of one scenario")
    d = scenario.draw() if draws is None else draws
    values = {k: tuple(float(x) for x in v[0]) for k, v in d.hdv_values.items()}
    return replace(scenario, hdv_values=values, heterogeneity={},
                   delay=tuple(float(x) for x in d.delay[0]), delay_spread=0.0,
                   perturbations=())  # fmt: skip


class ScenarioDeePLCC:
    """A ``type = "deep_lcc"`` table of a sweep: builds, for each scenario, DeeP-LCC on that
    scenario's data (:meth:`for_scenario`).

    Parameters
    ----------
    name : str
    table : mapping
        The ``[controllers.NAME]`` table (checked here).
    system : lcc_synth.problem.System
    source : str, optional
        The problem file (errors name it).
    """

    def __init__(self, name: str, table: Mapping[str, Any], system, source: str | None = None):
        from lcc_synth.deeplcc.settings import deep_settings_from_table

        field_name = f"controllers.{name}"
        try:
            self.settings = deep_settings_from_table(dict(table), field_name)
        except ConfigError as err:
            raise err.with_source(source) if source and not err.source else err from None
        self.name = name
        self.table = dict(table)
        self.system = system
        self.source = source
        self.sample_time = self.settings.sample_time
        self.record = True
        self.last = None  # the controller of the last scenario

    def for_scenario(self, scenario, draws=None):
        """DeeP-LCC on the data of ``scenario`` (a batch of one; ``draws``: its draws)."""
        from lcc_synth.controllers.switch import SwitchedOn
        from lcc_synth.deeplcc.build import deep_lcc_on_data
        from lcc_synth.schema import declared

        base = collection_base(scenario, draws)
        ctrl = deep_lcc_on_data(self.name, self.settings, self.system, base, self.source)
        ctrl.record = self.record
        field_name = f"controllers.{self.name}"
        start = declared("controllers.NAME:deep_lcc").get(self.table, "start", field_name)
        self.last = ctrl if start is None else SwitchedOn(ctrl, start)
        return self.last

    def _built(self):
        if self.last is None:
            raise RuntimeError(f"{self.name}: no scenario has run yet (for_scenario first)")
        return self.last

    def reset(self, ctx) -> None:
        """Reset the controller of the last scenario (module docstring)."""
        self._built().reset(ctx)

    def __call__(self, obs):
        return self._built()(obs)

    def stats(self) -> dict[str, Any]:
        """The last scenario's controller's statistics."""
        return {} if self.last is None else self.last.stats()

    def history(self) -> dict[str, Any]:
        """The last scenario's per-step history (:meth:`DeePLCCController.history`)."""
        inner = getattr(self.last, "inner", self.last)
        return {} if inner is None else inner.history()

    def describe(self) -> dict[str, Any]:
        """The settings; the data are each scenario's."""
        return {"type": "deep_lcc", "name": self.name, "data": "per scenario",
                **self.settings.as_dict()}  # fmt: skip


def scenario_controllers(tables: Mapping[str, Mapping[str, Any]], system,
                         source: str | None = None, gains: Mapping[str, Any] | None = None):
    """The controllers of a sweep or of a suite's layout: :class:`ScenarioDeePLCC` for
    ``deep_lcc`` tables, the others by
    :func:`lcc_synth.experiments.controller_tables.controller_from_table` (``gains``: ``{name:
    Gains}``, the gain object each is built with, its ``gains``)."""
    from lcc_synth.experiments.controller_tables import controller_from_table

    gains = gains or {}
    return {k: ScenarioDeePLCC(k, t, system, source) if t.get("type") == "deep_lcc"
            else controller_from_table(k, dict(t), system, source, gains=gains.get(k))
            for k, t in tables.items()}  # fmt: skip


def scenario_runs(scenario, ranges, start: int, stop: int, controllers) -> list:
    """The scenarios of a task ``start .. stop - 1``: one by one with their drawn settings
    (``ranges``) or when a :class:`ScenarioDeePLCC` runs, else one batch."""
    from lcc_synth.simulation.scenario import scenario_variant

    if ranges or any(isinstance(c, ScenarioDeePLCC) for c in controllers.values()):
        return [scenario_variant(scenario, ranges or {}, i) for i in range(start, stop)]
    return [replace(scenario, batch=stop - start, first_index=start)]


def run_scenario(scenario, controller, draws=None):
    """:func:`lcc_synth.simulation.backends.run_scenario`, a :class:`ScenarioDeePLCC`
    built for ``scenario`` first."""
    from lcc_synth.simulation.backends import run_scenario as run

    if isinstance(controller, ScenarioDeePLCC):
        controller = controller.for_scenario(scenario, draws)
    return run(scenario, controller, draws)
