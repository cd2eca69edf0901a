"""The result of a simulation: trajectories, CAV commands, collisions, what was simulated."""

from __future__ import annotations

from dataclasses import dataclass, field
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
        ``(batch, T, n_vehicles)``, columns head, HDVs ahead, CAV, HDVs behind (a platoon:
        head, positions 1..N; a ring: positions 1..N). ``acceleration`` is the applied one
        (after limits, emergency braking, perturbations); ``spacing[..., 0]`` is NaN (the
        head's; on a ring the gap of position 1 to position N). Positions are not wrapped on
        the ring. After a collision every later sample of that scenario is NaN.
    u_cmd : numpy.ndarray
        ``(batch, T)`` CAV command before limits and emergency braking (held between samples);
        ``(batch, T, n_cav)`` (``cavs`` order) when there are several CAVs.
    aeb_active : numpy.ndarray
        ``(batch, T)`` bool, the CAV's emergency braking overrode the command;
        ``(batch, T, n_cav)`` with several CAVs.
    collided, collision_time : numpy.ndarray
        ``(batch, n_vehicles)``: vehicle reached spacing <= 0, and when (NaN if never).
    m, n, cav : int
        Layout and the (first) CAV's column.
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
    cavs : tuple of int
        Every CAV's column (default ``(cav,)``).
    ring : bool
        A ring road (no head; column 0 follows the last column).
    circumference : float
        Ring length (m) of the road, vehicle lengths included; NaN on an open road.
    vehicle_length : float
        Length (m) of every vehicle: ``spacing`` is the bumper-to-bumper gap and ``position``
        the front bumper on the road (column ``j`` is ``j * vehicle_length`` behind where the
        gap coordinates put it).
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
    # not in the one-line repr (the scenario shown there holds the layout)
    cavs: tuple[int, ...] | None = field(default=None, repr=False)
    ring: bool = field(default=False, repr=False)
    circumference: float = field(default=float("nan"), repr=False, compare=False)
    vehicle_length: float = field(default=0.0, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.cavs is None:
            self.cavs = (int(self.cav),)

    @property
    def n_cav(self) -> int:
        """Number of CAVs."""
        return len(self.cavs)

    def u_columns(self) -> np.ndarray:
        """``u_cmd`` as ``(batch, T, n_cav)`` whatever the number of CAVs."""
        u = np.asarray(self.u_cmd)
        return u[:, :, None] if u.ndim == 2 else u

    def aeb_columns(self) -> np.ndarray:
        """``aeb_active`` as ``(batch, T, n_cav)`` whatever the number of CAVs."""
        a = np.asarray(self.aeb_active)
        return a[:, :, None] if a.ndim == 2 else a

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
            if self.cavs != (self.cav,) or self.ring:
                return f"vehicle {labels[j]}"
            if j == 0:
                return "the head vehicle"
            return "the CAV" if j == self.cav else f"HDV {labels[j]}"

        first = self.scenario.first_index if self.scenario is not None else 0
        out = []
        for b in np.flatnonzero(self.collided.any(axis=1)):
            hits = [
                f"{who(j)} hit {who((j - 1) % self.n_vehicles)} at t = "
                f"{self.collision_time[b, j]:.2f} s"
                for j in np.flatnonzero(self.collided[b])
            ]
            prefix = f"scenario {first + b}: " if self.batch > 1 or first else ""
            out.append(prefix + ", ".join(hits))
        return out

    def vehicle_labels(self) -> list[str]:
        """``head, -m, ..., -1, CAV, 1, ..., n``; a platoon ``head, 1, ..., N`` and a ring
        ``1, ..., N`` (positions) with a CAV's as ``CAV i``."""
        if self.scenario is not None and self.scenario.layout is not None:
            off = 1 if self.ring else 0
            return [
                ("head" if j == 0 and not self.ring else
                 f"CAV {j + off}" if j in self.cavs else str(j + off))
                for j in range(self.n_vehicles)
            ]  # fmt: skip
        return ["head", *[str(i) for i in range(-self.m, 0)], "CAV"] + [
            str(i) for i in range(1, self.n + 1)
        ]
