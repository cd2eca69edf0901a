"""Cost of the controllability/observability reports and of the Gramian, per call.

Usage: python benchmarks/bench_controllability_energy.py
"""

from __future__ import annotations

import time

from lcc_synth.analysis.controllability import (
    controllability_report,
    default_outputs,
    observability_report,
)
from lcc_synth.analysis.energy import gramian
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import fd_lcc, general_lcc


def _per_call(fn, repeat: int) -> float:
    fn()
    t0 = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - t0) / repeat


def main() -> None:
    coef = OVM().linear_coefficients(15.0)
    for m, n in [(2, 2), (5, 15), (10, 40)]:
        model = general_lcc(m, n, coef)
        outs = default_outputs(model, n)
        tc = _per_call(lambda model=model: controllability_report(model), 20)
        to = _per_call(lambda model=model, outs=outs: observability_report(model, outs), 20)
        print(
            f"general LCC m={m:2d} n={n:2d} ({model.nx:3d} states): "
            f"controllability {tc * 1e3:7.2f} ms, observability {to * 1e3:7.2f} ms"
        )
    for n in (5, 15, 40):
        model = fd_lcc(n, coef)
        tg = _per_call(lambda model=model: gramian(model.A, model.B, 30.0), 10)
        print(f"FD-LCC n={n:2d} ({model.nx:3d} states): gramian W(30 s) {tg * 1e3:7.2f} ms")


if __name__ == "__main__":
    main()
