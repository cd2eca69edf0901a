"""The ``[synthesis]`` table of a platoon or ring problem (``[system] kind = "platoon" | "ring"``).

.. code-block:: toml

    [synthesis]
    design = "structured"     # "full_state" (Riccati) | "structured" (per-CAV row patterns)
                              # | "sparsity" (greedy per-CAV range Pareto: platoon_sparsity)
    semantics = "replace"     # default "replace" (u = K x is the CAV's whole acceleration)
    comm_range = 5            # every CAV hears the R vehicles ahead and the R behind it
                              # (itself included; the ring wraps around); 0 = decentralised
    tol = 1e-7
    max_iter = 500

    [synthesis.patterns]      # per-CAV lists of heard vehicle positions (override comm_range;
    u_3 = [1, 2, 3, 4]        # the CAV itself is always heard)

    [synthesis.weights]       # q_s, q_s0 (the CAVs' own spacings), q_v, q_a, r, head, accel

    [synthesis.sparsity]      # design = "sparsity": only max_loss applies
    max_loss = 0.01           # chosen: fewest heard vehicles with H2 <= (1 + max_loss) H2*

    [synthesis.robust]        # one gain for a set of sampled HDV parameter sets
    samples = 20
    seed = 0
    objective = "mean"        # "mean" | "worst" (smooth maximum)
    alpha = [0.4, 0.8]        # uniform draw per vehicle and member; absent: the nominal value
    beta = [0.7, 1.1]
    s_go = [30.0, 40.0]

Neither comm_range nor patterns: every CAV hears every vehicle (the full-information optimum).
The single-CAV keys ``pattern`` (other than "all"), ``cross_check``, ``band``, ``sparsity``,
``string``, ``baseline`` and ``as_run`` do not apply and are named errors.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.platoon import Platoon
from lcc_synth.models.records import Record, system_tables, toml_text
from lcc_synth.problem import System
from lcc_synth.schema import declared
from lcc_synth.synthesis.h2 import Weights

__all__ = [
    "PLATOON_DESIGNS",
    "RobustSettings",
    "PlatoonSynthesisSpec",
    "platoon_spec",
    "comm_range_pattern",
    "robust_members",
]

#: The designs a platoon or ring accepts.
PLATOON_DESIGNS = ("full_state", "structured", "sparsity")

_NOT_FOR_PLATOONS = ("cross_check", "band", "string", "baseline", "as_run")


@dataclass(frozen=True, repr=False)
class RobustSettings(Record):
    """``[synthesis.robust]``: the sampled member set and the objective.

    Attributes
    ----------
    samples, seed : int
    objective : {"mean", "worst"}
    ranges : dict
        HDV parameter name -> ``(lo, hi)`` of its uniform draw (per vehicle and member).
    """

    samples: int = 20
    seed: int = 0
    objective: str = "mean"
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)


@dataclass(frozen=True, repr=False)
class PlatoonSynthesisSpec(Record):
    """A parsed platoon / ring synthesis problem.

    Attributes
    ----------
    patterns : dict or None
        CAV position -> sorted heard positions (the CAV included); ``None``: full information.
    comm_range : int or None
        The communication range the patterns came from (``None``: lists or full).
    """

    name: str
    system: System
    design: str
    semantics: str
    weights: Weights
    patterns: dict[int, tuple[int, ...]] | None
    comm_range: int | None
    tol: float = 1e-7
    max_iter: int = 500
    robust: RobustSettings | None = None
    source: str | None = None
    max_loss: float = 0.01

    def toml_tables(self) -> dict[str, Any]:
        """``name``, ``[hdv]``, ``[system]`` and ``[synthesis]``: the tables
        :func:`~lcc_synth.synthesis.config.spec_from_problem` reads back into an equal spec."""
        t: dict[str, Any] = {
            "design": self.design,
            "semantics": self.semantics,
            "method": "riccati" if self.design == "full_state" else "direct",
            "tol": self.tol,
            "max_iter": self.max_iter,
            "weights": {k: v for k, v in asdict(self.weights).items()
                        if k not in ("position", "q_p")},  # fmt: skip
        }
        if self.comm_range is not None:
            t["comm_range"] = self.comm_range
        if self.patterns is not None:
            base = (comm_range_pattern(self.system.platoon, self.comm_range)
                    if self.comm_range is not None else {})  # fmt: skip
            own = {f"u_{i}": list(v) for i, v in self.patterns.items() if base.get(i) != v}
            if own:
                t["patterns"] = own
        if self.design == "sparsity":
            t["sparsity"] = {"max_loss": self.max_loss}
        if self.robust is not None:
            rb = self.robust
            t["robust"] = {"samples": rb.samples, "seed": rb.seed, "objective": rb.objective,
                           **{k: list(v) for k, v in rb.ranges.items()}}  # fmt: skip
        return {"name": self.name, **system_tables(self.system), "synthesis": t}

    def to_toml(self) -> str:
        """This spec as a problem file (:meth:`toml_tables`)."""
        return toml_text(self.toml_tables())


def comm_range_pattern(platoon: Platoon, R: int) -> dict[int, tuple[int, ...]]:
    """Each CAV's heard positions for communication range ``R``: the ``R`` vehicles ahead,
    the ``R`` behind and itself (ring: wrapping around, at most every vehicle once; open
    platoon: clipped to ``1..N``)."""
    if isinstance(R, bool) or not isinstance(R, int | np.integer) or R < 0:
        raise ConfigError("synthesis.comm_range", f"must be an integer >= 0, got {R!r}")
    N = platoon.size
    out = {}
    for i in platoon.cavs:
        if platoon.ring:
            heard = {(i - 1 + d) % N + 1 for d in range(-R, R + 1)}
        else:
            heard = {j for j in range(i - R, i + R + 1) if 1 <= j <= N}
        out[i] = tuple(sorted(heard))
    return out


def _patterns(t: dict, platoon: Platoon) -> tuple[dict[int, tuple[int, ...]] | None, int | None]:
    T = declared("synthesis")
    R = T.get(t, "comm_range", "synthesis")
    pat = T.get(t, "patterns", "synthesis")
    raw = T.raw(t, "pattern")
    if raw != "all":
        raise ConfigError("synthesis.pattern", 'platoons and rings take comm_range or '
                          '[synthesis.patterns] (u_i = [positions]); pattern must be "all"')
    out = comm_range_pattern(platoon, R) if R is not None else None
    if not pat:
        return out, R
    PT = declared("synthesis.patterns")
    names = [f"u_{i}" for i in platoon.cavs]
    for u in pat:
        if u not in names:
            raise ConfigError(f"synthesis.patterns.{u}", f"not a CAV input: this platoon's CAVs "
                              f"are {names} (positions {list(platoon.cavs)})")  # fmt: skip
    N = platoon.size
    lists = PT.get_each(pat, "synthesis.patterns")
    full = {i: tuple(range(1, N + 1)) for i in platoon.cavs}
    out = dict(out or full)
    for u, vals in lists.items():
        orig = pat[u]
        i = int(u[2:])
        bad = [v for v in orig if isinstance(v, bool) or not isinstance(v, int)
               or not 1 <= v <= N]  # fmt: skip
        if bad or not vals:
            raise ConfigError(f"synthesis.patterns.{u}", f"must be a non-empty list of vehicle "
                              f"positions in [1, {N}], got {orig!r}")  # fmt: skip
        out[i] = tuple(sorted(set(orig) | {i}))
    return out, R


def _robust(t: dict, system: System) -> RobustSettings | None:
    T = declared("synthesis")
    r = T.get(t, "robust", "synthesis")
    if not r:
        return None
    f = "synthesis.robust"
    RB = declared("synthesis.robust")
    RB.check(r, f)
    ranges = {}
    params = {fl.name for fl in fields(system.hdv)}
    for key in ("alpha", "beta", "s_go"):
        v = RB.get(r, key, f)
        if v is None:
            continue
        if key not in params:
            raise ConfigError(f"{f}.{key}", f"the [hdv] model {type(system.hdv).__name__} has "
                              f"no parameter {key!r} (robust sampling needs the OVM)")  # fmt: skip
        lo, hi = v
        if not lo <= hi:
            raise ConfigError(f"{f}.{key}", f"must be [lo, hi] with lo <= hi, got {v!r}")
        ranges[key] = (float(lo), float(hi))
    if not ranges:
        raise ConfigError(f, "give at least one of alpha, beta, s_go as [lo, hi]")
    return RobustSettings(RB.get(r, "samples", f), RB.get(r, "seed", f),
                          RB.get(r, "objective", f), ranges)  # fmt: skip


def robust_members(system: System, robust: RobustSettings) -> list[Platoon]:
    """The sampled platoons: every vehicle's ``ranges`` parameters drawn uniformly and
    independently per member (``numpy.random.default_rng(seed)``, vehicle-major order);
    the other parameters those of the nominal vehicle. A ring keeps the nominal ``v*`` (or
    the given circumference)."""
    base = system.platoon
    rng = np.random.default_rng(robust.seed)
    keys = list(robust.ranges)
    lo = np.array([robust.ranges[k][0] for k in keys])
    hi = np.array([robust.ranges[k][1] for k in keys])
    out = []
    for s in range(robust.samples):
        draw = rng.uniform(lo, hi, size=(base.size, len(keys)))
        try:
            models = tuple(replace(h, **{k: float(x) for k, x in zip(keys, row, strict=True)})
                           for h, row in zip(base.hdv, draw, strict=True))  # fmt: skip
            v_star = None if base.circumference is not None else base.v_star
            out.append(Platoon(models, base.cavs, v_star, base.ring, base.circumference,
                               base.vehicle_length))
        except ConfigError as err:
            raise ConfigError("synthesis.robust", f"member {s}: {err.field}: {err.message}"
                              ) from None  # fmt: skip
    return out


def platoon_spec(name: str, system: System, t: dict[str, Any], src: str) -> PlatoonSynthesisSpec:
    """Parse ``[synthesis]`` (already key-checked) for a platoon or ring ``system``."""
    T = declared("synthesis")
    for key in _NOT_FOR_PLATOONS:
        if key in t:
            raise ConfigError(f"synthesis.{key}", f"does not apply to kind = "
                              f"{system.kind!r} (single-CAV designs only)")  # fmt: skip
    design = T.get(t, "design", "synthesis")
    if design not in PLATOON_DESIGNS:
        raise ConfigError("synthesis.design", f"must be one of {list(PLATOON_DESIGNS)} for "
                          f"kind = {system.kind!r}, got {design!r}")  # fmt: skip
    semantics = T.get(t, "semantics", "synthesis", default="replace")
    T.get(t, "method", "synthesis", default="riccati" if design == "full_state" else "direct",
          choices=("riccati",) if design == "full_state" else ("direct",))  # fmt: skip
    if not system.platoon.cavs:
        raise ConfigError("system.cavs", "synthesis needs at least one CAV")
    patterns, R = _patterns(t, system.platoon)
    if design != "structured" and patterns is not None:
        raise ConfigError("synthesis.design", f"{design} chooses whom each CAV hears: drop "
                          "comm_range and [synthesis.patterns], or use design = 'structured'")
    SP = declared("synthesis.sparsity")
    sp = T.get(t, "sparsity", "synthesis")
    SP.check(sp, "synthesis.sparsity")
    for key in sp:
        if key != "max_loss":
            raise ConfigError(f"synthesis.sparsity.{key}", f"does not apply to kind = "
                              f"{system.kind!r} (only max_loss)")  # fmt: skip
    max_loss = SP.get(sp, "max_loss", "synthesis.sparsity")
    W = declared("synthesis.weights")
    w = T.get(t, "weights", "synthesis")
    W.check(w, "synthesis.weights")
    for key in ("position", "q_p"):
        if key in w:
            raise ConfigError(f"synthesis.weights.{key}", "applies to fd_lcc only")
    kw = {key: W.get(w, key, "synthesis.weights")
          for key in ("q_s", "q_s0", "q_v", "r", "q_a", "head", "accel")}  # fmt: skip
    if system.platoon.ring and kw["head"] > 0:
        raise ConfigError("synthesis.weights.head", "a ring has no head vehicle: set it to 0")
    if kw["head"] == 0 and kw["accel"] == 0:
        raise ConfigError("synthesis.weights", "head and accel cannot both be 0")
    weights = Weights(**kw)
    tol = T.get(t, "tol", "synthesis")
    max_iter = T.get(t, "max_iter", "synthesis")
    robust = _robust(t, system)
    return PlatoonSynthesisSpec(name, system, design, semantics, weights, patterns, R, tol,
                                max_iter, robust, src, max_loss)  # fmt: skip
