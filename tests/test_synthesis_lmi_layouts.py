"""``method = "lmi"`` (and ``cross_check``) on platoons and rings, judged against independent
truth: the full-state LMI against the Riccati optimum (CARE) within ``CROSS_CHECK_TOL``, the
ring's LMI unchanged by the basis of its invariant hyperplane, the structured restriction
ordered as an upper bound must be (its bound >= its gain's Lyapunov H2 computed here with
scipy >= the polished H2 >= the full-information optimum), every row's pattern kept exactly,
the polish from the restriction's gain ending at the direct method's local minimum, a one-CAV
platoon giving the ``kind = "lcc"`` string's LMI results, and the real CLI."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from cli_subprocess import PAPER_HDV, run_cli
from test_synthesis_layouts import _lyapunov_h2, _problem, _truth

from lcc_synth.errors import ConfigError
from lcc_synth.problem import Problem
from lcc_synth.synthesis.config import spec_from_problem
from lcc_synth.synthesis.design import CROSS_CHECK_TOL, synthesize
from lcc_synth.synthesis.h2 import (
    make_platoon_plant,
    pattern_rows,
    platoon_cost,
    platoon_h2,
    platoon_riccati,
)
from lcc_synth.synthesis.lmi import lmi_full_state, restriction_start
from lcc_synth.synthesis.structured import descend, h2_objective

#: the two layouts of several inputs (nx = 12 each): a two-CAV open platoon and a ring
ROWS = ["two_cav_platoon", "ring"]


def _plant(spec):
    return make_platoon_plant(spec.system.linear_model(warn=False), spec.semantics, spec.weights)


# --------------------------------------------------------------------------------------------
# Full state: the LMI optimum is the Riccati optimum; on a ring, whatever the basis
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("layout", ROWS)
def test_full_state_lmi_is_the_riccati_optimum_on_platoon_and_ring(layout):
    spec = spec_from_problem(_problem(layout, "full_state", 'method = "lmi"'))
    assert spec.method == "lmi"
    rep = synthesize(spec)
    A, B, Q, Bw, V, _ = _truth(spec)
    K = np.asarray(rep.K, float)
    h2 = _lyapunov_h2(A, B, Q, Bw, V, K)  # scipy's Lyapunov solver on the reported gain
    assert rep.check.h2 == pytest.approx(h2, rel=1e-9)
    assert abs(h2 - rep.h2_unstructured) <= CROSS_CHECK_TOL * rep.h2_unstructured
    assert rep.solver["riccati_vs_lmi_h2_rel"] <= CROSS_CHECK_TOL
    assert rep.solver["status"] in ("optimal", "optimal_inaccurate")
    assert rep.h2_restriction == pytest.approx(h2, rel=1e-12)
    assert rep.h2_lmi_bound == pytest.approx(rep.h2_unstructured, rel=CROSS_CHECK_TOL)
    assert [s["stage"] for s in rep.stages] == ["riccati", "lmi"]
    # cross_check alone keeps the Riccati gain and reports the same LMI figures
    chk = synthesize(spec_from_problem(_problem(layout, "full_state", "cross_check = true")))
    assert chk.check.h2 == pytest.approx(rep.h2_unstructured, rel=1e-10)
    assert chk.h2_lmi_bound == pytest.approx(rep.h2_lmi_bound, rel=1e-9)
    assert set(chk.solver) == set(rep.solver)


def test_ring_lmi_does_not_depend_on_the_basis_of_the_invariant_hyperplane():
    spec = spec_from_problem(_problem("ring", "full_state"))
    plant = _plant(spec)
    U, _ = np.linalg.qr(np.random.default_rng(7).standard_normal((plant.V.shape[1],) * 2))
    other = plant.with_basis(plant.V @ U)
    a, b = lmi_full_state(plant), lmi_full_state(other)
    K_ric, J_ric, _ = platoon_riccati(plant)
    for lmi, p in ((a, plant), (b, other)):
        assert abs(platoon_h2(p, lmi.g) - math.sqrt(J_ric)) <= CROSS_CHECK_TOL * math.sqrt(J_ric)
    # the same gain rows (to the solver's accuracy: measured 4e-6 of entries up to 2), the
    # representative with no component along the conserved direction c, in either basis
    np.testing.assert_allclose(a.g, b.g, rtol=0, atol=1e-4)
    c = plant.model.conserved
    assert np.abs(a.g @ c).max() < 1e-12 and np.abs(b.g @ c).max() < 1e-12
    assert a.bound == pytest.approx(b.bound, rel=1e-7)
    np.testing.assert_allclose(a.g, K_ric, rtol=0, atol=1e-4)


# --------------------------------------------------------------------------------------------
# Structured: the convex restriction with a pattern per row starts the polish
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("layout", ROWS)
def test_structured_restriction_is_an_ordered_bound_with_every_rows_pattern(layout):
    spec = spec_from_problem(_problem(layout, "structured", 'method = "lmi"'))
    plant = _plant(spec)
    mask = pattern_rows(plant, spec.patterns)
    assert not np.array_equal(mask[0], mask[1])  # each row its own pattern
    lmi, J_restr = restriction_start(plant, mask)
    A, B, Q, Bw, V, _ = _truth(spec)
    assert platoon_cost(plant, lmi.g).stable
    h_restr = _lyapunov_h2(A, B, Q, Bw, V, lmi.g)
    assert math.sqrt(J_restr) == pytest.approx(h_restr, rel=1e-9)
    assert np.all(lmi.g[~mask] == 0.0) and np.all(np.any(lmi.g != 0.0, axis=1))

    rep = synthesize(spec)
    K = np.asarray(rep.K, float)
    h2 = _lyapunov_h2(A, B, Q, Bw, V, K)
    assert np.all(K[~mask] == 0.0)
    assert rep.h2_lmi_bound == pytest.approx(lmi.bound, rel=1e-12)
    assert rep.h2_restriction == pytest.approx(h_restr, rel=1e-9)
    # an upper bound, the gain it certifies, the polished gain, full information
    assert rep.h2_lmi_bound >= h_restr >= h2 >= rep.h2_unstructured
    assert rep.solver["n_psd_cones"] >= 1 and rep.solver["band"] == spec.band == 4

    # the polish from the restriction's own gain ends at the direct method's local minimum
    direct = synthesize(spec_from_problem(_problem(layout, "structured", 'method = "direct"')))
    res = descend(h2_objective(plant), lmi.g, mask, spec.tol, spec.max_iter)
    assert res.converged
    assert math.sqrt(res.f) == pytest.approx(direct.check.h2, rel=1e-9)
    np.testing.assert_allclose(res.K, np.asarray(direct.K), rtol=0, atol=1e-6)
    assert rep.check.h2 == pytest.approx(direct.check.h2, rel=1e-9)


# --------------------------------------------------------------------------------------------
# One CAV: the platoon's LMI results are the kind = "lcc" string's
# --------------------------------------------------------------------------------------------


def _text(system: str, synthesis: str) -> str:
    return (f'name = "one"\n{PAPER_HDV}[system]\n{system}\nv_star = 15.0\n[synthesis]\n'
            f'semantics = "replace"\nmethod = "lmi"\n{synthesis}\n[synthesis.weights]\n'
            "q_s = 0.5\nq_s0 = 2.0\nq_v = 1.0\nr = 0.7\nhead = 0.5\naccel = 1.0\n")  # fmt: skip


def _report(system: str, synthesis: str):
    text = _text(system, synthesis)
    return synthesize(spec_from_problem(Problem(Path("one.toml"), tomllib.loads(text))))


@pytest.mark.parametrize(("design", "lcc_keys", "platoon_keys"), [
    ("full_state", "", ""),
    ("structured", "pattern = [1, 2]", "[synthesis.patterns]\nu_3 = [4, 5]"),
])  # fmt: skip
def test_one_cav_platoon_lmi_equals_the_lcc_string(design, lcc_keys, platoon_keys):
    """``m = 2, n = 3``: the platoon of 6 with its CAV at position 3 is that string, bit for bit
    (``test_synthesis_layouts``); its LMI figures and gain agree to the solver's tolerance."""
    lcc = _report('kind = "lcc"\nm = 2\nn = 3', f'design = "{design}"\n{lcc_keys}')
    pl = _report('kind = "platoon"\nsize = 6\ncavs = [3]', f'design = "{design}"\n{platoon_keys}')
    assert pl.h2_lmi_bound == pytest.approx(lcc.h2_lmi_bound, rel=1e-7)
    assert pl.h2_restriction == pytest.approx(lcc.h2_restriction, rel=1e-7)
    assert pl.check.h2 == pytest.approx(lcc.check.h2, rel=1e-9)
    assert list(pl.solver) == list(lcc.solver)
    np.testing.assert_allclose(np.asarray(pl.K)[0], lcc.K, rtol=0, atol=1e-5)
    if design == "structured":
        assert pl.solver["n_psd_cones"] == lcc.solver["n_psd_cones"]
        assert pl.solver["largest_cone"] == lcc.solver["largest_cone"]


# --------------------------------------------------------------------------------------------
# Configuration and the CLI
# --------------------------------------------------------------------------------------------


def test_platoon_lmi_keys_round_trip_and_what_stays_refused():
    from dataclasses import replace

    spec = spec_from_problem(_problem("ring", "structured", 'method = "lmi"\nband = 2'))
    back = spec_from_problem(Problem(Path("b.toml"), tomllib.loads(spec.to_toml())))
    assert replace(back, source=spec.source) == spec and back.band == 2
    assert spec_from_problem(_problem("ring", "full_state")).cross_check is False  # opt-in
    with pytest.raises(ConfigError) as err:
        spec_from_problem(_problem("two_cav_platoon", "sparsity", 'method = "lmi"'))
    assert err.value.field == "synthesis.method" and "direct" in err.value.message
    for extra, field in (('method = "lmi"', "synthesis.method"),
                         ("cross_check = true", "synthesis.cross_check")):  # fmt: skip
        with pytest.raises(ConfigError) as err:  # the lag states a_i are in no pattern
            spec_from_problem(_problem("ring", "full_state", f"{extra}\ncav_lag = 0.2"))
        assert err.value.field == field and "cav_lag = 0" in err.value.message


def test_platoon_lmi_too_long_for_a_dense_lmi_names_the_size():
    text = (f'name = "long"\n{PAPER_HDV}[system]\nkind = "ring"\nsize = 101\ncavs = [1]\n'
            'v_star = 15.0\n[synthesis]\ndesign = "full_state"\nmethod = "lmi"\n')  # fmt: skip
    spec = spec_from_problem(Problem(Path("l.toml"), tomllib.loads(text)))
    with pytest.raises(ConfigError) as err:
        synthesize(spec)
    assert err.value.field == "system.size" and "size = 101" in err.value.message


def test_cli_synthesizes_a_platoon_with_method_lmi_and_reports_the_solver(tmp_path):
    p = tmp_path / "p.toml"
    p.write_text(_text('kind = "platoon"\nsize = 5\ncavs = [2, 4]',
                       'design = "structured"\ncomm_range = 1'))  # fmt: skip
    proc = run_cli(["synthesize", "p.toml", "--no-record", "--no-progress", "--json"],
                   cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    one_cav = _report('kind = "lcc"\nm = 1\nn = 2', 'design = "structured"\npattern = [1]')
    assert list(doc["solver"]) == list(one_cav.solver)  # the solver block as for one CAV
    assert doc["solver"]["status"] in ("optimal", "optimal_inaccurate")
    assert doc["h2_lmi_bound"] >= doc["h2_restriction"] >= doc["check"]["h2"]
    assert doc["check"]["h2"] >= doc["h2_unstructured"]
    assert doc["patterns"] == {"u_2": [1, 2, 3], "u_4": [3, 4, 5]}
