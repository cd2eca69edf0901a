"""The MPC of a ``[controllers.NAME]`` problem table (``type = "mpc"``): its settings
(:mod:`lcc_synth.mpc.settings`) and its fallback gain: another controller of the file
(``fallback = "NAME"``), a gains file (``fallback_gains_file``) or the paper's. On a
``kind = "platoon" | "ring"`` system the same :class:`~lcc_synth.mpc.controller.MPCController`
controls every CAV (:mod:`lcc_synth.mpc.joint`), and its fallback gains are in the platoon
form ``{u_i: {state: gain}}`` (default: each CAV's HDV law)."""

from __future__ import annotations

from lcc_synth.controllers.gains_files import read_fallback_file
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.mpc.controller import MPCController
from lcc_synth.mpc.settings import settings_from_table

__all__ = ["mpc_controller_from_table", "build_mpc"]


def _named_fallback(named, system, field_name: str) -> tuple[Gains, str]:
    """The gain of ``fallback = "NAME"`` (as :func:`lcc_synth.experiments.spec.resolve_fallbacks`
    inlines it) and its source label ``controller NAME``, read in the form of the system's
    layout (:meth:`~lcc_synth.models.feedback.Gains.from_mapping`): ``{state: gain}`` for the
    paper's one CAV, ``{u_i: {state: gain}}`` for a platoon or ring."""
    if not isinstance(named, dict) or not isinstance(named.get("gains"), dict):
        raise ConfigError(field_name, f"names controller {named!r}, which is not a static or h2 "
                          "controller (gains {state: gain} for one CAV, {u_i: {state: gain}} "
                          "on a platoon or ring)")  # fmt: skip
    semantics = named.get("semantics", "added")
    try:
        gains = Gains.from_mapping(named["gains"], system.linear_model(warn=False), semantics,
                                   f"{field_name}.gains")  # fmt: skip
    except ConfigError as err:
        if err.field.startswith(field_name):
            raise
        raise ConfigError(f"{field_name}.{err.field}", err.message) from None
    return gains, f"controller {named.get('controller', '?')}"


def mpc_controller_from_table(name: str, table, system, source: str | None = None,
                              fallback: Gains | None = None):  # fmt: skip
    """Build an :class:`MPCController` from a ``[controllers.NAME]`` table (``type = "mpc"``).

    The MPC's ``fallback = "NAME"`` is resolved above this package: given as the gain object
    ``fallback`` (e.g. the gain synthesised for an ``h2`` controller NAME, used as it is), or
    inlined in the table as plain data (``{"controller", "kind", "semantics", "gains"}``, the
    form :func:`lcc_synth.experiments.spec.resolve_fallbacks` writes for result files), which
    is read here.

    Parameters
    ----------
    name : str
        Controller name (table key).
    table : mapping
        The table; see :mod:`lcc_synth.mpc.settings` for the keys.
    system : lcc_synth.problem.System
    source : str, optional
        The problem file: errors name it and ``fallback_gains_file`` is relative to its folder.
    fallback : lcc_synth.models.feedback.Gains, optional
        The gain of the table's ``fallback = "NAME"`` (``NAME`` is its source label
        ``controller NAME``); without it an inlined ``fallback`` table is read.
    """
    field_name = f"controllers.{name}"
    try:
        table = dict(table)
        named = table.pop("fallback", None)  # resolved by the experiments layer
        settings = settings_from_table(table, field_name)
        fb_source = None  # None (and fallback None): the layout's default
        if fallback is not None:
            target = named.get("controller") if isinstance(named, dict) else named
            fb_source = f"controller {target or '?'}"
        elif named is not None:
            fallback, fb_source = _named_fallback(named, system, f"{field_name}.fallback")
        if settings.fallback_gains_file:
            fallback, path = read_fallback_file(table, field_name, system, source)
            fb_source = str(path)
        try:
            return MPCController(name, settings, system, fallback, fb_source)
        except ConfigError as err:
            if err.field.startswith(field_name):
                raise
            raise ConfigError(f"{field_name}.{err.field}", err.message) from None
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None


def build_mpc(system, name: str = "mpc", **settings):
    """The MPC of ``system`` with the keys of a ``type = "mpc"`` table as keyword arguments
    (``lcc.mpc(...)``; calling :mod:`lcc_synth.mpc` calls it): ``sample_time``, ``horizon``,
    ``n_model``, ``weights = {...}``, ``constraints = {...}``, ``prediction``, ``solver``."""
    table = {k: v for k, v in settings.items() if v is not None}
    return mpc_controller_from_table(name, {"type": "mpc", **table}, system)
