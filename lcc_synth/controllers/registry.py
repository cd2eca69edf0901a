"""``build_controller``: the controller of a ``[controllers.NAME]`` problem table of a type
this package builds (:data:`BASIC_TYPES`).

``type = "hdv"`` and ``"static"`` build the controllers of :mod:`lcc_synth.controllers.static`,
``"gains_file"`` a static-gain controller from a gains file written by ``lcc-synth synthesize``,
``"follower_stopper"``, ``"pi_saturation"``, ``"acc"`` and ``"cacc"`` the field's baselines
(:mod:`lcc_synth.controllers.baselines`). Any type takes ``start`` (s): the controller switches
on then, the CAVs driving with their HDV law before (:func:`switched_on`,
:mod:`lcc_synth.controllers.switch`). The predictive types (``"mpc"``, ``"deep_lcc"``) are
built by the packages above this one; the entry for every type is
:func:`lcc_synth.experiments.controller_tables.controller_from_table`.

For ``[system] kind = "platoon" | "ring"`` a ``static`` table gives one gain table per CAV
input (``[controllers.NAME.gains.u_3]``, ``s_3 = ...``: states ``s_i, v_i`` of positions, the
form of :meth:`~lcc_synth.models.feedback.Gains.as_table`), and a ``gains_file`` is the
platoon form of the synthesis: a JSON object with ``kind``, ``size``, ``cavs``, ``ring``,
``semantics``, ``state_names``, ``K`` (one row per CAV), ``gains`` (``{"u_20": {"s_20": ..}}``)
and ``h2_true``. Both forms are read by :mod:`lcc_synth.synthesis.gains_file`
(:mod:`lcc_synth.controllers.gains_files`): ``K`` and ``gains`` are both required and must agree
entry for entry, and a platoon file's ``gains`` may not be empty.
"""

from __future__ import annotations

from lcc_synth.controllers.base import Controller
from lcc_synth.controllers.baseline_tables import baseline_from_table
from lcc_synth.controllers.baselines import BASELINE_TYPES
from lcc_synth.controllers.gains_files import read_gains_file
from lcc_synth.controllers.static import (
    HDVController,
    StaticGainController,
)
from lcc_synth.controllers.switch import SwitchedOn
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.models.linear import model_from_hdv
from lcc_synth.models.platoon import PLATOON_KINDS
from lcc_synth.problem import warn_large_gains
from lcc_synth.schema import declared

__all__ = ["BASIC_TYPES", "STATIC_RUN_KEYS", "build_controller", "static_controller",
           "switched_on"]

#: The types :func:`build_controller` builds: the HDV law, static gains, gains files and the
#: field's baselines.
BASIC_TYPES = ("hdv", "static", "gains_file", *BASELINE_TYPES)


_EQ_KEYS = ("equilibrium", "equilibrium_tau", "measurement_filter")

#: Keys of a static-gain table besides its gains: how the law runs (passed on with an ``h2``
#: or ``gains_file`` controller's gains).
STATIC_RUN_KEYS = ("sample_time", *_EQ_KEYS)


def _sample_time(table, field: str, ctype: str) -> float | None:
    return declared(f"controllers.NAME:{ctype}").get(table, "sample_time", field)


def build_controller(name: str, table, system, source: str | None = None) -> Controller:
    """Build the controller of a ``[controllers.NAME]`` table of one of :data:`BASIC_TYPES`.

    Parameters
    ----------
    name : str
        The controller's name (the table key).
    table : mapping
        ``type = "hdv" | "static" | "gains_file" | ...`` and the type's keys (see
        ``problems/README.md``). ``gains_file`` paths are relative to ``source``'s folder.
    system : lcc_synth.problem.System
        The problem's ``[hdv]`` + ``[system]``.
    source : str, optional
        The problem file (for error messages and relative paths).

    Raises
    ------
    ConfigError
        A bad table; a type of another package (``mpc``, ``deep_lcc``: built by
        :func:`lcc_synth.experiments.controller_tables.controller_from_table`).
    """
    field = f"controllers.{name}"
    return switched_on(_build(name, table, system, source, field), table, field)


def switched_on(ctrl: Controller, table, field: str) -> Controller:
    """``ctrl`` switched on at the table's ``start`` (:class:`SwitchedOn`), ``ctrl`` itself
    when the table has none."""
    if isinstance(table, dict) and "start" in table:
        ctype = table["type"]
        start = declared(f"controllers.NAME:{ctype}").get(table, "start", field)
        if start is not None:
            return SwitchedOn(ctrl, start)
    return ctrl


def _build(name: str, table, system, source: str | None, field: str) -> Controller:
    try:
        if not isinstance(table, dict):
            raise ConfigError(field, f"must be a table, got {table!r}")
        ctype = declared("controllers.NAME").get(table, "type", field)
        if ctype not in BASIC_TYPES:
            raise ConfigError(f"{field}.type", f"{ctype!r} controllers are built by "
                              "lcc_synth.experiments.controller_tables.controller_from_table, "
                              f"not here (types here: {list(BASIC_TYPES)})")  # fmt: skip
        if ctype in BASELINE_TYPES:
            return baseline_from_table(name, ctype, table)
        T = declared(f"controllers.NAME:{ctype}")
        T.check(table, field)
        if ctype == "hdv":
            return HDVController(name, _sample_time(table, field, ctype))
        if system.platoon is not None:
            return _platoon_controller(name, table, system, ctype, field, source)
        if ctype == "static":
            kind = T.get(table, "kind", field, default=system.kind)
            if kind in PLATOON_KINDS:
                raise ConfigError(f"{field}.kind", f"{kind!r} gains need [system] kind = "
                                  f"{kind!r} (the problem has {system.kind!r})")  # fmt: skip
            semantics = T.get(table, "semantics", field)
            raw = T.get(table, "gains", field)
            where = field
        else:
            gains, doc = read_gains_file(table, field, system, source)
            kind, semantics, raw = doc["kind"], gains.semantics, gains.gains
            where = f"{field}.file"
        if ctype == "static":
            warn_large_gains(raw, f"{where}.gains")  # a gains file's: by read_gains
        run = _run_keys(table, T, field, ctype, kind)
        try:
            return _paper_controller(name, Gains.named(raw, semantics), kind, system, run)
        except ConfigError as err:
            raise ConfigError(f"{where}.{err.field}", f"{err.message} (kind {kind!r})") from None
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None


def _run_keys(table, T, field: str, ctype: str, kind: str) -> tuple:
    """``(sample_time, equilibrium, equilibrium_tau, measurement_filter)`` of a one-CAV static
    law: how it runs (:data:`STATIC_RUN_KEYS`)."""
    sample_time = _sample_time(table, field, ctype)
    equilibrium = T.get(table, "equilibrium", field)
    tau = None
    if "equilibrium_tau" in table:
        if equilibrium != "estimated":
            raise ConfigError(
                f"{field}.equilibrium_tau", 'only applies with equilibrium = "estimated"'
            )
        tau = T.get(table, "equilibrium_tau", field)
    if equilibrium == "estimated" and kind == "fd_lcc":
        raise ConfigError(
            f"{field}.equilibrium",
            'must be "fixed" for fd_lcc: FD-LCC has no vehicle ahead of the CAV to '
            "estimate the equilibrium velocity from",
        )
    return sample_time, equilibrium, tau, T.get(table, "measurement_filter", field)


def _paper_controller(name: str, gains: Gains, kind: str, system, run: tuple) -> Controller:
    """The static-gain controller of one CAV's ``gains`` on the ``kind`` model of ``system``,
    run as ``run`` (:func:`_run_keys`)."""
    model = model_from_hdv(kind, system.m, system.n, system.hdv, system.v_star, warn=False)
    return StaticGainController(name, gains, model, *run)


def static_controller(name: str, gains: Gains, table, system, source: str | None = None
                      ) -> Controller:  # fmt: skip
    """The static-gain controller of the gain object ``gains``, run as ``table`` says.

    The controller of a gain made in memory, e.g. the one synthesised for a ``type = "h2"``
    table (:attr:`lcc_synth.synthesis.report.SynthesisReport.gain`): the gain is used as it
    is, the same object, not written to a table and read back. ``table`` gives only how the
    law runs: the :data:`STATIC_RUN_KEYS` and ``start``, read as a ``type = "static"`` table
    reads them (its other keys, e.g. the synthesis keys of an ``h2`` table, are not read). The
    checks are those of a static table: the gain's CAVs and states must be the layout's
    (:meth:`~lcc_synth.models.feedback.Gains.check`), a platoon or ring runs with the fixed
    equilibrium, and gains above the plausible size warn.

    Parameters
    ----------
    name : str
        The controller's name (errors name ``controllers.NAME``).
    gains : lcc_synth.models.feedback.Gains
        The gain and its semantics, on the layout of ``system`` (one CAV: states by name from
        the CAV; a platoon or ring: a row per CAV).
    table : mapping
        The controller's table (``sample_time``, ``equilibrium``, ``equilibrium_tau``,
        ``measurement_filter``, ``start``; all optional).
    system : lcc_synth.problem.System
    source : str, optional
        The problem file (errors name it).

    Raises
    ------
    ConfigError
        A bad run key, or a gain that is not on the layout of ``system``.
    """
    field = f"controllers.{name}"
    T = declared("controllers.NAME:static")
    run = {k: table[k] for k in STATIC_RUN_KEYS if k in table}
    try:
        if system.platoon is not None:
            warn_large_gains({f"{u}.{k}": g for u, row in gains.as_table().items()
                              for k, g in row.items()}, f"{field}.gains")  # fmt: skip
            _fixed_equilibrium(run, T, field, system)
            ctrl = _platoon_static(name, gains, run, system, T, "static", field)
        else:
            warn_large_gains(gains.gains, f"{field}.gains")
            keys = _run_keys(run, T, field, "static", system.kind)
            try:
                ctrl = _paper_controller(name, gains, system.kind, system, keys)
            except ConfigError as err:
                raise ConfigError(f"{field}.{err.field}",
                                  f"{err.message} (kind {system.kind!r})") from None  # fmt: skip
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None
    return switched_on(ctrl, table, field)


def _platoon_controller(name: str, table, system, ctype: str, field: str, source: str | None):
    """A ``static`` or ``gains_file`` controller of a ``platoon`` / ``ring`` problem."""
    T = declared(f"controllers.NAME:{ctype}")
    model = system.linear_model(warn=False)
    _fixed_equilibrium(table, T, field, system)
    if ctype == "static":
        kind = T.get(table, "kind", field, default=system.kind)
        if kind != system.kind:
            raise ConfigError(f"{field}.kind", f"must be {system.kind!r} (the problem's kind): "
                              "the gains are on the platoon's states")  # fmt: skip
        raw = T.get(table, "gains", field)
        if not isinstance(raw, dict) or not all(isinstance(r, dict) for r in raw.values()):
            raise ConfigError(f"{field}.gains", f"kind = {kind!r} takes one table per CAV "
                              f"input: [{field}.gains.u_i] with s_j / v_j = gain, for "
                              f"u_i in {list(model.input_names)}")  # fmt: skip
        if not any(raw.values()):
            raise ConfigError(f"{field}.gains", f"is empty: give each CAV's gains "
                              f"[{field}.gains.u_i], u_i in {list(model.input_names)} (an empty "
                              "table is not a zero gain; drive the CAVs with type = \"hdv\" "
                              "for their HDV law)")  # fmt: skip
        warn_large_gains({f"{u}.{k}": g for u, row in raw.items() for k, g in row.items()},
                         f"{field}.gains")  # fmt: skip
        gains = Gains.from_table(raw, model, T.get(table, "semantics", field), f"{field}.gains")
    else:
        gains, _ = read_gains_file(table, field, system, source)
    return _platoon_static(name, gains, table, system, T, ctype, field)


def _fixed_equilibrium(table, T, field: str, system) -> None:
    if T.get(table, "equilibrium", field) != "fixed" or "equilibrium_tau" in table:
        raise ConfigError(
            f"{field}.equilibrium",
            f"must be \"fixed\" for kind = {system.kind!r} (the estimate follows one CAV's "
            "predecessor)",
        )


def _platoon_static(name: str, gains: Gains, table, system, T, ctype: str, field: str
                    ) -> Controller:  # fmt: skip
    """The static-gain controller of a platoon or ring gain, run as ``table`` says (its
    fixed equilibrium checked by :func:`_fixed_equilibrium` first)."""
    return StaticGainController(name, gains, system.linear_model(warn=False),
                                _sample_time(table, field, ctype),
                                measurement_filter=T.get(table, "measurement_filter", field))
