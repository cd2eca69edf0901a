"""CPU time of the figures of ``lcc-synth run`` (``problems/showcase.toml``): one
:func:`~lcc_synth.figures.plot_profiles` per scenario and one
:func:`~lcc_synth.figures.plot_gamma_curves` per layout with a head vehicle, drawn from the
real results of the showcase, the way ``lcc-synth run`` calls them.

The results (the suite's simulations and the as-run |Γ| curves, about 25 s CPU) are computed
once and kept in a pickle (``--data``, default in the system's temporary directory). Each
figure is then written ``--repeats`` times in each of two ways, alternately (so that both see
the same load of a shared machine): ``savefig``, matplotlib's own path (a layout-only draw,
then the picture; zlib level 6), what the writers did before, and ``once``, the writers as
they are (:func:`lcc_synth.figures.style._layout_once`: laid out and drawn once; zlib level
:data:`~lcc_synth.figures.style.PNG_OPTIONS`). The fastest and the median CPU time
(``time.process_time``) of each are printed, with the totals; a warm-up figure (matplotlib's
font cache, the first Agg draw) is excluded. The two write the same pixels
(``tests/test_figures.py``).

Measured 2026-12-03 on the 2-core machine at a load average of 0.5-1.0, fastest of 5,
``savefig`` -> ``once``: profiles 0.53 -> 0.48 (brake_behind), 0.58 -> 0.50 (head_sine),
0.66 -> 0.52 (head_brake), 1.10 -> 0.90 (heterogeneous), 0.50 -> 0.43 (platoon_brake),
0.57 -> 0.52 s (ring_wave); |Γ| 0.30 -> 0.27 (string10), 0.23 -> 0.19 (sec5a), 0.19 -> 0.15 s
(platoon8); all nine 4.68 -> 3.95 s CPU (-16 %). Also tried and not kept: placing each axis'
ticks once per layout pass (a memo on matplotlib's private ``Axis._update_ticks``, -22 % in
all with the above; not worth a private method). Nor drawing each curve through its
min/max-decimated rows (about 2-3 per pixel column,
:func:`lcc_synth.recording.decimate.minmax_rows`): it made the six profiles slower
(3.84 -> 4.24 s): a curve costs matplotlib per artist, not per point (Agg already
simplifies the 7,001-point paths in C++: 0.16 s for all six), and the decimation itself costs
0.5 ms per series.

Usage: ``python benchmarks/bench_figures.py [--data PATH] [--repeats 5] [--format png]
[--out DIR]`` (``--out`` keeps the figures to look at)
"""

from __future__ import annotations

import argparse
import pickle
import statistics
import tempfile
import time
from contextlib import contextmanager, nullcontext
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The frequencies of the |Γ| figures of ``lcc-synth run`` (``np.logspace(*_OMEGA)``).
OMEGA = (-3.0, 1.5, 500)


def showcase_data(problem: Path) -> dict:
    """``{"profiles": {scenario: (title, {controller: SimResult})}, "gamma": {layout: (title,
    curves)}, "omega": omega}`` of ``problem``: what ``lcc-synth run`` draws."""
    import numpy as np

    from lcc_synth.experiments.comparison import (
        applies,
        gamma_curves,
        gamma_settings,
        load_suite,
        run_suite,
    )

    suite = load_suite(problem)
    result = run_suite(suite, progress=False)
    omega = np.logspace(*OMEGA)
    profiles = {s: (suite.scenarios[s].title or s, per) for s, per in result.results.items()
                if per}  # fmt: skip
    gamma = {}
    for lname, rows in gamma_settings(suite).items():
        curves = {}
        for suffix, dt, lat, snames in rows:
            for c, k in result.controllers[lname].items():
                if any(applies(suite.controllers[c], lname, s) for s in snames):
                    per = gamma_curves({c: k}, suite.layouts[lname], omega, dt, lat)
                    curves.update({f"{n}{suffix}": v for n, v in per.items()})
        if curves:
            sy = suite.layouts[lname]
            size = (f"m={sy.m}, n={sy.n}" if sy.platoon is None else
                    f"size {sy.platoon.size}, CAVs {', '.join(map(str, sy.platoon.cavs))}")
            gamma[lname] = (f"|Γ(jω)| on layout {lname} ({sy.kind}, {size})", curves)
    return {"profiles": profiles, "gamma": gamma, "omega": omega}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problem", default=str(ROOT / "problems" / "showcase.toml"))
    ap.add_argument("--data", default=str(Path(tempfile.gettempdir()) / "bench_figures.pkl"),
                    help="pickle of the showcase's results (computed when missing)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--format", default="png", choices=("png", "pdf", "svg"))
    ap.add_argument("--out", default=None, help="keep the figures in this folder")
    args = ap.parse_args()

    data_path = Path(args.data)
    if data_path.exists():
        data = pickle.loads(data_path.read_bytes())
    else:
        t0 = time.process_time()
        data = showcase_data(Path(args.problem))
        from lcc_synth.outputs import writing

        with writing(data_path, overwrite=True) as out:  # a stopped run leaves no half file
            out.tmp.write_bytes(pickle.dumps(data))
        print(f"showcase results computed in {time.process_time() - t0:.1f} s CPU -> {data_path}")

    from lcc_synth.figures import plot_gamma_curves, plot_profiles

    jobs = [(f"profiles_{s}", plot_profiles, (per,), {"title": title})
            for s, (title, per) in data["profiles"].items()]  # fmt: skip
    jobs += [(f"gamma_{lname}", plot_gamma_curves, (curves, data["omega"]), {"title": title})
             for lname, (title, curves) in data["gamma"].items()]  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out) if args.out else Path(tmp)
        name, func, a, kw = jobs[0]
        func(*a, out / f"warmup.{args.format}", **kw)
        totals = {mode: [0.0, 0.0] for mode in MODES}
        print(f"{'figure':26s} {'savefig min':>11s} {'median':>7s} {'once min':>9s} "
              f"{'median':>7s} {'change':>7s}   ({args.repeats} repeats each, {args.format})")
        for name, func, a, kw in jobs:
            times: dict[str, list[float]] = {mode: [] for mode in MODES}
            for _ in range(args.repeats):
                for mode in MODES:
                    with _writer(mode):
                        t0 = time.process_time()
                        func(*a, out / f"{name}_{mode}.{args.format}", **kw)
                        times[mode].append(time.process_time() - t0)
            row = {m: (min(t), statistics.median(t)) for m, t in times.items()}
            for m in MODES:
                totals[m][0] += row[m][0]
                totals[m][1] += row[m][1]
            print(f"{name:26s} {row['savefig'][0]:11.3f} {row['savefig'][1]:7.3f} "
                  f"{row['once'][0]:9.3f} {row['once'][1]:7.3f} "
                  f"{row['once'][0] / row['savefig'][0] - 1:+7.0%}")  # fmt: skip
        t_s, t_o = totals["savefig"], totals["once"]
        print(f"{'total':26s} {t_s[0]:11.3f} {t_s[1]:7.3f} {t_o[0]:9.3f} {t_o[1]:7.3f} "
              f"{t_o[0] / t_s[0] - 1:+7.0%}")


#: The two ways of writing a figure that are compared.
MODES = ("savefig", "once")


@contextmanager
def _writer(mode: str):
    """``once``: the writers as they are; ``savefig``: matplotlib's own path (its layout-only
    draw before the picture, zlib's default level), what they did before."""
    from lcc_synth.figures import style

    if mode == "once":
        yield
        return
    saved = style._layout_once, style.PNG_OPTIONS
    style._layout_once = lambda fig, png, dpi: nullcontext()
    style.PNG_OPTIONS = {"compress_level": 6}
    try:
        yield
    finally:
        style._layout_once, style.PNG_OPTIONS = saved


if __name__ == "__main__":
    main()
