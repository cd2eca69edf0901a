"""H2 set-up, true H2 norm, Riccati vs LMI (independent methods), model particularities."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as sla

from lcc_synth.models.feedback import Gains, closed_loop, input_feedback
from lcc_synth.models.hdv import OVM, LinearCoefficients
from lcc_synth.models.linear import build_model, model_from_hdv
from lcc_synth.synthesis.h2 import (
    SynthesisError,
    Weights,
    check_stabilisable,
    h2_cost,
    h2_norm,
    make_plant,
    riccati_gain,
)
from lcc_synth.synthesis.lmi import lmi_full_state

HDV = OVM(alpha=0.6, beta=0.9, s_st=5.0, s_go=35.0, v_max=30.0)


def model(kind, m, n):
    return model_from_hdv(kind, m, n, HDV, 15.0)


def h2_by_quadrature(plant, g, T=80.0, N=16000):
    """sqrt(int_0^T ||Cz_K e^{A_K t} B_w||_F^2 dt) by the trapezoid rule on exact expm steps."""
    AK = plant.A + plant.B @ g.reshape(1, -1)
    Qk = plant.Q + plant.r * np.outer(g, g)
    Ck = sla.cholesky(Qk + 1e-300 * np.eye(plant.nx), lower=False)
    dt = T / N
    E = sla.expm(AK * dt)
    X = plant.Bw.copy()
    vals = np.empty(N + 1)
    for k in range(N + 1):
        vals[k] = np.sum((Ck @ X) ** 2)
        X = E @ X
    return math.sqrt(dt * (vals.sum() - 0.5 * (vals[0] + vals[-1])))


def test_true_h2_matches_impulse_response_quadrature():
    p = make_plant(model("cf_lcc", 0, 3), "replace", Weights(q_s=0.5, q_a=1.0, head=0.7))
    g = np.zeros(p.nx)
    g[p.state_names.index("v_0")] = -0.8
    g[p.state_names.index("s_0")] = 0.3
    assert h2_norm(p, g) == pytest.approx(h2_by_quadrature(p, g), rel=2e-4)


@pytest.mark.parametrize(
    ("kind", "m", "n", "sem"),
    [("fd_lcc", 0, 3, "replace"), ("cf_lcc", 0, 3, "added"), ("cf_lcc", 0, 3, "replace"),
     ("lcc", 2, 2, "added")],
)
def test_lmi_agrees_with_riccati(kind, m, n, sem):
    p = make_plant(model(kind, m, n), sem, Weights(head=0.5 if kind != "fd_lcc" else 0.0))
    g_ric, P = riccati_gain(p)
    res = lmi_full_state(p)
    assert res.status == "optimal"
    h_ric, h_lmi = h2_norm(p, g_ric), h2_norm(p, res.g)
    assert h_lmi == pytest.approx(h_ric, rel=1e-6)
    # the LMI bound is tight for the full-state problem (no restriction)
    assert res.bound == pytest.approx(h_ric, rel=1e-6)
    # and the optimal cost is tr(Bw' P Bw) from the CARE
    assert h_ric**2 == pytest.approx(np.trace(p.Bw.T @ P @ p.Bw), rel=1e-9)
    np.testing.assert_allclose(res.g, g_ric, atol=2e-3 * np.max(np.abs(g_ric)))


def test_riccati_gain_is_a_local_minimum_of_the_true_cost():
    p = make_plant(model("fd_lcc", 0, 4), "replace", Weights())
    g, _ = riccati_gain(p)
    J0 = h2_cost(p, g)[0]
    rng = np.random.default_rng(1)
    for _ in range(20):
        d = rng.standard_normal(p.nx)
        assert h2_cost(p, g + 1e-2 * d / np.linalg.norm(d))[0] > J0


def test_design_gain_is_the_semantic_gain_vector():
    """g designed on the plant, written as Gains, gives back the same closed loop."""
    for kind, sem in (("cf_lcc", "replace"), ("cf_lcc", "added"), ("lcc", "added")):
        mdl = model(kind, 1 if kind == "lcc" else 0, 3)
        p = make_plant(mdl, sem, Weights(head=1.0))
        g, _ = riccati_gain(p)
        K, kh = input_feedback(mdl, p.gains(g))
        Acl, Hcl = closed_loop(mdl, K, kh)
        np.testing.assert_allclose(Acl, p.A + p.B @ g.reshape(1, -1), atol=1e-12)
        np.testing.assert_allclose(Hcl.ravel(), p.Bw[:, 0] / p.weights.head, atol=1e-12)


def test_cf_lcc_replace_does_not_use_the_head_velocity():
    """'replace' for CF-LCC: ds0 = v_h - v0, dv0 = u (no alpha3 v_h term in the CAV's row)."""
    p = make_plant(model("cf_lcc", 0, 2), "replace", Weights(head=1.0))
    h = p.Bw[:, 0]
    assert h[0] == 1.0 and h[1] == 0.0


def test_fd_lcc_position_drop_and_weight():
    mdl = model("fd_lcc", 0, 3)
    pd = make_plant(mdl, "replace", Weights(position="drop"))
    assert "-p_0" not in pd.state_names and pd.nx == mdl.nx - 1
    g, _ = riccati_gain(pd)
    K, _ = pd.input_feedback(g)
    assert K[mdl.index("-p_0")] == 0.0
    # the free position integrator stays at 0 in the full model
    eig = np.linalg.eigvals(mdl.A + mdl.B @ K.reshape(1, -1))
    assert np.min(np.abs(eig)) < 1e-12
    pw = make_plant(mdl, "replace", Weights(position="weight", q_p=0.1))
    gw, _ = riccati_gain(pw)
    assert gw[pw.state_names.index("-p_0")] != 0.0
    assert np.max(np.linalg.eigvals(mdl.A + mdl.B @ gw.reshape(1, -1)).real) < 0


def test_uncontrollable_vehicles_ahead_and_unstabilisable_plant():
    stable = make_plant(model("lcc", 2, 1), "added", Weights(head=1.0))
    check_stabilisable(stable)  # ahead HDVs: uncontrollable but stable
    g, _ = riccati_gain(stable)
    assert np.any(g[:4] != 0)  # feed-forward gains on the vehicles ahead
    # an HDV ahead with alpha1 < 0 is an unstable mode the CAV cannot reach
    bad = LinearCoefficients(-0.2, 1.5, 0.9)
    ok = LinearCoefficients(0.6 * 0.94, 1.5, 0.9)
    mdl = build_model("lcc", 1, 2, [bad, ok, ok], ok)
    p = make_plant(mdl, "added", Weights(head=1.0))
    with pytest.raises(SynthesisError, match="not stabilisable"):
        riccati_gain(p)


def test_head_only_disturbance_gives_nonunique_optimum_on_fd_lcc_and_is_refused():
    from lcc_synth.errors import ConfigError

    with pytest.raises(ConfigError, match="head vehicle"):
        make_plant(model("fd_lcc", 0, 2), "replace", Weights(head=1.0, accel=0.0))


def test_bad_weights_are_config_errors():
    from lcc_synth.errors import ConfigError

    with pytest.raises(ConfigError, match="weights.r"):
        Weights(r=0.0)
    with pytest.raises(ConfigError, match="weights.position"):
        Weights(position="keep")
    with pytest.raises(ConfigError, match="both be 0"):
        Weights(head=0.0, accel=0.0)
    with pytest.raises(ConfigError, match="semantics"):
        make_plant(model("fd_lcc", 0, 2), "added")


def test_unstable_gain_has_infinite_h2():
    p = make_plant(model("fd_lcc", 0, 2), "replace", Weights())
    assert h2_norm(p, np.zeros(p.nx)) == math.inf  # v_0 integrator with no feedback
    g = Gains.named({"v_0": -0.5}, "replace")
    assert math.isfinite(h2_norm(p, g.matrix(p.model)[0][p.keep]))


def test_head_disturbance_alone_makes_the_cost_flat_in_some_gain_directions():
    """With only the head disturbance, B_w has rank one and the closed-loop Gramian is nearly
    singular: moving the optimal gain along its weakest direction barely changes the cost (the
    optimum is not unique in practice); acceleration noise on every vehicle removes this."""

    def flatness(weights):
        p = make_plant(model("lcc", 2, 3), "added", weights)
        g, _ = riccati_gain(p)
        J, L, _ = h2_cost(p, g)
        w, V = np.linalg.eigh(L)
        d = V[:, 0] / np.max(np.abs(V[:, 0]))
        return (h2_cost(p, g + 0.1 * d)[0] - J) / J

    assert 0 <= flatness(Weights(head=1.0, accel=0.0)) < 1e-7
    assert flatness(Weights(head=1.0, accel=1.0)) > 1e-4
