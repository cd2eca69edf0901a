"""Problem file -> scenario, controllers and metric settings (format: ``problems/README.md``)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.controllers.base import Controller
from lcc_synth.controllers.registry import build_controller
from lcc_synth.errors import ConfigError
from lcc_synth.metrics import VEHICLE_SETS, MetricsConfig
from lcc_synth.problem import (
    Problem,
    System,
    check_keys,
    get_bool,
    get_int,
    get_number,
    get_number_list,
    get_str,
    get_table,
    load_problem,
    system_from,
)
from lcc_synth.simulation.engine import V2V, Scenario
from lcc_synth.simulation.perturbations import perturbation_from_table, vehicle_column

__all__ = ["SimulationSpec", "scenario_from", "metrics_from", "controllers_from", "load_spec"]

_SCENARIO_KEYS = [
    "dt", "duration", "t_start", "a_min", "a_max", "cav_aeb", "hdv_aeb", "seed", "batch",
    "record_every", "spacing_reference", "hdv_accel_noise", "heterogeneity", "delay", "v2v",
    "perturbations", "hdv_values",
]  # fmt: skip


@dataclass(frozen=True)
class SimulationSpec:
    """Everything ``lcc-synth simulate`` needs from a problem file."""

    name: str
    system: System
    scenario: Scenario
    controllers: dict[str, Controller]
    metrics: MetricsConfig
    source: str


def scenario_from(data: Mapping[str, Any], system: System, base_dir: Path | None = None):
    """Build the :class:`~lcc_synth.simulation.engine.Scenario` of a problem's ``[scenario]``
    table."""
    f = "scenario"
    sc = get_table(data, "scenario", f)
    check_keys(sc, _SCENARIO_KEYS, f)
    hv_t = get_table(sc, "hdv_values", f"{f}.hdv_values")
    hdv_values = None
    if hv_t:
        from lcc_synth.simulation.engine import MODEL_PARAMS

        allowed = MODEL_PARAMS[system.hdv.name]
        check_keys(hv_t, allowed, f"{f}.hdv_values")
        hdv_values = {}
        hdv_cols = [j for j in range(system.m + system.n + 2) if j not in (0, system.m + 1)]
        for key in hv_t:
            vals = get_number_list(hv_t, key, f"{f}.hdv_values", length=len(hdv_cols))
            full = np.full(system.m + system.n + 2, float(getattr(system.hdv, key)))
            full[hdv_cols] = vals
            hdv_values[key] = full
    het = get_table(sc, "heterogeneity", f"{f}.heterogeneity")
    heterogeneity = {k: get_number(het, k, f"{f}.heterogeneity", lo=0.0) for k in het}
    delay_t = get_table(sc, "delay", f"{f}.delay")
    check_keys(delay_t, ["mean", "spread", "model"], f"{f}.delay")
    delay_model = get_str(delay_t, "model", f"{f}.delay", "full", choices=["full", "perception"])
    delay = get_number(delay_t, "mean", f"{f}.delay", 0.0, lo=0.0)
    spread = get_number(delay_t, "spread", f"{f}.delay", 0.0, lo=0.0, hi=delay)
    v2v_t = get_table(sc, "v2v", f"{f}.v2v")
    check_keys(
        v2v_t,
        ["loss_rate", "latency", "spacing_noise", "velocity_noise", "position_noise"],
        f"{f}.v2v",
    )
    nv = system.m + system.n + 2
    if isinstance(v2v_t.get("loss_rate"), list):
        loss = get_number_list(v2v_t, "loss_rate", f"{f}.v2v", length=nv, lo=0.0, hi=1.0)
    else:
        loss = get_number(v2v_t, "loss_rate", f"{f}.v2v", 0.0, lo=0.0, hi=1.0)
    v2v = V2V(
        loss,
        get_number(v2v_t, "latency", f"{f}.v2v", 0.0, lo=0.0),
        get_number(v2v_t, "spacing_noise", f"{f}.v2v", 0.0, lo=0.0),
        get_number(v2v_t, "velocity_noise", f"{f}.v2v", 0.0, lo=0.0),
        get_number(v2v_t, "position_noise", f"{f}.v2v", 0.0, lo=0.0),
    )
    perts = sc.get("perturbations", [])
    if not isinstance(perts, list):
        raise ConfigError(
            f"{f}.perturbations", "must be an array of tables [[scenario.perturbations]]"
        )
    perturbations = tuple(
        perturbation_from_table(p, f"{f}.perturbations[{i}]", system.m, system.n, base_dir)
        for i, p in enumerate(perts)
    )
    return Scenario(
        m=system.m,
        n=system.n,
        hdv=system.hdv,
        v_star=system.v_star,
        dt=get_number(sc, "dt", f, 0.01, lo=0.0, lo_open=True),
        duration=get_number(sc, "duration", f, 100.0, lo=0.0, lo_open=True),
        t_start=get_number(sc, "t_start", f, 0.0),
        batch=get_int(sc, "batch", f, 1, lo=1),
        a_min=get_number(sc, "a_min", f, -5.0, hi=0.0, hi_open=True),
        a_max=get_number(sc, "a_max", f, 2.0, lo=0.0, lo_open=True),
        cav_aeb=get_bool(sc, "cav_aeb", f, True),
        hdv_aeb=get_bool(sc, "hdv_aeb", f, False),
        perturbations=perturbations,
        hdv_values=hdv_values,
        heterogeneity=heterogeneity,
        delay=delay,
        delay_spread=spread,
        delay_model=delay_model,
        hdv_accel_noise=get_number(sc, "hdv_accel_noise", f, 0.0, lo=0.0),
        v2v=v2v,
        seed=get_int(sc, "seed", f, 0, lo=0),
        record_every=get_int(sc, "record_every", f, 1, lo=1),
        spacing_reference=get_str(
            sc, "spacing_reference", f, "nominal", choices=["nominal", "own_equilibrium"]
        ),
    )


def metrics_from(data: Mapping[str, Any], system: System, controllers=()) -> MetricsConfig:
    """The ``[metrics]`` table."""
    f = "metrics"
    mt = get_table(data, "metrics", f)
    check_keys(mt, ["window", "vehicles", "baseline"], f)
    window = tuple(get_number_list(mt, "window", f, [20.0, 40.0], length=2))
    vehicles = mt.get("vehicles", "cav_and_behind")
    if isinstance(vehicles, list):
        for v in vehicles:
            vehicle_column(v, system.m, system.n, f"{f}.vehicles")
        vehicles = tuple(vehicles)
    elif vehicles not in VEHICLE_SETS:
        raise ConfigError(
            f"{f}.vehicles", f"must be one of {list(VEHICLE_SETS)} or a list of vehicle indices"
        )
    baseline = get_str(mt, "baseline", f, None)
    if baseline is not None and controllers and baseline not in controllers:
        raise ConfigError(f"{f}.baseline", f"must name a controller, one of {list(controllers)}")
    return MetricsConfig(window, vehicles, baseline)


def controllers_from(data: Mapping[str, Any], system: System, source: str | None = None):
    """Every ``[controllers.NAME]`` table, built in file order."""
    tables = get_table(data, "controllers", "controllers", required=True)
    if not tables:
        raise ConfigError("controllers", "needs at least one [controllers.NAME] table")
    return {name: build_controller(name, t, system, source) for name, t in tables.items()}


def load_spec(path: str | Path | Problem, seeds: int | None = None) -> SimulationSpec:
    """Read a problem file for simulation; ``seeds`` overrides ``[scenario].batch``."""
    problem = path if isinstance(path, Problem) else load_problem(path)
    source = str(problem.path)
    try:
        system = system_from(problem.data, source)
        scenario = scenario_from(problem.data, system, problem.path.parent)
        if seeds is not None:
            if seeds < 1:
                raise ConfigError("--seeds", f"must be >= 1, got {seeds}")
            scenario = replace(scenario, batch=int(seeds))
        controllers = controllers_from(problem.data, system, source)
        metrics = metrics_from(problem.data, system, controllers)
        return SimulationSpec(problem.name, system, scenario, controllers, metrics, source)
    except ConfigError as err:
        raise err.with_source(source) if not err.source else err from None
