"""The string layout of the one MPC (:class:`~lcc_synth.mpc.controller.MPCController`): every
CAV of a mixed platoon or a ring road (``[system] kind = "platoon" | "ring"``, a ``type =
"mpc"`` controller).

The joint QP is the one condensed QP of :class:`lcc_synth.mpc.formulation.Formulation` with
one input per CAV, on the prediction model of :mod:`lcc_synth.mpc.joint_prediction` (CasADi,
built once); one OSQP workspace per
batch member is set up once and each sample only updates vectors (initial state, equilibrium,
bounds), warm-started from the shifted previous solution, with the status checked as in the
single-CAV MPC (:mod:`lcc_synth.mpc.solver`). Per sample:

1. **Equilibrium.** Open platoon: ``v_eq`` is the moving average (``prediction.
   equilibrium_window``) of the reference velocity, as in the single-CAV MPC: the head
   (array column 0) when the first CAV follows it, else the first vehicle of the platoon
   (column 1; the head is not connected, Section II). Ring: the moving average of the MEAN
   speed of all vehicles. On a ring the equilibrium is fixed by the circumference (every
   vehicle at its equilibrium spacing, the spacings summing to ``C``: ``v* =
   ring_velocity``); with a CAV it is a one-parameter family (the CAV's spacing takes up the
   rest), and the mean speed is the velocity the ring moves at. ``prediction.equilibrium =
   "fixed"`` uses the system's ``v*`` (the ring velocity). ``s_eq,i`` is vehicle ``i``'s own
   equilibrium spacing at ``v_eq`` (its own HDV law; a CAV's: the law of its slot).
2. **State.** ``x = (s_i - s_eq,i, v_i - v_eq)`` for positions ``1..N``. On the ring the
   spacing errors are then shifted by their mean, so that they sum to zero: the spacings sum
   to ``C`` but the ``s_eq,i(v_eq)`` do not (unless ``v_eq`` is the ring velocity), and this
   constant offset lies in the conserved direction ``c`` (total spacing) that no input
   changes. Projected out, the prediction stays on the hyperplane ``c x = 0`` where the
   terminal cost is defined (:func:`~lcc_synth.mpc.joint_prediction.joint_terminal_cost`) and the
   offset cannot bias the solution. Equivalently the reference spacings are ``s_eq,i + delta``
   with ``delta = (C - sum s_eq) / N``; the absolute safe-spacing bounds use the same
   reference, so they stay exact.
3. **Head prediction.** Open: ``d_k = v_ref - v_eq`` held (or the measured acceleration held,
   ``prediction.head = "accel"``), as today; ring: no head.
4. **QP**: each CAV's hard acceleration limits, each CAV's ABSOLUTE soft safe spacing
   ``s_i >= s_min + t_gap v_i`` (``constraints.margin`` tighter, exact l1 + small quadratic
   slack; ``constraints.spacing = "equilibrium"``: the DeeP-LCC paper's ``lo <= s_i - s_ref,i
   <= hi`` instead, :func:`~lcc_synth.mpc.formulation.spacing_families`), ISO 15622 comfort
   rows per CAV yielding to the spacing
   (:func:`~lcc_synth.mpc.comfort.solve_prioritised`).
5. **Fallback chain, per CAV**, when the QP is not solved: the previous plan shifted by one
   step (while it lasts), else the CAV's static fallback row (a :class:`~lcc_synth.models.
   feedback.Gains` row; default: the CAV's own HDV law, ``"added"`` semantics with a
   zero gain), computed from the states that row reads only, clipped to the limits; else the
   CAV holds its last command. Each CAV's outcome and the failure reason are counted
   (:meth:`~lcc_synth.mpc.controller.MPCController.stats`, ``per_cav``).

**Actuator lag** (``prediction.cav_lag``): each CAV's acceleration ``a_i`` is a state of
the prediction (:mod:`lcc_synth.mpc.joint_prediction`), measured at each sample
(``Observation.cav_acceleration``; without lag in the plant: the CAV's last command), as in
the single-CAV MPC (:mod:`lcc_synth.mpc.lag`).

**HDV delays** (``prediction.delay``, one delay or one per HDV front to tail): the delay
register of :mod:`lcc_synth.mpc.delay` over the platoon's HDV rows
(:func:`~lcc_synth.mpc.joint_prediction.joint_delay_model`), filled with the observed past as
errors from the current reference spacings (ring: the projected ones).

Not supported for platoons and rings (a ConfigError naming the key; the feature matrix is in
:mod:`lcc_synth.mpc`): ``n_model`` (the joint MPC models every vehicle), ``constraints.behind``
(every CAV's own spacing is constrained), ``weights.position`` (FD-LCC only). The controller
returns ``(batch,)`` with one CAV and ``(batch, n_cav)`` with several (CAV order of the
platoon).

Measured (``benchmarks/bench_mpc_platoon.py``, N = 50, Ts = 0.1 s, 2 shared cores): the
two-CAV DeeP-LCC platoon in its brake scenario takes 1.5 ms per step (median; OSQP 1.3 ms)
and 20-30 ms at p99: while both CAVs ride the acceleration limit behind the accelerating head
(t = 12-14 s) OSQP needs up to 3600 iterations (other rho / scaling settings did not help);
the 20-vehicle ring with one AV takes 0.6 ms (median) and 4.7 ms (p99).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import free_speed
from lcc_synth.mpc.comfort import jerk_bound
from lcc_synth.mpc.formulation import Family, error_bound, spacing_families
from lcc_synth.mpc.joint_prediction import joint_state_weights, linearize_joint
from lcc_synth.mpc.scaffold import (
    Layout,
    LoopState,
    Sample,
    head_prediction,
    new_history,
    update_equilibrium,
)
from lcc_synth.mpc.settings import MPCSettings

__all__ = ["StringLayout"]

_OUTCOME = {1: "fallback_shifted", 2: "fallback_static", 3: "fallback_hold"}


class StringLayout(Layout):
    """Every CAV of a platoon or ring: the state of positions ``1..N``, one input per CAV
    (module docstring).

    Parameters
    ----------
    system : lcc_synth.problem.System
        A system with a :class:`~lcc_synth.models.platoon.Platoon` (``kind = "platoon"`` or
        ``"ring"``) with at least one CAV.
    settings : MPCSettings
    """

    #: the history's plan is ``(B, S, N, n_cav)``; the command ``(batch, n_cav)``
    joint = True
    default_source = "hdv_law"

    def __init__(self, system, settings: MPCSettings):
        super().__init__(system, settings)
        self.platoon = pl = system.platoon
        if not pl.cavs:
            raise ConfigError("system.cavs", "the MPC needs at least one CAV, got none")
        if settings.n_model is not None:
            raise ConfigError("n_model", "is not used for a platoon or ring: the joint MPC "
                              "models every vehicle")  # fmt: skip
        if settings.constraints.behind:
            raise ConfigError("constraints.behind", "is not used for a platoon or ring: every "
                              "CAV's own spacing ahead is constrained")  # fmt: skip
        if settings.weights.position != 0.0:
            raise ConfigError("weights.position", "applies to fd_lcc only; must be 0 here")
        self.ring = pl.ring
        self.positions = tuple(pl.cavs)
        self.nu = len(self.positions)
        #: array column of each position 1..N (open: column 0 is the head)
        self.columns = np.arange(pl.size) + (0 if self.ring else 1)
        self.cav_columns = tuple(int(self.columns[i - 1]) for i in self.positions)
        self.v_hi = min(free_speed(h) for h in pl.hdv)
        self.v_design = pl.v_star

    # ---------------------------------------------------------------- set-up

    def linearize(self, v: float):
        return linearize_joint(self.platoon, v, self.settings)

    def state_weights(self, model) -> np.ndarray:
        return joint_state_weights(model, self.settings)

    def families(self, model) -> list[Family]:
        c = self.settings.constraints
        if not c.spacing_ahead:
            return []
        return [f for i in self.positions for f in spacing_families(i, 2 * i - 2, 2 * i - 1, c)]

    def default_fallback(self, model) -> Gains:
        return Gains.zero(model, "added")

    def check_fallback(self, model, fallback: Gains, source: str) -> None:
        try:
            fallback.input_feedback(model)
        except ConfigError as err:
            raise ConfigError("fallback", f"{err.field}: {err.message}") from None

    def feedback(self, model, fallback: Gains):
        return fallback.input_feedback(model)

    def check_context(self, ctx, name: str) -> None:
        cavs = tuple(int(c) for c in getattr(ctx, "cavs", (ctx.m + 1,)))
        ring = bool(getattr(ctx, "ring", False))
        if cavs != self.cav_columns or ring != self.ring:
            raise ConfigError(
                f"controllers.{name}",
                f"the MPC controls CAV columns {list(self.cav_columns)} on "
                f"{'a ring' if self.ring else 'an open platoon'}; the scenario has CAV "
                f"columns {list(cavs)}{' on a ring' if ring else ''}",
            )

    def limits(self, a_min: float, a_max: float) -> tuple[np.ndarray, np.ndarray]:
        return np.full(self.nu, a_min), np.full(self.nu, a_max)

    def member(self, mpc, ctx, b: int, W: int) -> LoopState:
        v0 = float(np.asarray(ctx.v_star).reshape(-1)[b])
        lin, qp, K, kh = mpc._linearization(v0)
        solver = mpc._new_solver(qp, np.zeros(self.nu), mpc._a_min, mpc._a_max)
        return LoopState(
            solver, lin, qp, K, kh, np.zeros(W), v_eq=v0, u_prev=np.zeros(self.nu),
            past=np.zeros((max(1, mpc.formulation.W), self.nu)), hist=new_history(),
            delay=None if lin.delay is None else lin.delay.history())  # fmt: skip

    def empty_output(self, batch: int) -> np.ndarray:
        return np.zeros((batch, self.nu))

    def output(self, out: np.ndarray) -> np.ndarray:
        return out[:, 0].copy() if self.nu == 1 else out

    # ---------------------------------------------------------------- one sample

    def observe(self, mpc, b: int, mem: LoopState, obs) -> Sample:
        """Update ``v_eq``; the state, head prediction and the reference spacings ``s_ref``
        (module docstring, steps 1-3)."""
        pred = self.settings.prediction
        cols = self.columns
        s = np.asarray(obs.spacing[b, cols], float)
        v = np.asarray(obs.velocity[b, cols], float)
        if self.ring:
            v_ref = float(np.mean(v))
        else:
            v_ref = float(obs.velocity[b, 0 if self.positions[0] == 1 else 1])
        if pred.equilibrium_mode(self.kind) == "fixed":
            mem.v_eq = float(np.asarray(mpc._ctx.v_star).reshape(-1)[b])
        else:
            update_equilibrium(mem, v_ref)
        v_eq = mem.v_eq
        ve = mpc._clip_v(v_eq)
        s_ref = self.platoon.spacings_at(ve)
        if self.ring:  # spacing errors summing to zero (module docstring, step 2)
            s_ref += np.mean(s - s_ref)
        x = np.empty(2 * s.size)
        x[0::2] = s - s_ref
        x[1::2] = v - v_eq
        N = self.settings.horizon
        d = np.zeros(N)
        if not self.ring:
            d0, d = head_prediction(mem, v_ref, N, mpc.sample_time, pred,
                                    float(mpc._a_min.min()), float(mpc._a_max.max()))
        else:
            d0 = 0.0
        if pred.cav_lag:  # each CAV's acceleration: measured, else its last command (no lag)
            acc = getattr(obs, "cav_acceleration", None)
            a = mem.past[0] if acc is None else np.asarray(acc, float)[b].reshape(-1)[: self.nu]
            x = np.concatenate([x, a])
        if mem.delay is not None:  # past observations as errors from the current equilibrium
            col = np.minimum(mem.delay.columns, s.size * 2 - 1) // 2
            x = mem.delay.push(x, d0, s_ref[col], v_eq)
        return Sample(x, d, d, {"s_ref": s_ref, "v": v, "s": s})

    def count_violations(self, mpc, o: Sample) -> None:
        """The measured violation of each CAV's spacing bound (absolute, or of its spacing
        error from ``s_ref`` with ``constraints.spacing = "equilibrium"``)."""
        c = self.settings.constraints
        if not c.spacing_ahead:
            return
        st = mpc._st
        pos = np.asarray(self.positions) - 1
        v, s = o.extra["v"], o.extra["s"]
        with np.errstate(invalid="ignore"):
            if c.spacing == "safe":
                viol = c.s_min + c.t_gap * v[pos] - s[pos]
            else:
                err = s[pos] - o.extra["s_ref"][pos]
                viol = np.maximum(c.spacing_error[0] - err, err - c.spacing_error[1])
        for k in np.flatnonzero(viol > 1e-6):
            pc = mpc._per_cav[k]
            pc["violation_steps"] += 1
            pc["max_violation_m"] = max(pc["max_violation_m"], float(viol[k]))
            st["violation_steps"] += 1
            st["max_violation"] = max(st["max_violation"], float(viol[k]))

    def spacing_bounds(self, mpc, mem: LoopState, o: Sample) -> np.ndarray:
        c = self.settings.constraints
        s_ref = o.extra["s_ref"]
        fb = np.empty((len(mpc._families), self.settings.horizon))
        for f, fam in enumerate(mpc._families):
            if fam.bound != "safe":  # the spacing error x[s] = s - s_ref (step 2)
                fb[f] = error_bound(fam, c.margin)
                continue
            fb[f] = fam.s_min + c.margin + fam.t_gap * mem.v_eq - s_ref[fam.vehicle - 1]
        return fb

    def jerk_bounds(self, o: Sample) -> np.ndarray:
        v = o.extra["v"]
        scale = self.settings.constraints.jerk_scale
        return np.array([jerk_bound(scale, float(v[i - 1])) for i in self.positions])

    def plan(self, U: np.ndarray) -> np.ndarray:
        return U.reshape(self.settings.horizon, self.nu)

    def command(self, mpc, mem: LoopState, o: Sample, U: np.ndarray):
        """``(cmd, cmd, codes)``: each CAV's first input, clipped; sets ``u_prev``."""
        cmd = np.clip(U[0], mpc._a_min, mpc._a_max)
        mem.u_prev = cmd.copy()
        return cmd, cmd, np.zeros(self.nu, int)

    def fallback(self, mpc, mem: LoopState, o: Sample, why: str) -> np.ndarray:
        """Each CAV's fallback chain: shifted plan, its static row, hold (module docstring)."""
        N = self.settings.horizon
        x0, d = o.x0, o.d
        cmd = np.empty(self.nu)
        code = np.empty(self.nu, int)
        if mem.plan is not None and mem.plan_age + 1 < N:
            mem.plan_age += 1
            cmd[:] = np.clip(mem.plan[mem.plan_age], mpc._a_min, mpc._a_max)
            code[:] = 1
        else:
            mem.plan = None
            d0 = float(d[0]) if d.size and math.isfinite(d[0]) else 0.0
            for k in range(self.nu):
                row = mem.fb_K[k]
                used = row != 0.0
                u = float(row[used] @ x0[: row.size][used]) + float(mem.fb_kh[k]) * d0
                if math.isfinite(u):
                    cmd[k] = float(np.clip(u, mpc._a_min[k], mpc._a_max[k]))
                    code[k] = 2
                else:
                    cmd[k] = self._hold(mpc, mem, [k], why)[0]
                    code[k] = 3
        for k in range(self.nu):
            pc = mpc._per_cav[k]
            if code[k] != 3:  # _hold counts its own
                pc[_OUTCOME[code[k]]] += 1
                mpc._st[_OUTCOME[code[k]]] += 1
                pc["reasons"][why] = pc["reasons"].get(why, 0) + 1
        mem.u_prev = cmd.copy()
        if mpc.record:
            mpc._record(mem, cmd, cmd, code, None, 0.0, x0, d, None)
        return cmd

    def hold(self, mpc, mem: LoopState, why: str) -> np.ndarray:
        return self._hold(mpc, mem, range(self.nu), why)

    def _hold(self, mpc, mem: LoopState, cavs, why: str) -> np.ndarray:
        out = []
        for k in cavs:
            pc = mpc._per_cav[k]
            pc["fallback_hold"] += 1
            pc["reasons"][why] = pc["reasons"].get(why, 0) + 1
            mpc._st["fallback_hold"] += 1
            prev = float(mem.past[0, k])
            out.append(float(np.clip(prev if math.isfinite(prev) else 0.0,
                                     mpc._a_min[k], mpc._a_max[k])))
        return np.array(out)

    # ---------------------------------------------------------------- history and reports

    def failed(self, value: int) -> np.ndarray:
        return np.full(self.nu, value)

    def history(self, mpc, out: dict[str, Any], S: int) -> None:
        """No keys beyond the common ones (:meth:`~lcc_synth.mpc.controller.MPCController.
        history`)."""

    def describe(self, mpc) -> tuple[dict, dict, str, Any]:
        ref = "mean speed of all vehicles" if self.ring else (
            "head" if self.positions[0] == 1 else "first vehicle of the platoon")
        return ({"joint": True, "cavs": list(self.positions), "ring": self.ring},
                {"equilibrium_reference": ref},
                "condensed joint QP, CasADi symbolic (built once)",
                mpc.fallback.as_table())  # fmt: skip

    def as_dict(self, mpc) -> dict[str, Any]:
        return mpc.describe()

    def stats(self, mpc, out: dict[str, Any]) -> dict[str, Any]:
        out["per_cav"] = {
            f"u_{i}": {**pc, "reasons": dict(pc["reasons"])}
            for i, pc in zip(self.positions, mpc._per_cav, strict=True)
        }
        return out
