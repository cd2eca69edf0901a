"""String-stability-aware design (bounded-real lemma + constrained polishing), verified by the
global check of lcc_synth.analysis.string_stability (both of its methods)."""

from __future__ import annotations

import numpy as np
import pytest

from lcc_synth.analysis.string_stability import string_stability
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import model_from_hdv
from lcc_synth.synthesis.design import design_gain_of
from lcc_synth.synthesis.h2 import SynthesisError, Weights, h2_norm, make_plant, riccati_gain
from lcc_synth.synthesis.string_lmi import string_aware_h2, string_lmi
from lcc_synth.synthesis.structured import pattern_mask

HDV = OVM(alpha=0.6, beta=0.9, s_st=5.0, s_go=35.0, v_max=30.0)
CASE_D = Gains.from_paper(
    {-2: 1.0, -1: 1.0, 1: -1.0, 2: -1.0}, {-2: -1.0, -1: -1.0, 1: -1.0, 2: -1.0}, "added"
)


@pytest.fixture(scope="module")
def plant():
    mdl = model_from_hdv("lcc", 2, 2, HDV, 15.0)
    return make_plant(mdl, "added", Weights(head=1.0, accel=1.0))


@pytest.fixture(scope="module")
def design(plant):
    return string_aware_h2(plant, [-2, -1, 1, 2], gamma=1.0, polish_steps=4)


def test_unconstrained_optimum_is_not_string_stable(plant):
    """The constraint matters: the H2-optimal gain has a low-frequency peak above 1."""
    g, _ = riccati_gain(plant)
    rep = string_stability(plant.model, *plant.input_feedback(g))
    assert rep.plant_stable and not rep.string_stable and rep.gamma_peak > 1.0


def test_string_aware_design_is_string_stable_by_both_global_methods(plant, design):
    K, kh = plant.input_feedback(design.g)
    for method in ("grid", "hamiltonian"):
        rep = string_stability(plant.model, K, kh, method=method)
        assert rep.plant_stable and rep.string_stable, method
        assert rep.gamma_peak <= 1.0 + 1e-12
    # the LMI's own gain too (the bounded-real certificate, checked independently)
    rep = string_stability(plant.model, *plant.input_feedback(design.lmi.g))
    assert rep.string_stable


def test_string_aware_h2_ordering(plant, design):
    h_opt = h2_norm(plant, riccati_gain(plant)[0])
    assert design.h2 == pytest.approx(h2_norm(plant, design.g), rel=1e-12)
    assert h_opt <= design.h2 <= design.h2_restriction <= design.h2_lmi_bound * (1 + 1e-6)
    # better than the paper's Case D gains (Table I), which are string stable too
    g_paper = design_gain_of(plant, CASE_D)
    assert string_stability(plant.model, *plant.input_feedback(g_paper)).string_stable
    assert design.h2 < h2_norm(plant, g_paper)


def test_infeasible_string_lmi_is_an_error(plant):
    with pytest.raises(SynthesisError, match="string-stability LMI"):
        string_lmi(plant, pattern_mask(plant, [1, 2]))


def test_gamma_below_one_is_a_config_error(plant):
    from lcc_synth.errors import ConfigError

    with pytest.raises(ConfigError, match="string.gamma"):
        string_lmi(plant, np.ones(plant.nx, bool), gamma=0.9)
