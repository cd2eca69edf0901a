"""``lcc-synth synthesize PROBLEM.toml [--out gains.json] [--json] [--figure pareto.png]``."""

from __future__ import annotations

import argparse
import json
import sys

from lcc_synth.cli.arguments import add_problem_arguments, add_recording

HELP = "synthesise H2 structured / sparse / string-stable static gains for the CAV"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_problem_arguments(
        parser, "problem file with a [synthesis] table", "print the report as one JSON object"
    )
    parser.add_argument(
        "--out", metavar="GAINS.json",
        help="write the gains as a JSON file that a [controllers.NAME] table can load (file = ...)",
    )  # fmt: skip
    parser.add_argument(
        "--figure", metavar="PNG", help="design = 'sparsity': write the Pareto-front PNG"
    )
    add_recording(parser, steps=False)


def run(args: argparse.Namespace) -> int:
    from lcc_synth.cli.output import write_and_report
    from lcc_synth.errors import ConfigError
    from lcc_synth.outputs import check_file
    from lcc_synth.problem import check_top_level, load_problem
    from lcc_synth.provenance import provenance
    from lcc_synth.recording import record_synthesis_file, recording_path

    problem = load_problem(args.problem)
    src = str(problem.path)
    try:
        check_top_level(problem.data)  # a misspelled [synthesis] gets its "did you mean"
    except ConfigError as err:
        raise err.with_source(src) from None
    if "synthesis" not in problem.data:
        raise ConfigError(
            "synthesis", "this file has no [synthesis] table (required by synthesize; e.g. "
            "problems/synth_cf_lcc_pattern.toml)", src,
        )  # fmt: skip
    # the synthesis stack (SciPy, CVXPY) once the file is read and has a [synthesis] table
    from lcc_synth.synthesis.config import spec_from_problem
    from lcc_synth.synthesis.design import synthesize
    from lcc_synth.synthesis.gains_file import write_gains
    from lcc_synth.synthesis.report import format_report

    spec = spec_from_problem(problem)
    platoon = spec.system.platoon is not None  # a gain row per CAV
    if args.figure and (platoon or spec.design != "sparsity"):
        why = (f"not available for kind = {spec.system.kind!r} yet" if platoon else
               f"only design = 'sparsity' draws a Pareto front; this one is {spec.design!r}")
        raise ConfigError("--figure", why, src)
    # every output checked before the synthesis runs: an existing file needs --overwrite
    for flag, value in (("--out", args.out), ("--figure", args.figure)):
        if value:
            check_file(value, flag, overwrite=args.overwrite)
    rrd = recording_path(args, spec.name)
    prov = provenance(problem.path, backend=None, controllers={spec.name: {"type": "h2"}})
    rep = _design(args, synthesize, spec)
    if rep is None:
        return 1

    def write(written: list[str]) -> None:
        if rrd is not None:
            path = record_synthesis_file(rrd, rep, spec.system, args.overwrite, prov)
            print(f"recording: {path} (lcc-synth review {path})", file=sys.stderr)
        if args.out:
            written.append(str(write_gains(args.out, rep, args.overwrite)))
        if args.figure:
            from lcc_synth.figures import plot_pareto_front

            written.append(str(plot_pareto_front(rep.pareto, rep.h2_unstructured, args.figure,
                                                title=rep.problem)))  # fmt: skip

    return write_and_report(
        "synthesize", args.json, write,
        lambda written, ok: {"ok": ok, **rep.as_dict(), "written": written, "provenance": prov},
        lambda: print(format_report(rep)),
    )  # fmt: skip


def _design(args: argparse.Namespace, design, spec):
    """``design(spec)`` with progress lines as asked; ``None`` (reported on stdout as JSON with
    ``--json``, and on stderr) when the synthesis fails."""
    from lcc_synth.interrupts import call_in_child
    from lcc_synth.resources import set_progress
    from lcc_synth.synthesis.h2 import SynthesisError

    set_progress(not args.quiet)
    try:  # in a child process: Ctrl-C / SIGTERM stop it at once, even inside a long LAPACK or
        # Clarabel call that holds the interpreter lock (a 402-state Riccati QZ takes seconds)
        return call_in_child(design, spec)
    except SynthesisError as err:
        if args.json:
            print(json.dumps({"ok": False, "error": str(err), "details": err.details},
                             default=str))
        print(f"lcc-synth synthesize: synthesis failed: {err}", file=sys.stderr)
        return None
    finally:
        set_progress(False)  # the switch is process-wide: back to off for later in-process calls
