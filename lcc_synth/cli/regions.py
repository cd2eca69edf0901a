"""``lcc-synth regions PROBLEM.toml [--json] [--png PATH] [--step STEP]``.

Computes every ``[maps.NAME]`` string-stable region map of the problem (Figs. 7-8): the
fractions of the ``(mu_i, k_i)`` grid that are plant stable and head-to-tail string stable,
and, for a map with a ``baseline``, how much string-stable area it gains over the baseline.
On an open platoon each map names the CAV whose gains vary (``cav``); see
:mod:`lcc_synth.analysis.region_specs`.
"""

from __future__ import annotations

import argparse
import sys

from lcc_synth.cli.arguments import add_problem_arguments, add_recording

HELP = "string-stable regions of one vehicle's feedback gains (Figs. 7-8)"

#: The estimate printed first: seconds per grid row and frequency (the closed-form roots of
#: the quadratics in ``k``) and per grid point (marking, Routh-Hurwitz). Measured on
#: ``problems/paper_fig7_fig8_regions.toml`` (eight 1001 x 1001 maps, 8570 frequencies):
#: 1.7-5.8 s per map, 13.6-38 s in all on this shared 2-core machine; the constants give 38 s.
ROW_FREQUENCY_S = 5e-7
POINT_S = 5e-7


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_problem_arguments(parser, "problem file with [system] and [maps.NAME] tables")
    parser.add_argument("--png", metavar="PATH", help="write the maps as one PNG (Figs. 7-8)")
    parser.add_argument(
        "--step", type=float, metavar="STEP", help="override the grid step of every map"
    )
    add_recording(parser, steps=False)


def run(args: argparse.Namespace) -> int:
    import time

    from lcc_synth.cli.output import write_and_report
    from lcc_synth.errors import ConfigError
    from lcc_synth.outputs import check_file
    from lcc_synth.problem import load_problem, system_from
    from lcc_synth.provenance import provenance
    from lcc_synth.recording import record_analysis_file, recording_path

    prob = load_problem(args.problem)
    rrd = recording_path(args, prob.name)  # a bad --rrd fails before the maps are computed
    if args.png:  # an existing --png needs --overwrite: refused before the maps are computed
        check_file(args.png, "--png", overwrite=args.overwrite)
    prov = provenance(prob.path, backend=None)
    src = str(prob.path)
    if args.step is not None and not args.step > 0:
        raise ConfigError("--step", f"must be > 0, got {args.step}")
    system = system_from(prob.data, src)
    # the analysis stack (SciPy) once the file, its system and the outputs are checked
    from lcc_synth.analysis.region_specs import expansion, region_specs_from, run_region_specs

    model = system.linear_model(warn=False)
    specs, omega = region_specs_from(prob.data, model, src, step=args.step)
    from lcc_synth.resources import format_duration, notice, progress_bar

    rows = sum(s.mu.size for s in specs.values())
    points = sum(s.mu.size * s.k.size for s in specs.values())
    guess = rows * omega.size * ROW_FREQUENCY_S + points * POINT_S
    notice("regions", f"estimate: {len(specs)} maps, {points} grid points x {omega.size} "
           f"frequencies, about {format_duration(guess)}")  # fmt: skip
    t0 = time.perf_counter()
    with progress_bar(points, "regions", unit="point") as bar:

        def advance(name: str, done: int) -> None:
            bar.set_postfix_str(name)
            bar.update(done * specs[name].k.size)

        maps = run_region_specs(model, specs, omega, on_rows=advance)
    total = time.perf_counter() - t0
    doc = {
        "problem": prob.name,
        "file": src,
        "system": {"kind": system.kind, "m": system.m, "n": system.n, "v_star": system.v_star},
        "n_omega": int(omega.size),
        "omega_range": [float(omega[0]), float(omega[-1])],
        "seconds": total,
        "maps": {},
    }
    for name, rm in maps.items():
        entry = rm.as_dict()
        entry["title"] = specs[name].title
        entry["us_per_point"] = 1e6 * rm.seconds / rm.points
        if specs[name].baseline:
            entry["baseline"] = specs[name].baseline
            entry["expansion"] = expansion(rm, maps[specs[name].baseline])
        doc["maps"][name] = entry

    def write(written: list[str]) -> None:
        if rrd is not None:
            reports = {n: {k: v for k, v in e.items() if k != "labels"}
                       for n, e in doc["maps"].items()}  # fmt: skip
            path = record_analysis_file(rrd, prob.name, regions=maps, region_reports=reports,
                                        summary=doc, overwrite=args.overwrite, provenance=prov)
            print(f"recording: {path} (lcc-synth review {path})", file=sys.stderr)
        if args.png:
            from lcc_synth.figures import plot_region_maps

            baselines = {n: maps[s.baseline] for n, s in specs.items() if s.baseline}
            titles = {n: s.title for n, s in specs.items()}
            written.append(str(plot_region_maps(maps, args.png, baselines, titles)))

    def report() -> None:
        layout = (f"CAVs at {list(model.cavs)} of {len(model.vehicles)}"
                  if model.kind == "platoon" else f"m = {system.m}, n = {system.n}")
        print(f"{doc['problem']} ({src}): {system.kind}, {layout}, "
              f"v* = {system.v_star:g} m/s; {omega.size} frequencies in "
              f"[{omega[0]:g}, {omega[-1]:g}] rad/s")
        _print_table(doc["maps"])
        print(f"total {total:.2f} s for {sum(m.points for m in maps.values())} points")

    return write_and_report(
        "regions", args.json, write,
        lambda written, ok: {**doc, "written": written, "provenance": prov}, report,
    )  # fmt: skip


def _print_table(maps: dict) -> None:
    """The maps' rows (``doc["maps"]``: fractions, the gain against the baseline, time) and the
    maps' points too close to call."""
    header = (
        f"{'map':<8} {'vehicle':>7} {'grid':>11} {'fixed gains':<22} {'plant st.':>9} "
        f"{'string st.':>10} {'vs baseline':<22} {'s':>6}"
    )
    print(header)
    print("-" * len(header))
    for name, e in maps.items():
        fixed = ", ".join(f"{k}={v:g}" for k, v in e["fixed_gains"].items()) or "-"
        vs = "-"
        if "expansion" in e:
            x = e["expansion"]
            vs = f"+{100 * x['gained_fraction']:.2f}% / -{100 * x['lost_fraction']:.2f}%"
        shape = f"{e['shape'][0]}x{e['shape'][1]}"
        vehicle = f"{e['vehicle']} (u_{e['cav']})" if "cav" in e else str(e["vehicle"])
        print(
            f"{name:<8} {vehicle:>7} {shape:>11} {fixed:<22} "
            f"{100 * e['plant_stable_fraction']:>8.2f}% {100 * e['string_stable_fraction']:>9.2f}% "
            f"{vs:<22} {e['seconds']:>6.2f}"
        )
    print("fractions of the grid; 'vs baseline': string-stable area gained / lost")
    close = {n: e["boundary_points"] for n, e in maps.items() if e["boundary_points"]}
    if close:
        print(
            "too close to call (inside the rounding band, labelled 'stable'): "
            + ", ".join(f"{n} {k} points" for n, k in close.items())
        )
