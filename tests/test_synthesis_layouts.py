"""One synthesis entry point for every layout: a one-CAV string, a two-CAV platoon and a ring.

Each layout goes through the same calls (``spec_from_problem`` -> ``synthesize`` ->
``format_report`` / ``as_dict``), and each result is judged against truth computed here from
the model matrices alone with scipy: the Riccati optimum (CARE) for ``design = "full_state"``
and the Lyapunov H2 norm of the reported whole-input gain for every design (the ring on its
invariant hyperplane ``c x = 0``, whose basis is scipy's null space of ``c``); ``design =
"sparsity"`` on every layout too, and the robust design of several CAVs on each sampled member
(one CAV's: tests/test_robust_one_cav.py). The features that exist only for one CAV (or only
for several) raise one ConfigError naming the key and the layout; the feature matrix in the
docstring of :mod:`lcc_synth.synthesis` is read and checked here cell by cell.
"""

from __future__ import annotations

import tomllib
from functools import cache
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg as sla

from lcc_synth.errors import ConfigError
from lcc_synth.problem import Problem
from lcc_synth.synthesis.config import spec_from_problem
from lcc_synth.synthesis.design import synthesize
from lcc_synth.synthesis.report import format_report

HDV = '[hdv]\nmodel = "ovm"\nalpha = 0.6\nbeta = 0.9\ns_st = 5.0\ns_go = 35.0\nv_max = 30.0\n'
Q_S, Q_V, R = 0.5, 1.0, 0.7

#: layout name -> (the [system] table, the structured pattern keys of its vocabulary)
LAYOUTS = {
    "one_cav_string": ('kind = "cf_lcc"\nn = 4\nv_star = 15.0', "pattern = [1, 2]"),
    "two_cav_platoon": ('kind = "platoon"\nsize = 6\ncavs = [2, 5]\nv_star = 15.0',
                        "comm_range = 1"),
    "ring": ('kind = "ring"\nsize = 6\ncavs = [1, 4]\nv_star = 15.0', "comm_range = 1"),
}  # fmt: skip


def _problem(layout: str, design: str, extra: str = "") -> Problem:
    system, pattern = LAYOUTS[layout]
    text = (f'name = "{layout}"\n{HDV}[system]\n{system}\n[synthesis]\ndesign = "{design}"\n'
            f'semantics = "replace"\n{pattern if design == "structured" else ""}\n{extra}\n'
            f"[synthesis.weights]\nq_s = {Q_S}\nq_v = {Q_V}\nr = {R}\nhead = 0.0\naccel = 1.0\n")
    return Problem(Path(f"{layout}.toml"), tomllib.loads(text))  # fmt: skip


def _truth(spec):
    """The design plant under "replace" (each CAV's acceleration is its input alone: its rows
    of ``A`` removed, ``A_d = A - B B^+ A``), weights and the invariant-subspace basis, built
    here from the model matrices."""
    model = spec.system.linear_model(warn=False)
    nx = np.asarray(model.A).shape[0]
    B = np.asarray(model.B, float).reshape(nx, -1)
    A = np.asarray(model.A, float) - B @ np.linalg.pinv(B) @ np.asarray(model.A, float)
    names = list(model.state_names)
    q = np.array([Q_S if nm.startswith("s_") else Q_V for nm in names])
    vel = [j for j, nm in enumerate(names) if nm.startswith("v_")]
    Bw = np.eye(nx)[:, vel]  # unit acceleration noise on every velocity (the CAVs' included)
    c = getattr(model, "conserved", None)
    V = np.eye(nx) if c is None else sla.null_space(np.asarray(c, float)[None, :])
    return A, B, np.diag(q), Bw, V, names


def _lyapunov_h2(A, B, Q, Bw, V, K) -> float:
    Acl = V.T @ (A + B @ K) @ V
    Cz = np.vstack([sla.sqrtm(Q).real @ V, np.sqrt(R) * K @ V])
    L = sla.solve_continuous_lyapunov(Acl, -(V.T @ Bw) @ (V.T @ Bw).T)
    return float(np.sqrt(np.trace(Cz @ L @ Cz.T)))


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_full_state_is_the_riccati_optimum_on_every_layout(layout):
    spec = spec_from_problem(_problem(layout, "full_state"))
    rep = synthesize(spec)
    A, B, Q, Bw, V, names = _truth(spec)
    K = np.atleast_2d(np.asarray(rep.K, float))
    assert rep.state_names == names
    assert K.shape == (B.shape[1], A.shape[0])  # one gain row per CAV
    model = spec.system.linear_model(warn=False)  # replace: the whole input cancels the CAV rows
    K0 = -np.linalg.pinv(B) @ np.asarray(model.A, float)
    np.testing.assert_allclose(np.atleast_2d(rep.input_K), K + K0, rtol=0, atol=1e-12)
    P = sla.solve_continuous_are(V.T @ A @ V, V.T @ B, V.T @ Q @ V, R * np.eye(B.shape[1]))
    h2_star = float(np.sqrt(np.trace((V.T @ Bw).T @ P @ (V.T @ Bw))))
    assert rep.h2_unstructured == pytest.approx(h2_star, rel=1e-8)
    assert rep.check.h2 == pytest.approx(h2_star, rel=1e-8)
    assert _lyapunov_h2(A, B, Q, Bw, V, K) == pytest.approx(h2_star, rel=1e-8)
    assert rep.as_dict()["problem"] == layout
    assert layout in format_report(rep)


@cache
def _structured(layout: str):
    """``(spec, report)`` of the structured design of ``layout``, designed once per session
    for the tests that read it."""
    spec = spec_from_problem(_problem(layout, "structured"))
    return spec, synthesize(spec)


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_structured_keeps_the_pattern_and_reports_its_true_h2_on_every_layout(layout):
    spec, rep = _structured(layout)
    A, B, Q, Bw, V, names = _truth(spec)
    K = np.atleast_2d(np.asarray(rep.K, float))
    vehicle = np.array([int(nm.split("_")[1]) for nm in names])
    heard = {  # written by hand: one CAV + HDVs 1, 2; comm_range 1 (the ring wraps around)
        "one_cav_string": [(0, 1, 2)],
        "two_cav_platoon": [(1, 2, 3), (4, 5, 6)],
        "ring": [(6, 1, 2), (3, 4, 5)],
    }[layout]
    heard = [np.isin(vehicle, h) for h in heard]
    for row, h in zip(K, heard, strict=True):
        assert np.all(row[~h] == 0.0)  # exact zeros off the pattern
        assert np.any(row[h] != 0.0)
    h2 = _lyapunov_h2(A, B, Q, Bw, V, K)
    assert rep.check.h2 == pytest.approx(h2, rel=1e-9)
    assert h2 >= rep.h2_unstructured * (1 - 1e-9)  # a pattern never beats full information


def test_the_as_run_design_of_a_ring_names_the_key_and_the_layout():
    """The one feature a ring refuses that an open platoon has: the as-run design (no head
    vehicle; tests/test_as_run_design_platoon.py runs it on platoons)."""
    with pytest.raises(ConfigError) as err:
        spec_from_problem(_problem("ring", "structured", "as_run = true"))
    assert err.value.field == "synthesis.as_run"
    assert "kind = 'ring'" in err.value.message


def test_a_one_cav_platoon_is_the_lcc_string():
    """A platoon of one CAV is the ``kind = "lcc"`` string (every single-CAV feature now runs on
    open platoons): that string's linear model is the platoon's, bit for bit."""
    import lcc_synth as lcc

    platoon = lcc.system(size=6, cavs=[3])
    a, b = lcc.model(platoon), lcc.model(lcc.system("lcc", m=2, n=3))
    for X, Y in ((a.A, b.A), (a.B, b.B), (a.H, b.H)):
        np.testing.assert_array_equal(X, Y)


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_polished_structured_gain_is_a_local_minimum_of_its_true_h2_on_every_layout(layout):
    """The polish (after the LMI on one CAV, the Newton iteration on a platoon or ring) ends
    at a stationary point of the true H2 over the pattern: the central differences of the
    Lyapunov H2 computed here vanish on every free entry (within 1e-6 of the H2 per unit
    gain; measured 2e-9), and a step of +-1e-3 on any free entry never lowers it (brute
    force)."""
    spec, rep = _structured(layout)
    A, B, Q, Bw, V, _ = _truth(spec)
    K = np.atleast_2d(np.asarray(rep.K, float))
    h2 = _lyapunov_h2(A, B, Q, Bw, V, K)
    free = np.argwhere(K != 0.0)
    assert len(free) >= 6  # every CAV hears its own states and its neighbours'

    def h2_at(i, j, step):
        Kp = K.copy()
        Kp[i, j] += step
        return _lyapunov_h2(A, B, Q, Bw, V, Kp)

    for i, j in free:
        grad = (h2_at(i, j, 1e-6) - h2_at(i, j, -1e-6)) / 2e-6
        assert abs(grad) <= 1e-6 * h2, (i, j, grad)
        assert min(h2_at(i, j, 1e-3), h2_at(i, j, -1e-3)) >= h2 * (1 - 1e-12), (i, j)


#: The keys of ``lcc-synth synthesize --json`` per layout, in order, as printed before the two
#: report types became one (captured from the CLI; the JSON must not change).
ONE_CAV_KEYS = ["problem", "design", "kind", "m", "n", "v_star", "semantics", "weights",
                "disturbances", "pattern", "state_names", "K", "gains", "input_K", "input_kh",
                "check", "h2_lmi_bound", "h2_restriction", "h2_unstructured", "solver",
                "polish", "baseline", "pareto", "timings", "notes", "as_run"]
PER_CAV_KEYS = ["problem", "design", "kind", "size", "cavs", "ring", "v_star", "circumference",
                "semantics", "weights", "disturbances", "patterns", "comm_range",
                "state_names", "K", "gains", "input_K", "input_kh", "check",
                "h2_unstructured", "conserved", "stages", "polish", "robust", "pareto",
                "timings", "notes"]  # fmt: skip
#: The keys of the JSON ``check`` object per layout, in order, as printed before the two check
#: types became one.
ONE_CAV_CHECK_KEYS = ["h2", "max_real_eig", "max_real_eig_model", "plant_stable",
                      "string_stable", "gamma_peak", "gamma_peak_omega", "string_verdict",
                      "string_margin"]
PER_CAV_CHECK_KEYS = ["h2", "max_real_eig", "stable", "subspace", "max_real_eig_full",
                      "conserved_mode"]  # fmt: skip


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_one_spec_and_one_report_type_keep_each_layouts_json(layout):
    import pickle

    from lcc_synth.synthesis.config import SynthesisSpec
    from lcc_synth.synthesis.report import UNSET, GainCheck, SynthesisReport

    spec = spec_from_problem(_problem(layout, "structured"))
    rep = synthesize(spec)
    assert type(spec) is SynthesisSpec and type(rep) is SynthesisReport
    assert type(rep.check) is GainCheck  # one check type too
    one_cav = layout == "one_cav_string"
    assert rep.per_cav is not one_cav
    d = rep.as_dict()
    assert list(d) == (ONE_CAV_KEYS if one_cav else PER_CAV_KEYS)
    assert list(d["check"]) == (ONE_CAV_CHECK_KEYS if one_cav else PER_CAV_CHECK_KEYS)
    assert UNSET not in d.values() and UNSET not in d["check"].values()
    # the CLI designs in a child process: the report crosses it unchanged, UNSET included
    back = pickle.loads(pickle.dumps(rep))
    assert back == rep and back.as_dict() == d
    assert (back.m is UNSET) is not one_cav and (back.cavs is UNSET) is one_cav
    assert (back.check.gamma_peak is UNSET) is not one_cav
    assert (back.check.subspace is UNSET) is one_cav
    assert "UNSET" not in repr(rep) and "UNSET" not in repr(rep.check)


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_spec_of_every_layout_round_trips_through_its_toml(layout):
    from dataclasses import replace

    extra = "[synthesis.sparsity]\nmax_loss = 0.05" if layout != "one_cav_string" else ""
    for design in ("structured", "sparsity"):
        spec = spec_from_problem(_problem(layout, design, extra if design == "sparsity" else ""))
        back = spec_from_problem(Problem(Path("back.toml"), tomllib.loads(spec.to_toml())))
        assert replace(back, source=spec.source) == spec
        assert back.max_loss == (0.05 if extra and design == "sparsity" else 0.01)


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_sparsity_reports_the_true_h2_of_a_sparser_gain_on_every_layout(layout):
    """``design = "sparsity"`` (the one-CAV Pareto sweep, the per-CAV range front of a platoon
    or ring): the chosen gain drops links (exact zeros), its reported H2 is its Lyapunov H2
    computed here, and no pattern beats the Riccati optimum (CARE, computed here)."""
    spec = spec_from_problem(_problem(layout, "sparsity"))
    rep = synthesize(spec)
    A, B, Q, Bw, V, _ = _truth(spec)
    K = np.atleast_2d(np.asarray(rep.K, float))
    assert K.shape == (B.shape[1], A.shape[0])
    assert 0 < np.count_nonzero(K) < K.size
    P = sla.solve_continuous_are(V.T @ A @ V, V.T @ B, V.T @ Q @ V, R * np.eye(B.shape[1]))
    h2_star = float(np.sqrt(np.trace((V.T @ Bw).T @ P @ (V.T @ Bw))))
    assert rep.h2_unstructured == pytest.approx(h2_star, rel=1e-8)
    h2 = _lyapunov_h2(A, B, Q, Bw, V, K)
    assert rep.check.h2 == pytest.approx(h2, rel=1e-9)
    assert h2 >= h2_star * (1 - 1e-9)


_ROBUST = ('[synthesis.robust]\nsamples = 4\nseed = 3\nobjective = "mean"\n'
           "alpha = [0.45, 0.75]\nbeta = [0.7, 1.1]\n")  # fmt: skip


@pytest.mark.parametrize("layout", ["two_cav_platoon", "ring"])
def test_robust_gain_is_stable_on_every_member_and_beats_the_nominal_on_every_layout(layout):
    """``[synthesis.robust]``: one structured gain for sampled HDV parameter sets. On each
    member (rebuilt here from the sampled platoon) the closed loop is stable on the space its
    dynamics keep, and the mean of the members' Lyapunov H2 (computed here) is no worse than
    that of the nominal structured gain."""
    from lcc_synth.models.platoon import platoon_model
    from lcc_synth.synthesis.config import robust_members

    spec = spec_from_problem(_problem(layout, "structured", _ROBUST))
    K = np.atleast_2d(np.asarray(synthesize(spec).K, float))
    Kn = np.atleast_2d(np.asarray(synthesize(spec_from_problem(_problem(layout, "structured"))).K,
                                  float))  # fmt: skip
    assert not np.array_equal(K, Kn)  # the members were used
    members = robust_members(spec.system, spec.robust)
    assert len(members) == 4 and len({m.hdv for m in members}) == 4
    h_rob, h_nom = [], []
    for platoon in members:  # _truth of the member's own linear model
        model = platoon_model(platoon, warn=False)
        A, B, Q, Bw, V, _ = _truth(SimpleNamespace(system=SimpleNamespace(
            linear_model=lambda warn, model=model: model)))  # fmt: skip
        for gain, out in ((K, h_rob), (Kn, h_nom)):
            assert np.max(np.linalg.eigvals(V.T @ (A + B @ gain) @ V).real) < 0
            out.append(_lyapunov_h2(A, B, Q, Bw, V, gain))
    assert np.mean(h_rob) <= np.mean(h_nom) * (1 + 1e-9)


def test_robust_design_on_one_cav_is_read_for_its_one_cav_platoon():
    """One CAV behind a head vehicle reads ``[synthesis.robust]`` too (designed on its one-CAV
    platoon: tests/test_robust_one_cav.py); the platoon vocabulary's keys stay refused."""
    spec = spec_from_problem(_problem("one_cav_string", "structured", _ROBUST))
    assert (spec.robust.samples, spec.robust.seed, spec.method) == (4, 3, "direct")
    assert spec.pattern == (1, 2) and spec.system.platoon is None
    with pytest.raises(ConfigError) as err:
        spec_from_problem(_problem("one_cav_string", "structured", "comm_range = 1"))
    assert err.value.field == "synthesis.comm_range"
    assert "kind = 'cf_lcc'" in err.value.message


# --------------------------------------------------------------------------------------------
# The feature matrix of lcc_synth.synthesis, cell by cell
# --------------------------------------------------------------------------------------------

_MATRIX_ROBUST = "[synthesis.robust]\nsamples = 2\nalpha = [0.5, 0.7]\n"
#: the matrix's option -> (design, the [synthesis] lines that ask for it)
_MATRIX_ROWS = {
    'design = "full_state"': ("full_state", ""),
    'design = "structured"': ("structured", ""),
    'design = "sparsity"': ("sparsity", ""),
    'design = "string_stable"': ("string_stable", ""),
    'method = "lmi"': ("structured", 'method = "lmi"'),
    "cross_check = true": ("full_state", "cross_check = true"),
    "band": ("structured", 'method = "lmi"\nband = 3'),
    "[synthesis.robust]": ("structured", _MATRIX_ROBUST),
    'robust, method = "lmi"': ("structured", 'method = "lmi"\n' + _MATRIX_ROBUST),
    "robust, sparsity": ("sparsity", _MATRIX_ROBUST),
    "robust, string_stable": ("string_stable", _MATRIX_ROBUST),
    "cav_lag": ("structured", "cav_lag = 0.3"),
    "cav_lag, full_state": ("full_state", "cav_lag = 0.3"),
    "cav_lag, sparsity": ("sparsity", "cav_lag = 0.3"),
    'cav_lag, method = "lmi"': ("structured", 'cav_lag = 0.3\nmethod = "lmi"'),
    "cav_lag, string_stable": ("string_stable", "cav_lag = 0.3"),
    "cav_lag, robust": ("structured", "cav_lag = 0.3\n" + _MATRIX_ROBUST),
    "[synthesis.as_run]": ("structured", "as_run = true"),
    "[synthesis.baseline]": ("structured", "[synthesis.baseline]\ngains = {BASELINE_GAINS}"),
    "pattern = [...]": ("structured", "pattern = [1]"),
    "comm_range": ("structured", "comm_range = 1"),
}


#: the baseline gains of each layout, in its vocabulary (state names; a row per CAV input)
_MATRIX_BASELINE = {"one_cav_string": "{ s_1 = 0.1 }", "two_cav_platoon": "{ u_2 = { s_3 = 0.1 } }",
                    "ring": "{ u_4 = { s_5 = 0.1 } }"}  # fmt: skip


def _matrix() -> dict[str, dict[str, str]]:
    """The table of the package docstring: option -> {layout: cell}."""
    import re

    import lcc_synth.synthesis as syn

    lines = syn.__doc__.split("Feature matrix")[1].split("::\n\n")[1].split("\n\n")[0]
    head, *rows = lines.splitlines()
    cols = re.split(r"\s{2,}", head.strip())[1:]
    assert cols == ["one CAV", "platoon", "ring"]
    out = {}
    for row in rows:
        option, *cells = re.split(r"\s{2,}", row.strip())
        out[option] = dict(zip(("one_cav_string", "two_cav_platoon", "ring"), cells, strict=True))
    return out


def test_the_feature_matrix_lists_every_checked_option():
    assert list(_matrix()) == list(_MATRIX_ROWS)


@pytest.mark.parametrize("layout", list(LAYOUTS))
@pytest.mark.parametrize("option", list(_MATRIX_ROWS))
def test_every_cell_of_the_feature_matrix_is_what_the_parser_does(option, layout):
    """A "yes" parses into a spec (its designs run in the tests the docstring names); a
    "no: KEY" is one ConfigError naming ``synthesis.KEY`` and the combination."""
    design, extra = _MATRIX_ROWS[option]
    extra = extra.replace("{BASELINE_GAINS}", _MATRIX_BASELINE[layout])
    cell = _matrix()[option][layout]
    system, pattern = LAYOUTS[layout]
    head = 0.0 if layout == "ring" else 0.5  # string_stable needs the head disturbance
    text = (f'name = "m"\n{HDV}[system]\n{system}\n[synthesis]\ndesign = "{design}"\n'
            f'semantics = "replace"\n{extra}\n[synthesis.weights]\nq_s = {Q_S}\nr = {R}\n'
            f"head = {head}\naccel = 1.0\n")  # fmt: skip
    problem = Problem(Path("m.toml"), tomllib.loads(text))
    if cell == "yes":
        spec = spec_from_problem(problem)
        assert spec.design == design
        return
    assert cell.startswith("no: ")
    with pytest.raises(ConfigError) as err:
        spec_from_problem(problem)
    assert err.value.field == f"synthesis.{cell[4:]}", err.value
