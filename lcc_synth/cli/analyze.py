"""``lcc-synth analyze PROBLEM.toml [--json] [--png PATH]``.

For the problem's linear system: the linear coefficients and the controllability condition
(13), the controllable and observable subspaces (which vehicles they contain); for every
``[cases.NAME]`` gain: closed-loop plant stability, the head-to-tail string-stability verdict
and the peak ``|Gamma(jw)|`` with its frequency. ``--png`` draws ``|Gamma(jw)|`` of every case
(Fig. 9). ``kind = "platoon" | "ring"`` (several CAVs, the ring on its invariant hyperplane,
gains per CAV in ``[cases.NAME.gains.u_3]``): :mod:`lcc_synth.cli.analyze_platoon`.
"""

from __future__ import annotations

import argparse
import json
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


def analyze(problem_path: str) -> tuple[dict, dict]:
    """Everything ``analyze`` reports, as a JSON-ready dict, plus the objects for plotting."""
    from lcc_synth.analysis.cases import analysis_options_from, cases_from
    from lcc_synth.analysis.controllability import (
        controllability_report,
        default_outputs,
        observability_report,
    )
    from lcc_synth.analysis.string_stability import string_stability
    from lcc_synth.analysis.transfer import closed_loop_eigenvalues, gamma_state_space
    from lcc_synth.errors import ConfigError
    from lcc_synth.models.feedback import closed_loop, input_feedback
    from lcc_synth.problem import load_problem, system_from

    prob = load_problem(problem_path)
    src = str(prob.path)
    system = system_from(prob.data, src)
    model = system.linear_model(warn=False)
    opts = analysis_options_from(prob.data, src)
    if system.platoon is not None:  # kind = "platoon" | "ring": several CAVs, the ring
        from lcc_synth.cli.analyze_platoon import platoon_document

        cases = cases_from(prob.data, model, src)
        doc, reports = platoon_document(prob, system, model, opts, cases)
        return doc, {"model": model, "options": opts, "reports": reports}
    outputs = list(opts.outputs) if opts.outputs else default_outputs(model)
    for name in outputs:
        if name not in model.state_names:
            raise ConfigError(
                "analysis.outputs",
                f"unknown state {name!r}; this model has {list(model.state_names)}",
                src,
            )
    cases = cases_from(prob.data, model, src)

    coef = model.coefficients[1 if model.n > 0 else -1]
    doc: dict = {
        "problem": prob.name,
        "file": src,
        "system": {
            "kind": system.kind,
            "m": system.m,
            "n": system.n,
            "v_star": system.v_star,
            "s_star": system.s_star,
            "hdv_model": system.hdv.name,
            "n_states": model.nx,
        },
        "linear_coefficients": {
            "alpha1": coef.alpha1,
            "alpha2": coef.alpha2,
            "alpha3": coef.alpha3,
            "eq13_margin": coef.controllability_margin,
            "eq13_holds": not any("(13)" in p for p in coef.problems()),
            "problems": coef.problems(),
        },
        "controllability": controllability_report(model).as_dict(),
        "observability": observability_report(model, outputs).as_dict(),
        "cases": {},
    }
    reports = {}
    for name, case in cases.items():
        K, kh = input_feedback(model, case.gains)
        entry = {"label": case.label, "semantics": case.gains.semantics,
                 "gains": dict(case.gains.gains), "vehicles_used": case.gains.vehicles()}
        if model.kind == "fd_lcc":
            Acl, _ = closed_loop(model, K, kh)
            max_re = float(closed_loop_eigenvalues(Acl).real.max())
            entry.update(
                plant_stable=bool(max_re < 0), string_stable=None, verdict=None, gamma_peak=None,
                gamma_peak_omega=None, max_real_eig=max_re,
                note="fd_lcc has no head vehicle: head-to-tail string stability is undefined",
            )
        else:
            rep = string_stability(model, K, kh, method=opts.method)
            reports[name] = (partial(gamma_state_space, model, K, kh), rep, case.label)
            entry.update(rep.as_dict())
        doc["cases"][name] = entry
    extra = {"model": model, "options": opts, "reports": reports}
    return doc, extra


_STRING_WORDS = {
    "string_stable": "stable",
    "string_unstable": "unstable",
    "plant_unstable": "unstable",
    "boundary": "BOUNDARY",
}


def _print_human(doc: dict) -> None:
    s = doc["system"]
    c = doc["linear_coefficients"]
    print(f"{doc['problem']} ({doc['file']})")
    print(
        f"system: {s['kind']}, m = {s['m']} HDVs ahead, n = {s['n']} behind, "
        f"v* = {s['v_star']:g} m/s, s* = {s['s_star']:.4g} m, HDV model {s['hdv_model']}"
    )
    print(
        f"linear coefficients: alpha1 = {c['alpha1']:.6g}, alpha2 = {c['alpha2']:.6g}, "
        f"alpha3 = {c['alpha3']:.6g}"
    )
    verdict = "holds" if c["eq13_holds"] else "VIOLATED"
    print(f"eq. (13): alpha1 - alpha2 alpha3 + alpha3^2 = {c['eq13_margin']:.6g} ({verdict})")
    for p in c["problems"]:
        print(f"  warning: {p}")

    def vehicles(v):
        return ", ".join(str(i) for i in v) or "none"

    ct = doc["controllability"]
    print(
        f"controllability: rank {ct['rank']} of {ct['n_states']} "
        f"({'controllable' if ct['controllable'] else 'not controllable'}, "
        f"{'stabilizable' if ct['stabilizable'] else 'NOT stabilizable'}); "
        f"vehicles inside: {vehicles(ct['vehicles_in_subspace'])}; "
        f"outside: {vehicles(ct['vehicles_outside'])}"
        + (f"; partial: {vehicles(ct['vehicles_partial'])}" if ct["vehicles_partial"] else "")
    )
    ob = doc["observability"]
    print(
        f"observability (outputs {', '.join(ob['outputs'])}): rank {ob['rank']} of "
        f"{ob['n_states']} ({'observable' if ob['observable'] else 'not observable'}); "
        f"vehicles inside: {vehicles(ob['vehicles_in_subspace'])}; "
        f"outside: {vehicles(ob['vehicles_outside'])}"
        + (f"; partial: {vehicles(ob['vehicles_partial'])}" if ob["vehicles_partial"] else "")
    )
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
        plant = "stable" if e["plant_stable"] else "UNSTABLE"
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


def run(args: argparse.Namespace) -> int:
    from lcc_synth.errors import ConfigError, FileError
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
    written, error = [], None
    try:  # a file that cannot be written (a full disk) does not hide the report printed below
        if rrd is not None:
            import numpy as np

            omega = extra["options"].omega()
            curves = {
                name: (omega, np.abs(gamma(omega)), rep.as_dict())
                for name, (gamma, rep, _label) in extra["reports"].items()
            }
            rrd = record_analysis_file(rrd, doc["problem"], gamma=curves, summary=doc,
                                       overwrite=args.overwrite, provenance=prov)  # fmt: skip
            print(f"recording: {rrd} (lcc-synth review {rrd})", file=sys.stderr)
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
    except FileError as err:
        error = err
    doc["written"] = written
    if args.json:
        print(json.dumps({**doc, "provenance": prov}))
    elif "size" in doc["system"]:  # kind = "platoon" | "ring"
        from lcc_synth.cli.analyze_platoon import print_platoon

        print_platoon(doc)
    else:
        _print_human(doc)
        for w in written:
            print(f"wrote {w}")
    if error is not None:
        print(f"lcc-synth analyze: error: {error}", file=sys.stderr)
        return 1
    return 0
