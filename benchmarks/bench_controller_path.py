"""The modules a controller table crosses from the problem file to the simulator (issue 29).

Run:  python benchmarks/bench_controller_path.py [--list]

A ``simulate`` problem file with one ``type = "h2"`` controller and one ``type = "mpc"`` with
``fallback = "h2"`` (CF-LCC, 4 HDVs behind, a 1 s run) is loaded with
:func:`lcc_synth.experiments.spec.load_spec` and each controller runs once
(:func:`lcc_synth.simulation.backends.run_scenario`). A profile hook notes every function of
``lcc_synth`` called with an argument that *is the controller or a piece of it*:

* a controller table (a mapping with ``type`` ``h2``, ``static`` or ``mpc``, or with a
  ``fallback``, ``gains`` or ``design`` key), the mapping of the controller tables, or a
  synthesis problem made from one (a mapping or :class:`~lcc_synth.problem.Problem` with a
  ``synthesis`` table and no ``controllers``);
* an object made from one: gains (``Gains``), a synthesis spec or
  report, MPC settings, a built controller (anything with ``reset`` and ``sample_time``), or
  the mapping of the built controllers.

The whole file's tables (``problem.data``) do not count: ``[scenario]`` and ``[metrics]`` are
read from them too. It prints the number of modules so met (``--list``: each with the
functions), the figure issue 29 quotes as "~22 modules".
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

PROBLEM = """
name = "controller_path"
[hdv]
model = "ovm"
[system]
kind = "cf_lcc"
n = 4
v_star = 15.0
[scenario]
dt = 0.05
duration = 1.0
[controllers.h2]
type = "h2"
design = "structured"
semantics = "replace"
pattern = [1, 2]
sample_time = 0.1
[controllers.mpc]
type = "mpc"
sample_time = 0.1
horizon = 10
fallback = "h2"
[metrics]
window = [0.0, 1.0]
"""

_TABLE_TYPES = ("h2", "static", "mpc")
_OBJECTS = ("Gains", "SynthesisSpec", "SynthesisReport", "MPCSettings")


def _is_table(v) -> bool:
    if not isinstance(v, Mapping):
        return False
    if v.get("type") in _TABLE_TYPES or any(k in v for k in ("fallback", "gains", "design")):
        return True
    return "synthesis" in v and "controllers" not in v  # a synthesis problem made from one


def _is_controller(v) -> bool:
    return hasattr(v, "reset") and hasattr(v, "sample_time") and callable(v)


def carries(v) -> bool:
    """Whether ``v`` is the controller, a piece of it or an object made from it (docstring)."""
    if _is_table(v) or _is_controller(v) or type(v).__name__ in _OBJECTS:
        return True
    if type(v).__name__ == "Problem":
        data = getattr(v, "data", {})
        return "synthesis" in data and "controllers" not in data
    if isinstance(v, Mapping) and v and "controllers" not in v:
        vals = list(v.values())
        return all(_is_table(x) for x in vals) or all(_is_controller(x) for x in vals)
    return False


def trace(run) -> dict[str, set[str]]:
    """``{module: {function, ...}}`` of the ``lcc_synth`` functions called with an argument
    that :func:`carries` the controller, while ``run()`` runs."""
    seen: dict[str, set[str]] = {}

    def hook(frame, event, arg):
        if event != "call":
            return
        module = frame.f_globals.get("__name__", "")
        if not module.startswith("lcc_synth"):
            return
        code = frame.f_code
        n = code.co_argcount + code.co_kwonlyargcount
        n += bool(code.co_flags & 0x04) + bool(code.co_flags & 0x08)  # *args, **kwargs
        values = []
        for name in code.co_varnames[:n]:
            v = frame.f_locals.get(name)
            values.extend(v if isinstance(v, tuple) else [v])
        if any(carries(v) for v in values):
            seen.setdefault(module, set()).add(code.co_qualname)

    sys.setprofile(hook)
    try:
        run()
    finally:
        sys.setprofile(None)
    return seen


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--list", action="store_true", help="each module with its functions")
    args = ap.parse_args()

    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.simulation.backends import run_scenario

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "controller_path.toml"
        path.write_text(PROBLEM)

        def run() -> None:
            spec = load_spec(path)
            scenario = replace(spec.scenario, batch=1)
            for ctrl in spec.controllers.values():
                run_scenario(scenario, ctrl)

        seen = trace(run)
    print(f"modules a controller table crosses (h2 + MPC with fallback = \"h2\"): {len(seen)}")
    if args.list:
        for module in sorted(seen):
            print(f"  {module}: {', '.join(sorted(seen[module]))}")


if __name__ == "__main__":
    main()
