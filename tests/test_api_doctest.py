"""The ``>>>`` examples in the docstrings of the flat API (:mod:`lcc_synth.api`) run and print
what they show.

Independent truth: each example's expected output is written in the docstring (the paper's
values where it has them: Theorem 2, Table II's CF-LCC gain, the 20 m equilibrium spacing of
the OVM at 15 m/s); the examples of the main entry points are counted, so that one cannot
disappear unnoticed.
"""

from __future__ import annotations

import doctest

import lcc_synth.api as api
import lcc_synth.experiments.problem_objects as problem_objects

#: The modules whose functions the flat API re-exports with their examples.
MODULES = (api, problem_objects)

#: Entry points whose docstring must hold a runnable example.
WITH_EXAMPLES = (
    "system", "ring", "model", "controllability", "gains", "string_stability",
    "synthesize_h2", "deep_lcc", "scenario", "simulate", "metrics", "sweep", "load_problem",
)  # fmt: skip


def test_every_main_entry_point_has_an_example():
    finder = doctest.DocTestFinder()
    tests = {t.name: t for mod in MODULES for t in finder.find(mod, mod.__name__)}
    missing = [name for name in WITH_EXAMPLES
               if not any(tests.get(f"{m.__name__}.{name}") and
                          tests[f"{m.__name__}.{name}"].examples for m in MODULES)]  # fmt: skip
    assert missing == []


def test_the_examples_print_what_they_show():
    flags = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
    results = [doctest.testmod(m, optionflags=flags, verbose=False, report=True) for m in MODULES]
    assert [r.failed for r in results] == [0, 0]
    assert sum(r.attempted for r in results) >= 30
