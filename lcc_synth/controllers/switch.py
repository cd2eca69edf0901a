"""Switching a controller on at a time: before ``start`` the CAVs drive with their HDV law.

The benchmark of the field (Stern et al. 2018; the Sugiyama ring) lets the wave form with every
vehicle human-driven, then switches one vehicle to its controller. :class:`SwitchedOn` wraps
any controller of the framework (a ``[controllers.NAME]`` table's ``start = 300.0``):

* before ``start`` every CAV drives with its own HDV law (its slot's car-following model on the
  exact state, as ``type = "hdv"`` does), inside the simulator's compiled loop;
* from the first controller sample at or after ``start`` the wrapped controller drives; it is
  reset when the run starts (so it knows the context) and called only from then on (a
  PI-with-saturation's speed window, an MPC's warm start, a CACC's state begin at the switch).
  A linear law (static gains, the HDV law) still runs in the compiled loop after the switch;
  any other controller is called from Python from then on.

The switch sample is ``ceil((start - t_start) / dt)`` rounded up to a multiple of the
controller's period (the simulator, :func:`~lcc_synth.simulation.engine.simulate`, does the
switching; :func:`switch_step` computes it). ``start`` at or before ``t_start`` is the wrapped
controller alone, bit for bit.
"""

from __future__ import annotations

import math
from typing import Any

from lcc_synth.controllers.base import ControlContext, Controller, Observation
from lcc_synth.errors import ConfigError

__all__ = ["SwitchedOn", "switch_step"]


def switch_step(start: float, t_start: float, dt: float, ratio: int, steps: int) -> int:
    """First simulation step (0-based, a multiple of the controller's ``ratio`` steps, at most
    ``steps``) at whose time ``t_start + k dt`` the controller switched on at ``start`` drives.

    Parameters
    ----------
    start : float
        Switch-on time (s).
    t_start : float
        Time of the first sample (s).
    dt : float
        Simulation step (s).
    ratio : int
        Controller period in steps (>= 1).
    steps : int
        Steps of the run (the switch never comes later than the end).
    """
    k = math.ceil((start - t_start) / dt - 1e-9)
    k = max(0, k)
    k = ratio * math.ceil(k / ratio)
    return min(k, steps)


class SwitchedOn:
    """``inner`` switched on at ``start`` s; before it the CAVs drive with their HDV law.

    Parameters
    ----------
    inner : Controller
        Any controller of the framework.
    start : float
        Switch-on time (s, finite).
    """

    def __init__(self, inner: Controller, start: float):
        t = float(start)
        if not math.isfinite(t):
            raise ConfigError(f"controllers.{inner.name}.start", f"must be finite, got {start!r}")
        self.inner = inner
        self.start = t
        self.name = inner.name
        self.sample_time = inner.sample_time
        law = getattr(inner, "linear_law", None)
        if callable(law):
            self.linear_law = law  # the compiled loop runs it after the switch

    def reset(self, ctx: ControlContext) -> None:
        """Reset the wrapped controller."""
        self.inner.reset(ctx)

    def __call__(self, obs: Observation):
        """The wrapped controller's command (the simulator calls it from the switch on)."""
        return self.inner(obs)

    def describe(self) -> dict[str, Any]:
        """The wrapped controller's description plus ``start``."""
        return {**self.inner.describe(), "start": self.start}

    def toml_table(self) -> dict[str, Any]:
        """The wrapped controller's ``[controllers.NAME]`` table plus ``start``."""
        return {**self.inner.toml_table(), "start": self.start}

    def as_dict(self) -> dict[str, Any]:
        """The wrapped controller's ``as_dict`` (what defines it, without run-time facts such
        as a set-up time) plus ``start``; :meth:`SwitchedOn.describe` when it has none."""
        inner = getattr(self.inner, "as_dict", None)
        base = inner() if callable(inner) else {"name": self.name, **self.inner.describe()}
        return {**base, "start": self.start}

    def stats(self) -> dict[str, Any]:
        """The wrapped controller's statistics."""
        return self.inner.stats()

    def __getattr__(self, key: str):
        if key == "inner":  # not yet set (copy, unpickling)
            raise AttributeError(key)
        return getattr(self.inner, key)
