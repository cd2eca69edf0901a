"""The DeeP-LCC paper's spacing target (``constraints.spacing = "equilibrium"``) of the one MPC
and of DeeP-LCC.

Independent truth: the OVM's equilibrium spacing in closed form, ``s*(v) = s_st + (s_go -
s_st) / pi * arccos(1 - 2 v / v_max)`` (eq. (2)-(4) of the LCC paper solved for the spacing),
evaluated here at the controller's recorded ``v_eq``, and the spacings the simulator
measured. The QP's spacing rows, evaluated on a random input plan with the prediction model
simulated in numpy (not the CasADi condensation), must be the distance of the predicted
ABSOLUTE spacing to ``s*(v_eq) + lo + margin`` (lower rows) and from ``s*(v_eq) + hi -
margin`` (upper rows), on one CAV (CF-LCC, and FD-LCC whose spacing is predicted from the
measured one), a two-CAV platoon and the ring (whose reference spacings are ``s*(v_eq)``
shifted by the mean measured offset, so that they sum to the circumference).
"""

from __future__ import annotations

import copy
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lcc_synth.errors import ConfigError
from lcc_synth.experiments.spec import load_spec
from lcc_synth.mpc import mpc_controller_from_table
from lcc_synth.problem import load_problem
from lcc_synth.simulation.engine import simulate

ROOT = Path(__file__).resolve().parents[1]
BRAKE = ROOT / "problems" / "mpc_head_brake.toml"
PLATOON = ROOT / "problems" / "platoon_deeplcc_brake.toml"
RING = ROOT / "problems" / "ring_stop_and_go.toml"
FD = ROOT / "problems" / "mpc_table2_fd.toml"
PAPER = {"spacing": "equilibrium", "spacing_error": [-15.0, 20.0]}


def ovm_spacing(h, v: float) -> float:
    """The OVM's equilibrium spacing at ``v`` in closed form."""
    return h.s_st + (h.s_go - h.s_st) / math.pi * math.acos(1.0 - 2.0 * v / h.v_max)


def _closed_loop(path: Path, table: dict, duration: float):
    """Run the MPC of ``table`` on the file's scenario for ``duration`` s, recording the QP
    vectors of every sample."""
    spec = load_spec(path)
    ctrl = mpc_controller_from_table("mpc", table, spec.system)
    calls = []
    orig = ctrl.formulation.bounds

    def rec(*a, **k):
        out = orig(*a, **k)
        calls.append(out)
        return out

    ctrl.formulation.bounds = rec
    res = simulate(replace(spec.scenario, duration=duration), ctrl)
    return spec, ctrl, res, calls[1:]  # calls[0]: the set-up of reset()


def _check_rows(ctrl, res, calls, samples, cav_cols, s_target, s_index):
    """On each sample: A z - l of every spacing row (random plan, zero slack) against the
    predicted absolute spacing's distance to the bound (module docstring). ``cav_cols[j]`` is
    the array column of CAV ``j``, ``s_target(k)[j]`` its target spacing at sample ``k``,
    ``s_index[j]`` its spacing state."""
    form, h = ctrl.formulation, ctrl.history()
    mem = ctrl._members[0]
    lo_e, hi_e = ctrl.settings.constraints.spacing_error
    margin = ctrl.settings.constraints.margin
    N, NU = form.N, form.n_input
    A = mem.qp.A.toarray()
    rng = np.random.default_rng(5)
    checked = []
    for k in samples:
        _, lo, _ = calls[k]
        U = rng.uniform(-1.0, 1.0, NU)
        z = np.concatenate([U, np.zeros(form.nz - NU)])
        r = A @ z - lo
        X = mem.lin.predict(h["x0"][0, k], h["d"][0, k], U)
        i = int(np.argmin(np.abs(res.t - h["t"][k])))
        for j, (col, si) in enumerate(zip(cav_cols, s_index, strict=True)):
            s_meas = float(res.spacing[0, i, col])
            target = s_target(k, i)[j]
            s_pred = s_meas + X[1:, si] - X[0, si]  # absolute predicted spacing, k = 1..N
            f_lo, f_hi = 2 * j, 2 * j + 1
            np.testing.assert_allclose(r[NU + f_lo * N:NU + (f_lo + 1) * N],
                                       s_pred - (target + lo_e + margin), atol=1e-8)
            np.testing.assert_allclose(r[NU + f_hi * N:NU + (f_hi + 1) * N],
                                       (target + hi_e - margin) - s_pred, atol=1e-8)
            checked.append(target)
    return np.array(checked)


def test_one_cav_rows_follow_the_ovm_equilibrium_spacing_of_v_eq():
    """CF-LCC, one CAV and 10 HDVs (``problems/mpc_head_brake.toml``): during the head's
    brake the target ``s*(v_eq)`` falls by metres and the rows follow it."""
    table = copy.deepcopy(load_problem(BRAKE).data["controllers"]["mpc"])
    table.setdefault("constraints", {}).update(PAPER)
    spec, ctrl, res, calls = _closed_loop(BRAKE, table, 30.0)
    assert [f.bound for f in ctrl._families] == ["error_min", "error_max"]
    h = ctrl.history()
    hdv = spec.system.hdv
    m = spec.system.m
    s_idx = ctrl._lin0.model.block(0).start
    samples = range(200, 300, 7)  # t = 20-30 s: the brake and the hold

    def target(k, i):
        return [ovm_spacing(hdv, float(h["v_eq"][0, k]))]

    t = _check_rows(ctrl, res, calls, samples, [m + 1], target, [s_idx])
    assert t.max() - t.min() > 3.0, t  # the bound moved with v_eq


def test_fd_lcc_rows_predict_the_spacing_from_the_measured_one():
    """FD-LCC (``problems/mpc_table2_fd.toml``: fixed v* = 15 m/s, the head cruising ahead,
    vehicle 1 braking behind): the state has no spacing of the CAV; its predicted spacing is
    the measured one plus the CAV's predicted displacement from the reference (``-p_0``), and
    the rows bound that against ``s*(15) = 20 m``."""
    table = copy.deepcopy(load_problem(FD).data["controllers"]["mpc"])
    table.pop("fallback", None)
    table.setdefault("constraints", {}).update(PAPER)
    spec, ctrl, res, calls = _closed_loop(FD, table, 25.0)
    i_s = [int(np.argmin(np.abs(res.t - t))) for t in ctrl.history()["t"]]
    assert np.all(res.velocity[0, i_s, 0] == spec.system.v_star)  # head error d = 0: no drift

    def target(k, i):
        return [ovm_spacing(spec.system.hdv, spec.system.v_star)]

    _check_rows(ctrl, res, calls, range(195, 250, 6), [1], target, [0])


def test_two_cav_platoon_rows_use_each_cavs_own_equilibrium_spacing():
    """The DeeP-LCC paper's platoon (CAVs at 3 and 6 of 8 heterogeneous OVM vehicles): each
    CAV's rows follow its own slot's ``s*(v_eq)``."""
    table = {"type": "mpc", "sample_time": 0.1, "horizon": 50, "constraints": dict(PAPER)}
    spec, ctrl, res, calls = _closed_loop(PLATOON, table, 6.0)
    pl = spec.system.platoon
    assert [(f.vehicle, f.bound) for f in ctrl._families] == [
        (3, "error_min"), (3, "error_max"), (6, "error_min"), (6, "error_max")]
    h = ctrl.history()

    def target(k, i):
        v = float(h["v_eq"][0, k])
        return [ovm_spacing(pl.hdv[p - 1], v) for p in pl.cavs]

    t = _check_rows(ctrl, res, calls, range(10, 60, 6), list(pl.cavs),
                    target, [2 * p - 2 for p in pl.cavs])
    assert t.max() - t.min() > 3.0, t


def test_ring_rows_use_the_reference_spacing_summing_to_the_circumference():
    """The ring (one AV in 20 vehicles): the target is ``s*(v_eq)`` plus the mean offset of
    the measured spacings from it (every reference shifted alike, summing to C)."""
    spec0 = load_spec(RING)
    table = copy.deepcopy(load_problem(RING).data["controllers"]["mpc"])
    table.pop("fallback", None)  # names another controller of the file: the default here
    table.setdefault("constraints", {}).update(PAPER)
    spec, ctrl, res, calls = _closed_loop(RING, table, 12.0)
    pl = spec0.system.platoon
    h = ctrl.history()
    cols = np.arange(pl.size)

    def target(k, i):
        v = float(h["v_eq"][0, k])
        s_star = np.array([ovm_spacing(hh, v) for hh in pl.hdv])
        delta = float(np.mean(res.spacing[0, i, cols] - s_star))
        return [s_star[p - 1] + delta for p in pl.cavs]

    _check_rows(ctrl, res, calls, range(40, 120, 9), [p - 1 for p in pl.cavs], target,
                [2 * p - 2 for p in pl.cavs])


# slow: 7 s; the pinned platoon and showcase tables guard the default as well
@pytest.mark.slow
def test_default_and_explicit_safe_give_the_same_run_bit_for_bit():
    """``spacing = "safe"`` (with any ``spacing_error``) is the default: same families, same
    commands and trajectories, bit for bit; the paper's target changes the run."""
    base = {"type": "mpc", "sample_time": 0.1, "horizon": 50}
    runs = {}
    for name, extra in (("default", {}),
                        ("safe", {"constraints": {"spacing": "safe",
                                                  "spacing_error": [-1.0, 1.0]}}),
                        ("paper", {"constraints": dict(PAPER)})):  # fmt: skip
        _, ctrl, res, _ = _closed_loop(PLATOON, {**base, **extra}, 20.0)
        runs[name] = (ctrl, res)
    (c0, r0), (c1, r1), (c2, r2) = runs["default"], runs["safe"], runs["paper"]
    assert c0._families == c1._families and all(f.bound == "safe" for f in c0._families)
    np.testing.assert_array_equal(c0.history()["u"], c1.history()["u"])
    np.testing.assert_array_equal(r0.velocity, r1.velocity)
    np.testing.assert_array_equal(r0.spacing, r1.spacing)
    assert [f.bound for f in c2._families] == ["error_min", "error_max"] * 2
    assert not np.array_equal(r0.velocity, r2.velocity)


@pytest.mark.parametrize(("constraints", "field", "words"), [
    ({"spacing": "paper"}, "controllers.mpc.constraints.spacing", "equilibrium"),
    ({"spacing": "equilibrium", "spacing_error": [5.0, 20.0]},
     "controllers.mpc.constraints.spacing_error", "lo < 0 < hi"),
    ({"spacing": "equilibrium", "spacing_error": [-15.0]},
     "controllers.mpc.constraints.spacing_error", "2"),
])  # fmt: skip
def test_bad_values_name_the_field(constraints, field, words):
    spec = load_spec(PLATOON)
    table = {"type": "mpc", "constraints": constraints}
    with pytest.raises(ConfigError) as err:
        mpc_controller_from_table("mpc", table, spec.system)
    assert err.value.field == field and words in str(err.value)


def test_deep_lcc_bad_values_name_the_field():
    from lcc_synth.deeplcc.settings import deep_settings_from_table

    f = "controllers.deep_lcc"
    with pytest.raises(ConfigError) as err:
        deep_settings_from_table({"type": "deep_lcc", "constraints": {"spacing": "x"}}, f)
    assert err.value.field == f"{f}.constraints.spacing"
    with pytest.raises(ConfigError) as err:
        deep_settings_from_table({"type": "deep_lcc", "constraints": {
            "spacing": "equilibrium", "spacing_error": [-15.0, -1.0]}}, f)  # fmt: skip
    assert err.value.field == f"{f}.constraints.spacing_error"


def test_deep_lcc_upper_rows_are_the_negated_spacing_errors_with_their_own_slacks():
    """DeeP-LCC's QP with the paper's target (reduced on random data of the right shape):
    the spacing map ``W`` reads the CAV spacing errors alone (no time gap); the upper rows
    are the lower rows negated on ``(v_u, beta)``, each with its own slack; the bounds are
    ``lo + margin`` and ``-(hi - margin)`` on the spacing errors from ``s_eq``; the default
    (``"safe"``) QP has no upper rows and equals the QP built without the option."""
    from lcc_synth.deeplcc.hankel import ReducedQP, spacing_rows
    from lcc_synth.deeplcc.qp import formulate
    from lcc_synth.mpc.formulation import error_bound, spacing_families
    from lcc_synth.mpc.settings import Constraints

    N, n_c, p = 6, 2, 9
    W = spacing_rows(N, p, [2, 5], 0.0)
    assert np.count_nonzero(W) == N * n_c  # one entry per row: the spacing error output
    rng = np.random.default_rng(0)
    n = N * n_c
    Bf = rng.normal(size=(2 * n, 2 * n))
    Gamma = Bf @ Bf.T
    red = ReducedQP(Gamma, np.zeros((2 * n, 1)), np.zeros((2 * n, 1)), None, None, None, n, Bf)
    safe, paper = formulate(red, 100.0, 1.0), formulate(red, 100.0, 1.0, upper=True)
    assert safe.n_up == 0 and paper.n_up == n
    A = paper.qp.A.toarray()
    nb = paper.n_beta
    free = slice(0, n + nb)
    np.testing.assert_array_equal(A[3 * n:4 * n, free], -A[n:2 * n, free])
    np.testing.assert_array_equal(A[3 * n:4 * n, n + nb + n:], np.eye(n))  # own slacks
    np.testing.assert_array_equal(A[3 * n:4 * n, n + nb:n + nb + n], 0.0)
    np.testing.assert_array_equal(A[:3 * n, :n + nb + n], safe.qp.A.toarray())
    c = Constraints(spacing="equilibrium", spacing_error=(-15.0, 20.0), margin=0.1)
    lo_f, hi_f = spacing_families(0, 0, 0, c)
    c_vec = rng.normal(size=2 * n)
    _, lo, hi = paper.vectors(c_vec, -5.0, 2.0, np.full(n, error_bound(lo_f, 0.1)),
                              np.full(n, error_bound(hi_f, 0.1)))
    off = paper.Gc @ c_vec
    np.testing.assert_allclose((lo + off)[n:2 * n], -15.0 + 0.1)
    np.testing.assert_allclose((lo + off)[3 * n:4 * n], -(20.0 - 0.1))
    assert np.all(np.isinf(hi[3 * n:]))


def test_cli_refuses_a_bad_spacing_target_with_one_line(tmp_path):
    text = PLATOON.read_text() + '\n[controllers.mpc.constraints]\nspacing = "paper"\n'
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    env = {"PYTHONPATH": str(ROOT), "RERUN_ANALYTICS": "0", "MPLBACKEND": "Agg",
           "PATH": "/usr/bin:/bin"}  # fmt: skip
    out = subprocess.run([sys.executable, "-m", "lcc_synth.cli.main", "simulate", str(bad),
                          "--no-record", "-q"], capture_output=True, text=True, env=env,
                         timeout=120)  # fmt: skip
    assert out.returncode != 0
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "controllers.mpc.constraints.spacing" in lines[0], out.stderr
