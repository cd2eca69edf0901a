"""``type = "h2"`` controller tables: the gain synthesised for one system, as a static table.

``lcc-synth run`` and ``sweep`` synthesise every ``h2`` controller per layout
(:func:`lcc_synth.experiments.comparison.prepare_controllers`), ``lcc-synth simulate`` for its
``[system]`` (:func:`lcc_synth.experiments.spec.controllers_from`): both through
:func:`synthesize_table`, which reads the controller's keys as the ``[synthesis]`` table of
``lcc-synth synthesize`` for the parsed system
(:func:`lcc_synth.synthesis.config.synthesis_spec`, the reader ``synthesize`` uses) and runs
:func:`lcc_synth.synthesis.design.synthesize` on it. So a synthesised controller equals the
gain ``lcc-synth synthesize`` writes for the same tables, bit for bit.

* single-CAV kinds (``lcc``, ``cf_lcc``, ``fd_lcc``, ``ccc``): a ``type = "static"`` table
  with the kind, semantics and the gains by state name (``s_0, v_0, s_1, ...``);
* ``kind = "platoon" | "ring"``: a ``type = "static"`` table in the platoon form that
  :class:`~lcc_synth.controllers.static.StaticGainController` reads, one row per CAV
  (``gains = {u_i: {s_j: g, v_j: g}}``, :meth:`~lcc_synth.models.feedback.Gains.as_table`
  of the report's gain; on a ring the gain is defined modulo the conserved total-spacing
  direction, as the report says).

The table is plain data, the form of the gain in result files (``controller_tables``, a
sweep's results files); an MPC's ``fallback = "NAME"`` inlines it there
(:func:`lcc_synth.experiments.spec.resolve_fallbacks`). The controllers are built from the gain
object itself, the report's ``gain`` (``run``, ``simulate`` and a sweep's workers, to which the
client ships the object: :func:`lcc_synth.experiments.spec.controller_gain`): the table is not
read back there.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from lcc_synth.controllers.registry import STATIC_RUN_KEYS
from lcc_synth.errors import ConfigError
from lcc_synth.problem import System

__all__ = ["synthesize_table", "synthesize_h2_tables"]


def synthesize_table(
    name: str,
    table: Mapping[str, Any],
    system: System,
    label: str,
    source: str | None = None,
):
    """Synthesise an ``h2`` controller for ``system``.

    Parameters
    ----------
    name : str
        The controller's name (errors name ``controllers.NAME``).
    table : mapping
        Its table for this system (``type = "h2"``, the keys of ``[synthesis]``, the
        :data:`~lcc_synth.controllers.registry.STATIC_RUN_KEYS` and ``start``).
    system : lcc_synth.problem.System
    label : str
        The name of the synthesis problem (the report's ``problem``).
    source : str, optional
        The problem file (errors name it).

    Returns
    -------
    tuple
        ``(static_table, report)``: a ``type = "static"`` controller table holding the
        synthesised gain (plain data; the
        :data:`~lcc_synth.controllers.registry.STATIC_RUN_KEYS` and ``start`` as the table
        gives them) and the
        :class:`~lcc_synth.synthesis.report.SynthesisReport` (platoon / ring: a gain row per
        CAV), whose ``gain`` is the synthesised gain object.

    Raises
    ------
    ConfigError
        A bad synthesis key (named ``controllers.NAME...``).
    lcc_synth.synthesis.SynthesisError
        Solver failure, infeasibility or an unusable result.
    """
    from lcc_synth.synthesis.config import synthesis_spec
    from lcc_synth.synthesis.design import synthesize

    synth = {k: v for k, v in table.items()
             if k not in ("type", "start") and k not in STATIC_RUN_KEYS}  # fmt: skip
    if synth.get("as_run") not in (None, False):  # design the loop the controller runs
        ar = {} if synth["as_run"] is True else dict(synth["as_run"])
        for key in STATIC_RUN_KEYS:
            if key in table and key not in ar:
                ar[key] = table[key]
        synth["as_run"] = ar
    where = str(Path(source) if source else Path(f"{label}.toml"))
    try:
        spec = synthesis_spec(label, system, synth, where)
    except ConfigError as err:
        fld = err.field
        fld = f"controllers.{name}" + fld[len("synthesis") :] if fld.startswith("synthesis") else (
            f"controllers.{name} ({fld})"
        )
        raise ConfigError(fld, err.message, source) from None
    rep = synthesize(spec)
    out: dict[str, Any] = {
        "type": "static",
        "kind": rep.kind,
        "semantics": rep.semantics,
        "gains": {k: dict(v) if isinstance(v, Mapping) else v for k, v in rep.gains.items()},
    }
    for key in (*STATIC_RUN_KEYS, "start"):
        if key in table:
            out[key] = table[key]
    return out, rep


def synthesize_h2_tables(
    tables: Mapping[str, Mapping[str, Any]],
    system: System,
    source: str | None = None,
    label: str = "problem",
    failures: dict[str, str] | None = None,
) -> tuple[dict[str, dict[str, Any]], dict[str, Any]]:
    """Every ``type = "h2"`` table of ``tables`` replaced by its synthesised static table
    (:func:`synthesize_table`, problem name ``LABEL_NAME``); the other tables unchanged.

    With ``failures`` (a dict), a synthesis that fails
    (:class:`~lcc_synth.synthesis.h2.SynthesisError`) is recorded there as
    ``{name: "synthesis failed: ..."}`` and its controller left out, so that the others still
    run; without it the error propagates.

    Returns
    -------
    tuple
        ``(tables, designs)``: ``{name: table}`` in the order of ``tables`` and
        ``{name: report}`` of the synthesised ones.
    """
    out: dict[str, dict[str, Any]] = {}
    designs: dict[str, Any] = {}
    for name, table in tables.items():
        if isinstance(table, Mapping) and table.get("type") == "h2":
            # the synthesis stack (SciPy, CVXPY) only for a file that has an h2 table
            from lcc_synth.synthesis.h2 import SynthesisError

            try:
                out[name], designs[name] = synthesize_table(
                    name, table, system, f"{label}_{name}", source
                )
            except SynthesisError as err:
                if failures is None:
                    raise
                failures[name] = f"synthesis failed: {err}"
        else:
            out[name] = table
    return out, designs
