"""``lcc-synth simulate PROBLEM.toml [--json] [--seeds N]``.

Runs every controller of the problem file on its scenario (the same random draws for all
controllers) and prints AAVE, fuel, safety metrics and, when ``[metrics] baseline`` names a
controller, the reductions versus that controller (paired per seed: mean and spread).
"""

from __future__ import annotations

import json
import math
import sys
from typing import Any

HELP = "Simulate every controller of a problem file and report AAVE, fuel and safety metrics."


def add_arguments(parser) -> None:
    parser.add_argument("problem", help="problem file (TOML) with [scenario] and [controllers.*]")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.add_argument(
        "--seeds",
        type=int,
        default=None,
        metavar="N",
        help="run N random draws (scenario batch) per controller; overrides [scenario].batch",
    )
    from lcc_synth.recording import add_recording_arguments

    add_recording_arguments(parser)


def collect(args, on_result=None):
    """Load the problem and simulate every controller: ``(spec, {name: SimResult})``.

    ``on_result(spec, name, result)``, when given, is called as soon as each controller's result
    exists (the recording), so an interrupted run keeps the controllers finished before.
    """
    from lcc_synth.errors import ConfigError
    from lcc_synth.scenario import load_spec
    from lcc_synth.simulation import simulate_many

    if args.seeds is not None and args.seeds < 1:
        raise ConfigError("--seeds", f"must be >= 1, got {args.seeds}")
    spec = load_spec(args.problem, seeds=args.seeds)
    if on_result is None:
        return spec, simulate_many(spec.scenario, spec.controllers)
    results = {}
    for name, ctrl in spec.controllers.items():  # same draws: they depend on the seed only
        results.update(simulate_many(spec.scenario, {name: ctrl}))
        on_result(spec, name, results[name])
    return spec, results


def _pct(base, x):
    import numpy as np

    with np.errstate(divide="ignore", invalid="ignore"):
        return 100.0 * (base - x) / base


def report(spec, results) -> dict[str, Any]:
    """Metric summary of every controller (+ reductions versus the baseline, if any)."""
    import numpy as np

    from lcc_synth.metrics import aave, fuel, summary

    cfg = spec.metrics
    out: dict[str, Any] = {}
    for name, res in results.items():
        entry = summary(res, cfg)
        entry["controller"] = res.controller_info
        entry["controller_stats"] = res.controller_stats
        entry["wall_time_s"] = res.wall_time
        out[name] = entry
    if cfg.baseline is not None:
        base = results[cfg.baseline]
        a0 = aave(base, cfg.window, cfg.vehicles)
        f0 = fuel(base, cfg.window, cfg.vehicles)
        for name, res in results.items():
            if name == cfg.baseline:
                continue
            ra = _pct(a0, aave(res, cfg.window, cfg.vehicles))
            rf = _pct(f0, fuel(res, cfg.window, cfg.vehicles))
            out[name]["reduction_vs_baseline"] = {
                "baseline": cfg.baseline,
                "aave_pct": float(np.mean(ra)),
                "aave_pct_std": float(np.std(ra)),
                "fuel_pct": float(np.mean(rf)),
                "fuel_pct_std": float(np.std(rf)),
            }
    return out


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


def print_table(spec, rep: dict[str, Any], file=None) -> None:
    """Human-readable table of :func:`report`."""
    file = file or sys.stdout
    sc = spec.scenario
    cfg = spec.metrics
    print(
        f"{spec.name}: m={sc.m}, n={sc.n}, v*={sc.v_star:g} m/s, dt={sc.dt:g} s, "
        f"{sc.steps} steps, batch={sc.batch}; metrics over t in "
        f"[{cfg.window[0]:g}, {cfg.window[1]:g}] s, vehicles={cfg.vehicles}",
        file=file,
    )
    has_red = cfg.baseline is not None
    cols = ["controller", "AAVE (m/s)", "fuel (mL)"]
    if has_red:
        cols += ["AAVE red. %", "fuel red. %"]
    cols += ["min s (m)", "min TTC (s)", "max|u|", "jerk rms", "AEB", "collisions"]
    rows = []
    for name, e in rep.items():
        b = e["batch"]
        row = [
            name,
            _fmt(e["aave"], e["aave_std"], b, 4),
            _fmt(e["fuel_ml"], e["fuel_ml_std"], b, 2),
        ]
        if has_red:
            r = e.get("reduction_vs_baseline")
            if r:
                row += [
                    _fmt(r["aave_pct"], r["aave_pct_std"], b, 2),
                    _fmt(r["fuel_pct"], r["fuel_pct_std"], b, 2),
                ]
            else:
                row += ["(baseline)", ""]
        row += [
            f"{e['min_spacing']:.2f}",
            f"{e['min_ttc']:.2f}",
            f"{e['max_abs_command']:.3f}",
            f"{e['rms_jerk_cav']:.3f}",
            str(e["aeb_activations"]),
            str(e["collisions"]),
        ]
        rows.append(row)
    widths = [max(len(c), *(len(r[i]) for r in rows)) for i, c in enumerate(cols)]
    print("  ".join(c.ljust(w) for c, w in zip(cols, widths, strict=True)), file=file)
    for r in rows:
        print("  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)), file=file)
    for name, e in rep.items():
        if e["controller_stats"]:
            print(f"{name} stats: {json.dumps(_clean(e['controller_stats']))}", file=file)


def run(args) -> int:
    from contextlib import ExitStack

    from lcc_synth.recording import SimulationRecorder

    with ExitStack() as stack:  # the recording is finalised however the run ends
        recorder = SimulationRecorder(args, stack)
        spec, results = collect(args, recorder if recorder.enabled else None)
        rep = report(spec, results)
        recorder.metrics(rep)
    if recorder.path is not None:
        print(f"recording: {recorder.path} (lcc-synth review {recorder.path})", file=sys.stderr)
    if args.json:
        print(json.dumps({"results": _clean(rep)}))
    else:
        print_table(spec, rep)
    return 0
