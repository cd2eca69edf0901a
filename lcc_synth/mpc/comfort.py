"""Comfort of the MPC: ISO 15622's bound on the CAV's 1 s average jerk, and its priority.

The QP's comfort rows (:mod:`lcc_synth.mpc.formulation`) bound ``|a_k - a_{k-W}|`` by
``J W Ts``, with ``J = constraints.jerk_scale * limit(v_0)``: ISO 15622's limit at the CAV's
measured speed (:func:`lcc_synth.metrics.iso15622_jerk_limit`: 5 m/s^3 at or below 5 m/s,
2.5 m/s^3 at or above 20 m/s, linear between), taken again at every sample. Within one sample
(0.1 s) the speed moves by at most 0.5 m/s, i.e. the limit by at most 0.08 m/s^3; the default
scale 0.9 (a margin of 0.25-0.5 m/s^3) covers that.

Priority, highest first:

1. the simulator's emergency braking (AEB) and its acceleration limits, which override any
   command (the metric leaves AEB and the second after it out);
2. the hard acceleration bounds of the QP;
3. the safe spacing (soft, exact l1 penalty): whenever the QP with the comfort rows needs more
   spacing slack than the same QP without them (by more than :data:`SLACK_TOL` m, summed over
   the horizon), or fails, the step is solved again without the comfort rows and that solution
   is applied (``jerk_relaxed`` in the step statistics counts these steps);
4. comfort (hard rows otherwise: the QP is always feasible with them, since repeating the last
   ``W`` commands satisfies every row, and past commands lie within the acceleration bounds).

The extra solve runs only on steps whose plan uses spacing slack (warm-started, same OSQP
workspace, only the bounds change).
"""

from __future__ import annotations

import math

import numpy as np

from lcc_synth.metrics import _ISO_JERK  # the limit's (speed, jerk) corners

__all__ = ["SLACK_TOL", "jerk_bound", "solve_prioritised"]

#: Spacing slack (m, summed over the horizon) the comfort rows may cost before they yield.
SLACK_TOL = 1e-4


def jerk_bound(scale: float, v: float) -> float:
    """``J`` (m/s^3) at the CAV's speed ``v``: ``scale`` times ISO 15622's limit (``inf``
    when the rows are off or the speed is unknown)."""
    if scale <= 0 or not math.isfinite(v):
        return math.inf
    # = scale * iso15622_jerk_limit(max(v, 0)) for a finite scalar, without its NaN mask
    return float(scale * np.interp(max(v, 0.0), *_ISO_JERK))


def _slack(form, z: np.ndarray) -> float:
    n = form.n_input  # N inputs per CAV
    return float(np.sum(z[n:])) if z.size > n else 0.0


def solve_prioritised(solver, form, q, lo, hi, warm_z, warm_y, record: dict):
    """Solve with the comfort rows; re-solve without them when they cost spacing slack or the
    solve fails (safety first, see the module docstring). Returns the applied
    :class:`~lcc_synth.mpc.solver.SolveResult` (its ``run_time`` covers both solves)."""
    res = solver.solve(q, lo, hi, warm_z, warm_y)
    if not form.W or not math.isfinite(float(hi[form.jerk_rows][0])):
        return res
    if res.ok and _slack(form, res.z) <= SLACK_TOL:
        return res
    r = form.jerk_rows
    lo2, hi2 = lo.copy(), hi.copy()
    lo2[r], hi2[r] = -np.inf, np.inf
    res2 = solver.solve(q, lo2, hi2, res.z if res.ok else warm_z, res.y if res.ok else warm_y)
    res2.run_time += res.run_time
    res2.iterations += res.iterations
    if res2.ok and (not res.ok or _slack(form, res2.z) < _slack(form, res.z) - SLACK_TOL):
        record["jerk_relaxed"] = record.get("jerk_relaxed", 0) + 1
        return res2
    res.run_time = res2.run_time
    res.iterations = res2.iterations
    return res
