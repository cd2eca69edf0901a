"""Where the SUMO backend puts the string: the road (an open straight road or the ring, built
by ``netconvert`` once per size and process), every vehicle's departure, its route, and the map
from what SUMO reports back to the built-in simulator's unwrapped frame.

Frames. The built-in simulator has point vehicles: column ``j`` at ``p_j`` (head, or the ring's
column 0, at 0), spacing ``p_{j-1} - p_j``. SUMO's vehicles have a length ``L``
(``[scenario.sumo] vehicle_length``) and SUMO's gap is bumper to bumper. Column ``j``'s front
bumper goes to SUMO position ``x_j = origin + p_j - j L`` and back again with
``p_j = x_j + j L - origin``, so SUMO's gap ``x_{j-1} - L - x_j`` *is* the spacing
``p_{j-1} - p_j`` and the length changes nothing but the road's length.

* Open road: one edge ``road``, long enough for the head's prescribed motion plus the string
  plus margins; ``x`` is SUMO's lane position.
* Ring (``kind = "ring"``): the scenario's circumference ``C`` is the built-in ring's, i.e. the
  sum of the gaps; SUMO's ring is ``C + N L`` long (``N`` vehicles) so that column 0's gap to
  column ``N - 1`` across the seam, ``x_{N-1} + C + N L - L - x_0``, is the built-in
  ``p_{N-1} + C - p_0``. It is :func:`~lcc_synth.simulation.sumo_net.ring_road` with 4 edges
  of ``(C + N L) / 4`` and no junction lanes; each vehicle's route starts at the edge it
  departs on and repeats the ring's 4 edges ``laps`` times (SUMO's route ``repeat``), enough
  for the run at the road's speed limit, so the vehicles loop for the whole run. Laps are
  tracked exactly: the vehicle's unwrapped SUMO position is
  ``(first edge + route index) x edge length + lane position`` (SUMO's route index counts the
  edges driven), never wrapped, as the built-in simulator's positions.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lcc_synth.models.records import Record
from lcc_synth.simulation.sumo_net import ring_road, straight_road

__all__ = ["RING_EDGES", "MARGIN", "SumoRoad", "place_string", "work_dir"]

#: Edges of the SUMO ring.
RING_EDGES = 4
#: Free road (m) before the tail and after the head's furthest position (open road).
MARGIN = 50.0

_NETS: dict[tuple[str, float, float], Path] = {}
_DIR: tempfile.TemporaryDirectory | None = None


def work_dir() -> Path:
    """This process's temporary directory for SUMO's files (removed at exit)."""
    global _DIR
    if _DIR is None:
        _DIR = tempfile.TemporaryDirectory(prefix="lcc-sumo-")
    return Path(_DIR.name)


def _net(kind: str, length: float, speed: float) -> Path:
    key = (kind, float(length), float(speed))
    if key not in _NETS:
        where = work_dir() / f"{kind}_{len(_NETS)}"
        if kind == "ring":
            _NETS[key] = ring_road(key[1], key[2], where, segments=RING_EDGES)
        else:
            _NETS[key] = straight_road(key[1], key[2], where)
    return _NETS[key]


@dataclass(frozen=True, repr=False)
class SumoRoad(Record):
    """One scenario's road in SUMO and the map back to the built-in frame.

    Attributes
    ----------
    net : pathlib.Path
        The ``.net.xml`` file.
    lane_pos : list of float
        Every vehicle's departure lane position (its front bumper, m) on its first edge.
    routes : list of (str, int) or None
        Every vehicle's route and repeat count (ring), ``None`` on the open road (edge
        ``road``).
    shift : numpy.ndarray
        ``(nv,)``: built-in position = unwrapped SUMO position + ``shift``.
    first_edge : numpy.ndarray
        ``(nv,)`` index of each vehicle's first ring edge (0 on the open road).
    edge_length : float
        Length of a ring edge (m; NaN on the open road).
    """

    net: Path
    lane_pos: list[float]
    routes: list[tuple[str, int]] | None
    shift: np.ndarray
    first_edge: np.ndarray
    edge_length: float

    @property
    def ring(self) -> bool:
        """Whether the road is the ring."""
        return self.routes is not None

    def to_builtin(self, route_index: np.ndarray, lane_pos: np.ndarray) -> np.ndarray:
        """Built-in (unwrapped, point-vehicle) positions from SUMO's route indices and lane
        positions."""
        if not self.ring:
            return lane_pos + self.shift
        return (self.first_edge + route_index) * self.edge_length + lane_pos + self.shift


def place_string(p: np.ndarray, length: float, ring_length: float | None, travel: float,
                 speed: float, duration: float) -> SumoRoad:  # fmt: skip
    """The road and departures of a string whose built-in positions are ``p`` (column 0 at
    0, decreasing).

    Parameters
    ----------
    p : numpy.ndarray
        ``(nv,)`` initial built-in positions.
    length : float
        SUMO vehicle length ``L`` (m).
    ring_length : float or None
        The built-in ring's circumference ``C`` (None: the open road).
    travel : float
        Distance (m) the head covers in the run (open road).
    speed : float
        The road's speed limit (m/s; bounds every vehicle's speed: the ring's laps).
    duration : float
        Length of the run (s).

    Returns
    -------
    SumoRoad
    """
    nv = p.shape[0]
    j = np.arange(nv)
    if ring_length is None:
        origin = MARGIN - float(p[-1]) + nv * length
        road_len = math.ceil((origin + travel + 2 * MARGIN) / 100.0) * 100.0
        x = origin + p - j * length
        return SumoRoad(_net("road", road_len, speed), [float(v) for v in x], None,
                        j * length - origin, np.zeros(nv, dtype=np.int64), math.nan)  # fmt: skip
    seg = float(f"{(float(ring_length) + nv * length) / RING_EDGES:.9f}")  # as netconvert's
    C = RING_EDGES * seg
    # column N-1's front bumper halfway into column 0's free gap behind the seam at 0, so
    # that every front bumper lies in [0, C)
    gap0 = float(p[-1]) + float(ring_length) - float(p[0])
    origin = 0.5 * (gap0 + length) - float(p[-1]) + (nv - 1) * length
    x = origin + p - j * length
    first = np.minimum(np.floor(x / seg).astype(np.int64), RING_EDGES - 1)
    lane = x - first * seg
    laps = math.ceil(duration * speed / C) + 2
    routes = [(" ".join(f"ring{(int(e) + i) % RING_EDGES}" for i in range(RING_EDGES)), laps)
              for e in first]  # fmt: skip
    return SumoRoad(_net("ring", C, speed), [float(v) for v in lane], routes,
                    j * length - origin, first, seg)  # fmt: skip
