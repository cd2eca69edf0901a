"""Run a synthesis problem on any layout: :func:`synthesize` is the one entry point.

Every layout reads one :class:`~lcc_synth.synthesis.config.SynthesisSpec` and gives one
:class:`~lcc_synth.synthesis.report.SynthesisReport`.

One CAV: dispatch on the design (full-state Riccati / LMI, structured, sparsity,
string-stable, optionally as run), check the result, build the report; with
``[synthesis.robust]`` the platoon design below on the string's one-CAV platoon
(:mod:`~lcc_synth.synthesis.robust_string`).

A platoon or a ring: per-CAV patterns, the design stages, the robust multi-model design, the
checks, the baseline's (:func:`baseline_check`) and the report with a gain row per CAV.
Stages (each reported with its true H2 norm and wall time):

* ``riccati`` -- the full-information optimum (CARE on the reduced plant); ``design =
  "full_state"`` returns it, checked against the Lyapunov evaluation of the same gain (with
  ``cav_lag``: the bound of a gain that feeds back the ``a_i``, and ``full_state`` is the
  start and polish below over every vehicle: :mod:`~lcc_synth.synthesis.lag_design`);
* ``lmi`` -- ``full_state`` with ``method = "lmi"`` or ``cross_check``: the LMI on the reduced
  plant, checked against Riccati (:func:`lmi_cross_check`; ``"lmi"`` returns its gain);
* ``convex restriction`` -- ``structured`` with ``method = "lmi"``: a gain with the patterns and
  its bound (:func:`~lcc_synth.synthesis.lmi.convex_restriction`);
* ``start`` -- a stabilising gain with the patterns (truncated Riccati modulo ``c``, or the
  penalty continuation: :func:`~lcc_synth.synthesis.structured.initial_gain`; with ``"lmi"``
  the restriction's gain when its true H2 is lower: :func:`~lcc_synth.synthesis.structured.
  structured_start`);
* ``polish`` -- Newton / BFGS descent on the true H2 with the patterns' mask;
* ``sparsity`` -- ``design = "sparsity"``: the greedy per-CAV range front
  (:func:`~lcc_synth.synthesis.sparsity.range_pareto`) and its chosen point;
* ``string LMI``, ``string polish`` -- ``design = "string_stable"`` (open platoons): the mixed
  H2 / H-infinity LMI on the patterns and the string-stable-feasible polish
  (:func:`~lcc_synth.synthesis.string_lmi.string_aware_h2`);
* ``robust`` -- with ``[synthesis.robust]``: descent on the mean (or smooth worst) true H2 over
  the sampled members, from the nominal design, every accepted gain stable on every member.
"""

from __future__ import annotations

import math
import time

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import input_feedback
from lcc_synth.resources import format_bytes, progress, require_memory, single_thread_blas
from lcc_synth.synthesis.config import SynthesisSpec, robust_members
from lcc_synth.synthesis.h2 import (
    H2Plant,
    PlatoonPlant,
    SynthesisError,
    h2_norm,
    make_plant,
    make_platoon_plant,
    pattern_rows,
    platoon_cost,
    platoon_h2,
    platoon_riccati,
    riccati_gain,
)
from lcc_synth.synthesis.lag_design import lag_note
from lcc_synth.synthesis.lmi import LMIResult, lmi_full_state, true_h2
from lcc_synth.synthesis.report import (
    UNSET,
    SynthesisReport,
    check_gain,
    check_platoon_gain,
    evaluate_gain,
    evaluate_platoon_gain,
)
from lcc_synth.synthesis.robust_string import robust_string_design
from lcc_synth.synthesis.sparsity import range_pareto, sparsity_sweep
from lcc_synth.synthesis.string_lmi import string_aware_h2, string_lmi
from lcc_synth.synthesis.structured import (
    ROBUST_TEMPERATURES,
    descend,
    h2_objective,
    pattern_mask,
    pattern_vehicles,
    robust_objective,
    structured_h2,
    structured_start,
)

__all__ = [
    "synthesize",
    "baseline_check",
    "design_gain_of",
    "lmi_cross_check",
    "member_stats",
    "robust_design",
]

#: largest string (m + n) of the designs that solve an LMI with dense cones (full-state and
#: string-aware designs, Clarabel): beyond it the solve takes minutes and its KKT system tens of
#: GiB; method = 'direct' has no such limit
MAX_LMI_VEHICLES = 100

#: largest string (m + n) of the structured design with method = 'lmi': its convex restriction
#: is split into small cones (chordal decomposition) and grows linearly, the Newton polishing
#: as nx^3 (measured, CF-LCC with the pattern CAV + HDVs 1, 2: 402 states about 45 s), so the
#: limit is the largest string a problem file accepts (n <= 200)
MAX_CHORDAL_VEHICLES = 200


def _uses_lmi(spec: SynthesisSpec) -> bool:
    if spec.design == "full_state":
        return spec.method == "lmi" or bool(spec.cross_check)
    return (spec.design == "structured" and spec.method == "lmi") or spec.design == "string_stable"


def check_size(spec: SynthesisSpec, nx: int) -> None:
    """Refuse an LMI design that cannot finish: ``m + n`` above :data:`MAX_LMI_VEHICLES`
    (:data:`MAX_CHORDAL_VEHICLES` for the structured restriction, whose cones are small) or,
    for the dense cones, a KKT estimate (``8 (nx (nx + 1) / 2)^2`` bytes, dense in the worst
    case) above the available memory."""
    if not _uses_lmi(spec):
        return
    platoon = spec.system.platoon
    if platoon is not None:  # a platoon or ring: size vehicles
        count, key, what = platoon.size, "system.size", "size"
    else:
        count, key, what = spec.system.m + spec.system.n, "system.n", "m + n"
    fix = {  # what avoids the LMI: string_stable always solves it, whatever its method
        "string_stable": "[synthesis] design = 'structured' and method = 'direct'",
        "full_state": "[synthesis] method = 'riccati' and cross_check = false",
    }.get(spec.design, "[synthesis] method = 'direct'")
    chordal = spec.design == "structured"
    limit = MAX_CHORDAL_VEHICLES if chordal else MAX_LMI_VEHICLES
    svec = nx * (nx + 1) // 2
    need = 8.0 * svec**2
    if count > limit:
        cost = "" if chordal else f" (estimated KKT memory {format_bytes(need)})"
        raise ConfigError(
            key,
            f"{spec.design} synthesis solves an LMI of {nx} states: {what} = {count} is above "
            f"the limit {limit}{cost}; use {fix} for long strings",
        )
    if not chordal:
        require_memory(key, need, f"LMI with {nx} states, {svec} unknowns per cone",
                       f"use {fix}")


#: relative H2 disagreement between the LMI and Riccati designs that counts as a failure
CROSS_CHECK_TOL = 1e-5


def lmi_cross_check(
    plant: H2Plant | PlatoonPlant, K_ric: np.ndarray, h2_star: float
) -> tuple[LMIResult, dict, float]:
    """The full-state LMI (:func:`~lcc_synth.synthesis.lmi.lmi_full_state`) checked against the
    Riccati optimum ``K_ric`` of value ``h2_star``: one CAV or a platoon / ring (its reduced
    plant); returns the LMI, the report's solver figures and the true H2 of the LMI's gain.

    Raises
    ------
    SynthesisError
        The true H2 of the LMI's gain and ``h2_star`` differ by more than
        ``CROSS_CHECK_TOL`` (relative), or the solve fails.
    """
    progress("synthesis: LMI solve (Clarabel)")
    lmi = lmi_full_state(plant)
    h_lmi = true_h2(plant, lmi.g)
    rel = abs(h_lmi - h2_star) / h2_star
    solver = {
        "status": lmi.status,
        "solve_time": lmi.solve_time,
        "residual": lmi.residual,
        "riccati_vs_lmi_h2_rel": rel,
        "riccati_vs_lmi_gain_max": float(np.max(np.abs(lmi.g - K_ric))),
    }
    if not rel <= CROSS_CHECK_TOL:
        raise SynthesisError(
            f"full-state LMI and Riccati disagree: H2 {h_lmi:.8g} vs {h2_star:.8g} "
            f"(relative {rel:.2e} > {CROSS_CHECK_TOL:g}; status {lmi.status})",
            solver,
        )
    return lmi, solver, h_lmi


def design_gain_of(plant: H2Plant, gains) -> np.ndarray:
    """Design-plant gain ``g`` whose closed loop equals that of ``Gains`` ``gains``.

    Raises :class:`SynthesisError` when it cannot be expressed on this plant (different head
    feed-through, or a gain on a dropped state).
    """
    K, kh = input_feedback(plant.model, gains)
    if not math.isclose(kh, plant.kh0, abs_tol=1e-12):
        raise SynthesisError("baseline semantics changes the head-velocity feed-through")
    g_full = K - plant.K0
    dropped = np.setdiff1d(np.arange(plant.model.nx), plant.keep)
    if np.any(g_full[dropped] != 0):
        raise SynthesisError("baseline has a gain on a state the design drops (-p_0)")
    return np.append(g_full[plant.keep], 0.0) if plant.lag > 0 else g_full[plant.keep]


def baseline_check(spec: SynthesisSpec, plant: H2Plant | PlatoonPlant) -> dict:
    """True H2, stability and string stability of the problem's baseline gains, on the design
    plant of their semantics (the design's weights and lag): one CAV by
    :func:`~lcc_synth.synthesis.report.evaluate_gain`; a platoon or ring by
    :func:`~lcc_synth.synthesis.report.evaluate_platoon_gain` (a ring's H2 and stability on
    its invariant hyperplane; an open platoon's head-to-tail string check always). An unstable
    baseline is reported (``h2`` infinite), not refused."""
    name, gains = spec.baseline
    if spec.system.platoon is not None:  # a gain row per CAV (the lag states' columns 0)
        bplant = plant
        if gains.semantics != plant.semantics:
            bplant = make_platoon_plant(plant.model, gains.semantics, plant.weights, plant.lag)
        K = np.zeros((bplant.n_in, bplant.nx))
        K[:, : plant.model.nx] = gains.matrix(plant.model)
        chk = evaluate_platoon_gain(bplant, K, string=True)
    else:
        bplant = plant
        if gains.semantics != plant.semantics:
            bplant = make_plant(plant.model, gains.semantics, plant.weights, plant.lag)
        chk = evaluate_gain(bplant, design_gain_of(bplant, gains))
    return {"name": name, "semantics": gains.semantics, "gains": gains.as_table(),
            "vehicles": gains.vehicles(), **chk.as_dict()}  # fmt: skip


@single_thread_blas
def synthesize(spec: SynthesisSpec) -> SynthesisReport:
    """Synthesise the gain of ``spec`` and check it: the one entry point of every layout (a
    platoon / ring spec gives a report with a gain row per CAV).

    Raises
    ------
    SynthesisError
        Solver failure, infeasibility, a non-stabilising result or a failed cross-check.
    """
    if spec.system.platoon is not None:  # kind = "platoon" | "ring": a gain row per CAV
        return _synthesize_platoon(spec)
    if spec.robust is not None:  # one CAV: the robust design of its one-CAV platoon
        return robust_string_design(spec, _synthesize_platoon)
    t_start = time.perf_counter()
    model = spec.system.linear_model(warn=False)
    plant = make_plant(model, spec.semantics, spec.weights, spec.cav_lag)
    check_size(spec, plant.nx)
    progress(f"synthesis: {spec.design} design, {plant.nx} states ({model.kind}, m = "
             f"{model.m}, n = {model.n})")
    vehicles = spec.pattern if spec.pattern is not None else [v for v in model.vehicles if v]
    notes: list[str] = []
    solver: dict = {}
    pol: dict = {}
    pareto = None
    bound = restr = None
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    progress("synthesis: Riccati (unstructured optimum)")
    g_ric, _ = riccati_gain(plant)
    timings["riccati"] = time.perf_counter() - t0
    h2_star = h2_norm(plant, g_ric)
    if plant.weights.accel == 0:
        notes.append(
            "head disturbance only: the H2 optimum is not unique (gains differ freely on "
            "directions the head disturbance does not excite)"
        )
    if model.kind == "fd_lcc":
        notes.append(
            "fd_lcc position state: "
            + (
                "dropped from the design (gain 0; the CAV's position is a free integrator)"
                if plant.weights.position == "drop"
                else f"kept with weight q_p = {plant.weights.q_p:g}"
            )
        )
    if model.m > 0:
        notes.append(
            "vehicles ahead are uncontrollable but stable: their gains act as feed-forward"
        )

    if spec.cav_lag > 0:
        notes.append(lag_note(spec))
    if spec.design == "full_state" and spec.cav_lag > 0:  # every state but the lag's a_0
        res = structured_h2(plant, vehicles, "direct", tol=spec.tol, max_iter=spec.max_iter)
        g, mask = res.g, res.mask
        pol = {"start": res.start, "iterations": res.polish.iterations,
               "converged": res.polish.converged, "grad_norm": res.polish.grad_norm}  # fmt: skip
        timings.update(res.timings)
    elif spec.design == "full_state":
        mask = np.ones(plant.nx, bool)
        g = g_ric
        if spec.method == "lmi" or spec.cross_check:
            lmi, solver, restr = lmi_cross_check(plant, g_ric, h2_star)
            timings["lmi"] = lmi.solve_time
            bound = lmi.bound
            if spec.method == "lmi":
                g = lmi.g
    elif spec.design == "structured":
        method = "direct" if spec.cav_lag > 0 else spec.method  # lag: no convex restriction
        res = structured_h2(
            plant, vehicles, method, tol=spec.tol, max_iter=spec.max_iter, band=spec.band
        )
        g, mask = res.g, res.mask
        bound, restr = (res.h2_lmi_bound, res.h2_restriction) if res.lmi else (None, None)
        if res.lmi is not None:
            solver = {
                "status": res.lmi.status,
                "solve_time": res.lmi.solve_time,
                "residual": res.lmi.residual,
                **res.lmi.info,
            }
        pol = {
            "start": res.start,
            "iterations": res.polish.iterations,
            "converged": res.polish.converged,
            "grad_norm": res.polish.grad_norm,
        }
        timings.update(res.timings)
    elif spec.design == "sparsity":
        sp = spec.sparsity
        res = sparsity_sweep(
            plant, gammas=sp["gammas"], reweight=sp["reweight"], rho=sp["rho"],
            n_gamma=sp["n_gamma"],
        )
        timings.update(res.timings)
        pareto = [
            {
                "count": p.count,
                "vehicles": p.vehicles,
                "gamma": p.gamma,
                "h2": p.h2,
                "on_front": p.on_front,
                "loss": p.h2 / res.h2_full - 1.0,
            }
            for p in res.points
        ]
        front = res.front
        chosen = next(
            (p for p in front if p.h2 <= (1 + sp["max_loss"]) * res.h2_full), front[-1]
        )
        g = chosen.g
        mask = pattern_mask(plant, chosen.vehicles)
        notes.append(
            f"chosen pattern: fewest vehicles with H2 within {100 * sp['max_loss']:g}% of the "
            f"unstructured optimum ({chosen.count} heard besides the CAV)"
        )
    elif spec.design == "string_stable":
        start = None
        if spec.cav_lag > 0:  # the LMI is infeasible with a_0 outside the pattern
            start = structured_h2(plant, vehicles, "direct", tol=spec.tol,
                                  max_iter=spec.max_iter).g  # fmt: skip
        res = string_aware_h2(
            plant, vehicles, spec.string_gamma, spec.polish_steps, spec.string_margin, start
        )
        g, mask = res.g, res.mask
        bound, restr = res.h2_lmi_bound, res.h2_restriction
        solver = {
            "status": res.lmi.status,
            "solve_time": res.lmi.solve_time,
            "residual": res.lmi.residual,
            "gamma_bound": spec.string_gamma,
        }
        pol = {
            "iterations": res.polish.iterations,
            "converged": res.polish.converged,
            "grad_norm": res.polish.grad_norm,
            "constraint": "string stable (global check) at every accepted step",
        }
        timings.update(res.timings)
    else:  # pragma: no cover - validated by the config
        raise SynthesisError(f"unknown design {spec.design!r}")

    as_run = None
    if spec.as_run is not None:
        from lcc_synth.synthesis.as_run import as_run_design, as_run_note

        g, as_run = as_run_design(plant, mask, np.where(mask, g, 0.0), spec.as_run)
        timings["as_run"] = as_run["timings"]["total"]
        if not as_run["string_stable"]:
            notes.append(as_run_note(spec.as_run, as_run))
    progress("synthesis: checking the gain (stability, H2, string stability)")
    g = np.where(mask, g, 0.0)  # exact zeros off the pattern (already so; kept explicit)
    chk = check_gain(plant, g, f"{spec.design} design", solver)
    if spec.design == "string_stable" and not chk.string_stable:
        raise SynthesisError(
            f"string_stable design: the result is not string stable by the global check "
            f"(peak |Gamma| = {chk.gamma_peak:.9f})",
            solver,
        )
    gains = plant.gains(g)
    K_in, kh_in = plant.input_feedback(g)
    baseline = baseline_check(spec, plant) if spec.baseline else None
    timings["total"] = time.perf_counter() - t_start
    progress(f"synthesis: done in {timings['total']:.1f} s")
    return SynthesisReport(
        problem=spec.name,
        design=spec.design,
        kind=model.kind,
        m=model.m,
        n=model.n,
        v_star=spec.system.v_star,
        semantics=spec.semantics,
        weights=plant.weights.as_dict(),
        disturbances=list(plant.w_names),
        pattern=pattern_vehicles(plant, mask),
        state_names=list(model.state_names),
        K=[gains.gains[nm] for nm in model.state_names],
        gains=dict(gains.gains),
        input_K=list(K_in),
        input_kh=kh_in,
        check=chk,
        h2_lmi_bound=bound,
        h2_restriction=restr,
        h2_unstructured=h2_star,
        solver=solver,
        polish=pol,
        baseline=baseline,
        pareto=pareto,
        timings=timings,
        notes=notes,
        as_run=as_run,
        gain=gains,
    )


#: relative disagreement between the Riccati value and the Lyapunov H2 of its gain that fails
RICCATI_CHECK_TOL = 1e-8


def member_stats(plants: list[PlatoonPlant], K: np.ndarray) -> dict:
    """Per-member true H2 and stability of ``K`` and their summary (mean / worst / best over
    the stable members; ``mean_h2`` is ``inf`` when any member is unstable)."""
    rows = []
    for j, p in enumerate(plants):
        ev = platoon_cost(p, K)
        rows.append({"member": j, "h2": math.sqrt(ev.J) if ev.stable else math.inf,
                     "stable": ev.stable, "max_real_eig": ev.max_real_eig})  # fmt: skip
    h = np.array([r["h2"] for r in rows])
    ok = np.isfinite(h)
    return {
        "members": rows,
        "n_stable": int(ok.sum()),
        "mean_h2": float(h.mean()) if ok.all() else math.inf,
        "worst_h2": float(h.max()),
        "best_h2": float(h[ok].min()) if ok.any() else math.inf,
    }


def robust_design(
    plants: list[PlatoonPlant], K0: np.ndarray, mask: np.ndarray, objective: str = "mean",
    tol: float = 1e-7, max_iter: int = 500,
) -> tuple[np.ndarray, dict]:
    """One gain with the pattern ``mask`` minimising the mean (or smooth worst) true H2 over
    ``plants``, from ``K0`` (stable on every member); returns the gain and the descent info.

    Raises
    ------
    SynthesisError
        ``K0`` is unstable on some member (named).
    """
    bad = [j for j, p in enumerate(plants) if not platoon_cost(p, K0).stable]
    if bad:
        raise SynthesisError(f"robust design: the nominal gain is not stable on members {bad}; "
                             "narrow the [synthesis.robust] ranges", {"unstable_members": bad})
    if objective == "mean":
        res = descend(robust_objective(plants, "mean"), K0, mask, tol, max_iter, "robust mean")
        return res.K, {"iterations": res.iterations, "converged": res.converged,
                       "grad_norm": res.grad_norm, "method": res.method}  # fmt: skip
    K, its, conv = K0, 0, True
    for frac in ROBUST_TEMPERATURES:
        h = member_stats(plants, K)
        t = frac * h["mean_h2"]
        res = descend(robust_objective(plants, "worst", t), K, mask, tol, max_iter,
                      f"robust worst (t = {t:.3g})")  # fmt: skip
        K, its, conv = res.K, its + res.iterations, conv and res.converged
    return K, {"iterations": its, "converged": conv, "grad_norm": res.grad_norm,
               "method": res.method, "temperatures": list(ROBUST_TEMPERATURES)}  # fmt: skip


def _robust_stage(spec: SynthesisSpec, plant: PlatoonPlant, K_nom, mask):
    rb = spec.robust
    members = robust_members(spec.system, rb)
    plants = [make_platoon_plant(_model(p), spec.semantics, spec.weights, spec.cav_lag)
              for p in members]  # fmt: skip
    nominal = member_stats(plants, K_nom)
    nominal["h2_nominal"] = platoon_h2(plant, K_nom)
    K, info = robust_design(plants, K_nom, mask, rb.objective, spec.tol, spec.max_iter)
    robust = member_stats(plants, K)
    robust["h2_nominal"] = platoon_h2(plant, K)
    if robust["n_stable"] != len(plants):  # pragma: no cover - descend only accepts stable
        raise SynthesisError("robust design: the result is unstable on some member")
    return K, {"objective": rb.objective, "samples": rb.samples, "seed": rb.seed,
               "ranges": {k: list(v) for k, v in rb.ranges.items()},
               "nominal_design": nominal, "robust_design": robust, **info}  # fmt: skip


def _model(platoon):
    from lcc_synth.models.platoon import platoon_model

    return platoon_model(platoon, warn=False)


def _string_stage(spec: SynthesisSpec, plant: PlatoonPlant, mask, stages, timings):
    """``design = "string_stable"`` on an open platoon: the gain, the polish's figures and the
    LMI's (``bound``, ``restriction``: its gain's true H2, ``solver``) for the report; the
    stages and timings are appended to ``stages`` and ``timings``."""
    res = string_aware_h2(plant, mask, spec.string_gamma, spec.polish_steps,
                          spec.string_margin)  # fmt: skip
    timings["lmi"], timings["polish"] = res.timings["lmi"], res.timings["polish"]
    stages.append({"stage": "string LMI", "h2": res.h2_restriction, "time": timings["lmi"]})
    stages.append({"stage": "string polish", "h2": res.h2, "time": timings["polish"]})
    solver = {"status": res.lmi.status, "solve_time": res.lmi.solve_time,
              "residual": res.lmi.residual, "gamma_bound": spec.string_gamma}  # fmt: skip
    pol = {"iterations": res.polish.iterations,
           "converged": res.polish.converged, "grad_norm": res.polish.grad_norm,
           "free_entries": int(mask.sum()),
           "constraint": "string stable (global check) at every accepted step"}  # fmt: skip
    return res.g, pol, {"bound": res.h2_lmi_bound, "restriction": res.h2_restriction,
                        "solver": solver}  # fmt: skip


def _synthesize_platoon(spec: SynthesisSpec) -> SynthesisReport:
    """Synthesise and check the gain of a platoon / ring ``spec``.

    Raises
    ------
    SynthesisError
        Not stabilisable (on the invariant subspace), no stabilising gain of the pattern, a
        robust start unstable on a member, or a failed check.
    """
    t_start = time.perf_counter()
    model = spec.system.linear_model(warn=False)
    plant = make_platoon_plant(model, spec.semantics, spec.weights, spec.cav_lag)
    check_size(spec, plant.Ar.shape[0])
    progress(f"synthesis: {spec.design} design, {plant.nx} states ({spec.system.kind}, CAVs "
             f"{list(model.cavs)})")  # fmt: skip
    timings: dict[str, float] = {}
    stages: list[dict] = []
    notes: list[str] = []
    if model.ring:
        notes.append(
            "ring: the total spacing (sum of s_i, direction c) is conserved -- eigenvalue 0, "
            "uncontrollable and not excited by the disturbances; stability and H2 are those "
            "of the invariant hyperplane c x = 0, and each CAV's gain row is defined modulo c "
            "(K and K + k c act identically there)"
        )
    if spec.cav_lag > 0:
        notes.append(lag_note(spec))
    t0 = time.perf_counter()
    progress("synthesis: Riccati (full-information optimum)")
    K_ric, J_ric, _ = platoon_riccati(plant)
    timings["riccati"] = time.perf_counter() - t0
    h2_star = math.sqrt(J_ric)
    stages.append({"stage": "riccati", "h2": h2_star, "time": timings["riccati"]})
    mask = pattern_rows(plant, spec.patterns)
    pol: dict = {}
    pareto = None
    lmi_info: dict = {}  # the LMI's figures for the report (string_stable, method lmi)
    if spec.design == "string_stable":
        K, pol, lmi_info = _string_stage(spec, plant, mask, stages, timings)
    elif spec.design == "sparsity":
        t0 = time.perf_counter()
        pareto, K, chosen = range_pareto(plant, h2_star, spec.max_loss, spec.tol, spec.max_iter)
        timings["sparsity"] = time.perf_counter() - t0
        mask = pattern_rows(plant, chosen)
        stages.append({"stage": "sparsity (chosen)", "h2": platoon_h2(plant, K),
                       "time": timings["sparsity"]})  # fmt: skip
        notes.append(f"chosen ranges: fewest heard vehicles with H2 within "
                     f"{100 * spec.max_loss:g}% of the full-information optimum (greedy "
                     "per-CAV range front)")  # fmt: skip
    elif mask.all() and (spec.design == "full_state" or spec.method != "lmi"):
        # full information (never with a lag: no pattern holds the a_i)
        K = K_ric
        h_lyap = platoon_h2(plant, K)
        rel = abs(h_lyap - h2_star) / h2_star
        pol = {"riccati_vs_lyapunov_h2_rel": rel}
        if not rel <= RICCATI_CHECK_TOL:
            raise SynthesisError(f"Riccati value {h2_star:.10g} and the Lyapunov H2 of its gain "
                                 f"{h_lyap:.10g} disagree (relative {rel:.2e})", pol)
        if spec.design == "full_state" and (spec.method == "lmi" or spec.cross_check):
            lmi, solver, h_lmi = lmi_cross_check(plant, K_ric, h2_star)
            timings["lmi"] = lmi.solve_time
            stages.append({"stage": "lmi", "h2": h_lmi, "time": lmi.solve_time})
            lmi_info = {"bound": lmi.bound, "restriction": h_lmi, "solver": solver}
            if spec.method == "lmi":
                K = lmi.g
    else:
        t0 = time.perf_counter()
        how = "lmi" if spec.method == "lmi" else "direct"  # full_state with a lag: direct
        K0, how, lmi = structured_start(plant, mask, K_ric, how, spec.band)
        timings["start"] = time.perf_counter() - t0
        if lmi is not None:
            h_lmi = platoon_h2(plant, lmi.g)
            timings["lmi"] = lmi.solve_time
            stages.append({"stage": "convex restriction", "h2": h_lmi, "time": lmi.solve_time})
            lmi_info = {"bound": lmi.bound, "restriction": h_lmi,
                        "solver": {"status": lmi.status, "solve_time": lmi.solve_time,
                                   "residual": lmi.residual, **lmi.info}}  # fmt: skip
        stages.append({"stage": f"start ({how})", "h2": platoon_h2(plant, K0),
                       "time": timings["start"]})  # fmt: skip
        t0 = time.perf_counter()
        res = descend(h2_objective(plant), K0, mask, spec.tol, spec.max_iter)
        timings["polish"] = time.perf_counter() - t0
        K = res.K
        stages.append({"stage": "polish", "h2": math.sqrt(res.f), "time": timings["polish"]})
        pol = {"start": how, "method": res.method, "iterations": res.iterations,
               "converged": res.converged, "grad_norm": res.grad_norm,
               "free_entries": int(mask.sum())}  # fmt: skip
    robust = None
    if spec.robust is not None:
        t0 = time.perf_counter()
        progress(f"synthesis: robust design over {spec.robust.samples} members")
        K, robust = _robust_stage(spec, plant, K, mask)
        timings["robust"] = time.perf_counter() - t0
        stages.append({"stage": f"robust ({spec.robust.objective})",
                       "h2": robust["robust_design"]["mean_h2"], "time": timings["robust"]})
        notes.append("robust stage: its H2 is the mean (objective mean) over the members; "
                     "check.h2 is the robust gain on the nominal model")  # fmt: skip
    as_run = UNSET
    if spec.as_run is not None:  # open platoons, fixed equilibrium (the config refuses the rest)
        from lcc_synth.synthesis.as_run import as_run_design, as_run_note

        progress("synthesis: as-run polish (string stable as run at every accepted step)")

        def lmi_gain():  # the fallback start: the string LMI's gain on the same patterns
            return string_lmi(plant, mask, spec.string_gamma).g

        K, as_run = as_run_design(plant, mask, np.where(mask, K, 0.0), spec.as_run, lmi_gain)
        timings["as_run"] = as_run["timings"]["total"]
        stages.append({"stage": "as-run polish", "h2": as_run["h2_after"],
                       "time": timings["as_run"]})  # fmt: skip
        if not as_run["string_stable"]:
            notes.append(as_run_note(spec.as_run, as_run))
    K = np.where(mask, K, 0.0)  # exact zeros off the patterns (already so; kept explicit)
    chk = check_platoon_gain(plant, K, f"{spec.design} design",
                             string=spec.design == "string_stable")  # fmt: skip
    if spec.design == "string_stable" and not chk.string_stable:
        raise SynthesisError("string_stable design: the result is not string stable by the "
                             f"global check (peak |Gamma| = {chk.gamma_peak:.9f})",
                             lmi_info.get("solver"))  # fmt: skip
    gains = plant.gains(K)
    Ku, kh = plant.input_feedback(K)
    baseline = baseline_check(spec, plant) if spec.baseline else UNSET
    timings["total"] = time.perf_counter() - t_start
    progress(f"synthesis: done in {timings['total']:.2f} s")
    pat = {f"u_{i}": sorted({v for v in range(1, model.platoon.size + 1)
                             if mask[k, model.block(v)].any()})
           for k, i in enumerate(model.cavs)}  # fmt: skip
    return SynthesisReport(
        problem=spec.name,
        design=spec.design,
        kind=spec.system.kind,
        size=model.platoon.size,
        cavs=list(model.cavs),
        ring=model.ring,
        v_star=float(model.platoon.v_star),
        circumference=model.platoon.length if model.ring else None,
        semantics=spec.semantics,
        weights={k: v for k, v in plant.weights.as_dict().items()
                 if k not in ("position", "q_p")},  # fmt: skip
        disturbances=list(plant.w_names),
        patterns=pat,
        comm_range=spec.comm_range,
        state_names=list(model.state_names),
        K=plant.model_gain(K).tolist(),
        gains=gains.as_table(),
        input_K=Ku.tolist(),
        input_kh=kh.tolist(),
        check=chk,
        h2_lmi_bound=lmi_info.get("bound", UNSET),
        h2_restriction=lmi_info.get("restriction", UNSET),
        h2_unstructured=h2_star,
        solver=lmi_info.get("solver", UNSET),
        conserved=None if model.conserved is None else model.conserved.tolist(),
        stages=stages,
        polish=pol,
        baseline=baseline,
        robust=robust,
        pareto=pareto,
        timings=timings,
        notes=notes,
        as_run=as_run,
        gain=gains,
    )
