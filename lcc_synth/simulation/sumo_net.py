"""What the SUMO backend builds before it runs: its settings (:class:`SumoSettings`, the
``[scenario.sumo]`` table), the check that a scenario can run in SUMO at all
(:func:`check_sumo_scenario`), the roads (:func:`straight_road`, :func:`ring_road`, built by
SUMO's own ``netconvert`` from plain XML nodes and edges) and the vehicle types and vehicles of
the route file (:func:`vehicle_types`, :func:`route_file`).

Nothing here imports ``libsumo``: the module is usable (and its errors are raised) without
SUMO installed; :func:`require_sumo` is the one place that imports it. The run itself is
:func:`lcc_synth.simulation.sumo.simulate_sumo`.

Vehicle-type mapping from the ``[hdv]`` IDM parameters (``v0, T, s0, a, b, delta``) to SUMO's
``<vType>`` attributes, per ``car_following`` model:

========== ==================================================================================
IDM        ``carFollowModel="IDM" maxSpeed=v0 tau=T minGap=s0 accel=a decel=b delta=delta
           stepping=dt`` (no IDM sub-stepping at our step, see :mod:`.sumo`)
EIDM       the same attributes, ``carFollowModel="EIDM"``; SUMO's EIDM adds its own defaults
           (reaction and estimation errors, jerk limit, ...) and ``sigma`` (driver imperfection)
Krauss     ``carFollowModel="Krauss" maxSpeed=v0 tau=T minGap=s0 accel=a decel=b sigma=sigma``
           (``delta`` has no Krauss counterpart)
========== ==================================================================================

Every vehicle type also gets ``emergencyDecel = |a_min|`` (SUMO never brakes harder than it,
the built-in simulator clips every HDV at ``a_min``), ``speedFactor = 1`` and ``speedDev = 0``
(the desired speed is exactly ``v0``; SUMO's default draws a factor around 1 per vehicle),
``collisionMinGapFactor = 0`` (a collision is a gap below 0, as in the built-in simulator;
SUMO's IDM would otherwise report one below ``0.5 minGap``) and the vehicle ``length`` of the
settings. SUMO's gap is bumper to bumper (front of the follower to the rear of the leader) and
its IDM desired gap is ``minGap + max(0, v T + v dv / (2 sqrt(a b)))``; the built-in simulator's
spacing ``p[j-1] - p[j]`` has no vehicle length, so the SUMO backend places every front bumper
``length`` further back per vehicle and reports SUMO's gap as the spacing: ``s0`` is SUMO's
``minGap`` exactly and the length changes nothing but the road's length.
"""

from __future__ import annotations

import contextlib
import io
import math
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

from lcc_synth.errors import ConfigError
from lcc_synth.models.records import Record

__all__ = [
    "CAR_FOLLOWING",
    "STEP_METHODS",
    "SumoSettings",
    "check_sumo_scenario",
    "require_sumo",
    "netconvert_binary",
    "straight_road",
    "ring_road",
    "vehicle_types",
    "route_file",
]

#: SUMO car-following models the backend maps the ``[hdv]`` IDM parameters to.
CAR_FOLLOWING = ("IDM", "EIDM", "Krauss")
#: SUMO's integration schemes: ``euler`` (SUMO's default, semi-implicit: the position advances
#: with the new speed) or ``ballistic`` (``--step-method.ballistic``: with the mean speed).
STEP_METHODS = ("euler", "ballistic")

_INSTALL = 'install SUMO with pip install -e ".[sumo]" (eclipse-sumo, libsumo, sumolib)'


@dataclass(frozen=True, repr=False)
class SumoSettings(Record):
    """How the SUMO backend runs a scenario (``[scenario.sumo]``).

    Parameters
    ----------
    car_following : {"IDM", "EIDM", "Krauss"}
        SUMO's car-following model of the HDVs (parameters mapped from ``[hdv]``; module
        docstring).
    step_method : {"euler", "ballistic"}
        SUMO's position update (see :mod:`lcc_synth.simulation.sumo` for what it changes).
    sigma : float
        SUMO's driver imperfection in [0, 1] (Krauss, EIDM); must be 0 for the IDM, which has
        none.
    vehicle_length : float
        Length (m) of every vehicle in SUMO, > 0; spacings are bumper-to-bumper gaps, so it
        changes nothing but the road's length.
    """

    car_following: str = "IDM"
    step_method: str = "euler"
    sigma: float = 0.0
    vehicle_length: float = 5.0

    def __post_init__(self) -> None:
        if self.car_following not in CAR_FOLLOWING:
            raise ConfigError(
                "scenario.sumo.car_following",
                f"must be one of {list(CAR_FOLLOWING)} (SUMO's names), got {self.car_following!r}",
            )
        if self.step_method not in STEP_METHODS:
            raise ConfigError(
                "scenario.sumo.step_method",
                f"must be one of {list(STEP_METHODS)}, got {self.step_method!r}",
            )
        sigma = float(self.sigma)
        if not 0.0 <= sigma <= 1.0:
            raise ConfigError("scenario.sumo.sigma", f"must be in [0, 1], got {self.sigma!r}")
        if sigma > 0.0 and self.car_following == "IDM":
            raise ConfigError(
                "scenario.sumo.sigma",
                "SUMO's IDM has no driver imperfection (sigma); use car_following = \"EIDM\" "
                "or \"Krauss\", or sigma = 0",
            )
        length = float(self.vehicle_length)
        if not (0.0 < length < math.inf):
            raise ConfigError(
                "scenario.sumo.vehicle_length", f"must be > 0 m, got {self.vehicle_length!r}"
            )

    def toml_table(self) -> dict[str, Any]:
        """The ``[scenario.sumo]`` table."""
        return {
            "car_following": self.car_following,
            "step_method": self.step_method,
            "sigma": float(self.sigma),
            "vehicle_length": float(self.vehicle_length),
        }


def check_sumo_scenario(sc) -> None:
    """Raise :class:`ConfigError` for what a scenario asks and SUMO cannot reproduce.

    SUMO steps in whole milliseconds (``scenario.dt``: 0.0125 s would silently run at
    0.013 s), its car-following models need the ``[hdv]`` IDM parameters (no OVM in SUMO), react to
    the current state (no reaction delay: ``[scenario.delay] mean = 0``), take the HDVs'
    white acceleration noise (``hdv_accel_noise``) with SUMO's IDM only
    (:mod:`lcc_synth.simulation.sumo_drive`; Krauss and EIDM have their own imperfection,
    ``[scenario.sumo] sigma``) and brake by their own rules
    (``hdv_aeb = false``: eq. 29 is the CAV's). Nothing is ignored silently.
    """
    import numpy as np

    steps_ms = float(sc.dt) * 1000.0
    if abs(steps_ms - round(steps_ms)) > 1e-9 * max(1.0, steps_ms):
        raise ConfigError(
            "scenario.dt",
            f'must be a whole number of milliseconds with scenario.backend = "sumo" (SUMO '
            f"steps in ms: {sc.dt!r} s would run at {round(steps_ms) / 1000.0:g} s), e.g. "
            f"{math.floor(steps_ms) / 1000.0:g} or {math.ceil(steps_ms) / 1000.0:g}",
        )
    if getattr(sc, "accel_noise_uniform", 0.0) > 0.0:
        raise ConfigError(
            "scenario.accel_noise_uniform",
            'must be 0 with scenario.backend = "sumo" (SUMO\'s own imperfection: '
            "[scenario.sumo] sigma)",
        )
    if sc.hdv.name != "idm":
        raise ConfigError(
            "hdv.model",
            f'must be "idm" with scenario.backend = "sumo" (SUMO has no {sc.hdv.name.upper()}; '
            "its car-following models take the IDM parameters), or use backend = \"builtin\"",
        )
    if float(np.max(np.asarray(sc.delay, dtype=float), initial=0.0)) > 0.0 or sc.delay_spread:
        raise ConfigError(
            "scenario.delay.mean",
            'must be 0 with scenario.backend = "sumo": SUMO\'s car-following models react to '
            "the current state (no reaction delay to reproduce)",
        )
    if sc.hdv_accel_noise > 0.0 and sc.sumo.car_following != "IDM":
        raise ConfigError(
            "scenario.hdv_accel_noise",
            'must be 0 with scenario.backend = "sumo" unless [scenario.sumo] car_following = '
            f'"IDM" (got {sc.sumo.car_following!r}: its own imperfection, [scenario.sumo] '
            "sigma, acts after the follow speed the noise is added to)",
        )
    if sc.hdv_aeb:
        raise ConfigError(
            "scenario.hdv_aeb",
            'must be false with scenario.backend = "sumo": SUMO\'s HDVs brake by their own '
            "car-following model (emergency braking eq. 29 is the CAV's)",
        )


def require_sumo():
    """Import and return ``libsumo``; :class:`ConfigError` naming ``scenario.backend`` when
    SUMO is not installed.

    libsumo prints a pyarrow version note on stdout when it is imported next to a pyarrow it
    was not built against (Rerun's); SUMO's parquet output, which needs it, is not used here,
    and the note would corrupt ``--json`` output, so it is swallowed.
    """
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            import libsumo
    except ImportError as err:
        raise ConfigError(
            "scenario.backend",
            f'"sumo" needs SUMO, which is not installed here ({err}); {_INSTALL}, or use '
            'backend = "builtin"',
        ) from None
    return libsumo


def netconvert_binary() -> str:
    """Path of SUMO's ``netconvert`` (sumolib's lookup, then ``PATH``); :class:`ConfigError`
    naming ``scenario.backend`` when there is none."""
    path = None
    with contextlib.suppress(ImportError):
        import sumolib

        candidate = sumolib.checkBinary("netconvert")
        path = shutil.which(candidate) or (candidate if Path(candidate).is_file() else None)
    path = path or shutil.which("netconvert")
    if path is None:
        raise ConfigError("scenario.backend", f'"sumo" needs SUMO\'s netconvert; {_INSTALL}')
    return path


def _netconvert(directory: Path, stem: str, nodes: str, edges: str, *extra: str) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    nod, edg = directory / f"{stem}.nod.xml", directory / f"{stem}.edg.xml"
    net = directory / f"{stem}.net.xml"
    nod.write_text(f"<nodes>\n{nodes}</nodes>\n")
    edg.write_text(f"<edges>\n{edges}</edges>\n")
    cmd = [netconvert_binary(), "--node-files", str(nod), "--edge-files", str(edg),
           "--output-file", str(net), "--no-turnarounds", "true", "--offset.disable-normalization",
           "true", "--no-warnings", "true", *extra]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0 or not net.is_file():
        raise RuntimeError(f"netconvert failed ({done.returncode}): {done.stderr.strip()}")
    return net


def straight_road(length: float, speed: float, directory: str | Path) -> Path:
    """A straight single-lane road (edge ``road``) of ``length`` m and speed limit ``speed``
    (m/s), built by ``netconvert`` in ``directory``; returns the ``.net.xml`` path."""
    if not (length > 0 and speed > 0):
        raise ValueError(f"straight_road needs length > 0 and speed > 0, got {length}, {speed}")
    nodes = f'  <node id="start" x="0" y="0"/>\n  <node id="end" x="{length:.3f}" y="0"/>\n'
    edges = (f'  <edge id="road" from="start" to="end" numLanes="1" speed="{speed:.3f}"/>\n')
    return _netconvert(Path(directory), "road", nodes, edges)


def ring_road(circumference: float, speed: float, directory: str | Path, segments: int = 4):
    """A single-lane ring road of ``circumference`` m (``segments`` edges ``ring0..``, joined
    end to end on a circle), built by ``netconvert`` in ``directory``; returns the
    ``.net.xml`` path. The length of each edge is set to ``circumference / segments`` (the
    chord geometry is only drawn; written to 1e-9 m: ``--precision 9``, netconvert's default
    is 0.01 m) and the junctions have no internal lanes
    (``--no-internal-links``: netconvert would otherwise add a 2.6 m curve per junction, with a
    turning-radius speed limit), so distances along the ring are exact: a vehicle leaves the end
    of edge ``ring<i>`` onto the start of ``ring<i+1>``."""
    if not (circumference > 0 and speed > 0) or segments < 2:
        raise ValueError("ring_road needs circumference > 0, speed > 0 and segments >= 2")
    r = circumference / (2.0 * math.pi)
    nodes = "".join(
        f'  <node id="n{i}" x="{r * math.cos(2 * math.pi * i / segments):.3f}" '
        f'y="{r * math.sin(2 * math.pi * i / segments):.3f}"/>\n'
        for i in range(segments)
    )
    seg = circumference / segments
    edges = "".join(
        f'  <edge id="ring{i}" from="n{i}" to="n{(i + 1) % segments}" numLanes="1" '
        f'speed="{speed:.3f}" length="{seg:.9f}"/>\n'
        for i in range(segments)
    )
    return _netconvert(Path(directory), "ring", nodes, edges, "--no-internal-links", "true",
                       "--precision", "9")


def _attrs(values: dict[str, Any]) -> str:
    out = []
    for k, v in values.items():
        text = f"{v:.17g}" if isinstance(v, float) else str(v)
        out.append(f"{k}={quoteattr(text)}")
    return " ".join(out)


def vehicle_types(settings: SumoSettings, idm: dict[str, float], dt: float, a_min: float):
    """The ``<vType>`` attributes of one HDV with IDM parameters ``idm`` (``v0, T, s0, a, b,
    delta``) under ``settings.car_following`` (module docstring)."""
    common = {
        "length": float(settings.vehicle_length),
        "minGap": float(idm["s0"]),
        "maxSpeed": float(idm["v0"]),
        "accel": float(idm["a"]),
        "decel": float(idm["b"]),
        "emergencyDecel": max(abs(float(a_min)), float(idm["b"])),
        "tau": float(idm["T"]),
        "speedFactor": 1.0,
        "speedDev": 0.0,
        "collisionMinGapFactor": 0.0,
    }
    model = settings.car_following
    if model == "Krauss":
        return {"carFollowModel": "Krauss", **common, "sigma": float(settings.sigma)}
    out = {"carFollowModel": model, **common, "delta": float(idm["delta"]), "stepping": float(dt)}
    if model == "EIDM":
        out["sigma"] = float(settings.sigma)
    return out


def route_file(
    path: str | Path,
    types: list[dict[str, Any]],
    departures: list[tuple[float, float]],
    edges: str = "road",
    routes: list[tuple[str, int]] | None = None,
) -> Path:
    """Write a route file: vehicle ``j`` (id ``v<j>``, type ``t<j>`` with attributes
    ``types[j]``) departs at time 0 at lane position ``departures[j][0]`` (its front bumper,
    m) with speed ``departures[j][1]`` (m/s) on the route ``edges``, without SUMO's insertion
    checks (the scenario's initial state is inserted as it is).

    ``routes`` (one per vehicle) gives each vehicle its own route instead: ``(edges, repeat)``,
    the edges from the one it departs on, driven ``1 + repeat`` times over (SUMO's route
    ``repeat`` attribute, the maintainers' way of looping a vehicle on a closed route:
    eclipse/sumo#7127); a ring's vehicles loop with it."""
    lines = ["<routes>"]
    for j, attrs in enumerate(types):
        lines.append(f'  <vType id="t{j}" {_attrs(attrs)}/>')
    if routes is None:
        lines.append(f'  <route id="route" edges="{edges}"/>')
    for j, (pos, speed) in enumerate(departures):
        head = (f'  <vehicle id="v{j}" type="t{j}" depart="0" departPos="{pos:.17g}" '
                f'departSpeed="{speed:.17g}" insertionChecks="none"')  # fmt: skip
        if routes is None:
            lines.append(f'{head} route="route"/>')
        else:
            own, repeat = routes[j]
            lines.append(f'{head}>\n    <route edges="{own}" repeat="{int(repeat)}"/>\n'
                         "  </vehicle>")  # fmt: skip
    lines.append("</routes>")
    path = Path(path)
    path.write_text("\n".join(lines) + "\n")
    return path
