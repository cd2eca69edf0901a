"""The CAV's own spacing weight ``q_s0``: the plant it builds, its parsing, and what it buys.

Independent truth: the steady state after a lasting head-speed change ``dv`` is computed twice,
from the closed loop (``x = -A_cl^-1 H dv``) and from the closed form of the ``Weights``
docstring (the CAV's command vanishes while every HDV sits at its equilibrium spacing change
``s_e = dv / V'(s*)``), and the HDVs' steady state from the closed loop is checked against
the OVM's own equilibrium slope.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import model_from_hdv
from lcc_synth.problem import Problem
from lcc_synth.synthesis.config import spec_from_problem
from lcc_synth.synthesis.h2 import Weights, make_plant, riccati_gain

HDV = OVM(alpha=0.6, beta=0.9, s_st=5.0, s_go=35.0, v_max=30.0)
HDV_TABLE = {"model": "ovm", "alpha": 0.6, "beta": 0.9, "s_st": 5.0, "s_go": 35.0, "v_max": 30.0}


def cf_model(n=10):
    return model_from_hdv("cf_lcc", 0, n, HDV, 15.0)


def test_default_is_q_s_and_q_s0_changes_only_the_s0_weight():
    m = cf_model(4)
    base = Weights(q_s=0.1, q_a=3.0)
    assert base.q_s0 is None and base.cav_spacing == 0.1
    p0 = make_plant(m, "replace", base)
    p_same = make_plant(m, "replace", Weights(q_s=0.1, q_a=3.0, q_s0=0.1))
    np.testing.assert_array_equal(p0.Q, p_same.Q)
    p1 = make_plant(m, "replace", Weights(q_s=0.1, q_a=3.0, q_s0=7.0))
    dQ = p1.Q - p0.Q
    i = p0.state_names.index("s_0")
    expect = np.zeros_like(dQ)
    expect[i, i] = 7.0 - 0.1
    np.testing.assert_allclose(dQ, expect, atol=1e-15)
    # general LCC: s_0 is the CAV's gap to the HDV ahead; the HDVs' spacings keep q_s
    p = make_plant(model_from_hdv("lcc", 2, 2, HDV, 15.0), "added", Weights(q_s=0.5, q_s0=4.0))
    q = dict(zip(p.state_names, p.q, strict=True))
    assert q["s_0"] == 4.0 and q["s_-1"] == q["s_1"] == q["s_2"] == 0.5


def test_fd_lcc_has_no_s0_and_ignores_q_s0():
    m = model_from_hdv("fd_lcc", 0, 3, HDV, 15.0)
    a = make_plant(m, "replace", Weights(q_s=0.3))
    b = make_plant(m, "replace", Weights(q_s=0.3, q_s0=50.0))
    np.testing.assert_array_equal(a.Q, b.Q)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), True])
def test_bad_q_s0_is_a_config_error(bad):
    with pytest.raises(ConfigError) as err:
        Weights(q_s0=bad)
    assert err.value.field == "weights.q_s0"


def _spec(weights):
    data = {
        "name": "w",
        "hdv": HDV_TABLE,
        "system": {"kind": "cf_lcc", "m": 0, "n": 4, "v_star": 15.0},
        "synthesis": {"design": "structured", "pattern": [1, 2], "weights": weights},
    }
    return spec_from_problem(Problem(Path("w.toml"), data))


def test_problem_file_key():
    assert _spec({"q_s": 0.2}).weights.q_s0 is None
    assert _spec({"q_s": 0.2, "q_s0": 5}).weights.q_s0 == 5.0
    with pytest.raises(ConfigError) as err:
        _spec({"q_s0": -2.0})
    assert err.value.field == "synthesis.weights.q_s0"
    assert "> 0" in err.value.message


def _steady_state(plant, g, dv):
    """Closed-loop steady state after a lasting head-velocity change ``dv``."""
    Acl = plant.A + plant.B @ g.reshape(1, -1)
    H = (plant.model.H + plant.model.B * plant.kh0).ravel()[plant.keep]
    return -np.linalg.solve(Acl, H * dv)


def test_head_speed_change_offset_closed_form_and_q_s0():
    dv = -10.0
    m = cf_model(10)
    vprime = m.coefficients[1].alpha1 / (m.coefficients[1].alpha2 - m.coefficients[1].alpha3)
    offsets = []
    for q_s0 in (None, 1.0, 10.0, 100.0):
        p = make_plant(m, "replace", Weights(q_s=0.1, q_v=1.0, q_a=3.0, q_s0=q_s0))
        g, _ = riccati_gain(p)
        x = _steady_state(p, g, dv)
        nm = p.state_names
        # every vehicle follows the head; every HDV sits at its equilibrium spacing change
        np.testing.assert_allclose(x[[nm.index(f"v_{i}") for i in range(11)]], dv, rtol=1e-9)
        s_e = dv / vprime
        np.testing.assert_allclose(x[[nm.index(f"s_{i}") for i in range(1, 11)]], s_e, rtol=1e-9)
        # the CAV's spacing offset: the closed form of the Weights docstring
        gs = {k: g[nm.index(k)] for k in nm}
        behind = sum(gs[f"s_{i}"] for i in range(1, 11)) * s_e
        closed = -(behind + dv * sum(gs[f"v_{i}"] for i in range(11))) / gs["s_0"]
        s0 = x[nm.index("s_0")]
        assert s0 == pytest.approx(closed, rel=1e-9)
        offsets.append(s0)
    # weighting s_0 alone stiffens the CAV's gap: the offset shrinks monotonically
    assert offsets[0] < offsets[1] < offsets[2] < offsets[3] < 0
    assert offsets[0] < 5 * s_e  # the default design would close a 20 m gap (collision course)
    assert abs(offsets[3]) < 2 * abs(s_e)
