"""One MPC for every CAV of a mixed platoon or a ring road (``[system] kind = "platoon" |
"ring"``, a ``type = "mpc"`` controller).

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
   slack), ISO 15622 comfort rows per CAV yielding to the spacing
   (:func:`~lcc_synth.mpc.comfort.solve_prioritised`).
5. **Fallback chain, per CAV**, when the QP is not solved: the previous plan shifted by one
   step (while it lasts), else the CAV's static fallback row (a :class:`~lcc_synth.models.
   feedback.Gains` row; default: the CAV's own HDV law, ``"added"`` semantics with a
   zero gain), computed from the states that row reads only, clipped to the limits; else the
   CAV holds its last command. Each CAV's outcome and the failure reason are counted
   (:meth:`JointMPCController.stats`, ``per_cav``).

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
from dataclasses import dataclass
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import free_speed
from lcc_synth.mpc.comfort import jerk_bound
from lcc_synth.mpc.delay import pad
from lcc_synth.mpc.formulation import Family, Formulation, check_horizon
from lcc_synth.mpc.joint_prediction import joint_state_weights, linearize_joint
from lcc_synth.mpc.report import new_step_record, step_statistics
from lcc_synth.mpc.scaffold import (
    STATUS_CODES,
    LoopState,
    MPCScaffold,
    head_prediction,
    update_equilibrium,
)
from lcc_synth.mpc.settings import MPCSettings

__all__ = ["JointMPCController", "STATUS_CODES"]

_OUTCOME = {1: "fallback_shifted", 2: "fallback_static", 3: "fallback_hold"}


@dataclass
class _Member(LoopState):
    """Loop state of one batch member: the shared fields plus each CAV's previous input."""

    u_prev: np.ndarray | None = None
    delay: Any = None  # delay.StateHistory (past observed states) with prediction.delay


class JointMPCController(MPCScaffold):
    """Joint safety-constrained MPC of every CAV of a platoon or ring (module docstring).

    Parameters
    ----------
    name : str
        Controller name.
    settings : MPCSettings
    system : lcc_synth.problem.System
        A system with a :class:`~lcc_synth.models.platoon.Platoon` (``kind = "platoon"`` or
        ``"ring"``) with at least one CAV.
    fallback : Gains, optional
        Static fallback gains, one row per CAV (default: each CAV's HDV law).
    fallback_source : str
        Where the fallback came from (for :meth:`describe`).
    record : bool
        Keep the per-step history (:meth:`history`).
    """

    def __init__(self, name: str, settings: MPCSettings, system,
                 fallback: Gains | None = None, fallback_source: str = "hdv_law",
                 record: bool = True):
        self.name = name
        self.settings = settings
        self.sample_time = settings.sample_time
        self.system = system
        self.platoon = pl = system.platoon
        if pl is None:
            raise ConfigError("system.kind", "the joint MPC needs kind = 'platoon' or 'ring'")
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
        self.kind = system.kind
        self.ring = pl.ring
        self.positions = tuple(pl.cavs)
        self.nu = len(self.positions)
        #: array column of each position 1..N (open: column 0 is the head)
        self.columns = np.arange(pl.size) + (0 if self.ring else 1)
        self.cav_columns = tuple(int(self.columns[i - 1]) for i in self.positions)
        self.record = record
        self._v_hi = min(free_speed(h) for h in pl.hdv)
        try:
            self._lin0 = linearize_joint(pl, self._clip_v(pl.v_star), settings)
        except ConfigError as err:
            where = err.field if err.field.startswith("prediction.") else f"weights ({err.field})"
            raise ConfigError(where, err.message) from None
        model = self._lin0.model
        c = settings.constraints
        self._families = [
            Family(i, 2 * i - 2, 2 * i - 1, c.t_gap, c.s_min) for i in self.positions
        ] if c.spacing_ahead else []
        nz = self._lin0.Ad.shape[0]  # model.nx, plus nu with prediction.cav_lag
        check_horizon(settings.horizon, nz, len(self._families))
        self.formulation = Formulation(
            self.kind, nz, settings, pad(joint_state_weights(model, settings), nz),
            self._families, nu=self.nu,
        )
        self._shift_z, self._shift_y = self.formulation.shift_indices()
        if fallback is None:
            fallback = Gains.zero(model, "added")
        try:
            fallback.input_feedback(model)
        except ConfigError as err:
            raise ConfigError("fallback", f"{err.field}: {err.message}") from None
        self.fallback = fallback
        self.fallback_source = fallback_source
        self._cache: dict[float, tuple] = {}
        self._members: list[_Member] = []
        self._ctx = None
        self._new_record()

    @property
    def n_cav(self) -> int:
        """Number of CAVs the MPC controls."""
        return self.nu

    # ---------------------------------------------------------------- setup helpers

    def _new_record(self) -> None:
        self._st = new_step_record()
        self._per_cav = [
            {"fallback_shifted": 0, "fallback_static": 0, "fallback_hold": 0, "reasons": {},
             "violation_steps": 0, "max_violation_m": 0.0}
            for _ in range(self.nu)
        ]  # fmt: skip
        self._t: list[float] = []

    def _linearize_at(self, v: float):
        return linearize_joint(self.platoon, v, self.settings)

    def _feedback(self, model):
        return self.fallback.input_feedback(model)

    def _check_context(self, ctx) -> None:
        cavs = tuple(int(c) for c in getattr(ctx, "cavs", (ctx.m + 1,)))
        ring = bool(getattr(ctx, "ring", False))
        if cavs != self.cav_columns or ring != self.ring:
            raise ConfigError(
                f"controllers.{self.name}",
                f"the MPC controls CAV columns {list(self.cav_columns)} on "
                f"{'a ring' if self.ring else 'an open platoon'}; the scenario has CAV "
                f"columns {list(cavs)}{' on a ring' if ring else ''}",
            )

    # ---------------------------------------------------------------- protocol

    def reset(self, ctx) -> None:
        """Check the scenario's layout and set up one OSQP workspace per batch member."""
        self._check_context(ctx)
        self._ctx = ctx
        c = self.settings.constraints
        self._a_min = np.full(self.nu, max(c.a_min, ctx.a_min))
        self._a_max = np.full(self.nu, min(c.a_max, ctx.a_max))
        self._new_record()
        W = self._window()
        self._members = []
        for b in range(ctx.batch):
            v0 = float(np.asarray(ctx.v_star).reshape(-1)[b])
            lin, qp, K, kh = self._linearization(v0)
            solver = self._new_solver(qp, np.zeros(self.nu), self._a_min, self._a_max)
            self._members.append(_Member(
                solver, lin, qp, K, kh, np.zeros(W), v_eq=v0, u_prev=np.zeros(self.nu),
                past=np.zeros((max(1, self.formulation.W), self.nu)),
                hist={k: [] for k in _HIST_KEYS},
                delay=None if lin.delay is None else lin.delay.history()))  # fmt: skip

    def __call__(self, obs) -> np.ndarray:
        """The commands of one sample: ``(batch,)`` with one CAV, ``(batch, n_cav)`` with
        several."""
        out = np.zeros((0 if self._ctx is None else self._ctx.batch, self.nu))
        self._run_members(obs, out)
        return out[:, 0].copy() if self.nu == 1 else out

    def _on_error(self, mem: _Member) -> np.ndarray:
        cmd = self._hold(mem, np.arange(self.nu), "error")
        if self.record:
            self._record(mem, cmd, np.full(self.nu, 3), None, 0.0, None, None, None)
        return cmd

    # ---------------------------------------------------------------- one member, one step

    def _observe(self, b: int, mem: _Member, obs):
        """Update ``v_eq``; return (x0, d, s_ref, v) with ``s_ref`` the reference spacings."""
        pred = self.settings.prediction
        cols = self.columns
        s = np.asarray(obs.spacing[b, cols], float)
        v = np.asarray(obs.velocity[b, cols], float)
        if self.ring:
            v_ref = float(np.mean(v))
        else:
            v_ref = float(obs.velocity[b, 0 if self.positions[0] == 1 else 1])
        if pred.equilibrium_mode(self.kind) == "fixed":
            mem.v_eq = float(np.asarray(self._ctx.v_star).reshape(-1)[b])
        else:
            update_equilibrium(mem, v_ref)
        v_eq = mem.v_eq
        ve = self._clip_v(v_eq)
        s_ref = np.array([float(h.equilibrium_spacing(ve)) for h in self.platoon.hdv])
        if self.ring:  # spacing errors summing to zero (module docstring, step 2)
            s_ref += np.mean(s - s_ref)
        x = np.empty(2 * s.size)
        x[0::2] = s - s_ref
        x[1::2] = v - v_eq
        N = self.settings.horizon
        d = np.zeros(N)
        if not self.ring:
            d0, d = head_prediction(mem, v_ref, N, self.sample_time, pred,
                                    float(self._a_min.min()), float(self._a_max.max()))
        else:
            d0 = 0.0
        if pred.cav_lag:  # each CAV's acceleration: measured, else its last command (no lag)
            acc = getattr(obs, "cav_acceleration", None)
            a = mem.past[0] if acc is None else np.asarray(acc, float)[b].reshape(-1)[: self.nu]
            x = np.concatenate([x, a])
        if mem.delay is not None:  # past observations as errors from the current equilibrium
            col = np.minimum(mem.delay.columns, s.size * 2 - 1) // 2
            x = mem.delay.push(x, d0, s_ref[col], v_eq)
        return x, d, s_ref, v, s

    def _step(self, b: int, mem: _Member, obs) -> np.ndarray:
        st = self._st
        c = self.settings.constraints
        x0, d, s_ref, v, s = self._observe(b, mem, obs)
        pos = np.asarray(self.positions) - 1
        if c.spacing_ahead:  # measured violation of each CAV's absolute bound
            with np.errstate(invalid="ignore"):
                viol = c.s_min + c.t_gap * v[pos] - s[pos]
            for k in np.flatnonzero(viol > 1e-6):
                pc = self._per_cav[k]
                pc["violation_steps"] += 1
                pc["max_violation_m"] = max(pc["max_violation_m"], float(viol[k]))
                st["violation_steps"] += 1
                st["max_violation"] = max(st["max_violation"], float(viol[k]))
        self._relinearize(mem)
        form = self.formulation
        N = self.settings.horizon
        if not (np.all(np.isfinite(x0)) and np.all(np.isfinite(d))):
            return self._fallback(mem, x0, d, "nonfinite_state")
        p = form.param(x0, d, mem.u_prev, mem.past)
        fb = np.empty((len(self._families), N))
        for f, fam in enumerate(self._families):
            fb[f] = fam.s_min + c.margin + fam.t_gap * mem.v_eq - s_ref[fam.vehicle - 1]
        jb = np.array([jerk_bound(c.jerk_scale, float(v[i])) for i in pos])
        q, lo, hi = form.bounds(mem.qp, p, self._a_min, self._a_max, fb, jb)
        res = self._solve(mem, q, lo, hi)
        if not res.ok:
            return self._fallback(mem, x0, d, res.status)
        z = res.z
        U = z[: form.n_input].reshape(N, self.nu)
        slack = float(z[form.n_input:].max()) if z.size > form.n_input else 0.0
        self._note_slack(slack)
        mem.plan = U.copy()
        mem.plan_age = 0
        cmd = np.clip(U[0], self._a_min, self._a_max)
        mem.u_prev = cmd.copy()
        if self.record:
            self._record(mem, cmd, np.zeros(self.nu, int), res, slack, x0, d, U)
        return cmd

    def _fallback(self, mem: _Member, x0, d, why: str) -> np.ndarray:
        """Each CAV's fallback chain: shifted plan, its static row, hold (module docstring)."""
        N = self.settings.horizon
        cmd = np.empty(self.nu)
        code = np.empty(self.nu, int)
        if mem.plan is not None and mem.plan_age + 1 < N:
            mem.plan_age += 1
            cmd[:] = np.clip(mem.plan[mem.plan_age], self._a_min, self._a_max)
            code[:] = 1
        else:
            mem.plan = None
            d0 = float(d[0]) if d.size and math.isfinite(d[0]) else 0.0
            for k in range(self.nu):
                row = mem.fb_K[k]
                used = row != 0.0
                u = float(row[used] @ x0[: row.size][used]) + float(mem.fb_kh[k]) * d0
                if math.isfinite(u):
                    cmd[k] = float(np.clip(u, self._a_min[k], self._a_max[k]))
                    code[k] = 2
                else:
                    cmd[k] = self._hold(mem, [k], why)[0]
                    code[k] = 3
        for k in range(self.nu):
            pc = self._per_cav[k]
            if code[k] != 3:  # _hold counts its own
                pc[_OUTCOME[code[k]]] += 1
                self._st[_OUTCOME[code[k]]] += 1
                pc["reasons"][why] = pc["reasons"].get(why, 0) + 1
        mem.u_prev = cmd.copy()
        if self.record:
            self._record(mem, cmd, code, None, 0.0, x0, d, None)
        return cmd

    def _hold(self, mem: _Member, cavs, why: str) -> np.ndarray:
        out = []
        for k in cavs:
            pc = self._per_cav[k]
            pc["fallback_hold"] += 1
            pc["reasons"][why] = pc["reasons"].get(why, 0) + 1
            self._st["fallback_hold"] += 1
            prev = float(mem.past[0, k])
            out.append(float(np.clip(prev if math.isfinite(prev) else 0.0,
                                     self._a_min[k], self._a_max[k])))
        return np.array(out)

    # ---------------------------------------------------------------- history and reports

    def _record(self, mem: _Member, cmd, code, res, slack, x0, d, U) -> None:
        h = mem.hist
        N, nx = self.settings.horizon, self.formulation.nx
        h["u"].append(np.asarray(cmd, float).copy())
        h["status"].append(np.asarray(code, int).copy())
        h["osqp_time"].append(math.nan if res is None else res.run_time)
        h["iterations"].append(-1 if res is None else res.iterations)
        h["slack"].append(slack)
        h["v_eq"].append(mem.v_eq)
        h["x0"].append(np.full(nx, np.nan) if x0 is None else np.asarray(x0, float).copy())
        h["d"].append(np.full(N, np.nan) if d is None else np.asarray(d, float).copy())
        h["plan"].append(np.full((N, self.nu), np.nan) if U is None else U.copy())
        h["lin"].append(mem.lin)

    def history(self) -> dict[str, np.ndarray]:
        """Per-sample record of the last run, leading axes ``(batch, samples)``.

        Keys: ``t (S,)``; ``u (B, S, n_cav)`` applied commands; ``status (B, S, n_cav)``
        (:data:`STATUS_CODES`); ``osqp_time`` (s, NaN when not solved);
        ``iterations``; ``slack`` (largest spacing slack, m); ``v_eq``; ``x0 (B, S, nx)``
        error state (ring: projected); ``d (B, S, N)``; ``plan (B, S, N, n_cav)``;
        ``predicted_states (B, S, N+1, nx)``; ``state_names``.
        """
        if not self._members or not self.record:
            return {}
        S = min(len(m.hist["u"]) for m in self._members)
        out: dict[str, Any] = {"t": np.array(self._t[:S])}
        for key in ("u", "status", "osqp_time", "iterations", "slack", "v_eq", "x0", "d",
                    "plan"):
            out[key] = np.array([np.array(m.hist[key][:S]) for m in self._members])
        N, nx = self.settings.horizon, self.formulation.nx
        X = np.full((len(self._members), S, N + 1, nx), np.nan)
        for b, mem in enumerate(self._members):
            for k in range(S):
                U = mem.hist["plan"][k]
                if np.all(np.isfinite(U)):
                    X[b, k] = mem.hist["lin"][k].predict(mem.hist["x0"][k], mem.hist["d"][k], U)
        nxm = self._lin0.model.nx  # the lag states (prediction.cav_lag) are left out
        out["x0"] = out["x0"][..., :nxm]
        out["predicted_states"] = X[..., :nxm]
        out["state_names"] = np.array(self._lin0.model.state_names)
        return out

    def describe(self) -> dict[str, Any]:
        """Horizon, weights, constraints, prediction, solver, the CAVs and their fallbacks."""
        ref = "mean speed of all vehicles" if self.ring else (
            "head" if self.positions[0] == 1 else "first vehicle of the platoon")
        return self._describe(
            {"joint": True, "cavs": list(self.positions), "ring": self.ring},
            {"equilibrium_reference": ref},
            "condensed joint QP, CasADi symbolic (built once)",
            self.fallback.as_table(),
        )

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable summary (:meth:`describe`)."""
        return self.describe()

    def stats(self) -> dict[str, Any]:
        """The single-CAV MPC's statistics (:func:`~lcc_synth.mpc.report.step_statistics`;
        fallback counters count CAV-samples) plus ``per_cav``: for each ``u_i`` its fallback
        counts, their reasons (OSQP status, ``nonfinite_state``, ``error``) and measured
        violations of its absolute spacing bound."""
        out = step_statistics(self._st)
        out["per_cav"] = {
            f"u_{i}": {**pc, "reasons": dict(pc["reasons"])}
            for i, pc in zip(self.positions, self._per_cav, strict=True)
        }
        return out


_HIST_KEYS = ("u", "status", "osqp_time", "iterations", "slack", "v_eq", "x0", "d", "plan",
              "lin")
