"""The one place that runs a scenario: :func:`run_scenario` picks the simulator the scenario
names (``[scenario] backend``): the built-in simulator
(:func:`lcc_synth.simulation.engine.simulate`) or SUMO
(:func:`lcc_synth.simulation.sumo.simulate_sumo`). ``simulate``, ``run`` and ``sweep`` all
call it, so every command runs in either.
"""

from __future__ import annotations

from lcc_synth.controllers.base import Controller
from lcc_synth.simulation.results import SimResult
from lcc_synth.simulation.scenario import BACKENDS, Draws, Scenario

__all__ = ["BACKENDS", "check_backend", "run_scenario"]


def check_backend(scenario: Scenario) -> None:
    """Fail early (before controllers are built or tasks sent) when the scenario's simulator
    is not installed: :class:`~lcc_synth.errors.ConfigError` naming ``scenario.backend``."""
    if scenario.backend == "sumo":
        from lcc_synth.simulation.sumo_net import netconvert_binary, require_sumo

        require_sumo()
        netconvert_binary()


def run_scenario(
    scenario: Scenario, controller: Controller, draws: Draws | None = None
) -> SimResult:
    """Run ``controller`` on ``scenario`` in the simulator of ``scenario.backend``.

    Parameters
    ----------
    scenario : Scenario
    controller : Controller
    draws : Draws, optional
        Per-vehicle draws (default ``scenario.draw()``); the same draws give every controller
        the same scenarios in either simulator.

    Returns
    -------
    SimResult

    Raises
    ------
    ConfigError
        ``scenario.backend = "sumo"`` without SUMO installed (``pip install -e ".[sumo]"``).

    Notes
    -----
    A controller switched on at a time (``start``) runs in either simulator: before the switch
    the CAV drives as an HDV, built in with its HDV law, in SUMO released to SUMO's
    car-following model (:mod:`lcc_synth.simulation.sumo_drive`).
    """
    if scenario.backend == "sumo":
        from lcc_synth.simulation.sumo import simulate_sumo

        return simulate_sumo(scenario, controller, draws)
    from lcc_synth.simulation.engine import simulate

    return simulate(scenario, controller, draws)
