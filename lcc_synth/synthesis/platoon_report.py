"""The report of a platoon / ring synthesis: checks of the gain, the text and JSON forms.

:func:`check_platoon_gain` computes from the gain alone the true H2 norm and the closed-loop
eigenvalues on the invariant subspace (ring) or the full state (open platoon), and turns an
unusable result (non-finite, unstable) into a :class:`~lcc_synth.synthesis.h2.SynthesisError`.
On the ring the full-state closed loop always keeps the conserved total-spacing eigenvalue 0
(``max_real_eig_full``): it is reported, never counted as instability.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from lcc_synth.models.records import Record
from lcc_synth.synthesis.h2 import STABILITY_TOL, SynthesisError
from lcc_synth.synthesis.platoon_h2 import PlatoonPlant, platoon_cost
from lcc_synth.synthesis.report import _fmt, _jsonable

__all__ = ["PlatoonCheck", "check_platoon_gain", "PlatoonReport", "format_platoon_report"]


@dataclass(repr=False)
class PlatoonCheck(Record):
    """Everything computed from one platoon gain.

    Attributes
    ----------
    h2 : float
        True H2 norm (ring: on the invariant subspace).
    max_real_eig : float
        Largest real part of the closed-loop eigenvalues on ``subspace``.
    stable : bool
    subspace : str
        ``"full state"`` or the ring's invariant hyperplane.
    max_real_eig_full : float
        The same on the full state (ring: 0 up to round-off, the conserved mode).
    conserved_mode : str or None
        The ring's conserved mode by name.
    """

    h2: float
    max_real_eig: float
    stable: bool
    subspace: str
    max_real_eig_full: float
    conserved_mode: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def check_platoon_gain(plant: PlatoonPlant, K: np.ndarray, what: str = "design") -> PlatoonCheck:
    """True H2 and stability of design gain ``K``; :class:`SynthesisError` when unusable."""
    K = np.asarray(K, float)
    if not np.all(np.isfinite(K)):
        raise SynthesisError(f"{what}: the gain has non-finite entries")
    ev = platoon_cost(plant, K)
    mre = float(np.max(np.linalg.eigvals(plant.closed_loop(K)).real))
    Acl_full = plant.A + plant.B @ K
    mre_full = float(np.max(np.linalg.eigvals(Acl_full).real))
    m = plant.model
    sub = (f"invariant hyperplane c x = 0 ({plant.V.shape[1]} of {plant.nx} states)"
           if m.ring else "full state")  # fmt: skip
    if not mre < -STABILITY_TOL:
        raise SynthesisError(f"{what}: the closed loop is not stable on the {sub} (max Re(eig) "
                             f"= {mre:.3g})", {"max_real_eig": mre})  # fmt: skip
    if not ev.stable:
        raise SynthesisError(f"{what}: the closed-loop H2 norm is not finite")
    return PlatoonCheck(math.sqrt(ev.J), mre, True, sub, mre_full, m.conserved_mode)


@dataclass(repr=False)
class PlatoonReport(Record):
    """Result of ``lcc-synth synthesize`` for a platoon or ring.

    ``K`` has one row per CAV (``cavs`` order) on ``state_names``; ``gains`` is the same in
    :meth:`~lcc_synth.models.platoon.PlatoonGains.as_table` form; ``input_K`` / ``input_kh``
    the CAVs' whole inputs ``u = input_K x + input_kh v_h`` under the semantics. ``stages``
    lists each stage's true H2 and time; ``robust`` the per-member figures; ``pareto`` the
    range front of ``design = "sparsity"``.
    """

    problem: str
    design: str
    kind: str
    size: int
    cavs: list[int]
    ring: bool
    v_star: float
    circumference: float | None
    semantics: str
    weights: dict[str, Any]
    disturbances: list[str]
    patterns: dict[str, list[int]]
    comm_range: int | None
    state_names: list[str]
    K: list[list[float]]
    gains: dict[str, dict[str, float]]
    input_K: list[list[float]]
    input_kh: list[float]
    check: PlatoonCheck
    h2_unstructured: float
    conserved: list[float] | None = None
    stages: list[dict[str, Any]] = field(default_factory=list)
    polish: dict[str, Any] = field(default_factory=dict)
    robust: dict[str, Any] | None = None
    pareto: list[dict[str, Any]] | None = None
    timings: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["check"] = self.check.as_dict()
        return _jsonable(d)


def format_platoon_report(rep: PlatoonReport) -> str:
    """Human-readable report."""
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
    for s in rep.stages:
        lines.append(f"stage {s['stage']:<22s}: H2 {_fmt(s['h2'])}  ({s['time']:.3f} s)")
    if rep.polish:
        lines.append("polish: " + ", ".join(f"{k}={_fmt(v) if isinstance(v, float) else v}"
                                             for k, v in rep.polish.items()))
    if rep.robust:
        r = rep.robust
        lines.append(f"robust ({r['objective']}, {r['samples']} members, seed {r['seed']}, "
                     f"ranges {r['ranges']}):")  # fmt: skip
        for key in ("nominal_design", "robust_design"):
            s = r[key]
            lines.append(f"  {key:<15s}: mean H2 {_fmt(s['mean_h2'])}, worst {_fmt(s['worst_h2'])}"
                         f", best {_fmt(s['best_h2'])}, stable on {s['n_stable']}/{r['samples']}")
        lines.append(f"  robust gain on the nominal model: H2 {_fmt(c.h2)} (nominal design "
                     f"{_fmt(r['nominal_design']['h2_nominal'])})")  # fmt: skip
    if rep.pareto:
        lines.append("range front (greedy per CAV: ranges -> vehicles heard, true H2, loss):")
        for p in rep.pareto:
            lines.append(f"  {'*' if p['chosen'] else ' '} {p['ranges']}  heard {p['heard']:>3d}"
                         f"  H2 {p['h2']:.6f}  loss {100 * p['loss']:.3f}%")
    if rep.timings:
        lines.append("time: " + ", ".join(f"{k} {v:.3f} s" for k, v in rep.timings.items()))
    lines += [f"note: {s}" for s in rep.notes]
    return "\n".join(lines)
