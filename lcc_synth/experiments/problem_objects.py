"""Every object a problem file holds, as one value: :class:`ProblemObjects`.

:func:`load_problem` reads a file with the loaders each command uses (the system, a
simulation's or a sweep's spec, a suite, a synthesis spec, the analysis cases, the region maps)
and returns their objects; :func:`build_problem` assembles the same from objects built in
Python; ``to_toml()`` writes them back, and loading that text gives equal objects (``==`` by
value, :func:`lcc_synth.models.records.same`; tests/test_roundtrip.py checks every file under
``problems/``). Loading runs no simulation: a DeeP-LCC controller collects its data at its
first use. The flat API re-exports these names (``lcc.load_problem``...).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from lcc_synth.errors import ConfigError
from lcc_synth.metrics import MetricsConfig
from lcc_synth.models.records import Record, ValueEq, plain, same, system_tables, toml_text
from lcc_synth.problem import System, system_from
from lcc_synth.simulation.scenario import Scenario

__all__ = ["ProblemObjects", "Regions", "build_problem", "load_problem"]


class Regions(NamedTuple):
    """``(specs, omega)`` of ``[regions]`` / ``[maps.*]`` (``{name: RegionSpec}``, the
    frequencies); ``==`` by value (:func:`~lcc_synth.models.records.same`)."""

    specs: dict[str, Any]
    omega: Any

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, tuple):
            return NotImplemented
        return same(tuple(self), tuple(other))

    def __ne__(self, other: object) -> bool:
        return not self == other if isinstance(other, tuple) else NotImplemented

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True, eq=False, repr=False)
class ProblemObjects(ValueEq, Record):
    """The objects a problem file holds, as the CLI builds them (``None``: not in the file).

    ``==`` compares by value (:func:`~lcc_synth.models.records.same`: arrays by their
    entries, controllers by what defines them): two loads of one file are equal.

    Attributes
    ----------
    name, description : str
    system : System or None
        ``[hdv]`` + ``[system]``.
    simulation : lcc_synth.experiments.spec.SimulationSpec or None
        ``[scenario]``, ``[controllers.*]``, ``[metrics]`` of ``lcc-synth simulate``.
    synthesis : lcc_synth.synthesis.config.SynthesisSpec or None
        ``[synthesis]`` of ``lcc-synth synthesize``.
    sweep : lcc_synth.experiments.sweep.SweepSpec or None
        ``[sweep]`` (with scenario, metrics, controller tables) of ``lcc-synth sweep``.
    suite : lcc_synth.experiments.comparison.Suite or None
        ``[layouts]``, ``[scenarios]``, ``[controllers]`` of ``lcc-synth run``.
    analysis : lcc_synth.analysis.cases.AnalysisOptions or None
        ``[analysis]`` of ``lcc-synth analyze``; ``cases`` its ``[cases.*]`` gains.
    regions : Regions or None
        ``(specs, omega)`` of ``[regions]`` / ``[maps.*]`` (``lcc-synth regions``); written
        back with every map's grid explicit (only the default frequency grid has a TOML form).
    source : str or None
    """

    name: str
    description: str = ""
    system: System | None = None
    simulation: Any = None
    synthesis: Any = None
    sweep: Any = None
    suite: Any = None
    analysis: Any = None
    cases: dict[str, Any] = field(default_factory=dict)
    regions: Any = None
    source: str | None = None

    @property
    def model(self):
        """The linearised model of :attr:`system` (``None`` without one)."""
        return None if self.system is None else self.system.linear_model(warn=False)

    @property
    def scenario(self) -> Scenario | None:
        """The simulated scenario (simulate or sweep files)."""
        spec = self.simulation or self.sweep
        return None if spec is None else spec.scenario

    @property
    def controllers(self) -> dict[str, Any]:
        """The built controllers of a simulate file (sweep / suite files keep tables)."""
        return {} if self.simulation is None else dict(self.simulation.controllers)

    @property
    def metrics(self) -> MetricsConfig | None:
        spec = self.simulation or self.sweep
        return None if spec is None else spec.metrics

    @property
    def mpc(self) -> dict[str, Any]:
        """``{name: MPCSettings}`` of the MPC controllers of a simulate file."""
        return {k: c.settings for k, c in self.controllers.items() if hasattr(c, "settings")}

    def toml_tables(self) -> dict[str, Any]:
        """The file's tables, as each object writes them (its ``toml_table(s)``)."""
        out: dict[str, Any] = {"name": self.name}
        if self.description:
            out["description"] = self.description
        if self.system is not None:
            out.update(system_tables(self.system))
        for part in (self.simulation, self.synthesis, self.sweep, self.suite):
            if part is not None:
                out.update(part.toml_tables())
        if self.analysis is not None:
            out["analysis"] = self.analysis.toml_table()
        if self.cases:
            out["cases"] = {k: c.toml_table() for k, c in self.cases.items()}
        if self.regions is not None:
            from lcc_synth.analysis.region_specs import regions_tables

            out.update(regions_tables(*self.regions))
        return out

    def to_toml(self) -> str:
        """The problem file of these objects; :func:`load_problem` reads it back equal."""
        return toml_text(self.toml_tables())

    def comparable(self) -> dict[str, Any]:
        """``as_dict()`` without where the file was (for comparing two loads)."""
        return _without_source(plain(self))


def build_problem(
    name: str,
    system: System,
    scenario: Scenario | None = None,
    controllers: Mapping[str, Any] | None = None,
    metrics: MetricsConfig | None = None,
    description: str = "",
    synthesis: Any = None,
) -> ProblemObjects:
    """The problem file of objects built in Python: ``build_problem(...).to_toml()`` is a file
    ``lcc-synth simulate`` runs (with ``scenario`` and ``controllers``; ``metrics`` default
    :class:`MetricsConfig` (), i.e. Table II's window) and / or ``lcc-synth synthesize`` runs
    (with ``synthesis``, from :func:`~lcc_synth.api.h2_problem`), which :func:`load_problem`
    reads back equal.
    With neither it holds ``[hdv]`` + ``[system]`` only."""
    sim = None
    if scenario is not None or controllers:
        from lcc_synth.experiments.spec import SimulationSpec

        if scenario is None or not controllers:
            raise ConfigError("controllers", "a simulation needs a scenario and a controller")
        sim = SimulationSpec(name, system, scenario, dict(controllers), metrics or
                             MetricsConfig(), "python", description=description)  # fmt: skip
    if synthesis is not None and synthesis.system != system:
        raise ConfigError("synthesis", "is for another system than the problem's")
    return ProblemObjects(name, description, system, simulation=sim, synthesis=synthesis)


def _without_source(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _without_source(v) for k, v in x.items() if k != "source"}
    if isinstance(x, list):
        return [_without_source(v) for v in x]
    return x


def load_problem(path: str | Path) -> ProblemObjects:
    """Read a problem file into the objects each command builds from it (the CLI's loaders:
    :func:`~lcc_synth.experiments.spec.load_spec`, :func:`~lcc_synth.synthesis.config.
    spec_from_problem`, :func:`~lcc_synth.experiments.sweep.load_sweep`,
    :func:`~lcc_synth.experiments.comparison.load_suite`, the analyze / regions readers).
    Errors are :class:`ConfigError` naming the file and the dotted field.

    Examples
    --------
    >>> import lcc_synth as lcc
    >>> from pathlib import Path
    >>> problems = Path(lcc.__file__).resolve().parents[1] / "problems"  # the repository's
    >>> objs = lcc.load_problem(problems / "paper_table2.toml")
    >>> objs.system.kind, objs.system.n, list(objs.controllers), objs.metrics.window
    ('fd_lcc', 10, ['all_hdv', 'fd_lcc', 'cf_lcc'], (20.0, 40.0))
    >>> objs == lcc.load_problem(problems / "paper_table2.toml")  # compared by value
    True
    """
    from lcc_synth.problem import load_problem as _load

    prob = _load(path)
    src = str(prob.path)
    data = prob.data
    kw: dict[str, Any] = {"source": src}
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise ConfigError("description", f"must be a string, got {desc!r}", src)
    if "layouts" in data or "scenarios" in data:
        from lcc_synth.experiments.comparison import load_suite

        kw["suite"] = load_suite(prob)
    if "system" in data:
        kw["system"] = system_from(data, src)
    if "sweep" in data:
        from lcc_synth.experiments.sweep import load_sweep

        kw["sweep"] = load_sweep(prob)
    elif "scenario" in data or ("controllers" in data and "suite" not in kw):
        from lcc_synth.experiments.spec import load_spec

        kw["simulation"] = load_spec(prob)
    if "synthesis" in data:
        from lcc_synth.synthesis.config import spec_from_problem

        kw["synthesis"] = spec_from_problem(prob)
    if "analysis" in data or "cases" in data:
        from lcc_synth.analysis.cases import analysis_options_from, cases_from

        kw["analysis"] = analysis_options_from(data, src)
        lin = kw["system"].linear_model(warn=False) if "system" in kw else None
        if lin is None:
            raise ConfigError("system", "table is required by [cases]", src)
        kw["cases"] = cases_from(data, lin, src)
    if "maps" in data or "regions" in data:
        from lcc_synth.analysis.region_specs import region_specs_from

        lin = kw["system"].linear_model(warn=False) if "system" in kw else None
        if lin is None:
            raise ConfigError("system", "table is required by [maps]", src)
        kw["regions"] = Regions(*region_specs_from(data, lin, src))
    return ProblemObjects(prob.name, desc, **kw)
