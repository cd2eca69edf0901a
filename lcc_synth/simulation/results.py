"""The result of a simulation: trajectories, CAV commands, collisions, what was simulated."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from lcc_synth.models.records import Record
from lcc_synth.simulation.scenario import Draws, Scenario

__all__ = ["SimResult"]


@dataclass(repr=False)
class SimResult(Record):
    """Trajectories of a batch of runs with one controller.

    Attributes
    ----------
    t : numpy.ndarray
        ``(T,)`` recorded sample times.
    position, velocity, acceleration, spacing : numpy.ndarray
        ``(batch, T, n_vehicles)``, columns head, HDVs ahead, CAV, HDVs behind. ``acceleration``
        is the applied one (after limits, emergency braking, perturbations); ``spacing[..., 0]``
        is NaN. After a collision every later sample of that scenario is NaN.
    u_cmd : numpy.ndarray
        ``(batch, T)`` CAV command before limits and emergency braking (held between samples).
    aeb_active : numpy.ndarray
        ``(batch, T)`` bool, the CAV's emergency braking overrode the command.
    collided, collision_time : numpy.ndarray
        ``(batch, n_vehicles)``: vehicle reached spacing <= 0, and when (NaN if never).
    m, n, cav : int
        Layout and the CAV's column.
    v_star, s_star : numpy.ndarray
        ``(batch,)`` nominal equilibrium.
    controller, controller_info, controller_stats
        Name, ``describe()`` and ``stats()`` of the controller.
    dt, sim_dt : float
        Spacing of the recorded samples and simulation step.
    scenario, draws
        What was simulated (per-vehicle parameters, delays, initial spacings).
    wall_time : float
        Seconds spent in :func:`simulate`.
    """

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    spacing: np.ndarray
    u_cmd: np.ndarray
    aeb_active: np.ndarray
    collided: np.ndarray
    collision_time: np.ndarray
    m: int
    n: int
    cav: int
    v_star: np.ndarray
    s_star: np.ndarray
    controller: str
    controller_info: dict[str, Any]
    controller_stats: dict[str, Any]
    dt: float
    sim_dt: float
    scenario: Scenario | None = None
    draws: Draws | None = None
    wall_time: float = 0.0

    @property
    def batch(self) -> int:
        return self.position.shape[0]

    @property
    def n_vehicles(self) -> int:
        return self.position.shape[2]

    def collision_report(self) -> list[str]:
        """One line per scenario of the batch that had a collision: which vehicle hit which,
        and when (``scenario i:`` prefixed, ``i`` its index in the study, when the batch has
        several or starts past the first)."""
        labels = self.vehicle_labels()

        def who(j: int) -> str:
            if j == 0:
                return "the head vehicle"
            return "the CAV" if j == self.cav else f"HDV {labels[j]}"

        first = self.scenario.first_index if self.scenario is not None else 0
        out = []
        for b in np.flatnonzero(self.collided.any(axis=1)):
            hits = [
                f"{who(j)} hit {who(j - 1)} at t = {self.collision_time[b, j]:.2f} s"
                for j in np.flatnonzero(self.collided[b])
            ]
            prefix = f"scenario {first + b}: " if self.batch > 1 or first else ""
            out.append(prefix + ", ".join(hits))
        return out

    def vehicle_labels(self) -> list[str]:
        """``head, -m, ..., -1, CAV, 1, ..., n``."""
        return ["head", *[str(i) for i in range(-self.m, 0)], "CAV"] + [
            str(i) for i in range(1, self.n + 1)
        ]
