"""The allowed range of a static feedback gain, shared by every reader of gains.

A gain is per unit: 1/s² on a spacing error, 1/s on a velocity error. Above
:data:`lcc_synth.problem.GAIN_LIMIT` (100) it is valid but implausible (a warning); beyond
:data:`GAIN_MAX` it is an error (:func:`valid_gain`):
:class:`~lcc_synth.models.feedback.Gains` refuses it, so a gain from a problem table, a
gains file or the API never reaches a computation its size would break. The schema declares the
same range on ``[controllers.NAME.gains]`` (``problems/REFERENCE.md``).
"""

from __future__ import annotations

import math

import numpy as np

from lcc_synth.errors import ConfigError

__all__ = ["GAIN_MAX", "SEMANTICS", "valid_gain"]

#: How a static gain enters each CAV's command (:class:`lcc_synth.models.feedback.Gains`):
#: ``"added"``: the CAV keeps its HDV law and ``K x`` is added (eq. 23); ``"replace"``:
#: ``u = K x`` is the whole acceleration.
SEMANTICS = ("added", "replace")

#: Largest magnitude of a gain. Beyond it the rounding of a state of order 10 (float64,
#: eps ≈ 2.2e-16) alone would move the command by more than 2e-3 m/s² (by the acceleration
#: limits themselves near 1e15: the command would be rounding noise), and the checks that square
#: the closed-loop eigenvalues overflow near 1e154 (a gain of -1e300 ended in an OverflowError).
GAIN_MAX = 1.0e12


def valid_gain(name: str, value: object) -> float:
    """``float(value)`` for a finite number of magnitude at most :data:`GAIN_MAX`, else a
    :class:`~lcc_synth.errors.ConfigError` naming ``name`` and the allowed range."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ConfigError(name, f"must be a number, got {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise ConfigError(name, f"must be finite, got {value!r}")
    if not -GAIN_MAX <= x <= GAIN_MAX:
        raise ConfigError(name, f"must be in [{-GAIN_MAX:g}, {GAIN_MAX:g}] (a gain per unit, "
                          f"1/s² or 1/s; above 100 is already implausible), got {x:g}")  # fmt: skip
    return x
