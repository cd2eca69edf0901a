"""`lcc-synth synthesize`: report, --json, gains file (contract 3), exit codes, and the gains
file running in the nonlinear simulator against the paper's gains (Table II scenario)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_subprocess import PAPER_HDV, PROBLEMS

from lcc_synth.cli.main import main
from lcc_synth.synthesis.gains_file import REQUIRED_KEYS, read_gains

BASE = """
""" + PAPER_HDV + """
[system]
kind = "{kind}"
m = {m}
n = {n}
v_star = 15.0

[synthesis]
{synthesis}
"""


def write(tmp_path, synthesis, kind="fd_lcc", m=0, n=3, name="p.toml"):
    p = tmp_path / name
    p.write_text(BASE.format(kind=kind, m=m, n=n, synthesis=synthesis))
    return p


@pytest.fixture(scope="module")
def fd_result(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth") / "fd.json"
    return out


def test_fd_problem_json_and_gains_file(fd_result, capsys):
    rc = main(["synthesize", "--no-record", str(PROBLEMS / "synth_fd_lcc_pattern.toml"),
               "--json", "--out", str(fd_result)])
    cap = capsys.readouterr()
    assert rc == 0
    doc = json.loads(cap.out)  # exactly one JSON object on stdout
    assert doc["ok"] and doc["design"] == "structured" and doc["pattern"] == [0, 1, 2]
    assert doc["check"]["h2"] < doc["baseline"]["h2"]  # beats the paper's gain on true H2
    assert doc["check"]["h2"] <= doc["h2_restriction"] <= doc["h2_lmi_bound"]
    file_doc = json.loads(fd_result.read_text())
    for key in (*REQUIRED_KEYS, "pattern", "weights", "h2_true", "h2_lmi_bound", "gamma_peak",
                "gamma_peak_omega", "string_stable", "plant_stable"):
        assert key in file_doc
    gains, d = read_gains(fd_result)
    assert d["kind"] == "fd_lcc" and d["m"] == 0 and d["n"] == 10
    assert gains.semantics == "replace"
    assert set(gains.vehicles()) == {0, 1, 2}
    assert all(gains.gains[f"{c}_{i}"] == 0.0 for i in range(3, 11) for c in "sv")
    assert gains.gains["-p_0"] == 0.0


def test_gains_file_runs_in_simulator_and_beats_paper_on_table2(fd_result):
    """Nonlinear Table II scenario: the synthesised FD-LCC gain (q_a-weighted) has lower AAVE
    and fuel than the paper's hand-picked gain on the same pattern."""
    if not fd_result.exists():
        main(["synthesize", "--no-record", str(PROBLEMS / "synth_fd_lcc_pattern.toml"),
              "--out", str(fd_result)])
    from lcc_synth.controllers.registry import build_controller
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.metrics import summary
    from lcc_synth.simulation.engine import simulate

    sim = load_spec(PROBLEMS / "paper_table2.toml")
    draws = sim.scenario.draw()
    ours = build_controller("synth", {"type": "gains_file", "file": str(fd_result)},
                            sim.system, sim.source)
    s_ours = summary(simulate(sim.scenario, ours, draws), sim.metrics)
    s_paper = summary(simulate(sim.scenario, sim.controllers["fd_lcc"], draws), sim.metrics)
    assert s_paper["aave"] == pytest.approx(0.58, abs=0.005)  # Table II
    assert s_ours["aave"] < s_paper["aave"]
    assert s_ours["fuel_ml"] < s_paper["fuel_ml"]
    assert s_ours["collisions"] == 0


def test_text_report_and_full_state_cross_check(tmp_path, capsys):
    p = write(tmp_path, 'design = "full_state"\ncross_check = true', kind="cf_lcc")
    assert main(["synthesize", "--no-record", str(p)]) == 0
    out = capsys.readouterr().out
    assert "true H2 norm" in out and "riccati_vs_lmi_h2_rel" in out and "string stable" in out


@pytest.mark.parametrize(
    ("synthesis", "field"),
    [
        ('design = "structured"\ncolour = 1', "synthesis.colour"),
        ('pattern = [1, 7]', "synthesis.pattern"),
        ('pattern = "some"', "synthesis.pattern"),
        ("[synthesis.weights]\nr = -1.0", "synthesis.weights.r"),
        ('[synthesis.weights]\nposition = "keep"', "synthesis.weights.position"),
        ("[synthesis.weights]\naccel = 0.0\nhead = 1.0", "synthesis.weights.accel"),
        ('semantics = "added"', "synthesis.semantics"),
        ('design = "string_stable"', "synthesis.design"),
        ('design = "magic"', "synthesis.design"),
        ("tol = 0.5", "synthesis.tol"),
        ("[synthesis.sparsity]\nn_gamma = 1", "synthesis.sparsity.n_gamma"),
        ("[synthesis.string]\ngamma = 0.5", "synthesis.string.gamma"),
        ('[synthesis.baseline]\ngains = { v_9 = 1.0 }', "synthesis.baseline.gains.v_9"),
    ],
)
def test_bad_fields_exit_2(tmp_path, capsys, synthesis, field):
    p = write(tmp_path, synthesis)
    assert main(["synthesize", "--no-record", str(p)]) == 2
    err = capsys.readouterr().err
    assert field in err and str(p) in err
    assert len(err.strip().splitlines()) == 1


def test_infeasible_synthesis_exits_1(tmp_path, capsys):
    p = write(
        tmp_path,
        'design = "string_stable"\nsemantics = "added"\npattern = [1, 2]\n'
        "[synthesis.weights]\nhead = 1.0",
        kind="lcc", m=2, n=2,
    )
    assert main(["synthesize", "--no-record", str(p), "--json"]) == 1
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    assert doc["ok"] is False and "string-stability LMI" in doc["error"]
    assert "synthesis failed" in cap.err


def test_bad_gains_file_is_config_error(tmp_path):
    from lcc_synth.errors import ConfigError

    p = tmp_path / "g.json"
    p.write_text(json.dumps({"kind": "fd_lcc", "m": 0, "n": 2, "semantics": "replace"}))
    with pytest.raises(ConfigError, match="state_names"):
        read_gains(p)
    p.write_text("{not json")
    with pytest.raises(ConfigError, match="JSON"):
        read_gains(p)


def test_sparsity_cli_writes_pareto_png(tmp_path, capsys):
    p = write(tmp_path, 'design = "sparsity"\n[synthesis.sparsity]\nn_gamma = 6', n=4)
    png = tmp_path / "front.png"
    assert main(["synthesize", "--no-record", str(p), "--json", "--figure", str(png)]) == 0
    doc = json.loads(capsys.readouterr().out)
    front = [q for q in doc["pareto"] if q["on_front"]]
    assert [q["count"] for q in front] == sorted(q["count"] for q in front)
    assert np.all(np.diff([q["h2"] for q in front]) < 0)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
