"""``[synthesis.robust]`` on the one-CAV string (lcc_synth.synthesis.robust_string).

The string's robust gain is the one the platoon pipeline designs on the equivalent one-CAV
platoon (bit for bit in "replace"; "added" is it minus the CAV's nominal HDV law). Its reported
member statistics are recomputed here from each sampled member alone: the member's vehicles
drawn here with numpy (``default_rng(seed)``, vehicle-major, as ``[synthesis.robust]``
documents), its linear string model built from their linear coefficients (eq. 9, the CAV's
own law nominal), the closed loop of the reported gain object, and its H2 norm from scipy's
Lyapunov solver. "added" and "replace" give the same closed loop; what cannot be expressed is
one named ConfigError; and the real CLI prints the robust statistics.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla
from cli_subprocess import PAPER_HDV, one_line_error, run_cli

from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import OVM, linear_coefficients
from lcc_synth.models.linear import general_lcc
from lcc_synth.problem import Problem
from lcc_synth.synthesis.config import spec_from_problem
from lcc_synth.synthesis.design import synthesize
from lcc_synth.synthesis.report import format_report

Q_S, Q_S0, Q_V, R, HEAD, ACCEL = 0.5, 0.8, 1.0, 0.7, 0.5, 1.0
SEED, SAMPLES, ALPHA, BETA = 3, 4, (0.45, 0.75), (0.7, 1.1)
ROBUST = (f"[synthesis.robust]\nsamples = {SAMPLES}\nseed = {SEED}\nobjective = \"mean\"\n"
          f"alpha = {list(ALPHA)}\nbeta = {list(BETA)}\n")  # fmt: skip
WEIGHTS = (f"[synthesis.weights]\nq_s = {Q_S}\nq_s0 = {Q_S0}\nq_v = {Q_V}\nr = {R}\n"
           f"head = {HEAD}\naccel = {ACCEL}\n")  # fmt: skip

#: one-CAV strings (m + n <= 3) -> (the [system] table, m, n, the [synthesis] pattern key or "")
STRINGS = {
    "lcc": ('kind = "lcc"\nm = 1\nn = 2', 1, 2, "pattern = [-1, 1]"),
    "cf_lcc": ('kind = "cf_lcc"\nn = 3', 0, 3, "pattern = [1, 2]"),
    "ccc": ('kind = "ccc"\nm = 2', 2, 0, ""),
}


def _text(system: str, synthesis: str, robust: str = ROBUST) -> str:
    return (f'name = "r"\n{PAPER_HDV}[system]\n{system}\nv_star = 15.0\n[synthesis]\n'
            f"{synthesis}\n{WEIGHTS}{robust}")  # fmt: skip


def _spec(system: str, synthesis: str, robust: str = ROBUST):
    return spec_from_problem(Problem(Path("r.toml"), tomllib.loads(_text(system, synthesis,
                                                                          robust))))


@cache
def _string(kind: str, semantics: str, design: str = "structured", lag: str = ""):
    """The robust design of the string ``kind`` (spec, report), once a session."""
    system, _, _, pattern = STRINGS[kind]
    pattern = pattern if design == "structured" else ""
    spec = _spec(system, f'design = "{design}"\nsemantics = "{semantics}"\n{pattern}\n{lag}')
    return spec, synthesize(spec)


@cache
def _platoon(kind: str, robust: bool = True, design: str = "structured", lag: str = ""):
    """The same problem written as the one-CAV platoon (positions from the head)."""
    _, m, n, pattern = STRINGS[kind]
    cav = m + 1
    heard = ""
    if pattern and design == "structured":
        vehicles = tomllib.loads(pattern)["pattern"]
        heard = f"[synthesis.patterns]\nu_{cav} = {[v + cav for v in vehicles]}\n"
    system = f'kind = "platoon"\nsize = {m + n + 1}\ncavs = [{cav}]'
    spec = _spec(system, f'design = "{design}"\nsemantics = "replace"\n{lag}\n{heard}',
                 ROBUST if robust else "")
    return synthesize(spec)


def _law(m: int, n: int) -> np.ndarray:
    """The CAV's nominal HDV law ``a1 s_0 - a2 v_0 + a3 v_-1`` on the string's states."""
    c = linear_coefficients(OVM(), 15.0)  # PAPER_HDV is the OVM's defaults (checked below)
    law = np.zeros(2 * (m + n + 1))
    law[2 * m], law[2 * m + 1] = c.alpha1, -c.alpha2
    if m:
        law[2 * m - 1] = c.alpha3
    return law


@pytest.mark.parametrize(("kind", "semantics", "design", "lag"), [
    ("lcc", "replace", "structured", ""), ("cf_lcc", "replace", "structured", ""),
    ("ccc", "added", "structured", ""), ("lcc", "added", "structured", ""),
    ("cf_lcc", "replace", "full_state", ""), ("lcc", "added", "structured", "cav_lag = 0.3"),
])  # fmt: skip
def test_robust_string_gain_is_the_one_cav_platoons(kind, semantics, design, lag):
    """The string's gain equals the platoon's robust gain on the same vehicles: bit for bit in
    "replace" (the same numbers, renamed); in "added" after adding back the CAV's nominal HDV
    law (one subtraction and one addition of three coefficients: 1e-12, measured 0 to 1e-16).
    The member statistics are the platoon report's; with ``cav_lag`` (every member lagged)
    too, and the check is of the lagged loop."""
    assert tomllib.loads(PAPER_HDV)["hdv"] == {"model": "ovm", **{
        k: getattr(OVM(), k) for k in ("alpha", "beta", "s_st", "s_go", "v_max")}}
    _, m, n, _ = STRINGS[kind]
    spec, rep = _string(kind, semantics, design, lag)
    prep = _platoon(kind, design=design, lag=lag)
    if lag:  # in the design: the check is of the lagged loop, not the lag-free one
        assert spec.cav_lag == 0.3 and any("lag" in note for note in rep.notes)
        assert rep.check.h2 != pytest.approx(_string(kind, semantics, design)[1].check.h2)
    whole = np.asarray(prep.K[0], float)
    names = [f"{x}_{i}" for i in range(-m, n + 1) for x in "sv"]
    assert rep.state_names == names and rep.kind == kind and (rep.m, rep.n) == (m, n)
    K = np.asarray(rep.K, float)
    if semantics == "replace":
        assert np.array_equal(K, whole)
    else:
        np.testing.assert_allclose(K + _law(m, n), whole, rtol=0, atol=1e-12)
        assert not np.allclose(K, whole)  # the law was taken off
    assert rep.gains == dict(zip(names, K.tolist(), strict=True))
    assert rep.robust == prep.robust and rep.semantics == semantics
    assert rep.check.h2 == pytest.approx(prep.check.h2, rel=1e-12)
    assert rep.pattern == sorted(p - m - 1 for p in prep.patterns[f"u_{m + 1}"])
    text = format_report(rep)
    assert "robust (mean, 4 members" in text and ("s_-1" in text) is (m > 0)


@pytest.mark.parametrize("design", ["structured", "full_state"])
def test_robust_string_with_the_lmi_start_is_the_one_cav_platoons(design):
    """``method = "lmi"`` starts the robust descent from the platoon's LMI gain (the convex
    restriction, or the full-state LMI): the string's gain, bound and solver figures are the
    one-CAV platoon's, bit for bit in "replace"."""
    lmi = 'method = "lmi"'
    spec, rep = _string("lcc", "replace", design, lmi)
    prep = _platoon("lcc", design=design, lag=lmi)
    assert spec.method == "lmi" and prep.solver["status"].startswith("optimal")
    assert np.array_equal(np.asarray(rep.K, float), np.asarray(prep.K[0], float))
    timeless = [{k: v for k, v in r.solver.items() if k != "solve_time"} for r in (rep, prep)]
    assert rep.robust == prep.robust and timeless[0] == timeless[1]
    assert (rep.h2_lmi_bound, rep.h2_restriction) == (prep.h2_lmi_bound, prep.h2_restriction)
    if design == "structured":  # the restriction's bound and gain: above the optimum
        assert rep.h2_lmi_bound >= rep.h2_restriction >= rep.h2_unstructured
    else:  # the full-state LMI is the Riccati optimum (to the solver's accuracy)
        assert rep.h2_restriction == pytest.approx(rep.h2_unstructured, rel=1e-6)
        assert rep.h2_lmi_bound == pytest.approx(rep.h2_unstructured, rel=1e-6)


def _members(m: int, n: int) -> list[list[OVM]]:
    """Each member's vehicles (front to tail, the CAV's entry at m), drawn here."""
    rng = np.random.default_rng(SEED)
    lo, hi = np.array([ALPHA[0], BETA[0]]), np.array([ALPHA[1], BETA[1]])
    out = []
    for _ in range(SAMPLES):
        draw = rng.uniform(lo, hi, size=(m + n + 1, 2))
        out.append([OVM(alpha=float(a), beta=float(b)) for a, b in draw])
    return out


def _member_h2(gain, m: int, n: int, vehicles: list[OVM]) -> tuple[float, float]:
    """(H2 norm, max Re(eig)) of ``gain`` on one member: the string model of the member's HDVs
    (the CAV's law nominal), its closed loop, and the weights of the file written out here."""
    coefs = [linear_coefficients(h, 15.0) for h in vehicles]
    model = general_lcc(m, n, coefs[:m] + coefs[m + 1:], linear_coefficients(OVM(), 15.0))
    A, H = gain.closed_loop(model)
    Ku, _ = gain.input_feedback(model)  # the CAV's whole command u = Ku x (+ 0 v_h, m >= 1)
    names = model.state_names
    vel = [j for j, nm in enumerate(names) if nm.startswith("v_")]
    Bw = np.column_stack([HEAD * H.ravel(), *(ACCEL * np.eye(len(names))[:, vel].T)])
    q = [Q_S0 if nm == "s_0" else Q_S if nm.startswith("s_") else Q_V for nm in names]
    Cz = np.vstack([np.diag(np.sqrt(q)), np.sqrt(R) * np.asarray(Ku, float).reshape(1, -1)])
    L = sla.solve_continuous_lyapunov(A, -Bw @ Bw.T)
    return float(np.sqrt(np.trace(Cz @ L @ Cz.T))), float(np.max(np.linalg.eigvals(A).real))


@pytest.mark.parametrize("semantics", ["replace", "added"])
def test_member_statistics_are_each_members_lyapunov_h2_and_beat_the_nominal(semantics):
    """Reported mean / worst H2 over the members = the members' Lyapunov H2 computed here
    (rel 1e-9); the robust gain is stable on every member and its mean H2 is no worse than
    that of the nominal structured gain it was descended from (the same computation)."""
    m, n = STRINGS["lcc"][1:3]
    _, rep = _string("lcc", semantics)
    members = _members(m, n)
    h_rob = [_member_h2(rep.gain, m, n, v) for v in members]
    nominal = _platoon("lcc", robust=False).gain  # the platoon's: the start of the descent
    Kn = np.asarray(nominal.K[0], float)  # its whole command on the string's states
    from lcc_synth.models.feedback import Gains

    model = general_lcc(m, n, linear_coefficients(OVM(), 15.0), linear_coefficients(OVM(), 15.0))
    h_nom = [_member_h2(Gains.on(model, Kn, "replace"), m, n, v) for v in members]
    assert all(eig < 0 for _, eig in h_rob) and all(eig < 0 for _, eig in h_nom)
    r, nom = rep.robust["robust_design"], rep.robust["nominal_design"]
    h = np.array([x for x, _ in h_rob])
    assert r["n_stable"] == SAMPLES and [row["stable"] for row in r["members"]] == [True] * 4
    assert [row["h2"] for row in r["members"]] == pytest.approx(h.tolist(), rel=1e-9)
    assert r["mean_h2"] == pytest.approx(h.mean(), rel=1e-9)
    assert r["worst_h2"] == pytest.approx(h.max(), rel=1e-9)
    hn = np.array([x for x, _ in h_nom])
    assert nom["mean_h2"] == pytest.approx(hn.mean(), rel=1e-9)
    assert h.mean() <= hn.mean() * (1 + 1e-12)
    assert not np.array_equal(np.asarray(rep.K) + (_law(m, n) if semantics == "added" else 0),
                              Kn)  # the members moved the gain  # fmt: skip


def test_added_and_replace_give_the_same_closed_loop():
    """The same design, written in either semantics: the closed loops ``(A + B K, H + B kh)``
    on the nominal model agree to 1e-12 (the law's coefficients subtracted and added back),
    and so do the checks and the member statistics (the same whole command, bit for bit)."""
    spec_a, rep_a = _string("lcc", "added")
    _, rep_r = _string("lcc", "replace")
    model = spec_a.system.linear_model(warn=False)
    (Aa, Ha), (Ar, Hr) = rep_a.gain.closed_loop(model), rep_r.gain.closed_loop(model)
    np.testing.assert_allclose(Aa, Ar, rtol=0, atol=1e-12)
    np.testing.assert_allclose(Ha, Hr, rtol=0, atol=1e-12)
    assert rep_a.gain.semantics == "added" and rep_r.gain.semantics == "replace"
    assert rep_a.check == rep_r.check and rep_a.robust == rep_r.robust
    assert rep_a.input_K == rep_r.input_K and rep_a.input_kh == rep_r.input_kh == 0.0


def test_robust_string_spec_round_trips_through_its_toml():
    spec, _ = _string("lcc", "added")
    back = spec_from_problem(Problem(Path("b.toml"), tomllib.loads(spec.to_toml())))
    assert replace(back, source=spec.source) == spec
    assert back.robust.ranges == {"alpha": ALPHA, "beta": BETA} and back.method == "direct"


LCC = 'kind = "lcc"\nm = 1\nn = 2'


@pytest.mark.parametrize(("system", "synthesis", "robust", "field", "words"), [
    ('kind = "fd_lcc"\nn = 3', 'semantics = "replace"', ROBUST, "synthesis.robust",
     ("fd_lcc", "head vehicle", "cf_lcc")),
    (LCC, "", ROBUST.replace("[synthesis.robust]", '[hdv]\nmodel = "idm"\n[synthesis.robust]'),
     "synthesis.robust.alpha", ("IDM", "OVM")),
    (LCC, 'design = "sparsity"', ROBUST, "synthesis.design", ("full_state", "structured")),
    (LCC, "cross_check = true", ROBUST, "synthesis.cross_check", ("drop it",)),
    (LCC, "as_run = true", ROBUST, "synthesis.as_run", ("drop it",)),
    (LCC, 'design = "structured"\nmethod = "riccati"', ROBUST, "synthesis.method",
     ("direct",)),
    ('kind = "cf_lcc"\nn = 3', 'semantics = "added"', ROBUST, "synthesis.semantics",
     ("m = 0", "replace")),
    (LCC, 'semantics = "added"\npattern = [1]', ROBUST, "synthesis.pattern", ("-1",)),
    (LCC, "", ROBUST.replace("alpha = [0.45, 0.75]", "alpha = [0.9, 0.5]"),
     "synthesis.robust.alpha", ("lo <= hi",)),
])  # fmt: skip
def test_what_cannot_be_expressed_is_one_named_error(system, synthesis, robust, field, words):
    if 'model = "idm"' in robust:  # the [hdv] table replaced by an IDM one
        text = _text(system, synthesis, "").replace(PAPER_HDV, '[hdv]\nmodel = "idm"\n')
        text += robust.replace('[hdv]\nmodel = "idm"\n', "")
        data = tomllib.loads(text)
    else:
        data = tomllib.loads(_text(system, synthesis, robust))
    with pytest.raises(ConfigError) as err:
        spec_from_problem(Problem(Path("r.toml"), data))
    assert err.value.field == field, err.value
    assert all(w in err.value.message for w in words), err.value.message


def test_cli_prints_the_robust_statistics_and_refuses_a_bad_value(tmp_path):
    good = tmp_path / "robust.toml"
    good.write_text(_text(STRINGS["lcc"][0], 'design = "structured"\npattern = [-1, 1]'))
    proc = run_cli(["synthesize", good, "--json", "--no-record", "--no-progress"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["ok"] and (doc["kind"], doc["m"], doc["n"]) == ("lcc", 1, 2)
    assert doc["semantics"] == "added" and "s_-1" in doc["gains"] and "cavs" not in doc
    r = doc["robust"]
    assert (r["samples"], r["seed"], r["objective"]) == (SAMPLES, SEED, "mean")
    for key in ("nominal_design", "robust_design"):
        assert set(r[key]) >= {"mean_h2", "worst_h2", "best_h2", "n_stable", "members"}
    assert r["robust_design"]["mean_h2"] <= r["nominal_design"]["mean_h2"]
    bad = tmp_path / "bad.toml"
    bad.write_text(good.read_text().replace("samples = 4", "samples = 0"))
    proc = run_cli(["synthesize", bad, "--no-record", "--no-progress"], tmp_path)
    assert proc.returncode == 2 and one_line_error(proc.stderr), proc.stderr
    assert "synthesis.robust.samples" in proc.stderr and proc.stdout == ""
