"""Checks of every synthesised gain and the report that carries them, for every layout.

One CAV: :func:`evaluate_gain` computes, from the gain alone: the closed-loop eigenvalues
(design plant and full model), the TRUE H2 norm (Lyapunov), and for models with a head vehicle
the global string-stability check (peak ``|Gamma|``, its frequency, verdict).
:func:`check_gain` turns an unusable result (non-finite entries, unstable closed loop, infinite
H2 norm) into a :class:`~lcc_synth.synthesis.h2.SynthesisError` -- never a returned gain.

Platoons and rings (a gain row per CAV): :func:`check_platoon_gain` computes from the gain
alone the true H2 norm and the closed-loop eigenvalues on the invariant subspace (ring) or the
full state (open platoon), and turns an unusable result (non-finite, unstable) into a
:class:`~lcc_synth.synthesis.h2.SynthesisError`. On the ring the full-state closed loop always
keeps the conserved total-spacing eigenvalue 0 (``max_real_eig_full``): it is reported, never
counted as instability.

Both give a :class:`GainCheck`, the one check type of every layout (``PlatoonCheck`` is another
name of it), and :class:`SynthesisReport` is the one report of every layout (``PlatoonReport``
is another name of it): in both, fields of one layout only are :data:`UNSET` on the others and
left out of ``as_dict``, the JSON form of ``lcc-synth synthesize --json``. :func:`format_report`
prints it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from lcc_synth.analysis.string_stability import verdict_text
from lcc_synth.models.feedback import Gains
from lcc_synth.models.records import Record, short
from lcc_synth.synthesis.h2 import (
    STABILITY_TOL,
    H2Plant,
    PlatoonPlant,
    SynthesisError,
    closed_loop_matrix,
    h2_norm,
    max_real_eig,
    platoon_cost,
)

__all__ = [
    "GainCheck",
    "evaluate_gain",
    "check_gain",
    "SynthesisReport",
    "UNSET",
    "format_report",
    "PlatoonCheck",
    "check_platoon_gain",
    "evaluate_platoon_gain",
    "PlatoonReport",
]


class _Unset:
    """The value of a check or report field that its layout does not have (:data:`UNSET`)."""

    __slots__ = ()

    def __repr__(self) -> str:
        return "UNSET"

    def __reduce__(self) -> str:  # one object across pickling (reports cross processes)
        return "UNSET"


#: A field of :class:`GainCheck` or :class:`SynthesisReport` that its layout does not have:
#: left out of ``as_dict`` (so ``null`` in the JSON always means a value of None).
UNSET: Any = _Unset()


@dataclass(repr=False, kw_only=True)
class GainCheck(Record):
    """Everything computed from one synthesised gain, for every layout (``PlatoonCheck`` is
    another name of it).

    The fields every layout has come first; a field of one layout only is :data:`UNSET` on the
    others and :meth:`as_dict` leaves it out (as :class:`SynthesisReport` does), so the
    ``check`` object of ``lcc-synth synthesize --json`` holds the layout's own keys.

    Attributes
    ----------
    h2 : float
        True H2 norm (Lyapunov; ring: on the invariant subspace).
    max_real_eig : float
        Largest real part of the closed-loop eigenvalues: one CAV, of the design plant; platoon
        / ring, on ``subspace``.
    max_real_eig_model : float
        One CAV: the same on the full model (FD-LCC: the free position integrator is 0).
    plant_stable, string_stable : bool or None
        One CAV; an open platoon designed with ``cav_lag`` (its lagged loop) or ``design =
        "string_stable"``: the head-to-tail check (``None`` without a head vehicle).
    gamma_peak, gamma_peak_omega : float or None
        The same layouts: peak ``|Gamma|`` and its frequency (rad/s).
    string_verdict : str or None
        The same layouts: ``StringStabilityReport.verdict``.
    string_margin : float or None
        The same layouts: ``StringStabilityReport.margin`` (relative; ``None`` when not
        finite).
    stable : bool
        Platoon / ring: the closed loop is stable on ``subspace`` (always ``True`` on a
        returned check: :func:`check_platoon_gain` raises otherwise).
    subspace : str
        Platoon / ring: ``"full state"`` or the ring's invariant hyperplane.
    max_real_eig_full : float
        Platoon / ring: ``max_real_eig`` on the full state (ring: 0 up to round-off, the
        conserved mode).
    conserved_mode : str or None
        Platoon / ring: the ring's conserved mode by name.
    """

    h2: float
    max_real_eig: float
    max_real_eig_model: float = UNSET
    plant_stable: bool | None = UNSET
    string_stable: bool | None = UNSET
    gamma_peak: float | None = UNSET
    gamma_peak_omega: float | None = UNSET
    string_verdict: str | None = UNSET
    string_margin: float | None = UNSET
    stable: bool = UNSET
    subspace: str = UNSET
    max_real_eig_full: float = UNSET
    conserved_mode: str | None = UNSET

    def as_dict(self) -> dict[str, Any]:
        """Every field of the layout, in field order; :data:`UNSET` fields left out."""
        return _set_fields(self)

    def __repr__(self) -> str:
        return _set_repr(self)


#: The check of a platoon or ring gain: the same type as one CAV's (kept for imports).
PlatoonCheck = GainCheck


def _set_fields(rec: Any) -> dict[str, Any]:
    """The fields of dataclass ``rec`` that are not :data:`UNSET`, in field order (an object
    that is not plain data, ``metadata={"plain": False}``, left out)."""
    d = {f.name: getattr(rec, f.name) for f in fields(rec) if f.metadata.get("plain", True)}
    return {k: v for k, v in d.items() if v is not UNSET}


def _set_repr(rec: Any) -> str:
    parts = (f"{k}={short(v)}" for k, v in _set_fields(rec).items())
    return f"{type(rec).__name__}({', '.join(parts)})"


def evaluate_gain(plant: H2Plant, g: np.ndarray) -> GainCheck:
    """Closed-loop eigenvalues, true H2 norm and string stability of design gain ``g``."""
    g = np.asarray(g, float).ravel()
    mre = max_real_eig(closed_loop_matrix(plant, g)) if np.all(np.isfinite(g)) else math.inf
    h2 = h2_norm(plant, g) if math.isfinite(mre) else math.inf
    model = plant.model
    K, kh = plant.input_feedback(g)
    A_cl = model.A + model.B @ K.reshape(1, -1)
    if plant.lag > 0:  # the CAV's actuator lag: the loop with the lag state
        from lcc_synth.analysis.lag_string import lag_string_stability, lagged_lcc

        A_cl = lagged_lcc(model, plant.lag).closed_loop(K)[0]
    mre_model = max_real_eig(A_cl) if math.isfinite(mre) else mre
    ps = ss = peak = peak_w = verdict = margin = None
    if model.kind != "fd_lcc" and math.isfinite(mre):
        from lcc_synth.analysis.string_stability import string_stability

        rep = (lag_string_stability(model, K, kh, plant.lag) if plant.lag > 0
               else string_stability(model, K, kh))  # fmt: skip
        ps, ss = bool(rep.plant_stable), bool(rep.string_stable)
        peak, peak_w = float(rep.gamma_peak), float(rep.gamma_peak_omega)
        verdict = rep.verdict
        margin = float(rep.margin) if math.isfinite(rep.margin) else None
    return GainCheck(h2=h2, max_real_eig=mre, max_real_eig_model=mre_model, plant_stable=ps,
                     string_stable=ss, gamma_peak=peak, gamma_peak_omega=peak_w,
                     string_verdict=verdict, string_margin=margin)


def check_gain(plant: H2Plant, g: np.ndarray, what: str, details: dict | None = None) -> GainCheck:
    """:func:`evaluate_gain`, raising :class:`SynthesisError` on an unusable result."""
    g = np.asarray(g, float).ravel()
    details = dict(details or {})
    if not np.all(np.isfinite(g)):
        raise SynthesisError(f"{what}: the gain has non-finite entries", details)
    chk = evaluate_gain(plant, g)
    if not chk.max_real_eig < -STABILITY_TOL:
        details["max_real_eig"] = chk.max_real_eig
        raise SynthesisError(
            f"{what}: the closed loop is not stable (max Re(eig) = {chk.max_real_eig:.3g})",
            details,
        )
    if not math.isfinite(chk.h2):
        raise SynthesisError(f"{what}: the closed-loop H2 norm is not finite", details)
    return chk


@dataclass(repr=False, kw_only=True)
class SynthesisReport(Record):
    """Result of ``lcc-synth synthesize`` on any layout: the gain, how it was found and its
    checks.

    One report type serves one CAV (a string of ``m`` HDVs ahead and ``n`` behind, the paper's
    indexing), a platoon behind a head vehicle and a ring (``cavs`` positions from the head).
    The fields every layout has come first; a field of one layout only is :data:`UNSET` on the
    others and :meth:`as_dict` leaves it out, so ``lcc-synth synthesize --json`` prints the
    layout's own keys.

    Attributes
    ----------
    problem, design, kind : str
        The problem's name, ``[synthesis] design`` and the model's kind.
    m, n : int
        One CAV: the HDVs ahead and behind.
    size, cavs, ring, circumference
        Platoon / ring: the vehicles, the CAV positions (1-based from the head), closed road,
        and the ring's length (``None`` for an open platoon).
    pattern : list of int
        One CAV: the vehicles heard besides the CAV (the paper's indexing).
    patterns, comm_range
        Platoon / ring: ``{"u_i": [positions heard]}`` and the range they came from.
    K, gains, input_K, input_kh
        One CAV: ``K`` on ``state_names``, ``gains`` ``{state: gain}``, the CAV's whole input
        ``u = input_K x + input_kh v_h``. Platoon / ring: a row per CAV (``cavs`` order),
        ``gains`` in :meth:`~lcc_synth.models.feedback.Gains.as_table` form, ``input_kh`` a
        number per CAV.
    check : GainCheck
        The checks of the gain (:func:`check_gain`, :func:`check_platoon_gain`).
    h2_lmi_bound, h2_restriction, solver
        The LMI bound, the LMI gain's true H2 and the solver's figures: one CAV, and a
        platoon / ring whose design solved an LMI (``method = "lmi"``, ``cross_check``, an
        open platoon's ``string_stable``).
    baseline : dict or None
        ``[synthesis.baseline]``'s checks (:func:`~lcc_synth.synthesis.design.baseline_check`:
        ``name``, ``semantics``, ``gains``, ``vehicles`` and the check's keys of the layout);
        one CAV: ``None`` without one; a platoon or ring: :data:`UNSET` without one.
    as_run
        One CAV: the as-run design's information.
    conserved, stages
        Platoon / ring: the ring's conserved direction ``c``, each stage's true H2 and time.
    robust
        The per-member figures of a robust design (``[synthesis.robust]``: a platoon or ring,
        or one CAV designed on its one-CAV platoon, :mod:`lcc_synth.synthesis.robust_string`);
        ``None`` without one on a platoon or ring.
    pareto : list of dict or None
        ``design = "sparsity"``: the Pareto front (one CAV) or the greedy range front.
    gain : lcc_synth.models.feedback.Gains
        The synthesised gain itself (``K``, ``gains`` and ``semantics`` are its plain form):
        the object a controller of the design is built from (a static controller, an MPC's
        fallback), never read back from ``gains``. Not part of :meth:`as_dict` (the JSON has
        its plain form), of the repr nor of the report's equality.
    """

    problem: str
    design: str
    kind: str
    m: int = UNSET
    n: int = UNSET
    size: int = UNSET
    cavs: list[int] = UNSET
    ring: bool = UNSET
    v_star: float
    circumference: float | None = UNSET
    semantics: str
    weights: dict[str, Any]
    disturbances: list[str]
    pattern: list[int] = UNSET
    patterns: dict[str, list[int]] = UNSET
    comm_range: int | None = UNSET
    state_names: list[str]
    K: list[float] | list[list[float]]
    gains: dict[str, float] | dict[str, dict[str, float]]
    input_K: list[float] | list[list[float]]
    input_kh: float | list[float]
    check: GainCheck
    h2_lmi_bound: float | None = UNSET
    h2_restriction: float | None = UNSET
    h2_unstructured: float | None = None
    solver: dict[str, Any] = UNSET
    conserved: list[float] | None = UNSET
    stages: list[dict[str, Any]] = UNSET
    polish: dict[str, Any] = field(default_factory=dict)
    baseline: dict[str, Any] | None = UNSET
    robust: dict[str, Any] | None = UNSET
    pareto: list[dict[str, Any]] | None = None
    timings: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    as_run: dict[str, Any] | None = UNSET  # lcc_synth.synthesis.as_run.as_run_design's info
    gain: Gains | None = field(default=None, compare=False, metadata={"plain": False})

    @property
    def per_cav(self) -> bool:
        """Is the gain a row per CAV (a platoon or ring report, ``cavs`` set)?"""
        return self.cavs is not UNSET

    def as_dict(self) -> dict[str, Any]:
        """The JSON form (``lcc-synth synthesize --json``): every field of the layout, in
        field order, :data:`UNSET` fields left out, non-finite numbers as ``None``."""
        d = _set_fields(self)
        d["check"] = self.check.as_dict()
        return _jsonable(d)

    def __repr__(self) -> str:
        return _set_repr(self)


#: The report of a platoon or ring synthesis: the same type as one CAV's (kept for imports).
PlatoonReport = SynthesisReport


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return [_jsonable(v) for v in x.tolist()]
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, float | np.floating):
        x = float(x)
        return x if math.isfinite(x) else None
    return x


def _fmt(x, spec=".6g") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return format(x, spec)


def format_report(rep: SynthesisReport) -> str:
    """Human-readable report of a synthesis (one CAV, or a platoon / ring: a row per CAV)."""
    if rep.per_cav:
        return _format_platoon_report(rep)
    c = rep.check
    lines = [
        f"synthesis: {rep.problem}  ({rep.design}, {rep.kind} m={rep.m} n={rep.n}, "
        f"v*={rep.v_star:g}, semantics={rep.semantics})",
        "weights: " + ", ".join(f"{k}={v}" for k, v in rep.weights.items() if v is not None),
        f"disturbances: {', '.join(rep.disturbances)}",
        f"pattern (vehicles heard): {rep.pattern}",
        "gain (u = +K x, "
        + ("added to the HDV law" if rep.semantics == "added" else "whole CAV command")
        + "):",
    ]
    nz = [(k, v) for k, v in rep.gains.items() if v != 0.0]
    lines += [f"  {k:>6s} = {v: .6f}" for k, v in nz] or ["  (all zero)"]
    lines += [
        f"true H2 norm           : {_fmt(c.h2)}",
        f"LMI bound              : {_fmt(rep.h2_lmi_bound)}"
        + (
            f"  (LMI gain's true H2 {_fmt(rep.h2_restriction)})"
            if rep.h2_restriction is not None
            else ""
        ),
        f"unstructured optimum   : {_fmt(rep.h2_unstructured)}",
        f"max Re(eig) closed loop: {_fmt(c.max_real_eig, '.4g')}"
        f"  (full model {_fmt(c.max_real_eig_model, '.4g')})",
    ]
    if c.string_stable is not None:
        lines.append(
            f"peak |Gamma|           : {_fmt(c.gamma_peak, '.9f')} at w = "
            f"{_fmt(c.gamma_peak_omega, '.4g')} rad/s -> "
            + verdict_text(c.string_verdict)
            + (f" (margin {c.string_margin:.3g})" if c.string_margin is not None else "")
        )
    else:
        lines.append("string stability       : n/a (no head vehicle)")
    if rep.solver:
        lines.append("solver: " + ", ".join(f"{k}={_fmt(v) if isinstance(v, float) else v}"
                                             for k, v in rep.solver.items()))
    if rep.polish:
        lines.append("polish: " + ", ".join(f"{k}={_fmt(v) if isinstance(v, float) else v}"
                                             for k, v in rep.polish.items()))
    lines += _baseline_lines(rep)
    lines += _robust_lines(rep)
    if rep.pareto:
        lines.append("Pareto sweep (vehicles heard besides the CAV -> true H2 after polishing):")
        lines.append(f"  {'#':>2s}  {'H2':>10s}  {'front':>5s}  vehicles")
        for p in rep.pareto:
            lines.append(
                f"  {p['count']:>2d}  {p['h2']:>10.6f}  {'*' if p['on_front'] else '':>5s}  "
                f"{p['vehicles']}"
            )
    if rep.timings:
        lines.append("time: " + ", ".join(f"{k} {v:.3f} s" for k, v in rep.timings.items()))
    lines += [f"note: {s}" for s in rep.notes]
    return "\n".join(lines)


def _baseline_lines(rep: SynthesisReport) -> list[str]:
    """The baseline gains' checks beside the design's (every layout; none without one; an
    unstable baseline: its H2 n/a and ``NOT stable``)."""
    if rep.baseline is UNSET or not rep.baseline:
        return []
    b, c = rep.baseline, rep.check
    h2 = b["h2"] if b["h2"] is not None else math.inf  # JSON-read reports: null
    line = (f"baseline '{b['name']}': true H2 {_fmt(b['h2'])}, max Re(eig) "
            f"{_fmt(b['max_real_eig'], '.4g')}")  # fmt: skip
    if not math.isfinite(h2):
        line += " (closed loop NOT stable)"
    if b.get("string_stable") is not None:
        line += f", peak |Gamma| {_fmt(b['gamma_peak'], '.6f')}, " + verdict_text(
            b.get("string_verdict"))
    if h2 and math.isfinite(h2):
        line += f"  -> synthesised gain is {100 * (1 - c.h2 / h2):.1f}% lower in H2"
    return [line]


def _robust_lines(rep: SynthesisReport) -> list[str]:
    """The per-member summary of a robust design (every layout; none without one)."""
    if rep.robust is UNSET or not rep.robust:
        return []
    r = rep.robust
    lines = [f"robust ({r['objective']}, {r['samples']} members, seed {r['seed']}, "
             f"ranges {r['ranges']}):"]  # fmt: skip
    for key in ("nominal_design", "robust_design"):
        s = r[key]
        lines.append(f"  {key:<15s}: mean H2 {_fmt(s['mean_h2'])}, worst {_fmt(s['worst_h2'])}"
                     f", best {_fmt(s['best_h2'])}, stable on {s['n_stable']}/{r['samples']}")
    lines.append(f"  robust gain on the nominal model: H2 {_fmt(rep.check.h2)} (nominal design "
                 f"{_fmt(r['nominal_design']['h2_nominal'])})")  # fmt: skip
    return lines


def evaluate_platoon_gain(plant: PlatoonPlant, K: np.ndarray, string: bool = False) -> GainCheck:
    """True H2 and stability of design gain ``K`` (finite entries), unstable ones included
    (``stable = False``, ``h2 = inf``): the platoon / ring form of :func:`evaluate_gain`.

    The head-to-tail check of an open platoon (the one-CAV fields ``plant_stable``,
    ``string_stable``, ``gamma_peak``, ``gamma_peak_omega``, ``string_verdict``,
    ``string_margin``) is added with ``string`` (by
    :func:`~lcc_synth.analysis.string_stability.string_stability` on the CAVs' whole inputs)
    and for a plant with an actuator lag (of the lagged loop,
    :func:`~lcc_synth.analysis.lag_string.lag_string_stability`)."""
    K = np.asarray(K, float)
    ev = platoon_cost(plant, K)
    mre = float(np.max(np.linalg.eigvals(plant.closed_loop(K)).real))
    Acl_full = plant.A + plant.B @ K
    mre_full = float(np.max(np.linalg.eigvals(Acl_full).real))
    m = plant.model
    sub = (f"invariant hyperplane c x = 0 ({plant.V.shape[1]} of {plant.nx} states)"
           if m.ring else "full state")  # fmt: skip
    stable = bool(mre < -STABILITY_TOL and ev.stable)
    ss: dict[str, Any] = {}
    if not m.ring and (string or plant.lag > 0):
        from lcc_synth.analysis.lag_string import lag_string_stability
        from lcc_synth.analysis.string_stability import string_stability

        rep = (lag_string_stability(m, *plant.input_feedback(K), plant.lag) if plant.lag > 0
               else string_stability(m, *plant.input_feedback(K)))  # fmt: skip
        ss = {"plant_stable": bool(rep.plant_stable), "string_stable": bool(rep.string_stable),
              "gamma_peak": float(rep.gamma_peak),
              "gamma_peak_omega": float(rep.gamma_peak_omega), "string_verdict": rep.verdict,
              "string_margin": float(rep.margin) if math.isfinite(rep.margin) else None}
    return GainCheck(h2=math.sqrt(ev.J) if stable else math.inf, max_real_eig=mre,
                     stable=stable, subspace=sub, max_real_eig_full=mre_full,
                     conserved_mode=m.conserved_mode, **ss)  # fmt: skip


def check_platoon_gain(
    plant: PlatoonPlant, K: np.ndarray, what: str = "design", string: bool = False
) -> GainCheck:
    """:func:`evaluate_platoon_gain`, raising :class:`SynthesisError` on an unusable result
    (non-finite entries, a closed loop not stable, an infinite H2 norm)."""
    K = np.asarray(K, float)
    if not np.all(np.isfinite(K)):
        raise SynthesisError(f"{what}: the gain has non-finite entries")
    chk = evaluate_platoon_gain(plant, K, string)
    if not chk.max_real_eig < -STABILITY_TOL:
        raise SynthesisError(f"{what}: the closed loop is not stable on the {chk.subspace} "
                             f"(max Re(eig) = {chk.max_real_eig:.3g})",
                             {"max_real_eig": chk.max_real_eig})  # fmt: skip
    if not chk.stable:
        raise SynthesisError(f"{what}: the closed-loop H2 norm is not finite")
    return chk


def _format_platoon_report(rep: SynthesisReport) -> str:
    """Human-readable report of a platoon / ring synthesis."""
    c = rep.check
    road = (f"ring of {rep.size} (circumference {rep.circumference:.6g} m)" if rep.ring
            else f"platoon of {rep.size} behind a head vehicle")  # fmt: skip
    lines = [
        f"synthesis: {rep.problem}  ({rep.design}, {road}, CAVs {rep.cavs}, v*={rep.v_star:g}, "
        f"semantics={rep.semantics})",
        "weights: " + ", ".join(f"{k}={v}" for k, v in rep.weights.items() if v is not None),
        f"disturbances: {', '.join(rep.disturbances)}",
        "patterns (positions heard)"
        + (f", comm_range R = {rep.comm_range}" if rep.comm_range is not None else "") + ":",
    ]
    lines += [f"  {u}: {v}" for u, v in rep.patterns.items()]
    lines.append("gain (u = +K x, "
                 + ("added to the HDV law" if rep.semantics == "added" else "whole CAV command")
                 + "):")  # fmt: skip
    for u, row in rep.gains.items():
        lines.append(f"  {u}: " + (", ".join(f"{k} {v: .5f}" for k, v in row.items())
                                   or "(all zero)"))  # fmt: skip
    lines += [
        f"true H2 norm            : {_fmt(c.h2)}  ({c.subspace})",
        f"unstructured optimum    : {_fmt(rep.h2_unstructured)}",
        f"max Re(eig) closed loop : {_fmt(c.max_real_eig, '.4g')} on the {c.subspace}"
        + (f" (full state {_fmt(c.max_real_eig_full, '.3g')}: the conserved mode)"
           if rep.ring else ""),
    ]  # fmt: skip
    if c.string_verdict is not UNSET:  # an open platoon's string check (lagged: with the lag)
        label = ("peak |Gamma| head->tail " if rep.design == "string_stable"
                 else "peak |Gamma| (lagged)   ")  # otherwise only a lagged design has it
        lines.append(f"{label}: {_fmt(c.gamma_peak, '.9f')} at w = "
                     f"{_fmt(c.gamma_peak_omega, '.4g')} rad/s -> "
                     + verdict_text(c.string_verdict)
                     + (f" (margin {c.string_margin:.3g})" if c.string_margin is not None
                        else ""))  # fmt: skip
    if rep.h2_lmi_bound is not UNSET:
        lines.append(f"LMI bound               : {_fmt(rep.h2_lmi_bound)}  (LMI gain's true H2 "
                     f"{_fmt(rep.h2_restriction)})")  # fmt: skip
    if rep.solver is not UNSET and rep.solver:
        lines.append("solver: " + ", ".join(f"{k}={_fmt(v) if isinstance(v, float) else v}"
                                             for k, v in rep.solver.items()))  # fmt: skip
    for s in rep.stages:
        lines.append(f"stage {s['stage']:<22s}: H2 {_fmt(s['h2'])}  ({s['time']:.3f} s)")
    if rep.polish:
        lines.append("polish: " + ", ".join(f"{k}={_fmt(v) if isinstance(v, float) else v}"
                                             for k, v in rep.polish.items()))
    lines += _baseline_lines(rep)
    lines += _robust_lines(rep)
    if rep.pareto:
        lines.append("range front (greedy per CAV: ranges -> vehicles heard, true H2, loss):")
        for p in rep.pareto:
            lines.append(f"  {'*' if p['chosen'] else ' '} {p['ranges']}  heard {p['heard']:>3d}"
                         f"  H2 {p['h2']:.6f}  loss {100 * p['loss']:.3f}%")
    if rep.timings:
        lines.append("time: " + ", ".join(f"{k} {v:.3f} s" for k, v in rep.timings.items()))
    lines += [f"note: {s}" for s in rep.notes]
    return "\n".join(lines)
