"""Run a platoon / ring synthesis problem: per-CAV patterns, the design stages, the robust
multi-model design, the checks and the report.

Stages (each reported with its true H2 norm and wall time):

* ``riccati`` -- the full-information optimum (CARE on the reduced plant); ``design =
  "full_state"`` returns it, checked against the Lyapunov evaluation of the same gain;
* ``start`` -- a stabilising gain with the patterns (truncated Riccati modulo ``c``, or the
  penalty continuation: :func:`~lcc_synth.synthesis.platoon_polish.initial_gain`);
* ``polish`` -- Newton / BFGS descent on the true H2 with the patterns' mask;
* ``sparsity`` -- ``design = "sparsity"``: the greedy per-CAV range front
  (:mod:`~lcc_synth.synthesis.platoon_sparsity`) and its chosen point;
* ``robust`` -- with ``[synthesis.robust]``: descent on the mean (or smooth worst) true H2 over
  the sampled members, from the nominal design, every accepted gain stable on every member.
"""

from __future__ import annotations

import math
import time

import numpy as np

from lcc_synth.resources import progress
from lcc_synth.synthesis.config import PlatoonSynthesisSpec, robust_members
from lcc_synth.synthesis.h2 import SynthesisError, single_thread_blas
from lcc_synth.synthesis.platoon_h2 import (
    PlatoonPlant,
    make_platoon_plant,
    pattern_rows,
    platoon_cost,
    platoon_h2,
    platoon_riccati,
)
from lcc_synth.synthesis.platoon_polish import (
    ROBUST_TEMPERATURES,
    descend,
    h2_objective,
    initial_gain,
    robust_objective,
)
from lcc_synth.synthesis.platoon_report import PlatoonReport, check_platoon_gain
from lcc_synth.synthesis.platoon_sparsity import range_pareto

__all__ = ["member_stats", "robust_design", "synthesize_platoon"]

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


def _robust_stage(spec: PlatoonSynthesisSpec, plant: PlatoonPlant, K_nom, mask):
    rb = spec.robust
    members = robust_members(spec.system, rb)
    plants = [make_platoon_plant(_model(p), spec.semantics, spec.weights) for p in members]
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


@single_thread_blas
def synthesize_platoon(spec: PlatoonSynthesisSpec) -> PlatoonReport:
    """Synthesise and check the gain of a platoon / ring ``spec``.

    Raises
    ------
    SynthesisError
        Not stabilisable (on the invariant subspace), no stabilising gain of the pattern, a
        robust start unstable on a member, or a failed check.
    """
    t_start = time.perf_counter()
    model = spec.system.linear_model(warn=False)
    plant = make_platoon_plant(model, spec.semantics, spec.weights)
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
    t0 = time.perf_counter()
    progress("synthesis: Riccati (full-information optimum)")
    K_ric, J_ric, _ = platoon_riccati(plant)
    timings["riccati"] = time.perf_counter() - t0
    h2_star = math.sqrt(J_ric)
    stages.append({"stage": "riccati", "h2": h2_star, "time": timings["riccati"]})
    mask = pattern_rows(plant, spec.patterns)
    pol: dict = {}
    pareto = None
    if spec.design == "sparsity":
        t0 = time.perf_counter()
        pareto, K, chosen = range_pareto(plant, h2_star, spec.max_loss, spec.tol, spec.max_iter)
        timings["sparsity"] = time.perf_counter() - t0
        mask = pattern_rows(plant, chosen)
        stages.append({"stage": "sparsity (chosen)", "h2": platoon_h2(plant, K),
                       "time": timings["sparsity"]})  # fmt: skip
        notes.append(f"chosen ranges: fewest heard vehicles with H2 within "
                     f"{100 * spec.max_loss:g}% of the full-information optimum (greedy "
                     "per-CAV range front)")  # fmt: skip
    elif spec.design == "full_state" or mask.all():
        K = K_ric
        h_lyap = platoon_h2(plant, K)
        rel = abs(h_lyap - h2_star) / h2_star
        pol = {"riccati_vs_lyapunov_h2_rel": rel}
        if not rel <= RICCATI_CHECK_TOL:
            raise SynthesisError(f"Riccati value {h2_star:.10g} and the Lyapunov H2 of its gain "
                                 f"{h_lyap:.10g} disagree (relative {rel:.2e})", pol)
    else:
        t0 = time.perf_counter()
        K0, how = initial_gain(plant, mask, K_ric)
        timings["start"] = time.perf_counter() - t0
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
    K = np.where(mask, K, 0.0)  # exact zeros off the patterns (already so; kept explicit)
    chk = check_platoon_gain(plant, K, f"{spec.design} design")
    gains = plant.gains(K)
    Ku, kh = plant.input_feedback(K)
    timings["total"] = time.perf_counter() - t_start
    progress(f"synthesis: done in {timings['total']:.2f} s")
    pat = {f"u_{i}": sorted({v for v in range(1, model.platoon.size + 1)
                             if mask[k, model.block(v)].any()})
           for k, i in enumerate(model.cavs)}  # fmt: skip
    return PlatoonReport(
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
        K=K.tolist(),
        gains=gains.as_table(model),
        input_K=Ku.tolist(),
        input_kh=kh.tolist(),
        check=chk,
        h2_unstructured=h2_star,
        conserved=None if model.conserved is None else model.conserved.tolist(),
        stages=stages,
        polish=pol,
        robust=robust,
        pareto=pareto,
        timings=timings,
        notes=notes,
    )
