"""Safety summary of simulated runs against the MPC's absolute spacing bound.

The bound ``s_0 >= s_min + t_gap v_0`` of :class:`~lcc_synth.mpc.settings.Constraints` is
checked on the simulator's trajectories (every integration step, not only the controller's
samples) for ANY controller, so the MPC and the static gains are judged by the same rule.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = [
    "bound_margin", "safety_summary", "new_step_record", "predicted_states", "step_statistics"
]


def bound_margin(result, s_min: float = 5.0, t_gap: float = 0.8) -> np.ndarray:
    """``s_0 - (s_min + t_gap v_0)`` of the CAV at every recorded step, ``(batch, T)`` (m).

    Negative entries violate the bound; NaN after a collision.
    """
    cav = result.cav
    return result.spacing[:, :, cav] - (s_min + t_gap * result.velocity[:, :, cav])


def safety_summary(result, s_min: float = 5.0, t_gap: float = 0.8) -> dict[str, Any]:
    """Bound violations of one run plus the MPC's statistics when the controller has them.

    Returns
    -------
    dict
        ``bound_violation_steps`` (recorded steps below the bound, all batch members),
        ``max_bound_violation_m``, ``min_bound_margin_m``, ``aeb_activations``, ``collisions``,
        and for an MPC ``fallbacks``, ``qp_failures``, ``slack_steps``, ``step_time_ms``
        (median / p99 / max) and ``osqp_time_ms``.
    """
    margin = bound_margin(result, s_min, t_gap)
    with np.errstate(invalid="ignore"):
        viol = np.where(np.isfinite(margin), np.maximum(-margin, 0.0), 0.0)
    out: dict[str, Any] = {
        "bound": {"s_min": s_min, "t_gap": t_gap},
        "bound_violation_steps": int(np.count_nonzero(viol > 0.0)),
        "max_bound_violation_m": float(viol.max()) if viol.size else 0.0,
        "min_bound_margin_m": float(np.nanmin(margin)) if np.isfinite(margin).any() else None,
        "aeb_activations": int(np.count_nonzero(result.aeb_active)),
        "collisions": int(np.count_nonzero(result.collided)),
    }
    st = result.controller_stats or {}
    if "step_time_ms" in st:
        out.update(
            {
                "fallbacks": st["fallbacks"],
                "qp_failures": st["qp_failures"],
                "slack_steps": st["slack_steps"],
                "step_time_ms": {k: st["step_time_ms"][k] for k in ("median", "p99", "max")},
                "osqp_time_ms": {k: st["osqp_time_ms"][k] for k in ("median", "p99", "max")},
            }
        )
    return out


def new_step_record() -> dict[str, Any]:
    """An empty step record of the MPC: counters and per-step times, filled in by the controller
    during a run and summarised by :func:`step_statistics`."""
    return {
        "steps": 0,
        "solves": 0,
        "qp_failures": {},
        "polish": {},
        "fallback_shifted": 0,
        "fallback_static": 0,
        "fallback_hold": 0,
        "errors": 0,
        "error_messages": [],
        "relinearizations": 0,
        "relinearize_failures": 0,
        "slack_steps": 0,
        "max_slack": 0.0,
        "jerk_relaxed": 0,
        "violation_steps": 0,
        "max_violation": 0.0,
        "step_time": [],
        "osqp_time": [],
        "relin_time": [],
        "iterations": [],
    }


def step_statistics(st: dict[str, Any]) -> dict[str, Any]:
    """:meth:`MPCController.stats <lcc_synth.mpc.controller.MPCController.stats>` of the
    controller's step record ``st`` (times in s, turned into ms distributions)."""

    def dist(values):
        a = np.asarray(values, float) * 1e3
        if a.size == 0:
            return {"median": None, "p99": None, "max": None, "mean": None, "count": 0}
        return {
            "median": float(np.median(a)),
            "p99": float(np.percentile(a, 99)),
            "max": float(a.max()),
            "mean": float(a.mean()),
            "count": int(a.size),
        }

    it = np.asarray(st["iterations"], float)
    fallbacks = st["fallback_shifted"] + st["fallback_static"] + st["fallback_hold"]
    return {
        "steps": st["steps"],
        "solves": st["solves"],
        "step_time_ms": dist(st["step_time"]),
        "osqp_time_ms": dist(st["osqp_time"]),
        "relinearize_time_ms": dist(st["relin_time"]),
        "iterations": {
            "median": float(np.median(it)) if it.size else None,
            "max": int(it.max()) if it.size else None,
        },
        "qp_failures": dict(st["qp_failures"]),
        "polish": dict(st["polish"]),
        "fallbacks": fallbacks,
        "fallback_shifted": st["fallback_shifted"],
        "fallback_static": st["fallback_static"],
        "fallback_hold": st["fallback_hold"],
        "errors": st["errors"],
        "error_messages": list(st["error_messages"]),
        "relinearizations": st["relinearizations"],
        "relinearize_failures": st["relinearize_failures"],
        "slack_steps": st["slack_steps"],
        "max_slack_m": st["max_slack"],
        "jerk_relaxed": st.get("jerk_relaxed", 0),
        "violation_steps": st["violation_steps"],
        "max_violation_m": st["max_violation"],
    }


def predicted_states(hists: list[dict], S: int, N: int, nx: int) -> np.ndarray:
    """The predicted states ``(B, S, N+1, nx)`` of every recorded plan of the members'
    histories (``lin.predict`` from the recorded ``x0``, ``d``, ``plan``); NaN where no plan
    was solved. Only the first ``nx`` states are kept (not the delay states)."""
    X = np.full((len(hists), S, N + 1, nx), np.nan)
    for b, h in enumerate(hists):
        for k in range(S):
            U = h["plan"][k]
            if np.all(np.isfinite(U)):
                X[b, k] = h["lin"][k].predict(h["x0"][k], h["d"][k], U)[:, :nx]
    return X
