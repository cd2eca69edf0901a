"""Control energy (Section III-B) and region maps (Figs. 7-8) on every layout: a one-CAV string,
a two-CAV platoon and a ring.

Truths computed here, not by the package: the Gramian of eq. (15) by adaptive quadrature
(``scipy.integrate.quad_vec``), restricted to the ring's hyperplane ``c x = 0`` in scipy's own
orthonormal null-space basis of ``c``; Lemma 2's minimum-energy input integrated by
``solve_ivp`` to the target, with its energy by quadrature; the paper's one-CAV string is a
platoon with one CAV (the same matrices bit for bit, so the same report bit for bit); the
multiprecision Gramian as a second method on the ring. Region maps vary the paper's one-CAV
gains: a platoon or ring is refused with one error naming the field, in the API and the CLI.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
from cli_subprocess import run_cli
from gramian_reference import quad_gramian
from scipy.integrate import quad_vec, solve_ivp

from lcc_synth.analysis.energy import (
    energy_report,
    energy_reports_mp,
    min_energy,
    min_energy_input,
)
from lcc_synth.analysis.regions import region_map
from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import model_from_hdv
from lcc_synth.models.platoon import Platoon, platoon_model

HDV = OVM(alpha=0.6, beta=0.9, v_max=30.0, s_st=5.0, s_go=35.0)
T = 10.0


def _layouts():
    """One CAV behind the head with three HDVs behind it; CAVs at 1 and 3 of a platoon of 5
    (both controllable: no HDV ahead of the first CAV); the same vehicles on a ring."""
    return {
        "one_cav": model_from_hdv("cf_lcc", 0, 3, HDV, 15.0, warn=False),
        "two_cav": platoon_model(Platoon((HDV,) * 5, (1, 3), 15.0), warn=False),
        "ring": platoon_model(Platoon((HDV,) * 5, (1, 3), 15.0, ring=True), warn=False),
    }


def _kept_basis(model) -> np.ndarray:
    """Orthonormal basis of the space the dynamics keep: scipy's null space of the ring's
    conserved row (sum of the spacings), else the identity."""
    if not model.ring:
        return np.eye(model.nx)
    c = np.zeros(model.nx)
    c[0::2] = 1.0
    return sla.null_space(c[None, :])


@pytest.mark.parametrize("name", ["one_cav", "two_cav", "ring"])
def test_energy_report_on_every_layout_is_the_quadrature_gramians(name):
    model = _layouts()[name]
    V = _kept_basis(model)
    lam = np.linalg.eigvalsh(V.T @ quad_gramian(model.A, model.B, T) @ V)
    rep = energy_report(model, T)
    assert rep.n_states == V.shape[1] == model.nx - (1 if model.ring else 0)
    assert lam[0] > 1e-10 * lam[-1]  # controllable on the kept space: the check could fail
    np.testing.assert_allclose(rep.lambda_min, lam[0], rtol=1e-6)
    np.testing.assert_allclose(rep.lambda_max, lam[-1], rtol=1e-9)
    np.testing.assert_allclose(rep.trace_inv, np.sum(1.0 / lam), rtol=1e-6)


def test_the_ring_without_its_hyperplane_is_singular():
    """The full ring Gramian has the conserved total spacing in its null space: the report is
    of the hyperplane, whose eigenvalues are the full Gramian's without that zero."""
    model = _layouts()["ring"]
    W = quad_gramian(model.A, model.B, T)
    lam = np.linalg.eigvalsh(W)
    assert abs(lam[0]) < 1e-12 * lam[-1]
    np.testing.assert_allclose(energy_report(model, T).lambda_min, lam[1], rtol=1e-6)


@pytest.mark.parametrize("name", ["one_cav", "two_cav", "ring"])
def test_min_energy_input_steers_to_the_target_on_every_layout(name):
    model = _layouts()[name]
    rng = np.random.default_rng(11)
    x0 = rng.normal(size=model.nx)
    xt = rng.normal(size=model.nx)
    if model.ring:  # a reachable target keeps the total spacing of x0
        xt[0::2] += (x0[0::2].sum() - xt[0::2].sum()) / (model.nx // 2)
    u = min_energy_input(model, T, x0, xt)

    def rhs(tau, x):
        return model.A @ x + model.B @ u(tau)

    sol = solve_ivp(rhs, (0.0, T), x0, method="DOP853", rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(sol.y[:, -1], xt, atol=1e-6 * max(1.0, np.abs(xt).max()))
    energy, _ = quad_vec(lambda tau: float(u(tau) @ u(tau)), 0.0, T, epsrel=1e-10)
    np.testing.assert_allclose(energy, min_energy(model, T, x0, xt), rtol=1e-7)


def test_a_ring_target_with_another_total_spacing_is_refused():
    model = _layouts()["ring"]
    x0 = np.zeros(model.nx)
    xt = np.zeros(model.nx)
    xt[0] = 1.0  # one more metre of spacing in total: no input reaches it
    with pytest.raises(ConfigError) as err:
        min_energy(model, T, x0, xt)
    assert err.value.field == "x_target"
    assert "total spacing" in err.value.message


@pytest.mark.parametrize(("m", "n"), [(0, 3), (0, 1)])
def test_the_papers_string_energy_is_the_platoon_with_one_cav_bit_for_bit(m, n):
    lcc = model_from_hdv("lcc", m, n, HDV, 15.0, warn=False)
    one = platoon_model(Platoon((HDV,) * (m + n + 1), (m + 1,), 15.0), warn=False)
    assert np.array_equal(lcc.A, one.A) and np.array_equal(lcc.B, one.B)
    a, b = energy_report(lcc, T), energy_report(one, T)
    for key in ("n_states", "lambda_min", "lambda_max", "trace_inv", "condition", "digits"):
        assert getattr(a, key) == getattr(b, key), key
    x0, xt = np.linspace(-1.0, 1.0, lcc.nx), np.linspace(0.5, -0.5, lcc.nx)
    assert min_energy(lcc, T, x0, xt) == min_energy(one, T, x0, xt)


def test_the_rings_multiprecision_energy_is_the_float64_energy():
    model = _layouts()["ring"]
    double = energy_report(model, T)
    (mp,) = energy_reports_mp(model, [T], digits=12)
    assert mp.n_states == double.n_states == model.nx - 1
    assert mp.digits >= 12
    tol = 10.0 ** -(double.digits - 1)  # float64 keeps about `digits` digits of lambda_min
    np.testing.assert_allclose(double.lambda_min, mp.lambda_min, rtol=tol)
    np.testing.assert_allclose(double.trace_inv, mp.trace_inv, rtol=tol)
    np.testing.assert_allclose(double.lambda_max, mp.lambda_max, rtol=1e-12)


@pytest.mark.parametrize(("name", "field", "words"), [
    ("two_cav", "cav", ("[1, 3]", "None")),  # which CAV's gains vary: it must be said
    ("ring", "system.kind", ("no head vehicle",)),  # no head-to-tail Gamma at all
])  # fmt: skip
def test_region_maps_on_a_platoon_or_ring_name_what_is_missing(name, field, words):
    """Region maps exist for open platoons (tests/test_regions_platoon.py), one CAV's gains at a
    time: a platoon map that does not say which CAV is one error naming ``cav``; a ring has no
    head vehicle and no map."""
    model = _layouts()[name]
    axis = np.linspace(-1.0, 1.0, 3)
    with pytest.raises(ConfigError) as err:
        region_map(model, 2, axis, axis)
    assert err.value.field == field
    assert all(w in err.value.message for w in words), err.value.message


def test_region_map_of_the_one_cav_layout_runs():
    """The one-CAV layout is the one the maps are of: the same call gives a map (its labels
    are checked against the exact per-point decision in tests/test_regions.py)."""
    axis = np.linspace(-1.0, 1.0, 3)
    rm = region_map(_layouts()["one_cav"], 2, axis, axis)
    assert rm.labels.shape == (3, 3)


@pytest.mark.parametrize(("kind", "field"), [("platoon", "maps.a.cav"), ("ring", "system.kind")])
def test_regions_command_on_a_platoon_or_ring_file_is_one_error(tmp_path, kind, field):
    """A platoon's map that names no CAV, a ring's map: exit 2, one line naming the field."""
    problem = tmp_path / f"{kind}.toml"
    problem.write_text(
        f'name = "{kind}"\n[hdv]\nmodel = "ovm"\n[system]\nkind = "{kind}"\nsize = 5\n'
        'cavs = [1, 3]\nv_star = 15.0\n[maps.a]\nvehicle = 2\n'
    )
    out = run_cli(["regions", problem, "--no-record", "-q"], cwd=tmp_path, timeout=120)
    assert out.returncode == 2, out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and field in lines[0], out.stderr
    assert "Traceback" not in out.stderr
