"""The flat Python API: ``import lcc_synth as lcc``, then the paper in order.

Every function is a documented entry point over the package function that does the work (named
in its docstring); none re-implements it. The objects are those the problem files build, so a
problem file and a script are two faces of one thing:
:func:`~lcc_synth.experiments.problem_objects.load_problem` gives the CLI's objects, and every
object here is written back to TOML by ``to_toml()`` (a round trip gives
equal objects: tests/test_roundtrip.py checks every file under ``problems/``).

========================  ====================================================================
paper                     API
========================  ====================================================================
eq. (1)-(4), HDV models   :class:`OVM`, :class:`IDM`
Sec. II, eq. (8)-(14)     :func:`system` (``[hdv]`` + ``[system]``; a mixed platoon with
                          ``size``, ``cavs``), :func:`ring`, :func:`model` (the linearised
                          LCC / CF-LCC / FD-LCC / CCC / platoon / ring state space)
Sec. III, Thm. 1-3        :func:`controllability`, :func:`observability` (of a System or
                          its model)
Sec. III-C, Fig. 5        :func:`control_energy` (Gramian metrics at a horizon)
Sec. IV, eq. (23)-(27)    :func:`gains` (``semantics`` "added" or "replace", always stated),
                          :func:`string_stability` (head-to-tail ``Gamma``)
Sec. IV-B, Fig. 7-8       :func:`region_map`
H2 / LMI synthesis        :func:`h2_problem` (``[synthesis]``), :func:`synthesize_h2`
Sec. V, eq. (29)          :func:`scenario`, :class:`Brake`, :class:`Sine`, :class:`BrakeProfile`,
                          :class:`Profile`, :func:`hdv_controller`, :func:`static_controller`,
                          :func:`mpc`, :func:`deep_lcc` (data-driven), :func:`simulate`
Monte Carlo               :func:`sweep` (``lcc-synth sweep``; in-process or on a Dask client)
Table II metrics          :func:`metrics` (AAVE, fuel, spacing, TTC, jerk...; ``window``
                          explicit), :func:`aave`, :func:`fuel`
real drivers              :func:`~lcc_synth.calibration.fit.calibrate` (``lcc.calibrate``:
                          OVM / IDM fitted to a recorded platoon, ``lcc-synth calibrate``)
recordings                :func:`record` (a Rerun ``.rrd`` file)
problem files             :func:`~lcc_synth.experiments.problem_objects.load_problem` /
                          :func:`~lcc_synth.experiments.problem_objects.build_problem` ->
                          :class:`~lcc_synth.experiments.problem_objects.ProblemObjects`
                          (``to_toml()``; ``==`` by value;
                          :mod:`lcc_synth.experiments.problem_objects`)
========================  ====================================================================

Results are small dataclasses with ``as_dict()`` and a one-line ``repr``
(:class:`lcc_synth.models.records.Record`); the objects of a problem file compare with ``==`` by
value (:func:`lcc_synth.models.records.same`). The main entry points carry ``>>>`` examples
(run by ``tests/test_api_doctest.py``). Bad input raises
:class:`~lcc_synth.errors.ConfigError` naming the dotted field, as a problem file would.
Importing this module imports numpy and scipy.linalg; cvxpy, CasADi/OSQP and Rerun are imported
by the functions that need them (:func:`synthesize_h2`, :func:`mpc`, :func:`record`). Measured on
this 2-core machine: ``import lcc_synth`` 2-3 ms (``lcc_synth.errors`` only), the first API
name 0.4-0.5 s; README's snippet (Table II's CF-LCC row, 100 s simulated, and the structured
H2 gain) about 5 s, of which the synthesis about 1 s; ``examples/paper_walkthrough.py`` 7 s.
``lcc.metrics`` and ``lcc.mpc`` are this module's :func:`metrics` and :func:`mpc` (the module
:mod:`lcc_synth.metrics` and the package :mod:`lcc_synth.mpc` keep their names as modules).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.calibration.fit import calibrate
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.problem_objects import (
    ProblemObjects,
    Regions,
    build_problem,
    load_problem,
)
from lcc_synth.metrics import MetricsConfig
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import IDM, OVM
from lcc_synth.models.linear import LCCModel
from lcc_synth.models.platoon import PlatoonModel
from lcc_synth.models.records import system_tables
from lcc_synth.problem import Problem, System, system_from
from lcc_synth.simulation.perturbations import Brake, BrakeProfile, Profile, Sine
from lcc_synth.simulation.scenario import V2V, Scenario

__all__ = [
    "OVM", "IDM", "System", "Scenario", "V2V", "Gains", "MetricsConfig",
    "Brake", "Sine", "BrakeProfile", "Profile",
    "system", "ring", "model", "controllability", "observability", "control_energy", "gains",
    "string_stability", "region_map", "h2_problem", "synthesize_h2", "hdv_controller",
    "static_controller", "mpc", "deep_lcc",
    "scenario", "simulate", "sweep", "metrics", "aave", "fuel", "calibrate", "record",
    "ProblemObjects", "Regions", "build_problem", "load_problem", "TABLE2_WINDOW",
]  # fmt: skip

#: Table II's metric window (s): AAVE and fuel over 20 <= t <= 40.
TABLE2_WINDOW = (20.0, 40.0)


def system(
    kind: str | None = None,
    m: int | None = None,
    n: int | None = None,
    v_star: float | None = None,
    hdv: OVM | IDM | None = None,
    *,
    size: int | None = None,
    cavs: Sequence[int] | None = None,
    hdv_values: Mapping[str, Sequence[float]] | None = None,
    circumference: float | None = None,
    vehicle_length: float | None = None,
) -> System:
    """The ``[hdv]`` + ``[system]`` tables: layout, equilibrium velocity and HDV model.

    Every argument is the ``[system]`` key of the same name; one left out is left out of the
    table (the file's default, or the file's error when the kind needs it), and the tables are
    validated by :func:`lcc_synth.problem.system_from`, exactly as a problem file's.

    Parameters
    ----------
    kind : {"lcc", "cf_lcc", "fd_lcc", "ccc", "platoon", "ring"}, optional
        General LCC (Sec. II), car-following LCC, free-driving LCC, CCC (no HDV behind), a
        mixed platoon behind a head vehicle or a ring road (:func:`ring`). Default
        ``"platoon"`` when ``size`` or ``cavs`` is given, else the file's ``"lcc"``.
    m, n : int, optional
        HDVs ahead of / behind the CAV (the paper's kinds: ``m`` for lcc and ccc, ``n`` for
        lcc, cf_lcc and fd_lcc are required).
    v_star : float, optional
        Equilibrium velocity (m/s); default 15.
    hdv : OVM or IDM, optional
        HDV car-following model; default the paper's OVM (``OVM()``).
    size : int, optional
        Platoon or ring: the vehicles behind the head / on the ring (required).
    cavs : sequence of int, optional
        Platoon or ring: the CAV positions ``1..size``; default none (all HDVs).
    hdv_values : mapping of str to sequence of float, optional
        Platoon or ring: per-vehicle values of ``hdv``'s parameters, one per position.
    circumference : float, optional
        Ring: its length (m), instead of ``v_star``.
    vehicle_length : float, optional
        Platoon or ring: every vehicle's length (m); default 0.

    Examples
    --------
    >>> import lcc_synth as lcc
    >>> string = lcc.system("fd_lcc", n=10)  # Table II: the CAV and 10 HDVs behind it
    >>> string.kind, string.m, string.n, string.v_star, round(string.s_star, 3)
    ('fd_lcc', 0, 10, 15.0, 20.0)
    >>> platoon = lcc.system(size=8, cavs=[3, 6])  # DeeP-LCC's platoon: CAVs 3 and 6
    >>> platoon.kind, platoon.platoon.types
    ('platoon', ('hdv', 'hdv', 'cav', 'hdv', 'hdv', 'cav', 'hdv', 'hdv'))
    >>> lcc.system("lcc", n=2)
    Traceback (most recent call last):
    ...
    lcc_synth.errors.ConfigError: system.m: is required for kind = 'lcc': the number of HDVs ...
    """
    if kind is None and (size is not None or cavs is not None):
        kind = "platoon"
    cavs = _as_list(cavs)  # the table's arrays are lists; other values reach the validation
    if isinstance(hdv_values, Mapping):
        hdv_values = {k: _as_list(v) for k, v in hdv_values.items()}
    given = {"kind": kind, "m": m, "n": n, "v_star": v_star, "size": size, "cavs": cavs,
             "hdv_values": hdv_values, "circumference": circumference,
             "vehicle_length": vehicle_length}  # fmt: skip
    hdv = OVM() if hdv is None else hdv
    table = {k: v for k, v in given.items() if v is not None}
    return system_from({"hdv": hdv.toml_table(), "system": table})


def _as_list(x: Any) -> Any:
    """A tuple, range or numpy array as the list a TOML array is; anything else unchanged."""
    if isinstance(x, np.ndarray):
        return x.tolist()
    return list(x) if isinstance(x, tuple | range) else x


def ring(
    size: int,
    cavs: Sequence[int] = (),
    v_star: float | None = None,
    hdv: OVM | IDM | None = None,
    *,
    circumference: float | None = None,
    hdv_values: Mapping[str, Sequence[float]] | None = None,
    vehicle_length: float | None = None,
) -> System:
    """A ring road of ``size`` vehicles with CAVs at ``cavs`` (``[system] kind = "ring"``):
    :func:`system` with ``kind = "ring"``; give ``v_star`` (default 15 m/s: every vehicle at
    its equilibrium spacing) or the ``circumference`` (m), not both.

    Examples
    --------
    >>> import lcc_synth as lcc
    >>> road = lcc.ring(20, cavs=[20])  # 20 vehicles, the last one automated
    >>> road.kind, road.platoon.size, road.platoon.cavs, round(road.platoon.length, 6)
    ('ring', 20, (20,), 400.0)
    >>> sugiyama = lcc.ring(22, cavs=[22], circumference=230.0)  # 22 vehicles on 230 m
    >>> round(sugiyama.v_star, 4)  # the OVM's V(230 m / 22) = 15 (1 - cos(pi 5.4545 / 30))
    2.3812
    """
    return system("ring", v_star=v_star, hdv=hdv, size=size, cavs=cavs,
                  circumference=circumference, hdv_values=hdv_values,
                  vehicle_length=vehicle_length)  # fmt: skip


def model(
    kind: str | System | None = None,
    m: int | None = None,
    n: int | None = None,
    v_star: float | None = None,
    hdv: OVM | IDM | None = None,
    *,
    size: int | None = None,
    cavs: Sequence[int] | None = None,
    hdv_values: Mapping[str, Sequence[float]] | None = None,
    circumference: float | None = None,
    vehicle_length: float | None = None,
) -> LCCModel | PlatoonModel:
    """The linearised state-space model of eq. (8)-(14) (an
    :class:`~lcc_synth.models.linear.LCCModel`: ``A``, ``B``, ``H``, ``state_names``; a
    platoon or ring: a :class:`~lcc_synth.models.platoon.PlatoonModel`).

    Same parameters as :func:`system`; ``system(...).linear_model()``. Or a :class:`System`
    alone (``lcc.model(lcc.system(size=5, cavs=[2]))``).

    Examples
    --------
    >>> import lcc_synth as lcc
    >>> lcc.model("lcc", m=1, n=1).state_names
    ('s_-1', 'v_-1', 's_0', 'v_0', 's_1', 'v_1')
    """
    if isinstance(kind, System):
        given = [k for k, v in (("m", m), ("n", n), ("v_star", v_star), ("hdv", hdv),
                                ("size", size), ("cavs", cavs), ("hdv_values", hdv_values),
                                ("circumference", circumference),
                                ("vehicle_length", vehicle_length)) if v is not None]  # fmt: skip
        if given:
            raise ConfigError(given[0], "give a System alone, or a kind and its parameters")
        return kind.linear_model()
    return system(kind, m, n, v_star, hdv, size=size, cavs=cavs, hdv_values=hdv_values,
                  circumference=circumference, vehicle_length=vehicle_length).linear_model()


def _linear(model: Any, warn: bool = True) -> LCCModel | PlatoonModel:
    """The linear model of ``model``: a System's (:meth:`~lcc_synth.problem.System.linear_model`)
    or the model itself."""
    linear = getattr(model, "linear_model", None)  # a System's; a linear model is its own
    if callable(linear):
        return linear(warn=warn)
    if hasattr(model, "state_names") and hasattr(model, "cavs"):
        return model
    raise ConfigError(
        "model", "must be a System (lcc.system(...), lcc.ring(...)) or its linear model "
        f"(lcc.model(...), system.linear_model()), got {type(model).__name__}",
    )


def controllability(model: System | LCCModel | PlatoonModel, tol: float | None = None):
    """Controllability of ``(A, B)`` (Sec. III, Theorems 1-3): a
    :class:`~lcc_synth.analysis.controllability.ControllabilityReport` (rank, verdict,
    uncontrollable modes) of any layout (a platoon or ring: several CAVs; the ring on its
    invariant hyperplane, the conserved total spacing named).
    :func:`lcc_synth.analysis.controllability.controllability_report`.

    ``model``: a :class:`System` (its :meth:`~lcc_synth.problem.System.linear_model`) or a
    linear model (:func:`model`).

    Examples
    --------
    >>> import lcc_synth as lcc
    >>> lcc.controllability(lcc.system("fd_lcc", n=10)).verdict  # Theorem 2
    'controllable'
    >>> rep = lcc.controllability(lcc.system("lcc", m=2, n=2))  # Theorem 3: not the HDVs ahead
    >>> rep.controllable, rep.rank, rep.n_states
    (False, 6, 10)
    """
    from lcc_synth.analysis.controllability import controllability_report

    return controllability_report(_linear(model), tol)


def observability(
    model: System | LCCModel | PlatoonModel,
    outputs: Sequence[str] | None = None,
    tol: float | None = None,
):
    """Observability from the measured ``outputs`` (state names; default the paper's set, eq.
    19 / 21: the tail HDV's velocity ``v_n``, plus the CAV's ``s_0, v_0`` for LCC and CCC;
    :func:`~lcc_synth.analysis.controllability.default_outputs`; a platoon or ring: every
    CAV's own states plus the tail's velocity).
    :func:`lcc_synth.analysis.controllability.observability_report`. ``model``: a
    :class:`System` or its linear model."""
    from lcc_synth.analysis.controllability import observability_report

    return observability_report(_linear(model), outputs, tol)


def control_energy(model: System | LCCModel | PlatoonModel, horizon: float):
    """Gramian energy metrics at ``horizon`` seconds (Sec. III-C, Fig. 5): an
    :class:`~lcc_synth.analysis.energy.EnergyReport` (``lambda_min``, ``trace_inv``...).
    :func:`lcc_synth.analysis.energy.energy_report`; a numerically singular Gramian raises
    :class:`~lcc_synth.analysis.energy.NumericallySingularError`. ``model``: a
    :class:`System` or its linear model, of any layout (a ring: on the hyperplane its total
    spacing keeps)."""
    from lcc_synth.analysis.energy import energy_report

    return energy_report(_linear(model), horizon)


def gains(
    values: Mapping[str, Any] | Gains | str | Path,
    semantics: str | None = None,
    model: System | PlatoonModel | None = None,
) -> Gains:
    """Static CAV gains of eq. (23), with how they enter the command stated.

    Parameters
    ----------
    values : mapping, Gains or path
        State name -> gain (``{"s_1": -1.0, "v_1": -1.0}``, missing states 0); on a platoon or
        ring one table per CAV input, ``{"u_3": {"s_3": ..., "v_2": ...}, ...}`` (then give
        ``model``). A gains object is returned as it is. A path (``str`` or ``Path``): a gains
        file of ``lcc-synth synthesize --out``, either form
        (:func:`lcc_synth.synthesis.gains_file.read_gains`; with ``model``, checked against its
        layout); the file states its semantics.
    semantics : {"added", "replace"}
        Required with a mapping (the paper uses both; there is no default): ``"added"``, the
        CAV keeps its HDV law and the gains add to it (eq. 23, Sec. IV and V-A); ``"replace"``,
        the gains are the whole command (Sec. V-B, Table II). With a gains object it must agree
        with the object's.
    model : System or PlatoonModel, optional
        The platoon or ring whose per-CAV tables ``values`` holds (then the gain is on its
        CAVs and states; else it is the paper's single-CAV gain, vehicles indexed from the
        CAV: :class:`~lcc_synth.models.feedback.Gains`).

    Examples
    --------
    >>> import lcc_synth as lcc
    >>> lcc.gains({"s_1": -1.0, "v_1": -1.0}, semantics="added")
    Gains(cavs=(0,), gains={'s_1': -1, 'v_1': -1}, semantics='added')
    >>> lcc.gains({"s_1": -1.0})
    Traceback (most recent call last):
    ...
    lcc_synth.errors.ConfigError: semantics: must be given with gains: "added" (the CAV's ...
    """
    if isinstance(values, str | Path):
        from lcc_synth.synthesis.gains_file import read_gains

        is_system = callable(getattr(model, "linear_model", None))
        values = read_gains(values, system=model if is_system else None,
                            model=None if is_system else model)[0]
    if isinstance(values, Gains):
        if semantics is not None and semantics != values.semantics:
            raise ConfigError(
                "semantics", f"{semantics!r} contradicts the gains' {values.semantics!r}"
            )
        return values
    if not isinstance(values, Mapping):
        raise ConfigError("gains", f"must be a mapping of state name -> gain, got "
                          f"{type(values).__name__}")  # fmt: skip
    if semantics is None:
        raise ConfigError("semantics", 'must be given with gains: "added" (the CAV\'s HDV law plus '
                          'the gains, eq. 23) or "replace" (the gains are the whole command)')
    return Gains.from_mapping(dict(values), None if model is None else _linear(model, warn=False),
                              semantics)  # fmt: skip


def _stated(gain: Any, model: LCCModel | PlatoonModel) -> Gains:
    """``gain`` as given to an analysis of ``model``: a gains object (which states its
    semantics) of the model's layout."""
    if isinstance(gain, Mapping):
        raise ConfigError("gain", 'a plain mapping does not say how the gains enter the command: '
                          'write lcc.gains({...}, semantics="added"|"replace")')  # fmt: skip
    paper = tuple(model.cavs) == (0,)  # the paper's one-CAV model: vehicles from the CAV
    if not isinstance(gain, Gains) or gain.cavs != tuple(model.cavs):
        raise ConfigError("gain", "must be lcc.gains({...}, semantics=...) for " + (
            "one CAV ({'s_1': ..., 'v_1': ...})" if paper else
            "a platoon or ring, one table per CAV ({'u_3': {...}}, model=...)") + ", got " + (
            f"gains for CAVs {list(gain.cavs)}" if isinstance(gain, Gains)
            else type(gain).__name__))  # fmt: skip
    return gain


def string_stability(
    model: System | LCCModel | PlatoonModel,
    gain: Gains,
    method: str = "grid",
):
    """Head-to-tail string stability of the closed loop with static gains (Sec. IV, eq.
    (24)-(27)): a :class:`~lcc_synth.analysis.string_stability.StringStabilityReport`
    (``plant_stable``, ``string_stable``, ``gamma_peak`` and its frequency, ``verdict``).
    :func:`lcc_synth.analysis.string_stability.gains_string_stability`.

    ``model``: a :class:`System` or its linear model. ``gain``: from :func:`gains`, which
    states the semantics (a plain mapping is refused: the paper's ``"added"`` and
    ``"replace"`` gains give opposite verdicts for the same numbers). On an open platoon
    (several CAVs) a :class:`~lcc_synth.models.feedback.Gains` (``lcc.gains({"u_3":
    {...}}, semantics=..., model=...)``).

    Examples
    --------
    Table II's CF-LCC gain is the whole command (``"replace"``): string stable; read as
    ``"added"`` to the HDV law, the same numbers are not.

    >>> import lcc_synth as lcc
    >>> cf = lcc.model("cf_lcc", n=10)
    >>> table2 = {"s_0": 0.1, "v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}
    >>> lcc.string_stability(cf, lcc.gains(table2, semantics="replace")).string_stable
    True
    >>> added = lcc.string_stability(cf, lcc.gains(table2, semantics="added"))
    >>> added.string_stable, round(added.gamma_peak, 3)
    (False, 1.136)
    """
    from lcc_synth.analysis.string_stability import gains_string_stability

    model = _linear(model)
    return gains_string_stability(model, _stated(gain, model), method=method)


def region_map(
    model: System | LCCModel,
    vehicle: int,
    mu,
    k,
    gain: Gains | None = None,
    omega=None,
    name: str = "",
    cav: int | None = None,
):
    """Stability / string-stability map over the gains ``(mu, k)`` of one HDV's spacing and
    velocity (Sec. IV-B, Fig. 7-8): a :class:`~lcc_synth.analysis.regions.RegionMap`.
    ``gain``: the other gains, fixed (from :func:`gains`). ``model``: a :class:`System` or its
    linear model. ``cav``: on an open platoon, the position of the CAV whose gains on
    ``vehicle`` vary (default: the only CAV). :func:`lcc_synth.analysis.regions.region_map`."""
    from lcc_synth.analysis.regions import region_map as _region_map

    model = _linear(model)
    g = None if gain is None else _stated(gain, model)
    return _region_map(model, vehicle, np.asarray(mu, float), np.asarray(k, float), g, omega,
                       name, cav=cav)  # fmt: skip


def h2_problem(
    system: System,
    design: str = "structured",
    pattern: Sequence[int] | str = "all",
    weights: Mapping[str, Any] | None = None,
    name: str = "python",
    **options: Any,
):
    """The ``[synthesis]`` problem of ``lcc-synth synthesize`` for ``system``: a
    :class:`~lcc_synth.synthesis.config.SynthesisSpec` (``build_problem(..., synthesis=spec)``
    writes it as a problem file).

    Parameters
    ----------
    system : System
        From :func:`system`.
    design : {"full_state", "structured", "sparsity", "string_stable"}
    pattern : list of int or "all"
        Vehicles the CAV hears besides itself (structured designs), e.g. ``[1, 2]``.
    weights : mapping, optional
        The ``[synthesis.weights]`` keys (``q_s`` = 1, ``q_v`` = 1, ``q_a`` = 0, ``r`` = 1,
        ``accel`` = 1, ``head`` = 0 ... when absent; see :class:`lcc_synth.synthesis.h2.Weights`).
    **options
        Any other ``[synthesis]`` key (``semantics``, ``method``, ``tol``, ``string = {...}``,
        ``sparsity = {...}``, ``baseline = {...}``, ``as_run = {...}``, ``robust = {...}``).

    Validated by :func:`lcc_synth.synthesis.config.spec_from_problem`, as a problem file (errors
    name ``<python>`` and the dotted field).
    """
    from lcc_synth.synthesis.config import spec_from_problem

    table = {"design": design, "pattern": pattern if isinstance(pattern, str) else list(pattern),
             "weights": dict(weights or {}), **options}  # fmt: skip
    data = {"name": name, **system_tables(system), "synthesis": table}
    return spec_from_problem(Problem(Path("<python>"), data))


def synthesize_h2(
    system,
    design: str = "structured",
    pattern: Sequence[int] | str = "all",
    weights: Mapping[str, Any] | None = None,
    name: str = "python",
    **options: Any,
):
    """Synthesise a static H2 gain (``lcc-synth synthesize``) on any layout.

    ``system``: a :class:`System` of any layout (one CAV, a platoon, a ring; the other
    arguments are those of :func:`h2_problem`: ``design``, ``pattern`` for one CAV,
    ``comm_range`` / ``patterns`` for several, ``weights`` and any ``[synthesis]`` key), or a
    spec from :func:`h2_problem` / :func:`~lcc_synth.experiments.problem_objects.load_problem`
    (``.synthesis``) alone.

    Returns
    -------
    lcc_synth.synthesis.report.SynthesisReport
        ``gains`` (state name -> gain), ``check.h2`` (true H2 norm), string-stability checks;
        ``lcc.static_controller(string, report.gains, semantics=report.semantics, kind=...)``
        drives it in :func:`simulate`.

    Solved by :func:`lcc_synth.synthesis.design.synthesize` (cvxpy + Clarabel for the LMI
    designs; the showcase's structured CF-LCC gain, 22 states, takes about 1 s here).

    Examples
    --------
    A CF-LCC gain for a CAV that hears only HDV 1 of the two behind it:

    >>> import lcc_synth as lcc
    >>> h2 = lcc.synthesize_h2(lcc.system("cf_lcc", n=2), pattern=[1], semantics="replace")
    >>> round(h2.check.h2, 4), h2.check.string_stable
    (1.8809, True)
    >>> {k: round(g, 3) for k, g in h2.gains.items() if g}
    {'s_0': 1.003, 'v_0': -1.973, 's_1': -0.314, 'v_1': -0.189}
    """
    from lcc_synth.synthesis.design import synthesize

    if isinstance(system, System):
        spec = h2_problem(system, design, pattern, weights, name, **options)
    elif options or (design, pattern, weights, name) != ("structured", "all", None, "python"):
        raise ConfigError("synthesis", "give a System and options, or a spec alone")
    else:
        spec = system
    return synthesize(spec)


def hdv_controller(name: str = "all_hdv", sample_time: float | None = None):
    """The CAV driving exactly like an HDV (Table II's "all HDVs" row, ``type = "hdv"``)."""
    from lcc_synth.controllers.static import HDVController

    return HDVController(name, sample_time)


def _controller(name: str, table: dict[str, Any], system: System):
    from lcc_synth.controllers.registry import build_controller

    return build_controller(name, {k: v for k, v in table.items() if v is not None}, system)


def static_controller(
    system: System,
    gain: Mapping[str, Any] | Gains,
    name: str = "static",
    semantics: str | None = None,
    kind: str | None = None,
    **run: Any,
):
    """A static-gain controller (``type = "static"``, eq. 23) on ``system``.

    ``gain``: from :func:`gains`, or a mapping with its ``semantics`` (``"added"`` or
    ``"replace"``, required: :func:`gains`); on a platoon or ring one table per CAV input
    (``{"u_3": {...}}``). ``kind``: the model the gains are written for (default
    ``system.kind``; e.g. ``"cf_lcc"`` gains on an ``fd_lcc`` string with a head vehicle, as
    in Table II); ``**run``: ``sample_time``, ``equilibrium``, ``equilibrium_tau``,
    ``measurement_filter``. :func:`lcc_synth.controllers.registry.build_controller`."""
    g = gains(gain, semantics, system)
    table = {"type": "static", "kind": kind or system.kind, "semantics": g.semantics,
             "gains": g.as_table(), **run}  # fmt: skip
    return _controller(name, table, system)


def mpc(system: System, name: str = "mpc", **settings: Any):
    """The safety-constrained MPC (``type = "mpc"``) on ``system``.

    ``**settings``: the keys of a ``[controllers.NAME]`` MPC table (``sample_time`` = 0.1,
    ``horizon`` = 50, ``n_model``, ``weights = {...}``, ``constraints = {...}``,
    ``prediction = {...}``, ``solver = {...}``; :mod:`lcc_synth.mpc.settings`). Builds the
    CasADi/OSQP problem once. :func:`lcc_synth.mpc.build.build_mpc`."""
    from lcc_synth.mpc.build import build_mpc

    return build_mpc(system, name, **settings)


def deep_lcc(system: System, name: str = "deep_lcc", scenario: Scenario | None = None,
             **settings: Any):  # fmt: skip
    """DeeP-LCC (``type = "deep_lcc"``), the data-driven predictive controller, on ``system``.

    ``**settings``: the keys of a ``[controllers.NAME]`` DeeP-LCC table (``t_ini``,
    ``horizon``, ``weights = {...}``, ``constraints = {...}``, ``solver = {...}``,
    ``data = {...}``; :mod:`lcc_synth.deeplcc.settings`). Its data are collected from
    ``scenario`` (default: the nominal string of ``system``) at its first use, not here.
    Any open layout (a one-CAV string, a platoon of several CAVs); a ring has no head vehicle
    to drive the data and is refused. :func:`lcc_synth.deeplcc.build.build_deep_lcc`.

    Examples
    --------
    >>> import lcc_synth as lcc
    >>> ctrl = lcc.deep_lcc(lcc.system(size=8, cavs=[3, 6]), t_ini=20, horizon=50)
    >>> ctrl.cavs, ctrl.sample_time, ctrl.built
    ((3, 6), 0.05, False)
    """
    from lcc_synth.deeplcc.build import build_deep_lcc

    return build_deep_lcc(system, name, scenario, **settings)


def sweep(
    problem: str | Path | Problem, count: int | None = None, *, seed: int | None = None,
    controllers: Sequence[str] | None = None, batch_size: int | None = None,
    client: Any = None, progress: bool = False,
):  # fmt: skip
    """A Monte-Carlo sweep of a sweep problem file (``lcc-synth sweep``), on any layout.

    ``count``, ``seed``, ``controllers`` and ``batch_size`` override the file's
    (:func:`lcc_synth.experiments.sweep.load_sweep`, which checks every input before any
    work); the ``h2`` controllers are synthesised here, then the scenarios run on ``client``
    (a ``dask.distributed.Client``) or, without one, in this process, with the same task
    function and the same results (:func:`lcc_synth.experiments.sweep.run_sweep`).

    Returns
    -------
    lcc_synth.experiments.sweep.SweepResult
        ``samples`` (``{controller: {metric: (count,) array}}``), ``summary`` (mean, 5th and
        95th percentiles), ``info`` (count, tasks, times).

    Examples
    --------
    >>> import lcc_synth as lcc
    >>> from pathlib import Path
    >>> problems = Path(lcc.__file__).resolve().parents[1] / "problems"  # the repository's
    >>> res = lcc.sweep(problems / "sweep_robustness.toml", count=4,
    ...                 controllers=["all_hdv", "paper"])
    >>> res.samples["all_hdv"]["aave"].round(3), int(res.samples["paper"]["collisions"].sum())
    (array([3.043, 3.166, 3.029, 3.126]), 0)
    """
    from lcc_synth.experiments.sweep import load_sweep, run_sweep

    spec = load_sweep(problem, count=count, batch_size=batch_size, seed=seed,
                      controllers=controllers)  # fmt: skip
    return run_sweep(spec, client=client, progress=progress)


def scenario(system: System, perturbations: Sequence[Any] = (), **keys: Any) -> Scenario:
    """A :class:`Scenario` on ``system``: ``perturbations`` (:class:`Brake`, :class:`Sine`...)
    and any ``[scenario]`` field (``dt`` = 0.01, ``duration`` = 100, ``t_start``, ``a_min`` =
    -5, ``a_max`` = 2, ``cav_aeb`` = True, ``batch``, ``seed``, ``heterogeneity``, ``v2v``...).

    Built as a problem file's ``[scenario]`` on its ``[system]``
    (:func:`lcc_synth.simulation.scenario_file.scenario_for`): a platoon or ring takes its
    layout and per-vehicle parameters from the system, and perturbations name its vehicles by
    position (the paper's strings: by index, ``-m..n``, or ``"head"``).

    Examples
    --------
    >>> import lcc_synth as lcc
    >>> brake = lcc.scenario(lcc.system("fd_lcc", n=10), [lcc.Brake(vehicle=1)], duration=60.0)
    >>> brake.n_vehicles, brake.steps, brake.perturbations
    (12, 6000, (Brake(vehicle=1, start=20, duration=1, decel=-5),))
    >>> wave = lcc.scenario(lcc.ring(20, cavs=[20]), [lcc.Brake(vehicle=1, start=5.0)])
    >>> wave.n_vehicles, wave.cavs, wave.ring
    (20, (19,), True)
    """
    from lcc_synth.simulation.scenario_file import scenario_for

    return scenario_for(system, perturbations, **keys)


def simulate(scenario: Scenario, controller):
    """Run the nonlinear mixed-traffic simulation: a
    :class:`~lcc_synth.simulation.results.SimResult` (trajectories ``(batch, T, vehicles)``).
    :func:`lcc_synth.simulation.engine.simulate`, or SUMO with ``backend = "sumo"``
    (:func:`lcc_synth.simulation.backends.run_scenario`).

    Examples
    --------
    >>> import lcc_synth as lcc
    >>> string = lcc.system("fd_lcc", n=10)
    >>> brake = lcc.scenario(string, [lcc.Brake(vehicle=1)], t_start=0.01)  # Table II
    >>> run = lcc.simulate(brake, lcc.hdv_controller())
    >>> run.velocity.shape  # (batch, samples, vehicles: the head, the CAV, 10 HDVs)
    (1, 10000, 12)
    >>> bool(run.collided.any())
    False
    """
    from lcc_synth.simulation.backends import run_scenario

    return run_scenario(scenario, controller)


def metrics(
    result, *, window: tuple[float, float], vehicles: str | Sequence[int] = "cav_and_behind"
) -> dict[str, Any]:
    """Every metric of a run (:func:`lcc_synth.metrics.summary`): ``aave`` (m/s), ``fuel_ml``,
    ``min_spacing``, ``min_ttc``, jerk, AEB steps, collisions...

    ``window`` (s) is required: AAVE and fuel depend on it (Table II uses
    :data:`TABLE2_WINDOW` = (20, 40)); ``vehicles``: ``"cav_and_behind"`` (Table II), ``"all"``,
    ``"hdvs"`` or a list of paper indices.

    Examples
    --------
    Table II's "all HDVs" row: HDV 1 brakes at -5 m/s² for 1 s at t = 20 s.

    >>> import lcc_synth as lcc
    >>> brake = lcc.scenario(lcc.system("fd_lcc", n=10), [lcc.Brake(vehicle=1)], t_start=0.01)
    >>> row = lcc.metrics(lcc.simulate(brake, lcc.hdv_controller()), window=lcc.TABLE2_WINDOW)
    >>> round(row["aave"], 4), round(row["fuel_ml"], 2)
    (0.8928, 392.86)
    """
    from lcc_synth.metrics import summary

    return summary(result, _metrics_config(window, vehicles))


def _metrics_config(window: tuple[float, float], vehicles) -> MetricsConfig:
    """The :class:`MetricsConfig` of an explicit window and vehicle set."""
    vehicles = vehicles if isinstance(vehicles, str) else tuple(vehicles)
    try:
        t0, t1 = (float(t) for t in window)
    except (TypeError, ValueError):
        raise ConfigError("metrics.window", f"must be (t0, t1) in s, got {window!r}") from None
    return MetricsConfig((t0, t1), vehicles)


def aave(result, *, window: tuple[float, float], vehicles="cav_and_behind") -> np.ndarray:
    """Average absolute velocity error (m/s) per scenario over ``window`` (required).
    :func:`lcc_synth.metrics.aave`."""
    from lcc_synth.metrics import aave as _aave

    config = _metrics_config(window, vehicles)
    return _aave(result, config.window, config.vehicles)


def fuel(result, *, window: tuple[float, float], vehicles="cav_and_behind") -> np.ndarray:
    """Fuel (mL, Bowyer model) per scenario over ``window`` (required).
    :func:`lcc_synth.metrics.fuel`."""
    from lcc_synth.metrics import fuel as _fuel

    config = _metrics_config(window, vehicles)
    return _fuel(result, config.window, config.vehicles)


def record(
    path: str | Path,
    results: Mapping[str, Any],
    name: str = "python",
    window: tuple[float, float] | None = None,
    controllers: Mapping[str, Any] | None = None,
    decimate: int | str = "minmax",
) -> Path:
    """Write the runs ``results`` (``{controller name: SimResult}``) side by side into one
    Rerun recording ``path`` (``lcc-synth review PATH`` opens it), with the CLI's layout; with
    ``window`` each run's :func:`metrics` too; with ``controllers`` (``{name: controller}``)
    the MPCs' solve times and plans of their last run. ``decimate`` as the CLI's
    ``--record-every``: ``"minmax"`` (min/max-preserving, the default) or every N-th step
    (``1``: exact). Returns ``path``.
    :func:`lcc_synth.recording.open_recording`, :func:`~lcc_synth.recording.record_simulation`.
    """
    from lcc_synth.recording import (
        open_recording,
        record_metrics,
        record_simulation,
        simulation_blueprint,
    )
    from lcc_synth.recording.layout import merge_ranges, plot_ranges

    if not results:
        raise ConfigError("results", "needs at least one {name: SimResult}")
    path = Path(path)
    histories = {k: c.history() for k, c in (controllers or {}).items()
                 if k in results and callable(getattr(c, "history", None))}  # fmt: skip
    ranges = merge_ranges(*(plot_ranges(r) for r in results.values()))
    blueprint = simulation_blueprint(name, list(results), list(histories), ranges)
    with open_recording(path, name, blueprint) as rec:
        for cname, result in results.items():
            record_simulation(rec, result, name, controller=cname, decimate=decimate,
                              mpc_history=histories.get(cname) or None)  # fmt: skip
            if window is not None:
                record_metrics(rec, name, cname, metrics(result, window=window))
    return path
