"""The ``[scenario]`` table of a problem file: :func:`scenario_from` reads it and
:func:`scenario_for` builds the :class:`~lcc_synth.simulation.scenario.Scenario` on the
``[system]`` (a mixed platoon or ring takes its layout from the system's platoon); the flat
API's :func:`lcc_synth.api.scenario` builds through :func:`scenario_for` too."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.problem import System
from lcc_synth.schema import declared
from lcc_synth.simulation.checks import check_timing
from lcc_synth.simulation.perturbations import (
    Perturbation,
    Recorded,
    perturbation_from_table,
    recorded_file,
    vehicle_column,
)
from lcc_synth.simulation.scenario import MODEL_PARAMS, V2V, Scenario
from lcc_synth.simulation.sumo_net import SumoSettings

__all__ = ["nominal_scenario", "scenario_from", "scenario_for"]


def _platoon_layout(system: System) -> dict[str, Any]:
    """Scenario fields of a ``platoon`` / ``ring`` system: CAV columns, ``m``, ``n``, every
    column's explicit HDV values (a CAV's: its slot's law) and the ring."""
    P = system.platoon
    nv = P.size if P.ring else P.size + 1
    cols = tuple(c - 1 if P.ring else c for c in P.cavs)
    if not cols:
        raise ConfigError(
            "system.cavs",
            "simulate needs at least one CAV position (an all-HDV run drives the CAVs with "
            'an HDV controller: type = "hdv")',
        )
    off = 0 if P.ring else 1  # column of position 1
    values = {}
    for key in MODEL_PARAMS[system.hdv.name]:
        full = np.full(nv, float(getattr(system.hdv, key)))
        full[off:] = [float(getattr(h, key)) for h in P.hdv]
        values[key] = full
    return {
        "m": cols[0] - 1, "n": nv - 1 - cols[0], "cavs": cols, "hdv_values": values,
        "ring": bool(P.ring), "circumference": P.length if P.ring else None,
        "vehicle_length": P.vehicle_length,
    }  # fmt: skip


def _check_platoon_keys(system: System, hdv_values: Any, spacing_reference: str | None) -> None:
    """A platoon's or ring's per-vehicle values are its ``[system.hdv_values]``, and its
    spacing errors are from each vehicle's own equilibrium: other values are errors."""
    if hdv_values:
        raise ConfigError(
            "scenario.hdv_values",
            f"kind = {system.kind!r} takes its per-vehicle parameters from "
            "[system.hdv_values] (one value per position)",
        )
    if spacing_reference not in (None, "own_equilibrium"):
        raise ConfigError(
            "scenario.spacing_reference",
            f'must be "own_equilibrium" for kind = {system.kind!r}: the platoon model '
            "linearises every vehicle at its own equilibrium",
        )


def scenario_for(
    system: System, perturbations: Sequence[Perturbation] = (), **fields: Any
) -> Scenario:
    """The :class:`Scenario` of ``fields`` (its keyword arguments) on ``system``.

    The string comes from the system: ``m``, ``n``, the HDV model and ``v*``; for ``kind =
    "platoon" | "ring"`` also the CAV columns, every vehicle's own parameters (then
    ``hdv_values`` may not be given) and the ring, spacing errors from each vehicle's own
    equilibrium (``spacing_reference = "own_equilibrium"``, the only one allowed). Every
    perturbation's vehicle is checked on the layout (a paper index in ``[-m, n]`` or
    ``"head"``; a platoon's or ring's position), and the meaning of the values in this run
    (:func:`~lcc_synth.simulation.checks.check_timing`)."""
    layout: dict[str, Any] = {"m": system.m, "n": system.n}
    if system.platoon is not None:
        _check_platoon_keys(system, fields.get("hdv_values"), fields.get("spacing_reference"))
        layout = _platoon_layout(system)
        fields = {**{k: v for k, v in fields.items() if k != "hdv_values"},
                  "spacing_reference": "own_equilibrium"}  # fmt: skip
    perturbations = tuple(perturbations)
    for i, p in enumerate(perturbations):
        vehicle_column(p.vehicle, layout["m"], layout["n"],
                       f"scenario.perturbations[{i}].vehicle", system.numbering)  # fmt: skip
    out = Scenario(hdv=system.hdv, v_star=system.v_star, perturbations=perturbations,
                   **layout, **fields)  # fmt: skip
    check_timing(out)
    return out


def scenario_from(data: Mapping[str, Any], system: System, base_dir: Path | None = None):
    """Build the :class:`Scenario` of a problem's ``[scenario]`` table.

    For ``[system] kind = "platoon" | "ring"`` the layout comes from ``system.platoon``: the
    CAV columns, every vehicle's own parameters (``[system.hdv_values]``; a
    ``[scenario.hdv_values]`` table is then an error), every vehicle starting at its own
    equilibrium spacing at ``v*``, spacing errors from each vehicle's own equilibrium
    (``spacing_reference = "own_equilibrium"``, the platoon model's linearisation), vehicles
    of perturbations named by position.

    Besides every value's own range, the meaning of the values in this run is checked
    (:func:`~lcc_synth.simulation.checks.check_timing`: delays, latency and perturbation
    windows against the run's length) and every value a heterogeneity draw can produce
    (:class:`~lcc_synth.simulation.scenario.Scenario`)."""
    f = "scenario"
    S = declared("scenario")
    sc = declared("").get(data, "scenario", "")
    S.check(sc, f)
    hv_t = S.get(sc, "hdv_values", f)
    hdv_values = None
    layout: dict[str, Any] = {}
    if system.platoon is not None:
        ref = S.get(sc, "spacing_reference", f) if "spacing_reference" in sc else None
        _check_platoon_keys(system, hv_t, ref)
        layout = _platoon_layout(system)
    elif hv_t:
        HV = declared("scenario.hdv_values")
        HV.check(hv_t, f"{f}.hdv_values", allowed=list(MODEL_PARAMS[system.hdv.name]))
        hdv_values = {}
        hdv_cols = [j for j in range(system.m + system.n + 2) if j not in (0, system.m + 1)]
        each = HV.get_each(hv_t, f"{f}.hdv_values", length=len(hdv_cols))
        for key, vals in each.items():
            full = np.full(system.m + system.n + 2, float(getattr(system.hdv, key)))
            full[hdv_cols] = vals
            hdv_values[key] = full
    het = S.get(sc, "heterogeneity", f)
    heterogeneity = declared("scenario.heterogeneity").get_each(het, f"{f}.heterogeneity")
    D = declared("scenario.delay")
    delay_t = S.get(sc, "delay", f)
    D.check(delay_t, f"{f}.delay")
    delay_model = D.get(delay_t, "model", f"{f}.delay")
    delay = D.get(delay_t, "mean", f"{f}.delay")
    spread = D.get(delay_t, "spread", f"{f}.delay", hi=delay)
    V = declared("scenario.v2v")
    v2v_t = S.get(sc, "v2v", f)
    V.check(v2v_t, f"{f}.v2v")
    m, n = layout.pop("m", system.m), layout.pop("n", system.n)
    nv = m + n + 2
    if isinstance(V.raw(v2v_t, "loss_rate"), list):
        loss = declared("scenario.v2v:list").get(v2v_t, "loss_rate", f"{f}.v2v", length=nv)
    else:
        loss = V.get(v2v_t, "loss_rate", f"{f}.v2v")
    v2v = V2V(
        loss,
        V.get(v2v_t, "latency", f"{f}.v2v"),
        V.get(v2v_t, "spacing_noise", f"{f}.v2v"),
        V.get(v2v_t, "velocity_noise", f"{f}.v2v"),
        V.get(v2v_t, "position_noise", f"{f}.v2v"),
    )
    perts = S.raw(sc, "perturbations")
    if not isinstance(perts, list):
        raise ConfigError(
            f"{f}.perturbations", "must be an array of tables [[scenario.perturbations]]"
        )
    perturbations = tuple(
        perturbation_from_table(p, f"{f}.perturbations[{i}]", m, n, base_dir, system.numbering)
        for i, p in enumerate(perts)
    )
    initial_state = None
    if S.get(sc, "initial", f) == "data":
        initial_state = _initial_from_data(perts, perturbations, system, nv, base_dir)
    return scenario_for(
        system,
        perturbations,
        initial_state=initial_state,
        dt=S.get(sc, "dt", f),
        duration=S.get(sc, "duration", f),
        t_start=S.get(sc, "t_start", f),
        batch=S.get(sc, "batch", f),
        a_min=S.get(sc, "a_min", f),
        a_max=S.get(sc, "a_max", f),
        cav_aeb=S.get(sc, "cav_aeb", f),
        hdv_aeb=S.get(sc, "hdv_aeb", f),
        hdv_values=hdv_values,
        heterogeneity=heterogeneity,
        delay=delay,
        delay_spread=spread,
        delay_model=delay_model,
        hdv_accel_noise=S.get(sc, "hdv_accel_noise", f),
        v2v=v2v,
        seed=S.get(sc, "seed", f),
        record_every=S.get(sc, "record_every", f),
        backend=S.get(sc, "backend", f),
        sumo=_sumo_from(S.get(sc, "sumo", f), f"{f}.sumo"),
        spacing_reference=(S.get(sc, "spacing_reference", f) if system.platoon is None
                           else "own_equilibrium"),  # fmt: skip
        accel_noise_uniform=S.get(sc, "accel_noise_uniform", f),
        cav_lag=S.get(sc, "cav_lag", f),
    )


def _initial_from_data(
    tables: list, perturbations: Sequence[Perturbation], system: System, nv: int,
    base_dir: Path | None,
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """``[scenario] initial = "data"``: speeds and spacings (headway - vehicle length) of every
    vehicle at the first sample of the first recorded trajectory's file."""
    f = "scenario.initial"
    idx = [i for i, p in enumerate(perturbations) if isinstance(p, Recorded)]
    if not idx:
        raise ConfigError(f, '"data" takes the initial state from a recording: add a '
                          '[[scenario.perturbations]] entry with type = "trajectory"')
    length = system.vehicle_length
    if system.ring or not length > 0:  # the paper's strings: point vehicles (length 0)
        raise ConfigError(f, '"data" needs [system] kind = "platoon" with vehicle_length > 0 '
                          "(recorded headways are front to front: spacing = headway - "
                          "vehicle_length)")
    i = idx[0]
    traj = recorded_file(tables[i], f"scenario.perturbations[{i}]", base_dir)
    if traj.n_vehicles != nv:
        raise ConfigError(f, f"{traj.path} holds {traj.n_vehicles} vehicles; the string has "
                          f"{nv} (the head and [system] size = {nv - 1}): one file vehicle per "
                          "vehicle, file vehicle k in column k")
    gaps = traj.headway[:, 0] - length
    gaps[0] = 0.0  # the head follows no one
    return tuple(float(x) for x in gaps), tuple(float(x) for x in traj.v[:, 0])


def nominal_scenario(system: System):
    """The :class:`Scenario` of an empty ``[scenario]`` table on ``system``'s string: every
    default, no perturbation (e.g. the nominal string DeeP-LCC collects its data on when there
    is no scenario of its own)."""
    return scenario_from({}, system)


def _sumo_from(table: Mapping[str, Any], f: str) -> SumoSettings:
    """The :class:`SumoSettings` of a ``[scenario.sumo]`` table."""
    T = declared("scenario.sumo")
    T.check(table, f)
    return SumoSettings(**{k: T.get(table, k, f) for k in
                           ("car_following", "step_method", "sigma", "vehicle_length")})
