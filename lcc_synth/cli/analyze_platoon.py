"""``lcc-synth analyze`` on ``[system] kind = "platoon" | "ring"`` (several CAVs, the ring).

The report of :func:`lcc_synth.analysis.controllability.controllability_report` and
:func:`~lcc_synth.analysis.controllability.observability_report` (the ring on its
invariant hyperplane, the conserved total spacing named), each vehicle's eq. (8) coefficients
and eq. (13), and for every ``[cases.NAME]`` (gains per CAV in ``[cases.NAME.gains.u_3]``):
the closed-loop plant stability and, on an open platoon, the head-to-tail string verdict of
:func:`~lcc_synth.analysis.string_stability.gains_string_stability`. A ring has no head
vehicle: its cases report the plant stability on the hyperplane only.
"""

from __future__ import annotations

import math

import numpy as np

from lcc_synth.analysis.cases import AnalysisOptions, GainCase
from lcc_synth.analysis.controllability import (
    controllability_report,
    observability_report,
    reduce_conserved,
)
from lcc_synth.analysis.string_stability import gains_string_stability, string_band
from lcc_synth.analysis.transfer import closed_loop_eigenvalues, gamma_state_space
from lcc_synth.errors import ConfigError
from lcc_synth.models.platoon import PlatoonModel

__all__ = ["platoon_document", "print_platoon"]


def _ring_case(model: PlatoonModel, case: GainCase) -> dict:
    """Plant stability of a ring's closed loop on its invariant hyperplane."""
    Acl, _ = case.gains.closed_loop(model)
    Az, _, _ = reduce_conserved(Acl, model.B, model.conserved)
    eigs = closed_loop_eigenvalues(Az)
    max_re = float(eigs.real.max())
    band = string_band(eigs) * float(np.abs(eigs).max())
    if abs(max_re) <= band:
        verdict = "boundary"
    else:
        verdict = "plant_stable" if max_re < 0 else "plant_unstable"
    return {
        "plant_stable": verdict == "plant_stable",
        "plant_verdict": verdict,
        "max_real_eig": max_re,
        "string_stable": None,
        "verdict": None,
        "note": "a ring has no head vehicle: head-to-tail string stability is undefined; "
        "eigenvalues on the invariant hyperplane (the conserved total spacing left out)",
    }


def platoon_document(
    prob, system, model: PlatoonModel, opts: AnalysisOptions, cases: dict[str, GainCase]
) -> tuple[dict, dict]:
    """``analyze``'s JSON-ready document of a platoon / ring problem, and ``{name: (gamma
    function of omega, report, label)}`` of the cases with a head-to-tail transfer."""
    src = str(prob.path)
    outputs = list(opts.outputs) if opts.outputs else None
    for name in outputs or ():
        if name not in model.state_names:
            raise ConfigError(
                "analysis.outputs",
                f"unknown state {name!r}; this model has {list(model.state_names)}",
                src,
            )
    platoon = model.platoon
    coefs = []
    for i, (kind, c) in enumerate(zip(platoon.types, model.coefficients, strict=True), 1):
        coefs.append({"vehicle": i, "type": kind, "alpha1": c.alpha1, "alpha2": c.alpha2,
                      "alpha3": c.alpha3, "eq13_margin": c.controllability_margin,
                      "problems": c.problems()})  # fmt: skip
    doc: dict = {
        "problem": prob.name,
        "file": src,
        "system": {
            "kind": system.kind,
            "size": platoon.size,
            "cavs": list(platoon.cavs),
            "m": system.m,
            "n": system.n,
            "v_star": float(platoon.v_star),
            "circumference": platoon.length if platoon.ring else None,
            "n_states": model.nx,
            "hdv_model": system.hdv.name,
        },
        "linear_coefficients": coefs,
        "controllability": controllability_report(model).as_dict(),
        "observability": observability_report(model, outputs).as_dict(),
        "cases": {},
    }
    reports = {}
    for name, case in cases.items():
        entry = {"label": case.label, "semantics": case.gains.semantics, "gains": case.table}
        if platoon.ring:
            entry.update(_ring_case(model, case))
        else:
            rep = gains_string_stability(model, case.gains, method=opts.method)
            entry.update(rep.as_dict())
            fb = case.gains.input_feedback(model)
            reports[name] = (lambda w, fb=fb: gamma_state_space(model, *fb, w), rep, case.label)
        doc["cases"][name] = entry
    return doc, reports


def _f(x, spec: str) -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def print_platoon(doc: dict) -> None:
    """The human-readable form of :func:`platoon_document`."""
    s = doc["system"]
    print(f"{doc['problem']} ({doc['file']})")
    where = f"platoon of {s['size']} vehicles behind the head"
    if s["kind"] == "ring":
        where = f"ring of {s['size']} vehicles, circumference {s['circumference']:.6g} m"
    cavs = ", ".join(str(c) for c in s["cavs"]) or "none"
    print(f"system: {where}, CAVs at {cavs}, v* = {s['v_star']:g} m/s, HDV model "
          f"{s['hdv_model']}, {s['n_states']} states")  # fmt: skip
    for c in doc["linear_coefficients"]:
        if c["problems"]:
            print(f"  warning: vehicle {c['vehicle']}: {'; '.join(c['problems'])}")
    ct = doc["controllability"]
    print(f"controllability on the {ct['subspace']} ({ct['n_states']} dimensions): rank "
          f"{ct['rank']}" + (f"..{ct['rank_upper']}" if ct["undecided"] else "")
          + f", {ct['verdict']}; reachable (first CAV and behind) {ct['reachable_states']}: "
          f"{ct['reachable_verdict']}; "
          f"{'stabilizable' if ct['stabilizable'] else 'NOT stabilizable'}; decision margin "
          f"{_f(ct['decision_margin'], '.3g')}")  # fmt: skip
    if ct["conserved_mode"]:
        print(f"  conserved mode (not a defect, never excited): {ct['conserved_mode']}")
    print(f"  vehicles inside: {ct['vehicles_in_subspace']}, outside: {ct['vehicles_outside']}"
          + (f", partial: {ct['vehicles_partial']}" if ct["vehicles_partial"] else ""))
    cond = {True: "holds", False: "VIOLATED", None: "not applicable"}[ct["condition_s"]]
    print(f"  segment condition (S) (eq. 13 per segment): {cond}")
    for x in ct["cancellations"]:
        print(f"    vehicle {x['zero_vehicle']}'s zero cancels vehicle {x['pole_vehicle']}'s "
              f"pole at {x['eigenvalue']:.6g} (segment of CAV {x['cav']})")  # fmt: skip
    ob = doc["observability"]
    print(f"observability (outputs {', '.join(ob['outputs'])}): rank {ob['rank']} of "
          f"{ob['n_states']}, {ob['verdict']}; vehicles inside: {ob['vehicles_in_subspace']}, "
          f"outside: {ob['vehicles_outside']}")  # fmt: skip
    if not doc["cases"]:
        print("no [cases.NAME] tables: nothing else to analyse")
        return
    print()
    for name, e in doc["cases"].items():
        if e.get("verdict") is None:
            print(f"{name:<12} {e['label'][:12]:<12} plant {e['plant_verdict']}, max Re "
                  f"{e['max_real_eig']:+.4f} (ring: no head-to-tail transfer)")  # fmt: skip
        else:
            print(f"{name:<12} {e['label'][:12]:<12} {e['verdict']}, peak |Gamma| "
                  f"{_f(e['gamma_peak'], '.6f')} at {_f(e['gamma_peak_omega'], '.4f')} rad/s, "
                  f"margin {_f(e['margin'], '+.3g')}, max Re {e['max_real_eig']:+.4f}")  # fmt: skip
