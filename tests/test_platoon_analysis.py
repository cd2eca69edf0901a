"""Controllability, observability and head-to-tail string stability of platoons with several
CAVs and of the ring (lcc_synth.analysis.controllability / string_stability / transfer, the
analyses of every layout), against
independent truth: exact rational Kalman ranks (fractions.Fraction Gaussian elimination on
dyadic coefficients, so the float model *is* the rational one), the theorem's condition (S)
decided in rational arithmetic, invariance under units and similarity transforms, the product
of per-vehicle transfer functions, python-control's interconnection, and the exact
low-frequency curvature identity of a cascade (a gain built to sit on the boundary)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from exact_rank import kalman_rank

from lcc_synth.analysis.controllability import (
    controllability_report,
    observability_report,
    reduce_conserved,
    segment_cancellations,
    segments,
)
from lcc_synth.analysis.staircase import kalman_decomposition
from lcc_synth.analysis.string_stability import gains_string_stability
from lcc_synth.analysis.transfer import gamma_product, gamma_state_space, local_cav_laws
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import OVM, LinearCoefficients
from lcc_synth.models.platoon import (
    HEAD,
    Platoon,
    PlatoonModel,
    chain_matrices,
    platoon_model,
)

DEEPLCC = {  # the DeeP-LCC paper's platoon (tests/test_platoon.py): CAVs 3 and 6
    "alpha": [0.45, 0.75, 0.6, 0.70, 0.50, 0.6, 0.40, 0.80],
    "beta": [0.60, 0.95, 0.9, 0.95, 0.75, 0.9, 0.80, 1.00],
    "s_go": [38.0, 31.0, 35.0, 33.0, 37.0, 35.0, 39.0, 34.0],
}

# Dyadic coefficients: exact in binary, so Fraction(float) is the rational model itself.
GEN = [LinearCoefficients(0.75, 1.5, 0.25), LinearCoefficients(1.25, 2.0, 0.5),
       LinearCoefficients(0.5, 1.25, 0.75), LinearCoefficients(1.0, 1.75, 0.375)]  # fmt: skip
#: eq. (13) violated: a1 - a2 a3 + a3^2 = 1/2 - 3/4 + 1/4 = 0 (lost mode -a1/a3 = -1)
BOUND = LinearCoefficients(0.5, 1.5, 0.5)
#: zero at -a1/a3 = -1, its own eq. (13) holds (1/2 - 1/2 + 1/4)
ZERO_AT_M1 = LinearCoefficients(0.5, 1.0, 0.5)
#: pole at -1 (gamma(-1) = 1 - 2 + 1 = 0), own eq. (13) holds (1 - 1/2 + 1/16)
POLE_AT_M1 = LinearCoefficients(1.0, 2.0, 0.25)


def _deeplcc(cavs=(3, 6), ring=False) -> PlatoonModel:
    hdv = tuple(OVM(alpha=a, beta=b, s_go=g) for a, b, g in zip(*DEEPLCC.values(), strict=True))
    return platoon_model(Platoon(hdv, cavs, 15.0, ring=ring))


def _chain(coefs, cavs, ring=False) -> PlatoonModel:
    """A platoon with the given eq. (8) coefficients per position, through chain_matrices."""
    N = len(coefs)
    platoon = Platoon((OVM(),) * N, tuple(cavs), 15.0, ring=ring)
    follows = [N - 1 if ring else HEAD] + list(range(N - 1))
    A, B, H = chain_matrices(platoon.types, coefs, follows)
    return PlatoonModel(platoon, A, B, H, tuple(coefs))


# --------------------------------------------------------------------------------------------
# Controllability against exact rational ranks and the theorem
# --------------------------------------------------------------------------------------------

CASES = {
    # name: (coefficients per position, CAVs, ring, exact rank on the analysed space)
    "two_cavs": ([GEN[0], None, GEN[1], None, GEN[2], GEN[3]], (2, 4), False, 10),
    "segment_on_eq13": ([GEN[0], None, GEN[1], None, BOUND, BOUND], (2, 4), False, 8),
    "zero_ahead_of_pole": ([GEN[0], None, ZERO_AT_M1, POLE_AT_M1, None, GEN[2]], (2, 5), False, 9),
    "pole_ahead_of_zero": ([GEN[0], None, POLE_AT_M1, ZERO_AT_M1, None, GEN[2]], (2, 5), False, 10),
    "zero_and_pole_split_by_cav": ([None, ZERO_AT_M1, None, POLE_AT_M1], (1, 3), False, 8),
    "ring_one_cav": ([GEN[0], GEN[1], GEN[2], GEN[3], None], (5,), True, 9),
    "ring_segment_on_eq13": ([BOUND, None, GEN[1], GEN[2], None, BOUND], (2, 5), True, 9),
    "ring_all_hdv": ([GEN[0], GEN[1], GEN[2], GEN[3]], (), True, 0),
}


def _coefs(spec):
    return [GEN[3] if c is None else c for c in spec]  # a CAV slot: any HDV law (unused)


@pytest.mark.parametrize("name", list(CASES))
def test_controllability_matches_exact_rational_rank_and_the_theorem(name):
    spec, cavs, ring, exact = CASES[name]
    model = _chain(_coefs(spec), cavs, ring)
    rep = controllability_report(model)
    n_an = model.nx - (1 if ring else 0)
    if ring:  # the full pair: the conserved direction is never reached
        assert kalman_rank(model.A, model.B) == exact
        Az, Bz, W = reduce_conserved(model.A, model.B, model.conserved)
        assert np.abs(model.A @ W - W @ Az).max() == 0  # exactly invariant
        assert kalman_rank(Az, Bz) == exact
    else:
        assert kalman_rank(model.A, model.B) == exact
    assert rep.n_states == n_an and rep.model_states == model.nx
    assert not rep.undecided and rep.rank == exact, rep.as_dict()
    bound = n_an if ring or not cavs else 2 * (model.platoon.size - cavs[0] + 1)
    assert rep.condition_s == (exact == bound or not cavs) == (not rep.cancellations)
    assert rep.theory_rank == (exact if rep.condition_s else None)
    assert rep.verdict == ("controllable" if exact == n_an else "uncontrollable")
    # every lost mode is stable (lambda = -a1/a3 or an HDV ahead), the conserved one excluded;
    # the all-HDV ring: stabilisable iff it is stable on its hyperplane
    V = model.invariant_basis()
    stable = bool(np.linalg.eigvals(V.T @ model.A @ V).real.max() < 0)
    assert rep.stabilizable == (bool(cavs) or stable)
    assert rep.reachable_verdict == ("controllable" if exact == rep.reachable_states
                                     else "uncontrollable")  # fmt: skip
    if ring:
        assert rep.conserved_mode == model.conserved_mode and rep.conserved_residual == 0.0


def test_eq13_segment_loses_one_mode_per_hdv_at_minus_a1_over_a3():
    spec, cavs, ring, _ = CASES["segment_on_eq13"]
    rep = controllability_report(_chain(_coefs(spec), cavs, ring))
    assert {(c.zero_vehicle, c.pole_vehicle) for c in rep.cancellations} == {(5, 5), (5, 6), (6, 6)}
    ev = np.sort_complex(rep.uncontrollable_eigenvalues)
    # vehicle 1 ahead (GEN[0]: s^2 + 1.5 s + 0.75) and the two cancelled modes at -1
    ahead = np.sort_complex(np.roots([1.0, 1.5, 0.75]))
    assert np.allclose(np.sort_complex(np.concatenate([ahead, [-1.0, -1.0]])), ev, atol=1e-7)
    assert rep.vehicles_outside == [1] and 5 in rep.vehicles_partial + rep.vehicles_outside
    # the first segment (CAV 2, HDV 3) is untouched by the second's violation
    assert {2, 3, 4} <= set(rep.vehicles_in_subspace)


def test_theorem_condition_is_decided_exactly_and_depends_on_the_order():
    zp = _chain(_coefs(CASES["zero_ahead_of_pole"][0]), (2, 5))
    pz = _chain(_coefs(CASES["pole_ahead_of_zero"][0]), (2, 5))
    assert [(c.zero_vehicle, c.pole_vehicle, c.eigenvalue) for c in segment_cancellations(zp)
            if c.exact] == [(3, 4, -1.0)]  # fmt: skip
    assert not any(c.exact for c in segment_cancellations(pz))
    assert segments(zp) == [(2, (3, 4)), (5, (6,))]
    ring = _chain(_coefs(CASES["ring_segment_on_eq13"][0]), (2, 5), ring=True)
    assert segments(ring) == [(2, (3, 4)), (5, (6, 1))]


def test_deeplcc_platoon_report():
    model = _deeplcc()
    rep = controllability_report(model)
    assert rep.verdict == "uncontrollable" and rep.rank == 12 and not rep.undecided
    assert rep.vehicles_outside == [1, 2] and rep.vehicles_in_subspace == [3, 4, 5, 6, 7, 8]
    assert rep.stabilizable and rep.condition_s and rep.theory_rank == 12
    assert rep.decision_margin > 1e3 and rep.reachable_verdict == "controllable"
    # the uncontrollable modes are exactly those of the two HDVs ahead (2x2 blocks)
    ahead = np.concatenate([np.roots([1.0, c.alpha2, c.alpha1]) for c in model.coefficients[:2]])
    assert np.allclose(np.sort_complex(ahead), np.sort_complex(rep.uncontrollable_eigenvalues))
    doc = json.loads(json.dumps(rep.as_dict()))
    assert doc["verdict"] == "uncontrollable" and doc["segments"][1] == {"cav": 6, "hdvs": [7, 8]}
    assert doc["closest_cancellation"]["exact"] is False


def _scaled(model: PlatoonModel, T: np.ndarray, Tinv: np.ndarray) -> PlatoonModel:
    return PlatoonModel(model.platoon, Tinv @ model.A @ T, Tinv @ model.B, Tinv @ model.H,
                        model.coefficients)  # fmt: skip


@pytest.mark.parametrize("ring", [False, True])
def test_verdict_does_not_depend_on_units(ring):
    """Spacings in km and velocities in km/h (x' = D x): same rank, verdict, classes."""
    model = _deeplcc((3, 6) if not ring else (8,), ring=ring)
    D = np.tile([1e-3, 3.6], model.platoon.size)
    km = _scaled(model, np.diag(1.0 / D), np.diag(D))
    a, b = controllability_report(model), controllability_report(km)
    assert (a.rank, a.rank_upper, a.verdict) == (b.rank, b.rank_upper, b.verdict)
    assert a.vehicles_in_subspace == b.vehicles_in_subspace
    assert a.vehicles_outside == b.vehicles_outside
    assert a.stabilizable == b.stabilizable
    assert b.verdict == ("controllable" if ring else "uncontrollable")


def test_verdict_survives_random_similarity_transforms():
    """Dense coordinates hide every zero: a decided rank must still be the theory's."""
    rng = np.random.default_rng(7)
    model = _deeplcc()
    ring = _deeplcc((8,), ring=True)
    decided = 0
    for _ in range(6):
        Q = np.linalg.qr(rng.standard_normal((16, 16)))[0]
        T = Q @ np.diag(rng.uniform(1.0, 10.0, 16)) @ Q.T  # cond <= 10
        Ti = np.linalg.inv(T)
        dec = kalman_decomposition(Ti @ model.A @ T, Ti @ model.B)
        assert dec.n_c == 12 or (dec.undecided and dec.n_c <= 12 <= dec.n_c_upper)
        Az, Bz, _ = reduce_conserved(Ti @ ring.A @ T, Ti @ ring.B, ring.conserved @ T)
        dz = kalman_decomposition(Az, Bz)
        assert dz.n_c == 15 or (dz.undecided and dz.n_c <= 15 <= dz.n_c_upper)
        decided += (not dec.undecided) + (not dz.undecided)
    assert decided >= 6


@pytest.mark.parametrize("N", [20, 40])
def test_ring_with_one_av_is_controllable_on_the_invariant_hyperplane(N):
    ring = platoon_model(Platoon((OVM(),) * N, (N,), 15.0, ring=True))
    rep = controllability_report(ring)
    assert rep.verdict == "controllable" and rep.controllable and rep.stabilizable
    assert rep.rank == rep.n_states == 2 * N - 1 and not rep.undecided
    assert rep.conserved_mode.startswith("total spacing") and rep.conserved_residual == 0.0
    assert rep.uncontrollable_eigenvalues.size == 0  # the conserved mode is named, not counted
    assert rep.vehicles_in_subspace == list(range(1, N + 1))
    doc = json.loads(json.dumps(rep.as_dict()))
    assert doc["stabilizable"] is True and doc["subspace"].startswith("invariant hyperplane")
    # the orthonormal (Householder) basis of the model gives the same verdict
    V = ring.invariant_basis()
    dec = kalman_decomposition(V.T @ ring.A @ V, V.T @ ring.B)
    assert dec.n_c == 2 * N - 1 and not dec.undecided
    # all HDVs: nothing is controllable, and the ring is not called stabilisable
    # all HDVs: nothing is controllable; this ring is unstable (the stop-and-go wave), so
    # not stabilisable -- because of its wave, not of the conserved mode
    all_hdv = platoon_model(Platoon((OVM(),) * N, (), 15.0, ring=True))
    hdv = controllability_report(all_hdv)
    assert hdv.rank == 0 and hdv.verdict == "uncontrollable" and hdv.theory_rank == 0
    Vh = all_hdv.invariant_basis()
    wave = np.linalg.eigvals(Vh.T @ all_hdv.A @ Vh)
    assert wave.real.max() > 1e-3 and not hdv.stabilizable
    assert hdv.uncontrollable_max_real == pytest.approx(wave.real.max(), rel=1e-6)


def test_undecided_when_a_segment_is_within_round_off_of_eq13():
    """An HDV 6e-13 from eq. (13) in the second segment: the coupling that keeps its mode is
    at the probes' noise, and the report says so instead of guessing (the full-state verdict
    stays decided: vehicle 1 ahead is never reachable)."""
    a2, a3 = 1.5, 0.9

    def report(delta):
        near = LinearCoefficients(a2 * a3 - a3 * a3 + delta, a2, a3)
        return controllability_report(_chain(_coefs([GEN[0], None, GEN[1], None, near]),
                                              (2, 4)))  # fmt: skip

    rep = report(6e-13)
    assert rep.undecided and rep.rank == 7 and rep.rank_upper == 8 == rep.reachable_states
    assert rep.reachable_verdict == "undecided" and rep.decision_margin < 1.0
    assert rep.verdict == "uncontrollable"  # 10 states, at most 8 reachable: decided
    assert rep.condition_s is True  # the float data satisfy (S), by a hair
    assert json.loads(json.dumps(rep.as_dict()))["reachable_verdict"] == "undecided"
    clear = report(1e-6)
    assert clear.reachable_verdict == "controllable" and not clear.undecided
    assert report(0.0).reachable_verdict == "uncontrollable"  # on the boundary (to round-off)


# --------------------------------------------------------------------------------------------
# Observability
# --------------------------------------------------------------------------------------------


def test_observability_exact_ranks_open_and_ring():
    model = _chain(_coefs(CASES["two_cavs"][0]), (2, 4))
    rep = observability_report(model, ["s_2", "v_2", "s_4", "v_4"])
    C = model.output_matrix(["s_2", "v_2", "s_4", "v_4"])
    assert kalman_rank(model.A.T, C.T) == 8 == rep.rank  # v_4 measured: vehicles 1..4
    assert rep.verdict == "unobservable" and rep.vehicles_outside == [5, 6]
    assert rep.vehicles_in_subspace == [1, 2, 3, 4]
    full = observability_report(model)  # default: the CAVs' own states and v_6
    assert full.outputs == ["s_2", "v_2", "s_4", "v_4", "v_6"] and full.verdict == "observable"
    ring = _chain(_coefs(CASES["ring_one_cav"][0]), (5,), ring=True)
    rr = observability_report(ring)
    Az, _, W = reduce_conserved(ring.A, ring.B, ring.conserved)
    Cz = ring.output_matrix(rr.outputs) @ W
    assert kalman_rank(Az.T, Cz.T) == rr.rank == 9 and rr.verdict == "observable"
    assert rr.n_states == 9 and rr.vehicles_in_subspace == [1, 2, 3, 4, 5]
    assert observability_report(_deeplcc()).verdict == "observable"


# --------------------------------------------------------------------------------------------
# Head-to-tail Gamma and string stability
# --------------------------------------------------------------------------------------------

OMEGA = np.logspace(-3, 2, 400)
LOCAL = {"u_3": {"s_3": 0.5, "v_3": -1.2, "v_2": 0.9}, "u_6": {"s_6": 0.4, "v_6": -1.5,
         "v_5": 1.1}}  # fmt: skip


@pytest.mark.parametrize("semantics", ["replace", "added"])
def test_gamma_state_space_equals_product_of_vehicle_transfer_functions(semantics):
    model = _deeplcc()
    table = LOCAL if semantics == "replace" else {"u_3": {"s_3": 0.2, "v_3": -0.3},
                                                  "u_6": {"v_5": 0.1}}  # fmt: skip
    K, kh = Gains.from_table(table, model, semantics).input_feedback(model)
    ss = gamma_state_space(model, K, kh, OMEGA)
    prod = gamma_product(model, K, kh, OMEGA)
    assert np.max(np.abs(ss - prod) / np.abs(prod)) < 1e-10
    # by hand for the "replace" CAVs: T_c = (k_p s + k_s) / (s^2 - k_v s + k_s)
    if semantics == "replace":
        assert local_cav_laws(model, K, kh) == {3: (0.5, -1.2, 0.9), 6: (0.4, -1.5, 1.1)}
    # all-HDV limit: "added" with zero gains is the product of the eight HDVs
    zero = Gains.zero(model, "added")
    s = 1j * OMEGA
    hdv = np.prod([(c.alpha3 * s + c.alpha1) / (s * s + c.alpha2 * s + c.alpha1)
                   for c in model.coefficients], axis=0)  # fmt: skip
    zero_gamma = gamma_state_space(model, *zero.input_feedback(model), OMEGA)
    assert np.max(np.abs(zero_gamma / hdv - 1)) < 1e-10


def test_gamma_agrees_with_python_control_for_nonlocal_gains():
    import control as ct

    model = _deeplcc()
    table = {"u_3": {"s_3": 0.5, "v_3": -1.2, "v_2": 0.9, "v_5": 0.3, "s_8": -0.1},
             "u_6": {"s_6": 0.4, "v_6": -1.5, "v_1": 0.2, "v_8": 0.15}}  # fmt: skip
    gains = Gains.from_table(table, model)
    Ku, kh = gains.input_feedback(model)
    with pytest.raises(ConfigError) as err:
        local_cav_laws(model, Ku, kh)
    assert err.value.field == "gains.u_3"
    plant = model.to_statespace()
    law = ct.ss([], [], [], np.column_stack([Ku, kh]), inputs=[*model.state_names, "v_h"],
                outputs=list(model.input_names), name="law")  # fmt: skip
    loop = ct.interconnect([plant, law], inplist=["v_h"], outlist=["v_8"])
    w = np.logspace(-2, 1, 60)
    theirs = np.array([complex(loop(1j * x)) for x in w])
    assert np.allclose(gamma_state_space(model, Ku, kh, w), theirs, rtol=1e-9, atol=0)


def test_string_verdicts_and_a_case_too_close_to_call():
    """Two identical local CAV laws whose curvatures cancel the HDVs' exactly (cascade:
    c = sum of the vehicles' own (a3^2 - a2^2 + 2 a1) / a1^2): the boundary, reported as
    such by both searches; 1e-3 on either side of it decided, on the right side."""
    model = _deeplcc()
    hdv_c = sum((c.alpha3**2 - c.alpha2**2 + 2 * c.alpha1) / c.alpha1**2
                for i, c in enumerate(model.coefficients, 1) if i not in (3, 6))  # fmt: skip
    ks = 0.5
    kv = -np.sqrt(2 * ks + hdv_c * ks * ks / 2)  # 2 (k_p^2 - k_v^2 + 2 k_s) / k_s^2 = -hdv_c
    expect = {0.0: "boundary", 1e-3: "string_unstable", -1e-3: "string_stable"}
    for dk, verdict in expect.items():
        g = Gains.from_table({f"u_{c}": {f"s_{c}": ks, f"v_{c}": kv + dk} for c in (3, 6)},
                                    model)  # fmt: skip
        for method in ("grid", "hamiltonian"):
            rep = gains_string_stability(model, g, method)
            assert rep.verdict == verdict and rep.plant_stable, (dk, method, rep)
    hdv = gains_string_stability(model, Gains.zero(model, "added"))
    assert hdv.verdict == "string_unstable" and hdv.gamma_peak > 1.2


def test_ring_has_no_head_to_tail_transfer():
    ring = _deeplcc((8,), ring=True)
    with pytest.raises(ConfigError) as err:
        gains_string_stability(ring, Gains.zero(ring, "replace"))
    assert err.value.field == "system.kind"


# --------------------------------------------------------------------------------------------
# lcc-synth analyze on kind = "platoon" / "ring"
# --------------------------------------------------------------------------------------------

PLATOON_TOML = """
[system]
kind = "platoon"
size = 8
cavs = [3, 6]

[system.hdv_values]
alpha = [0.45, 0.75, 0.6, 0.70, 0.50, 0.6, 0.40, 0.80]
beta = [0.60, 0.95, 0.9, 0.95, 0.75, 0.9, 0.80, 1.00]
s_go = [38.0, 31.0, 35.0, 33.0, 37.0, 35.0, 39.0, 34.0]

[cases.local]
semantics = "replace"
label = "local laws"

[cases.local.gains.u_3]
s_3 = 0.5
v_3 = -1.2
v_2 = 0.9

[cases.local.gains.u_6]
s_6 = 0.4
v_6 = -1.5
v_5 = 1.1

[cases.hdv]
semantics = "added"
"""

RING_TOML = """
[system]
kind = "ring"
size = 20
cavs = [20]

[cases.damp]
semantics = "added"
[cases.damp.gains.u_20]
s_20 = -0.5
v_20 = -2.0
v_19 = -0.5

[cases.as_hdv]
semantics = "added"
"""


def _analyze(tmp_path, capsys, text, *extra):
    from lcc_synth.cli.main import main

    path = tmp_path / "p.toml"
    path.write_text(text)
    code = main(["analyze", str(path), "--no-record", *extra])
    out = capsys.readouterr()
    return code, out


def test_cli_analyze_platoon_json(tmp_path, capsys):
    code, out = _analyze(tmp_path, capsys, PLATOON_TOML, "--json")
    assert code == 0
    doc = json.loads(out.out)
    ct = doc["controllability"]
    assert ct["rank"] == 12 and ct["reachable_verdict"] == "controllable"
    assert ct["vehicles_outside"] == [1, 2] and doc["system"]["cavs"] == [3, 6]
    assert doc["observability"]["verdict"] == "observable"
    model = _deeplcc()
    direct = gains_string_stability(model, Gains.from_table(LOCAL, model))
    assert doc["cases"]["local"]["verdict"] == direct.verdict == "string_unstable"
    assert doc["cases"]["local"]["gamma_peak"] == direct.gamma_peak
    assert doc["cases"]["local"]["gains"] == LOCAL
    hdv = gains_string_stability(model, Gains.zero(model, "added"))
    assert doc["cases"]["hdv"]["gamma_peak"] == hdv.gamma_peak
    code, out = _analyze(tmp_path, capsys, PLATOON_TOML)
    assert code == 0 and "reachable (first CAV and behind) 12: controllable" in out.out


def test_cli_analyze_ring_json(tmp_path, capsys):
    code, out = _analyze(tmp_path, capsys, RING_TOML, "--json")
    assert code == 0
    doc = json.loads(out.out)
    ct = doc["controllability"]
    assert ct["verdict"] == "controllable" and ct["stabilizable"] is True
    assert ct["conserved_mode"].startswith("total spacing") and ct["n_states"] == 39
    damp, as_hdv = doc["cases"]["damp"], doc["cases"]["as_hdv"]
    assert damp["plant_verdict"] == "plant_stable" and damp["verdict"] is None
    # zero added gain: the all-HDV ring, whose stop-and-go mode grows
    hdv = controllability_report(platoon_model(Platoon((OVM(),) * 20, (), 15.0, ring=True)))
    assert as_hdv["plant_verdict"] == "plant_unstable"
    assert as_hdv["max_real_eig"] == pytest.approx(hdv.uncontrollable_max_real, rel=1e-9)
    code, out = _analyze(tmp_path, capsys, RING_TOML, "--png", str(tmp_path / "g.png"))
    assert code == 2 and "--png" in out.err


@pytest.mark.parametrize(
    ("table", "field"),
    [
        ('[cases.x.gains.u_4]\ns_4 = 1.0\n', "cases.x.gains.u_4"),
        ('[cases.x.gains.u_3]\ns_9 = 1.0\n', "cases.x.gains.u_3.s_9"),
        ('[cases.x.gains.u_3]\ns_3 = "a"\n', "cases.x.gains.u_3.s_3"),
    ],
)
def test_cli_analyze_platoon_bad_gains_name_the_field(tmp_path, capsys, table, field):
    text = PLATOON_TOML.split("[cases.local]")[0] + table
    code, out = _analyze(tmp_path, capsys, text)
    assert code == 2 and field in out.err and "Traceback" not in out.err


def test_api_dispatches_platoon_models():
    import lcc_synth as lcc

    ring = platoon_model(Platoon((OVM(),) * 20, (20,), 15.0, ring=True))
    rep = lcc.controllability(ring)
    assert rep.verdict == "controllable" and rep.conserved_mode == ring.conserved_mode
    assert lcc.observability(ring).verdict == "observable"
    model = _deeplcc()
    table = {"u_3": {"s_3": 0.2, "v_3": -0.3}, "u_6": {"v_5": 0.1}}
    ours = lcc.string_stability(model, lcc.gains(table, semantics="added", model=model))
    direct = gains_string_stability(model, Gains.from_table(table, model, "added"))
    assert ours.as_dict() == direct.as_dict()


def test_seeded_sweep_numerics_equal_exact_rational_ranks():
    """60 seeded platoons and rings (3-6 vehicles, 0-3 CAVs anywhere), dyadic coefficients with
    planted eq. (13) violations and zero/pole pairs: every decided rank is the exact one, the
    theorem's (S) predicts it, and nothing here is undecided (exact data, exact structure)."""
    rng = np.random.default_rng(2026)
    pool = [*GEN, BOUND, ZERO_AT_M1, POLE_AT_M1]
    violated = cross = 0
    for trial in range(60):
        N = int(rng.integers(3, 7))
        ring = bool(trial % 3 == 0)
        ncav = int(rng.integers(0 if ring else 1, min(3, N) + 1))
        cavs = tuple(sorted(int(c) for c in rng.choice(np.arange(1, N + 1), ncav, replace=False)))
        coefs = [pool[int(rng.integers(len(pool)))] for _ in range(N)]
        model = _chain(coefs, cavs, ring)
        rep = controllability_report(model)
        if ring:
            Az, Bz, _ = reduce_conserved(model.A, model.B, model.conserved)
            exact = kalman_rank(Az, Bz)
        else:
            exact = kalman_rank(model.A, model.B)
        assert not rep.undecided and rep.rank == exact, (trial, N, cavs, ring)
        if rep.condition_s:
            assert rep.theory_rank == exact, (trial, cavs)
        else:
            assert exact < rep.reachable_states, (trial, cavs)
            violated += 1
            cross += any(c.zero_vehicle != c.pole_vehicle for c in rep.cancellations)
    assert violated >= 10 and cross >= 3  # the sweep does exercise both kinds of (S) failure


def test_ring_conserved_mode_is_found_by_the_staircase_on_the_full_state():
    """On the full ring state the only direction no input reaches is the total spacing: the
    orthogonal complement of the controllable subspace is span(c), its mode is 0."""
    ring = _deeplcc((8,), ring=True)
    dec = kalman_decomposition(ring.A, ring.B)
    assert dec.n_c == 15 and not dec.undecided
    u = dec.T[:, dec.n_c]
    u = u * np.sign(u @ ring.conserved)
    dev = np.linalg.norm(u - ring.conserved)
    assert dev < 1e-12
    # c A = 0 exactly, so |u' A u| <= 2 ||A|| dev (+ rounding): the mode is 0 to that accuracy
    norm_a = np.linalg.norm(ring.A, 2)
    assert abs(u @ ring.A @ u) <= 2 * norm_a * dev + 32 * np.finfo(float).eps * norm_a


def test_string_verdicts_do_not_depend_on_the_realisation():
    """The loop in random dense coordinates (cond <= 10): the same verdict on both sides of the
    boundary and at it, the same peak to 1e-9 (loop_string_stability on T^-1 A T)."""
    from lcc_synth.analysis.string_stability import loop_string_stability
    from lcc_synth.analysis.transfer import head_to_tail_loop

    model = _deeplcc()
    hdv_c = sum((c.alpha3**2 - c.alpha2**2 + 2 * c.alpha1) / c.alpha1**2
                for i, c in enumerate(model.coefficients, 1) if i not in (3, 6))  # fmt: skip
    kv = -np.sqrt(1.0 + hdv_c / 8)  # k_s = 0.5, k_p = 0: on the boundary
    rng = np.random.default_rng(3)
    for dk in (0.0, 1e-3, -1e-3):
        g = Gains.from_table({f"u_{c}": {f"s_{c}": 0.5, f"v_{c}": kv + dk} for c in (3, 6)},
                                    model)  # fmt: skip
        A, h, c = head_to_tail_loop(model, *g.input_feedback(model))
        base = loop_string_stability(A, h, c)
        for _ in range(3):
            Q = np.linalg.qr(rng.standard_normal((16, 16)))[0]
            T = Q @ np.diag(rng.uniform(1.0, 10.0, 16)) @ Q.T
            Ti = np.linalg.inv(T)
            rep = loop_string_stability(Ti @ A @ T, Ti @ h, c @ T)
            assert rep.verdict == base.verdict, (dk, rep)
            assert rep.gamma_peak == pytest.approx(base.gamma_peak, rel=1e-9)
