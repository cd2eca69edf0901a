"""HDV car-following models (Section II-A) against hand computations of eqs. (2)-(4), (8)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import (
    IDM,
    OVM,
    ControllabilityWarning,
    LinearCoefficients,
    linear_coefficients,
    model_from_dict,
)
from lcc_synth.models.hdv import numeric_linear_coefficients as numeric

PAPER = OVM(alpha=0.6, beta=0.9, s_st=5.0, s_go=35.0, v_max=30.0)


def _V_by_hand(s: float) -> float:
    """Eq. (3)-(4) with the paper's parameters, written out case by case."""
    if s <= 5.0:
        return 0.0
    if s >= 35.0:
        return 30.0
    return 15.0 * (1.0 - math.cos(math.pi * (s - 5.0) / 30.0))


@pytest.mark.parametrize(
    ("s", "ds", "v"),
    [
        (20.0, 0.0, 15.0),  # equilibrium: V(20) = 15
        (10.0, 1.5, 12.0),
        (3.0, -2.0, 4.0),  # below s_st: V = 0
        (-1.0, 0.5, 1.0),  # negative spacing (collision) still V = 0
        (50.0, 3.0, 33.0),  # above s_go: V = v_max; v above v_max is not clipped
        (35.0, -4.0, 0.0),
        (5.0, 0.0, 2.0),
    ],
)
def test_ovm_accel_matches_eq2_by_hand(s, ds, v):
    expected = 0.6 * (_V_by_hand(s) - v) + 0.9 * ds
    assert PAPER.accel(s, ds, v) == pytest.approx(expected, rel=1e-14, abs=1e-14)


def test_ovm_clipping_is_only_inside_V():
    # ds and v enter linearly however large they are.
    a1 = PAPER.accel(50.0, 10.0, 40.0)
    a2 = PAPER.accel(50.0, 20.0, 80.0)
    assert a2 - a1 == pytest.approx(0.9 * 10.0 - 0.6 * 40.0)
    # V is flat outside [s_st, s_go].
    assert PAPER.accel(100.0, 0.0, 0.0) == PAPER.accel(35.0, 0.0, 0.0) == pytest.approx(18.0)
    assert PAPER.accel(0.0, 0.0, 0.0) == PAPER.accel(5.0, 0.0, 0.0) == 0.0


def test_ovm_broadcasts_over_a_batch():
    s = np.array([[3.0, 10.0, 20.0], [35.0, 50.0, 12.5]])
    ds = np.array([0.5, -1.0, 2.0])
    v = 14.0
    out = PAPER.accel(s, ds, v)
    assert out.shape == (2, 3)
    for idx in np.ndindex(out.shape):
        assert out[idx] == pytest.approx(0.6 * (_V_by_hand(s[idx]) - v) + 0.9 * ds[idx[1]])


def test_paper_equilibrium_and_coefficients():
    """s*(15) = 20 m; alpha1 = 0.6 (30/2)(pi/30) sin(pi/2) = 0.3 pi; alpha2 = 1.5, alpha3 = 0.9."""
    assert PAPER.equilibrium_spacing(15.0) == pytest.approx(20.0, rel=1e-14)
    c = PAPER.linear_coefficients(15.0)
    assert c.alpha1 == pytest.approx(0.3 * math.pi, rel=1e-14)
    assert c.alpha2 == pytest.approx(1.5) and c.alpha3 == pytest.approx(0.9)
    assert c.controllability_margin == pytest.approx(0.3 * math.pi - 1.35 + 0.81)
    assert PAPER.accel(20.0, 0.0, 15.0) == pytest.approx(0.0, abs=1e-14)


@pytest.mark.parametrize("v_star", [2.0, 8.0, 15.0, 22.5, 29.0])
def test_ovm_numeric_coefficients_match_analytic(v_star):
    s_star = PAPER.equilibrium_spacing(v_star)
    assert PAPER.accel(s_star, 0.0, v_star) == pytest.approx(0.0, abs=1e-12)
    ana = PAPER.linear_coefficients(v_star)
    num = numeric(PAPER, v_star)
    np.testing.assert_allclose(num.as_tuple(), ana.as_tuple(), rtol=1e-7)


def _idm_derivatives_by_hand(m: IDM, v: float):
    """Closed-form partial derivatives of the IDM at (s*, 0, v*).

    F = a [1 - (v/v0)^d - (s_des/s)^2], s_des = s0 + v T - v ds / (2 sqrt(ab)):
    dF/ds  = 2 a s_des^2 / s^3
    dF/dds = a s_des v / (s^2 sqrt(ab))            (d s_des / d ds = -v / (2 sqrt(ab)))
    dF/dv  = -a d v^(d-1) / v0^d - 2 a s_des T / s^2  (at ds = 0)
    """
    s = (m.s0 + v * m.T) / math.sqrt(1.0 - (v / m.v0) ** m.delta)
    sd = m.s0 + v * m.T
    dfds = 2 * m.a * sd**2 / s**3
    dfdds = m.a * sd * v / (s**2 * math.sqrt(m.a * m.b))
    dfdv = -m.a * m.delta * v ** (m.delta - 1) / m.v0**m.delta - 2 * m.a * sd * m.T / s**2
    return s, dfds, dfdds - dfdv, dfdds


@pytest.mark.parametrize(
    ("model", "v_star"),
    [(IDM(), 15.0), (IDM(), 25.0), (IDM(v0=33.0, T=1.0, s0=3.0, a=0.8, b=2.0, delta=4.0), 10.0)],
)
def test_idm_linear_coefficients_against_closed_form(model, v_star):
    s_star, a1, a2, a3 = _idm_derivatives_by_hand(model, v_star)
    assert model.equilibrium_spacing(v_star) == pytest.approx(s_star, rel=1e-14)
    assert model.accel(s_star, 0.0, v_star) == pytest.approx(0.0, abs=1e-12)
    c = linear_coefficients(model, v_star, warn=False)
    np.testing.assert_allclose(c.as_tuple(), (a1, a2, a3), rtol=1e-6)
    assert c.alpha1 > 0 and c.alpha2 > c.alpha3 > 0


def test_idm_accel_by_hand():
    m = IDM()
    s, ds, v = 30.0, -2.0, 20.0
    s_des = 2.0 + 20.0 * 1.5 - 20.0 * (-2.0) / (2 * math.sqrt(1.5))
    expected = 1.0 * (1 - (20.0 / 30.0) ** 4 - (s_des / 30.0) ** 2)
    assert m.accel(s, ds, v) == pytest.approx(expected, rel=1e-14)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"alpha": -0.6}, "alpha"),
        ({"alpha": 0.0}, "alpha"),
        ({"beta": -0.1}, "beta"),
        ({"s_st": 40.0}, "s_st"),
        ({"s_st": 35.0}, "s_st"),
        ({"v_max": 0.0}, "v_max"),
        ({"s_go": float("nan")}, "s_go"),
    ],
)
def test_ovm_validation_names_the_field(kwargs, field):
    with pytest.raises(ConfigError) as err:
        OVM(**kwargs)
    assert err.value.field == field


@pytest.mark.parametrize("v_star", [30.0, 31.0, 0.0, -5.0])
def test_v_star_outside_the_ovm_range_is_refused(v_star):
    with pytest.raises(ConfigError) as err:
        PAPER.equilibrium_spacing(v_star)
    assert err.value.field == "v_star" and "v_max" in err.value.message


@pytest.mark.parametrize(("kwargs", "field"), [({"a": 0.0}, "a"), ({"T": -1.0}, "T")])
def test_idm_validation_names_the_field(kwargs, field):
    with pytest.raises(ConfigError) as err:
        IDM(**kwargs)
    assert err.value.field == field
    with pytest.raises(ConfigError, match="v_star"):
        IDM().equilibrium_spacing(30.0)


def test_model_from_dict_errors_name_the_dotted_field():
    assert model_from_dict({"model": "ovm", "alpha": 0.6}) == OVM()
    assert model_from_dict({"model": "idm", "T": 1.2}).T == 1.2
    cases = [
        ({"model": "gipps"}, "hdv.model"),
        ({"model": "ovm", "gamma": 1.0}, "hdv.gamma"),
        ({"model": "ovm", "alpha": "fast"}, "hdv.alpha"),
        ({"model": "ovm", "alpha": True}, "hdv.alpha"),
        ({"model": "ovm", "s_st": 40.0}, "hdv.s_st"),
        ({"model": "ovm", "beta": float("inf")}, "hdv.beta"),
    ]
    for table, field in cases:
        with pytest.raises(ConfigError) as err:
            model_from_dict(table)
        assert err.value.field == field, table


def _violating_v_star(m: OVM) -> float:
    """v* at which alpha V'(s*) = alpha2 alpha3 - alpha3^2 = alpha beta, i.e. V'(s*) = beta."""
    w = m.s_go - m.s_st
    theta = math.asin(m.beta / (m.v_max * math.pi / (2 * w)))
    return m.v_max / 2 * (1 - math.cos(theta))


def test_controllability_warning_when_eq13_is_violated():
    v_bad = _violating_v_star(PAPER)
    with pytest.warns(ControllabilityWarning, match=r"\(13\)"):
        c = linear_coefficients(PAPER, v_bad)
    assert abs(c.controllability_margin) < 1e-12
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        linear_coefficients(PAPER, 15.0)  # valid: no warning
        linear_coefficients(PAPER, v_bad, warn=False)
    with pytest.warns(ControllabilityWarning, match="alpha2"):
        LinearCoefficients(0.5, 0.8, 0.9).check()
    with pytest.warns(ControllabilityWarning, match="alpha1"):
        LinearCoefficients(-0.1, 1.5, 0.9).check()
    assert LinearCoefficients(0.54, 1.5, 0.9).problems()  # 0.54 - 1.35 + 0.81 = 0
