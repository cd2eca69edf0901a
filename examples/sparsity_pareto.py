"""Which HDVs should the CAV listen to? The sparsity Pareto front
==============================================================

Which HDVs should the CAV listen to? Group-sparse H2 Pareto front (vehicles heard vs H2).

Runs the ``problems/synth_sparsity_pareto.toml`` design through the package's API, prints the
table of every pattern found by the penalty sweep (true H2 after re-polishing on the pattern,
loss relative to hearing every vehicle) and writes the Pareto-front PNG under ``--out``.

Usage::

    python examples/sparsity_pareto.py [--problem FILE] [--out DIR]   (DIR/sparsity_pareto.png)
"""

from __future__ import annotations

import argparse
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    from lcc_synth.cli.arguments import add_example_out
    from lcc_synth.figures import plot_pareto_front
    from lcc_synth.problem import load_problem
    from lcc_synth.synthesis.config import spec_from_problem
    from lcc_synth.synthesis.design import synthesize

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problem", default=str(ROOT / "problems" / "synth_sparsity_pareto.toml"))
    add_example_out(ap)
    args = ap.parse_args()

    rep = synthesize(spec_from_problem(load_problem(args.problem)))
    print(f"{rep.problem}: {rep.kind} n={rep.n}, unstructured optimum H2 = "
          f"{rep.h2_unstructured:.4f}, sweep {rep.timings['total']:.1f} s")
    print(f"{'heard':>5s} {'H2':>9s} {'loss %':>7s} {'front':>5s} {'gamma':>9s}  vehicles")
    for p in rep.pareto:
        print(f"{p['count']:>5d} {p['h2']:>9.4f} {100 * p['loss']:>7.3f} "
              f"{'*' if p['on_front'] else '':>5s} {p['gamma']:>9.3g}  {p['vehicles']}")
    print(f"chosen: vehicles {rep.pattern} (H2 {rep.check.h2:.4f})")
    path = plot_pareto_front(
        rep.pareto, rep.h2_unstructured, Path(args.out) / "sparsity_pareto.png", title=rep.problem
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
