"""``lcc-synth run [PROBLEM.toml]``: the main job, a suite of scenarios x controllers.

Default problem: ``problems/showcase.toml`` of the repository checkout. Synthesises the ``h2``
controllers for every layout, builds the MPC, runs every controller on every scenario, prints
the metrics table and writes under ``results/<problem>-<UTC timestamp>/``: ``table.md``,
``table.csv``, ``table.json`` (the ``--json`` shape), ``details.json`` (controller tables,
synthesis reports, controller statistics, timings), the synthesised gains files,
``string_stability.txt`` (the as-run ``|Gamma|`` line of every controller; ``--verbose`` prints
them too), figures (``--format png|pdf|svg``: velocity and spacing profiles per scenario,
``|Gamma(j omega)|`` of the designs per layout) and ONE Rerun recording with every run side by
side (``logs/`` by default).

On stderr, before the work, one estimate line
(:func:`lcc_synth.experiments.suite_size.estimate_suite`: the work counted from the tables
times measured per-unit costs), then a progress bar with a count per stage (controllers,
simulations, string stability as run); ``--quiet`` silences them. Text lines on stdout are at
most :data:`~lcc_synth.cli.output.LINE_WIDTH` characters: the tables wrap their columns.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from lcc_synth.cli.arguments import add_output_arguments, add_problem_arguments, add_recording

HELP = "run the showcase comparison: baseline, paper gains, H2 gain and MPC on a scenario suite"

#: Frequencies (rad/s) of the |Gamma(j omega)| figures and recordings.
_OMEGA = (-3.0, 1.5, 500)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_problem_arguments(
        parser,
        "suite problem file (default: problems/showcase.toml of the repository)",
        optional=True,
    )
    parser.add_argument(
        "--scenarios", metavar="A,B", help="comma-separated scenario names to run (default all)"
    )
    add_output_arguments(parser, "the run", "figures")
    parser.add_argument(
        "--verbose", action="store_true",
        help="also print the as-run |Gamma| line of every controller (always written to "
        "string_stability.txt in the results directory)",
    )  # fmt: skip
    add_recording(parser)


def default_problem() -> Path:
    """``problems/showcase.toml`` next to the installed package (the repository checkout)."""
    import lcc_synth
    from lcc_synth.errors import ConfigError

    path = Path(lcc_synth.__file__).resolve().parents[1] / "problems" / "showcase.toml"
    if not path.is_file():
        raise ConfigError(
            "problem",
            f"no problem file given and the default {path} does not exist (the package is not "
            "installed from a repository checkout): pass a suite problem file",
        )
    return path


def _names(value: str | None) -> list[str] | None:
    return None if value is None else value.split(",")


def _design_cavs(result) -> dict[str, list[str]]:
    """``{<layout>.<controller>: CAV inputs}`` of the run's designs with a gain row per CAV
    (none before the designs exist)."""
    from lcc_synth.recording import synthesis_cavs

    designs = {} if result is None else result.designs
    return synthesis_cavs({f"{lname}.{cname}": rep for lname, per in designs.items()
                           for cname, rep in per.items()})  # fmt: skip


def _blueprint(suite, controllers, gamma_cases, design_names, road=None, design_cavs=None):
    """One tab per scenario (the recording module's simulation layout), plus analysis.
    ``road``: ``{scenario: road bounds}`` (:func:`lcc_synth.recording.layout.road_bounds` of
    its runs, merged), known once the runs are done; without it the road views fit the data.
    ``design_cavs``: the CAV inputs of the designs with a gain row per CAV."""
    import rerun.blueprint as rrb

    from lcc_synth.experiments.comparison import applies
    from lcc_synth.recording import analysis_blueprint, simulation_blueprint, synthesis_blueprint
    from lcc_synth.recording.layout import time_panel

    tabs = []
    for sname, ss in suite.scenarios.items():  # the controllers that run in this scenario
        ctrls = [c for c in controllers if applies(suite.controllers[c], ss.layout, sname)]
        mpc = [c for c in ctrls if suite.controllers[c].get("type") == "mpc"]
        t = ss.scenario.times()  # each tab's plots open on its own run (not the longest)
        ranges = {"time": (float(t[0]), float(t[-1])), **(road or {}).get(sname, {})}
        box = simulation_blueprint(sname, ctrls or controllers, mpc, ranges).root_container
        box.name = ss.title or sname
        tabs.append(box)
    if gamma_cases:
        box = analysis_blueprint(gamma_cases).root_container
        box.name = "|Γ(jω)| of the linear designs"
        tabs.append(box)
    if design_names:
        box = synthesis_blueprint(design_names, cavs=design_cavs).root_container
        box.name = "synthesised gains"
        tabs.append(box)
    # one time panel for every scenario: paused on the simulated time, expanded
    return rrb.Blueprint(rrb.Tabs(*tabs), rrb.BlueprintPanel(state="collapsed"),
                         rrb.SelectionPanel(state="collapsed"), time_panel(rrb))  # fmt: skip


def run(args: argparse.Namespace) -> int:
    from datetime import UTC, datetime

    from lcc_synth.errors import FileError
    from lcc_synth.experiments.comparison import gamma_settings, load_suite
    from lcc_synth.experiments.suite_size import check_suite_recording, estimate_suite
    from lcc_synth.outputs import check_directory, new_directory, remove_if_empty
    from lcc_synth.recording import recording_decimation, recording_path
    from lcc_synth.resources import notice

    problem = Path(args.problem) if args.problem else default_problem()
    suite = load_suite(problem, _names(args.scenarios), _names(args.controllers))
    now = datetime.now(UTC)
    stamp = now.strftime("%Y%m%dT%H%M%SZ")
    rrd = recording_path(args, suite.name, now=now)  # a bad or existing --rrd: before the work
    every = recording_decimation(args)
    rec_estimate = check_suite_recording(args, suite)  # --max-recording-size, the free space
    settings = gamma_settings(suite)  # {layout: [(suffix, dt, latency, scenarios)]}
    prov = _provenance(problem, suite)
    log = sys.stderr if args.json else sys.stdout
    # after every input check, before the long work: an unwritable or full --out fails now;
    # the directory is new (exclusive create) and removed again if the run leaves it empty
    check_directory(args.out, "--out", RESULTS_BYTES, "tables, details, gains and figures")
    out_dir = new_directory(args.out, suite.name, stamp)
    notice("run", f"estimate: {estimate_suite(suite, rec_estimate).line()}")
    try:
        result, curves, omega, rrd_written, rec_error = _simulate_and_record(
            args, suite, rrd, every, settings, prov
        )
        if result is None:  # nothing could be designed or run
            remove_if_empty(out_dir)
            return 1
        # what was computed is printed first: a file that cannot be written cannot hide it
        gamma = _gamma_lines(suite, curves, settings)
        _print_results(args, suite, result, curves, gamma, log, prov)
        failures = _failure_lines(result)
        for line in failures:
            print(f"lcc-synth run: {line}", file=sys.stderr)  # one line each (stderr)
        try:
            written = _write_files(args, problem, suite, result, curves, omega, out_dir,
                                   rrd_written, prov, gamma)  # fmt: skip
        except FileError as err:
            if not args.verbose and not args.json:  # computed: shown if it cannot be kept
                for line in gamma:
                    _say(line, log)
            print(f"lcc-synth run: error: {err}", file=sys.stderr)
            remove_if_empty(out_dir)
            return 1
    except BaseException:
        remove_if_empty(out_dir)  # interrupted or failed before writing anything into it
        raise
    if gamma and not args.json:
        _say(f"{_gamma_summary(curves)}: {written[-1].name}", log)
    print(f"results: {out_dir}", file=log)  # a path: never wrapped
    if rrd_written is not None:
        print(f"recording: {rrd_written}  (open with: lcc-synth review {rrd_written})", file=log)
    t = result.timings
    _say(
        f"time: controllers {t['controllers']:.1f} s, simulations {t['simulations']:.1f} s, "
        f"string stability as run {t.get('string_stability', 0.0):.1f} s",
        log,
    )
    if rec_error is not None:
        print(f"lcc-synth run: error: {rec_error}", file=sys.stderr)
        return 1
    return 1 if failures else 0


#: Bytes the results directory of a run needs at most (tables, details.json, gains files and
#: PNG figures: 1.2 MB measured for problems/showcase.toml, six scenarios; 4x for margin).
RESULTS_BYTES = 5e6


def _provenance(problem: Path, suite) -> dict:
    """The run's provenance (:func:`lcc_synth.provenance.provenance`): backends and seeds per
    scenario, the solver of every controller."""
    from lcc_synth.provenance import provenance

    return provenance(
        problem,
        backend={s: ss.scenario.backend for s, ss in suite.scenarios.items()},
        seeds={s: ss.scenario.seed for s, ss in suite.scenarios.items()},
        controllers=suite.controllers,
    )


def _simulate_and_record(args, suite, rrd, every, settings, prov):
    """Design, simulate and analyse the suite, recording as it goes. Returns ``(result,
    curves, omega, recording written, recording error)``; ``result`` is ``None`` when no
    controller could run (the reasons are printed)."""
    import time
    from contextlib import nullcontext

    import numpy as np

    from lcc_synth.errors import FileError
    from lcc_synth.experiments.comparison import applies, gamma_curves, run_suite
    from lcc_synth.experiments.suite_context import scenario_context
    from lcc_synth.recording import (
        entity_name,
        open_recording,
        record_gamma,
        record_provenance,
        record_simulation,
        record_synthesis,
        record_text,
        set_status,
        written_path,
    )
    from lcc_synth.recording.context import context_markdown
    from lcc_synth.recording.layout import merge_ranges, road_bounds
    from lcc_synth.resources import progress_bar

    ctrl_names = list(suite.controllers)
    gamma_cases = [
        f"{lname}.{c}{suffix}" for lname, rows in settings.items() for suffix, *_ in rows
        for c in ctrl_names
    ]  # fmt: skip
    design_names = [
        f"{lname}.{c}" for lname in suite.layouts_used() for c, t in suite.controllers.items()
        if t.get("type") == "h2"
    ]
    if rrd is not None:  # its layout is sent at the end, with the road views' bounds
        recording = open_recording(rrd, suite.name, scenario=suite.name,
                                   overwrite=bool(getattr(args, "overwrite", False)))
    else:
        recording = nullcontext(None)
    result, curves, omega, rec = None, {}, np.logspace(*_OMEGA), None
    road: dict = {}  # {scenario: road-view bounds of every run recorded}
    try:
        with recording as rec:
            try:
                if rec is not None:
                    record_provenance(rec, prov)
                    for sname in suite.scenarios:  # each tab's context document, as simulate's
                        record_text(rec, f"/{entity_name(sname)}/context",
                                    context_markdown(scenario_context(suite, sname),
                                                     time_panel=False))  # fmt: skip

                def on_result(sname, cname, res, row, ctrl):
                    if rec is None:
                        return
                    history = ctrl.history() if hasattr(ctrl, "history") else None
                    road[sname] = merge_ranges(road.get(sname, {}), road_bounds(res))
                    record_simulation(
                        rec, res, sname, controller=cname, metrics=row, decimate=every,
                        mpc_history=history or None,
                    )

                result = run_suite(suite, progress=not args.quiet, on_result=on_result)
                if not result.results or not any(result.results.values()):
                    for line in _failure_lines(result):
                        print(f"lcc-synth run: {line}", file=sys.stderr)
                    if rec is not None:
                        set_status(rec, "failed", "\n".join(_failure_lines(result)))
                    return None, {}, omega, None, None
                t0 = time.perf_counter()
                todo = [(lname, suffix, dt, lat, c, k) for lname, rows in settings.items()
                        for suffix, dt, lat, snames in rows
                        for c, k in result.controllers[lname].items()
                        if any(applies(suite.controllers[c], lname, s) for s in snames)]
                curves = {lname: {} for lname in settings}
                # one count per controller and setting: a measured (not linear) one takes seconds
                with progress_bar(len(todo), "string stability as run", not args.quiet,
                                  unit="curve") as bar:  # fmt: skip
                    for lname, suffix, dt, lat, c, k in todo:
                        bar.set_postfix_str(f"{lname}/{c}{suffix}")
                        per = gamma_curves({c: k}, suite.layouts[lname], omega, dt, lat)
                        curves[lname].update({f"{n}{suffix}": v for n, v in per.items()})
                        bar.update(1)
                result.timings["string_stability"] = time.perf_counter() - t0
                if rec is not None:
                    for lname, per in curves.items():
                        for cname, (mag, rep) in per.items():
                            w, m = (rep.omega, rep.ratio) if hasattr(rep, "ratio") else (omega, mag)
                            record_gamma(rec, f"{lname}.{cname}", w, m, rep.as_dict())
                    for lname, per in result.designs.items():
                        for cname, rep in per.items():
                            record_synthesis(rec, rep, name=f"{lname}.{cname}")
                    failures = _failure_lines(result)
                    if failures:
                        set_status(rec, "partial", "\n".join(failures))
            finally:  # the layout, sent once however the run ends (make_default: the one
                # the viewer opens): its road views bounded around every run recorded
                if rec is not None:
                    rec.send_blueprint(
                        _blueprint(suite, ctrl_names, gamma_cases, design_names, road,
                                   _design_cavs(result)),
                        make_active=True, make_default=True,
                    )
    except FileError as err:  # the recording could not be written: the results still count
        if result is None:
            raise
        return result, curves, omega, None, err
    return result, curves, omega, (written_path(rec) if rec is not None else None), None


def _print_results(args, suite, result, curves, gamma, log, prov) -> None:
    """The table (``--json``: the JSON document on stdout), collisions and controller
    statistics, in lines of at most :data:`~lcc_synth.cli.output.LINE_WIDTH` characters; the
    as-run |Γ| lines (``gamma``) with ``--verbose`` only (they go to a file)."""
    from lcc_synth.cli.output import LINE_WIDTH, controller_stats_lines
    from lcc_synth.experiments.tables import format_table, json_rows, json_safe, unsafe_lines

    if args.json:
        doc = {"results": json_rows(result.table), "provenance": prov,
               "string_stability": _string_stability_json(curves)}  # fmt: skip
        print(json.dumps(json_safe(doc)))
        for line in _collision_lines(result):
            _say(line, log)
        return
    _say(_title(suite))
    print(format_table(result.table, width=LINE_WIDTH))
    for line in _collision_lines(result):
        _say(line)
    for line in unsafe_lines(result.table):
        _say(line)
    stats = {f"{s}/{c}": r.controller_stats for s, per in result.results.items()
             for c, r in per.items()}  # fmt: skip
    for line in controller_stats_lines(stats, LINE_WIDTH):
        _say(line)
    if args.verbose:
        for line in gamma:
            _say(line)


def _string_stability_json(curves) -> dict:
    """``{layout: {controller[@setting]: report}}`` of ``--json``, ``table.json`` and
    ``details.json``: every controller's as-run string stability on every layout. A linear
    loop's report has ``gamma_peak``, ``gamma_peak_omega`` and ``verdict`` (the analysed
    |Γ(jω)| of the loop as run: sampling, latency, estimator, filter, described by
    ``as_run``); a nonlinear controller's (``verdict`` ``"not_linear"``) has the simulated
    tail/head amplitude ratios ``measured_ratio`` at ``measured_omega`` and ``gamma_peak``,
    their maximum."""
    return {lname: {c: rep.as_dict() for c, (_, rep) in per.items()}
            for lname, per in curves.items()}  # fmt: skip


def _say(line: str, file=None) -> None:
    """Print a line of prose wrapped at :data:`~lcc_synth.cli.output.LINE_WIDTH` characters
    (continuations indented; words and paths never split)."""
    import textwrap

    from lcc_synth.cli.output import LINE_WIDTH

    out = sys.stdout if file is None else file
    if len(line) <= LINE_WIDTH:
        print(line, file=out)
        return
    for part in textwrap.wrap(line, LINE_WIDTH, subsequent_indent="    ",
                              break_long_words=False, break_on_hyphens=False):  # fmt: skip
        print(part, file=out)


def _gamma_lines(suite, curves, settings) -> list[str]:
    """The as-run |Γ| line of every controller and setting (``string_stability.txt``)."""
    from lcc_synth.analysis.string_stability import verdict_text

    lines = []
    for lname, rows in settings.items():
        for suffix, _, lat, snames in rows:
            if suffix:
                lines.append(f"|Γ| on {lname} with the V2V latency {lat:g} s of "
                             f"{', '.join(snames)}:")  # fmt: skip
            for cname in suite.controllers:
                if f"{cname}{suffix}" in curves.get(lname, {}):
                    rep = curves[lname][f"{cname}{suffix}"][1]
                    lines.append(f"|Γ| {lname}/{cname}{suffix}: {_gamma_line(rep, verdict_text)}")
    return lines


def _gamma_summary(curves) -> str:
    """``|Γ| as run: 17 curves, 3 string stable, 6 measured (not linear)``: one curve per
    controller and setting."""
    reps = [rep for per in curves.values() for _, rep in per.values()]
    stable = sum(1 for r in reps if getattr(r, "verdict", None) == "string_stable")
    measured = sum(1 for r in reps if hasattr(r, "ratio"))
    return (f"|Γ| as run: {len(reps)} curves, {stable} string stable, {measured} measured "
            "(not linear)")  # fmt: skip


def _write_files(
    args, problem, suite, result, curves, omega, out_dir, rrd, prov, gamma
) -> list[Path]:
    """Every file of the results directory, each written atomically under a name built from
    safe parts (:func:`lcc_synth.outputs.path_part`) inside ``out_dir``; figures as
    ``--format``; the as-run |Γ| lines (``gamma``) last, in ``string_stability.txt``."""
    from lcc_synth.experiments.tables import json_safe, write_csv, write_json, write_markdown
    from lcc_synth.outputs import child, path_part, write_text
    from lcc_synth.synthesis.gains_file import write_gains

    def name(*parts: str, ext: str) -> Path:
        return child(out_dir, "_".join(path_part(p) for p in parts) + ext)

    written = [
        write_markdown(result.table, out_dir / "table.md", title=_title(suite), overwrite=False),
        write_csv(result.table, out_dir / "table.csv", overwrite=False),
        write_json(result.table, out_dir / "table.json", overwrite=False, provenance=prov,
                   string_stability=_string_stability_json(curves)),
    ]
    for lname, per in result.designs.items():
        for cname, rep in per.items():
            written.append(write_gains(name("gains", lname, cname, ext=".json"), rep, False))
    details = {
        "problem": str(problem),
        "suite": suite.name,
        "provenance": prov,
        "scenarios": {
            s: {"layout": ss.layout, "title": ss.title, "metrics_window": list(ss.metrics.window),
                "metrics_vehicles": ss.metrics.vehicles, "backend": ss.scenario.backend}
            for s, ss in suite.scenarios.items()
        },
        "layouts": {
            lname: {"kind": sy.kind, "m": sy.m, "n": sy.n, "v_star": sy.v_star}
            for lname, sy in suite.layouts.items() if lname in suite.layouts_used()
        },
        "controller_tables": result.tables,
        "failures": result.failures,
        "synthesis": {
            lname: {c: rep.as_dict() for c, rep in per.items()}
            for lname, per in result.designs.items()
        },
        "string_stability": _string_stability_json(curves),
        "controller_stats": {
            s: {c: r.controller_stats for c, r in per.items()} for s, per in result.results.items()
        },
        "timings_s": result.timings,
        "recording": str(rrd) if rrd else None,
    }
    text = json.dumps(json_safe(details), indent=2, default=str) + "\n"
    written.append(write_text(out_dir / "details.json", text))
    if not args.no_figures:
        from lcc_synth.figures import plot_gamma_curves, plot_profiles
        from lcc_synth.resources import progress_bar

        ext = f".{args.format}"
        count = sum(1 for per in result.results.values() if per) + sum(
            1 for per in curves.values() if per)
        with progress_bar(count, "figures", unit="figure") as bar:  # 0.3-2 s each
            for sname, per in result.results.items():
                if per:
                    ss = suite.scenarios[sname]
                    written.append(plot_profiles(per, name("profiles", sname, ext=ext),
                                                 title=ss.title or sname))  # fmt: skip
                    bar.update(1)
            for lname, per in curves.items():
                if per:
                    sy = suite.layouts[lname]
                    size = (f"m={sy.m}, n={sy.n}" if sy.platoon is None else
                            f"size {sy.platoon.size}, CAVs {', '.join(map(str, sy.platoon.cavs))}")
                    written.append(plot_gamma_curves(
                        per, omega, name("gamma", lname, ext=ext),
                        title=f"|Γ(jω)| on layout {lname} ({sy.kind}, {size})",
                    ))  # fmt: skip
                    bar.update(1)
    if gamma:
        written.append(write_text(out_dir / "string_stability.txt", "\n".join(gamma) + "\n"))
    return written


def _failure_lines(result) -> list[str]:
    """``failed: LAYOUT/CONTROLLER: not run: why`` and ``failed: SCENARIO/CONTROLLER: its
    solver failed on k steps`` lines (what makes ``run`` exit 1)."""
    lines = [f"failed: {lname}/{cname}: not run: {why}"
             for lname, per in result.failures.items() for cname, why in per.items()]
    for sname, per in result.table.items():
        for cname, row in per.items():
            if row.get("failed_steps"):
                st = result.results[sname][cname].controller_stats or {}
                lines.append(f"failed: {sname}/{cname}: its solver failed on "
                             f"{row['failed_steps']} of {st.get('steps', '?')} steps")
    return lines


def _collision_lines(result) -> list[str]:
    """``collided: SCENARIO/CONTROLLER: who hit whom, when`` for every run with a collision."""
    lines = []
    for sname, per in result.table.items():
        for cname, row in per.items():
            if row.get("collided"):
                what = "; ".join(result.results[sname][cname].collision_report())
                lines.append(f"collided: {sname}/{cname}: {what}")
    if lines:
        lines.append("(a collided run has NaN AAVE and fuel and is ranked last in its scenario)")
    return lines


def _gamma_line(rep, verdict_text) -> str:
    """``peak ... -> verdict`` of an as-run report, or the measured ratios of a nonlinear one."""
    if hasattr(rep, "ratio"):
        pts = ", ".join(f"{r:.3f}@{w:g}" for w, r in zip(rep.omega, rep.ratio, strict=True))
        return f"not linear; measured tail/head (ratio@rad/s) {pts} -> max {rep.gamma_peak:.4f}"
    loop = rep.loop
    what = [f"{loop['equilibrium']} equilibrium"]
    if loop.get("sample_time"):
        what.append(f"T = {loop['sample_time']:g} s")
    if loop.get("latency"):
        what.append(f"latency {loop['latency']:g} s")
    if loop.get("measurement_filter"):
        what.append(f"filter {loop['measurement_filter']:g} s")
    at = f" at {rep.gamma_peak_omega:.3g} rad/s" if rep.gamma_peak_omega > 0 else ""
    return (
        f"as run ({', '.join(what)}): peak {rep.gamma_peak:.4f}{at}, margin {rep.margin:+.3g}"
        f" -> {verdict_text(rep.verdict)}"
    )


def _title(suite) -> str:
    return f"{suite.name}: {len(suite.scenarios)} scenarios x {len(suite.controllers)} controllers"
