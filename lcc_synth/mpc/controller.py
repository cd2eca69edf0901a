"""The LCC model predictive controller (a controller of :mod:`lcc_synth.controllers.base`).

At every sample (``sample_time``, default 0.1 s; the simulator holds the command in between):

1. **Equilibrium.** ``v_eq`` is the moving average (``prediction.equilibrium_window``) of the
   reference velocity: the vehicle ahead of the CAV when ``m = 0`` (CF-LCC, LCC with m = 0; the
   CAV senses it), vehicle ``-m`` otherwise (the head of general LCC is not connected, Section
   II). FD-LCC uses the fixed design velocity ``v*`` (Remark 1 of the paper). ``s_eq`` is the
   nominal HDV model's equilibrium spacing at ``v_eq``, plus each vehicle's offset
   ``s_ref - s*`` from the context (heterogeneous strings with ``spacing_reference =
   "own_equilibrium"``; zero otherwise).
2. **State.** The error state of the model (``s_i - s_eq``, ``v_i - v_eq`` for the CAV and the
   ``n_model`` HDVs behind, the HDVs ahead; ``prediction.delay``: also the past samples the
   delayed HDVs react to, :mod:`lcc_synth.mpc.delay`). FD-LCC's ``-p_0`` is the CAV's position
   relative to a reference point moving at ``v_eq``; when its weight is 0 it is re-zeroed at
   every sample (the QP then only uses it to predict the spacing to a vehicle ahead, if any).
3. **Head prediction.** ``d_k = v_ref - v_eq`` held over the horizon (``head = "constant"``), or
   the reference vehicle's measured acceleration held for ``head_accel_hold`` seconds
   (``head = "accel"``; velocity never below 0).
4. **Re-linearisation** (option): when ``|v_eq - v_lin| > relinearize_threshold`` the HDV model
   is re-linearised at ``v_eq`` rounded to a quarter of the threshold, and OSQP gets the new
   matrix values (same pattern, ``update(Px=..., Ax=...)``). Linearisations are cached on that
   grid, so batch members and returns to an earlier speed reuse them; a new one costs one
   CasADi evaluation and one Riccati solve (tens of ms, see ``benchmarks/bench_mpc.py``).
5. **QP** (:mod:`lcc_synth.mpc.formulation`) solved by OSQP with warm start from the shifted
   previous solution. The cost regulates the string towards the equilibrium consistent with the
   PREDICTED head velocity. The safe spacing to the vehicle ahead is in ABSOLUTE metres,
   ``s_0 >= s_min + t_gap v_0`` with ``s_0 = s_eq + s~_0`` and ``v_0 = v_eq + v~_0``, enforced
   ``constraints.margin`` tighter (default 0.1 m: covers the mismatch between the exact ZOH
   prediction and the simulator's Euler steps), soft with an exact l1 penalty (FD-LCC: ``s_0``
   predicted from the measured spacing, the vehicle ahead moving with the head prediction).
6. **Fallback chain** when the QP is not solved (status other than ``solved``, non-finite
   data, any exception): the previous plan shifted by one step (while it lasts), else a static
   gain (another controller of the file, ``fallback = "h2"`` in ``problems/showcase.toml``; or
   ``fallback_gains_file``; else the paper's Section V-B gain for FD-/CF-LCC and the CAV's HDV
   law for LCC/CCC) on the same error state, clipped to the acceleration
   limits; the simulator's emergency braking is the last layer. Nothing raises inside the loop.
7. **Comfort** (``constraints.jerk_scale``): the QP bounds the 1 s average jerk by a fraction of
   ISO 15622's limit at the CAV's speed, and yields to the safe spacing (:mod:`~lcc_synth.mpc.
   comfort`: its priority order).

The applied command is the model input for LCC/FD-LCC/CCC and ``K_law x + k_h d_0 + u_hat`` (the
CAV's linear HDV law plus the MPC's added input) for CF-LCC.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lcc_synth.controllers.base import ControlContext, Observation
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains, cav_feedback
from lcc_synth.models.hdv import free_speed
from lcc_synth.mpc.comfort import jerk_bound
from lcc_synth.mpc.delay import pad
from lcc_synth.mpc.formulation import (
    Family,
    Formulation,
    Linearization,
    check_horizon,
    linearize,
    state_weights,
)
from lcc_synth.mpc.report import new_step_record, predicted_states, step_statistics
from lcc_synth.mpc.scaffold import (
    STATUS_CODES,
    LoopState,
    MPCScaffold,
    head_prediction,
    update_equilibrium,
)
from lcc_synth.mpc.settings import MPCSettings, paper_fallback_gains
from lcc_synth.mpc.step_cache import LastValue, clip

__all__ = ["MPCController", "STATUS_CODES"]


@dataclass
class _Member(LoopState):
    """Loop state of one batch member: the shared fields plus the single-CAV ones."""

    s_off: np.ndarray = field(default_factory=lambda: np.zeros(0))
    p_ref: float = math.nan
    u_prev: float = 0.0
    cmd_prev: float = 0.0
    delay: Any = None  # delay.StateHistory (past observed states) or lag.LagState (a_0)
    s_off_cols: np.ndarray | None = None  # s_off of the modelled vehicles (state order)
    s_eq: LastValue = field(default_factory=LastValue)
    hist: dict[str, list] = field(default_factory=dict)


class MPCController(MPCScaffold):
    """Safety-constrained linear MPC of the CAV (see the module docstring).

    Parameters
    ----------
    name : str
        Controller name.
    settings : MPCSettings
    system : lcc_synth.problem.System
        Kind, ``m``, ``n``, nominal HDV model and design ``v*``.
    fallback : Gains, optional
        Static fallback gain (default :func:`paper_fallback_gains`).
    fallback_source : str
        Where the fallback came from (for :meth:`describe`).
    record : bool
        Keep the per-step history (:meth:`history`).

    Attributes
    ----------
    history_enabled : bool
    """

    def __init__(
        self,
        name: str,
        settings: MPCSettings,
        system,
        fallback: Gains | None = None,
        fallback_source: str = "paper",
        record: bool = True,
    ):
        self.name = name
        self.settings = settings
        self.sample_time = settings.sample_time
        self.system = system
        self.kind = system.kind
        self.m = system.m
        n_model = system.n if settings.n_model is None else settings.n_model
        if n_model > system.n:
            raise ConfigError("n_model", f"must be <= [system].n = {system.n}, got {n_model}")
        if self.kind in ("cf_lcc", "fd_lcc") and n_model < 1:
            raise ConfigError("n_model", f"must be >= 1 for {self.kind}, got {n_model}")
        if self.kind == "lcc" and self.m == 0 and n_model == 0:
            raise ConfigError("n_model", "must be >= 1 for LCC with m = 0")
        self.n_model = n_model
        self.record = record
        self._v_hi = free_speed(system.hdv)
        v0 = self._clip_v(system.v_star)
        try:
            self._lin0 = linearize(self.kind, self.m, n_model, system.hdv, v0, settings)
        except ConfigError as err:
            where = err.field if err.field.startswith("prediction.") else f"weights ({err.field})"
            raise ConfigError(where, err.message) from None
        model = self._lin0.model
        self._families = self._make_families(model)
        nz = self._lin0.Ad.shape[0]  # model.nx, or more with delay states
        check_horizon(settings.horizon, nz, len(self._families))
        self.formulation = Formulation(
            self.kind, nz, settings, pad(state_weights(model, settings), nz), self._families
        )
        self._shift_z, self._shift_y = self.formulation.shift_indices()
        self.fallback = fallback if fallback is not None else paper_fallback_gains(
            self.kind, n_model
        )
        self.fallback_source = fallback_source
        try:
            cav_feedback(model, self.fallback)
        except ConfigError as err:
            from_file = fallback_source != "paper" and not fallback_source.startswith("controller")
            raise ConfigError(
                "fallback_gains_file" if from_file else "fallback",
                f"{err.field}: {err.message} (the MPC models m={self.m}, n={n_model})",
            ) from None
        self._cache: dict[float, tuple[Linearization, Any, np.ndarray, float]] = {}
        self._members: list[_Member] = []
        self._ctx: ControlContext | None = None
        self._st = new_step_record()

    # ---------------------------------------------------------------- setup helpers

    def _make_families(self, model) -> list[Family]:
        c = self.settings.constraints
        fams = []
        if c.spacing_ahead:
            b = model.block(0)
            fams.append(Family(0, b.start, b.start + 1, c.t_gap, c.s_min))
        for i in c.behind:
            if i > self.n_model:
                raise ConfigError(
                    "constraints.behind",
                    f"HDV {i} is not in the MPC's model (n_model = {self.n_model})",
                )
            b = model.block(i)
            fams.append(Family(i, b.start, b.start + 1, c.t_gap_behind, c.s_min_behind))
        return fams

    def _linearize_at(self, v: float) -> Linearization:
        return linearize(self.kind, self.m, self.n_model, self.system.hdv, v, self.settings)

    def _feedback(self, model) -> tuple[np.ndarray, float]:
        K, kh = cav_feedback(model, self.fallback)
        return np.asarray(K, float), float(kh)

    # ---------------------------------------------------------------- protocol

    def reset(self, ctx: ControlContext) -> None:
        """Set up one OSQP workspace per batch member (the only solver set-up of the run)."""
        if ctx.m != self.m or ctx.n < self.n_model:
            raise ConfigError(
                f"controllers.{self.name}",
                f"the MPC models m={self.m}, n={self.n_model}; the scenario has "
                f"m={ctx.m}, n={ctx.n}",
            )
        self._ctx = ctx
        self._a_min = max(self.settings.constraints.a_min, ctx.a_min)
        self._a_max = min(self.settings.constraints.a_max, ctx.a_max)
        self._st = new_step_record()
        self._t = []
        W = self._window()
        self._members = []
        self._cols = np.arange(-self.m, self.n_model + 1) + self.m + 1
        for b in range(ctx.batch):
            lin, qp, K, kh = self._linearization(float(ctx.v_star[b]))
            solver = self._new_solver(qp, 0.0, self._a_min, self._a_max)
            s_off = np.asarray(ctx.spacing_reference()[b], float) - float(ctx.s_star[b])
            s_off = np.nan_to_num(s_off, nan=0.0)
            mem = _Member(solver, lin, qp, K, kh, np.zeros(W), s_off=s_off,
                          v_eq=float(ctx.v_star[b]))
            mem.hist = {k: [] for k in _HIST_KEYS}
            mem.s_off_cols = s_off[self._cols]
            mem.past = np.zeros(max(1, self.formulation.W))
            mem.delay = None if lin.delay is None else lin.delay.history()  # delay, lag
            self._members.append(mem)

    def __call__(self, obs: Observation) -> np.ndarray:
        """The commands ``(batch,)`` of one sample (the steps of the module docstring)."""
        out = np.zeros(0 if self._ctx is None else self._ctx.batch)
        self._run_members(obs, out)
        return out

    def _on_error(self, mem: _Member) -> float:
        cmd = self._hold(mem)
        self._record_fail(mem, cmd)
        return cmd

    # ---------------------------------------------------------------- one member, one step

    def _observe(self, b: int, mem: _Member, obs: Observation):
        """Update ``v_eq``; return (x0, xi_full, d, v_ref, s0_meas)."""
        ctx = self._ctx
        pred = self.settings.prediction
        m, cav = self.m, ctx.cav
        ref_col = 0 if m == 0 else 1
        v_ref = float(obs.velocity[b, ref_col])
        if pred.equilibrium_mode(self.kind) == "fixed":
            mem.v_eq = float(ctx.v_star[b])
        else:
            update_equilibrium(mem, v_ref)
        v_eq = mem.v_eq
        s_eq = mem.s_eq.get(self.system.hdv, self._clip_v(v_eq))
        cols = self._cols
        x = np.empty(2 * cols.size)
        x[0::2] = obs.spacing[b, cols] - s_eq - mem.s_off_cols  # (spacing - s_eq) - s_off
        x[1::2] = obs.velocity[b, cols] - v_eq
        # FD-LCC: -p_0 relative to a reference moving at v_eq
        p0 = float(obs.position[b, cav])
        if math.isnan(mem.p_ref):
            mem.p_ref = p0
        xi = -(p0 - mem.p_ref)
        mem.p_ref += v_eq * self.sample_time
        if self.kind == "fd_lcc":
            x[0] = xi if self.settings.weights.position > 0 else 0.0
        N = self.settings.horizon
        d0, d = head_prediction(mem, v_ref, N, self.sample_time, pred, self._a_min, self._a_max)
        d_model = np.zeros(N) if self.kind == "fd_lcc" else d  # FD-LCC: no head input
        s0 = float(obs.spacing[b, cav])
        if mem.delay is not None:
            x = mem.delay.push(x, d0, s_eq, v_eq, obs=obs, b=b, u_prev=float(mem.past[0]))
        return x, xi, d, d_model, s_eq, s0

    def _family_bounds(self, mem: _Member, x0, d, s_eq, s0) -> np.ndarray:
        N = self.settings.horizon
        v_eq = mem.v_eq
        out = np.empty((len(self._families), N))
        for f, fam in enumerate(self._families):
            base = fam.s_min + self.settings.constraints.margin + fam.t_gap * v_eq
            if fam.vehicle == 0 and self.kind == "fd_lcc":
                if not math.isfinite(s0):
                    out[f] = -np.inf
                    continue
                # s_0(k) = s0 + sum_{j<k} (v_ahead_j - v_eq) Ts + (xi_k - xi_0)
                drift = np.cumsum(d) * self.sample_time
                out[f] = base - (s0 - x0[0] + drift)
            else:
                out[f] = base - s_eq - mem.s_off[fam.vehicle + self.m + 1]
        return out

    def _step(self, b: int, mem: _Member, obs: Observation) -> float:
        st = self._st
        x0, xi, d, d_model, s_eq, s0 = self._observe(b, mem, obs)
        # measured constraint violation (absolute spacing to the vehicle ahead)
        c = self.settings.constraints
        v0 = float(obs.velocity[b, self._ctx.cav])
        if c.spacing_ahead and math.isfinite(s0) and math.isfinite(v0):
            viol = c.s_min + c.t_gap * v0 - s0
            if viol > 1e-6:
                st["violation_steps"] += 1
                st["max_violation"] = max(st["max_violation"], viol)
        self._relinearize(mem)
        lin, form, N = mem.lin, self.formulation, self.settings.horizon
        if not (np.isfinite(x0).all() and np.isfinite(d_model).all()):
            return self._fallback(mem, x0, xi, d_model, "nonfinite_state")
        p = form.param(x0, d_model, mem.u_prev, mem.past)
        fb = self._family_bounds(mem, x0, d, s_eq, s0)
        jb = jerk_bound(c.jerk_scale, v0)
        q, lo, hi = form.bounds(mem.qp, p, self._a_min, self._a_max, fb, jb)
        res = self._solve(mem, q, lo, hi)
        if not res.ok:
            return self._fallback(mem, x0, xi, d_model, res.status)
        z = res.z
        U = z[:N]
        slack = float(z[N:].max()) if z.size > N else 0.0
        self._note_slack(slack)
        mem.plan = U.copy()
        mem.plan_age = 0
        u_model = float(U[0])
        cmd = self._total(lin, x0, d_model[0], u_model)
        mem.u_prev = cmd if self.settings.weights.input_on == "total" else u_model
        mem.cmd_prev = cmd
        if self.record:
            self._record(mem, cmd, u_model, 0, res, slack, x0, d_model, U)
        return cmd

    def _total(self, lin: Linearization, x0, d0: float, u_model: float) -> float:
        u = u_model
        if self.kind == "cf_lcc":
            u += float(lin.K_law @ x0) + lin.k_h * d0
        return clip(u, self._a_min, self._a_max)

    def _fallback(self, mem: _Member, x0, xi, d_model, why: str) -> float:
        st = self._st
        N = self.settings.horizon
        lin = mem.lin
        if (
            mem.plan is not None
            and mem.plan_age + 1 < N
            and np.all(np.isfinite(x0))
            and np.all(np.isfinite(d_model))
        ):
            mem.plan_age += 1
            u_model = float(mem.plan[mem.plan_age])
            cmd = self._total(lin, x0, d_model[0], u_model)
            st["fallback_shifted"] += 1
            code = 1
        else:
            xs = np.array(x0[: mem.fb_K.size], dtype=float)  # without delay states
            if self.kind == "fd_lcc":
                xs[0] = xi
            cmd = float(mem.fb_K @ xs + mem.fb_kh * (d_model[0] if d_model.size else 0.0))
            if math.isfinite(cmd):
                cmd = float(np.clip(cmd, self._a_min, self._a_max))
                u_model = cmd
                if self.kind == "cf_lcc" and np.all(np.isfinite(x0)):
                    u_model = cmd - float(lin.K_law @ x0) - lin.k_h * d_model[0]
                mem.plan = None
                st["fallback_static"] += 1
                code = 2
            else:
                cmd = self._hold(mem)
                self._record_fail(mem, cmd)
                return cmd
        mem.u_prev = cmd if self.settings.weights.input_on == "total" else u_model
        mem.cmd_prev = cmd
        if self.record:
            self._record(mem, cmd, u_model, code, None, 0.0, x0, d_model, None)
        return cmd

    def _hold(self, mem: _Member) -> float:
        self._st["fallback_hold"] += 1
        cmd = mem.cmd_prev if math.isfinite(mem.cmd_prev) else 0.0
        return float(np.clip(cmd, self._a_min, self._a_max))

    # ---------------------------------------------------------------- history

    def _record(self, mem: _Member, cmd, u_model, code, res, slack, x0, d, U) -> None:
        h = mem.hist
        N = self.settings.horizon
        h["u"].append(cmd)
        h["u_model"].append(u_model)
        h["status"].append(code)
        h["osqp_time"].append(math.nan if res is None else res.run_time)
        h["iterations"].append(-1 if res is None else res.iterations)
        h["slack"].append(slack)
        h["v_eq"].append(mem.v_eq)
        h["v_lin"].append(mem.lin.v_lin)
        h["x0"].append(np.asarray(x0, float).copy())
        h["d"].append(np.asarray(d, float).copy())
        h["plan"].append(np.full(N, np.nan) if U is None else np.asarray(U, float).copy())
        h["lin"].append(mem.lin)

    def _record_fail(self, mem: _Member, cmd: float) -> None:
        if not self.record:
            return
        nx = mem.lin.Ad.shape[0]
        N = self.settings.horizon
        self._record(mem, cmd, math.nan, 3, None, 0.0, np.full(nx, np.nan), np.full(N, np.nan),
                     None)

    def history(self) -> dict[str, np.ndarray]:
        """Per-sample record of the last run, arrays with leading axes ``(batch, samples)``.

        Keys: ``t (S,)``; ``u`` applied command; ``u_model`` model input (CF-LCC: ``u_hat``);
        ``status`` (:data:`STATUS_CODES`); ``step_time`` (s, whole controller step) and
        ``osqp_time`` (s, OSQP run time, NaN when not solved); ``iterations``; ``slack`` (largest
        spacing slack, m); ``v_eq``, ``v_lin``; ``x0 (B, S, nx)`` error state; ``d (B, S, N)``
        head prediction; ``plan (B, S, N)`` optimal model inputs; ``predicted_states
        (B, S, N+1, nx)``; ``predicted_velocity`` and ``predicted_spacing`` ``(B, S, N+1, V)``
        absolute values for the modelled vehicles ``-m..n_model`` (``state_names`` tells the
        order; FD-LCC's CAV spacing column is NaN); ``pred_time (N+1,)`` offsets (s).
        """
        if not self._members or not self.record:
            return {}
        N = self.settings.horizon
        out: dict[str, Any] = {"t": np.array(self._t)}
        B = len(self._members)
        S = min(len(m.hist["u"]) for m in self._members)
        for key in ("u", "u_model", "status", "osqp_time", "iterations", "slack", "v_eq", "v_lin"):
            out[key] = np.array([m.hist[key][:S] for m in self._members])
        out["step_time"] = np.array(self._st["step_time"][: S * B]).reshape(S, B).T
        nx = self._lin0.model.nx  # the delay states are left out
        for key in ("x0", "d", "plan"):
            out[key] = np.array([np.array(m.hist[key][:S]) for m in self._members])
        out["x0"] = out["x0"][..., :nx]
        out["predicted_states"] = X = predicted_states([m.hist for m in self._members], S, N, nx)
        v_eq = out["v_eq"][:, :, None, None]
        v_cl = np.clip(out["v_eq"], 1.0, self._v_hi - 1.0)
        s_eq = np.asarray(self.system.hdv.equilibrium_spacing(v_cl))[:, :, None, None]
        out["predicted_velocity"] = X[..., 1::2] + v_eq
        cols = np.arange(-self.m, self.n_model + 1) + self.m + 1
        offs = np.array([mem.s_off[cols] for mem in self._members])[:, None, None, :]
        sp = X[..., 0::2] + s_eq + offs
        if self.kind == "fd_lcc":
            sp[..., self.m] = np.nan
        out["predicted_spacing"] = sp
        out["pred_time"] = np.arange(N + 1) * self.sample_time
        out["state_names"] = np.array(self._lin0.model.state_names)
        return out

    # ---------------------------------------------------------------- reports

    def describe(self) -> dict[str, Any]:
        """Horizon, weights, constraints, prediction, solver and fallback settings."""
        return self._describe({"m": self.m, "n_model": self.n_model}, {},
                              "condensed, CasADi symbolic (built once)",
                              dict(self.fallback.gains))  # fmt: skip

    def as_dict(self) -> dict[str, Any]:
        return {**self.describe(), "fallback": dict(self.fallback.gains)}

    def stats(self) -> dict[str, Any]:
        """Solve-time distribution, fallbacks, QP failures, slack use and measured violations.

        Times are in milliseconds: ``step_time_ms`` is the whole controller step of one batch
        member (state, QP update and solve, fallback), ``osqp_time_ms`` OSQP's own run time.
        ``violation_steps`` / ``max_violation_m`` compare the MEASURED spacing with
        ``s_min + t_gap v_0`` at every sample; ``slack_steps`` / ``max_slack_m`` are the
        predicted violations the QP accepted.
        """
        return step_statistics(self._st)


_HIST_KEYS = ("u", "u_model", "status", "osqp_time", "iterations", "slack", "v_eq", "v_lin",
              "x0", "d", "plan", "lin")


