"""The as-run trade-off of the showcase's string10: peak |Gamma| as run against the head brake.

:func:`as_run_front` designs, with :mod:`lcc_synth.synthesis.as_run_dynamics`, the gain, the
equilibrium estimator and the measurement filter of the showcase's ``h2`` controller (pattern
CAV + HDVs 1, 2 on the 10-HDV string) for a decreasing sequence of bounds on the as-run peak
``|Gamma|`` (latency 0 and 0.1 s), each search warm-started from the previous point, finds the
lowest peak the structure reaches from many starts (:func:`~lcc_synth.synthesis.
as_run_dynamics.lowest_peak`), and simulates every point, today's ``h2`` first, on the
showcase's ``head_brake`` and ``heterogeneous`` scenarios (:func:`~lcc_synth.experiments.
comparison.run_suite`: AAVE, fuel, minimum gap, emergency braking, ISO 15622 jerk).
``examples/as_run_front.py`` writes the front as CSV and PNG.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.experiments.comparison import (
    load_suite,
    prepare_controllers,
    run_suite,
)
from lcc_synth.synthesis.as_run_dynamics import (
    AsRunPoint,
    DynamicDesign,
    DynamicsSettings,
    design_dynamics,
    lowest_peak,
)
from lcc_synth.synthesis.h2 import Weights, make_plant
from lcc_synth.synthesis.structured import pattern_mask

__all__ = ["SCENARIOS", "FRONT_COLUMNS", "FrontPoint", "AsRunFront", "showcase_h2", "as_run_front",
           "front_csv"]  # fmt: skip

#: The showcase scenarios of the goal (string10).
SCENARIOS = ("head_brake", "heterogeneous")

#: Columns of :func:`front_csv` after ``name`` and ``bound``.
FRONT_COLUMNS = (
    "peak_lat0", "peak_lat01", "string_stable", "h2", "gap_peak", "equilibrium_tau",
    "measurement_filter",
    "sample_time", "aave_head_brake", "fuel_head_brake", "min_gap_head_brake",
    "jerk1s_head_brake", "aeb_head_brake", "aave_heterogeneous", "fuel_heterogeneous",
    "min_gap_heterogeneous", "jerk1s_heterogeneous", "jerk_over_limit_s_heterogeneous",
    "aeb_heterogeneous",
)


@dataclass(frozen=True)
class FrontPoint:
    """One controller of the front: its design, the exact verdict and its simulated rows
    (``rows[scenario]``: the :data:`~lcc_synth.experiments.tables.SUITE_METRICS`)."""

    name: str
    bound: float | None
    point: AsRunPoint
    string_stable: bool
    rows: dict[str, dict[str, Any]]

    def values(self) -> dict[str, Any]:
        """The :data:`FRONT_COLUMNS` of this point."""
        hb, he = self.rows["head_brake"], self.rows["heterogeneous"]
        p = self.point
        return {
            "peak_lat0": p.peaks[0], "peak_lat01": p.peaks[-1],
            "string_stable": self.string_stable, "h2": p.h2, "gap_peak": p.gap_peak,
            "equilibrium_tau": p.equilibrium_tau, "measurement_filter": p.measurement_filter,
            "sample_time": p.sample_time, "aave_head_brake": hb["aave"],
            "fuel_head_brake": hb["fuel_ml"], "min_gap_head_brake": hb["min_spacing"],
            "jerk1s_head_brake": hb["max_jerk_1s_cav"], "aeb_head_brake": hb["aeb_activations"],
            "aave_heterogeneous": he["aave"], "fuel_heterogeneous": he["fuel_ml"],
            "min_gap_heterogeneous": he["min_spacing"],
            "jerk1s_heterogeneous": he["max_jerk_1s_cav"],
            "jerk_over_limit_s_heterogeneous": he["jerk_1s_over_limit_s"],
            "aeb_heterogeneous": he["aeb_activations"],
        }  # fmt: skip


@dataclass(frozen=True)
class AsRunFront:
    """The front (today's ``h2`` first), the certificate search and the designs behind it."""

    points: list[FrontPoint]
    certificate: DynamicDesign
    designs: list[DynamicDesign]
    settings: DynamicsSettings


def showcase_h2(problem: str | Path):
    """``(suite, system, plant, mask, g0, table)`` of the showcase's ``h2`` on string10: the
    suite restricted to :data:`SCENARIOS`, the design plant and pattern of its ``[controllers.h2]``
    table and today's synthesised gain (design vector) and resolved static table."""
    suite = load_suite(problem, scenarios=list(SCENARIOS), controllers=["h2"])
    system = suite.layouts["string10"]
    tables, designs = prepare_controllers(
        {"h2": suite.controllers["h2"]}, system, "string10", source=suite.source
    )
    table = tables["h2"]
    raw = suite.controllers["h2"]
    model = system.linear_model(warn=False)
    plant = make_plant(model, table["semantics"], Weights(**raw["weights"]))
    mask = pattern_mask(plant, raw["pattern"])
    g0 = np.array([float(table["gains"].get(nm, 0.0)) for nm in plant.state_names])
    return suite, system, plant, mask, g0, table


def _x(p: AsRunPoint, plant, mask) -> np.ndarray:
    idx = np.flatnonzero(mask)
    g = [p.gains.get(plant.state_names[i], 0.0) for i in idx]
    return np.r_[g, math.log(p.equilibrium_tau), math.log(p.measurement_filter)]


def as_run_front(
    problem: str | Path,
    bounds: tuple[float, ...] = (1.12, 1.08, 1.04, 1.0),
    settings: DynamicsSettings | None = None,
    certificate: DynamicsSettings | None = None,
    progress=None,
) -> AsRunFront:
    """The front of the module docstring on ``problem`` (the showcase file).

    ``bounds``: the peak bounds, decreasing; ``settings``: the searches of the front;
    ``certificate``: the lowest-peak search (default: ``settings`` with twice the starts);
    ``progress``: ``callable(str)`` told what is being done.
    """
    say = progress or (lambda _msg: None)
    st = settings or DynamicsSettings(starts=4, maxfev=400)
    cert_st = certificate or replace(st, starts=2 * st.starts)
    suite, system, plant, mask, g0, table = showcase_h2(problem)
    tau0, tf0 = float(table["equilibrium_tau"]), float(table["measurement_filter"])
    say(f"certificate: lowest peak from {cert_st.starts} starts")
    cert = lowest_peak(plant, mask, g0, tau0, tf0, cert_st)
    designs: list[DynamicDesign] = []
    extra: list[np.ndarray] = []
    for b in bounds:
        say(f"design: peak <= {b:g}")
        d = design_dynamics(plant, mask, g0, tau0, tf0, b, st, extra_starts=extra)
        designs.append(d)
        extra = [_x(d.point, plant, mask)]
    from lcc_synth.synthesis.as_run_dynamics import evaluate_point

    dt = float(suite.scenarios[SCENARIOS[0]].scenario.dt)  # today's h2 runs every step
    today = evaluate_point(plant, g0, tau0, tf0, float(table.get("sample_time") or dt), st)
    named = {"h2": (None, today, table)}
    for b, d in zip(bounds, designs, strict=True):
        t = d.point.controller_table(table["semantics"], table["kind"])
        named[f"asrun_{b:g}"] = (b, d.point, t)
    t = cert.point.controller_table(table["semantics"], table["kind"])
    named["lowest_peak"] = (None, cert.point, t)
    say(f"simulating {len(named)} controllers on {', '.join(SCENARIOS)}")
    run = run_suite(replace(suite, controllers={k: v[2] for k, v in named.items()},
                            fallbacks={}), progress=False)  # fmt: skip
    points = []
    for name, (b, p, _t) in named.items():
        rows = {s: run.table[s][name] for s in SCENARIOS}
        ss = _exact_verdict(plant, p, st)
        points.append(FrontPoint(name, b, p, ss, rows))
    return AsRunFront(points, cert, designs, st)


def _exact_verdict(plant, p: AsRunPoint, st: DynamicsSettings) -> bool:
    from lcc_synth.analysis.as_run import as_run_loop, as_run_report, law_of_gains

    g = np.array([p.gains.get(nm, 0.0) for nm in plant.state_names])
    law = law_of_gains(plant.model, plant.gains(g))
    return all(
        as_run_report(as_run_loop(plant.model, law, p.sample_time, lat, p.equilibrium_tau,
                                  p.measurement_filter)).string_stable
        for lat in st.latencies
    )  # fmt: skip


def front_csv(front: AsRunFront) -> str:
    """The front as CSV text: ``name, bound`` and :data:`FRONT_COLUMNS`, then the gains."""
    gnames = sorted({k for p in front.points for k in p.point.gains},
                    key=lambda s: (int(s.split("_")[1]), s[0]))  # fmt: skip
    head = ["name", "bound", *FRONT_COLUMNS, *gnames]
    lines = [",".join(head)]
    for p in front.points:
        vals = p.values()
        cells = [p.name, "" if p.bound is None else repr(p.bound)]
        cells += [str(vals[k]).lower() if isinstance(vals[k], bool) else repr(float(vals[k]))
                  for k in FRONT_COLUMNS]  # fmt: skip
        cells += [repr(float(p.point.gains.get(k, 0.0))) for k in gnames]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"
