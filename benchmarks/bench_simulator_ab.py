"""Simulator kernel A/B: this tree's ``simulate`` against the one of an earlier commit, in one
process, interleaved, timed in thread CPU time (robust to other load on a shared machine).

Run: ``python benchmarks/bench_simulator_ab.py [REV] [--repeat R]`` (default REV: ``HEAD~1``).
The earlier ``lcc_synth/simulation/{kernels,engine}.py`` are extracted with ``git show`` into a
temporary folder and loaded as separate modules (everything else comes from this tree); both
must give identical Table II and Appendix C results (checked) before anything is timed.
Prints the minimum and median of ``R`` single Table II runs per controller and their ratio.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

import numpy as np

from lcc_synth.experiments.spec import load_spec
from lcc_synth.simulation.engine import simulate

ROOT = Path(__file__).resolve().parents[1]


def _load(name: str, path: Path, fix=None) -> types.ModuleType:
    src = path.read_text()
    if fix is not None:
        src = fix(src)
    mod = types.ModuleType(name)
    mod.__file__ = str(path)
    sys.modules[name] = mod
    exec(compile(src, str(path), "exec"), mod.__dict__)
    return mod


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("rev", nargs="?", default="HEAD~1")
    ap.add_argument("--repeat", type=int, default=100)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="lcc_ab_"))
    for f in ("kernels", "engine"):
        text = subprocess.run(
            ["git", "-C", str(ROOT), "show", f"{args.rev}:lcc_synth/simulation/{f}.py"],
            check=True, capture_output=True, text=True,
        ).stdout  # fmt: skip
        (tmp / f"ab_old_{f}.py").write_text(text)
    _load("ab_old_kernels", tmp / "ab_old_kernels.py")
    old = _load(
        "ab_old_engine",
        tmp / "ab_old_engine.py",
        lambda s: s.replace(
            "from lcc_synth.simulation.kernels import", "from ab_old_kernels import"
        ),
    )
    spec = load_spec(ROOT / "problems" / "paper_table2.toml")
    spec_c = load_spec(ROOT / "problems" / "paper_appendix_c.toml", seeds=40)
    for sc, ctrls in ((spec.scenario, spec.controllers), (spec_c.scenario, spec_c.controllers)):
        for name, c in ctrls.items():
            a, b = old.simulate(sc, c), simulate(sc, c)
            if not (np.array_equal(a.velocity, b.velocity, equal_nan=True)
                    and np.array_equal(a.u_cmd, b.u_cmd, equal_nan=True)):  # fmt: skip
                raise SystemExit(f"{name}: results differ between {args.rev} and this tree")
    print(f"identical results ({args.rev} vs this tree): Table II, Appendix C (40 draws)")
    times: dict[tuple[str, str], list[float]] = {}
    for _ in range(args.repeat):
        for which, fn in (("old", old.simulate), ("new", simulate)):
            for name, c in spec.controllers.items():
                t0 = time.thread_time()
                fn(spec.scenario, c)
                times.setdefault((which, name), []).append(time.thread_time() - t0)
    for name in spec.controllers:
        o, n = np.array(times[("old", name)]), np.array(times[("new", name)])
        print(
            f"Table II [{name}]: {args.rev} min {o.min() * 1e3:.2f} ms median "
            f"{np.median(o) * 1e3:.2f} ms | this tree min {n.min() * 1e3:.2f} ms median "
            f"{np.median(n) * 1e3:.2f} ms (ratio of medians {np.median(n) / np.median(o):.3f})"
        )


if __name__ == "__main__":
    main()
