"""The context document of a simulation recording: what was run, as a reader of the recording
needs it without the problem file at hand.

A recording of ``lcc-synth simulate`` holds, at ``/<scenario>/context``, one markdown document
(:func:`context_markdown`), and so does every scenario tab of ``lcc-synth run``'s
(:func:`lcc_synth.experiments.suite_context.scenario_context`):

* the problem's name and ``description``;
* the layout (the paper's ``m`` HDVs ahead and ``n`` behind the CAV, or the platoon / ring with
  its CAV positions), the equilibrium velocity, time step, duration and batch;
* each perturbation with its parameters (what happens, to which vehicle, when): the *first
  event* is the earliest perturbation start (:func:`first_event`), where the recording's time
  panel opens;
* the metric window and vehicle set, the baseline of the reductions;
* the HDV model's parameters and the scenario's heterogeneity, reaction delays, noise and V2V;
* each controller's type;
* and the whole problem as the TOML that reproduces it (``SimulationSpec.to_toml``: every
  setting, controller settings included), so nothing is left out of the summary by choice.

The document is written when the recording opens, before any result: an interrupted run keeps
it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from lcc_synth.models.records import plain

__all__ = ["context_markdown", "first_event"]


def first_event(scenario: Any) -> float | None:
    """The earliest start (s) of the scenario's perturbations, ``None`` without any (every
    perturbation of :mod:`lcc_synth.simulation.perturbations` has a ``start``)."""
    starts = [float(p.start) for p in getattr(scenario, "perturbations", ()) if
              getattr(p, "start", None) is not None]  # fmt: skip
    return min(starts) if starts else None


def _value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return str(v)


def _pairs(d: Mapping[str, Any]) -> str:
    return ", ".join(f"{k} = {_value(v)}" for k, v in d.items())


def _layout(scenario: Any) -> str:
    layout = getattr(scenario, "layout", None)
    if layout is None:
        return (f"one CAV with m = {scenario.m} HDVs ahead and n = {scenario.n} behind "
                "(the paper's Fig. 1)")  # fmt: skip
    size, ring = layout
    cols = list(getattr(scenario, "cav_columns", ()))
    cavs = ", ".join(str(c + 1 if ring else c) for c in cols)
    return (f"a ring road of {size} vehicles" if ring else
            f"a platoon of {size} vehicles behind the head") + f", CAVs at positions {cavs}"


def context_markdown(spec: Any, time_panel: bool = True) -> str:
    """The context document of ``spec`` (a
    :class:`~lcc_synth.experiments.spec.SimulationSpec`, or one scenario of a suite,
    :class:`~lcc_synth.experiments.suite_context.ScenarioContext`: ``name``,
    ``description``, ``scenario``, ``metrics``, ``controllers`` (objects or tables),
    ``to_toml()``). ``time_panel``: the recording's time panel selects from the first event
    to the end (``simulate``'s; ``run``'s one panel serves every scenario, so its documents do
    not say so)."""
    sc, cfg = spec.scenario, spec.metrics
    lines = [f"# {spec.name}: context", ""]
    description = str(getattr(spec, "description", "") or "").strip()
    if description:
        lines += [description, ""]
    lines += [
        "## scenario", "",
        f"- layout: {_layout(sc)}",
        f"- equilibrium velocity v* = {sc.v_star:g} m/s; time step {sc.dt:g} s; "
        f"{sc.duration:g} s from t = {sc.t_start:g} s; batch of {sc.batch} "
        f"(seed {getattr(sc, 'seed', 0)})",
        f"- acceleration limits [{sc.a_min:g}, {sc.a_max:g}] m/s²; CAV emergency braking "
        f"{'on' if sc.cav_aeb else 'off'}, HDV emergency braking {'on' if sc.hdv_aeb else 'off'}",
        "", "## perturbations", "",
    ]  # fmt: skip
    perturbations = list(getattr(sc, "perturbations", ()))
    for p in perturbations:
        d = {k: v for k, v in plain(p).items() if v is not None}
        lines.append(f"- {type(p).__name__}: {_pairs(d)}")
    if not perturbations:
        lines.append("- none (the run starts from the equilibrium, or its noise only)")
    t0 = first_event(sc)
    if t0 is not None:
        lines.append(f"- first event at t = {t0:g} s"
                     + (" (the time panel's selection starts there)" if time_panel else ""))
    baseline = getattr(cfg, "baseline", None)
    lines += [
        "", "## metrics", "",
        f"- window {cfg.window[0]:g} s ≤ t ≤ {cfg.window[1]:g} s, vehicles: {cfg.vehicles}"
        + (f"; reductions against {baseline}" if baseline else ""),
        "", "## human drivers", "",
        f"- model: {_pairs(plain(sc.hdv))}",
    ]  # fmt: skip
    het = dict(getattr(sc, "heterogeneity", {}) or {})
    if het:
        lines.append(f"- heterogeneity (half widths of U[-w, w] per HDV): {_pairs(het)}")
    delay = getattr(sc, "delay", 0.0)
    if plain(delay) not in (0, 0.0, None):
        lines.append(f"- reaction delay: {_value(plain(delay))} s "
                     f"(spread {getattr(sc, 'delay_spread', 0.0):g} s, "
                     f"model {getattr(sc, 'delay_model', 'full')})")  # fmt: skip
    noise = float(getattr(sc, "hdv_accel_noise", 0.0) or 0.0)
    if noise:
        lines.append(f"- acceleration noise: {noise:g} m/s²")
    v2v = getattr(sc, "v2v", None)
    if v2v is not None:
        nonzero = {k: v for k, v in plain(v2v).items() if v not in (0, 0.0, None, False)}
        ideal = "ideal (no loss, latency or noise)"
        lines.append(f"- V2V: {_pairs(nonzero) if nonzero else ideal}")
    lines += ["", "## controllers", ""]
    for name, ctrl in dict(spec.controllers).items():
        table = ctrl if isinstance(ctrl, Mapping) else getattr(ctrl, "source_table", None)
        if not table and callable(getattr(ctrl, "toml_table", None)):
            try:
                table = ctrl.toml_table()
            except Exception:  # noqa: BLE001 - its class name says enough
                table = None
        kind = table.get("type") if isinstance(table, Mapping) else None
        lines.append(f"- {name}: {kind or type(ctrl).__name__}")
    for name, why in dict(getattr(spec, "failed", {}) or {}).items():
        lines.append(f"- {name}: not run ({why})")
    try:
        toml = spec.to_toml()
    except Exception as err:  # noqa: BLE001 - the summary above still stands
        toml = f"# the problem could not be written back as TOML: {err}"
    lines += ["", "## the problem file that reproduces this run", "", "```toml", toml.rstrip(),
              "```", ""]  # fmt: skip
    return "\n".join(lines)
