"""Static LCC feedback (eq. 23): both semantics, CF-LCC vs general LCC, closed loops."""

from __future__ import annotations

import numpy as np
import pytest

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains, cav_feedback, closed_loop, input_feedback
from lcc_synth.models.hdv import OVM, LinearCoefficients
from lcc_synth.models.linear import cf_lcc, fd_lcc, general_lcc

PAPER = OVM().linear_coefficients(15.0)
HET = [
    LinearCoefficients(0.7, 1.6, 0.8),
    LinearCoefficients(0.9, 1.3, 0.5),
    LinearCoefficients(1.1, 2.0, 1.2),
    LinearCoefficients(0.6, 1.45, 0.95),
]
MU = {-2: 0.3, -1: -0.4, 1: -1.0, 2: 0.25}
K = {-2: -0.2, -1: 0.6, 1: -1.5, 2: 0.1}


def test_added_semantics_reproduces_eq23_term_by_term():
    model = general_lcc(2, 2, HET)
    gains = Gains.from_paper(MU, K, "added")
    Kvec, kh = cav_feedback(model, gains)
    assert kh == 0.0  # with a vehicle ahead the HDV law uses v_-1, not the head
    rng = np.random.default_rng(0)
    c0 = model.coefficients[0]
    for _ in range(5):
        x = dict(zip(model.state_names, rng.normal(size=model.nx), strict=True))
        u = c0.alpha1 * x["s_0"] - c0.alpha2 * x["v_0"] + c0.alpha3 * x["v_-1"]
        u += sum(MU[i] * x[f"s_{i}"] + K[i] * x[f"v_{i}"] for i in (-2, -1, 1, 2))
        xv = np.array([x[nm] for nm in model.state_names])
        assert Kvec @ xv == pytest.approx(u, rel=1e-13)


def test_added_gain_on_own_states_adds_to_the_hdv_law():
    model = general_lcc(1, 1, PAPER)
    Kvec, _ = cav_feedback(model, Gains.named({"s_0": 0.5, "v_0": -0.25}, "added"))
    assert Kvec[model.index("s_0")] == pytest.approx(PAPER.alpha1 + 0.5)
    assert Kvec[model.index("v_0")] == pytest.approx(-PAPER.alpha2 - 0.25)
    assert Kvec[model.index("v_-1")] == pytest.approx(PAPER.alpha3)


def test_replace_semantics_is_the_whole_command():
    """Section V-B FD-LCC demo: u = -0.5 v0 - 0.2 s1 + 0.05 v1 - 0.1 s2 + 0.05 v2."""
    model = fd_lcc(2, PAPER)
    g = Gains.named({"v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}, "replace")
    Kvec, kh = cav_feedback(model, g)
    np.testing.assert_array_equal(Kvec, [0, -0.5, -0.2, 0.05, -0.1, 0.05])
    assert kh == 0.0
    np.testing.assert_array_equal(input_feedback(model, g)[0], Kvec)
    Acl, Hcl = closed_loop(model, Kvec, kh)
    expected = model.A.copy()
    expected[1] = Kvec
    np.testing.assert_array_equal(Acl, expected)
    assert not Hcl.any()


@pytest.mark.parametrize("semantics", ["added", "replace"])
def test_cf_lcc_input_feedback_equals_general_lcc_with_m0(semantics):
    """CF-LCC holds the CAV's HDV law in A_c; feedback on u_hat must give the same closed loop
    as the whole command on the general LCC with m = 0."""
    n = 2
    hdv = HET[2:]
    gains = Gains.from_paper({1: -1.0, 2: 0.4}, {1: -1.5, 2: 0.2}, semantics)
    cf, g = cf_lcc(n, hdv), general_lcc(0, n, hdv)
    assert cf.state_names == g.state_names
    Kc, khc = input_feedback(cf, gains)
    Kg, khg = cav_feedback(g, gains)
    A1, H1 = closed_loop(cf, Kc, khc)
    A2, H2 = closed_loop(g, Kg, khg)
    np.testing.assert_allclose(A1, A2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(H1, H2, rtol=0, atol=1e-15)
    if semantics == "added":
        # Zero feedback on u_hat leaves CF-LCC's own A_c.
        assert khc == 0.0 and khg == pytest.approx(hdv[0].alpha3)


def test_zero_added_gains_make_the_cav_an_hdv():
    """With mu = k = 0 eq. (23) is the HDV law: Gamma(s) = (phi/gamma)^(m+n+1) (Section IV)."""
    m, n = 2, 2
    model = general_lcc(m, n, PAPER)
    Acl, Hcl = closed_loop(model, *cav_feedback(model, Gains.named({}, "added")))
    a1, a2, a3 = PAPER.as_tuple()
    for w in (0.1, 0.5, 2.0):
        s = 1j * w
        x = np.linalg.solve(s * np.eye(model.nx) - Acl, Hcl[:, 0])
        assert x[-1] == pytest.approx(((a3 * s + a1) / (s * s + a2 * s + a1)) ** (m + n + 1))


def test_fd_lcc_rejects_added():
    with pytest.raises(ConfigError) as err:
        cav_feedback(fd_lcc(2, PAPER), Gains.named({"v_1": -1.0}, "added"))
    assert err.value.field == "semantics" and "replace" in err.value.message


@pytest.mark.parametrize(
    ("gains", "semantics", "field"),
    [
        ({"x_1": 1.0}, "added", "gains.x_1"),
        ({"v_1": "fast"}, "added", "gains.v_1"),
        ({"v_1": True}, "added", "gains.v_1"),
        ({"v_1": float("nan")}, "added", "gains.v_1"),
        ({"v_1": 1.0}, "sum", "semantics"),
    ],
)
def test_gain_validation_names_the_field(gains, semantics, field):
    with pytest.raises(ConfigError) as err:
        Gains.named(gains, semantics)
    assert err.value.field == field


def test_gain_on_a_missing_state_and_wrong_length():
    model = general_lcc(1, 2, PAPER)
    with pytest.raises(ConfigError) as err:
        cav_feedback(model, Gains.named({"s_5": 1.0}))
    assert err.value.field == "gains.s_5"
    with pytest.raises(ConfigError, match="gain"):
        closed_loop(model, np.zeros(3))


def test_from_paper_and_vehicles():
    g = Gains.from_paper({-1: 0.5, 2: 0.0}, {1: -1.0})
    assert g.gains == {"s_-1": 0.5, "s_2": 0.0, "v_1": -1.0}
    assert g.vehicles() == [-1, 1]


def test_closed_loop_of_several_cavs_and_of_gains_objects():
    """``closed_loop`` takes one row and one head gain per CAV (several CAVs) and is
    ``Gains.closed_loop``; one gains type gives the input feedback of every layout."""
    from lcc_synth.models.platoon import Platoon, platoon_model

    model = platoon_model(Platoon((OVM(),) * 4, (1, 3), 15.0), warn=False)
    gains = Gains.on(model, np.arange(16.0).reshape(2, 8) / 10, "added", kh=[0.5, 0.0])
    Ku, kh = gains.input_feedback(model)
    A, H = closed_loop(model, Ku, kh)
    Ag, Hg = gains.closed_loop(model)
    assert np.array_equal(A, Ag) and np.array_equal(H, Hg)
    assert np.array_equal(H[:, 0], model.H[:, 0] + model.B @ kh)  # v_h enters through the CAVs
    one = general_lcc(2, 2, HET)
    g = Gains.from_paper(MU, K, "added")
    assert all(np.array_equal(a, b) for a, b in zip(g.input_feedback(one), input_feedback(one, g),
                                                   strict=True))  # fmt: skip
    with pytest.raises(ConfigError, match="10 entries"):
        closed_loop(one, np.zeros(3))
    with pytest.raises(ConfigError, match=r"shape \(2, 8\)"):
        closed_loop(model, np.zeros((1, 8)))
    with pytest.raises(ConfigError, match="2 head-velocity"):
        closed_loop(model, np.zeros((2, 8)), [0.0, 0.0, 0.0])

