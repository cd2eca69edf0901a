"""``[synthesis.as_run]`` on open platoons: the as-run design with a gain row per CAV.

Truths:

* the loop as the simulator's controller runs it (:class:`StaticGainController` built from the
  reported gains, sampled at ``T``, V2V values ``latency`` old:
  :func:`~lcc_synth.experiments.string_as_run.controller_loop`), its ``|Gamma(e^{j w T})|``
  evaluated here on a dense grid up to the Nyquist frequency (not the design's verdict);
* the simulator's measured tail/head ratio at ``dt`` and ``dt / 2`` (slow test; Euler's
  first-order error, bounds of tests/test_as_run_platoon.py);
* the hand-written patterns (exact zeros), the plain structured design of the same patterns
  (a local H2 minimum: a constrained design cannot beat it);
* the ``kind = "lcc"`` string that a one-CAV platoon is (bit for bit when the structured gain
  is string stable as run; when it is not, the string reports so and the platoon starts the
  polish from its string LMI gain: the stated difference).
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from cli_subprocess import PAPER_HDV, run_cli

import lcc_synth as lcc
from lcc_synth.controllers.static import StaticGainController
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.string_as_run import controller_loop, measured_ratio
from lcc_synth.problem import Problem
from lcc_synth.synthesis.config import spec_from_problem
from lcc_synth.synthesis.design import synthesize

#: The stiff own-spacing weight of tests/test_synthesis_string_platoon.py: the plain H2 designs
#: amplify the head's waves, so the as-run design has something to do.
WEIGHTS = {"q_s": 1.0, "q_s0": 10.0, "q_v": 1.0, "r": 1.0, "head": 1.0, "accel": 1.0}
#: Size 4, CAVs 2 and 4: CAV 2 hears vehicles 1-3, CAV 4 every vehicle.
PATTERNS = {"u_2": [1, 2, 3]}
#: Sampled at 0.1 s, V2V values two samples old: the plain gain peaks at |Gamma| 1.024 as run.
AS_RUN = {"sample_time": 0.1, "latency": 0.2}
T, LATENCY = 0.1, 0.2


def _system():
    return lcc.system(size=4, cavs=[2, 4], v_star=15.0)


def _design(as_run=None, system=None, **extra):
    opts = {"as_run": as_run} if as_run is not None else {}
    spec = lcc.h2_problem(system or _system(), design="structured", weights=WEIGHTS,
                          semantics="replace", **opts, **extra)  # fmt: skip
    return synthesize(spec)


def _controller(rep, system):
    model = system.linear_model(warn=False)
    return StaticGainController("g", rep.gain, model, sample_time=T)


def _peak_as_run(rep, system, latency=LATENCY) -> float:
    """``max |Gamma|`` of the loop the simulator's controller runs, on a dense grid."""
    loop = controller_loop(_controller(rep, system), system, 0.01, latency)
    assert loop.sample_time == T
    w = np.logspace(-4, math.log10(math.pi / T), 4000)
    return float(np.max(np.abs(loop.response(w))))


@pytest.fixture(scope="module")
def designs():
    return _design(patterns=PATTERNS), _design(AS_RUN, patterns=PATTERNS)


def test_as_run_design_of_a_two_cav_platoon_is_string_stable_as_run(designs):
    plain, rep = designs
    system = _system()
    assert _peak_as_run(plain, system) > 1.02  # the plain gain amplifies as run
    assert _peak_as_run(rep, system) <= 1.0 + 1e-9  # the design does not
    a = rep.as_run
    assert a["before"]["verdict"] == "string_unstable"
    assert a["after"]["verdict"] == "string_stable" and a["string_stable"]
    assert a["after"]["margin"] >= 1e-3  # the settings' margin (default)
    assert a["start"] == "fallback" and a["polished"] and a["polish_iterations"] >= 1
    assert a["before"]["gamma_peak"] == pytest.approx(_peak_as_run(plain, system), rel=1e-4)
    # the pattern's zeros, written by hand: CAV 2 does not hear vehicle 4
    names = rep.state_names
    K = np.asarray(rep.K, float)
    off = [names.index("s_4"), names.index("v_4")]
    assert np.all(K[0, off] == 0.0) and np.all(K[0, : off[0]] != 0.0) and np.all(K[1] != 0.0)
    # the plain design is the pattern's local H2 minimum: the constrained one cannot beat it
    assert rep.check.h2 >= plain.check.h2 * (1 + 1e-6)
    assert a["h2_before"] == pytest.approx(plain.check.h2, rel=1e-9)
    assert a["h2_after"] == pytest.approx(rep.check.h2, rel=1e-9)
    assert [s["stage"] for s in rep.stages][-1] == "as-run polish"
    assert "as_run" not in plain.as_dict()  # no table, no block: the JSON is unchanged


def test_string_stable_design_then_as_run():
    """``design = "string_stable"`` (string stable in continuous time, margin 1.2e-4 as run at
    0.1 s without latency: below the as-run margin 1e-3) ends string stable as run with that
    margin, and still in continuous time (the design's check)."""
    rep = synthesize(lcc.h2_problem(_system(), design="string_stable", weights=WEIGHTS,
                                    semantics="replace", patterns=PATTERNS,
                                    as_run={"sample_time": T}))  # fmt: skip
    a = rep.as_run
    assert 0 < a["before"]["margin"] < 1e-3 <= a["after"]["margin"] and a["string_stable"]
    assert _peak_as_run(rep, _system(), 0.0) <= 1.0 + 1e-9
    assert rep.check.string_stable


@pytest.mark.slow  # the analysed loop of the default test above is this loop
def test_the_simulator_measures_what_the_design_analyses(designs):
    """Tail/head ratios in the simulator at the plain gain's peak and around it: the plain
    gain amplifies there, the design does not (Euler's error halves at ``dt / 2``)."""
    system = _system()
    omega = np.array([0.1, 0.38, 0.6])
    for rep, amplifies in zip(designs, (True, False), strict=True):
        ctrl = _controller(rep, system)
        analysed = np.abs(controller_loop(ctrl, system, 0.01, LATENCY).response(omega))
        r1 = measured_ratio(ctrl, system, omega, 0.01, LATENCY)
        r2 = measured_ratio(ctrl, system, omega, 0.005, LATENCY)
        assert np.all(np.abs(r1 / analysed - 1) < 1e-2), (r1, analysed)
        assert np.all(np.abs(r2 / analysed - 1) <= np.abs(r1 / analysed - 1) * 0.6 + 1e-5)
        assert (np.max(2 * r2 - r1) > 1.01) if amplifies else np.all(2 * r2 - r1 < 1.0)


def test_a_one_cav_platoon_designs_as_the_lcc_string():
    """Same m, n, semantics replace: bit for bit while the structured gain is string stable
    as run; when it is not, the string reports so and the platoon starts from its string LMI
    gain (the stated difference)."""
    ar = {"sample_time": 0.1, "latency": 0.2, "margin": 1e-2, "polish_steps": 30}
    string = lcc.system("lcc", m=1, n=2, v_star=15.0)
    platoon = lcc.system(size=4, cavs=[2], v_star=15.0)
    soft = {**WEIGHTS, "q_s0": 1.0}
    a = synthesize(lcc.h2_problem(string, "structured", weights=soft, semantics="replace",
                                  as_run=ar))  # fmt: skip
    b = synthesize(lcc.h2_problem(platoon, "structured", weights=soft, semantics="replace",
                                  as_run=ar))  # fmt: skip
    assert a.as_run["polished"] and b.as_run["start"] == "design"
    np.testing.assert_array_equal(np.asarray(a.K, float), np.asarray(b.K, float).ravel())
    assert a.as_run["after"] == b.as_run["after"]
    a = synthesize(lcc.h2_problem(string, "structured", weights=WEIGHTS, semantics="replace",
                                  as_run=ar))  # fmt: skip
    b = synthesize(lcc.h2_problem(platoon, "structured", weights=WEIGHTS, semantics="replace",
                                  as_run=ar))  # fmt: skip
    assert a.as_run["before"] == b.as_run["before"]  # the same start, not string stable
    assert not a.as_run["string_stable"] and any("NOT string stable" in n for n in a.notes)
    assert b.as_run["start"] == "fallback" and b.as_run["string_stable"]


@pytest.mark.parametrize(("kind", "as_run", "extra", "field", "words"), [
    ("ring", True, {}, "synthesis.as_run", "kind = 'ring'"),
    ("platoon", {"equilibrium": "estimated"}, {}, "synthesis.as_run.equilibrium",
     "no per-CAV equilibrium estimator"),
    ("platoon", {"weight": 1.0}, {}, "synthesis.as_run.weight", "must be 0 on a platoon"),
    ("platoon", True, {"robust": {"samples": 2, "alpha": [0.5, 0.7]}}, "synthesis.as_run",
     "[synthesis.robust]"),
    ("platoon", True, {"cav_lag": 0.3}, "synthesis.cav_lag", "no actuator lag"),
    ("platoon", True, {}, "synthesis.as_run", "'structured' or 'string_stable'"),
])  # fmt: skip
def test_refusals_name_the_field(kind, as_run, extra, field, words):
    system = (lcc.system(size=4, cavs=[1, 3], v_star=15.0) if kind == "platoon" else
              lcc.system("ring", size=4, cavs=[1, 3], v_star=15.0))  # fmt: skip
    design = "full_state" if words.startswith("'structured'") else "structured"
    weights = {"head": 0.0} if kind == "ring" else {}
    with pytest.raises(ConfigError) as err:
        lcc.h2_problem(system, design=design, weights=weights, as_run=as_run, **extra)
    assert err.value.field == field
    assert words in err.value.message


def test_the_spec_round_trips_its_as_run_table():
    spec = lcc.h2_problem(_system(), design="structured", weights=WEIGHTS, patterns=PATTERNS,
                          as_run=AS_RUN)  # fmt: skip
    again = spec_from_problem(Problem(Path("p.toml"), tomllib.loads(spec.to_toml())))
    assert again.as_run == spec.as_run and again.as_run.sample_time == T


@pytest.mark.slow  # the design's path: test_as_run_design_of_a_two_cav_platoon_is_string_...
def test_cli_reports_the_as_run_block(tmp_path):
    weights = "".join(f"{k} = {v}\n" for k, v in WEIGHTS.items())
    problem = tmp_path / "p.toml"
    problem.write_text(f'name = "p"\n{PAPER_HDV}[system]\nkind = "platoon"\nsize = 4\n'
                       'cavs = [2, 4]\nv_star = 15.0\n[synthesis]\ndesign = "structured"\n'
                       'semantics = "replace"\n[synthesis.patterns]\nu_2 = [1, 2, 3]\n'
                       f"[synthesis.weights]\n{weights}[synthesis.as_run]\nsample_time = 0.1\n"
                       "latency = 0.2\n")  # fmt: skip
    proc = run_cli(["synthesize", "--no-record", problem, "--json"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["cavs"] == [2, 4] and doc["as_run"]["string_stable"] is True
    assert doc["as_run"]["before"]["verdict"] == "string_unstable"
    assert doc["as_run"]["after"]["verdict"] == "string_stable"


def test_cli_refuses_the_as_run_design_of_a_ring(tmp_path):
    ring = tmp_path / "r.toml"
    ring.write_text(f'name = "r"\n{PAPER_HDV}[system]\nkind = "ring"\nsize = 4\ncavs = [1, 3]\n'
                    'v_star = 15.0\n[synthesis]\ndesign = "structured"\nas_run = true\n')
    proc = run_cli(["synthesize", "--no-record", ring], cwd=tmp_path)
    assert proc.returncode == 2
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and "synthesis.as_run" in err[0] and "kind = 'ring'" in err[0]
    assert not proc.stdout
