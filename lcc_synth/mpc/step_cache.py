"""Small exact shortcuts of the MPC's per-step bookkeeping (:mod:`lcc_synth.mpc.controller`).

A control step of the n = 10, N = 50 MPC takes about 0.3 ms, of which OSQP's own solve is
0.24 ms (``benchmarks/bench_mpc.py``); the rest is Python. These helpers take the same values
with less of it, bit for bit:

- :func:`clip` is ``float(np.clip(v, lo, hi))`` for a scalar without building numpy scalars
  (about 5 us each, several per step). ``np.clip`` is ``minimum(maximum(v, lo), hi)`` and only
  selects one of its arguments, as ``min(max(v, lo), hi)`` does; a NaN ``v`` stays NaN in both.
- :class:`LastValue` remembers the HDV model's equilibrium spacing at the last equilibrium
  velocity: ``v_eq`` is a moving average that stays exactly constant while the reference
  vehicle cruises, and the model's spacing law (with its argument checks) costs about 10 us.

(``tests/test_mpc_speed.py`` checks both against the expressions they replace.)
"""

from __future__ import annotations

import math

__all__ = ["clip", "LastValue"]


def clip(v: float, lo: float, hi: float) -> float:
    """``float(np.clip(v, lo, hi))`` for scalars with ``lo <= hi`` (NaN stays NaN).

    Parameters
    ----------
    v, lo, hi : float
        Value and bounds.

    Returns
    -------
    float
    """
    return float(min(max(v, lo), hi))


class LastValue:
    """``float(hdv.equilibrium_spacing(v))``, recomputed only when ``v`` or ``hdv`` changes.

    State is real here: one instance per batch member holds the last argument and value.
    """

    __slots__ = ("_hdv", "_v", "_s")

    def __init__(self) -> None:
        self._hdv = None
        self._v = math.nan
        self._s = math.nan

    def get(self, hdv, v: float) -> float:
        """The equilibrium spacing of ``hdv`` at ``v`` (m).

        Parameters
        ----------
        hdv : lcc_synth.models.hdv.CarFollowingModel
            The nominal HDV model.
        v : float
            Velocity (m/s), already clipped to the model's range.

        Returns
        -------
        float
        """
        if v != self._v or hdv is not self._hdv:  # NaN never matches: recomputed (and raises)
            self._s = float(hdv.equilibrium_spacing(v))
            self._v, self._hdv = v, hdv
        return self._s
