"""``lcc-synth analyze PROBLEM.toml [--json] [--png PATH]``, on every layout.

For the problem's linear system (the paper's one-CAV kinds, a platoon with several CAVs or a
ring): each vehicle's linear coefficients and the controllability condition (13), the
controllable and observable subspaces (which vehicles they contain; the ring on its invariant
hyperplane, the conserved total spacing named), the segment condition (S) of the generalised
theorem; for every ``[cases.NAME]`` gain (one CAV: ``gains = { s_1 = ... }``; a platoon or
ring: one table per CAV input, ``[cases.NAME.gains.u_3]``): closed-loop plant stability and,
with a head vehicle, the head-to-tail string-stability verdict and the peak ``|Gamma(jw)|``
with its frequency. ``--png`` draws ``|Gamma(jw)|`` of every case (Fig. 9).

The ``--json`` document has the same keys for every layout. Two keys keep the meaning each
kind of file gave them before the layouts shared one command: ``linear_coefficients`` is the
dict of the (homogeneous) HDV model for the paper's kinds and the per-vehicle list for
``kind = "platoon" | "ring"`` (``vehicle_coefficients`` is that list on every layout), and
``m``, ``n`` are the ``[system]`` table's (a platoon's ``n`` counts the first CAV;
``controllability.vehicles_behind`` is the paper's ``n`` on every layout).
"""

from __future__ import annotations

import argparse
import math
import sys
from functools import partial

from lcc_synth.cli.arguments import add_problem_arguments, add_recording

HELP = "controllability/observability and head-to-tail string stability of the gain cases"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_problem_arguments(parser, "problem file with [system] and optional [cases.NAME]")
    parser.add_argument("--png", metavar="PATH", help="write |Gamma(jw)| of every case (Fig. 9)")
    add_recording(parser, steps=False)


def _fmt(x, spec: str) -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def _coefficients(model) -> list[dict]:
    """Each vehicle's eq. (8) coefficients and eq. (13), front to tail."""
    return [
        {"vehicle": i, "type": "cav" if i in model.cavs else "hdv", "alpha1": c.alpha1,
         "alpha2": c.alpha2, "alpha3": c.alpha3, "eq13_margin": c.controllability_margin,
         "problems": c.problems()}
        for i, c in zip(model.vehicles, model.vehicle_coefficients, strict=True)
    ]  # fmt: skip


def _paper_coefficients(model) -> dict:
    """The paper's kinds: the homogeneous HDV's coefficients (the first HDV behind the CAV,
    else the last ahead) and eq. (13)."""
    coef = model.coefficients[1 if model.n > 0 else -1]
    return {
        "alpha1": coef.alpha1,
        "alpha2": coef.alpha2,
        "alpha3": coef.alpha3,
        "eq13_margin": coef.controllability_margin,
        "eq13_holds": not any("(13)" in p for p in coef.problems()),
        "problems": coef.problems(),
    }


def _vehicles_used(model, table: dict) -> list[int]:
    """Vehicles with a non-zero gain in a case's gains table (flat, or one table per CAV)."""
    rows = [r for r in table.values() if isinstance(r, dict)] or [table]
    names = {name for row in rows for name, g in row.items() if g}
    return sorted({model.vehicles[model.index(name) // 2] for name in names})


def analyze(problem_path: str) -> tuple[dict, dict]:
    """Everything ``analyze`` reports, as a JSON-ready dict, plus the objects for plotting."""
    from lcc_synth.analysis.cases import analysis_options_from, cases_from
    from lcc_synth.analysis.controllability import controllability_report, observability_report
    from lcc_synth.analysis.string_stability import plant_stability, string_stability
    from lcc_synth.analysis.transfer import gamma_state_space, has_head
    from lcc_synth.errors import ConfigError
    from lcc_synth.models.platoon import PLATOON_KINDS
    from lcc_synth.problem import load_problem, system_from

    prob = load_problem(problem_path)
    src = str(prob.path)
    system = system_from(prob.data, src)
    model = system.linear_model(warn=False)
    opts = analysis_options_from(prob.data, src)
    outputs = list(opts.outputs) if opts.outputs else None
    for name in outputs or ():
        if name not in model.state_names:
            raise ConfigError(
                "analysis.outputs",
                f"unknown state {name!r}; this model has {list(model.state_names)}",
                src,
            )
    cases = cases_from(prob.data, model, src)
    per_vehicle = _coefficients(model)
    doc: dict = {
        "problem": prob.name,
        "file": src,
        "system": {
            "kind": system.kind,
            "size": len(model.vehicles),
            "cavs": list(model.cavs),
            "m": system.m,
            "n": system.n,
            "v_star": system.v_star,
            "s_star": system.s_star,
            "circumference": system.platoon.length if model.ring else None,
            "hdv_model": system.hdv.name,
            "n_states": model.nx,
        },
        "linear_coefficients": (per_vehicle if model.kind in PLATOON_KINDS
                                else _paper_coefficients(model)),  # fmt: skip
        "vehicle_coefficients": per_vehicle,
        "controllability": controllability_report(model).as_dict(),
        "observability": observability_report(model, outputs).as_dict(),
        "cases": {},
    }
    reports = {}
    for name, case in cases.items():
        K, kh = case.gains.input_feedback(model)
        table = case.toml_table()["gains"]
        entry = {"label": case.label, "semantics": case.gains.semantics, "gains": table,
                 "vehicles_used": _vehicles_used(model, table)}  # fmt: skip
        if has_head(model):
            rep = string_stability(model, K, kh, method=opts.method)
            reports[name] = (partial(gamma_state_space, model, K, kh), rep, case.label)
            entry.update(rep.as_dict())
        else:
            verdict, max_re = plant_stability(model, K, kh)
            who = "a ring" if model.ring else model.kind
            note = f"{who} has no head vehicle: head-to-tail string stability is undefined"
            if model.ring:
                note += ("; eigenvalues on the invariant hyperplane (the conserved total "
                         "spacing left out)")  # fmt: skip
            entry.update(
                plant_stable=verdict == "plant_stable", plant_verdict=verdict,
                max_real_eig=max_re, string_stable=None, verdict=None, gamma_peak=None,
                gamma_peak_omega=None, note=note,
            )
        doc["cases"][name] = entry
    extra = {"model": model, "options": opts, "reports": reports}
    return doc, extra


_STRING_WORDS = {
    "string_stable": "stable",
    "string_unstable": "unstable",
    "plant_unstable": "unstable",
    "boundary": "BOUNDARY",
}
_PLANT_WORDS = {"plant_stable": "stable", "plant_unstable": "UNSTABLE", "boundary": "BOUNDARY"}


def _vehicles(v) -> str:
    return ", ".join(str(i) for i in v) or "none"


def _print_coefficients(doc: dict) -> None:
    hdvs = [c for c in doc["vehicle_coefficients"] if c["type"] == "hdv"]
    distinct = {(c["alpha1"], c["alpha2"], c["alpha3"]) for c in hdvs}
    if len(distinct) == 1:  # a homogeneous string: the paper's one line and eq. (13)
        c = hdvs[0]
        print(f"linear coefficients: alpha1 = {c['alpha1']:.6g}, alpha2 = {c['alpha2']:.6g}, "
              f"alpha3 = {c['alpha3']:.6g}")  # fmt: skip
        verdict = "holds" if not any("(13)" in p for p in c["problems"]) else "VIOLATED"
        print(f"eq. (13): alpha1 - alpha2 alpha3 + alpha3^2 = {c['eq13_margin']:.6g} ({verdict})")
        for p in c["problems"]:
            print(f"  warning: {p}")
        return
    print(f"linear coefficients: {len(distinct)} different HDVs (per vehicle: --json)")
    for c in doc["vehicle_coefficients"]:
        if c["problems"]:
            print(f"  warning: vehicle {c['vehicle']}: {'; '.join(c['problems'])}")


def _print_human(doc: dict) -> None:
    s = doc["system"]
    ct = doc["controllability"]
    print(f"{doc['problem']} ({doc['file']})")
    where = (f"({ct['m']} ahead of the first, {ct['vehicles_behind']} behind it)"
             if s["circumference"] is None else f"on a ring of {s['circumference']:.6g} m")
    print(f"system: {s['kind']}, {s['size']} vehicles, CAVs at {_vehicles(s['cavs'])} {where}, "
          f"v* = {s['v_star']:g} m/s, s* = {s['s_star']:.4g} m, HDV model {s['hdv_model']}, "
          f"{s['n_states']} states")  # fmt: skip
    _print_coefficients(doc)
    partial_ = f"; partial: {_vehicles(ct['vehicles_partial'])}" if ct["vehicles_partial"] else ""
    rank = f"{ct['rank']}" + (f"..{ct['rank_upper']}" if ct["undecided"] else "")
    print(f"controllability: rank {rank} of {ct['n_states']} ({ct['verdict']}, "
          f"{'stabilizable' if ct['stabilizable'] else 'NOT stabilizable'}); vehicles inside: "
          f"{_vehicles(ct['vehicles_in_subspace'])}; outside: "
          f"{_vehicles(ct['vehicles_outside'])}{partial_}")  # fmt: skip
    print(f"  on the {ct['subspace']}; reachable (first CAV and behind) "
          f"{ct['reachable_states']}: {ct['reachable_verdict']}; decision margin "
          f"{_fmt(ct['decision_margin'], '.3g')}")  # fmt: skip
    if ct["conserved_mode"]:
        print(f"  conserved mode (not a defect, never excited): {ct['conserved_mode']}")
    cond = {True: "holds", False: "VIOLATED", None: "not applicable"}[ct["condition_s"]]
    print(f"  segment condition (S) (eq. 13 per segment): {cond}")
    for x in ct["cancellations"]:
        print(f"    vehicle {x['zero_vehicle']}'s zero cancels vehicle {x['pole_vehicle']}'s "
              f"pole at {x['eigenvalue']:.6g} (segment of CAV {x['cav']})")  # fmt: skip
    ob = doc["observability"]
    partial_ = f"; partial: {_vehicles(ob['vehicles_partial'])}" if ob["vehicles_partial"] else ""
    print(f"observability (outputs {', '.join(ob['outputs'])}): rank {ob['rank']} of "
          f"{ob['n_states']} ({ob['verdict']}); vehicles inside: "
          f"{_vehicles(ob['vehicles_in_subspace'])}; outside: "
          f"{_vehicles(ob['vehicles_outside'])}{partial_}")  # fmt: skip
    if not doc["cases"]:
        print("no [cases.NAME] tables: nothing else to analyse")
        return
    print()
    header = (
        f"{'case':<12} {'label':<12} {'plant':<9} {'string':<10} {'peak |G|':>10} "
        f"{'at w rad/s':>11} {'c (s^2)':>10} {'margin':>10} {'max Re lam':>11}"
    )
    print(header)
    print("-" * len(header))
    for name, e in doc["cases"].items():
        plant = _PLANT_WORDS.get(e.get("plant_verdict"),
                                 "stable" if e["plant_stable"] else "UNSTABLE")  # fmt: skip
        string = _STRING_WORDS.get(e.get("verdict"), "n/a")
        print(
            f"{name:<12} {e['label'][:12]:<12} {plant:<9} {string:<10} "
            f"{_fmt(e.get('gamma_peak'), '10.6f'):>10} "
            f"{_fmt(e.get('gamma_peak_omega'), '11.4f'):>11} "
            f"{_fmt(e.get('low_freq_curvature'), '+10.4g'):>10} "
            f"{_fmt(e.get('margin'), '+10.3g'):>10} "
            f"{_fmt(e.get('max_real_eig'), '11.4f'):>11}"
        )
    print(
        "peak |G| = sup over w > 0 of |Gamma(jw)| (at w = 0: the limit |Gamma(0)| = 1); "
        "c: |Gamma(jw)|^2 = 1 + c w^2 + ...;\nmargin: -max over w >= 0 of q(w), "
        "q = (|Gamma(jw)|^2 - 1) / w^2 relative to its terms (> band: stable, < -band: "
        "unstable, else BOUNDARY: too close to call)"
    )
    if any(e.get("verdict") is None for e in doc["cases"].values()):
        print(f"string n/a: {s['kind']} has no head vehicle (plant stability only"
              + (", on the invariant hyperplane)" if s["circumference"] is not None else ")"))


def run(args: argparse.Namespace) -> int:
    from lcc_synth.cli.output import write_and_report
    from lcc_synth.errors import ConfigError
    from lcc_synth.outputs import check_file
    from lcc_synth.provenance import provenance
    from lcc_synth.recording import record_analysis_file, recording_path

    recording_path(args, "check")  # a bad --rrd fails before the analysis runs
    if args.png:  # an existing --png needs --overwrite: refused before the analysis runs
        check_file(args.png, "--png", overwrite=args.overwrite)
    doc, extra = analyze(args.problem)
    rrd = recording_path(args, doc["problem"])
    prov = provenance(args.problem, backend=None)
    if args.png and not extra["reports"]:
        raise ConfigError(
            "--png", "needs [cases.NAME] tables on a system with a head vehicle", doc["file"]
        )

    def write(written: list[str]) -> None:
        if rrd is not None:
            import numpy as np

            omega = extra["options"].omega()
            curves = {
                name: (omega, np.abs(gamma(omega)), rep.as_dict())
                for name, (gamma, rep, _label) in extra["reports"].items()
            }
            path = record_analysis_file(rrd, doc["problem"], gamma=curves, summary=doc,
                                        overwrite=args.overwrite, provenance=prov)  # fmt: skip
            print(f"recording: {path} (lcc-synth review {path})", file=sys.stderr)
        if args.png:
            import numpy as np

            from lcc_synth.figures import plot_gamma_curves

            omega = extra["options"].omega()
            curves = {}
            for gamma, rep, label in extra["reports"].values():
                mag = np.abs(gamma(omega))
                curves[label] = (mag, rep)
            title = f"{doc['problem']}: head-to-tail |Gamma(jw)| (Fig. 9)"
            written.append(str(plot_gamma_curves(curves, omega, args.png, title=title)))

    return write_and_report(
        "analyze", args.json, write,
        lambda written, ok: {**doc, "written": written, "provenance": prov},
        lambda: _print_human(doc),
    )  # fmt: skip
