"""``[synthesis.baseline]`` on a platoon and a ring: hand-picked gains (a row per CAV input,
``{u_i: {state: gain}}``) reported beside the design, judged against truth built here.

The truth: the closed loop ``A_d + B K`` of the baseline's gain under "replace" (each CAV's
acceleration is its input alone: ``A_d = A - B B^+ A``) built from the model's ``A``, ``B``
and the gains, its H2 norm by scipy's Lyapunov solver (the ring on its invariant hyperplane,
a basis of which is scipy's null space of ``c``), its eigenvalues by numpy, and an open
platoon's head-to-tail velocity response ``|e_N^T (jw I - A_cl)^-1 H_d|`` evaluated here.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla
from cli_subprocess import run_cli

from lcc_synth.errors import ConfigError
from lcc_synth.problem import Problem
from lcc_synth.synthesis.config import spec_from_problem
from lcc_synth.synthesis.design import synthesize
from lcc_synth.synthesis.report import format_report

HDV = '[hdv]\nmodel = "ovm"\nalpha = 0.6\nbeta = 0.9\ns_st = 5.0\ns_go = 35.0\nv_max = 30.0\n'
Q_S, Q_V, R = 0.5, 1.0, 0.7

#: layout -> ([system] table, a stabilising hand-picked baseline in its vocabulary)
LAYOUTS = {
    "platoon": ('kind = "platoon"\nsize = 6\ncavs = [2, 5]\nv_star = 15.0',
                "{ u_2 = { s_2 = 0.3, v_2 = -0.6, v_1 = 0.2 }, "
                "u_5 = { s_5 = 0.3, v_5 = -0.6, v_4 = 0.2 } }"),
    "ring": ('kind = "ring"\nsize = 6\ncavs = [1, 4]\nv_star = 15.0',
             "{ u_1 = { s_1 = 0.3, v_1 = -0.6, v_6 = 0.2 }, "
             "u_4 = { s_4 = 0.3, v_4 = -0.6, v_3 = 0.2 } }"),
}  # fmt: skip


def _problem(layout: str, baseline: str, design: str = "full_state") -> Problem:
    system, _ = LAYOUTS[layout]
    text = (f'name = "{layout}"\n{HDV}[system]\n{system}\n[synthesis]\ndesign = "{design}"\n'
            f'semantics = "replace"\n{baseline}\n'
            f"[synthesis.weights]\nq_s = {Q_S}\nq_v = {Q_V}\nr = {R}\nhead = 0.0\naccel = 1.0\n")
    return Problem(Path(f"{layout}.toml"), tomllib.loads(text))  # fmt: skip


def _spec(layout: str, gains: str | None = None, extra: str = ""):
    gains = LAYOUTS[layout][1] if gains is None else gains
    return spec_from_problem(_problem(layout, f'[synthesis.baseline]\nname = "hand"\n{extra}'
                                              f"gains = {gains}"))  # fmt: skip


def _truth(model, table: dict):
    """``(A_cl, H_cl, V, h2)`` of the "replace" gain ``table`` ({u_i: {state: gain}}) built
    here from the model's matrices (``h2``: inf when not stable on ``V``)."""
    A, B, H = (np.asarray(model.A, float), np.asarray(model.B, float),
               np.asarray(model.H, float).reshape(-1, 1))  # fmt: skip
    P = np.eye(A.shape[0]) - B @ np.linalg.pinv(B)  # the CAVs' rows removed
    names = list(model.state_names)
    K = np.zeros((B.shape[1], A.shape[0]))
    for k, i in enumerate(model.cavs):
        for nm, g in table.get(f"u_{i}", {}).items():
            K[k, names.index(nm)] = g
    Acl = P @ A + B @ K
    c = getattr(model, "conserved", None)
    V = np.eye(A.shape[0]) if c is None else sla.null_space(np.asarray(c, float)[None, :])
    Ar = V.T @ Acl @ V
    if np.max(np.linalg.eigvals(Ar).real) >= 0:
        return Acl, P @ H, V, np.inf
    Bw = np.eye(A.shape[0])[:, [j for j, nm in enumerate(names) if nm.startswith("v_")]]
    Q = np.diag([Q_S if nm.startswith("s_") else Q_V for nm in names])
    L = sla.solve_continuous_lyapunov(Ar, -(V.T @ Bw) @ (V.T @ Bw).T)
    Cz = np.vstack([np.sqrt(Q) @ V, np.sqrt(R) * K @ V])
    return Acl, P @ H, V, float(np.sqrt(np.trace(Cz @ L @ Cz.T)))


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_baseline_h2_and_stability_are_those_of_its_closed_loop_built_here(layout):
    spec = _spec(layout)
    rep = synthesize(spec)
    b = rep.baseline
    model = spec.system.linear_model(warn=False)
    table = tomllib.loads(f"g = {LAYOUTS[layout][1]}")["g"]
    Acl, H, V, h2 = _truth(model, table)
    assert b["name"] == "hand" and b["semantics"] == "replace" and b["gains"] == table
    assert b["stable"] is True and b["h2"] == pytest.approx(h2, rel=1e-9)
    assert b["max_real_eig"] == pytest.approx(np.max(np.linalg.eigvals(V.T @ Acl @ V).real),
                                              abs=1e-9)  # fmt: skip
    assert b["vehicles"] == sorted({int(nm[2:]) for row in table.values() for nm in row})
    assert rep.check.h2 < b["h2"]  # the design beats the hand-picked gain on its own cost
    text = format_report(rep)
    assert f"baseline 'hand': true H2 {b['h2']:.6g}" in text and "lower in H2" in text
    if layout == "ring":  # no head vehicle: no string check
        assert "string_stable" not in b and "gamma_peak" not in b
        return
    # the open platoon's head -> tail velocity response, evaluated here
    e = np.zeros(Acl.shape[0])
    e[model.state_names.index("v_6")] = 1.0
    n = Acl.shape[0]

    def gamma(w):
        return abs(e @ np.linalg.solve(1j * w * np.eye(n) - Acl, H)[:, 0])

    assert gamma(b["gamma_peak_omega"]) == pytest.approx(b["gamma_peak"], rel=1e-9)
    grid = max(gamma(w) for w in np.linspace(1e-3, 3.0, 300))
    assert grid <= b["gamma_peak"] * (1 + 1e-9)
    assert b["gamma_peak"] > 1.0 and b["string_stable"] is False  # this one amplifies
    assert b["string_verdict"] == "string_unstable"


@pytest.mark.parametrize(("layout", "cav_lag"), [("platoon", 0.0), ("ring", 0.0),
                                                  ("platoon", 0.3)])  # fmt: skip
def test_a_baseline_equal_to_the_designs_gain_reports_the_designs_h2(layout, cav_lag):
    """The same gain, the same plant (with ``cav_lag``: the lag states' columns 0 in both):
    the same H2 to the last bit."""
    spec = replace(_spec(layout), cav_lag=cav_lag)
    rep = synthesize(spec)
    again = synthesize(replace(spec, baseline=("own", rep.gain)))
    assert again.baseline["h2"] == again.check.h2 == rep.check.h2
    assert again.baseline["max_real_eig"] == again.check.max_real_eig


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_an_unstable_baseline_is_reported_unstable_not_refused(layout):
    cav = 2 if layout == "platoon" else 1
    gains = LAYOUTS[layout][1].replace(f"v_{cav} = -0.6", f"v_{cav} = 5.0")  # speeds itself up
    spec = _spec(layout, gains)
    rep = synthesize(spec)
    b = rep.as_dict()["baseline"]
    table = tomllib.loads(f"g = {gains}")["g"]
    assert table[f"u_{cav}"][f"v_{cav}"] == 5.0
    Acl, _, V, h2 = _truth(spec.system.linear_model(warn=False), table)
    assert h2 == np.inf and b["h2"] is None and b["stable"] is False
    assert b["max_real_eig"] == pytest.approx(np.max(np.linalg.eigvals(V.T @ Acl @ V).real),
                                              rel=1e-9)  # fmt: skip
    assert b["max_real_eig"] > 0
    if layout == "platoon":
        assert b["string_verdict"] == "plant_unstable" and b["string_stable"] is False
    assert "(closed loop NOT stable)" in format_report(rep)
    assert rep.check.stable  # the design itself is checked as before


@pytest.mark.parametrize(("layout", "gains", "extra", "field"), [
    ("platoon", "{ u_3 = { s_3 = 0.1 } }", "", "synthesis.baseline.gains.u_3"),
    ("ring", "{ u_1 = { s_7 = 0.1 } }", "", "synthesis.baseline.gains.u_1.s_7"),
    ("platoon", "{ s_2 = 0.1 }", "", "synthesis.baseline.gains.s_2"),
    ("ring", "{ u_1 = 0.1 }", "", "synthesis.baseline.gains.u_1"),
    ("platoon", '{ u_2 = { v_2 = "fast" } }', "", "synthesis.baseline.gains.u_2.v_2"),
    ("ring", "{ u_1 = { v_1 = 0.1 } }", 'semantics = "both"\n', "synthesis.baseline.semantics"),
    ("platoon", "{ u_2 = { v_2 = 0.1 } }", "colour = 1\n", "synthesis.baseline.colour"),
])  # fmt: skip
def test_bad_baselines_name_their_field(layout, gains, extra, field):
    with pytest.raises(ConfigError) as err:
        _spec(layout, gains, extra)
    assert err.value.field == field, err.value


def test_spec_with_a_baseline_round_trips_through_its_toml():
    spec = _spec("platoon", extra='semantics = "added"\n')
    assert spec.baseline[1].semantics == "added"
    back = spec_from_problem(Problem(Path("platoon.toml"), tomllib.loads(spec.to_toml())))
    assert back == spec


def test_cli_reports_a_rings_baseline_in_json(tmp_path):
    system, gains = LAYOUTS["ring"]
    p = tmp_path / "ring.toml"
    p.write_text(f'name = "ring"\n{HDV}[system]\n{system}\n[synthesis]\ndesign = "full_state"\n'
                 f'[synthesis.baseline]\nname = "hand"\ngains = {gains}\n'
                 f"[synthesis.weights]\nq_s = {Q_S}\nq_v = {Q_V}\nr = {R}\n")  # fmt: skip
    proc = run_cli(["synthesize", p, "--no-record", "--json"], cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    b = doc["baseline"]
    assert doc["ok"] and b["name"] == "hand" and b["stable"] is True
    assert b["gains"] == tomllib.loads(f"g = {gains}")["g"]
    assert 0 < doc["check"]["h2"] < b["h2"]


def test_cli_refuses_an_unknown_cav_of_a_baseline_naming_it(tmp_path):
    system, _ = LAYOUTS["platoon"]
    p = tmp_path / "platoon.toml"
    p.write_text(f'name = "platoon"\n{HDV}[system]\n{system}\n[synthesis]\ndesign = "full_state"\n'
                 '[synthesis.baseline]\ngains = { u_3 = { s_3 = 0.1 } }\n')  # fmt: skip
    proc = run_cli(["synthesize", p, "--no-record"], cwd=tmp_path, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "synthesis.baseline.gains.u_3" in proc.stderr and "u_2" in proc.stderr
    assert "Traceback" not in proc.stderr
