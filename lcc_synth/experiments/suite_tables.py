"""The controller tables of a suite (``lcc-synth run``), per layout and scenario: a table on a
layout (:func:`controller_table`: its base keys merged with its ``layouts`` entry), where a
controller runs (:func:`applies`: ``only_layouts``, ``only_scenarios``) and what of them is
checked when the suite is loaded (:func:`check_suite_controllers`). Re-exported by
:mod:`lcc_synth.experiments.comparison`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from lcc_synth.controllers.gains_files import check_gains_files
from lcc_synth.experiments.spec import check_starts

__all__ = ["applies", "check_suite_controllers", "controller_table"]


def _merge(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def controller_table(table: Mapping[str, Any], layout: str) -> dict[str, Any]:
    """The controller table for ``layout``: the base keys merged with its ``layouts`` entry."""
    base = {k: v for k, v in table.items() if k not in ("layouts", "only_layouts",
                                                        "only_scenarios")}
    over = table.get("layouts", {}).get(layout, {})
    return _merge(base, over)


def applies(table: Mapping[str, Any], layout: str, scenario: str | None = None) -> bool:
    """Does the controller of ``table`` run on ``layout`` (and in ``scenario``, when given)?
    (``only_layouts``: the layouts it is for, e.g. the paper's gains, written for two
    single-CAV strings; ``only_scenarios``: the scenarios; absent: every one.) A controller
    left out has no row there."""
    only = table.get("only_layouts")
    scen = table.get("only_scenarios")
    return (only is None or layout in only) and (scenario is None or scen is None
                                                 or scenario in scen)  # fmt: skip


def check_suite_controllers(
    ctrls: Mapping[str, Mapping[str, Any]], names: Sequence[str], extra: Sequence[str],
    scenarios: Mapping[str, Any], layouts: Mapping[str, Any], source: str | None = None,
) -> None:  # fmt: skip
    """What :func:`lcc_synth.experiments.comparison.load_suite` checks of the controller
    tables ``ctrls`` before any design: in every scenario of the file (``scenarios``:
    ``{name: SuiteScenario}``, selected or not) each controller of ``names`` that drives there
    switches on before its end (:func:`lcc_synth.experiments.spec.check_starts`), and on every
    layout of a scenario (``layouts``: ``{name: System}``) the gains files that they and the
    controllers ``extra`` their MPCs fall back to name are read
    (:func:`lcc_synth.controllers.gains_files.check_gains_files`).

    Raises
    ------
    ConfigError
        A ``start`` at or after a scenario's last sample; a gains file that cannot be read or
        does not fit its layout.
    """
    for sname, ss in scenarios.items():
        tables = {c: controller_table(ctrls[c], ss.layout) for c in names
                  if applies(ctrls[c], ss.layout, sname)}  # fmt: skip
        check_starts(tables, ss.scenario, f" in scenario {sname!r}")
    for lname in dict.fromkeys(ss.layout for ss in scenarios.values()):
        tables = {c: controller_table(ctrls[c], lname) for c in [*names, *extra]
                  if applies(ctrls[c], lname)}  # fmt: skip
        check_gains_files(tables, layouts[lname], source)
