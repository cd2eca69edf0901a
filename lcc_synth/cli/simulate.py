"""``lcc-synth simulate PROBLEM.toml [--json] [--seeds N] [--export DIR]``.

Runs every controller of the problem file on its scenario (the same random draws for all
controllers) and prints AAVE, fuel, safety metrics and, when ``[metrics] baseline`` names a
controller, the reductions versus that controller (paired per seed: mean and spread).
``--export DIR`` writes every run's trajectories (:mod:`lcc_synth.simulation.export`).
"""

from __future__ import annotations

import json
import math
import sys
from typing import Any

from lcc_synth.cli.arguments import add_export_arguments, add_problem_arguments, add_recording

HELP = "Simulate every controller of a problem file and report AAVE, fuel and safety metrics."


def add_arguments(parser) -> None:
    add_problem_arguments(parser, "problem file (TOML) with [scenario] and [controllers.*]")
    parser.add_argument(
        "--seeds",
        type=int,
        default=None,
        metavar="N",
        help="run N random draws (scenario batch) per controller; overrides [scenario].batch",
    )
    parser.add_argument(
        "--record-seeds",
        default=None,
        metavar="LIST",
        help="with --seeds N: record only these scenarios (e.g. 0,3 or 2-5; default: all N, "
        "each as <controller>_seed<k>, one tab per seed in the viewer)",
    )
    add_recording(parser)
    add_export_arguments(parser)


#: Collided draws listed by name per controller (the rest are counted).
_MAX_LISTED = 5

#: Largest recorded batch kept in memory at once (bytes); larger seed studies run in chunks.
MEMORY_BUDGET = 1.5e9


def load(args):
    """The :class:`~lcc_synth.experiments.spec.SimulationSpec` of ``args.problem``
    (+ ``--seeds``)."""
    from lcc_synth.cli.arguments import check_export
    from lcc_synth.errors import ConfigError
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.simulation.backends import check_backend
    from lcc_synth.simulation.export import export_bytes

    if args.seeds is not None and args.seeds < 1:
        raise ConfigError("--seeds", f"must be >= 1, got {args.seeds}")
    spec = load_spec(args.problem, seeds=args.seeds, keep_going=True)
    check_backend(spec.scenario)  # SUMO missing: before any run
    check_simulation(args, spec)
    sc, runs = spec.scenario, spec.scenario.batch * len(spec.controllers)
    check_export(args, export_bytes(sc, runs), runs)
    return spec


def run_provenance(spec) -> dict[str, Any]:
    """The provenance of a ``simulate`` run (:func:`lcc_synth.provenance.provenance`)."""
    from lcc_synth.provenance import provenance

    sc = spec.scenario
    tables = {n: getattr(c, "source_table", None) or c.toml_table()
              for n, c in spec.controllers.items()}  # fmt: skip
    return provenance(
        spec.source, backend=sc.backend, controllers=tables,
        seeds={"seed": sc.seed, "draws": sc.batch, "first_index": sc.first_index},
    )  # fmt: skip


def check_simulation(args: Any, spec: Any, budget: float = MEMORY_BUDGET) -> Any:
    """Before any simulation: refuse a recording estimated above ``--max-recording-size``, a
    run whose memory estimate exceeds what is available (exit 2, one line naming ``--seeds``,
    ``scenario.batch`` or ``scenario.duration``) and a recording larger than the free space
    (``--rrd``), in that order; print the estimate on stderr when the run should take more
    than about 10 s (:data:`lcc_synth.resources.LONG_RUN_S`).

    Returns the :class:`~lcc_synth.resources.WorkEstimate`. Called by :func:`load`.
    """
    from lcc_synth.recording.cli import (
        check_recording_limit,
        check_recording_space,
        record_seed_count,
        recording_decimation,
    )
    from lcc_synth.recording.size import estimate_simulation_recording
    from lcc_synth.resources import announce, estimate_simulation, require_memory

    sc = spec.scenario
    if args.seeds is not None:
        field, fewer = "--seeds", "run fewer seeds (--seeds)"
    elif sc.batch > 1:
        field, fewer = "scenario.batch", "run fewer scenarios (scenario.batch, or --seeds N)"
    else:
        field, fewer = "scenario.duration", "shorten scenario.duration or raise scenario.dt"
    recording = None
    if not getattr(args, "no_record", False):
        seeds = record_seed_count(getattr(args, "record_seeds", None), sc.batch)
        every = recording_decimation(args)
        recording = estimate_simulation_recording(sc, spec.controllers, seeds, every)
        fixes = ("record fewer seeds (--record-seeds 0,3), " if seeds > 1 else "") + (
            "--record-every minmax, " if every != "minmax" else "") + "--no-record"
        check_recording_limit(args, recording, field, fixes)
    estimate = estimate_simulation(sc, spec.controllers, chunk=chunk_size(sc, budget),
                                   recording=recording)  # fmt: skip
    require_memory(field, estimate.memory, estimate.what, fewer)
    if recording is not None:
        check_recording_space(args, recording)
    announce("simulate", estimate)
    return estimate


def chunk_size(scenario: Any, budget: float = MEMORY_BUDGET) -> int:
    """Scenarios per seed chunk of :func:`chunks` (at most ``scenario.batch``)."""
    samples = (scenario.steps - 1) // scenario.record_every + 1
    size = max(1, int(budget // (samples * (scenario.n_vehicles * 4 * 8 + 9))))
    return min(size, scenario.batch)


def chunks(scenario, budget: float = MEMORY_BUDGET) -> list:
    """The scenario split into seed chunks whose recorded results fit ``budget`` bytes.

    Every chunk keeps the draws of the whole study (``first_index``), so results do not depend
    on the chunking.
    """
    from dataclasses import replace

    size = chunk_size(scenario, budget)
    if scenario.batch <= size:
        return [scenario]
    return [
        replace(
            scenario,
            batch=min(size, scenario.batch - b0),
            first_index=scenario.first_index + b0,
        )
        for b0 in range(0, scenario.batch, size)
    ]


def iter_results(spec, budget: float = MEMORY_BUDGET):
    """Yield ``(chunk, controller_name, SimResult)``, one controller run at a time: every
    controller on the same draws, seed chunk after seed chunk (a single chunk unless the study
    exceeds ``budget``)."""
    from lcc_synth.resources import progress_bar
    from lcc_synth.simulation.backends import run_scenario

    parts = chunks(spec.scenario, budget)
    # a bar with a count of controller runs, naming the one running (--quiet: none)
    with progress_bar(len(parts) * len(spec.controllers), "simulations") as bar:
        for i, scenario in enumerate(parts):
            draws = scenario.draw()
            for name, ctrl in spec.controllers.items():
                bar.set_postfix_str(name if len(parts) == 1 else f"{name}, chunk {i + 1}")
                result = run_scenario(scenario, ctrl, draws)
                bar.update(1)
                yield i, name, result



def collect(args, on_result=None):
    """Load the problem and simulate every controller: ``(spec, {name: SimResult})`` with the
    whole batch in memory (:func:`run` streams seed chunks instead).

    ``on_result(spec, name, result)``, when given, is called as soon as each controller's result
    exists (the recording), so an interrupted run keeps the controllers finished before.
    """
    from lcc_synth.simulation.backends import run_scenario

    spec = load(args)
    draws = spec.scenario.draw()
    results = {}
    for name, ctrl in spec.controllers.items():
        results[name] = run_scenario(spec.scenario, ctrl, draws)
        if on_result is not None:
            on_result(spec, name, results[name])
    return spec, results


def _pct(base, x):
    import numpy as np

    with np.errstate(divide="ignore", invalid="ignore"):
        return 100.0 * (base - x) / base


def _mean_finite(x) -> float:
    import numpy as np

    ok = np.isfinite(x)
    return float(np.mean(x[ok])) if ok.any() else float("nan")


def report_from(spec, per: dict[str, dict], info: dict[str, tuple]) -> dict[str, Any]:
    """Report from the :func:`lcc_synth.metrics.per_scenario` arrays of every controller;
    ``info[name] = (controller_info, controller_stats, wall_time_s)``.

    ``collided`` marks a controller with a collision in some draw (its AAVE and fuel there are
    NaN: the means are over the other draws); those controllers come last.

    A relative AAVE reduction needs a baseline AAVE above round-off. Each step rounds every
    velocity to ``eps |v|`` (``eps`` = 2.2e-16), and over the run's ``steps`` those errors add
    up to at most ``eps * max|v| * steps`` (``max|v| = |v*| +`` the baseline run's largest
    velocity error: a scale from the data, e.g. 1e-11 m/s for 3000 steps at 15 m/s). A baseline
    AAVE at or below that level cannot be told from a run in which nothing happened (e.g. the
    perturbation came after the window); a relative change of it is rounding noise, not a
    reduction: ``aave_pct`` and ``aave_pct_std`` are then ``None``, ``aave_pct_note`` says why
    and the table prints ``n/a``."""
    import numpy as np

    from lcc_synth.experiments.tables import failed_steps, failure_rank, unsafe_reasons
    from lcc_synth.metrics import PHASE_PREFIX, aggregate

    cfg = spec.metrics
    out: dict[str, Any] = {}
    for name, arrays in per.items():
        entry = aggregate(arrays)
        entry["controller"], entry["controller_stats"], entry["wall_time_s"] = info[name]
        entry["collided"] = entry["scenarios_with_collision"] > 0
        entry["failed_steps"] = failed_steps(entry["controller_stats"])
        entry["unsafe"] = unsafe_reasons(entry)  # worst case over the batch: ranked after safe
        out[name] = entry
    for name, why in getattr(spec, "failed", {}).items():  # could not be built: no metrics
        out[name] = {"failed": why, "collided": False, "failed_steps": 0, "unsafe": []}
    if cfg.baseline is not None and cfg.baseline in per:
        base = per[cfg.baseline]
        a0, f0 = base["aave"], base["fuel_ml"]
        mv = np.asarray(base["max_abs_velocity_error"], dtype=float)  # (batch, nv)
        v_max = abs(float(spec.scenario.v_star)) + np.where(np.isfinite(mv), mv, 0.0).max(axis=1)
        floor = np.finfo(float).eps * v_max * spec.scenario.steps  # the AAVE's round-off level
        at_roundoff = np.isfinite(a0) & (np.abs(a0) <= floor)
        note = None
        if at_roundoff.any():
            k = int(np.flatnonzero(at_roundoff)[0])
            note = (f"not meaningful: the baseline {cfg.baseline}'s AAVE {a0[k]:.3g} m/s is at "
                    f"round-off level (<= eps x max|v| x steps = {floor[k]:.3g} m/s: nothing "
                    "happened to reduce)")  # fmt: skip
        for name, arrays in per.items():
            if name == cfg.baseline:
                continue
            ra = _pct(a0, arrays["aave"])
            rf = _pct(f0, arrays["fuel_ml"])
            ok = np.isfinite(ra) & np.isfinite(rf)  # scenarios without a collision in either
            nan = float("nan")
            red = out[name]["reduction_vs_baseline"] = {
                "baseline": cfg.baseline,
                "aave_pct": float(np.mean(ra[ok])) if ok.any() else nan,
                "aave_pct_std": float(np.std(ra[ok])) if ok.any() else nan,
                "fuel_pct": float(np.mean(rf[ok])) if ok.any() else nan,
                "fuel_pct_std": float(np.std(rf[ok])) if ok.any() else nan,
                "scenarios": int(ok.sum()),
            }
            if note is not None:
                red.update(aave_pct=None, aave_pct_std=None, aave_pct_note=note)
            if cfg.phases:  # [metrics] phases: each phase's fuel reduction (mean over draws)
                out[name]["reduction_vs_baseline"]["fuel_phases_pct"] = {
                    p: _mean_finite(_pct(per[cfg.baseline][k], arrays[k]))
                    for p, k in ((p, PHASE_PREFIX + p) for p, _ in cfg.phases)
                }
    return dict(sorted(out.items(), key=lambda item: failure_rank(item[1])))


def report(spec, results) -> dict[str, Any]:
    """Metric summary of every controller's result (+ reductions versus the baseline)."""
    from lcc_synth.metrics import per_scenario

    per = {name: per_scenario(r, spec.metrics) for name, r in results.items()}
    info = {n: (r.controller_info, r.controller_stats, r.wall_time) for n, r in results.items()}
    return report_from(spec, per, info)


def _clean(x):
    """JSON-safe copy: NaN and infinities become null."""
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if hasattr(x, "item") and not isinstance(x, str):
        return _clean(x.item())
    return x


def _fmt(mean: float, std: float, batch: int, digits: int) -> str:
    if batch > 1:
        return f"{mean:.{digits}f} ± {std:.{digits}f}"
    return f"{mean:.{digits}f}"


def print_table(spec, rep: dict[str, Any], file=None, collisions=None) -> None:
    """Human-readable table of :func:`report`; ``collisions`` (``{name: [line, ...]}``, e.g.
    :meth:`~lcc_synth.simulation.results.SimResult.collision_report`) says which runs collided."""
    file = file or sys.stdout
    sc = spec.scenario
    cfg = spec.metrics
    if sc.layout is None:
        where = f"m={sc.m}, n={sc.n}"
    else:  # a platoon or ring: CAVs by position
        size, ring = sc.layout
        cavs = ", ".join(str(c + 1 if ring else c) for c in sc.cav_columns)
        where = f"{'ring' if ring else 'platoon'} of {size}, CAVs at {cavs}"
    print(
        f"{spec.name}: {where}, v*={sc.v_star:g} m/s, dt={sc.dt:g} s, "
        f"{sc.steps} steps, batch={sc.batch}; metrics over t in "
        f"[{cfg.window[0]:g}, {cfg.window[1]:g}] s, vehicles={cfg.vehicles}",
        file=file,
    )
    has_red = cfg.baseline is not None
    cols = ["controller", "AAVE (m/s)", "fuel (mL)"]
    if has_red:
        cols += ["AAVE red. %", "fuel red. %"]
    cols += ["foll. v std", "min s (m)", "min TTC (s)", "max|u|", "jerk rms", "jerk 1 s",
             "ISO 15622 jerk", "AEB", "collisions"]  # fmt: skip
    from lcc_synth.experiments.tables import UNSAFE_RULE, row_label

    rows = []
    for name, e in rep.items():
        if e.get("failed"):  # not run: no metrics
            rows.append([row_label(name, e)] + ["n/a"] * (len(cols) - 1))
            continue
        b = e["batch"]
        k = e["scenarios_with_collision"]
        marks = [] if not k else ["collided"] if b == 1 else [f"collided {k}/{b}"]
        marks += ["unsafe"] if not k and e.get("unsafe") else []
        steps = e.get("failed_steps") or 0
        marks += [f"QP failed on {steps} step{'s' if steps != 1 else ''}"] if steps else []
        row = [
            f"{name} ({', '.join(marks)})" if marks else name,
            _fmt(e["aave"], e["aave_std"], b, 4),
            _fmt(e["fuel_ml"], e["fuel_ml_std"], b, 2),
        ]
        if has_red:
            r = e.get("reduction_vs_baseline")
            if r:
                row += [
                    "n/a" if r["aave_pct"] is None else _fmt(r["aave_pct"], r["aave_pct_std"],
                                                             b, 2),
                    _fmt(r["fuel_pct"], r["fuel_pct_std"], b, 2),
                ]
            else:
                row += ["(baseline)", ""]
        row += [
            f"{e['follower_velocity_std']:.3f}",
            f"{e['min_spacing']:.2f}",
            f"{e['min_ttc']:.2f}",
            f"{e['max_abs_command']:.3f}",
            f"{e['rms_jerk_cav']:.3f}",
            f"{e['max_jerk_1s_cav']:.3f}",
            "ok" if e["jerk_1s_over_limit_s"] == 0 else f"over {e['jerk_1s_over_limit_s']:.2f} s",
            str(e["aeb_activations"]),
            str(e["collisions"]),
        ]
        rows.append(row)
    widths = [max(len(c), *(len(r[i]) for r in rows)) for i, c in enumerate(cols)]
    print("  ".join(c.ljust(w) for c, w in zip(cols, widths, strict=True)), file=file)
    for r in rows:
        print("  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)), file=file)
    notes = {(e.get("reduction_vs_baseline") or {}).get("aave_pct_note") for e in rep.values()}
    for note in sorted(n for n in notes if n):
        print(f"AAVE red. % n/a: {note}", file=file)
    for line in phase_lines(rep, cfg):
        print(line, file=file)
    for line in collision_lines(rep, collisions):
        print(line, file=file)
    unsafe = {n: e["unsafe"] for n, e in rep.items()
              if e.get("unsafe") and not e.get("scenarios_with_collision")}  # fmt: skip
    for name, why in unsafe.items():
        print(f"unsafe: {name}: {', '.join(why)}", file=file)
    if unsafe:
        print(UNSAFE_RULE, file=file)
    from lcc_synth.cli.output import controller_stats_lines

    stats = {n: e["controller_stats"] for n, e in rep.items() if "controller_stats" in e}
    for line in controller_stats_lines(stats):
        print(line, file=file)


def phase_lines(rep: dict[str, Any], cfg) -> list[str]:
    """``fuel per phase (mL)`` lines of :func:`report` when ``[metrics] phases`` is set: each
    controller's fuel of every phase (with its reduction versus the baseline)."""
    if not cfg.phases:
        return []
    heads = ", ".join(f"{p} [{w[0]:g}, {w[1]:g}] s" for p, w in cfg.phases)
    out = [f"fuel per phase (mL): {heads}"]
    for name, e in rep.items():
        if e.get("failed"):
            continue
        red = (e.get("reduction_vs_baseline") or {}).get("fuel_phases_pct", {})
        cells = [f"{e['fuel_ml_phases'][p]:.2f}" + (f" ({red[p]:+.2f} %)" if p in red else "")
                 for p, _ in cfg.phases]  # fmt: skip
        out.append(f"  {name}: " + ", ".join(cells))
    return out


def collision_lines(rep: dict[str, Any], collisions=None) -> list[str]:
    """``collided: NAME: ...`` lines for the controllers of :func:`report` that collided
    (``collisions``: ``{name: [line, ...]}`` of the draws that did, as in :func:`print_table`)."""
    out = []
    for name, e in rep.items():
        if e.get("failed"):
            continue
        b, k = e["batch"], e["scenarios_with_collision"]
        if not k:
            continue
        lines = (collisions or {}).get(name, [])
        more = f" (+{k - len(lines)} more)" if lines and len(lines) < k else ""
        what = "; ".join(lines) + more if lines else f"{k} of {b} draws"
        out.append(f"collided: {name}: {what}")
        means = "NaN" if k == b else f"the means over the {b - k} draws without a collision"
        out.append(f"  AAVE and fuel are {means}; the row is ranked last")
    return out


def failure_lines(rep: dict[str, Any]) -> list[str]:
    """``failed: NAME: ...`` lines for the controllers of :func:`report` that did not run, or
    whose solver failed on some steps (what makes ``simulate`` exit 1)."""
    out = []
    for name, e in rep.items():
        if e.get("failed"):
            out.append(f"failed: {name}: not run: {e['failed']}")
        elif e.get("failed_steps"):
            st = e.get("controller_stats") or {}
            why = ", ".join(f"{k} {v}" for k, v in (st.get("qp_failures") or {}).items())
            out.append(
                f"failed: {name}: its solver failed on {e['failed_steps']} of "
                f"{st.get('steps', '?')} steps (fallbacks {st.get('fallbacks', 0)}, errors "
                f"{st.get('errors', 0)}{'; QP statuses: ' + why if why else ''})"
            )
    return out


def run(args) -> int:
    from contextlib import ExitStack

    from lcc_synth.errors import ConfigError, FileError
    from lcc_synth.metrics import concatenate, per_scenario
    from lcc_synth.recording import SimulationRecorder
    from lcc_synth.simulation.export import write_trajectories

    rep: dict[str, Any] | None = None
    rec_error: FileError | None = None
    export_error: FileError | None = None
    exported: list = []
    try:
        with ExitStack() as stack:  # the recording is finalised however the run ends
            recorder = SimulationRecorder(args, stack)
            spec = load(args)
            prov = run_provenance(spec)
            recorder.provenance = prov
            if args.record_seeds is not None and spec.scenario.batch == 1:
                raise ConfigError(
                    "--record-seeds", "applies to a study of several scenarios (--seeds N, or "
                    "[scenario].batch > 1); this one has a single scenario",
                )  # fmt: skip
            if recorder.enabled:  # a bad --record-seeds fails before the simulation runs
                from lcc_synth.recording.cli import parse_record_seeds

                parse_record_seeds(getattr(args, "record_seeds", None), spec.scenario.batch)
            offsets = [c.first_index - spec.scenario.first_index for c in chunks(spec.scenario)]
            parts: dict[str, list] = {name: [] for name in spec.controllers}
            crashes: dict[str, list[str]] = {name: [] for name in spec.controllers}
            info: dict[str, tuple] = {}
            for chunk, name, result in iter_results(spec):
                recorder(spec, name, result, offset=offsets[chunk])  # the selected seeds
                if args.export is not None and export_error is None:
                    try:
                        exported += write_trajectories(
                            result, args.export, spec.name, prov, args.export_format,
                            first_index=offsets[chunk] if spec.scenario.batch > 1 else None,
                        )  # fmt: skip
                    except FileError as err:  # the results still print; exit 1
                        export_error = err
                parts[name].append(per_scenario(result, spec.metrics))
                crashes[name] += result.collision_report()[: _MAX_LISTED - len(crashes[name])]
                wall = info[name][2] + result.wall_time if name in info else result.wall_time
                info[name] = (result.controller_info, result.controller_stats, wall)
                del result
            per = {n: concatenate(p) for n, p in parts.items()}
            rep = report_from(spec, per, info)
            recorder.metrics({n: e for n, e in rep.items() if not e.get("failed")}, per)
            failures = failure_lines(rep)
            if failures:
                recorder.status("failed" if not per else "partial", "\n".join(failures))
    except FileError as err:  # the recording could not be written: the results still print
        if rep is None:
            raise
        rec_error = err
    if recorder.written is not None:
        path = recorder.written
        print(f"recording: {path} (lcc-synth review {path})", file=sys.stderr)
    if exported:
        print(f"trajectories: {len(exported)} file(s) in {args.export}", file=sys.stderr)
    if args.json:
        print(json.dumps({"results": _clean(rep), "provenance": prov}))
        for line in collision_lines(rep, crashes):
            print(line, file=sys.stderr)
    else:
        print_table(spec, rep, collisions=crashes)
    for line in failures:
        print(f"lcc-synth simulate: {line}", file=sys.stderr)
    errors = [e for e in (rec_error, export_error) if e is not None]
    for err in errors:
        print(f"lcc-synth simulate: error: {err}", file=sys.stderr)
    return 1 if failures or errors else 0
