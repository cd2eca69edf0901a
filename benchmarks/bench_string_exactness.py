"""String-stability verdicts against the exact rational reference (issue 19 measurements).

Over several hundred seeded gains of the paper's models -- random gains on random models,
gains near Table I's cases C/D, Riccati (H2) gains, string-aware designs and points on lines
through the string-stability boundary (low-frequency curvature c crossing 0, and an interior
peak crossing 1) -- the verdict of :func:`lcc_synth.analysis.string_stability.string_stability` for
``method="grid"`` and ``"hamiltonian"`` is compared with ``tests/exact_reference.py`` (exact
integer arithmetic, 50-digit mpmath peak). Also counted: verdict flips under harmless
transformations (state permutations, diagonal scalings, orthogonal and well-conditioned
similarity transforms, 1e-12 relative gain perturbations), and the calibration of the
tolerance band: ``max |q_computed - q_exact| / (eps kappa)`` at ``w = 0`` and at the exact
maximiser of ``q`` (``kappa = max(1, max|lambda| / min|lambda|)``; the band is
``tau = BAND_FACTOR eps kappa``).

Works with the code before the exact verdict (no ``loop_string_stability``: transformed loops
are fed by patching ``closed_loop``/``tail_output`` in the module) and after it.

Phases (default: all; each is cached in ``--cache``):
  sample   build the seeded sample (string-aware designs use whichever string_stability is
           imported: run it once with the old code, tag "old", and once with the new, "new")
  exact    exact verdicts of every sampled loop (BLAS-independent)
  measure  verdicts of both methods, flips, peaks and the calibration (depends on BLAS:
           run under several OPENBLAS_CORETYPE values)

Usage:
  python benchmarks/bench_string_exactness.py [--cache DIR] [--phase PHASE] [--label NAME]
  PYTHONPATH=/path/to/old/checkout python benchmarks/... --phase measure --label old-haswell
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sla

import lcc_synth.analysis.string_stability as ss
from lcc_synth.analysis.transfer import closed_loop_eigenvalues, tail_output
from lcc_synth.models.feedback import Gains, closed_loop, input_feedback
from lcc_synth.models.hdv import OVM, LinearCoefficients
from lcc_synth.models.linear import build_model, general_lcc, model_from_hdv

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
from exact_reference import exact_string_verdict  # noqa: E402

EPS = float(np.finfo(float).eps)
# Table I and the random models/gains of tests/test_string_stability.py (copied: that module's
# imports follow the current code, the benchmark also runs against older checkouts)
TABLE_I = {
    "hdv_only": {},
    "case_a": {"s_-2": 1, "v_-2": -1},
    "case_b": {"s_-2": 1, "v_-2": -1, "s_-1": 1, "v_-1": -1},
    "case_c": {"s_-2": 1, "v_-2": -1, "s_-1": 1, "v_-1": -1, "s_1": -1, "v_1": -1},
    "case_d": {
        "s_-2": 1, "v_-2": -1, "s_-1": 1, "v_-1": -1, "s_1": -1, "v_1": -1, "s_2": -1, "v_2": -1,
    },
}  # fmt: skip


def random_coefs(rng) -> LinearCoefficients:
    while True:
        a3 = rng.uniform(0.1, 2.0)
        a2 = a3 + rng.uniform(0.1, 2.0)
        a1 = rng.uniform(0.05, 3.0)
        c = LinearCoefficients(a1, a2, a3)
        if abs(c.controllability_margin) > 0.05:
            return c


def random_model(rng, kind="lcc"):
    m = 0 if kind == "cf_lcc" else int(rng.integers(0 if kind == "lcc" else 1, 4))
    n = 0 if kind == "ccc" else int(rng.integers(1, 4))
    coefs = [random_coefs(rng) for _ in range(m + n)]
    return build_model(kind, m, n, coefs, cav=random_coefs(rng))


def random_gains(rng, model, scale=2.0) -> Gains:
    names = list(model.state_names)
    pick = rng.choice(names, size=int(rng.integers(1, len(names) + 1)), replace=False)
    return Gains.named({str(p): float(rng.uniform(-scale, scale)) for p in pick})


NEW_API = hasattr(ss, "loop_string_stability")
CODE_TAG = "new" if NEW_API else "old"
# the verdict balances the loop first (exact powers of 2): calibrate q the same way
BALANCED = NEW_API and "matrix_balance" in inspect.getsource(ss.loop_string_stability)
PAPER = OVM().linear_coefficients(15.0)
HDV = OVM(alpha=0.6, beta=0.9, s_st=5.0, s_go=35.0, v_max=30.0)
TRANSFORMS = ("perm", "perm", "diag", "diag", "similar", "similar", "orth", "orth", "gain", "gain")


# --------------------------------------------------------------------------------------------
# Sample
# --------------------------------------------------------------------------------------------


def _spec(model) -> dict:
    coefs = [model.coefficients[i] for i in model.vehicles if i != 0]
    cav = model.coefficients[0]
    return {
        "kind": model.kind,
        "m": model.m,
        "n": model.n,
        "coefs": [(c.alpha1, c.alpha2, c.alpha3) for c in coefs],
        "cav": (cav.alpha1, cav.alpha2, cav.alpha3),
    }


def _model(spec: dict):
    coefs = [LinearCoefficients(*c) for c in spec["coefs"]]
    return build_model(spec["kind"], spec["m"], spec["n"], coefs, LinearCoefficients(*spec["cav"]))


def _case(group: str, model, K, kh, note: str = "") -> dict:
    return {
        "group": group,
        "spec": _spec(model),
        "K": np.asarray(K, float).copy(),
        "kh": float(kh),
        "note": note,
        "nx": model.nx,
    }


def _loop(model, K, kh):
    A, H = closed_loop(model, K, kh)
    return A, H.reshape(-1), tail_output(model)


def _exact_fast(model, K, kh):
    return exact_string_verdict(*_loop(model, K, kh), peak=False, q=False)


def _table_cases(model):
    out = {}
    for name, g in TABLE_I.items():
        gg = {k: v for k, v in g.items() if k in model.state_names}
        out[name] = input_feedback(model, Gains.named(gg))
    return out


def _boundary_line(group, model, Ka, kha, Kb, khb, note, rng, out):
    """Points on the segment Ka -> Kb around where the exact verdict changes."""

    def at(t):
        return Ka + t * (Kb - Ka), kha + t * (khb - kha)

    def stable(t):
        ev = _exact_fast(model, *at(t))
        return ev.plant_stable and ev.string_stable, ev

    sa, _ = stable(0.0)
    sb, _ = stable(1.0)
    if sa == sb:
        return 0
    lo, hi = 0.0, 1.0  # verdict(lo) = sa, verdict(hi) = sb
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if stable(mid)[0] == sa:
            lo = mid
        else:
            hi = mid
    ev_lo, ev_hi = stable(lo)[1], stable(hi)[1]
    if not (ev_lo.plant_stable and ev_hi.plant_stable):
        return 0  # a plant-stability boundary, not a string one
    side = ev_lo if not sa else ev_hi  # the string-unstable neighbour
    kind = "lowfreq" if side.c_sign >= 0 else "interior"
    count = 0
    ts = [lo, hi]
    for d in (1e-15, 1e-13, 1e-11, 1e-9, 1e-7, 1e-5, 1e-3):
        ts += [lo - d, hi + d]
    for t in ts:
        if 0.0 <= t <= 1.0:
            out.append(_case(f"boundary_{kind}", model, *at(t), f"{note} t={t!r}"))
            count += 1
    return count


def build_core_sample(rng) -> list[dict]:
    out: list[dict] = []
    paper = general_lcc(2, 2, PAPER)
    table = _table_cases(paper)
    for name, (K, kh) in table.items():
        out.append(_case("table_i", paper, K, kh, name))
    # random gains on random models of the three kinds with a head vehicle
    for kind, count in (("lcc", 120), ("cf_lcc", 40), ("ccc", 40)):
        for _ in range(count):
            model = random_model(rng, kind)
            K, kh = input_feedback(model, random_gains(rng, model))
            out.append(_case(f"random_{kind}", model, K, kh))
    for _ in range(40):  # the paper's lcc(2,2) with larger gains
        K, kh = input_feedback(paper, random_gains(rng, paper, 3.0))
        out.append(_case("random_paper", paper, K, kh))
    for m, n, count in ((2, 8, 15), (3, 9, 15)):  # 22 and 26 states
        big = general_lcc(m, n, PAPER)
        for _ in range(count):
            K, kh = input_feedback(big, random_gains(rng, big, 1.0))
            out.append(_case("random_big", big, K, kh))
    # near Table I's cases C and D
    for name in ("case_c", "case_d"):
        K, kh = table[name]
        for sigma in (1e-6, 1e-3, 1e-2, 1e-1, 3e-1):
            for _ in range(8):
                Kp = K * (1.0 + sigma * rng.standard_normal(K.size))
                out.append(_case("near_cd", paper, Kp, kh, f"{name} sigma={sigma}"))
    # Riccati (H2-optimal) gains
    from lcc_synth.synthesis.h2 import SynthesisError, Weights, make_plant, riccati_gain

    plants = [
        ("lcc", 2, 2, "added"),
        ("lcc", 2, 2, "replace"),
        ("lcc", 1, 3, "added"),
        ("lcc", 3, 1, "added"),
        ("cf_lcc", 0, 3, "added"),
        ("lcc", 2, 8, "added"),
    ]
    for kind, m, n, sem in plants:
        mdl = model_from_hdv(kind, m, n, HDV, 15.0)
        for _ in range(6):
            w = Weights(
                q_s=float(10 ** rng.uniform(-1, 1)),
                q_v=float(10 ** rng.uniform(-1, 1)),
                r=float(10 ** rng.uniform(-1, 1)),
                head=float(rng.choice([0.0, 0.5, 1.0])),
                accel=float(rng.choice([0.5, 1.0])),
                q_a=float(rng.choice([0.0, 1.0])),
            )
            try:
                p = make_plant(mdl, sem, w)
                g, _ = riccati_gain(p)
            except SynthesisError:
                continue
            K, kh = p.input_feedback(g)
            out.append(_case("riccati", mdl, K, kh, f"{kind}({m},{n}) {sem}"))
    # lines through the boundary: Table I pairs, random pairs, the second-peak example
    lines = [
        ("case_b", "case_c"),
        ("case_a", "case_d"),
        ("hdv_only", "case_c"),
        ("case_b", "case_d"),
        ("hdv_only", "case_d"),
    ]
    for a, b in lines:
        _boundary_line("line", paper, *table[a], *table[b], f"{a}->{b}", rng, out)
    for m, n in ((2, 8), (3, 9)):
        big = general_lcc(m, n, PAPER)
        tb = _table_cases(big)
        _boundary_line("line", big, *tb["case_b"], *tb["case_c"], f"big{m},{n} b->c", rng, out)
    K2, kh2 = input_feedback(paper, Gains.named({"v_-1": 1.9, "v_-2": 1.5, "v_2": -2.7}))
    _boundary_line("line", paper, K2, kh2, *table["case_d"], "second_peak->case_d", rng, out)
    _boundary_line("line", paper, K2, kh2, *table["case_c"], "second_peak->case_c", rng, out)
    made, tries = 0, 0
    while made < 6 and tries < 400:  # random pairs with opposite exact verdicts
        tries += 1
        model = random_model(rng, "lcc")
        Ka, kha = input_feedback(model, random_gains(rng, model))
        Kb, khb = input_feedback(model, random_gains(rng, model))
        ea, eb = _exact_fast(model, Ka, kha), _exact_fast(model, Kb, khb)
        if ea.plant_stable and eb.plant_stable and ea.string_stable != eb.string_stable:
            made += bool(_boundary_line("line", model, Ka, kha, Kb, khb, "random", rng, out))
    return out


def build_design_sample(rng) -> list[dict]:
    """String-aware designs (they use the imported string_stability while polishing)."""
    from lcc_synth.synthesis.h2 import SynthesisError, Weights, make_plant, riccati_gain
    from lcc_synth.synthesis.string_lmi import string_aware_h2

    out = []
    setups = [
        (2, 2, [-2, -1, 1, 2], Weights(head=1.0, accel=1.0), (0, 4, 20, 200)),
        (2, 2, [-1, 1, 2], Weights(head=1.0, accel=1.0), (4, 50)),
        (2, 2, [-2, -1, 1, 2], Weights(head=0.5, accel=1.0, q_v=2.0), (4, 50)),
        (1, 3, [-1, 1, 2, 3], Weights(head=1.0, accel=1.0), (4, 50)),
    ]
    for m, n, veh, w, steps_list in setups:
        mdl = model_from_hdv("lcc", m, n, HDV, 15.0)
        p = make_plant(mdl, "added", w)
        for steps in steps_list:
            t0 = time.perf_counter()
            try:
                d = string_aware_h2(p, veh, gamma=1.0, polish_steps=steps)
            except SynthesisError as err:
                print(f"  design lcc({m},{n}) {veh} steps={steps}: {err}")
                continue
            note = f"lcc({m},{n}) {veh} steps={steps} [{CODE_TAG}]"
            print(f"  design {note}: {time.perf_counter() - t0:.1f} s")
            out.append(_case(f"string_aware_{CODE_TAG}", mdl, *p.input_feedback(d.g), note))
            if steps == steps_list[0]:
                out.append(
                    _case(
                        f"string_aware_{CODE_TAG}", mdl, *p.input_feedback(d.lmi.g), f"{note} lmi"
                    )
                )
        if (m, n) == (2, 2) and veh == [-2, -1, 1, 2] and CODE_TAG == "old":
            g, _ = riccati_gain(p)  # unconstrained optimum -> the design: through the boundary
            K0, kh0 = p.input_feedback(g)
            for case in [c for c in out if c["note"].startswith("lcc(2,2) [-2, -1, 1, 2]")][:2]:
                _boundary_line(
                    "line",
                    mdl,
                    K0,
                    kh0,
                    case["K"],
                    case["kh"],
                    f"riccati->{case['note']}",
                    rng,
                    out,
                )
    return out


# --------------------------------------------------------------------------------------------
# Exact
# --------------------------------------------------------------------------------------------


def exact_record(case) -> dict:
    model = _model(case["spec"])
    A, h, c = _loop(model, case["K"], case["kh"])
    ev = exact_string_verdict(A, h, c)
    rec = {
        "plant_stable": ev.plant_stable,
        "string_stable": ev.string_stable,
        "positive_roots": ev.positive_roots,
        "c_sign": ev.c_sign,
        "g0_is_one": ev.g0_is_one,
        "curvature": ev.curvature,
        "peak": ev.peak,
        "peak_omega": ev.peak_omega,
        "q_max": ev.q_max,
        "q_max_omega": ev.q_max_omega,
        "q0": ev.extra.get("q0", np.nan),
        "q_at_peak": np.nan,
        "seconds_exact": ev.seconds_exact,
        "seconds_total": ev.seconds_total,
    }
    if ev.plant_stable and ev.peak_omega > 0:
        rec["q_at_peak"] = ev.q_exact(ev.peak_omega)
    return rec


# --------------------------------------------------------------------------------------------
# Measurement
# --------------------------------------------------------------------------------------------


def _transform(kind, A, h, c, rng):
    nx = A.shape[0]
    if kind == "perm":
        p = rng.permutation(nx)
        return A[np.ix_(p, p)], h[p], c[p]
    if kind == "diag":
        d = 10.0 ** rng.uniform(-2, 2, nx)
        return A * d[None, :] / d[:, None], h / d, c * d
    if kind == "orth":
        Q, _ = np.linalg.qr(rng.standard_normal((nx, nx)))
        return Q.T @ A @ Q, Q.T @ h, c @ Q
    if kind == "similar":
        Q1, _ = np.linalg.qr(rng.standard_normal((nx, nx)))
        Q2, _ = np.linalg.qr(rng.standard_normal((nx, nx)))
        T = Q1 @ np.diag(rng.uniform(0.5, 2.0, nx)) @ Q2  # cond(T) <= 4
        return np.linalg.solve(T, A @ T), np.linalg.solve(T, h), c @ T
    raise ValueError(kind)


def _code(rep) -> str:
    """S(tring stable), U(nstable), P(lant unstable), B(oundary)."""
    v = getattr(rep, "verdict", None)
    if v is not None:
        return {
            "string_stable": "S",
            "string_unstable": "U",
            "plant_unstable": "P",
            "boundary": "B",
        }[v]
    if rep.string_stable:
        return "S"
    return "U" if rep.plant_stable else "P"


def _exact_code(ex) -> str:
    if not ex["plant_stable"]:
        return "P"
    return "S" if ex["string_stable"] else "U"


def _loop_report(model, A, h, c, method):
    if NEW_API:
        return ss.loop_string_stability(A, h, c, method=method)
    saved = ss.closed_loop, ss.tail_output
    ss.closed_loop = lambda _m, _K, _kh: (A, h.reshape(-1, 1))
    ss.tail_output = lambda _m: c
    try:
        return ss.string_stability(model, np.zeros(model.nx), 0.0, method=method)
    finally:
        ss.closed_loop, ss.tail_output = saved


def _q_float(A, h, c, omegas):
    """The decision function in floating point: the library's when it has one, else the same
    formula (three LU solves, then dense solves at the few frequencies)."""
    if hasattr(ss, "decision_function"):
        if BALANCED:  # as loop_string_stability does before deciding
            A, (s, _) = sla.matrix_balance(A, permute=False, separate=True)
            h, c = h / s, c * s
        q, _, _ = ss.decision_function(A, h, c)
        return np.asarray(q(np.asarray(omegas, float)), float)
    lu = sla.lu_factor(A)
    b1 = sla.lu_solve(lu, h)
    b2 = sla.lu_solve(lu, b1)
    b3 = sla.lu_solve(lu, b2)
    g0 = -float(c @ b1)
    out = []
    for w in omegas:
        if w == 0.0:
            G1, G2 = -float(c @ b2), -float(c @ b3)
        else:
            y = np.linalg.solve(1j * w * np.eye(A.shape[0]) - A, np.column_stack([b1, b2]))
            G1, G2 = c @ y[:, 0], c @ y[:, 1]
        a = abs(G1) ** 2
        b = 2.0 * g0 * np.real(G2)
        S = a + abs(b)
        out.append((a - b) / S if S > 0 else 0.0)
    return np.array(out)


def measure(sample, exact, label, n_transforms, seed=20261201):
    rows = []
    t_start = time.perf_counter()
    for idx, case in enumerate(sample):
        ex = exact[case["id"]]
        model = _model(case["spec"])
        A, h, c = _loop(model, case["K"], case["kh"])
        eigs = closed_loop_eigenvalues(A)
        mags = np.abs(eigs)
        kappa = max(1.0, float(mags.max() / mags.min())) if mags.min() > 0 else np.inf
        row = {
            "id": case["id"],
            "group": case["group"],
            "nx": case["nx"],
            "exact": _exact_code(ex),
            "margin": -ex["q_max"] if ex["plant_stable"] else np.nan,
            "kappa": kappa,
            "orig": {},
            "peak_err": {},
            "flips": {},
            "calib": [],
        }
        for method in ("grid", "hamiltonian"):
            rep = ss.string_stability(model, case["K"], case["kh"], method=method)
            row["orig"][method] = _code(rep)
            if ex["plant_stable"]:
                row["peak_err"][method] = abs(rep.gamma_peak - ex["peak"]) / ex["peak"]
        variants = []
        tr_rng = np.random.default_rng([seed, idx, 1])
        for kind in TRANSFORMS[:n_transforms]:
            if kind == "gain":
                Kp = case["K"] * (1.0 + 1e-12 * tr_rng.standard_normal(case["K"].size))
                khp = case["kh"] * (1.0 + 1e-12 * tr_rng.standard_normal())
                variants.append((kind, None, Kp, khp))
            else:
                variants.append((kind, _transform(kind, A, h, c, tr_rng), None, None))
        for kind, loop, Kp, khp in variants:
            for method in ("grid", "hamiltonian"):
                if loop is None:
                    rep = ss.string_stability(model, Kp, khp, method=method)
                else:
                    rep = _loop_report(model, *loop, method)
                row["flips"].setdefault(method, []).append((kind, _code(rep)))
        if ex["plant_stable"] and np.isfinite(kappa):
            om = [0.0] + ([ex["q_max_omega"]] if ex["q_max_omega"] > 0 else [])
            ref = [ex["q0"]] + ([ex["q_max"]] if ex["q_max_omega"] > 0 else [])
            loops = [("orig", (A, h, c))] + [(k, lp) for k, lp, _, _ in variants if lp]
            for kind, lp in loops:
                with np.errstate(all="ignore"):
                    qc = _q_float(*lp, om)
                for j, w in enumerate(om):
                    err = abs(float(qc[j]) - ref[j])
                    where = "w0" if w == 0 else "wmax"
                    row["calib"].append((kind, where, err / (EPS * kappa), ref[j]))
        rows.append(row)
        if (idx + 1) % 100 == 0:
            print(
                f"  {label}: {idx + 1}/{len(sample)} ({time.perf_counter() - t_start:.0f} s)",
                flush=True,
            )
    return rows


def summarise(rows, label, band_factor):
    def line(*a):
        print(*a, flush=True)

    n = len(rows)
    line(f"\n=== {label}: {n} gains, code '{CODE_TAG}' (q calibrated balanced: {BALANCED}) ===")
    ex_counts = {k: sum(r["exact"] == k for r in rows) for k in "SUP"}
    line(
        f"exact: string stable {ex_counts['S']}, string unstable {ex_counts['U']}, "
        f"plant unstable {ex_counts['P']}"
    )
    groups = sorted({r["group"] for r in rows})
    for method in ("grid", "hamiltonian"):
        wrong = [
            r
            for r in rows
            if r["orig"][method] in "SUP" and (r["orig"][method] == "S") != (r["exact"] == "S")
        ]
        plant_wrong = [
            r
            for r in rows
            if r["orig"][method] in "SUP" and (r["orig"][method] == "P") != (r["exact"] == "P")
        ]
        bnd = [r for r in rows if r["orig"][method] == "B"]
        bnd_wide = [r for r in bnd if np.isfinite(r["margin"]) and abs(r["margin"]) > 1e-6]
        line(
            f"[{method}] wrong string verdicts {len(wrong)}/{n} "
            f"(S->U {sum(r['exact'] == 'S' for r in wrong)}, "
            f"U->S {sum(r['exact'] != 'S' for r in wrong)}); plant verdict wrong "
            f"{len(plant_wrong)}; boundary {len(bnd)} (of which exact |margin| > 1e-6: "
            f"{len(bnd_wide)})"
        )
        if wrong:
            ms = [abs(r["margin"]) for r in wrong if np.isfinite(r["margin"])]
            line(
                f"    wrong: max exact |margin| {max(ms) if ms else np.nan:.3g}; groups "
                + ", ".join(
                    f"{g}:{sum(r['group'] == g for r in wrong)}"
                    for g in groups
                    if any(r["group"] == g for r in wrong)
                )
            )
        per = {g: sum(1 for r in wrong if r["group"] == g) for g in groups}
        line(
            "    per group (wrong/total): "
            + ", ".join(f"{g} {per[g]}/{sum(r['group'] == g for r in rows)}" for g in groups)
        )
        # flips under transformations
        for thresh in (0.0, 1e-6):
            pool = [
                r
                for r in rows
                if (thresh == 0.0 or (np.isfinite(r["margin"]) and abs(r["margin"]) >= thresh))
            ]
            cases = sum(len(r["flips"].get(method, [])) for r in pool)
            flips = [
                (r, k, v)
                for r in pool
                for k, v in r["flips"].get(method, [])
                if v != r["orig"][method]
            ]
            hard = [f for f in flips if "B" not in (f[2], f[0]["orig"][method])]
            by_kind = {}
            for _, k, _ in flips:
                by_kind[k] = by_kind.get(k, 0) + 1
            tag = "all gains" if thresh == 0.0 else "exact |margin| >= 1e-6"
            line(
                f"    flips ({tag}): {len(flips)}/{cases} (S<->U/P without boundary "
                f"{len(hard)}) by transform {by_kind}"
            )
        errs = [
            r["peak_err"][method]
            for r in rows
            if method in r["peak_err"] and r["orig"][method] in "SU"
        ]
        if errs:
            line(
                f"    gamma_peak vs exact: max rel err {max(errs):.3g}, "
                f"> 1e-9: {sum(e > 1e-9 for e in errs)}"
            )
    agree = sum(r["orig"]["grid"] == r["orig"]["hamiltonian"] for r in rows)
    line(f"grid vs hamiltonian verdicts agree on {agree}/{n}")
    # calibration
    # (all of q, then only near the boundary |q_exact| < 1e-2, where the band matters)
    combos = [(w, s, n) for n in (np.inf, 1e-2) for w in ("w0", "wmax") for s in ("orig", "all")]
    for where, scope, near in combos:
        vals = [
            v
            for r in rows
            for k, w, v, qref in r["calib"]
            if w == where and (scope == "all" or k == "orig") and abs(qref) < near
        ]
        if not vals:
            continue
        vals = np.array(vals)
        line(
            f"calibration {where} ({scope} loops{'' if near == np.inf else ', |q| < 1e-2'}, "
            f"{vals.size}): max |q_c - q_exact| / "
            f"(eps kappa) = {vals.max():.3g} (99% {np.quantile(vals, 0.99):.3g}, "
            f"median {np.median(vals):.3g}); / tau (factor {band_factor:g}) = "
            f"{vals.max() / band_factor:.3g}"
        )
    vals = [c[2] for r in rows for c in r["calib"]]
    if vals:
        worst = max(((v, r["group"], k, w) for r in rows for k, w, v, _ in r["calib"]))
        line(f"calibration worst: {worst[0]:.3g} eps*kappa ({worst[1]}, {worst[2]}, {worst[3]})")
    kap = np.array([r["kappa"] for r in rows if np.isfinite(r["kappa"])])
    tau_med, tau_max = band_factor * EPS * np.median(kap), band_factor * EPS * kap.max()
    line(
        f"kappa: median {np.median(kap):.3g}, max {kap.max():.3g} -> tau = "
        f"{tau_med:.2g} (median) .. {tau_max:.2g}"
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--cache", default="/tmp/lcc_string_exactness")
    ap.add_argument("--phase", default="all", choices=["sample", "exact", "measure", "all"])
    ap.add_argument("--label", default=None)
    ap.add_argument("--transforms", type=int, default=len(TRANSFORMS))
    ap.add_argument("--limit", type=int, default=0, help="first N gains only (quick look)")
    ap.add_argument("--no-designs", action="store_true")
    ap.add_argument("--summarise", metavar="LABEL", help="print the summary of a stored run")
    args = ap.parse_args(argv)
    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    if args.summarise:
        rows = json.loads((cache / f"measure_{args.summarise}.json").read_text())
        summarise(rows, args.summarise, getattr(ss, "BAND_FACTOR", 1e4))
        return 0
    print(f"lcc_synth from {ss.__file__} (code '{CODE_TAG}')")
    core = cache / "sample_core.pkl"
    if args.phase in ("sample", "all"):
        if not core.exists():
            t0 = time.perf_counter()
            pickle.dump(build_core_sample(np.random.default_rng(19)), core.open("wb"))
            print(f"core sample: {time.perf_counter() - t0:.1f} s")
        des = cache / f"sample_designs_{CODE_TAG}.pkl"
        if not des.exists() and not args.no_designs:
            t0 = time.perf_counter()
            pickle.dump(build_design_sample(np.random.default_rng(190)), des.open("wb"))
            print(f"designs ({CODE_TAG}): {time.perf_counter() - t0:.1f} s")
    sample = []
    for path in sorted(cache.glob("sample_*.pkl")):
        for i, case in enumerate(pickle.load(path.open("rb"))):
            case["id"] = f"{path.stem}:{i}"
            sample.append(case)
    if args.limit:
        sample = sample[: args.limit]
    print(
        f"sample: {len(sample)} gains; groups "
        + ", ".join(
            f"{g} {sum(c['group'] == g for c in sample)}"
            for g in sorted({c["group"] for c in sample})
        )
    )
    exact_path = cache / "exact.pkl"
    exact = pickle.load(exact_path.open("rb")) if exact_path.exists() else {}
    if args.phase in ("exact", "all", "measure"):
        todo = [c for c in sample if c["id"] not in exact]
        t0 = time.perf_counter()
        for case in todo:
            exact[case["id"]] = exact_record(case)
        if todo:
            pickle.dump(exact, exact_path.open("wb"))
            print(f"exact: {len(todo)} new verdicts in {time.perf_counter() - t0:.1f} s")
        by_n = {}
        for case in sample:
            by_n.setdefault(case["nx"], []).append(exact[case["id"]])
        for nx in sorted(by_n):
            ex_t = np.array([e["seconds_exact"] for e in by_n[nx]])
            tot = np.array([e["seconds_total"] for e in by_n[nx]])
            print(
                f"  exact reference nx={nx:>2} ({len(ex_t)}): exact part median "
                f"{1e3 * np.median(ex_t):.1f} ms max {1e3 * ex_t.max():.1f} ms; with mpmath "
                f"peak/q median {np.median(tot):.2f} s max {tot.max():.2f} s"
            )
    if args.phase in ("measure", "all"):
        label = args.label or f"{CODE_TAG}-{os.environ.get('OPENBLAS_CORETYPE', 'default')}"
        t0 = time.perf_counter()
        rows = measure(sample, exact, label, args.transforms)
        print(f"measure: {time.perf_counter() - t0:.1f} s")
        out = cache / f"measure_{label}.json"
        out.write_text(json.dumps(rows, default=float))
        summarise(rows, label, getattr(ss, "BAND_FACTOR", 1e4))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
