"""What the CAVs receive from the other vehicles (V2V): :class:`V2V`, the ``[scenario.v2v]``
model of :mod:`lcc_synth.simulation.scenario` (loss, latency, measurement noise)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.records import Record
from lcc_synth.problem import check_range

__all__ = ["V2V", "check_number"]


def check_number(name: str, value, lo=None, hi=None, lo_open=False) -> float:
    """``float(value)`` within ``[lo, hi]`` (``lo_open``: ``> lo``); ConfigError naming ``name``."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(name, f"must be a number, got {value!r}") from None
    return check_range(name, x, lo, hi, lo_open, shown=value)


@dataclass(frozen=True, repr=False)
class V2V(Record):
    """What the CAV receives from the other vehicles.

    Parameters
    ----------
    loss_rate : float or sequence of float
        Packet-loss probability in [0, 1], one for all links or one per vehicle column
        (head..tail; the CAV's entry is ignored).
    latency : float
        Age (s) of every received value, >= 0; rounded to simulation steps.
    spacing_noise, velocity_noise, position_noise : float
        Standard deviations of the measurement noise on received values, >= 0.
    """

    loss_rate: float | Sequence[float] = 0.0
    latency: float = 0.0
    spacing_noise: float = 0.0
    velocity_noise: float = 0.0
    position_noise: float = 0.0

    def __post_init__(self) -> None:
        rates = np.atleast_1d(np.asarray(self.loss_rate, dtype=float))
        if rates.ndim != 1 or not np.all(np.isfinite(rates)) or np.any((rates < 0) | (rates > 1)):
            raise ConfigError(
                "scenario.v2v.loss_rate", f"must be in [0, 1], got {self.loss_rate!r}"
            )
        check_number("scenario.v2v.latency", self.latency, lo=0.0)
        for key in ("spacing_noise", "velocity_noise", "position_noise"):
            check_number(f"scenario.v2v.{key}", getattr(self, key), lo=0.0)

    def toml_table(self) -> dict[str, Any]:
        """The ``[scenario.v2v]`` table."""
        rates = np.atleast_1d(np.asarray(self.loss_rate, dtype=float))
        loss = float(rates[0]) if np.ndim(self.loss_rate) == 0 else rates.tolist()
        return {"loss_rate": loss, "latency": float(self.latency),
                **{k: float(getattr(self, k))
                   for k in ("spacing_noise", "velocity_noise", "position_noise")}}  # fmt: skip

    def rates(self, nv: int) -> np.ndarray:
        """Per-column loss rates ``(nv,)``."""
        rates = np.atleast_1d(np.asarray(self.loss_rate, dtype=float))
        if rates.size == 1:
            return np.full(nv, float(rates[0]))
        if rates.size != nv:
            raise ConfigError(
                "scenario.v2v.loss_rate",
                f"needs 1 or {nv} entries (one per vehicle, head..tail), got {rates.size}",
            )
        return rates.copy()
