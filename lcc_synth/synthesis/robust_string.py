"""The robust multi-model H2 design (``[synthesis.robust]``) of a one-CAV string.

A string of ``m`` HDVs ahead of the CAV and ``n`` behind it, behind a head vehicle
(``kind = "lcc" | "cf_lcc" | "ccc"``), is the open platoon of ``m + n + 1`` vehicles with its one
CAV at position ``m + 1`` (``kind = "platoon"``): the paper's state ``s_i, v_i`` (vehicle ``i``
counted from the CAV) is the platoon's ``s_{i+m+1}, v_{i+m+1}``, in the same order, and the two
linear models have the same ``A``, ``B``, ``H`` bit for bit (eq. 9, 11, 14;
``tests/test_platoon.py``). So the robust design of a string is the platoon's robust design
(:func:`lcc_synth.synthesis.design.robust_design`: descent on the mean or smooth worst true H2
over the sampled members, from the nominal structured design) run on that platoon, one
pipeline for both vocabularies: :func:`robust_string_design` builds the platoon spec, runs
the platoon design of :func:`lcc_synth.synthesis.design.synthesize` (which dispatches a robust
one-CAV spec here) on it and reports the result in the string's own
names (``s_-1``, ``v_1`` ...), pattern and semantics, with the platoon report's per-member
statistics (``robust``).

What is designed, and the semantics
-----------------------------------
The design works on the CAV's whole command ``u = K x`` (the platoon's ``"replace"``): its
input weight ``r`` weighs ``u``, and the CAV's own sampled parameters, which a platoon member
keeps nominal, enter nowhere (they are the HDV law the CAV would drive with, not a
human's). The reported gain is then written in the user's ``semantics``: ``"replace"`` is
``K`` itself; ``"added"`` is ``K`` minus the CAV's *nominal* HDV law ``a1 s_0 - a2 v_0 + a3
v_-1`` (eq. 23), so both semantics give the same closed loop (to rounding, ~1e-16 relative:
one subtraction and one addition of the law's three coefficients). Two combinations cannot be
written that way and are refused with a ConfigError naming the field:

* ``semantics = "added"`` with no HDV ahead (``m = 0``, CF-LCC): the HDV law adds
  ``a3 v_h``, the head vehicle's velocity, which a gain on the string's states cannot cancel;
* ``semantics = "added"`` with a ``pattern`` that leaves out vehicle ``-1``: the HDV law hears
  it, so the added gain's information is not the pattern's.

``kind = "fd_lcc"`` has no head vehicle (the CAV drives freely at the front), so it is not a
one-CAV platoon: refused (use ``cf_lcc``). The designs are ``full_state`` (the Riccati start,
or ``method = "lmi"``: the full-state LMI's) and ``structured`` (the platoon's start and Newton
polish, ``method = "direct"``, or ``"lmi"``: the convex restriction's start, ``band`` as on the
platoon); the keys of the sparsity, string-stable, as-run and baseline designs and the
full-state ``cross_check`` are refused with robust.
``cav_lag`` runs as on the platoon (every member lagged,
:mod:`~lcc_synth.synthesis.lag_design`); the check is then of the string's lagged loop.

Numerical limits
----------------
The same as the platoon's robust stage: one true-H2 evaluation per member and step (two
Lyapunov solves of ``2 (m + n + 1)`` states). Measured on this machine (2 shared cores,
``benchmarks/bench_robust_one_cav.py``, 20 members, alpha / beta / s_go sampled): CF-LCC
n = 10 with pattern [1, 2] 0.22 s (mean, 3 iterations) and 0.40 s (worst, 9); LCC m = 2, n = 8
over every vehicle 0.36 s / 0.67 s; CCC m = 5 0.10 s / 0.18 s. The CAV's whole command of
the reported gain differs from the platoon's gain by at most 6e-17 ("added") and 0
("replace"). The check (stability, true H2, string stability) is that of the one-CAV report,
on the nominal model; its H2 equals the platoon report's to ~1e-12.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.platoon import Platoon
from lcc_synth.problem import System
from lcc_synth.synthesis.h2 import SynthesisError, make_plant
from lcc_synth.synthesis.report import UNSET, SynthesisReport, check_gain

__all__ = ["ROBUST_STRING_DESIGNS", "string_platoon", "check_robust_string",
           "robust_string_design"]  # fmt: skip

#: The designs ``[synthesis.robust]`` runs on a one-CAV string.
ROBUST_STRING_DESIGNS = ("full_state", "structured")

#: ``[synthesis]`` keys of one-CAV designs that do not combine with ``[synthesis.robust]``.
_NOT_WITH_ROBUST = ("cross_check", "string", "sparsity", "as_run", "baseline")


def string_platoon(system: System) -> System:
    """The one-CAV open platoon equivalent to the string ``system`` (kind ``lcc``, ``cf_lcc``
    or ``ccc``): ``m + n + 1`` vehicles of its ``[hdv]`` model at its ``v_star``, the CAV at
    position ``m + 1`` (vehicle ``i`` of the string is position ``i + m + 1``).

    Raises
    ------
    ConfigError
        ``kind = "fd_lcc"`` (no head vehicle), naming ``synthesis.robust``.
    """
    if system.kind == "fd_lcc":
        raise ConfigError("synthesis.robust", "kind = 'fd_lcc' has no head vehicle, so it is not "
                          "the one-CAV platoon the robust design runs on; use kind = 'cf_lcc' "
                          "(the CAV behind a head vehicle) or drop [synthesis.robust]")
    size = system.m + system.n + 1
    platoon = Platoon((system.hdv,) * size, (system.m + 1,), system.v_star)
    return System("platoon", system.m, system.n + 1, float(platoon.v_star), system.hdv, platoon)


def check_robust_string(
    t: dict[str, Any], system: System, design: str, semantics: str,
    pattern: tuple[int, ...] | None,
) -> str:
    """Refuse what ``[synthesis.robust]`` cannot do on the one-CAV string ``system`` (the
    module docstring) and return the design's default ``method`` (``"riccati"`` for
    ``full_state``, else ``"direct"``; ``"lmi"`` may be asked: the platoon's LMI start).

    Raises
    ------
    ConfigError
        Naming the field: the kind, the design, a key of another design, or ``semantics =
        "added"`` where its HDV law cannot be subtracted.
    """
    string_platoon(system)  # the kind first
    what = "[synthesis.robust] on a one-CAV string"
    if design not in ROBUST_STRING_DESIGNS:
        raise ConfigError("synthesis.design", f"{what} takes design = 'full_state' or "
                          f"'structured', not {design!r}")  # fmt: skip
    for key in _NOT_WITH_ROBUST:
        if key in t:
            raise ConfigError(f"synthesis.{key}", f"does not combine with {what} (its designs: "
                              "full_state, structured; method riccati / direct): drop it")
    if semantics == "added" and system.m == 0:
        raise ConfigError("synthesis.semantics", f"{what} designs the CAV's whole command; with "
                          "no HDV ahead (m = 0) the HDV law of 'added' feeds the head velocity "
                          "(alpha3 v_h), which a gain on the states cannot cancel: use "
                          "semantics = 'replace'")  # fmt: skip
    if semantics == "added" and pattern is not None and -1 not in pattern:
        raise ConfigError("synthesis.pattern", f"{what} designs the CAV's whole command; with "
                          "semantics = 'added' its HDV law hears vehicle -1, so the pattern "
                          "must list -1 (or use semantics = 'replace')")  # fmt: skip
    return "riccati" if design == "full_state" else "direct"


def robust_string_design(
    spec, design_platoon: Callable[[Any], SynthesisReport]
) -> SynthesisReport:
    """Run the robust design of the one-CAV string ``spec`` (a
    :class:`~lcc_synth.synthesis.config.SynthesisSpec` with ``robust`` set, checked by
    :func:`check_robust_string`) on its one-CAV platoon with ``design_platoon`` (the platoon
    design of :func:`lcc_synth.synthesis.design.synthesize`) and report it in the string's
    names and semantics (the module docstring).

    Raises
    ------
    lcc_synth.synthesis.SynthesisError
        As the platoon design does (no stabilising gain, a nominal gain unstable on a member).
    """
    t_start = time.perf_counter()
    system = spec.system
    psys = string_platoon(system)
    cav = system.m + 1
    patterns = None
    if spec.pattern is not None:
        patterns = {cav: tuple(sorted({v + cav for v in spec.pattern} | {cav}))}
    pspec = replace(spec, system=psys, semantics="replace", pattern=None, patterns=patterns,
                    sparsity={"max_loss": 0.01}, cross_check=False)  # the platoon's keys
    prep = design_platoon(pspec)
    K = np.asarray(prep.K, float)[0]  # the CAV's whole command, in the string's state order
    model = system.linear_model(warn=False)
    lag = [0.0] if spec.cav_lag > 0 else []  # the lag state a_0 is in no gain
    whole = make_plant(model, "replace", spec.weights, spec.cav_lag)
    g_whole = np.append(K, lag)
    chk = check_gain(whole, g_whole, f"robust {spec.design} design")
    if spec.semantics == "replace":
        plant, g = whole, g_whole
    else:  # "added": minus the CAV's nominal HDV law (m >= 1: no head feed-through)
        plant = make_plant(model, spec.semantics, spec.weights, spec.cav_lag)
        if plant.kh0 != whole.kh0:  # pragma: no cover - check_robust_string refuses m = 0
            raise SynthesisError("robust design: 'added' changes the head-velocity feed-through")
        g = np.append(K - plant.K0, lag)
    gains = plant.gains(g)
    K_in, kh_in = whole.input_feedback(g_whole)
    heard = sorted(p - cav for p in prep.patterns[f"u_{cav}"])
    notes = [f"robust design on the one-CAV platoon kind = 'platoon', size = {psys.platoon.size},"
             f" cavs = [{cav}] (vehicle i of the string is position i + {cav}): the CAV's "
             "whole command is designed (r weighs it; the CAV's own sampled parameters enter "
             "nowhere)" + ("" if spec.semantics == "replace" else "; the gain is written "
                           "added to the CAV's nominal HDV law: the same closed loop")]
    if model.m > 0:
        notes.append("vehicles ahead are uncontrollable but stable: their gains act as "
                     "feed-forward")  # fmt: skip
    notes += prep.notes
    lmi = {k: (None if getattr(prep, k) is UNSET else getattr(prep, k))  # method = "lmi" only
           for k in ("h2_lmi_bound", "h2_restriction", "solver")}  # fmt: skip
    timings = {k: v for k, v in prep.timings.items() if k != "total"}
    timings["total"] = time.perf_counter() - t_start
    return SynthesisReport(
        problem=spec.name, design=spec.design, kind=model.kind, m=model.m, n=model.n,
        v_star=system.v_star, semantics=spec.semantics, weights=plant.weights.as_dict(),
        disturbances=list(whole.w_names), pattern=heard, state_names=list(model.state_names),
        K=[gains.gains[nm] for nm in model.state_names], gains=dict(gains.gains),
        input_K=list(K_in), input_kh=kh_in, check=chk, h2_lmi_bound=lmi["h2_lmi_bound"],
        h2_restriction=lmi["h2_restriction"], h2_unstructured=prep.h2_unstructured,
        solver=lmi["solver"] or {},
        polish=prep.polish, baseline=None, robust=prep.robust, pareto=None, timings=timings,
        notes=notes, as_run=None, gain=gains,
    )  # fmt: skip
