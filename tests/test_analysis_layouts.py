"""Every analysis on every layout: a one-CAV string (the paper's models), a two-CAV platoon and a
ring (string stability on the open layouts only).

Truths: the paper's one-CAV string *is* a platoon with one CAV (the same matrices bit for bit,
so every report must agree once the vehicles are renumbered); exact rational Kalman and
observability ranks on dyadic coefficients (:mod:`exact_rank`); the paper's closed form of
``Gamma`` (eq. 24) against the per-vehicle cascade product; closed-loop eigenvalues computed in
the orthonormal Householder basis of the ring (not the reduction the analysis uses).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_subprocess import PAPER_HDV
from exact_rank import kalman_rank, observability_rank

from lcc_synth.analysis.controllability import (
    controllability_report,
    default_outputs,
    observability_report,
    reduce_conserved,
    segments,
)
from lcc_synth.analysis.lag_string import gamma_lag, lag_string_stability
from lcc_synth.analysis.string_stability import (
    gains_string_stability,
    plant_stability,
    string_stability,
)
from lcc_synth.analysis.transfer import (
    gamma_closed_form,
    gamma_product,
    gamma_state_space,
    local_cav_laws,
)
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains, closed_loop, input_feedback
from lcc_synth.models.hdv import OVM, LinearCoefficients
from lcc_synth.models.linear import ccc, cf_lcc, fd_lcc, general_lcc, model_from_hdv
from lcc_synth.models.platoon import (
    HEAD,
    Platoon,
    PlatoonModel,
    chain_matrices,
    platoon_model,
)

ROOT = Path(__file__).resolve().parents[1]
FIG9 = ROOT / "problems" / "paper_fig9_cases.toml"

# Dyadic coefficients: exact in binary, so the float models are the rational ones.
GEN = [LinearCoefficients(0.75, 1.5, 0.25), LinearCoefficients(1.25, 2.0, 0.5),
       LinearCoefficients(0.5, 1.25, 0.75), LinearCoefficients(1.0, 1.75, 0.375)]  # fmt: skip
#: eq. (13) violated: a1 - a2 a3 + a3^2 = 1/2 - 3/4 + 1/4 = 0 (lost mode -a1/a3 = -1)
BOUND = LinearCoefficients(0.5, 1.5, 0.5)


def _chain(coefs, cavs, ring=False) -> PlatoonModel:
    N = len(coefs)
    platoon = Platoon((OVM(),) * N, tuple(cavs), 15.0, ring=ring)
    follows = [N - 1 if ring else HEAD] + list(range(N - 1))
    A, B, H = chain_matrices(platoon.types, coefs, follows)
    return PlatoonModel(platoon, A, B, H, tuple(coefs))


def _layouts():
    """The three layouts, dyadic: (one-CAV string m = 1, n = 3), (two CAVs at 2 and 4 of 6),
    (a ring of 5 with one CAV at 5)."""
    return {
        "one_cav": general_lcc(1, 3, [GEN[0], GEN[1], GEN[2], GEN[3]]),
        "two_cav": _chain([GEN[0], GEN[3], GEN[1], GEN[3], GEN[2], GEN[3]], (2, 4)),
        "ring": _chain([GEN[0], GEN[1], GEN[2], GEN[3], GEN[3]], (5,), ring=True),
    }


def _exact_pair(model):
    """``(A, B, W)`` of the analysed space in exact arithmetic: the ring's reduction is exact
    (``A W = W A_z`` with no rounding), checked here."""
    if not model.ring:
        return model.A, model.B, None
    Az, Bz, W = reduce_conserved(model.A, model.B, model.conserved)
    assert np.array_equal(model.A @ W, W @ Az)
    return Az, Bz, W


# --------------------------------------------------------------------------------------------
# One CAV is a platoon with one CAV
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("m", "n"), [(0, 3), (2, 2), (3, 0)])
def test_the_papers_string_is_a_platoon_with_one_cav(m, n):
    lcc = model_from_hdv("lcc", m, n, OVM(), 15.0, warn=False)
    one = platoon_model(Platoon((OVM(),) * (m + n + 1), (m + 1,), 15.0), warn=False)
    for M in ("A", "B", "H"):  # tests/test_platoon.py: the same model, bit for bit
        assert np.array_equal(getattr(lcc, M), getattr(one, M)), M
    shift = m + 1  # vehicle i of the paper's string is position i + m + 1 of the platoon
    a, b = controllability_report(lcc), controllability_report(one)
    for key in ("rank", "rank_upper", "verdict", "reachable_verdict", "reachable_states",
                "condition_s", "theory_rank", "vehicles_behind", "n_states", "stabilizable"):
        assert getattr(a, key) == getattr(b, key), key
    assert np.array_equal(a.uncontrollable_eigenvalues, b.uncontrollable_eigenvalues)
    assert [i + shift for i in a.vehicles_in_subspace] == b.vehicles_in_subspace
    assert [i + shift for i in a.vehicles_outside] == b.vehicles_outside
    assert a.segments == ((0, tuple(range(1, n + 1))),)
    oa, ob = observability_report(lcc), observability_report(one)
    tail = [n] if n else []
    assert oa.outputs == ["s_0", "v_0", *(f"v_{i}" for i in tail)]
    assert ob.outputs == [f"s_{shift}", f"v_{shift}", *(f"v_{i + shift}" for i in tail)]
    assert (oa.rank, oa.verdict) == (ob.rank, ob.verdict)
    # the same gain in both vocabularies: the same closed loop, the same verdict bit for bit
    paper = Gains.named({"s_0": -0.25, "v_0": 0.5, f"v_{n}": -0.125}, "added")
    table = {f"u_{shift}": {f"s_{shift}": -0.25, f"v_{shift}": 0.5, f"v_{n + shift}": -0.125}}
    K, kh = paper.input_feedback(lcc)
    Kp, khp = Gains.from_table(table, one, "added").input_feedback(one)
    assert np.array_equal(np.atleast_2d(K), Kp) and np.array_equal(np.atleast_1d(kh), khp)
    sa, sb = string_stability(lcc, K, kh), string_stability(one, Kp, khp)
    assert sa.as_dict() == sb.as_dict()


# --------------------------------------------------------------------------------------------
# Controllability and observability against exact ranks on each layout
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["one_cav", "two_cav", "ring"])
def test_controllability_on_every_layout_is_the_exact_rank_and_the_theorem(name):
    model = _layouts()[name]
    Aa, Ba, _ = _exact_pair(model)
    exact = kalman_rank(Aa, Ba)
    rep = controllability_report(model)
    assert not rep.undecided and rep.rank == exact and rep.n_states == Aa.shape[0]
    assert rep.model_states == model.nx and rep.cavs == model.cavs
    # the theorem: the vehicles ahead of the first CAV are never reached; (S) gives the rest
    first = list(model.vehicles).index(model.cavs[0])
    reach = model.nx - 1 if model.ring else 2 * (len(model.vehicles) - first)
    assert rep.reachable_states == reach
    assert rep.condition_s == (exact == reach) and rep.theory_rank == (reach if
                                                                      rep.condition_s else None)
    assert rep.vehicles_outside == ([] if model.ring else list(model.vehicles[:first]))
    doc = json.loads(json.dumps(rep.as_dict()))
    assert doc["verdict"] == rep.verdict and doc["kind"] == model.kind


@pytest.mark.parametrize(
    "build", [lambda n: fd_lcc(n, BOUND), lambda n: cf_lcc(n, BOUND),
              lambda n: general_lcc(2, n, [GEN[0], GEN[1]] + [BOUND] * n)],  # fmt: skip
    ids=["fd_lcc", "cf_lcc", "lcc"],
)
@pytest.mark.parametrize("n", [1, 3])
def test_eq13_violated_on_the_papers_models_loses_one_mode_per_hdv_at_minus_a1_over_a3(build, n):
    """Theorems 1-2 on the boundary of eq. (13): the generalised theorem's segment (the CAV and
    its n HDVs) loses exactly one mode per HDV, at -a1/a3 = -1: the exact rank says so."""
    model = build(n)
    rep = controllability_report(model)
    reach = 2 * (n + 1)
    assert kalman_rank(model.A, model.B) == reach - n == rep.rank
    assert rep.condition_s is False and rep.theory_rank is None and rep.stabilizable
    pairs = {(c.zero_vehicle, c.pole_vehicle) for c in rep.cancellations}
    assert pairs == {(k, i) for k in range(1, n + 1) for i in range(k, n + 1)}
    assert {c.eigenvalue for c in rep.cancellations} == {-1.0}
    assert rep.reachable_verdict == "uncontrollable"


def test_ccc_segment_is_the_cav_alone():
    """Corollary 2: in CCC only the CAV is controllable; its segment has no HDV."""
    model = ccc(3, GEN[:3], cav=GEN[3])
    rep = controllability_report(model)
    assert segments(model) == [(0, ())] and kalman_rank(model.A, model.B) == 2
    assert rep.rank == rep.reachable_states == rep.theory_rank == 2
    assert rep.vehicles_outside == [-3, -2, -1] and rep.vehicles_in_subspace == [0]


def test_default_outputs_on_every_layout():
    lay = _layouts()
    assert default_outputs(lay["one_cav"]) == ["s_0", "v_0", "v_3"]
    assert default_outputs(lay["one_cav"], 2) == ["s_0", "v_0", "v_2"]
    assert default_outputs(fd_lcc(3, GEN[0])) == ["v_3"]
    assert default_outputs(ccc(2, GEN[0]), 1) == ["s_0", "v_0"]  # nobody behind the CAV
    assert default_outputs(lay["two_cav"]) == ["s_2", "v_2", "s_4", "v_4", "v_6"]
    assert default_outputs(lay["two_cav"], 3) == ["s_2", "v_2", "s_4", "v_4", "v_3"]
    assert default_outputs(lay["ring"]) == ["s_5", "v_5"]
    assert default_outputs(_chain(GEN, (), ring=True)) == ["v_4"]
    for model, k in ((lay["one_cav"], -1), (lay["two_cav"], 1), (lay["one_cav"], 4)):
        with pytest.raises(ConfigError) as err:
            default_outputs(model, k)
        assert err.value.field == "k"


@pytest.mark.parametrize("name", ["one_cav", "two_cav", "ring"])
def test_observability_on_every_layout_is_the_exact_rank(name):
    model = _layouts()[name]
    Aa, _, W = _exact_pair(model)
    for outputs in (None, [f"v_{model.vehicles[-1]}"]):
        rep = observability_report(model, outputs)
        C = model.output_matrix(rep.outputs)
        exact = observability_rank(Aa, C if W is None else C @ W)
        assert not rep.undecided and rep.rank == exact, (outputs, rep.as_dict())
        assert rep.verdict == ("observable" if exact == Aa.shape[0] else "unobservable")
    assert observability_report(model).verdict == "observable"  # the CAVs' states and the tail


# --------------------------------------------------------------------------------------------
# Closed loops: plant stability everywhere, string stability on the open layouts
# --------------------------------------------------------------------------------------------


def _feedback(model, scale: float):
    """A gain on every CAV's own spacing and velocity (``"replace"``)."""
    K = np.zeros((len(model.cavs), model.nx))
    for row, c in enumerate(model.cavs):
        K[row, model.index(f"s_{c}")] = 0.5 * scale
        K[row, model.index(f"v_{c}")] = -1.5 * scale
        j = list(model.vehicles).index(c)
        if j > 0:
            K[row, model.index(f"v_{model.vehicles[j - 1]}")] = 1.0 * scale
    kh = np.zeros(len(model.cavs))
    if list(model.vehicles).index(model.cavs[0]) == 0 and not model.ring:
        kh[0] = 1.0 * scale
    return K, kh


@pytest.mark.parametrize("name", ["one_cav", "two_cav", "ring"])
@pytest.mark.parametrize("scale", [1.0, -1.0])
def test_plant_stability_on_every_layout(name, scale):
    """Against numpy's eigenvalues of the closed loop, on the ring in the orthonormal
    Householder basis of the hyperplane (not the reduction the analysis uses)."""
    model = _layouts()[name]
    K, kh = _feedback(model, scale)
    Acl, _ = closed_loop(model, K, kh)
    if model.ring:
        V = model.invariant_basis()
        Acl = V.T @ Acl @ V
    truth = np.linalg.eigvals(Acl).real.max()
    assert abs(truth) > 1e-3  # far from the boundary: numpy's answer is the truth
    verdict, max_re = plant_stability(model, K, kh)
    assert verdict == ("plant_stable" if truth < 0 else "plant_unstable")
    assert max_re == pytest.approx(truth, rel=1e-9, abs=1e-12)


def test_plant_stability_of_fd_lcc_without_a_position_gain_is_the_boundary():
    """FD-LCC's -p_0 is an integrator: its column of A_cl is zero without a gain on it, so 0 is
    an exact eigenvalue and the verdict cannot be decided; with a gain on it, it can."""
    model = fd_lcc(3, GEN[0])
    K, _ = input_feedback(model, Gains.named({"v_0": -0.5, "s_1": -0.2, "v_1": 0.05}, "replace"))
    assert not np.any(closed_loop(model, K)[0][:, 0])
    assert plant_stability(model, K)[0] == "boundary"
    K[0] = 0.1  # u = ... + 0.1 (-p_0)
    assert plant_stability(model, K)[0] == "plant_stable"
    assert np.linalg.eigvals(closed_loop(model, K)[0]).real.max() < -1e-3


def test_cascade_product_of_a_one_cav_string_is_the_papers_closed_form():
    """CF-LCC with a local CAV law (gains on s_0, v_0 only, "added"): Gamma as the product of
    the per-vehicle transfer functions read from the closed loop equals eq. (24)."""
    n, mu0, k0 = 3, 0.25, -0.5
    model = cf_lcc(n, GEN[:n], cav=GEN[3])
    K, kh = input_feedback(model, Gains.named({"s_0": mu0, "v_0": k0}, "added"))
    c0 = GEN[3]
    assert local_cav_laws(model, K, kh) == {0: (c0.alpha1 + mu0, k0 - c0.alpha2, c0.alpha3)}
    w = np.logspace(-2, 1.5, 120)
    coefs = {0: c0, **{i: GEN[i - 1] for i in range(1, n + 1)}}
    paper = gamma_closed_form(coefs, {0: mu0}, {0: k0}, 0, n, 1j * w)
    assert np.max(np.abs(gamma_product(model, K, kh, w) / paper - 1)) < 1e-12
    assert np.max(np.abs(gamma_state_space(model, K, kh, w) / paper - 1)) < 1e-10
    # a gain on a vehicle behind breaks the cascade, named by the CAV's input
    Kb, khb = input_feedback(model, Gains.named({"s_0": mu0, "v_2": 0.1}, "added"))
    with pytest.raises(ConfigError) as err:
        local_cav_laws(model, Kb, khb)
    assert err.value.field == "gains.u_0"


def _dense_peak(gamma) -> float:
    """``max |gamma(j w)|``: a dense logarithmic grid over 1e-3..1e2 rad/s, then a dense linear
    grid between the neighbours of its best point."""
    w = np.logspace(-3, 2, 20001)
    j = int(np.argmax(np.abs(gamma(w))))
    fine = np.linspace(w[max(j - 1, 0)], w[min(j + 1, w.size - 1)], 20001)
    return float(np.abs(gamma(fine)).max())


@pytest.mark.parametrize("name", ["one_cav", "two_cav"])
@pytest.mark.parametrize(("scale", "tau", "verdict"),
                         [(1.0, 2.0, "string_stable"), (0.25, 1.0, "string_unstable")])
def test_string_stability_on_the_open_layouts(name, scale, tau, verdict):
    """The verdict of every open layout against a dense |Gamma| grid of the cascade product
    (an independent computation of Gamma), with and without the actuator lag."""
    model = _layouts()[name]
    K, kh = _feedback(model, scale)
    rep = string_stability(model, K, kh)
    assert rep.plant_stable and rep.verdict == verdict
    peak = _dense_peak(lambda w: gamma_product(model, K, kh, w))
    assert rep.string_stable == (peak <= 1.0 + 1e-9)
    assert rep.gamma_peak == pytest.approx(max(peak, 1.0), rel=1e-9)
    ham = string_stability(model, K, kh, "hamiltonian")
    assert ham.verdict == rep.verdict and ham.gamma_peak == pytest.approx(rep.gamma_peak, 1e-9)
    lagged = lag_string_stability(model, K, kh, tau)
    assert lagged.plant_stable and lagged.verdict == "string_unstable"
    assert lagged.gamma_peak > rep.gamma_peak  # the lag amplifies more
    slow = _dense_peak(lambda w: gamma_lag(model, K, kh, tau, w))
    assert lagged.gamma_peak == pytest.approx(slow, rel=1e-9)


@pytest.mark.parametrize("model", [_layouts()["ring"], fd_lcc(3, GEN[0])], ids=["ring", "fd"])
def test_no_head_to_tail_transfer_without_a_head_vehicle(model):
    K, kh = _feedback(model, 1.0) if model.ring else (np.zeros(model.nx), 0.0)
    for call in (lambda: string_stability(model, K, kh),
                 lambda: gamma_state_space(model, K, kh, [1.0]),
                 lambda: lag_string_stability(model, K, kh, 0.3),
                 lambda: local_cav_laws(model, K, kh)):  # fmt: skip
        with pytest.raises(ConfigError) as err:
            call()
        assert err.value.field == "system.kind" and "no head vehicle" in err.value.message


def test_gains_of_either_vocabulary_give_the_same_string_report():
    """``gains_string_stability`` reads any gains object through its ``input_feedback``."""
    lay = _layouts()
    gains = Gains.named({"s_0": 0.25, "v_0": -0.5}, "added")
    K, kh = input_feedback(lay["one_cav"], gains)
    ours = gains_string_stability(lay["one_cav"], gains)
    assert ours.as_dict() == string_stability(lay["one_cav"], K, kh).as_dict()
    pg = Gains.zero(lay["two_cav"], "added")
    ours = gains_string_stability(lay["two_cav"], pg)
    assert ours.as_dict() == string_stability(lay["two_cav"], *pg.input_feedback(lay["two_cav"])
                                              ).as_dict()  # fmt: skip


# --------------------------------------------------------------------------------------------
# lcc-synth analyze: one document for every layout
# --------------------------------------------------------------------------------------------

FIG9_AS_PLATOON = """
""" + PAPER_HDV + """
[system]
kind = "platoon"
size = 5
cavs = [3]
v_star = 15.0

[analysis]
outputs = ["s_3", "v_3", "v_5"]

[cases.case_a]
semantics = "added"
[cases.case_a.gains.u_3]
s_1 = 1.0
v_1 = -1.0
"""

RING = """
[system]
kind = "ring"
size = 6
cavs = [6]

[cases.damp]
semantics = "added"
[cases.damp.gains.u_6]
v_6 = -1.0
"""


def _json(tmp_path, capsys, path_or_text):
    from lcc_synth.cli.main import main

    path = Path(path_or_text) if isinstance(path_or_text, Path) else tmp_path / "p.toml"
    if not isinstance(path_or_text, Path):
        path.write_text(path_or_text)
    assert main(["analyze", str(path), "--json", "--no-record"]) == 0
    return json.loads(capsys.readouterr().out)


def test_analyze_gives_one_document_for_every_layout(tmp_path, capsys):
    paper = _json(tmp_path, capsys, FIG9)
    one = _json(tmp_path, capsys, FIG9_AS_PLATOON)
    ring = _json(tmp_path, capsys, RING)
    for key in ("system", "controllability", "observability"):
        assert set(paper[key]) == set(one[key]) == set(ring[key]), key
    assert set(paper) == set(one) == set(ring)
    # the one-CAV platoon is Fig. 9's string: the same verdicts, the vehicles renumbered
    ca, cb = paper["controllability"], one["controllability"]
    for key in ("rank", "n_states", "verdict", "reachable_verdict", "condition_s",
                "vehicles_behind", "decision_margin"):
        assert ca[key] == cb[key], key
    assert [v + 3 for v in ca["vehicles_outside"]] == cb["vehicles_outside"] == [1, 2]
    assert paper["observability"]["rank"] == one["observability"]["rank"] == 10
    assert paper["cases"]["case_a"]["gamma_peak"] == one["cases"]["case_a"]["gamma_peak"]
    assert paper["cases"]["case_a"]["vehicles_used"] == [-2]
    assert one["cases"]["case_a"]["vehicles_used"] == [1]
    # the shapes each kind of file had before: the HDV's dict, the per-vehicle list
    assert isinstance(paper["linear_coefficients"], dict)
    assert isinstance(one["linear_coefficients"], list) and len(one["vehicle_coefficients"]) == 5
    assert paper["system"]["n"] == 2 and one["system"]["n"] == 3  # the [system] tables' n
    damp = ring["cases"]["damp"]
    assert damp["verdict"] is None and damp["gamma_peak"] is None
    assert damp["plant_verdict"] == "plant_stable" and ring["system"]["circumference"] > 0
