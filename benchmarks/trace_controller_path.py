"""Which modules a controller table crosses on its way from the problem file to the simulator.

Traces (``sys.setprofile``) every call of a function defined under ``lcc_synth/`` from the
entry into :func:`lcc_synth.problem.load_problem` to the simulator's first call of each
controller, on the path ``lcc-synth run`` takes (:func:`lcc_synth.experiments.comparison.
load_suite`, then :func:`~lcc_synth.experiments.comparison.run_suite`): by default the
``h2`` controller (synthesised, then run as a static gain) and the ``mpc`` controller with
its static fallback (``fallback = "h2"``) of ``problems/showcase.toml`` in its ``head_brake``
scenario. The simulator's call of a controller is the engine's ``controller.linear_law(ctx)``
(a static gain runs in the compiled kernel) or ``controller(obs)`` (the MPC, every sample);
the trace stops at the MPC's first ``controller(obs)``, before its first QP is solved.
(``benchmarks/bench_controller_path.py`` counts a narrower set on the ``simulate`` path: only
the modules whose functions receive the controller table or an object made from it.)

Printed: the modules whose functions were called up to the first simulator call, in the order
first reached, with the number of distinct functions each, and their count (the functions run
after a controller's first simulator call until the next controller's run starts, i.e. the
rest of that simulation and its metrics, are not on the path and are left out; imports, the
module bodies, are not counted as calls). Then the round trips: every call of a function that
turns an object into a plain TOML-like table (``as_dict``, ``as_table``, ``to_toml``,
``toml_tables``, and the two that turn a synthesised gain into a controller table:
``synthesize_table``, ``resolve_fallbacks``) whose returned table (or a dict or list inside
it, found by identity, that the call made: the dicts and lists it was given and returns
inside its table, e.g. a problem file's sub-tables passed through, are not counted) is later
passed to a function that reads tables into objects
(``controller_from_table``, ``build_controller``, ``from_mapping``, ``*_from``,
``_named_fallback``). The figures depend on the problem file and the code, not on the
machine; with the trace the path takes about 4 s here (synthesis, MPC set-up).

Measured on the default path: 63 modules, 440 functions, 0 round trips of 3 to-table calls
(the synthesised gain goes to the static controller and to the MPC's fallback as the object,
``SynthesisReport.gain``; ``synthesize_table`` and ``resolve_fallbacks`` still make the plain
tables that the result files report). Before that: 63 modules, 437 functions, 2 round trips
(the static table read back by ``controller_from_table`` and ``build_controller``, the MPC's
inlined fallback by ``_named_fallback`` and ``Gains.from_mapping``).

Usage::

    python benchmarks/trace_controller_path.py [--problem problems/showcase.toml]
        [--scenario head_brake] [--controllers h2,mpc]
"""

from __future__ import annotations

import argparse
import functools
import sys
import time
from pathlib import Path

import lcc_synth

PACKAGE = Path(lcc_synth.__file__).resolve().parent
ROOT = PACKAGE.parent

#: Functions that turn an object (or a result) into a plain TOML-like table.
TO_TABLE = {"as_dict", "as_table", "to_toml", "toml_tables", "synthesize_table",
            "resolve_fallbacks"}  # fmt: skip
#: Functions that read such a table into an object (besides every public ``*_from``).
READERS = {"controller_from_table", "build_controller", "from_mapping", "_named_fallback"}


class Reached(BaseException):
    """The simulator called the last controller traced: stop the run there."""


@functools.cache
def _module(filename: str) -> str | None:
    """The ``lcc_synth`` module of a code object's file (``None``: not the package's)."""
    path = Path(filename)
    if not path.is_absolute() or PACKAGE not in path.parents:
        return None
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _reads_table(name: str) -> bool:
    return name in READERS or (name.endswith("_from") and not name.startswith("_"))


def _containers(value, depth: int = 4):
    """``value`` and the dicts and lists inside it (to ``depth`` levels)."""
    if isinstance(value, dict | list | tuple):
        yield value
        if depth > 0:
            items = value.values() if isinstance(value, dict) else value
            for item in items:
                yield from _containers(item, depth - 1)


def trace(problem: Path, scenario: str, controllers: list[str]) -> dict:
    """Run the traced path; return ``{"modules": {module: [functions]}, "trips": [...],
    "reached": [...]}`` (``trips``: ``(to-table function, its caller, [readers])``)."""
    from lcc_synth.experiments.comparison import load_suite, run_suite

    modules: dict[str, list[str]] = {}
    made: dict[int, int] = {}  # id of a container returned by a to-table call -> its trip
    keep: list = []  # the returned tables stay alive: their ids are not reused
    inputs: dict[int, set[int]] = {}  # frame of a running to-table call -> its inputs' ids
    trips: list[tuple[str, str, list[str]]] = []
    reached: list[str] = []
    state: dict = {"on": False, "resume": None}
    last = controllers[-1]

    def name_of(frame) -> tuple[str | None, str]:
        mod = _module(frame.f_code.co_filename)
        return mod, f"{mod}.{frame.f_code.co_qualname}"

    def profile(frame, event, arg):
        code = frame.f_code
        mod = _module(code.co_filename)
        if mod is None or code.co_name == "<module>" or event not in ("call", "return"):
            return
        if event == "return":
            given = inputs.pop(id(frame), set())
            if state["on"] and code.co_name in TO_TABLE and isinstance(arg, dict | list | tuple):
                caller = name_of(frame.f_back)[1] if frame.f_back is not None else "?"
                trips.append((f"{mod}.{code.co_qualname}", caller, []))
                keep.append(arg)
                for c in _containers(arg):
                    if id(c) not in given:  # passed through (e.g. a file's sub-table): not made
                        made.setdefault(id(c), len(trips) - 1)
            return
        if not state["on"]:
            if state["resume"] is code or (
                mod == "lcc_synth.problem" and code.co_name == "load_problem"
                and state["resume"] is None
            ):  # fmt: skip
                state["on"] = True
            else:
                return
        if code.co_name in TO_TABLE:  # the containers it is given, to tell the ones it makes
            inputs[id(frame)] = {id(c) for v in frame.f_locals.values() for c in _containers(v)}
        funcs = modules.setdefault(mod, [])
        if code.co_qualname not in funcs:
            funcs.append(code.co_qualname)
        if _reads_table(code.co_name) and made:
            hit = {made[id(c)] for v in frame.f_locals.values() for c in _containers(v)
                   if id(c) in made}  # fmt: skip
            for i in sorted(hit):
                reader = f"{mod}.{code.co_qualname}"
                if reader not in trips[i][2]:
                    trips[i][2].append(reader)
        caller = frame.f_back
        if (caller is not None and _module(caller.f_code.co_filename) ==
                "lcc_synth.simulation.engine" and code.co_name in ("__call__", "linear_law")):
            label = getattr(frame.f_locals.get("self"), "name", "?")
            reached.append(f"{label}: {mod}.{code.co_qualname}")
            if label == last and code.co_name == "__call__":
                raise Reached
            # off until the next run starts: the frame that run_suite called for this one
            f = caller
            while f.f_back is not None and f.f_back.f_code.co_name != "run_suite":
                f = f.f_back
            state["on"], state["resume"] = False, f.f_code

    sys.setprofile(profile)
    try:
        suite = load_suite(problem, [scenario], controllers)
        run_suite(suite, progress=False)
    except Reached:
        pass
    finally:
        sys.setprofile(None)
    return {"modules": modules, "trips": trips, "reached": reached}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problem", default=str(ROOT / "problems" / "showcase.toml"))
    parser.add_argument("--scenario", default="head_brake")
    parser.add_argument("--controllers", default="h2,mpc",
                        help="comma-separated; the trace stops at the last one's first step")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    out = trace(Path(args.problem), args.scenario, args.controllers.split(","))
    took = time.perf_counter() - t0
    print(f"{args.problem} [{args.scenario}] controllers {args.controllers}: "
          f"load_problem -> each controller's first simulator call ({took:.0f} s traced)")
    print("simulator calls:", "; ".join(out["reached"]) or "none")
    print("modules whose functions were called (first reached first), functions each:")
    for mod, funcs in out["modules"].items():
        print(f"  {mod:<48} {len(funcs):>4}")
    print(f"distinct modules: {len(out['modules'])}, distinct functions: "
          f"{sum(len(f) for f in out['modules'].values())}")  # fmt: skip
    print("object -> table calls, and the readers their tables reach (round trip if any):")
    for func, caller, readers in out["trips"]:
        print(f"  {func}  (called by {caller})")
        for r in readers:
            print(f"      -> re-parsed by {r}")
    n = sum(1 for _, _, readers in out["trips"] if readers)
    print(f"object -> dict -> object round trips: {n} of {len(out['trips'])} to-table calls")
    return 0


if __name__ == "__main__":
    sys.exit(main())
