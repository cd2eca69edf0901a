"""The package layout: no import cycle inside ``lcc_synth``, no module over a soft ceiling of
900 lines (modules hold one concept each, sized by the concept: issue 29 replaced the former
600-line rule, which had started to shape files instead of concepts), few plain modules at the
top.

Imports are read with :mod:`ast`, function-level (lazy) imports included: a cycle closed by a
lazy import is still a cycle. Importing ``a.b.c`` also runs the ``__init__`` of ``a.b``, so an
import reaches the parent packages of its target too (those the importer is not inside).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "lcc_synth"
MAX_LINES = 900
MAX_TOP_MODULES = 8


def _modules() -> dict[str, Path]:
    mods = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        mods[".".join(parts)] = path
    return mods


def _owner(name: str, mods: dict[str, Path]) -> str | None:
    """The module of the package that ``name`` (a module or a name inside one) lives in."""
    while name and name not in mods:
        name = name.rpartition(".")[0]
    return name or None


def _parents(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def import_graph() -> dict[str, set[str]]:
    """``{module: modules of lcc_synth it imports}``, lazy imports and parent packages included."""
    mods = _modules()
    graph: dict[str, set[str]] = {}
    for mod, path in mods.items():
        is_pkg = path.name == "__init__.py"
        targets: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    here = mod.split(".") if is_pkg else mod.split(".")[:-1]
                    here = here[: len(here) - node.level + 1]
                    base = ".".join([*here, base] if base else here)
                targets.update(f"{base}.{a.name}" for a in node.names)
        deps = set()
        for target in targets:
            owner = _owner(target, mods)
            if owner is None:
                continue
            deps.add(owner)
            deps.update(p for p in _parents(owner) if p not in (mod, *_parents(mod)))
        deps.discard(mod)
        graph[mod] = deps
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle as ``[a, b, ..., a]``, or ``None``."""
    state: dict[str, int] = {}  # 1 on the path, 2 done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start)):
            return found
    return None


def test_no_import_cycle():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle inside lcc_synth: " + " -> ".join(cycle)


def test_find_cycle_sees_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_lazy_imports_and_parent_packages_are_edges():
    graph = import_graph()
    # experiments.controller_tables imports the MPC inside controller_from_table only
    assert "lcc_synth.mpc.build" in graph["lcc_synth.experiments.controller_tables"]
    assert "lcc_synth.mpc" in graph["lcc_synth.experiments.controller_tables"]


#: Packages that import none of the packages above them (issue 29: imports point one way).
#: The controller of a table of any type is built above all three
#: (:mod:`lcc_synth.experiments.controller_tables`).
_ABOVE = {
    "lcc_synth.controllers": ("lcc_synth.mpc", "lcc_synth.deeplcc", "lcc_synth.simulation",
                              "lcc_synth.experiments", "lcc_synth.recording", "lcc_synth.cli",
                              "lcc_synth.api"),  # fmt: skip
    "lcc_synth.mpc": ("lcc_synth.deeplcc", "lcc_synth.experiments", "lcc_synth.recording",
                      "lcc_synth.cli", "lcc_synth.api"),  # fmt: skip
    "lcc_synth.deeplcc": ("lcc_synth.experiments", "lcc_synth.recording", "lcc_synth.cli",
                          "lcc_synth.api"),  # fmt: skip
}


def _inside(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def upward_imports(graph: dict[str, set[str]], low: str) -> list[str]:
    """``"a -> b"`` for every import of a module of package ``low`` from a package above it
    (:data:`_ABOVE`)."""
    return sorted(f"{mod} -> {dep}" for mod, deps in graph.items() if _inside(mod, low)
                  for dep in deps if any(_inside(dep, high) for high in _ABOVE[low]))  # fmt: skip


@pytest.mark.parametrize("low", sorted(_ABOVE))
def test_no_package_imports_one_above_it(low):
    upward = upward_imports(import_graph(), low)
    assert not upward, upward


def test_upward_imports_sees_a_lazy_import():
    """The lazy import of the MPC's builder that controllers.registry once made inside
    ``build_controller`` would be reported."""
    registry = "lcc_synth.controllers.registry"
    graph = import_graph()
    graph[registry] = {*graph[registry], "lcc_synth.mpc.build"}
    assert upward_imports(graph, "lcc_synth.controllers") == [f"{registry} -> lcc_synth.mpc.build"]


@pytest.mark.parametrize("path", sorted(_modules().values()), ids=lambda p: str(p.name))
def test_module_size(path):
    lines = len(path.read_text().splitlines())
    assert lines <= MAX_LINES, f"{path.relative_to(PACKAGE.parent)} has {lines} lines"


def test_few_plain_modules_at_the_top():
    top = sorted(p.name for p in PACKAGE.glob("*.py") if p.name != "__init__.py")
    assert len(top) <= MAX_TOP_MODULES, top


#: The layers of docs/guide/architecture.md, bottom up: a module imports only its own layer and
#: the layers below (lazy imports included).
LAYERS = (
    ("lcc_synth.errors",),
    ("lcc_synth.models", "lcc_synth.resources", "lcc_synth.interrupts"),
    ("lcc_synth.schema", "lcc_synth.outputs"),
    ("lcc_synth.problem", "lcc_synth.provenance"),
    ("lcc_synth.analysis", "lcc_synth.calibration"),
    ("lcc_synth.synthesis",),
    ("lcc_synth.controllers",),
    ("lcc_synth.simulation",),
    ("lcc_synth.metrics",),
    ("lcc_synth.mpc", "lcc_synth.deeplcc"),
    ("lcc_synth.recording",),
    ("lcc_synth.experiments", "lcc_synth.figures"),
    ("lcc_synth.api",),
    ("lcc_synth.cli",),
)
#: Known exceptions, each with its reason: the schema declares the baselines' keys from the
#: baselines' own default values (one place for them).
LAYER_EXCEPTIONS = {("lcc_synth.schema.controllers", "lcc_synth.controllers.baselines"),
                    ("lcc_synth.schema.controllers", "lcc_synth.controllers")}  # fmt: skip


def layer_of(module: str) -> int | None:
    for i, packages in enumerate(LAYERS):
        if any(_inside(module, p) for p in packages):
            return i
    return None


def test_layers_point_down():
    graph = import_graph()
    unlayered = sorted(m for m in graph if m != "lcc_synth" and layer_of(m) is None)
    assert not unlayered, f"modules in no layer of docs/guide/architecture.md: {unlayered}"
    # ``lcc_synth`` itself (its __init__: __version__, and the flat API loaded on first use)
    # is outside the layers: everything may read its version, and it may load the API
    upward = sorted(f"{m} -> {d}" for m, deps in graph.items() if m != "lcc_synth" for d in deps
                    if (layer_of(m) or 0) < (layer_of(d) or 0)
                    and (m, d) not in LAYER_EXCEPTIONS)  # fmt: skip
    assert not upward, upward


def test_layers_see_an_upward_import():
    graph = {"lcc_synth.models.hdv": {"lcc_synth.metrics"}, "lcc_synth.metrics": set()}
    assert layer_of("lcc_synth.models.hdv") < layer_of("lcc_synth.metrics")
    assert [m for m, deps in graph.items() for d in deps if layer_of(m) < layer_of(d)]
