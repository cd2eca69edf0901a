"""Structured H2: exact pattern, convex restriction (chordal = dense), polishing on the true cost,
comparison with the paper's gains; sparsity-promoting Pareto sweep."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import model_from_hdv
from lcc_synth.synthesis.design import design_gain_of
from lcc_synth.synthesis.h2 import SynthesisError, Weights, h2_cost, h2_norm, make_plant
from lcc_synth.synthesis.sparsity import sparsity_sweep
from lcc_synth.synthesis.structured import (
    convex_restriction,
    pattern_mask,
    polish,
    structured_h2,
)

HDV = OVM(alpha=0.6, beta=0.9, s_st=5.0, s_go=35.0, v_max=30.0)
PAPER_FD = {"v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}
PAPER_CF = {"s_0": 0.1, **PAPER_FD}


def plant(kind, n, weights=None, sem="replace"):
    return make_plant(model_from_hdv(kind, 0, n, HDV, 15.0), sem, weights or Weights())


def test_chordal_restriction_equals_the_dense_lmi():
    p = plant("fd_lcc", 6)
    mask = pattern_mask(p, [1, 2])
    a = convex_restriction(p, mask, chordal=True)
    b = convex_restriction(p, mask, chordal=False)
    assert a.bound == pytest.approx(b.bound, rel=1e-5)
    assert a.info["largest_cone"] < p.nx
    # the restriction's bound really bounds the true H2 norm of its gain
    assert h2_norm(p, a.g) <= a.bound * (1 + 1e-6)
    # a wider band of X_N contains the narrower one: the bound can only tighten
    bounds = [convex_restriction(p, mask, band=b).bound for b in (0, 1, 4)]
    assert bounds[0] >= bounds[1] * (1 - 1e-6) and bounds[1] >= bounds[2] * (1 - 1e-6)
    assert bounds[2] < 0.9 * bounds[0]


@pytest.mark.parametrize("kind", ["fd_lcc", "cf_lcc"])
def test_structured_gain_pattern_and_ordering(kind):
    p = plant(kind, 8, Weights(q_s=0.1, q_a=3.0))
    res = structured_h2(p, [1, 2], method="lmi")
    allowed = pattern_mask(p, [1, 2])
    veh = p.vehicle_of_state()
    assert set(veh[allowed]) == {0, 1, 2}
    # zeros are exactly zero, and the designed gain uses the CAV and vehicles 1, 2
    assert np.all(res.g[~allowed] == 0.0)
    assert np.all(res.g[allowed] != 0.0)
    gains = p.gains(res.g)
    assert set(gains.vehicles()) == {0, 1, 2}
    # true H2: polished <= convex restriction's gain, >= unstructured optimum
    assert res.h2 == pytest.approx(h2_norm(p, res.g), rel=1e-12)
    assert res.h2 <= res.h2_restriction * (1 + 1e-12)
    assert res.h2_restriction <= res.h2_lmi_bound * (1 + 1e-6)
    from lcc_synth.synthesis.h2 import riccati_gain

    assert res.h2 >= h2_norm(p, riccati_gain(p)[0]) * (1 - 1e-12)
    # polishing from the restriction's gain alone also improves on it and reaches the same cost
    pol = polish(p, res.lmi.g, allowed)
    assert pol.converged
    assert math.sqrt(pol.J) <= res.h2_restriction
    assert math.sqrt(pol.J) == pytest.approx(res.h2, rel=1e-5)
    # paper's gain on the same pattern is worse
    paper = Gains.named(PAPER_CF if kind == "cf_lcc" else PAPER_FD, "replace")
    h_paper = h2_norm(p, design_gain_of(p, paper))
    assert res.h2 < h_paper


def test_polish_gradient_is_the_true_gradient():
    """Projected gradient used by the descent vs central finite differences of J."""
    p = plant("cf_lcc", 3, Weights(head=0.5), sem="added")
    mask = pattern_mask(p, [1])
    g = np.where(mask, -0.3, 0.0)
    J, L, P = h2_cost(p, g)
    grad = (2.0 * (p.r * g.reshape(1, -1) + p.B.T @ P) @ L).ravel()
    h = 1e-6
    for j in np.flatnonzero(mask):
        e = np.zeros(p.nx)
        e[j] = h
        fd = (h2_cost(p, g + e)[0] - h2_cost(p, g - e)[0]) / (2 * h)
        assert grad[j] == pytest.approx(fd, rel=1e-5, abs=1e-8)


def test_polish_needs_a_stabilising_start():
    p = plant("fd_lcc", 3)
    with pytest.raises(SynthesisError, match="stabilising"):
        polish(p, np.zeros(p.nx), pattern_mask(p, [1]))


def test_direct_method_matches_lmi_path():
    p = plant("fd_lcc", 10, Weights(q_s=0.1, q_a=3.0))
    a = structured_h2(p, [1, 2], method="direct")
    b = structured_h2(p, [1, 2], method="lmi")
    assert a.h2 == pytest.approx(b.h2, rel=1e-6)
    assert math.isnan(a.h2_lmi_bound)


def test_sparsity_front_is_monotone_and_consistent():
    p = plant("fd_lcc", 6, Weights(q_s=0.1, q_a=3.0))
    res = sparsity_sweep(p, n_gamma=10)
    front = res.front
    counts = [q.count for q in front]
    h2s = [q.h2 for q in front]
    assert counts == sorted(counts) and len(set(counts)) == len(counts)
    assert all(b < a for a, b in zip(h2s, h2s[1:], strict=False))  # strictly better with more
    assert front[0].count == 0 and front[-1].count == 6
    assert front[-1].h2 == pytest.approx(res.h2_full, rel=1e-9)
    assert len(front) >= 3
    for q in res.points:
        mask = pattern_mask(p, q.vehicles)
        assert np.all(q.g[~mask] == 0.0)  # exact zeros on the vehicles not heard
        assert q.h2 == pytest.approx(h2_norm(p, q.g), rel=1e-12)
    # a pattern never scores worse than one of its subsets
    for a in res.points:
        for b in res.points:
            if set(a.vehicles) < set(b.vehicles):
                assert b.h2 <= a.h2 * (1 + 1e-12)
