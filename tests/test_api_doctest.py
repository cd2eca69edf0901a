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

#: Entry points whose docstring must hold a runnable example.
WITH_EXAMPLES = (
    "system", "ring", "model", "controllability", "gains", "string_stability",
    "synthesize_h2", "deep_lcc", "scenario", "simulate", "metrics", "sweep", "load_problem",
)  # fmt: skip


def test_every_main_entry_point_has_an_example():
    finder = doctest.DocTestFinder()
    tests = {t.name.rsplit(".", 1)[-1]: t for t in finder.find(api, "lcc_synth.api")}
    missing = [name for name in WITH_EXAMPLES if not tests.get(name, None) or
               not tests[name].examples]  # fmt: skip
    assert missing == []


def test_the_examples_print_what_they_show():
    flags = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
    result = doctest.testmod(api, optionflags=flags, verbose=False, report=True)
    assert result.failed == 0
    assert result.attempted >= 30
