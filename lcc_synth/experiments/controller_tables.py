"""``controller_from_table``: the controller of a ``[controllers.NAME]`` problem table, of any
type.

This is the one entry from a controller table to a controller, and it sits above the packages
that build them, so that imports point one way (down):

* ``type = "mpc"``: :func:`lcc_synth.mpc.build.mpc_controller_from_table` (imported only then);
* ``type = "deep_lcc"``: :func:`lcc_synth.deeplcc.build.deep_lcc_controller_from_table`, whose
  data are collected on ``scenario`` at the controller's first use (imported only then);
* every other type (``hdv``, ``static``, ``gains_file`` and the field's baselines):
  :func:`lcc_synth.controllers.registry.build_controller`.

A gain already in memory is passed as the object, never as a table: ``gains`` is the gain
synthesised for a ``type = "h2"`` table (the report's ``gain``,
:class:`~lcc_synth.synthesis.report.SynthesisReport`; built by
:func:`lcc_synth.controllers.registry.static_controller`, the table giving only how it runs)
or, for an MPC, the gain its ``fallback = "NAME"`` names
(:func:`lcc_synth.experiments.spec.controller_gain` picks it).

Any type takes ``start`` (s): the controller switches on then, the CAVs driving with their HDV
law before (:func:`lcc_synth.controllers.registry.switched_on`).
"""

from __future__ import annotations

from typing import Any

from lcc_synth.controllers.base import Controller
from lcc_synth.controllers.baselines import BASELINE_TYPES
from lcc_synth.controllers.registry import build_controller, static_controller, switched_on
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.problem import System

__all__ = ["CONTROLLER_TYPES", "PREDICTIVE_TYPES", "controller_from_table"]

#: The types built above :mod:`lcc_synth.controllers` (by :mod:`lcc_synth.mpc` and
#: :mod:`lcc_synth.deeplcc`).
PREDICTIVE_TYPES = ("mpc", "deep_lcc")
#: Every ``type`` of a ``[controllers.NAME]`` table of ``lcc-synth simulate``.
CONTROLLER_TYPES = ("hdv", "static", "gains_file", *PREDICTIVE_TYPES, *BASELINE_TYPES)


def controller_from_table(name: str, table: Any, system: System, source: str | None = None,
                          scenario=None, gains: Gains | None = None) -> Controller:  # fmt: skip
    """Build the controller of a ``[controllers.NAME]`` table (module docstring).

    Parameters
    ----------
    name : str
        The controller's name (the table key).
    table : mapping
        ``type`` (one of :data:`CONTROLLER_TYPES`) and the type's keys (see
        ``problems/README.md``). ``gains_file`` and ``fallback_gains_file`` paths are relative
        to ``source``'s folder.
    system : lcc_synth.problem.System
        The problem's ``[hdv]`` + ``[system]``.
    source : str, optional
        The problem file (for error messages and relative paths).
    scenario : lcc_synth.simulation.scenario.Scenario, optional
        The problem's scenario: a ``deep_lcc`` controller collects its data on it (default:
        the nominal string of ``system``).
    gains : lcc_synth.models.feedback.Gains, optional
        With ``type = "h2"``: the gain synthesised for the table, run as a static gain. With
        ``type = "mpc"``: the gain of its ``fallback = "NAME"``. Used as it is (module
        docstring); any other type takes none.

    Raises
    ------
    ConfigError
        A bad table, naming ``controllers.NAME...`` and ``source``.
    """
    field = f"controllers.{name}"
    ctype = table.get("type") if isinstance(table, dict) else None
    if gains is not None and ctype not in ("h2", "mpc"):
        raise ConfigError(f"{field}.type", f"a gain object is given for h2 (its synthesised "
                          f"gain) or mpc (its fallback) controllers, not {ctype!r}", source)
    if ctype == "h2" and gains is not None:
        return static_controller(name, gains, table, system, source)
    if ctype not in PREDICTIVE_TYPES:  # checked there, a bad type or table too
        return build_controller(name, table, system, source)
    try:
        if ctype == "mpc":
            try:
                from lcc_synth.mpc.build import mpc_controller_from_table
            except ImportError as err:
                raise ConfigError(
                    f"{field}.type", f"'mpc' controllers need lcc_synth.mpc, which failed: {err}"
                ) from None
            ctrl = mpc_controller_from_table(name, table, system, source, gains)
        else:
            from lcc_synth.deeplcc.build import deep_lcc_controller_from_table

            ctrl = deep_lcc_controller_from_table(name, table, system, source, scenario)
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None
    return switched_on(ctrl, table, field)
