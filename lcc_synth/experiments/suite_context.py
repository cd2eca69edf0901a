"""One scenario of a suite (``lcc-synth run``) as what its recording's context document needs.

``lcc-synth simulate`` records, per scenario, a context document
(:func:`lcc_synth.recording.context.context_markdown`: the problem's description, the layout,
the perturbations, the metric window, the HDV parameters, the controllers and the problem file
that reproduces the run). :func:`scenario_context` gives a suite scenario the same shape, so
that every tab of ``lcc-synth run``'s recording carries the same document at
``/<scenario>/context``. Its "problem file that reproduces this run" is a suite file of that
one scenario: its layout, the controllers that run in it (their ``only_layouts`` /
``only_scenarios`` dropped: restricted to that scenario they apply anyway) and the controllers
those fall back to; ``lcc-synth run`` on it runs the same scenario with the same controllers.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from lcc_synth.experiments.comparison import Suite, fallback_names
from lcc_synth.experiments.suite_tables import applies

__all__ = ["ScenarioContext", "scenario_context"]

_RESTRICTIONS = ("only_layouts", "only_scenarios")


@dataclass(frozen=True)
class ScenarioContext:
    """One suite scenario in the shape :func:`~lcc_synth.recording.context.context_markdown`
    reads (``name``, ``description``, ``scenario``, ``metrics``, ``controllers``,
    ``to_toml()``).

    Attributes
    ----------
    name : str
        The scenario's name in the suite.
    description : str
        Its title, where it comes from (suite, layout) and the suite's description.
    scenario : Scenario
        The simulator scenario.
    metrics : MetricsConfig
        Its metric settings.
    controllers : dict
        ``{name: controller table}`` of the controllers that run in it.
    suite : Suite
        The suite of this scenario alone (:meth:`to_toml`).
    """

    name: str
    description: str
    scenario: Any
    metrics: Any
    controllers: dict[str, dict[str, Any]]
    suite: Suite

    def to_toml(self) -> str:
        """The suite file of this scenario alone (``lcc-synth run`` reads it)."""
        return self.suite.to_toml()


def _unrestricted(table: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in table.items() if k not in _RESTRICTIONS}


def scenario_context(suite: Suite, name: str) -> ScenarioContext:
    """Scenario ``name`` of ``suite`` as a :class:`ScenarioContext`.

    Raises
    ------
    KeyError
        ``name`` is not one of ``suite.scenarios``.
    """
    ss = suite.scenarios[name]
    runs = {c: _unrestricted(t) for c, t in suite.controllers.items()
            if applies(t, ss.layout, name)}  # fmt: skip
    every = {**suite.controllers, **suite.fallbacks}
    falls = {c: _unrestricted(every[c]) for c in fallback_names(every, list(runs))
             if c not in runs}  # fmt: skip
    alone = replace(suite, scenarios={name: ss}, layouts={ss.layout: suite.layouts[ss.layout]},
                    controllers=runs, fallbacks=falls)  # fmt: skip
    head = f"{ss.title}\n\n" if ss.title else ""
    where = f"Scenario `{name}` of the suite `{suite.name}`, on its layout `{ss.layout}`."
    about = str(suite.description or "").strip()
    return ScenarioContext(
        name=name, description=head + where + (f"\n\n{about}" if about else ""),
        scenario=ss.scenario, metrics=ss.metrics, controllers=runs, suite=alone,
    )  # fmt: skip
