"""``[synthesis] cav_lag`` on platoons and rings: a lag state ``a_i`` per CAV in the design plant.

Independent truths: the lagged closed loop built here by hand from the model's ``A, B, H``
and the reported whole-input gain (each CAV's velocity row becomes ``dv_c/dt = a_c``, its
command feeds ``da_c/dt = (cmd_c - a_c) / tau``), with scipy's Lyapunov solver and null space
(the ring on ``c x = 0``); the head-to-tail ``Gamma`` solved per frequency from the lag-free
closed loop with the factor ``1 / (tau s + 1)`` on each CAV's velocity row; the first-order
expansion in ``tau`` of the lagged design's H2 norm; the one-CAV string ``kind = "lcc"``
(the same plant bit for bit); the nonlinear simulator with the actuator lag.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.linalg as sla
from cli_subprocess import one_line_error, run_cli

import lcc_synth as lcc
from lcc_synth.errors import ConfigError
from lcc_synth.models.linear import model_from_hdv
from lcc_synth.models.platoon import Platoon, platoon_model
from lcc_synth.synthesis.h2 import Weights, make_plant, make_platoon_plant

W = {"q_s": 0.5, "q_v": 1.0, "r": 0.7, "accel": 1.0}
#: layout -> (system, structured options)
LAYOUTS = {
    "two_cav_platoon": (lambda: lcc.system(size=6, cavs=[2, 5]), {"comm_range": 1}),
    "ring": (lambda: lcc.ring(6, cavs=[1, 4]), {"comm_range": 1}),
}
DESIGNS = {"full_state": {}, "structured": None}  # None: the layout's structured options


def _design(layout, design, tau, head=0.0):
    make, opts = LAYOUTS[layout]
    system = make()
    kw = DESIGNS[design] if DESIGNS[design] is not None else opts
    weights = {**W, "head": head}
    extra = {"cav_lag": tau} if tau else {}
    return system, lcc.synthesize_h2(system, design=design, weights=weights, **extra, **kw)


def _lagged_by_hand(model, Ku, kh, tau):
    """``(M, h)`` of the lagged closed loop ``d[x; a] = M [x; a] + h v_h`` from the model's
    matrices and the whole-input gain ``u = Ku x + kh v_h``."""
    nx = model.nx
    Acl = model.A + model.B @ Ku
    hcl = model.H.ravel() + model.B @ kh
    rows = [model.index(f"v_{c}") for c in model.cavs]
    M = np.zeros((nx + len(rows), nx + len(rows)))
    M[:nx, :nx] = Acl
    h = np.concatenate([hcl, np.zeros(len(rows))])
    for j, r in enumerate(rows):
        M[nx + j, :nx] = Acl[r] / tau  # the command the CAV asks for ...
        M[nx + j, nx + j] = -1.0 / tau  # ... reaches its acceleration through the lag
        h[nx + j] = hcl[r] / tau
        M[r] = 0.0
        M[r, nx + j] = 1.0  # dv_c/dt = a_c
        h[r] = 0.0
    return M, h


def _h2_by_hand(model, Ku, kh, tau, head):
    """Eigenvalues and the true H2 norm of the lagged loop (ring: on ``(c, 0) x = 0``)."""
    M, h = _lagged_by_hand(model, Ku, kh, tau)
    N, nx = M.shape[0], model.nx
    names = list(model.state_names)
    cols = [W["accel"] * np.eye(N)[:, j] for j, nm in enumerate(names) if nm.startswith("v_")]
    if head:
        cols.insert(0, head * h)
    Bw = np.column_stack(cols)
    q = [W["q_s"] if nm.startswith("s_") else W["q_v"] for nm in names] + [0.0] * (N - nx)
    Cz = np.vstack([np.diag(np.sqrt(q)), np.sqrt(W["r"]) * np.hstack([Ku, 0 * Ku[:, :N - nx]])])
    c = model.conserved
    V = np.eye(N) if c is None else sla.null_space(np.concatenate([c, np.zeros(N - nx)])[None])
    Mr = V.T @ M @ V
    L = sla.solve_continuous_lyapunov(Mr, -(V.T @ Bw) @ (V.T @ Bw).T)
    return np.linalg.eigvals(Mr), float(np.sqrt(np.trace(Cz @ V @ L @ V.T @ Cz.T)))


@pytest.mark.parametrize("layout", list(LAYOUTS))
@pytest.mark.parametrize("design", list(DESIGNS))
def test_the_reported_checks_are_those_of_the_lagged_loop_built_by_hand(layout, design):
    tau = 0.3
    head = 0.5 if layout == "two_cav_platoon" else 0.0
    system, rep = _design(layout, design, tau, head)
    model = system.linear_model(warn=False)
    Ku, kh = np.array(rep.input_K), np.array(rep.input_kh)
    eig, h2 = _h2_by_hand(model, Ku, kh, tau, head)
    assert rep.check.h2 == pytest.approx(h2, rel=1e-9)
    assert rep.check.max_real_eig == pytest.approx(eig.real.max(), rel=1e-9)
    assert eig.real.max() < 0
    assert any("actuator lag" in n for n in rep.notes)
    # the gain reads spacings and velocities only; the a_i are no state of the report
    assert rep.state_names == list(model.state_names) and np.shape(rep.K) == Ku.shape
    # a pattern never beats the full-information bound of a gain that feeds back the a_i
    assert rep.check.h2 >= rep.h2_unstructured * (1 - 1e-9)
    # the same gain without the lag is another loop: the lag is really in the check
    lag_free = _h2_by_hand(model, Ku, kh, 1e-9, head)[1]
    assert abs(lag_free / h2 - 1) > 1e-2
    if model.ring:
        assert "string_verdict" not in rep.check.as_dict()  # no head: no string check
        return
    # open platoon: Gamma per frequency from the lag-free loop, 1/(tau s + 1) on each CAV row
    Acl = model.A + model.B @ Ku
    hcl = model.H.ravel() + model.B @ kh
    rows = [model.index(f"v_{c}") for c in model.cavs]
    omega = np.geomspace(1e-3, 20.0, 400)
    gam = []
    for w in omega:
        s = 1j * w
        Ms = s * np.eye(model.nx) - Acl
        rhs = hcl.astype(complex)
        for r in rows:
            Ms[r] = s * np.eye(model.nx)[r] - Acl[r] / (tau * s + 1.0)
            rhs[r] = hcl[r] / (tau * s + 1.0)
        gam.append(np.linalg.solve(Ms, rhs)[model.index(f"v_{model.platoon.size}")])
    peak = float(np.abs(gam).max())
    assert rep.check.string_verdict == "string_stable" and rep.check.string_stable
    assert peak <= rep.check.gamma_peak * (1 + 1e-9) and rep.check.gamma_peak <= 1 + 1e-12


@pytest.mark.parametrize("layout", list(LAYOUTS))
@pytest.mark.parametrize("design", list(DESIGNS))
def test_a_vanishing_lag_gives_the_lag_free_design(layout, design):
    """First order in ``tau``: ``h(tau) = h(0) (1 + c tau + O(tau^2))`` (the lag multiplies the
    command by ``1 / (tau s + 1) = 1 - tau s + O(tau^2)``; the fast mode ``-1/tau`` leaves).
    So the relative excess ``d(tau) = h(tau) / h(0) - 1`` vanishes linearly: ``d(2 tau) /
    d(tau) = 2 + O(c tau)``. Measured ``c`` = 0.545 /s on both layouts (``d(1e-4)`` = 5.5e-5,
    the ratio 2 to 5e-5); the test allows ``|c| <= 10 /s`` and the ratio to 1e-2."""
    h0 = _design(layout, design, 0.0)[1].check.h2
    d1 = _design(layout, design, 1e-4)[1].check.h2 / h0 - 1
    d2 = _design(layout, design, 2e-4)[1].check.h2 / h0 - 1
    assert 0 < d1 <= 10 * 1e-4
    assert d2 / d1 == pytest.approx(2.0, abs=1e-2)


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_the_simulator_with_the_lag_settles_a_perturbation_under_the_designed_gain(layout):
    """A 1 s brake of 0.5 m/s^2 by the HDV at position 2 (the CAVs keep their lag of 0.3 s):
    after 60 s the velocity errors are below 1e-4 of their peak, and over 20-40 s their
    envelope decays at the lagged loop's slowest rate ``-max Re(eig)`` (within 25 %: the
    envelope of several modes, fitted on 10 s windows). The lag changes the run."""
    tau = 0.3
    system, rep = _design(layout, "structured", tau)
    ctrl = lcc.static_controller(system, rep.gain)
    brake = [lcc.Brake(vehicle=2, start=1.0, duration=1.0, decel=-0.5)]
    sc = lcc.scenario(system, brake, duration=60.0, cav_lag=tau, cav_aeb=False)
    r = lcc.simulate(sc, ctrl)
    dev = np.abs(r.velocity[0] - system.v_star).max(axis=1)
    assert dev.max() > 0.1 and dev[-1] < 1e-4 * dev.max()
    t = r.t

    def env(a):
        i = np.searchsorted(t, a)
        return dev[i:i + 1000].max()

    rate = np.log(env(30.0) / env(20.0)) / 10.0
    assert rate == pytest.approx(rep.check.max_real_eig, rel=0.25)
    free = lcc.simulate(lcc.scenario(system, brake, duration=60.0, cav_aeb=False), ctrl)
    assert np.abs(free.velocity - r.velocity).max() > 1e-2


@pytest.mark.parametrize("design", list(DESIGNS))
def test_a_one_cav_platoon_is_the_lcc_string_with_the_lag(design):
    """``kind = "platoon"``, ``cavs = [m + 1]`` and ``kind = "lcc"`` (m = 2, n = 3, semantics
    replace): the lagged design plants are equal bit for bit, and both designs (the platoon's
    start and Newton polish, the string's structured "direct" design: the same truncated
    Riccati start and Newton steps on the same plant) reach the same gain; measured 5e-15
    apart, so 1e-12 on H2 and 1e-9 on the gains leave room for round-off only."""
    m, n, tau = 2, 3, 0.4
    w = Weights(q_s=0.5, q_v=1.0, r=0.7, head=0.5, accel=1.0)
    one = make_plant(model_from_hdv("lcc", m, n, lcc.OVM(), 15.0, warn=False), "replace", w,
                     tau)  # fmt: skip
    P = platoon_model(Platoon((lcc.OVM(),) * (m + n + 1), (m + 1,), 15.0), warn=False)
    pl = make_platoon_plant(P, "replace", w, tau)
    for a, b in ((pl.A, one.A), (pl.B, one.B), (pl.Bw, one.Bw), (pl.Q, one.Q)):
        assert np.array_equal(a, b)
    weights = {**W, "head": 0.5}
    kw = {"pattern": [-1, 1]} if design == "structured" else {}
    string = lcc.synthesize_h2(lcc.system("lcc", m, n), design=design, weights=weights,
                               semantics="replace", cav_lag=tau, **kw)  # fmt: skip
    kw = {"patterns": {"u_3": [2, 4]}} if design == "structured" else {}
    platoon = lcc.synthesize_h2(lcc.system(size=m + n + 1, cavs=[m + 1]), design=design,
                                weights=weights, cav_lag=tau, **kw)  # fmt: skip
    assert platoon.check.h2 == pytest.approx(string.check.h2, rel=1e-12)
    np.testing.assert_allclose(np.ravel(platoon.input_K), string.input_K, rtol=0, atol=1e-9)
    assert platoon.check.string_verdict == string.check.string_verdict == "string_stable"
    assert platoon.check.gamma_peak == pytest.approx(string.check.gamma_peak, rel=1e-9)


def test_the_robust_design_runs_on_the_lagged_members():
    """Every sampled member gets the lag: the robust gain's member H2 norms are those of each
    member's lagged loop built by hand, and it is stable on every member."""
    system = lcc.system(size=5, cavs=[2, 4])
    tau = 0.3
    rep = lcc.synthesize_h2(system, design="structured", weights=W, cav_lag=tau,
                            comm_range=1, robust={"samples": 3, "alpha": [0.5, 0.7]})
    from lcc_synth.synthesis.config import robust_members

    spec = lcc.h2_problem(system, design="structured", weights=W, cav_lag=tau, comm_range=1,
                          robust={"samples": 3, "alpha": [0.5, 0.7]})  # fmt: skip
    rows = rep.robust["robust_design"]["members"]
    assert len(rows) == 3
    for row, member in zip(rows, robust_members(spec.system, spec.robust), strict=True):
        model = platoon_model(member, warn=False)
        Ku, kh = rep.gain.input_feedback(model)
        eig, h2 = _h2_by_hand(model, Ku, kh, tau, 0.0)
        assert row["stable"] and eig.real.max() < 0
        assert row["h2"] == pytest.approx(h2, rel=1e-9)


def test_refusals_name_synthesis_cav_lag():
    with pytest.raises(ConfigError) as err:
        lcc.h2_problem(lcc.ring(6, cavs=[1, 4]), design="sparsity", cav_lag=0.3, weights=W)
    assert err.value.field == "synthesis.cav_lag" and "sparsity" in err.value.message
    with pytest.raises(ConfigError) as err:
        lcc.h2_problem(lcc.system(size=6, cavs=[2, 5]), cav_lag=-0.1, weights=W)
    assert err.value.field == "synthesis.cav_lag" and ">= 0" in err.value.message
    spec = lcc.h2_problem(lcc.system(size=6, cavs=[2, 5]), comm_range=1, cav_lag=0.3,
                          weights=W)  # fmt: skip
    assert spec.toml_tables()["synthesis"]["cav_lag"] == 0.3  # and it is written back


PROBLEM = """name = "lagged_platoon"
[system]
kind = "platoon"
size = 5
cavs = [2, 4]
v_star = 15.0
[synthesis]
design = "structured"
comm_range = 1
cav_lag = {tau}
[synthesis.weights]
q_s = 0.5
accel = 1.0
head = 0.5
"""


def test_cli_synthesizes_a_lagged_platoon_and_refuses_a_bad_lag(tmp_path):
    good = tmp_path / "lag.toml"
    good.write_text(PROBLEM.format(tau=0.3))
    r = run_cli(["synthesize", "--no-record", "--no-progress", "--json", good], tmp_path)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["check"]["stable"] and doc["check"]["string_verdict"] == "string_stable"
    assert any("actuator lag tau = 0.3 s" in n for n in doc["notes"])
    bad = tmp_path / "bad.toml"
    bad.write_text(PROBLEM.format(tau=-0.3))
    r = run_cli(["synthesize", "--no-record", "--no-progress", bad], tmp_path)
    assert r.returncode == 2 and one_line_error(r.stderr)
    assert "synthesis.cav_lag" in r.stderr
