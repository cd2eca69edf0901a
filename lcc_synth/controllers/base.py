"""The controller interface shared by every CAV controller of the framework.

The simulator calls a controller with what the CAV can observe and applies the returned
acceleration command (then clips it to the acceleration limits and applies emergency braking).
All arrays carry a leading batch axis: one row per scenario advanced together.

Vehicle order everywhere: index 0 is the head vehicle, ``1..m`` the HDVs ahead of the CAV,
``m + 1`` the CAV, ``m + 2 .. m + n + 1`` the HDVs behind (front of the string to the tail).
The paper's vehicle index ``i`` (-m..n) is array column ``i + m + 1``.

Several CAVs (``[system] kind = "platoon" | "ring"``): :attr:`ControlContext.cavs` are the
CAV columns. Open platoon: column 0 is the head, column ``i`` position ``i`` (1..N). Ring:
column ``j`` is position ``j + 1`` (0..N-1), column 0 follows column N-1, there is no head,
and the spacing of column 0 is ``p[N-1] + C - p[0]``. ``m`` (first CAV column - 1) and ``n``
(columns after it) keep their meaning, so single-CAV code is unchanged. A controller returns
``(batch,)`` with one CAV and ``(batch, n_cav)`` (``cavs`` order) with several. The CAVs are
connected: every CAV's own spacing, velocity and position are exact in the observation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from lcc_synth.models.hdv import CarFollowingModel

__all__ = ["ControlContext", "Observation", "Controller"]


@dataclass(frozen=True)
class ControlContext:
    """What a controller learns once, when a run starts.

    Attributes
    ----------
    m, n : int
        HDVs ahead of and behind the CAV.
    batch : int
        Number of scenarios advanced together.
    dt : float
        Simulation step (s).
    v_star, s_star : numpy.ndarray
        ``(batch,)`` nominal equilibrium velocity and spacing used to form errors.
    a_min, a_max : float
        Acceleration limits (m/s^2) the simulator enforces.
    hdv : CarFollowingModel
        The nominal HDV model (the CAV's own "HDV law" for the ``added`` semantics).
    s_ref : numpy.ndarray, optional
        ``(batch, n_vehicles)`` spacing reference of each vehicle for its spacing error
        (e.g. each heterogeneous HDV's own equilibrium spacing at ``v*``); ``None`` means
        ``s_star`` for every vehicle. See :meth:`spacing_reference`.
    cavs : tuple of int, optional
        Array columns of the CAVs, front to tail; default ``(m + 1,)``.
    ring : bool
        A ring road (no head vehicle; column 0 follows the last column).
    circumference : float
        Ring length (m); NaN on an open road.
    cav_models : tuple of CarFollowingModel, optional
        Each CAV's own HDV law (``cavs`` order; a platoon slot's parameters); default ``hdv``
        for every CAV.
    """

    m: int
    n: int
    batch: int
    dt: float
    v_star: np.ndarray
    s_star: np.ndarray
    a_min: float
    a_max: float
    hdv: CarFollowingModel
    s_ref: np.ndarray | None = None
    cavs: tuple[int, ...] | None = None
    ring: bool = False
    circumference: float = float("nan")
    cav_models: tuple[CarFollowingModel, ...] | None = None

    def __post_init__(self) -> None:
        cavs = (self.m + 1,) if self.cavs is None else tuple(int(c) for c in self.cavs)
        object.__setattr__(self, "cavs", cavs)
        if self.cav_models is None:
            object.__setattr__(self, "cav_models", tuple(self.hdv for _ in cavs))

    @property
    def n_cav(self) -> int:
        """Number of CAVs."""
        return len(self.cavs)

    def ahead(self, column: int) -> int:
        """Column of the vehicle ahead of ``column`` (the last column for column 0 of a ring)."""
        return column - 1 if column > 0 else self.n_vehicles - 1

    def spacing_reference(self) -> np.ndarray:
        """``(batch, n_vehicles)`` reference of every spacing error (``s_ref`` or ``s_star``)."""
        if self.s_ref is not None:
            return self.s_ref
        return np.repeat(np.asarray(self.s_star, dtype=float)[:, None], self.n_vehicles, axis=1)

    @property
    def cav(self) -> int:
        """Array column of the CAV."""
        return self.m + 1

    @property
    def n_vehicles(self) -> int:
        """Vehicles in the string, head included."""
        return self.m + self.n + 2


@dataclass(frozen=True)
class Observation:
    """What the CAV knows at time ``t`` (after V2V loss, latency and noise).

    Attributes
    ----------
    t : float
        Simulated time (s).
    spacing, velocity : numpy.ndarray
        ``(batch, n_vehicles)``; every CAV's own entries are exact (the CAVs are connected),
        the others are the last values received. ``spacing[:, 0]`` (head vehicle) is NaN; on
        a ring it is the gap of position 1 to position N.
    position : numpy.ndarray
        ``(batch, n_vehicles)`` positions as received (used by FD-LCC's ``-p_0`` state).
    cav_acceleration : numpy.ndarray, optional
        ``(batch, n_cav)``: each CAV's own acceleration, the state of its actuator lag
        (``[scenario] cav_lag > 0``); ``None`` without lag (the CAV applies its command).
    """

    t: float
    spacing: np.ndarray
    velocity: np.ndarray
    position: np.ndarray
    cav_acceleration: np.ndarray | None = None


@runtime_checkable
class Controller(Protocol):
    """A CAV controller.

    ``sample_time`` is the controller's period (s); ``None`` means every simulation step.
    Between samples the simulator holds the last command (zero-order hold). A controller never
    raises inside the loop: it reports trouble through :meth:`stats` (e.g. MPC fallbacks).
    """

    name: str
    sample_time: float | None

    def reset(self, ctx: ControlContext) -> None:
        """Prepare for a run (allocate state for ``ctx.batch`` scenarios)."""

    def __call__(self, obs: Observation) -> np.ndarray:
        """Commanded CAV acceleration, shape ``(batch,)``; ``(batch, n_cav)`` with several CAVs."""

    def describe(self) -> dict[str, Any]:
        """Gains, weights, solver settings: JSON-serialisable, for reports and recordings."""

    def stats(self) -> dict[str, Any]:
        """Run statistics (fallbacks, solve times...); ``{}`` when there is nothing to say."""
