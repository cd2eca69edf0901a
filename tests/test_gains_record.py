"""One gains record for every layout (:class:`lcc_synth.models.feedback.Gains`).

Proofs against independent truth:

* the closed loops of the paper's gains (Table II's CF-LCC and FD-LCC gains, Sec. V-B,
  "replace"; Table I's case D, Sec. IV-B, "added" on the HDV law, eq. 23) equal the matrices
  written here from the paper's equations (8), (9), (11), (12) and the OVM linearisation at
  v* = 15 m/s (alpha1 = alpha V'(s*) = 0.6 pi / 2, alpha2 = alpha + beta, alpha3 = beta), entry
  for entry;
* gains files written by the previous version (``tests/data/gains/``, one per form) are read
  into the gains that version read: the file's own ``K`` rows on its ``state_names`` and its
  ``gains`` table, entry for entry;
* ``s_1`` names vehicle 1 of the layout the gain is on, and a gain of one layout is refused
  by a model of another.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import model_from_hdv
from lcc_synth.models.platoon import Platoon, platoon_model
from lcc_synth.problem import load_problem, system_from
from lcc_synth.synthesis.gains_file import read_gains

DATA = Path(__file__).parent / "data" / "gains"
PROBLEMS = Path(__file__).parent.parent / "problems"

# OVM of the paper (alpha 0.6, beta 0.9, s_st 5, s_go 35, v_max 30) at v* = 15: s* = 20 and
# V'(s*) = v_max pi / (2 (s_go - s_st)) = pi / 2.
A1, A2, A3 = 0.6 * math.pi / 2, 0.6 + 0.9, 0.9

TABLE2_CF = {"s_0": 0.1, "v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}
TABLE2_FD = {"v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}
CASE_D_MU = {-2: 1.0, -1: 1.0, 1: -1.0, 2: -1.0}
CASE_D_K = {-2: -1.0, -1: -1.0, 1: -1.0, 2: -1.0}


def _paper_loop(vehicles, gain, cav_law: bool, head: bool):
    """``(A_cl, H_cl)`` written from the paper: two states per vehicle of ``vehicles``
    (front to tail, the CAV is 0), HDVs by eq. (8), the CAV's acceleration ``sum(gain *
    state)`` plus, with ``cav_law``, its HDV law towards the vehicle ahead (eq. 23)."""
    idx = {}
    for j, i in enumerate(vehicles):
        idx[f"s_{i}"], idx[f"v_{i}"] = 2 * j, 2 * j + 1
    nx = 2 * len(vehicles)
    A, H = np.zeros((nx, nx)), np.zeros(nx)
    for j, i in enumerate(vehicles):
        s, v = 2 * j, 2 * j + 1
        first = j == 0
        if i == 0 and not head:  # FD-LCC: the first state is -p_0, d(-p_0)/dt = -v_0
            A[s, v] = -1.0
        else:
            A[s, v] = -1.0
            if first:
                H[s] = 1.0
            else:
                A[s, v - 2] = 1.0
        if i != 0 or cav_law:
            A[v, s] += A1
            A[v, v] += -A2
            if first:
                H[v] += A3
            else:
                A[v, v - 2] += A3
        if i == 0:
            for name, g in gain.items():
                A[v, idx[name]] += g
    return A, H


@pytest.mark.parametrize(
    ("kind", "m", "n", "gain", "semantics"),
    [
        ("cf_lcc", 0, 10, TABLE2_CF, "replace"),
        ("fd_lcc", 0, 10, TABLE2_FD, "replace"),
        ("lcc", 2, 2, None, "added"),
        ("cf_lcc", 0, 3, TABLE2_CF, "added"),
    ],
)
def test_closed_loop_of_paper_gains_is_the_papers(kind, m, n, gain, semantics):
    model = model_from_hdv(kind, m, n, OVM(), 15.0, warn=False)
    g = (Gains.from_paper(CASE_D_MU, CASE_D_K, semantics) if gain is None
         else Gains.named(gain, semantics))  # fmt: skip
    named = g.gains
    A, H = _paper_loop(list(range(-m, n + 1)), named, semantics == "added", kind != "fd_lcc")
    A_cl, H_cl = g.closed_loop(model)
    # alpha1 here (0.6 pi / 2) and the package's (alpha V'(s*) from the OVM) differ by 1 ulp,
    # and the CF-LCC law is added and taken off again: entries O(1), so 1e-15 is a few ulp
    np.testing.assert_allclose(A_cl, A, rtol=0, atol=1e-15)
    np.testing.assert_allclose(H_cl.ravel(), H, rtol=0, atol=1e-15)
    assert np.count_nonzero(A_cl) == np.count_nonzero(A)  # the same pattern: no stray entry


def test_paper_view_round_trips_the_named_gains():
    g = Gains.from_paper(CASE_D_MU, CASE_D_K, "added")
    assert g.cavs == (0,) and g.paper() == (CASE_D_MU, CASE_D_K)
    assert g.gains == {"s_-2": 1.0, "s_-1": 1.0, "s_1": -1.0, "s_2": -1.0, "v_-2": -1.0,
                       "v_-1": -1.0, "v_1": -1.0, "v_2": -1.0}  # fmt: skip
    assert g == Gains.named(g.gains, "added") and g != Gains.named(g.gains, "replace")
    assert g == Gains.named(dict(reversed(g.gains.items())), "added")  # by name, not position
    assert g != Gains.named({**g.gains, "s_0": 0.0}, "added")  # another set of named states
    assert g.vehicles() == [-2, -1, 1, 2]


def test_s_1_is_vehicle_1_of_the_layout_and_layouts_do_not_mix():
    paper = model_from_hdv("lcc", 2, 2, OVM(), 15.0, warn=False)
    g = Gains.named({"s_1": 1.0}, "replace")
    # the paper's vehicle 1 is the first HDV behind the CAV: the fourth block (-2, -1, 0, 1, 2)
    assert np.flatnonzero(g.matrix(paper)).tolist() == [6]
    chain = platoon_model(Platoon((OVM(),) * 5, (3,), 15.0), warn=False)
    p = Gains.from_table({"u_3": {"s_1": 1.0}}, chain)
    # the platoon's vehicle 1 is the first behind the head: the first block
    assert np.flatnonzero(p.matrix(chain)).tolist() == [0]
    assert p.as_table() == {"u_3": {"s_1": 1.0}}
    with pytest.raises(ConfigError, match=r"^gains: are for CAVs \[0\]; the model has CAVs \[3\]"):
        g.matrix(chain)
    with pytest.raises(ConfigError, match=r"^gains: are for CAVs \[3\]; the model has CAVs \[0\]"):
        p.input_feedback(paper)


def test_entries_are_checked_and_named():
    with pytest.raises(ConfigError, match=r"^gains\.u_6\.v_2: must be finite"):
        Gains(np.array([[0.0, 1.0], [0.0, np.inf]]), (3, 6), ("s_2", "v_2"), "added")
    with pytest.raises(ConfigError, match=r"^gains\.s_1: must be in \[-1e\+12, 1e\+12\]"):
        Gains.named({"s_1": 1e13}, "added")
    with pytest.raises(ConfigError, match=r"^gains: needs one row per CAV \(2: \[3, 6\]\)"):
        Gains(np.zeros((1, 2)), (3, 6), ("s_2", "v_2"), "added")
    with pytest.raises(ConfigError, match=r"^gains: names a state twice"):
        Gains(np.zeros((1, 2)), (0,), ("s_2", "s_2"), "added")
    with pytest.raises(ConfigError, match=r"^semantics: must be one of"):
        Gains.named({}, "both")


def _expected(doc):
    """What the previous version read from a gains file: its ``K`` on ``state_names`` (one
    row per CAV) and its ``gains`` table."""
    K = np.atleast_2d(np.array(doc["K"], float))
    return K, list(doc["state_names"]), doc["gains"]


@pytest.mark.parametrize(
    ("name", "problem"),
    [
        ("fd_lcc_pattern.json", "synth_fd_lcc_pattern.toml"),
        ("lcc_m2n2_string_stable.json", "synth_string_stable_m2n2.toml"),
        ("ring_sugiyama.json", "synth_ring_sugiyama.toml"),
    ],
)
def test_files_of_the_previous_version_read_the_same_gains(name, problem):
    """The committed files were written by ``lcc-synth synthesize PROBLEM --out`` before the
    two gains types became one."""
    path = DATA / name
    doc = json.loads(path.read_text(encoding="utf-8"))
    K, names, table = _expected(doc)
    system = system_from(load_problem(PROBLEMS / problem).data)
    gains, read_doc = read_gains(path, system=system)
    assert read_doc == doc and gains.semantics == doc["semantics"]
    model = system.linear_model(warn=False)
    if doc["kind"] in ("platoon", "ring"):
        assert gains.cavs == tuple(doc["cavs"]) and gains.states == tuple(names)
        assert gains.as_table() == table
    else:
        assert gains.cavs == (0,) and gains.gains == table
    assert list(model.state_names) == names
    got = gains.matrix(model)
    assert got.shape == K.shape and np.array_equal(got, K)  # bit for bit


def test_the_flat_api_reads_a_gains_file_of_either_form():
    import lcc_synth as lcc

    ring = system_from(load_problem(PROBLEMS / "synth_ring_sugiyama.toml").data)
    fd = system_from(load_problem(PROBLEMS / "synth_fd_lcc_pattern.toml").data)
    for name, system in (("ring_sugiyama.json", ring), ("fd_lcc_pattern.json", fd)):
        assert lcc.gains(str(DATA / name), model=system) == read_gains(DATA / name)[0]
    with pytest.raises(ConfigError, match=r"^semantics: 'replace' contradicts the gains' 'added'"):
        lcc.gains(DATA / "ring_sugiyama.json", "replace")
    with pytest.raises(ConfigError, match=r"ring_sugiyama\.json: kind: 'ring': a gains file for "
                       r"a platoon or ring .*; the problem has kind='fd_lcc'"):
        lcc.gains(DATA / "ring_sugiyama.json", model=fd)
