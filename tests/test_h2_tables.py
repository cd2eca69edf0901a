"""An ``h2`` controller table is synthesised for the parsed system itself (issue 29: no
object -> dict -> object round trip): the gain equals the one ``lcc-synth synthesize``
computes from the problem file, and no ``[hdv]`` / ``[system]`` table is read again."""

from __future__ import annotations

from pathlib import Path

import pytest

import lcc_synth.problem as problem
import lcc_synth.synthesis.config as config
from lcc_synth.experiments.h2_tables import synthesize_table
from lcc_synth.problem import load_problem
from lcc_synth.synthesis.config import spec_from_problem
from lcc_synth.synthesis.design import synthesize

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"


@pytest.mark.parametrize("name", ["synth_cf_lcc_pattern", "synth_ring_sugiyama"])
def test_h2_table_is_the_gain_of_synthesize_on_the_file(name, monkeypatch):
    path = PROBLEMS / f"{name}.toml"
    prob = load_problem(path)
    want = synthesize(spec_from_problem(prob))  # the gain `lcc-synth synthesize` writes
    system = spec_from_problem(prob).system

    def refuse(*args, **kwargs):
        raise AssertionError("the system was parsed again from a table")

    monkeypatch.setattr(problem, "system_from", refuse)
    monkeypatch.setattr(config, "system_from", refuse)  # the reader `synthesize` uses
    table = {"type": "h2", **prob.data["synthesis"], "sample_time": 0.1}
    static, rep = synthesize_table("h2", table, system, prob.name, str(path))
    assert rep.kind == want.kind
    gains = want.gains if system.platoon is None else {k: dict(v) for k, v in want.gains.items()}
    assert static == {"type": "static", "kind": want.kind, "semantics": want.semantics,
                      "gains": gains, "sample_time": 0.1}  # fmt: skip


def test_a_bad_synthesis_key_names_the_controller():
    from lcc_synth.errors import ConfigError

    prob = load_problem(PROBLEMS / "synth_cf_lcc_pattern.toml")
    system = spec_from_problem(prob).system
    with pytest.raises(ConfigError) as err:
        synthesize_table("mine", {"type": "h2", "design": "nope"}, system, "t", "p.toml")
    assert err.value.field == "controllers.mine.design" and err.value.source == "p.toml"
