"""Multi-input H2 synthesis for platoons and the ring road against independent truth:
Riccati = the multi-input optimum (a Gramian by scipy, python-control's H2 norm), the ring's
reduced H2 = the full-state H2 with the conserved mode shifted away (any basis of the
hyperplane), hand-written communication patterns, patterns kept exactly, the single-CAV
design reproduced, the robust design on every member, named errors and the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla

from lcc_synth.cli.main import main
from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import model_from_hdv
from lcc_synth.models.platoon import Platoon, platoon_model
from lcc_synth.problem import Problem
from lcc_synth.synthesis.config import comm_range_pattern, robust_members, spec_from_problem
from lcc_synth.synthesis.design import synthesize
from lcc_synth.synthesis.gains_file import read_gains
from lcc_synth.synthesis.h2 import (
    Weights,
    h2_norm,
    make_plant,
    make_platoon_plant,
    pattern_rows,
    platoon_cost,
    platoon_gradient,
    platoon_h2,
    platoon_hessian,
    platoon_riccati,
    riccati_gain,
)
from lcc_synth.synthesis.structured import structured_h2

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ROOT / "problems"

DEEPLCC = {  # the DeeP-LCC paper's platoon: positions 1..8, CAVs 3 and 6 (nominal there)
    "alpha": [0.45, 0.75, 0.6, 0.70, 0.50, 0.6, 0.40, 0.80],
    "beta": [0.60, 0.95, 0.9, 0.95, 0.75, 0.9, 0.80, 1.00],
    "s_go": [38.0, 31.0, 35.0, 33.0, 37.0, 35.0, 39.0, 34.0],
}
RING_W = Weights(q_s=0.03, q_v=0.15, r=1.0, accel=1.0)


def deeplcc_model():
    hdv = tuple(OVM(alpha=a, beta=b, s_go=g) for a, b, g in zip(*DEEPLCC.values(), strict=True))
    return platoon_model(Platoon(hdv, (3, 6), 15.0), warn=False)


def ring_model(N=12, cavs=None):
    return platoon_model(Platoon((OVM(),) * N, cavs or (N,), 15.0, ring=True), warn=False)


def lyap_h2(Acl, Bw, Cz):
    """Independent H2: controllability Gramian by scipy's own Lyapunov solver."""
    L = sla.solve_continuous_lyapunov(Acl, -Bw @ Bw.T)
    return float(np.sqrt(np.trace(Cz @ L @ Cz.T)))


def perf_output(plant, K, V=None):
    V = np.eye(plant.nx) if V is None else V
    Qh = sla.sqrtm(plant.Q).real
    return np.vstack([Qh @ V, np.sqrt(plant.r) * K @ V])


# --------------------------------------------------------------------------------------------
# Full information: the multi-input H2 optimum is Riccati's
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("semantics", ["replace", "added"])
def test_full_information_multi_input_h2_is_the_riccati_optimum(semantics):
    import control as ct

    plant = make_platoon_plant(deeplcc_model(), semantics, Weights(q_s=0.5, head=1.0))
    K, J, _ = platoon_riccati(plant)
    assert K.shape == (2, 16)
    Acl = plant.A + plant.B @ K
    Cz = perf_output(plant, K)
    h_scipy = lyap_h2(Acl, plant.Bw, Cz)
    h_ct = ct.norm(ct.ss(Acl, plant.Bw, Cz, np.zeros((Cz.shape[0], plant.Bw.shape[1]))), 2)
    assert np.sqrt(J) == pytest.approx(h_scipy, rel=1e-9)
    assert h_ct == pytest.approx(h_scipy, rel=1e-7)
    assert platoon_h2(plant, K) == pytest.approx(h_scipy, rel=1e-10)
    # optimal: the gradient vanishes and every perturbation costs more
    assert np.abs(platoon_gradient(plant, platoon_cost(plant, K))).max() < 1e-8
    rng = np.random.default_rng(1)
    for _ in range(5):
        D = rng.normal(size=K.shape) * 1e-2
        assert platoon_h2(plant, K + D) > np.sqrt(J)


def test_gradient_and_hessian_match_central_differences():
    plant = make_platoon_plant(deeplcc_model(), "replace", Weights(q_s=0.5, head=1.0))
    mask = pattern_rows(plant, {3: (2, 3, 4), 6: (5, 6, 7)})
    K = np.where(mask, platoon_riccati(plant)[0], 0.0)
    ev = platoon_cost(plant, K)
    free = np.flatnonzero(mask.ravel())
    G, H = platoon_gradient(plant, ev).ravel()[free], platoon_hessian(plant, ev, free)
    h = 1e-5
    for c, f in enumerate(free[::3]):
        E = np.zeros(K.size)
        E[f] = h
        E = E.reshape(K.shape)
        jp, jm = platoon_cost(plant, K + E), platoon_cost(plant, K - E)
        assert (jp.J - jm.J) / (2 * h) == pytest.approx(G[3 * c], rel=1e-6, abs=1e-9)
        dG = (platoon_gradient(plant, jp) - platoon_gradient(plant, jm)).ravel()[free] / (2 * h)
        assert np.allclose(dG, H[:, 3 * c], rtol=1e-5, atol=1e-7 * np.abs(H).max())


# --------------------------------------------------------------------------------------------
# The ring: the invariant subspace, the basis, the conserved direction
# --------------------------------------------------------------------------------------------


def test_ring_h2_on_the_invariant_subspace_is_basis_free_and_the_full_state_value():
    M = ring_model(12, (4, 12))
    plant = make_platoon_plant(M, "replace", RING_W)
    K = np.where(pattern_rows(plant, comm_range_pattern(M.platoon, 2)),
                 platoon_riccati(plant)[0], 0.0)  # fmt: skip
    h = platoon_h2(plant, K)
    assert np.isfinite(h)
    # a random orthogonal change of basis of the hyperplane: the same value
    Qr, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(23, 23)))
    V2 = plant.V @ Qr
    assert platoon_h2(plant.with_basis(V2), K) == pytest.approx(h, rel=1e-11)
    # second method, full state: shift the conserved eigenvalue 0 to -mu along c (the
    # hyperplane stays invariant, the trajectories from w are unchanged), scipy's Gramian
    c = M.conserved[:, None]
    Acl = plant.A + plant.B @ K
    assert abs(np.linalg.eigvals(Acl).real).min() < 1e-12  # the conserved mode itself
    Cz = perf_output(plant, K)
    for mu in (0.5, 3.0):
        assert lyap_h2(Acl - mu * c @ c.T, plant.Bw, Cz) == pytest.approx(h, rel=1e-9)


def test_ring_gain_is_defined_modulo_the_conserved_direction():
    M = ring_model(10)
    plant = make_platoon_plant(M, "replace", RING_W)
    K, J, _ = platoon_riccati(plant)
    shifted = K + 0.37 * M.conserved[None, :]
    assert platoon_cost(plant, shifted).J == pytest.approx(J, rel=1e-12)
    assert np.abs(plant.closed_loop(shifted) - plant.closed_loop(K)).max() < 1e-14
    assert abs(K @ M.conserved).max() < 1e-12  # the representative without a c component


def test_ring_is_never_unstabilisable_for_the_conserved_mode():
    spec = spec_from_problem(Problem(PROBLEMS / "ring_n20_full.toml", _toml("ring_n20_full")))
    rep = synthesize(spec)
    assert rep.check.stable and rep.check.max_real_eig < 0
    assert abs(rep.check.max_real_eig_full) < 1e-12  # the full state keeps the mode at 0
    assert "modulo c" in " ".join(rep.notes) and rep.check.conserved_mode.startswith("total")


# --------------------------------------------------------------------------------------------
# Patterns
# --------------------------------------------------------------------------------------------


def test_comm_range_pattern_is_the_hand_written_list():
    ring = Platoon((OVM(),) * 6, (1, 4), 15.0, ring=True)
    assert comm_range_pattern(ring, 2) == {1: (1, 2, 3, 5, 6), 4: (2, 3, 4, 5, 6)}
    assert comm_range_pattern(ring, 0) == {1: (1,), 4: (4,)}  # decentralised
    assert comm_range_pattern(ring, 3) == {1: (1, 2, 3, 4, 5, 6), 4: (1, 2, 3, 4, 5, 6)}
    open_ = Platoon((OVM(),) * 6, (2, 6), 15.0)
    assert comm_range_pattern(open_, 2) == {2: (1, 2, 3, 4), 6: (4, 5, 6)}
    with pytest.raises(ConfigError) as e:
        comm_range_pattern(open_, -1)
    assert e.value.field == "synthesis.comm_range"


def test_every_per_cav_pattern_is_respected_exactly():
    text = _deeplcc_toml('[synthesis.patterns]\nu_3 = [2, 4]\nu_6 = [5, 7, 8]\n')
    spec = spec_from_problem(Problem(Path("p.toml"), _parse(text)))
    rep = synthesize(spec)
    K = np.array(rep.K)
    allowed = {0: {2, 3, 4}, 1: {5, 6, 7, 8}}
    for k, heard in allowed.items():
        for j, nm in enumerate(rep.state_names):
            if int(nm.split("_")[1]) not in heard:
                assert K[k, j] == 0.0  # exactly zero, not small
    assert all(np.count_nonzero(K[k]) == 2 * len(h) for k, h in allowed.items())
    assert rep.patterns == {"u_3": [2, 3, 4], "u_6": [5, 6, 7, 8]}
    stages = {s["stage"].split()[0]: s["h2"] for s in rep.stages}
    assert stages["riccati"] <= stages["polish"] <= stages["start"]
    assert rep.check.h2 == pytest.approx(stages["polish"], rel=1e-12)


def test_decentralised_two_cav_ring_is_stable_and_between_the_bounds():
    M = ring_model(10, (5, 10))
    plant = make_platoon_plant(M, "replace", RING_W)
    from lcc_synth.synthesis.structured import descend, h2_objective, initial_gain

    mask = pattern_rows(plant, comm_range_pattern(M.platoon, 1))
    K0, _ = initial_gain(plant, mask)
    res = descend(h2_objective(plant), K0, mask)
    assert res.converged and np.all(res.K[~mask] == 0.0)
    J_ric = platoon_riccati(plant)[1]
    assert J_ric <= res.f <= platoon_cost(plant, K0).J
    assert np.max(np.linalg.eigvals(plant.closed_loop(res.K)).real) < 0


def test_penalty_continuation_stabilises_where_the_truncated_riccati_gain_does_not():
    from lcc_synth.synthesis.structured import descend, h2_objective, initial_gain

    alpha = [0.87, 0.9, 1.15, 0.78, 0.61, 1.0, 0.41]
    beta = [0.38, 0.62, 0.89, 0.73, 0.31, 0.85, 0.24]
    hdv = tuple(OVM(alpha=a, beta=b) for a, b in zip(alpha, beta, strict=True))
    M = platoon_model(Platoon(hdv, (3,), 15.0, ring=True), warn=False)
    plant = make_platoon_plant(M, "added", Weights(q_s=0.027, q_v=0.011, r=7.266))
    mask = pattern_rows(plant, comm_range_pattern(M.platoon, 1))
    K_ric = platoon_riccati(plant)[0]
    V = plant.V
    c, off = M.conserved, ~mask[0]
    shift = -(c[off] @ K_ric[0, off]) / (c[off] @ c[off])  # least dropped part modulo c
    Kt = np.where(mask, K_ric + shift * c, 0.0)
    assert np.abs(Kt[0, off]).max() == 0 and np.abs((K_ric + shift * c)[0, off]).max() > 0.1
    assert np.max(np.linalg.eigvals(V.T @ (plant.A + plant.B @ Kt) @ V).real) > 0
    K0, how = initial_gain(plant, mask, K_ric)
    assert how == "penalty_continuation" and np.all(K0[~mask] == 0.0)
    assert np.max(np.linalg.eigvals(V.T @ (plant.A + plant.B @ K0) @ V).real) < 0
    res = descend(h2_objective(plant), K0, mask)
    assert res.converged and res.f <= platoon_cost(plant, K0).J and np.all(res.K[~mask] == 0)


def test_bfgs_reaches_the_newton_optimum(monkeypatch):
    import lcc_synth.synthesis.structured as pp

    plant = make_platoon_plant(deeplcc_model(), "replace", Weights(q_s=0.5, head=1.0))
    mask = pattern_rows(plant, {3: (2, 3, 4), 6: (5, 6, 7)})
    K0, _ = pp.initial_gain(plant, mask)
    newton = pp.descend(pp.h2_objective(plant), K0, mask, tol=1e-9)
    monkeypatch.setattr(pp, "DESCENT_NEWTON_MAX_FREE", 0)
    bfgs = pp.descend(pp.h2_objective(plant), K0, mask, tol=1e-9, max_iter=2000)
    assert newton.method == "newton" and bfgs.method == "bfgs"
    assert bfgs.iterations > newton.iterations
    assert np.sqrt(bfgs.f) == pytest.approx(np.sqrt(newton.f), rel=1e-9)
    assert np.abs(bfgs.K - newton.K).max() < 1e-4 * np.abs(newton.K).max()


def test_ring_is_stabilisable_on_the_invariant_subspace_only():
    from lcc_synth.analysis.staircase import uncontrollable_modes
    from lcc_synth.synthesis.h2 import check_stabilisable

    plant = make_platoon_plant(ring_model(8), "replace", RING_W)
    full = uncontrollable_modes(plant.A, plant.B)
    assert len(full) >= 1 and min(abs(lam) for lam in full) < 1e-9  # the conserved mode
    assert all(lam.real < -1e-9 for lam in uncontrollable_modes(plant.Ar, plant.Br))
    check_stabilisable(plant)  # no error: the conserved mode is not in the plant


# --------------------------------------------------------------------------------------------
# One CAV: the platoon code reproduces the single-CAV design
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("semantics", ["added", "replace"])
def test_one_cav_platoon_matches_the_single_cav_lcc_design(semantics):
    m, n = 2, 3
    w = Weights(q_s=0.5, q_v=1.0, q_s0=2.0, q_a=0.3, r=0.7, head=1.0, accel=0.8)
    hdv = OVM()
    lcc = make_plant(model_from_hdv("lcc", m, n, hdv, 15.0, warn=False), semantics, w)
    P = platoon_model(Platoon((hdv,) * (m + n + 1), (m + 1,), 15.0), warn=False)
    plant = make_platoon_plant(P, semantics, w)
    for a, b in ((plant.A, lcc.A), (plant.B, lcc.B), (plant.Bw, lcc.Bw), (plant.Q, lcc.Q)):
        assert np.array_equal(a, b)
    g_ric, _ = riccati_gain(lcc)
    assert np.sqrt(platoon_riccati(plant)[1]) == pytest.approx(h2_norm(lcc, g_ric), rel=1e-9)
    res = structured_h2(lcc, [-1, 1], "direct", tol=1e-9)
    t = _lcc_toml(m, n, semantics, w, "[synthesis.patterns]\nu_3 = [2, 4]\n")
    rep = synthesize(spec_from_problem(Problem(Path("p.toml"), _parse(t))))
    assert rep.check.h2 == pytest.approx(res.h2, rel=1e-9)


def test_sparsity_range_front_per_cav():
    from lcc_synth.synthesis.sparsity import range_pareto

    M = ring_model(10)
    plant = make_platoon_plant(M, "replace", RING_W)
    h_star = np.sqrt(platoon_riccati(plant)[1])
    points, K, chosen = range_pareto(plant, h_star, max_loss=0.003)
    assert [p["ranges"]["u_10"] for p in points] == [0, 1, 2, 3, 4, 5]
    h = [p["h2"] for p in points]
    assert all(a >= b for a, b in zip(h, h[1:], strict=False))  # nested patterns
    assert h[-1] == pytest.approx(h_star, rel=1e-9)  # every vehicle heard: the optimum
    for p in points[1:4]:  # one CAV: each point is the structured design of its range
        R = p["ranges"]["u_10"]
        text = (PROBLEMS / "ring_n20_cr5.toml").read_text().replace("size = 20", "size = 10")
        text = text.replace("cavs = [20]", "cavs = [10]").replace("comm_range = 5",
                                                                     f"comm_range = {R}")
        rep = synthesize(spec_from_problem(Problem(Path("r.toml"), _parse(text))))
        assert p["h2"] == pytest.approx(rep.check.h2, rel=1e-9)
    pick = next(p for p in points if p["h2"] <= 1.003 * h_star)
    assert pick["chosen"] and sum(p["chosen"] for p in points) == 1
    assert chosen == {10: tuple(sorted({(9 + d) % 10 + 1 for d in range(-pick["ranges"]["u_10"],
                                                                     pick["ranges"]["u_10"] + 1)}))}
    assert np.all(K[~pattern_rows(plant, chosen)] == 0.0)


# --------------------------------------------------------------------------------------------
# Robust multi-model design
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("objective", "t"), [("mean", 0.0), ("worst", 0.05)])
def test_robust_objective_derivatives_match_central_differences(objective, t):
    from lcc_synth.synthesis.structured import robust_objective

    rng = np.random.default_rng(0)
    plants = []
    for _ in range(4):
        hdv = tuple(OVM(alpha=a, beta=b) for a, b in rng.uniform(0.5, 0.9, (8, 2)))
        M = platoon_model(Platoon(hdv, (3, 6), 15.0), warn=False)
        plants.append(make_platoon_plant(M, "replace", Weights(head=1.0)))
    mask = pattern_rows(plants[0], {3: (2, 3, 4), 6: (5, 6, 7)})
    K = np.where(mask, platoon_riccati(plants[0])[0], 0.0)
    free = np.flatnonzero(mask.ravel())
    fun = robust_objective(plants, objective, t)
    f, g, hess = fun(K, 2)
    H = hess(free)
    d, e = rng.normal(size=free.size), 1e-6
    Kp, Km = K.copy(), K.copy()
    Kp.ravel()[free] += e * d
    Km.ravel()[free] -= e * d
    (fp, gp, _), (fm, gm, _) = fun(Kp, 1), fun(Km, 1)
    assert (fp - fm) / (2 * e) == pytest.approx(g.ravel()[free] @ d, rel=1e-6)
    assert np.abs((gp - gm).ravel()[free] / (2 * e) - H @ d).max() < 1e-7 * np.abs(H @ d).max()
    h = [np.sqrt(platoon_cost(p, K).J) for p in plants]  # the value itself, independently
    expect = np.mean(h) if objective == "mean" else t * np.log(np.mean(np.exp(np.array(h) / t)))
    assert f == pytest.approx(expect, rel=1e-12)


@pytest.mark.parametrize("objective", ["mean", "worst"])
def test_robust_gain_is_stable_on_every_member_and_beats_the_nominal_on_its_objective(
    objective,
):
    robust = (f'[synthesis.robust]\nsamples = 6\nseed = 2\nobjective = "{objective}"\n'
              "alpha = [0.4, 0.8]\nbeta = [0.7, 1.1]\ns_go = [31.0, 39.0]\n")  # fmt: skip
    text = _deeplcc_toml("", comm_range=2) + robust
    spec = spec_from_problem(Problem(Path("p.toml"), _parse(text)))
    rep = synthesize(spec)
    K = np.array(rep.K)
    nominal = synthesize(spec_from_problem(
        Problem(Path("p.toml"), _parse(_deeplcc_toml("", comm_range=2)))))  # fmt: skip
    Kn = np.array(nominal.K)
    members = robust_members(spec.system, spec.robust)
    assert len(members) == 6
    h_rob, h_nom = [], []
    for p in members:  # independent check: numpy eigenvalues, scipy Gramians
        mp = make_platoon_plant(platoon_model(p, warn=False), "replace", spec.weights)
        for gain, out in ((K, h_rob), (Kn, h_nom)):
            Acl = mp.A + mp.B @ gain
            assert np.max(np.linalg.eigvals(Acl).real) < 0
            out.append(lyap_h2(Acl, mp.Bw, perf_output(mp, gain)))
    if objective == "mean":
        assert np.mean(h_rob) <= np.mean(h_nom)
    else:
        assert np.max(h_rob) <= np.max(h_nom)
    r = rep.robust["robust_design"]
    assert r["n_stable"] == 6 and r["mean_h2"] == pytest.approx(np.mean(h_rob), rel=1e-8)
    assert rep.robust["nominal_design"]["mean_h2"] == pytest.approx(np.mean(h_nom), rel=1e-8)
    assert np.all(K[~pattern_rows(make_platoon_plant(deeplcc_model()), spec.patterns)] == 0.0)


def test_robust_members_draw_the_hdvs_and_keep_each_cavs_own_law():
    """Only the human drivers are uncertain: a CAV's "added" law is part of its controller,
    so every member keeps it nominal, while each HDV gets the row numpy draws for its
    position (vehicle-major, one row per vehicle of the road, the CAVs' rows discarded)."""
    robust = ('[synthesis.robust]\nsamples = 3\nseed = 5\nalpha = [0.4, 0.8]\n'
              "s_go = [31.0, 39.0]\n")  # fmt: skip
    text = _deeplcc_toml("", comm_range=1).replace(
        "[synthesis.weights]", 'semantics = "added"\n' + robust + "[synthesis.weights]")
    spec = spec_from_problem(Problem(Path("p.toml"), _parse(text)))
    assert spec.semantics == "added"
    base = spec.system.platoon
    rng = np.random.default_rng(5)
    for member in robust_members(spec.system, spec.robust):
        draw = rng.uniform([0.4, 31.0], [0.8, 39.0], size=(8, 2))
        for i, (h, h0, row) in enumerate(zip(member.hdv, base.hdv, draw, strict=True), 1):
            if i in (3, 6):
                assert h == h0  # the CAVs' own law, as their controller runs it
            else:
                assert (h.alpha, h.s_go) == (row[0], row[1])
                assert h.beta == h0.beta  # a parameter without a range stays nominal


# --------------------------------------------------------------------------------------------
# Bad input and the CLI
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("extra", "field"),
    [
        ("comm_range = -1\n", "synthesis.comm_range"),
        ("[synthesis.patterns]\nu_3 = [2, 9]\n", "synthesis.patterns.u_3"),
        ("[synthesis.patterns]\nu_5 = [4]\n", "synthesis.patterns.u_5"),
        ("[synthesis.patterns]\nu_3 = [0]\n", "synthesis.patterns.u_3.0"),
        ('pattern = [1, 2]\n', "synthesis.pattern"),
        ("band = 51\n", "synthesis.band"),
        ("[synthesis.robust]\nsamples = 3\n", "synthesis.robust"),
        ("[synthesis.robust]\nalpha = [0.9, 0.5]\n", "synthesis.robust.alpha"),
        ("[synthesis.sparsity]\nn_gamma = 4\n", "synthesis.sparsity.n_gamma"),
    ],
)
def test_bad_input_is_a_named_field_error_and_exit_2(tmp_path, extra, field, capsys):
    base = _deeplcc_toml("")
    head, _, tail = base.partition("[synthesis.weights]")
    if extra.startswith("["):
        text = base + extra
    else:
        text = head.replace('design = "structured"\n', 'design = "structured"\n' + extra) + \
            "[synthesis.weights]" + tail
    with pytest.raises(ConfigError) as e:
        spec_from_problem(Problem(tmp_path / "p.toml", _parse(text)))
    assert e.value.field == field
    p = tmp_path / "p.toml"
    p.write_text(text)
    assert main(["synthesize", "--no-record", str(p)]) == 2
    assert field in capsys.readouterr().err


def test_ring_head_disturbance_and_single_cav_keys_are_refused():
    data = _toml("ring_n20_cr5")
    data["synthesis"]["weights"]["head"] = 1.0
    with pytest.raises(ConfigError) as e:
        spec_from_problem(Problem(Path("r.toml"), data))
    assert e.value.field == "synthesis.weights.head"
    lcc = _parse('name = "l"\n[system]\nkind = "lcc"\nm = 1\nn = 1\n[synthesis]\n'
                 "comm_range = 2\n")
    with pytest.raises(ConfigError) as e:
        spec_from_problem(Problem(Path("l.toml"), lcc))
    assert e.value.field == "synthesis.comm_range"


def test_cli_json_reports_check_h2_and_writes_the_platoon_gains_file(tmp_path, capsys):
    out = tmp_path / "g.json"
    rc = main(["synthesize", "--no-record", "--no-progress", str(PROBLEMS / "ring_n20_cr5.toml"),
               "--json", "--out", str(out)])  # fmt: skip
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["ok"] and doc["check"]["stable"] and doc["patterns"] == {
        "u_20": [1, 2, 3, 4, 5, 15, 16, 17, 18, 19, 20]}
    assert doc["h2_unstructured"] < doc["check"]["h2"] < 1.01 * doc["h2_unstructured"]
    assert "invariant" in doc["check"]["subspace"] and doc["conserved"] is not None
    model = ring_model(20)
    gains, fdoc = read_gains(out, model=model)
    assert fdoc["h2_true"] == doc["check"]["h2"] and fdoc["ring"] and fdoc["cavs"] == [20]
    plant = make_platoon_plant(model, "replace", RING_W)
    assert platoon_h2(plant, gains.K) == pytest.approx(doc["check"]["h2"], rel=1e-12)


def test_platoon_spec_round_trips_through_its_toml():
    robust = '[synthesis.robust]\nsamples = 4\nobjective = "worst"\nalpha = [0.5, 0.7]\n'
    text = _deeplcc_toml("[synthesis.patterns]\nu_6 = [8]\n", comm_range=1) + robust
    spec = spec_from_problem(Problem(Path("p.toml"), _parse(text)))
    assert spec.patterns == {3: (2, 3, 4), 6: (6, 8)}  # comm_range, u_6 overridden
    back = spec_from_problem(Problem(Path("q.toml"), _parse(spec.to_toml())))
    assert back.toml_tables() == spec.toml_tables() and back.patterns == spec.patterns
    assert back.robust == spec.robust and back.weights == spec.weights
    assert [h.alpha for h in back.system.platoon.hdv] == DEEPLCC["alpha"]


def test_api_synthesize_h2_runs_a_ring_problem():
    from lcc_synth import api

    rep = api.synthesize_h2(api.load_problem(PROBLEMS / "ring_n20_full.toml").synthesis)
    plant = make_platoon_plant(ring_model(20), "replace", RING_W)
    assert rep.check.h2 == pytest.approx(np.sqrt(platoon_riccati(plant)[1]), rel=1e-12)


def test_platoon_gains_file_is_validated(tmp_path):
    from lcc_synth.models.hdv import OVM
    from lcc_synth.problem import System
    from lcc_synth.synthesis.gains_file import platoon_gains_document

    spec = spec_from_problem(Problem(Path("p.toml"), _parse(_deeplcc_toml("", comm_range=1))))
    rep = synthesize(spec)
    doc = platoon_gains_document(rep)
    assert len(doc["K"]) == 2 and set(doc["gains"]) == {"u_3", "u_6"}
    p = tmp_path / "g.json"
    p.write_text(json.dumps(doc))
    gains, _ = read_gains(p, model=deeplcc_model())
    assert np.array_equal(gains.K, np.array(rep.K)) and gains.cavs == (3, 6)
    with pytest.raises(ConfigError) as e:
        read_gains(p, system=System(kind="cf_lcc", m=0, n=2, v_star=15.0, hdv=OVM()))
    assert e.value.field == "kind" and "platoon or ring" in e.value.message  # not one CAV's
    for key, value, field in (("h2_true", None, "h2_true"), ("K", [[0.0]], "K")):
        bad = dict(doc)
        if value is None:
            del bad[key]
        else:
            bad[key] = value
        p.write_text(json.dumps(bad))
        with pytest.raises(ConfigError) as e:
            read_gains(p)
        assert e.value.field == field
    bad = json.loads(json.dumps(doc))
    bad["gains"]["u_3"]["s_3"] += 1.0  # the table disagrees with K
    p.write_text(json.dumps(bad))
    with pytest.raises(ConfigError) as e:
        read_gains(p, model=deeplcc_model())
    assert e.value.field == "gains"


# --------------------------------------------------------------------------------------------
# helpers: problem texts
# --------------------------------------------------------------------------------------------


def _parse(text: str) -> dict:
    import tomllib

    return tomllib.loads(text)


def _toml(stem: str) -> dict:
    return _parse((PROBLEMS / f"{stem}.toml").read_text())


def _deeplcc_toml(extra: str, comm_range: int | None = None) -> str:
    hv = "\n".join(f"{k} = {v}" for k, v in DEEPLCC.items())
    cr = "" if comm_range is None else f"comm_range = {comm_range}\n"
    return (f'name = "p"\n[hdv]\nmodel = "ovm"\n[system]\nkind = "platoon"\nsize = 8\n'
            f'cavs = [3, 6]\nv_star = 15.0\n[system.hdv_values]\n{hv}\n[synthesis]\n'
            f'design = "structured"\n{cr}[synthesis.weights]\nq_s = 0.5\nhead = 1.0\n{extra}')


def _lcc_toml(m: int, n: int, semantics: str, w: Weights, extra: str) -> str:
    ws = "\n".join(f"{k} = {v}" for k, v in w.as_dict().items()
                   if v is not None and k not in ("position", "q_p"))  # fmt: skip
    return (f'name = "p"\n[hdv]\nmodel = "ovm"\n[system]\nkind = "platoon"\nsize = {m + n + 1}'
            f'\ncavs = [{m + 1}]\nv_star = 15.0\n[synthesis]\ndesign = "structured"\n'
            f'semantics = "{semantics}"\n[synthesis.weights]\n{ws}\n{extra}')
