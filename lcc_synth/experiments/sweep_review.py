"""The sweep's hardest scenario, found in its samples and simulated again with every controller
(for ``lcc-synth sweep``'s second recording).

The hardest scenario is the one with the smallest minimum spacing over every controller and
vehicle (a collision first: its spacing reached 0); ties go to the lower scenario index, then
to the controller listed first. Scenario ``i`` draws everything from ``(seed, i)`` only
(:mod:`lcc_synth.experiments.sweep`), so simulating it alone, with the controllers the
workers ran (their tables and gain objects,
:attr:`~lcc_synth.experiments.sweep.SweepResult.worker_tables` and ``gains``; or the plain
tables, :attr:`~lcc_synth.experiments.sweep.SweepResult.tables`), gives the run that the sweep
measured, bit for bit (``tests/test_sweep_review.py`` checks every metric), now with its whole
trajectory and each MPC's solve history.

Cost, measured: one scenario per controller on the client, 0.31 s for all_hdv, paper, h2 and
mpc of ``problems/sweep_robustness.toml`` (after a first call that builds the MPC), and 0.68 s
more for its DeeP-LCC (its data are collected again for that scenario).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError

__all__ = ["HardestScenario", "hardest_scenario", "simulate_scenario"]


@dataclass(frozen=True)
class HardestScenario:
    """Where a sweep came closest to a collision.

    Attributes
    ----------
    index : int
        Scenario index (its draws come from ``(seed, index)``).
    controller : str
        The controller with that smallest spacing.
    min_spacing : float
        Its minimum spacing (m; <= 0 for a collision).
    collided : bool
        Whether that run collided.
    """

    index: int
    controller: str
    min_spacing: float
    collided: bool


def hardest_scenario(samples: Mapping[str, Mapping[str, np.ndarray]]) -> HardestScenario:
    """The scenario with the smallest minimum spacing of any controller (module docstring).

    Parameters
    ----------
    samples : mapping
        ``{controller: {"min_spacing": (count,), "collisions": (count,), ...}}``
        (:attr:`~lcc_synth.experiments.sweep.SweepResult.samples`).

    Raises
    ------
    ConfigError
        No controller, or no finite minimum spacing at all.
    """
    best = None
    for c, per in samples.items():
        if "min_spacing" not in per or "collisions" not in per:
            raise ConfigError("samples", f"controller {c!r} has no min_spacing / collisions")
        s = np.asarray(per["min_spacing"], dtype=float)
        coll = np.asarray(per["collisions"], dtype=float) > 0
        # a collision ranks first whatever spacing was recorded before it
        key = np.where(coll, -np.inf, np.where(np.isfinite(s), s, np.inf))
        i = int(np.argmin(key))
        if key[i] < np.inf:  # some finite spacing or a collision
            cand = (key[i], i, c, float(s[i]), bool(coll[i]))
            if best is None or cand[:2] < best[:2]:
                best = cand
    if best is None:
        raise ConfigError("samples", "no controller has a finite minimum spacing")
    return HardestScenario(best[1], best[2], best[3], best[4])


def simulate_scenario(
    spec: Any, tables: Mapping[str, Mapping[str, Any]], index: int, progress: bool = False,
    gains: Mapping[str, Any] | None = None,
):
    """Simulate scenario ``index`` of a sweep alone with every controller of ``tables``.

    Parameters
    ----------
    spec : lcc_synth.experiments.sweep.SweepSpec
        The sweep (scenario, system, ranges, source).
    tables : mapping
        Controller tables as the workers got them
        (:attr:`~lcc_synth.experiments.sweep.SweepResult.worker_tables`, with ``gains``), or
        the plain ones (:attr:`~lcc_synth.experiments.sweep.SweepResult.tables`).
    index : int
        Scenario index, ``0 <= index < spec.count``.
    progress : bool
        A progress bar on stderr, one count per controller
        (:func:`lcc_synth.resources.progress_bar`).
    gains : mapping, optional
        ``{controller: Gains}``: the gain objects the workers built controllers with
        (:attr:`~lcc_synth.experiments.sweep.SweepResult.gains`).

    Returns
    -------
    scenario : lcc_synth.simulation.scenario.Scenario
        Scenario ``index`` with its drawn settings (batch of one).
    results : dict
        ``{controller: SimulationResult}``; an MPC keeps its per-step history.
    controllers : dict
        The controllers that ran (their ``history()`` for the recording).

    Raises
    ------
    ConfigError
        ``index`` outside ``[0, count)``.
    """
    from lcc_synth.experiments.deeplcc_runs import (
        run_scenario,
        scenario_controllers,
        scenario_runs,
    )

    if not 0 <= int(index) < spec.count:
        raise ConfigError("index", f"must be in [0, {spec.count - 1}], got {index}")
    ctrls = scenario_controllers(tables, spec.system, spec.source, gains)
    (scenario,) = scenario_runs(spec.scenario, spec.ranges, int(index), int(index) + 1, ctrls)
    from lcc_synth.resources import progress_bar

    draws = scenario.draw()
    results = {}
    with progress_bar(len(ctrls), f"scenario {index} again", progress) as bar:
        for name, c in ctrls.items():
            bar.set_postfix_str(name)
            results[name] = run_scenario(scenario, c, draws)
            bar.update(1)
    return scenario, results, ctrls
