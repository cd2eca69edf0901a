"""``design = "string_stable"`` on open platoons: the one-CAV string-aware design (mixed
H2 / bounded-real-lemma LMI, then polishing that keeps string stability) with a gain row per
CAV and per-CAV patterns.

Truth used here: the head-to-tail transfer function ``Gamma(jw) = c (jwI - A_cl)^-1 h`` built
from the model's ``A``, ``B``, ``H`` and the reported whole-input gain alone (``c`` picks the
last vehicle's velocity), on a dense frequency grid; the exact zeros of the patterns; the
plain structured design on the same patterns (a local H2 minimum: the string-stable design
cannot beat it); the ``kind = "lcc"`` string that a one-CAV platoon is.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
from cli_subprocess import PAPER_HDV, run_cli

from lcc_synth.errors import ConfigError
from lcc_synth.problem import Problem
from lcc_synth.synthesis.config import spec_from_problem
from lcc_synth.synthesis.design import synthesize
from lcc_synth.synthesis.report import format_report

#: A stiff own-spacing weight (q_s0 = 10) makes every CAV track its gap tightly: the plain
#: H2 designs of these platoons amplify the head's low-frequency waves (peak |Gamma| 1.018
#: for the two-CAV patterns below), so the string-aware design has something to do.
WEIGHTS = ("[synthesis.weights]\nq_s = 1.0\nq_s0 = 10.0\nq_v = 1.0\nr = 1.0\nhead = 1.0\n"
           "accel = 1.0\n")

#: Size 6, CAVs at 2 and 4: CAV 2 hears vehicles 1-3 only, CAV 4 hears every vehicle (with
#: comm_range = 1 the block-diagonal LMI certificate is infeasible, as for one CAV hearing
#: few vehicles: the error says to hear more vehicles or raise gamma).
TWO_CAVS = ('kind = "platoon"\nsize = 6\ncavs = [2, 4]\nv_star = 15.0',
            "[synthesis.patterns]\nu_2 = [1, 2, 3]\nu_4 = [1, 2, 3, 4, 5, 6]\n")  # fmt: skip


def _text(system: str, design: str, extra: str = "") -> str:
    return (f'name = "p"\n{PAPER_HDV}[system]\n{system}\n[synthesis]\ndesign = "{design}"\n'
            f'semantics = "replace"\n{extra}\n{WEIGHTS}')  # fmt: skip


def _spec(system: str, design: str, extra: str = ""):
    return spec_from_problem(Problem(Path("p.toml"), tomllib.loads(_text(system, design, extra))))


#: The frequency grid of the independent check (rad/s).
OMEGA = np.logspace(-4, 2, 3000)


def _peak_gamma(spec, rep) -> float:
    """``max |Gamma(jw)|`` on :data:`OMEGA`, from the model matrices and the reported input
    gain."""
    model = spec.system.linear_model(warn=False)
    A, B, H = np.asarray(model.A), np.asarray(model.B), np.asarray(model.H).reshape(-1)
    Ku = np.atleast_2d(rep.input_K)
    kh = np.atleast_1d(rep.input_kh)
    Acl, h = A + B @ Ku, H + B @ kh
    c = np.zeros(A.shape[0])
    c[list(model.state_names).index(f"v_{spec.system.platoon.size}")] = 1.0
    M = 1j * OMEGA[:, None, None] * np.eye(A.shape[0]) - Acl
    return float(np.max(np.abs(np.linalg.solve(M, h[None, :, None])[:, :, 0] @ c)))


@pytest.fixture(scope="module")
def two_cav():
    system, patterns = TWO_CAVS
    designs = {}
    for design in ("structured", "string_stable"):
        spec = _spec(system, design, patterns)
        designs[design] = (spec, synthesize(spec))
    return designs


def test_two_cav_string_stable_design_keeps_the_patterns_and_fixes_the_plain_design(two_cav):
    spec, rep = two_cav["string_stable"]
    _, plain = two_cav["structured"]
    # the plain structured design on the same patterns amplifies waves: the design matters
    assert _peak_gamma(spec, plain) > 1.01
    # the design is string stable by the independent frequency check (|Gamma(0)| = 1 for
    # every stabilising gain: the grid's values stay at or below 1 up to round-off)
    assert _peak_gamma(spec, rep) <= 1.0 + 1e-9
    c = rep.check
    assert c.string_stable and c.plant_stable and c.string_verdict == "string_stable"
    assert c.string_margin >= 1e-4 * (1 - 1e-9)  # DESIGN_MARGIN kept by every accepted step
    # the patterns' zeros exactly; every CAV uses the states it hears
    K = np.asarray(rep.K, float)
    vehicle = np.array([int(nm.split("_")[1]) for nm in rep.state_names])
    for row, heard in zip(K, ([1, 2, 3], [1, 2, 3, 4, 5, 6]), strict=True):
        h = np.isin(vehicle, heard)
        assert np.all(row[~h] == 0.0)
        assert np.any(row[h] != 0.0)
    assert rep.patterns == {"u_2": [1, 2, 3], "u_4": [1, 2, 3, 4, 5, 6]}
    # a constrained design on the same patterns cannot beat the plain local optimum
    assert rep.h2_unstructured <= plain.check.h2 <= c.h2 <= rep.h2_restriction * (1 + 1e-12)
    assert rep.h2_restriction <= rep.h2_lmi_bound * (1 + 1e-6)  # the LMI's H2 bound holds
    assert [s["stage"] for s in rep.stages] == ["riccati", "string LMI", "string polish"]
    text = format_report(rep)
    assert "at w = 0 rad/s -> string stable (margin" in text and "LMI bound" in text


def test_one_cav_platoon_gives_the_gain_of_the_lcc_string_it_is():
    """Size 5 with the CAV at 3 is ``kind = "lcc"``, ``m = n = 2`` (the same A, B, H bit for
    bit): the same LMI data and the same polish give the same gain. Measured: identical to the
    last bit; the tolerance 1e-9 leaves room for another BLAS's summation order in the
    interior-point solve (the LMI is solved numerically, to about 1e-8)."""
    steps = "[synthesis.string]\npolish_steps = 3\n"
    plat_spec = _spec('kind = "platoon"\nsize = 5\ncavs = [3]\nv_star = 15.0',
                      "string_stable", steps)  # fmt: skip
    one_spec = _spec('kind = "lcc"\nm = 2\nn = 2\nv_star = 15.0', "string_stable", steps)
    plat, one = synthesize(plat_spec), synthesize(one_spec)
    np.testing.assert_allclose(np.asarray(plat.K[0]), np.asarray(one.K), rtol=1e-9, atol=1e-12)
    assert plat.check.h2 == pytest.approx(one.check.h2, rel=1e-9)
    assert plat.check.string_margin == pytest.approx(one.check.string_margin, rel=1e-6)
    assert plat.h2_lmi_bound == pytest.approx(one.h2_lmi_bound, rel=1e-9)
    assert plat.polish["iterations"] == one.polish["iterations"]
    assert plat.check.string_stable and one.check.string_stable


@pytest.mark.parametrize(("extra", "design", "field"), [
    ("", "string_stable", "synthesis.design"),
    ("[synthesis.string]\ngamma = 1.0\n", "structured", "synthesis.string"),
])  # fmt: skip
def test_a_ring_refuses_the_string_stable_design(extra, design, field):
    ring = 'kind = "ring"\nsize = 6\ncavs = [1, 4]\nv_star = 15.0'
    with pytest.raises(ConfigError) as err:
        _spec(ring, design, extra)
    assert err.value.field == field
    assert "kind = 'ring'" in err.value.message and "head" in err.value.message


def test_string_stable_platoon_needs_the_head_disturbance_and_refuses_robust_and_lag():
    system, patterns = TWO_CAVS
    with pytest.raises(ConfigError) as err:
        spec_from_problem(Problem(Path("p.toml"), tomllib.loads(
            _text(system, "string_stable", patterns).replace("head = 1.0", "head = 0.0"))))
    assert err.value.field == "synthesis.weights.head"
    with pytest.raises(ConfigError) as err:
        _spec(system, "string_stable", patterns + "[synthesis.robust]\nalpha = [0.5, 0.7]\n")
    assert err.value.field == "synthesis.robust"
    with pytest.raises(ConfigError) as err:  # its LMI and polish are of the lag-free loop
        _spec(system, "string_stable", "cav_lag = 0.3\n" + patterns)
    assert err.value.field == "synthesis.cav_lag" and "structured" in err.value.message


def test_spec_round_trips_the_string_table():
    system, patterns = TWO_CAVS
    spec = _spec(system, "string_stable",
                 patterns + "[synthesis.string]\ngamma = 1.0\npolish_steps = 7\nmargin = 2e-4\n")
    assert (spec.string_gamma, spec.polish_steps, spec.string_margin) == (1.0, 7, 2e-4)
    back = spec_from_problem(Problem(Path("p.toml"), tomllib.loads(spec.to_toml())))
    assert back == spec


def test_cli_designs_a_string_stable_platoon(tmp_path):
    system, patterns = TWO_CAVS
    problem = tmp_path / "platoon_string.toml"
    problem.write_text(_text(system, "string_stable",
                             patterns + "[synthesis.string]\npolish_steps = 1\n"))
    proc = run_cli(["synthesize", "--no-record", problem, "--json"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["design"] == "string_stable" and doc["cavs"] == [2, 4]
    # the one-CAV string fields of --json, on the platoon's report
    for key in ("plant_stable", "string_stable", "gamma_peak", "gamma_peak_omega",
                "string_verdict", "string_margin"):
        assert key in doc["check"], key
    assert doc["check"]["string_stable"] is True
    assert doc["check"]["string_verdict"] == "string_stable"
    assert doc["check"]["gamma_peak"] <= 1.0 + 1e-12
    assert doc["solver"]["gamma_bound"] == 1.0 and doc["solver"]["status"].startswith("optimal")
    assert doc["polish"]["iterations"] <= 1
    assert doc["check"]["h2"] <= doc["h2_restriction"] <= doc["h2_lmi_bound"] * (1 + 1e-6)


def test_cli_refuses_a_string_stable_ring_with_one_line(tmp_path):
    problem = tmp_path / "ring_string.toml"
    problem.write_text(_text('kind = "ring"\nsize = 6\ncavs = [1, 4]\nv_star = 15.0',
                             "string_stable"))
    proc = run_cli(["synthesize", "--no-record", problem], cwd=tmp_path)
    assert proc.returncode == 2
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and "synthesis.design" in err[0] and str(problem) in err[0]
    assert "kind = 'ring'" in err[0] and not proc.stdout
