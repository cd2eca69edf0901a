"""The ``[synthesis]`` table of a problem file (``lcc-synth synthesize``) in both vocabularies,
one CAV (``m, n, pattern``) and a platoon or ring (``size, cavs, comm_range``), read by
:func:`synthesis_spec` into the one :class:`SynthesisSpec` (``PlatoonSynthesisSpec`` is
another name of it).

One CAV (``[system] kind = "cf_lcc" | "fd_lcc" | "lcc" | "ccc"``):

.. code-block:: toml

    [synthesis]
    design = "structured"     # "full_state" | "structured" | "sparsity" | "string_stable"
    semantics = "replace"     # "replace" | "added" (feedback.py, eq. 23); default: "replace"
                              # for fd_lcc/cf_lcc, "added" for lcc/ccc
    pattern = [1, 2]          # vehicles heard besides the CAV (structured, string_stable);
                              # "all" (default) = every vehicle of the string
    method = "lmi"            # structured: "lmi" (convex restriction + polish) | "direct"
                              # full_state: "riccati" | "lmi"
    cross_check = true        # full_state: also solve the other method and compare
    cav_lag = 0.0             # the CAV's actuator lag tau (s) in the plant (lag_design.py)
    tol = 1e-7                # polishing tolerance (relative gradient norm), in (0, 1e-2]
    max_iter = 500            # polishing iterations, >= 1
    band = 4                  # structured "lmi": coupling range (vehicles) of the non-heard
                              # block of X in the convex restriction, 0..50 (wider = tighter)

    [synthesis.weights]       # see lcc_synth.synthesis.h2.Weights
    q_s = 1.0                 # spacing errors, > 0
    q_s0 = 1.0                # the CAV's own spacing error s_0, > 0 (default: q_s); a stiff
                              # s_0 keeps the CAV's spacing when the head changes speed
    q_v = 1.0                 # velocity errors, > 0
    q_a = 0.0                 # every HDV's acceleration (smooth driving / fuel proxy), >= 0
    q_p = 0.1                 # FD-LCC -p_0 when position = "weight", > 0
    r = 1.0                   # the gain's input, > 0
    head = 0.0                # head-vehicle velocity disturbance, >= 0
    accel = 1.0               # acceleration noise on every velocity state, >= 0
    position = "drop"         # FD-LCC position state: "drop" | "weight"

    [synthesis.sparsity]      # design = "sparsity"
    gammas = [0.1, 1.0]       # penalties >= 0 (default: n_gamma log-spaced values x J*)
    n_gamma = 12              # 2..60
    reweight = true           # group weights from the unstructured optimum
    rho = 10.0                # ADMM penalty parameter, > 0
    max_loss = 0.01           # chosen gain: fewest vehicles with H2 <= (1 + max_loss) H2*

    [synthesis.string]        # design = "string_stable"
    gamma = 1.0               # H-infinity bound on head -> tail, >= 1
    polish_steps = 200        # string-stable-feasible polishing iterations, >= 0
    margin = 1e-4             # relative string-stability margin every polishing step keeps,
                              # [0, 0.1] (string_stability's margin; the verdict's band ~1e-11)

    [synthesis.as_run]        # optional: design the loop as it runs (synthesis/as_run.py);
                              # `as_run = true` = this table with its defaults
    equilibrium = "estimated" # "fixed" | "estimated" (the controller's equilibrium)
    equilibrium_tau = 1.0     # s, > 0, with "estimated"
    sample_time = 0.1         # controller period (s); default: every simulator step dt
    dt = 0.01                 # simulator step (s)
    latency = 0.0             # V2V latency (s) of the string check, a multiple of the period
    measurement_filter = 0.0  # s, 0 = off
    margin = 1e-3             # relative as-run string-stability margin of accepted steps
    weight = 0.0              # trade-off weight on the as-run amplification, >= 0
    polish_steps = 200        # as-run-string-stable polishing iterations, >= 0

    [synthesis.baseline]      # optional: compare with hand-picked gains (e.g. the paper's);
                              # an unstable one is reported (H2 inf), not refused
    name = "paper"
    semantics = "replace"
    gains = { v_0 = -0.5, s_1 = -0.2, v_1 = 0.05, s_2 = -0.1, v_2 = 0.05 }

    [synthesis.robust]        # optional, lcc / cf_lcc / ccc: one gain for sampled HDV
                              # parameter sets, the keys of the platoon's table below
                              # (robust_string.py)

``[synthesis.robust]`` on one CAV runs the platoon's robust design on the string's one-CAV
platoon (``lcc_synth.synthesis.robust_string``): designs ``full_state`` and ``structured``
(method ``riccati`` / ``direct``), the CAV's whole command designed and written in the file's
``semantics`` (``"added"``: minus the CAV's nominal HDV law, the same closed loop). Refused with
a ConfigError naming the key: ``kind = "fd_lcc"`` (no head vehicle), the keys ``cross_check``,
``band``, ``string``, ``sparsity``, ``as_run``, ``baseline``, ``method = "lmi"``, and
``semantics = "added"`` with ``m = 0`` or a ``pattern`` without vehicle -1 (``cav_lag`` works:
every member lagged).

A platoon or a ring (``[system] kind = "platoon" | "ring"``):

.. code-block:: toml

    [synthesis]
    design = "structured"     # "full_state" (Riccati) | "structured" (per-CAV row patterns)
                              # | "sparsity" (greedy per-CAV range Pareto: sparsity.py)
                              # | "string_stable" (open platoons: string_lmi.py; per-CAV
                              # patterns as structured; needs weights.head > 0)
    semantics = "replace"     # default "replace" (u = K x is the CAV's whole acceleration)
    method = "direct"         # structured: "direct" (default) | "lmi" (the convex restriction,
                              # a pattern per CAV row, starts the polish; its bound reported);
                              # full_state: "riccati" (default) | "lmi" (checked against Riccati)
    cross_check = false       # full_state: also solve the LMI and compare (default false here)
    band = 4                  # structured "lmi": as for one CAV
    comm_range = 5            # every CAV hears the R vehicles ahead and the R behind it
                              # (itself included; the ring wraps around); 0 = decentralised
    cav_lag = 0.0             # every CAV's actuator lag tau (s) in the plant, a state a_i per
                              # CAV (lag_design.py); full_state, structured, robust
    tol = 1e-7
    max_iter = 500

    [synthesis.patterns]      # per-CAV lists of heard vehicle positions (override comm_range;
    u_3 = [1, 2, 3, 4]        # the CAV itself is always heard)

    [synthesis.weights]       # q_s, q_s0 (the CAVs' own spacings), q_v, q_a, r, head, accel

    [synthesis.sparsity]      # design = "sparsity": only max_loss applies
    max_loss = 0.01           # chosen: fewest heard vehicles with H2 <= (1 + max_loss) H2*

    [synthesis.string]        # design = "string_stable", open platoons: as for one CAV
    gamma = 1.0               # H-infinity bound on head -> tail velocity, >= 1
    polish_steps = 200        # string-stable-feasible descent iterations, >= 0
    margin = 1e-4             # relative string-stability margin every accepted step keeps

    [synthesis.baseline]      # optional: hand-picked gains reported beside the design, a
    name = "hand"             # row per CAV input (the form of static controllers); their
    semantics = "replace"     # true H2 (ring: on c x = 0), stability and, open platoons, the
    gains = { u_3 = { s_3 = 0.3, v_3 = -0.6, v_2 = 0.2 } }  # head-to-tail string check

    [synthesis.robust]        # one gain for a set of sampled HDV parameter sets
    samples = 20
    seed = 0
    objective = "mean"        # "mean" | "worst" (smooth maximum)
    alpha = [0.4, 0.8]        # uniform draw per vehicle and member; absent: the nominal value
    beta = [0.7, 1.1]
    s_go = [30.0, 40.0]

Neither comm_range nor patterns: every CAV hears every vehicle (the full-information optimum).
The LMI designs work on every layout: a platoon's or ring's full-state LMI is solved on its
reduced plant (the ring's invariant hyperplane) and checked against Riccati within
``CROSS_CHECK_TOL``; its structured restriction has a block of ``X`` per set of states heard by
the same CAVs (:func:`~lcc_synth.synthesis.lmi.convex_restriction`); with ``cav_lag`` they are
refused there (the lag states are in no pattern). The single-CAV keys ``pattern`` (other than
"all") and ``sparsity`` (but ``max_loss``) do not apply: a ConfigError names the key and
the layout (``kind``); the platoon keys ``comm_range`` and
``patterns`` are refused for one CAV the same way (``robust`` applies to both: see above).
``[synthesis.as_run]`` works on open platoons with ``design = "structured"`` or
``"string_stable"`` (the same table; every CAV samples at ``sample_time`` with the same
``latency`` and ``measurement_filter``): ``equilibrium = "fixed"`` only and ``weight = 0``
(ConfigErrors naming ``synthesis.as_run.equilibrium`` / ``synthesis.as_run.weight``); a ring
refuses it (``synthesis.as_run``: no head vehicle), as do ``[synthesis.robust]`` and
``cav_lag`` with it (``synthesis.as_run`` / ``synthesis.cav_lag``).
``design = "string_stable"`` and ``[synthesis.string]`` need a head vehicle: a ring refuses
them (``synthesis.design`` / ``synthesis.string``), and on a platoon they do not combine with
``[synthesis.robust]`` or ``cav_lag``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.models.platoon import Platoon
from lcc_synth.models.records import Record, system_tables, toml_text
from lcc_synth.problem import Problem, System, check_top_level, system_from, warn_large_gains
from lcc_synth.schema import declared
from lcc_synth.synthesis.h2 import Weights
from lcc_synth.synthesis.lag_design import check_lag_design
from lcc_synth.synthesis.robust_string import check_robust_string

__all__ = [
    "DESIGNS",
    "RobustSettings",
    "SynthesisSpec",
    "PlatoonSynthesisSpec",
    "spec_from_problem",
    "synthesis_spec",
    "platoon_spec",
    "comm_range_pattern",
    "robust_members",
]

#: The designs of ``[synthesis].design`` (declared in :mod:`lcc_synth.schema`).
DESIGNS = declared("synthesis").key("design").choices


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


@dataclass(frozen=True, repr=False, kw_only=True)
class SynthesisSpec(Record):
    """A parsed ``[synthesis]`` problem of any layout (one CAV, a platoon or a ring).

    The fields every layout reads come first; the others keep their defaults on the layouts
    they do not apply to (:func:`synthesis_spec` refuses their keys there).

    Attributes
    ----------
    name, system, design, semantics, weights, tol, max_iter, source
        Every layout. ``method``: ``"riccati"`` | ``"lmi"`` for ``full_state``, ``"lmi"`` |
        ``"direct"`` otherwise (a platoon or ring: default ``"direct"``; ``sparsity``:
        ``"direct"`` only).
    sparsity : dict
        ``[synthesis.sparsity]``: every key for one CAV, ``max_loss`` only for a platoon or
        ring.
    pattern : tuple of int or None
        One CAV: the vehicles heard besides the CAV (the paper's indexing); ``None``: all.
    cross_check, band
        Every layout: the full-state cross-check (default true for one CAV, false for a
        platoon or ring), the LMI restriction's band.
    baseline : tuple or None
        Every layout: ``(name, Gains)`` of ``[synthesis.baseline]``, the gains on the model
        (one CAV: by state name; a platoon or ring: a row per CAV).
    as_run
        One CAV only (the as-run design).
    string_gamma, polish_steps, string_margin
        ``[synthesis.string]`` of the string-aware design (one CAV or an open platoon).
    cav_lag : float
        Every layout: the CAVs' actuator lag ``tau`` (s) in the design plant (0: none;
        :mod:`lcc_synth.synthesis.lag_design`).
    patterns : dict or None
        Platoon / ring: CAV position -> sorted heard positions (the CAV included); ``None``:
        full information.
    comm_range : int or None
        Platoon / ring: the communication range the patterns came from (``None``: lists or
        full).
    robust : RobustSettings or None
        ``[synthesis.robust]``: a platoon or ring, or one CAV behind a head vehicle (run on its
        one-CAV platoon, :mod:`lcc_synth.synthesis.robust_string`).
    """

    name: str
    system: System
    design: str
    semantics: str
    weights: Weights
    method: str
    tol: float = 1e-7
    max_iter: int = 500
    sparsity: dict[str, Any] = field(default_factory=dict)
    source: str | None = None
    pattern: tuple[int, ...] | None = None  # None = every vehicle
    cross_check: bool = True
    band: int = 4
    string_gamma: float = 1.0
    polish_steps: int = 200
    string_margin: float = 1e-4
    baseline: tuple[str, Gains] | None = None
    as_run: Any = None  # lcc_synth.synthesis.as_run.AsRunSettings
    cav_lag: float = 0.0  # the CAV's actuator lag (s), lcc_synth.synthesis.lag_design
    patterns: dict[int, tuple[int, ...]] | None = None
    comm_range: int | None = None
    robust: RobustSettings | None = None

    @property
    def max_loss(self) -> float:
        """``[synthesis.sparsity] max_loss``: the chosen point's H2 loss bound."""
        return self.sparsity["max_loss"]

    def toml_tables(self) -> dict[str, Any]:
        """``name``, ``[hdv]``, ``[system]`` and ``[synthesis]``: the tables
        :func:`spec_from_problem` reads back into an equal spec (``None``: the default)."""
        rows = self.system.platoon is not None  # a gain row per CAV: positions, not pattern
        t = self._platoon_table() if rows else self._one_cav_table()
        return {"name": self.name, **system_tables(self.system), "synthesis": t}

    def to_toml(self) -> str:
        """This spec as a problem file (:meth:`toml_tables`)."""
        return toml_text(self.toml_tables())

    def _one_cav_table(self) -> dict[str, Any]:
        t: dict[str, Any] = {
            "design": self.design,
            "semantics": self.semantics,
            "pattern": "all" if self.pattern is None else list(self.pattern),
            "method": self.method,
            "cross_check": self.cross_check,
            "tol": self.tol,
            "max_iter": self.max_iter,
            "band": self.band,
            "weights": asdict(self.weights),
            "sparsity": dict(self.sparsity),
            "string": {"gamma": self.string_gamma, "polish_steps": self.polish_steps,
                       "margin": self.string_margin},  # fmt: skip
        }
        if self.robust is not None:  # the keys of the other designs do not combine with it
            for key in ("cross_check", "band", "sparsity", "string"):
                del t[key]
            t["robust"] = _robust_table(self.robust)
            return t
        if self.baseline is not None:
            bname, gains = self.baseline
            t["baseline"] = {"name": bname, "semantics": gains.semantics, "gains": gains.gains}
        if self.cav_lag:
            t["cav_lag"] = self.cav_lag
        if self.as_run is not None:
            t["as_run"] = _as_run_table(self.as_run)
        return t

    def _platoon_table(self) -> dict[str, Any]:
        t: dict[str, Any] = {
            "design": self.design,
            "semantics": self.semantics,
            "method": self.method,
            "tol": self.tol,
            "max_iter": self.max_iter,
            "weights": {k: v for k, v in asdict(self.weights).items()
                        if k not in ("position", "q_p")},  # fmt: skip
        }
        if self.cross_check:  # a platoon's default: no cross-check
            t["cross_check"] = True
        if self.band != 4:
            t["band"] = self.band
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
        if self.cav_lag:
            t["cav_lag"] = self.cav_lag
        if self.design == "string_stable":
            t["string"] = {"gamma": self.string_gamma, "polish_steps": self.polish_steps,
                           "margin": self.string_margin}  # fmt: skip
        if self.robust is not None:
            t["robust"] = _robust_table(self.robust)
        if self.baseline is not None:
            bname, gains = self.baseline
            t["baseline"] = {"name": bname, "semantics": gains.semantics,
                             "gains": gains.as_table()}  # fmt: skip
        if self.as_run is not None:
            t["as_run"] = _as_run_table(self.as_run)
        return t


def _as_run_table(st) -> dict[str, Any]:
    """``[synthesis.as_run]`` of settings ``st`` (every layout with a head vehicle)."""
    return {"equilibrium": "fixed" if st.equilibrium_tau is None else "estimated", **asdict(st)}


def _robust_table(rb: RobustSettings) -> dict[str, Any]:
    """``[synthesis.robust]`` of ``rb`` (every layout)."""
    return {"samples": rb.samples, "seed": rb.seed, "objective": rb.objective,
            **{k: list(v) for k, v in rb.ranges.items()}}  # fmt: skip


#: The spec of a platoon or ring synthesis: the same type as one CAV's (kept for imports).
PlatoonSynthesisSpec = SynthesisSpec


def _pattern(table: dict, system: System) -> tuple[int, ...] | None:
    value = declared("synthesis").raw(table, "pattern")
    if value == "all":
        return None
    lo, hi = -system.m, system.n
    if not isinstance(value, list) or any(
        isinstance(v, bool) or not isinstance(v, int) for v in value
    ):
        raise ConfigError(
            "synthesis.pattern",
            f'must be "all" or a list of vehicle indices in [{lo}, {hi}], got {value!r}',
        )
    for v in value:
        if not lo <= v <= hi:
            raise ConfigError(
                "synthesis.pattern", f"vehicle {v} outside [{lo}, {hi}] for this system"
            )
    return tuple(sorted(set(value) - {0}))


def _as_run(t: dict, system: System, design: str):
    """The ``[synthesis.as_run]`` table (or ``as_run = true``) as ``AsRunSettings``."""
    from lcc_synth.synthesis.as_run import AsRunSettings

    f = "synthesis.as_run"
    raw = declared("synthesis").raw(t, "as_run")
    if raw is False:
        return None
    if raw is True:
        raw = {}
    if not isinstance(raw, dict):
        raise ConfigError(f, f"must be true, false or a table, got {raw!r}")
    A = declared("synthesis.as_run")
    A.check(raw, f)
    if design not in ("structured", "string_stable"):
        raise ConfigError(f, f"applies to design = 'structured' or 'string_stable', not {design!r}")
    if system.kind == "fd_lcc":
        raise ConfigError(f, "needs a head vehicle: fd_lcc has none")
    eq = A.get(raw, "equilibrium", f)
    tau = A.get(raw, "equilibrium_tau", f)
    if eq == "fixed" and "equilibrium_tau" in raw:
        raise ConfigError(f"{f}.equilibrium_tau", 'only applies with equilibrium = "estimated"')
    st = A.get(raw, "sample_time", f)
    settings = AsRunSettings(
        equilibrium_tau=tau if eq == "estimated" else None,
        sample_time=st,
        dt=A.get(raw, "dt", f),
        latency=A.get(raw, "latency", f),
        measurement_filter=A.get(raw, "measurement_filter", f),
        margin=A.get(raw, "margin", f),
        weight=A.get(raw, "weight", f),
        polish_steps=A.get(raw, "polish_steps", f),
    )
    if system.platoon is not None:  # a ring, "estimated", weight > 0: named refusals
        from lcc_synth.synthesis.as_run import check_platoon

        check_platoon(system.ring, settings)
    return settings


def spec_from_problem(problem: Problem) -> SynthesisSpec:
    """Parse the ``[hdv]``, ``[system]`` and ``[synthesis]`` tables of a problem file into a
    :class:`SynthesisSpec` (every layout)."""
    src = str(problem.path)
    try:
        check_top_level(problem.data)
        system = system_from(problem.data, src)
        table = declared("").get(problem.data, "synthesis", "")
        return synthesis_spec(problem.name, system, table, src)
    except ConfigError as err:
        raise err.with_source(src) if not err.source else err from None


def synthesis_spec(
    name: str, system: System, table: dict[str, Any], source: str | None = None
) -> SynthesisSpec:
    """The spec of a ``[synthesis]`` table for an already parsed ``system``.

    Parameters
    ----------
    name : str
        The problem's name (the report's ``problem``).
    system : System
        The string the gain is designed for.
    table : dict
        The ``[synthesis]`` table (errors name ``synthesis.KEY``).
    source : str, optional
        Where the table came from (kept in the spec).

    Raises
    ------
    ConfigError
        A bad key or value, naming ``synthesis...``.
    """
    t = table
    T = declared("synthesis")
    T.check(t, "synthesis")
    if system.platoon is not None:
        return platoon_spec(name, system, t, source)
    for key in ("comm_range", "patterns"):
        if key in t:
            T.get(t, key, "synthesis")  # a value out of range: that error first
            raise ConfigError(f"synthesis.{key}", f"only kind = 'platoon' or 'ring' has one "
                              f"(kind = {system.kind!r}: use pattern)")  # fmt: skip
    design = T.get(t, "design", "synthesis")
    default_sem = "replace" if system.kind in ("fd_lcc", "cf_lcc") else "added"
    semantics = T.get(t, "semantics", "synthesis", default=default_sem)
    if semantics == "added" and system.kind == "fd_lcc":
        raise ConfigError(
            "synthesis.semantics", "fd_lcc has no vehicle ahead to follow: use 'replace'"
        )
    pattern = _pattern(t, system)
    robust = None
    if T.get(t, "robust", "synthesis"):  # the one-CAV platoon's robust design (robust_string.py)
        method = check_robust_string(t, system, design, semantics, pattern)
        robust = _robust(t, system)
        method = T.get(t, "method", "synthesis", default=method, choices=(method, "lmi"))
    elif design == "full_state":
        method = T.get(t, "method", "synthesis", default="riccati", choices=("riccati", "lmi"))
    else:
        method = T.get(t, "method", "synthesis", default="lmi", choices=("lmi", "direct"))
    cross_check = T.get(t, "cross_check", "synthesis", default=True) and robust is None
    tol = T.get(t, "tol", "synthesis")
    max_iter = T.get(t, "max_iter", "synthesis")
    band = T.get(t, "band", "synthesis")

    W = declared("synthesis.weights")
    w = T.get(t, "weights", "synthesis")
    W.check(w, "synthesis.weights")
    order = ("q_s", "q_s0", "q_v", "r", "q_a", "q_p", "head", "accel", "position")
    kw = {key: W.get(w, key, "synthesis.weights") for key in order}
    if kw["head"] == 0 and kw["accel"] == 0:
        raise ConfigError("synthesis.weights", "head and accel cannot both be 0")
    if system.kind == "fd_lcc" and kw["accel"] == 0:
        raise ConfigError(
            "synthesis.weights.accel",
            "must be > 0 for fd_lcc (no head vehicle: the head disturbance does not exist)",
        )
    if kw["position"] == "weight" and kw["q_p"] <= 0:
        raise ConfigError("synthesis.weights.q_p", "must be > 0 when position = 'weight'")
    weights = Weights(**kw)

    SP = declared("synthesis.sparsity")
    sp = T.get(t, "sparsity", "synthesis")
    SP.check(sp, "synthesis.sparsity")
    sparsity = {key: SP.get(sp, key, "synthesis.sparsity") for key in SP.names}
    if sparsity["gammas"] is not None and not sparsity["gammas"]:
        raise ConfigError("synthesis.sparsity.gammas", "must not be empty")

    ST = declared("synthesis.string")
    st = T.get(t, "string", "synthesis")
    ST.check(st, "synthesis.string")
    string_gamma = ST.get(st, "gamma", "synthesis.string")
    polish_steps = ST.get(st, "polish_steps", "synthesis.string")
    string_margin = ST.get(st, "margin", "synthesis.string")
    if design == "string_stable" and system.kind == "fd_lcc":
        raise ConfigError(
            "synthesis.design", "string_stable needs a head vehicle; fd_lcc has none"
        )
    if design == "string_stable" and weights.head == 0:
        raise ConfigError(
            "synthesis.weights.head",
            "must be > 0 for design = 'string_stable' (the head disturbance is the point)",
        )

    baseline = _baseline(t, system, semantics)
    as_run = _as_run(t, system, design)
    cav_lag = check_lag_design(T.get(t, "cav_lag", "synthesis"), design, as_run)
    asked = t.get("method") == "lmi" or t.get("cross_check") is True
    if cav_lag > 0 and asked and design != "string_stable":  # as on a platoon or ring
        key = "method" if t.get("method") == "lmi" else "cross_check"
        raise ConfigError(f"synthesis.{key}", "with cav_lag the full-state and structured "
                          "designs run the direct method (the lag state a_0 is in no "
                          "pattern, so no LMI): leave method and cross_check out, or "
                          "cav_lag = 0")  # fmt: skip
    return SynthesisSpec(
        cav_lag=cav_lag,
        as_run=as_run,
        name=name,
        system=system,
        design=design,
        semantics=semantics,
        weights=weights,
        pattern=pattern,
        method=method,
        cross_check=cross_check,
        tol=tol,
        max_iter=max_iter,
        band=band,
        sparsity=sparsity,
        string_gamma=string_gamma,
        polish_steps=polish_steps,
        string_margin=string_margin,
        baseline=baseline,
        source=source,
        robust=robust,
    )


def _baseline(t: dict, system: System, semantics: str) -> tuple[str, Gains] | None:
    """``[synthesis.baseline]`` of any layout as ``(name, gains)`` (``None`` without one): the
    gains in the layout's vocabulary (``{state: gain}`` for one CAV, :meth:`~lcc_synth.models.
    feedback.Gains.named`; ``{u_i: {state: gain}}`` for a platoon or ring, :meth:`~lcc_synth.
    models.feedback.Gains.from_table`, as static controllers read them), checked
    against the model (errors name ``synthesis.baseline...``)."""
    f = "synthesis.baseline"
    B = declared("synthesis.baseline")
    b = declared("synthesis").get(t, "baseline", "synthesis")
    if not b:
        return None
    B.check(b, f)
    bname = B.get(b, "name", f)
    bsem = B.get(b, "semantics", f, default=semantics)
    bg = B.get(b, "gains", f)
    flat = {f"{u}.{k}": g for u, row in bg.items() if isinstance(row, dict)
            for k, g in row.items()}  # fmt: skip
    warn_large_gains({**bg, **flat}, f"{f}.gains")
    model = system.linear_model(warn=False)
    try:
        gains = (Gains.named(bg, bsem) if system.platoon is None
                 else Gains.from_table(bg, model, bsem, f"{f}.gains"))  # fmt: skip
        gains.check(model)
    except ConfigError as err:
        if err.field.startswith(f):
            raise
        raise ConfigError(f"{f}.{err.field}", err.message) from None
    return bname, gains


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
    """The sampled platoons of a platoon or ring ``system`` (a one-CAV string: of
    :func:`lcc_synth.synthesis.robust_string.string_platoon`): every HDV's ``ranges``
    parameters drawn uniformly and independently per member (``numpy.random.default_rng(seed)``,
    vehicle-major order, one row drawn per vehicle of the road); the other parameters those of
    the nominal vehicle. A CAV keeps its nominal law in every member: under ``"added"`` that
    law is part of its controller, not an uncertain driver (its drawn row is discarded, so the
    HDVs' draws do not depend on where the CAVs are). A ring keeps the nominal ``v*`` (or the
    given circumference)."""
    base = system.platoon
    rng = np.random.default_rng(robust.seed)
    keys = list(robust.ranges)
    lo = np.array([robust.ranges[k][0] for k in keys])
    hi = np.array([robust.ranges[k][1] for k in keys])
    out = []
    for s in range(robust.samples):
        draw = rng.uniform(lo, hi, size=(base.size, len(keys)))
        try:
            models = tuple(
                h if i in base.cavs else replace(h, **dict(zip(keys, map(float, row), strict=True)))
                for i, (h, row) in enumerate(zip(base.hdv, draw, strict=True), 1)
            )
            v_star = None if base.circumference is not None else base.v_star
            out.append(Platoon(models, base.cavs, v_star, base.ring, base.circumference,
                               base.vehicle_length))
        except ConfigError as err:
            raise ConfigError("synthesis.robust", f"member {s}: {err.field}: {err.message}"
                              ) from None  # fmt: skip
    return out


def platoon_spec(name: str, system: System, t: dict[str, Any], src: str) -> SynthesisSpec:
    """Parse ``[synthesis]`` (already key-checked) for a platoon or ring ``system``."""
    T = declared("synthesis")
    design = T.get(t, "design", "synthesis")  # every design of one CAV
    if system.ring and (design == "string_stable" or "string" in t):
        key = "design" if design == "string_stable" else "string"
        raise ConfigError(f"synthesis.{key}", "string_stable needs a head vehicle: kind = "
                          "'ring' has none (no head-to-tail transfer function); use kind = "
                          "'platoon'")  # fmt: skip
    semantics = T.get(t, "semantics", "synthesis", default="replace")
    choices = {"full_state": ("riccati", "lmi"), "structured": ("lmi", "direct"),
               "string_stable": ("lmi", "direct")}  # as for one CAV (string_stable: unused)
    method = T.get(t, "method", "synthesis", default="riccati" if design == "full_state"
                   else "direct", choices=choices.get(design, ("direct",)))  # fmt: skip
    cross_check = T.get(t, "cross_check", "synthesis", default=False)
    band = T.get(t, "band", "synthesis")
    if not system.platoon.cavs:
        raise ConfigError("system.cavs", "synthesis needs at least one CAV")
    patterns, R = _patterns(t, system.platoon)
    if design not in ("structured", "string_stable") and patterns is not None:
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
    if design == "string_stable" and kw["head"] == 0:
        raise ConfigError("synthesis.weights.head",
                          "must be > 0 for design = 'string_stable' (the head disturbance is "
                          "the point)")  # fmt: skip
    weights = Weights(**kw)
    ST = declared("synthesis.string")
    st = T.get(t, "string", "synthesis")
    ST.check(st, "synthesis.string")
    string = {key: ST.get(st, key, "synthesis.string") for key in ("gamma", "polish_steps",
                                                                   "margin")}  # fmt: skip
    tol = T.get(t, "tol", "synthesis")
    max_iter = T.get(t, "max_iter", "synthesis")
    robust = _robust(t, system)
    as_run = _as_run(t, system, design)
    cav_lag = check_lag_design(T.get(t, "cav_lag", "synthesis"), design, as_run)
    if as_run is not None and robust is not None:
        raise ConfigError("synthesis.as_run", "does not combine with [synthesis.robust] (the "
                          "robust descent does not keep the as-run string stability): drop "
                          "one of them")  # fmt: skip
    if robust is not None and design == "string_stable":
        raise ConfigError("synthesis.robust", "does not apply to design = 'string_stable' (the "
                          "robust descent does not keep string stability); drop "
                          "[synthesis.robust] or use design = 'structured'")  # fmt: skip
    if cav_lag > 0 and design == "string_stable":
        raise ConfigError("synthesis.cav_lag", "a platoon's design = 'string_stable' has no "
                          "actuator lag (its LMI and polish are of the lag-free loop): use "
                          "0, or design = 'structured' (its report checks the lagged "
                          "string)")  # fmt: skip
    if cav_lag > 0 and (method == "lmi" or cross_check):  # the a_i: in no pattern, no X
        key = "method" if method == "lmi" else "cross_check"
        raise ConfigError(f"synthesis.{key}", "the LMI designs of a platoon or ring have no "
                          "actuator lag: use method = 'riccati' / 'direct' without "
                          "cross_check, or cav_lag = 0")  # fmt: skip
    return SynthesisSpec(name=name, system=system, design=design, semantics=semantics,
                         weights=weights, method=method, cross_check=cross_check, band=band,
                         tol=tol, max_iter=max_iter,
                         sparsity={"max_loss": max_loss}, source=src, patterns=patterns,
                         comm_range=R, robust=robust, cav_lag=cav_lag,
                         baseline=_baseline(t, system, semantics),
                         string_gamma=string["gamma"], polish_steps=string["polish_steps"],
                         string_margin=string["margin"], as_run=as_run)  # fmt: skip
