"""The one MPC of every layout (a controller of :mod:`lcc_synth.controllers.base`).

:class:`MPCController` is the safety-constrained linear MPC of one CAV of the paper's kinds
(CF-LCC, FD-LCC, general LCC, CCC) and of every CAV of a platoon or ring road (``[system] kind
= "platoon" | "ring"``); ``JointMPCController`` (:mod:`lcc_synth.mpc`) is the same class. The
sample loop, the condensed QP (:class:`~lcc_synth.mpc.formulation.Formulation`, one input per
CAV), the warm-started solve, the fallback chain's order, the step record, the history and the
reports are written once here and in :mod:`lcc_synth.mpc.scaffold`. What a layout adds is its
prediction model and error state, chosen once from the system:

- :class:`OneCAVLayout` (below): the paper's error state of vehicles ``-m..n_model`` around the
  one CAV, with FD-LCC's position state, CF-LCC's HDV law under the MPC's input, and spacing
  constraints behind the CAV (``constraints.behind``).
- :class:`~lcc_synth.mpc.joint.StringLayout`: the string's state of positions ``1..N``, one
  input per CAV, the ring's projection onto its invariant hyperplane.

The two layouts keep their own arithmetic (every pinned number is bit for bit the one of the
two controllers this class replaced); a one-CAV platoon and the paper's LCC of the same
``(m, n)`` give the same QP to round-off (``tests/test_mpc_platoon.py``).

At every sample (``sample_time``, default 0.1 s; the simulator holds the command in between),
for one CAV of the paper's kinds (:class:`~lcc_synth.mpc.joint.StringLayout` states its own):

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
   ``constraints.spacing = "equilibrium"`` replaces it by the DeeP-LCC paper's two-sided
   bound on the spacing error, ``lo <= s_0 - s_eq <= hi`` (``constraints.spacing_error``,
   both soft, ``margin`` tighter; :func:`~lcc_synth.mpc.formulation.spacing_families`).
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
    error_bound,
    linearize,
    spacing_families,
    state_weights,
)
from lcc_synth.mpc.joint import StringLayout
from lcc_synth.mpc.report import new_step_record, predicted_states, step_statistics
from lcc_synth.mpc.scaffold import (
    STATUS_CODES,
    Layout,
    LoopState,
    MPCScaffold,
    Sample,
    head_prediction,
    new_history,
    update_equilibrium,
)
from lcc_synth.mpc.settings import MPCSettings, paper_fallback_gains
from lcc_synth.mpc.step_cache import clip

__all__ = ["MPCController", "OneCAVLayout", "layout_of", "STATUS_CODES"]


class OneCAVLayout(Layout):
    """The paper's one CAV (``kind`` cf_lcc, fd_lcc, lcc, ccc): the error state of vehicles
    ``-m..n_model`` (module docstring, steps 1-3 and 6).

    Parameters
    ----------
    system : lcc_synth.problem.System
        Kind, ``m``, ``n``, nominal HDV model and design ``v*``.
    settings : MPCSettings
    """

    #: the history's plan is ``(B, S, N)`` and the command ``(batch,)``
    joint = False
    default_source = "paper"

    def __init__(self, system, settings: MPCSettings):
        super().__init__(system, settings)
        self.m = system.m
        n_model = system.n if settings.n_model is None else settings.n_model
        if n_model > system.n:
            raise ConfigError("n_model", f"must be <= [system].n = {system.n}, got {n_model}")
        if self.kind in ("cf_lcc", "fd_lcc") and n_model < 1:
            raise ConfigError("n_model", f"must be >= 1 for {self.kind}, got {n_model}")
        if self.kind == "lcc" and self.m == 0 and n_model == 0:
            raise ConfigError("n_model", "must be >= 1 for LCC with m = 0")
        self.n_model = n_model
        self.nu = 1
        self.v_hi = free_speed(system.hdv)
        self.v_design = system.v_star
        self.cols = np.arange(-self.m, n_model + 1) + self.m + 1

    # ---------------------------------------------------------------- set-up

    def linearize(self, v: float) -> Linearization:
        return linearize(self.kind, self.m, self.n_model, self.system.hdv, v, self.settings)

    def state_weights(self, model) -> np.ndarray:
        return state_weights(model, self.settings)

    def families(self, model) -> list[Family]:
        c = self.settings.constraints
        fams = []
        if c.spacing_ahead:
            b = model.block(0)
            fams += spacing_families(0, b.start, b.start + 1, c)
        for i in c.behind:
            if i > self.n_model:
                raise ConfigError(
                    "constraints.behind",
                    f"HDV {i} is not in the MPC's model (n_model = {self.n_model})",
                )
            b = model.block(i)
            fams.append(Family(i, b.start, b.start + 1, c.t_gap_behind, c.s_min_behind))
        return fams

    def default_fallback(self, model) -> Gains:
        return paper_fallback_gains(self.kind, self.n_model)

    def check_fallback(self, model, fallback: Gains, source: str) -> None:
        try:
            cav_feedback(model, _on_model(fallback, model))
        except ConfigError as err:
            from_file = source != "paper" and not source.startswith("controller")
            raise ConfigError(
                "fallback_gains_file" if from_file else "fallback",
                f"{err.field}: {err.message} (the MPC models m={self.m}, n={self.n_model})",
            ) from None

    def feedback(self, model, fallback: Gains) -> tuple[np.ndarray, float]:
        K, kh = cav_feedback(model, _on_model(fallback, model))
        return np.asarray(K, float), float(kh)

    def check_context(self, ctx: ControlContext, name: str) -> None:
        if ctx.m != self.m or ctx.n < self.n_model:
            raise ConfigError(
                f"controllers.{name}",
                f"the MPC models m={self.m}, n={self.n_model}; the scenario has "
                f"m={ctx.m}, n={ctx.n}",
            )

    def limits(self, a_min: float, a_max: float) -> tuple[float, float]:
        return a_min, a_max

    def member(self, mpc: MPCController, ctx: ControlContext, b: int, W: int) -> LoopState:
        lin, qp, K, kh = mpc._linearization(float(ctx.v_star[b]))
        solver = mpc._new_solver(qp, 0.0, mpc._a_min, mpc._a_max)
        s_off = np.asarray(ctx.spacing_reference()[b], float) - float(ctx.s_star[b])
        s_off = np.nan_to_num(s_off, nan=0.0)
        mem = LoopState(solver, lin, qp, K, kh, np.zeros(W), s_off=s_off, v_eq=float(ctx.v_star[b]))
        mem.hist = new_history()
        mem.s_off_cols = s_off[self.cols]
        mem.past = np.zeros(max(1, mpc.formulation.W))
        mem.delay = None if lin.delay is None else lin.delay.history()  # delay, lag
        return mem

    def empty_output(self, batch: int) -> np.ndarray:
        return np.zeros(batch)

    def output(self, out: np.ndarray) -> np.ndarray:
        return out

    # ---------------------------------------------------------------- one sample

    def observe(self, mpc: MPCController, b: int, mem: LoopState, obs: Observation) -> Sample:
        """Update ``v_eq``; the error state, head prediction and measurements (steps 1-3)."""
        ctx = mpc._ctx
        pred = self.settings.prediction
        m, cav = self.m, ctx.cav
        ref_col = 0 if m == 0 else 1
        v_ref = float(obs.velocity[b, ref_col])
        if pred.equilibrium_mode(self.kind) == "fixed":
            mem.v_eq = float(ctx.v_star[b])
        else:
            update_equilibrium(mem, v_ref)
        v_eq = mem.v_eq
        s_eq = mem.s_eq.get(self.system.hdv, mpc._clip_v(v_eq))
        cols = self.cols
        x = np.empty(2 * cols.size)
        x[0::2] = obs.spacing[b, cols] - s_eq - mem.s_off_cols  # (spacing - s_eq) - s_off
        x[1::2] = obs.velocity[b, cols] - v_eq
        # FD-LCC: -p_0 relative to a reference moving at v_eq
        p0 = float(obs.position[b, cav])
        if math.isnan(mem.p_ref):
            mem.p_ref = p0
        xi = -(p0 - mem.p_ref)
        mem.p_ref += v_eq * mpc.sample_time
        if self.kind == "fd_lcc":
            x[0] = xi if self.settings.weights.position > 0 else 0.0
        N = self.settings.horizon
        d0, d = head_prediction(mem, v_ref, N, mpc.sample_time, pred, mpc._a_min, mpc._a_max)
        d_model = np.zeros(N) if self.kind == "fd_lcc" else d  # FD-LCC: no head input
        s0 = float(obs.spacing[b, cav])
        if mem.delay is not None:
            x = mem.delay.push(x, d0, s_eq, v_eq, obs=obs, b=b, u_prev=float(mem.past[0]))
        v0 = float(obs.velocity[b, cav])
        return Sample(x, d, d_model, {"xi": xi, "s_eq": s_eq, "s0": s0, "v0": v0,
                                      "s_off0": float(mem.s_off[m + 1])})

    def count_violations(self, mpc: MPCController, o: Sample) -> None:
        """The measured violation of the bound on the spacing to the vehicle ahead (absolute,
        or of the spacing error from ``s_eq`` with ``constraints.spacing = "equilibrium"``)."""
        st = mpc._st
        c = self.settings.constraints
        s0, v0 = o.extra["s0"], o.extra["v0"]
        if c.spacing_ahead and math.isfinite(s0) and math.isfinite(v0):
            if c.spacing == "safe":
                viol = c.s_min + c.t_gap * v0 - s0
            else:
                lo, hi = c.spacing_error
                err = s0 - o.extra["s_eq"] - o.extra["s_off0"]
                viol = max(lo - err, err - hi)
            if viol > 1e-6:
                st["violation_steps"] += 1
                st["max_violation"] = max(st["max_violation"], viol)

    def spacing_bounds(self, mpc: MPCController, mem: LoopState, o: Sample) -> np.ndarray:
        N = self.settings.horizon
        v_eq = mem.v_eq
        s_eq, s0, x0, d = o.extra["s_eq"], o.extra["s0"], o.x0, o.d
        out = np.empty((len(mpc._families), N))
        margin = self.settings.constraints.margin
        for f, fam in enumerate(mpc._families):
            if fam.bound != "safe":  # spacing error from s_eq (+ offset): x[s] for all but FD-LCC
                gap = 0.0
                if self.kind == "fd_lcc":
                    if not math.isfinite(s0):
                        out[f] = -np.inf
                        continue
                    drift = np.cumsum(d) * mpc.sample_time
                    gap = s_eq + o.extra["s_off0"] - (s0 - x0[0] + drift)
                out[f] = error_bound(fam, margin, gap)
                continue
            base = fam.s_min + self.settings.constraints.margin + fam.t_gap * v_eq
            if fam.vehicle == 0 and self.kind == "fd_lcc":
                if not math.isfinite(s0):
                    out[f] = -np.inf
                    continue
                # s_0(k) = s0 + sum_{j<k} (v_ahead_j - v_eq) Ts + (xi_k - xi_0)
                drift = np.cumsum(d) * mpc.sample_time
                out[f] = base - (s0 - x0[0] + drift)
            else:
                out[f] = base - s_eq - mem.s_off[fam.vehicle + self.m + 1]
        return out

    def jerk_bounds(self, o: Sample) -> Any:
        return jerk_bound(self.settings.constraints.jerk_scale, o.extra["v0"])

    def plan(self, U: np.ndarray) -> np.ndarray:
        return U

    def _total(self, mpc: MPCController, lin: Linearization, x0, d0: float,
               u_model: float) -> float:  # fmt: skip
        u = u_model
        if self.kind == "cf_lcc":
            u += float(lin.K_law @ x0) + lin.k_h * d0
        return clip(u, mpc._a_min, mpc._a_max)

    def command(self, mpc: MPCController, mem: LoopState, o: Sample, U: np.ndarray):
        """``(cmd, u_model)`` of the plan's first input; sets ``u_prev``."""
        u_model = float(U[0])
        cmd = self._total(mpc, mem.lin, o.x0, o.d_model[0], u_model)
        mem.u_prev = cmd if self.settings.weights.input_on == "total" else u_model
        mem.cmd_prev = cmd
        return cmd, u_model, 0

    def fallback(self, mpc: MPCController, mem: LoopState, o: Sample, why: str) -> float:
        """The shifted plan, the static gain on the same error state, else hold (step 6)."""
        st = mpc._st
        N = self.settings.horizon
        lin, x0, d_model = mem.lin, o.x0, o.d_model
        if (
            mem.plan is not None
            and mem.plan_age + 1 < N
            and np.all(np.isfinite(x0))
            and np.all(np.isfinite(d_model))
        ):
            mem.plan_age += 1
            u_model = float(mem.plan[mem.plan_age])
            cmd = self._total(mpc, lin, x0, d_model[0], u_model)
            st["fallback_shifted"] += 1
            code = 1
        else:
            xs = np.array(x0[: mem.fb_K.size], dtype=float)  # without delay states
            if self.kind == "fd_lcc":
                xs[0] = o.extra["xi"]
            cmd = float(mem.fb_K @ xs + mem.fb_kh * (d_model[0] if d_model.size else 0.0))
            if math.isfinite(cmd):
                cmd = float(np.clip(cmd, mpc._a_min, mpc._a_max))
                u_model = cmd
                if self.kind == "cf_lcc" and np.all(np.isfinite(x0)):
                    u_model = cmd - float(lin.K_law @ x0) - lin.k_h * d_model[0]
                mem.plan = None
                st["fallback_static"] += 1
                code = 2
            else:
                cmd = self.hold(mpc, mem, why)
                mpc._record_fail(mem, cmd)
                return cmd
        mem.u_prev = cmd if self.settings.weights.input_on == "total" else u_model
        mem.cmd_prev = cmd
        if mpc.record:
            mpc._record(mem, cmd, u_model, code, None, 0.0, x0, d_model, None)
        return cmd

    def hold(self, mpc: MPCController, mem: LoopState, why: str) -> float:
        mpc._st["fallback_hold"] += 1
        cmd = mem.cmd_prev if math.isfinite(mem.cmd_prev) else 0.0
        return float(np.clip(cmd, mpc._a_min, mpc._a_max))

    # ---------------------------------------------------------------- history and reports

    def failed(self, value: int) -> int:
        return value

    def history(self, mpc: MPCController, out: dict[str, Any], S: int) -> None:
        """The one-CAV keys: ``u_model``, ``v_lin``, ``step_time`` and the absolute predicted
        velocities and spacings of the modelled vehicles (:meth:`MPCController.history`)."""
        members = mpc._members
        N = self.settings.horizon
        B = len(members)
        for key in ("u_model", "v_lin"):
            out[key] = np.array([m.hist[key][:S] for m in members])
        out["step_time"] = np.array(mpc._st["step_time"][: S * B]).reshape(S, B).T
        X = out["predicted_states"]
        v_eq = out["v_eq"][:, :, None, None]
        v_cl = np.clip(out["v_eq"], 1.0, self.v_hi - 1.0)
        s_eq = np.asarray(self.system.hdv.equilibrium_spacing(v_cl))[:, :, None, None]
        out["predicted_velocity"] = X[..., 1::2] + v_eq
        offs = np.array([mem.s_off[self.cols] for mem in members])[:, None, None, :]
        sp = X[..., 0::2] + s_eq + offs
        if self.kind == "fd_lcc":
            sp[..., self.m] = np.nan
        out["predicted_spacing"] = sp
        out["pred_time"] = np.arange(N + 1) * mpc.sample_time
        order = ("t", "u", "u_model", "status", "osqp_time", "iterations", "slack", "v_eq", "v_lin",
                 "step_time", "x0", "d", "plan", "predicted_states", "predicted_velocity",
                 "predicted_spacing", "pred_time")  # the order of the keys before
        kept = dict(out)
        out.clear()
        out.update({k: kept[k] for k in order})

    def describe(self, mpc: MPCController) -> tuple[dict, dict, str, Any]:
        return ({"m": self.m, "n_model": self.n_model}, {},
                "condensed, CasADi symbolic (built once)", _applied(mpc.fallback))  # fmt: skip

    def as_dict(self, mpc: MPCController) -> dict[str, Any]:
        return {**mpc.describe(), "fallback": _applied(mpc.fallback)}

    def stats(self, mpc: MPCController, out: dict[str, Any]) -> dict[str, Any]:
        return out


#: Attributes of the layout the controller shows as its own: one CAV's ``m`` and ``n_model``; a
#: string's ``platoon``, ``ring``, ``positions`` (of the CAVs, 1-based), ``columns`` (array
#: column of each position) and ``cav_columns``.
LAYOUT_ATTRIBUTES = frozenset({"m", "n_model", "platoon", "ring", "positions", "columns",
                               "cav_columns"})


def _on_model(fallback: Gains, model) -> Gains:
    """``fallback`` on the MPC's model: without the states the model lacks whose gains are
    zero. A gain designed on the whole string (the ``h2`` gain an MPC falls back to, on all 10
    HDVs) runs on an MPC that predicts fewer (``n_model``) when it hears none of the others;
    a non-zero gain on a state the model lacks stays, for :meth:`Gains.check` to name."""
    keep = [j for j, nm in enumerate(fallback.states)
            if nm in model.state_names or np.any(fallback.K[:, j] != 0.0)]  # fmt: skip
    if len(keep) == len(fallback.states):
        return fallback
    return Gains(fallback.K[:, keep], fallback.cavs, tuple(fallback.states[j] for j in keep),
                 fallback.semantics, fallback.kh)  # fmt: skip


def _applied(fallback: Gains) -> dict[str, float]:
    """The fallback's non-zero gains by state name (what :meth:`describe` shows, as the
    platoon form of a string's MPC does)."""
    return {nm: g for nm, g in fallback.gains.items() if g != 0.0}


def layout_of(system, settings: MPCSettings):
    """The layout of ``system``: :class:`~lcc_synth.mpc.joint.StringLayout` when it has a
    string of positions (``kind = "platoon" | "ring"``), else :class:`OneCAVLayout`."""
    if getattr(system, "platoon", None) is not None:
        return StringLayout(system, settings)
    return OneCAVLayout(system, settings)


class MPCController(MPCScaffold):
    """Safety-constrained linear MPC of the CAVs of any layout (see the module docstring).

    Parameters
    ----------
    name : str
        Controller name.
    settings : MPCSettings
    system : lcc_synth.problem.System
        The paper's kinds (``m``, ``n``, nominal HDV model, design ``v*``) or a platoon or
        ring (``kind = "platoon" | "ring"``, at least one CAV).
    fallback : Gains, optional
        Static fallback gain, one row per CAV (default: the paper's Section V-B gain for one
        CAV, :func:`paper_fallback_gains`; each CAV's HDV law for a string).
    fallback_source : str, optional
        Where the fallback came from (for :meth:`describe`; default ``"paper"`` for one CAV,
        ``"hdv_law"`` for a string).
    record : bool
        Keep the per-step history (:meth:`history`).

    Attributes
    ----------
    layout : OneCAVLayout or lcc_synth.mpc.joint.StringLayout
        The prediction model's layout and its state.
    """

    def __init__(
        self,
        name: str,
        settings: MPCSettings,
        system,
        fallback: Gains | None = None,
        fallback_source: str | None = None,
        record: bool = True,
    ):
        self.name = name
        self.settings = settings
        self.sample_time = settings.sample_time
        self.system = system
        self.layout = lay = layout_of(system, settings)
        self.kind = system.kind
        self.nu = lay.nu
        self.record = record
        self._v_hi = lay.v_hi
        try:
            self._lin0 = lay.linearize(self._clip_v(lay.v_design))
        except ConfigError as err:
            where = err.field if err.field.startswith("prediction.") else f"weights ({err.field})"
            raise ConfigError(where, err.message) from None
        model = self._lin0.model
        self._families = lay.families(model)
        nz = self._lin0.Ad.shape[0]  # model.nx, or more with delay or lag states
        check_horizon(settings.horizon, nz, len(self._families))
        self.formulation = Formulation(
            self.kind, nz, settings, pad(lay.state_weights(model), nz), self._families,
            nu=self.nu,
        )
        self._shift_z, self._shift_y = self.formulation.shift_indices()
        self.fallback = lay.default_fallback(model) if fallback is None else fallback
        self.fallback_source = lay.default_source if fallback_source is None else fallback_source
        lay.check_fallback(model, self.fallback, self.fallback_source)
        self._cache: dict[float, tuple] = {}
        self._members: list[LoopState] = []
        self._ctx: ControlContext | None = None
        self._new_record()

    def __getattr__(self, key: str):
        """The layout's attributes read through the controller (:data:`LAYOUT_ATTRIBUTES`)."""
        if key in LAYOUT_ATTRIBUTES and "layout" in self.__dict__:
            try:
                return getattr(self.__dict__["layout"], key)
            except AttributeError:
                pass
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {key!r}")

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
        return self.layout.linearize(v)

    def _feedback(self, model):
        return self.layout.feedback(model, self.fallback)

    # ---------------------------------------------------------------- protocol

    def reset(self, ctx: ControlContext) -> None:
        """Check the scenario's layout; set up one OSQP workspace per batch member (the only
        solver set-up of the run)."""
        lay = self.layout
        lay.check_context(ctx, self.name)
        self._ctx = ctx
        c = self.settings.constraints
        self._a_min, self._a_max = lay.limits(max(c.a_min, ctx.a_min), min(c.a_max, ctx.a_max))
        self._new_record()
        W = self._window(self.settings.prediction.equilibrium_window)
        self._members = [lay.member(self, ctx, b, W) for b in range(ctx.batch)]

    def __call__(self, obs: Observation) -> np.ndarray:
        """The commands of one sample (the steps of the module docstring): ``(batch,)`` with
        one CAV, ``(batch, n_cav)`` with several."""
        out = self.layout.empty_output(0 if self._ctx is None else self._ctx.batch)
        self._run_members(obs, out)
        return self.layout.output(out)

    def _on_error(self, mem: LoopState):
        cmd = self.layout.hold(self, mem, "error")
        self._record_fail(mem, cmd)
        return cmd

    # ---------------------------------------------------------------- one member, one step

    def _step(self, b: int, mem: LoopState, obs: Observation):
        lay = self.layout
        o = lay.observe(self, b, mem, obs)
        lay.count_violations(self, o)
        self._relinearize(mem)
        form = self.formulation
        if not (np.isfinite(o.x0).all() and np.isfinite(o.d_model).all()):
            return lay.fallback(self, mem, o, "nonfinite_state")
        p = form.param(o.x0, o.d_model, mem.u_prev, mem.past)
        fb = lay.spacing_bounds(self, mem, o)
        q, lo, hi = form.bounds(mem.qp, p, self._a_min, self._a_max, fb, lay.jerk_bounds(o))
        res = self._solve(mem, q, lo, hi)
        if not res.ok:
            return lay.fallback(self, mem, o, res.status)
        z = res.z
        n_in = form.n_input
        U = lay.plan(z[:n_in])
        slack = float(z[n_in:].max()) if z.size > n_in else 0.0
        self._note_slack(slack)
        mem.plan = U.copy()
        mem.plan_age = 0
        cmd, u_model, code = lay.command(self, mem, o, U)
        if self.record:
            self._record(mem, cmd, u_model, code, res, slack, o.x0, o.d_model, U)
        return cmd

    # ---------------------------------------------------------------- history

    def _record(self, mem: LoopState, cmd, u_model, code, res, slack, x0, d, U) -> None:
        h = mem.hist
        h["u"].append(np.asarray(cmd, float).copy() if self.layout.joint else cmd)
        h["u_model"].append(u_model)
        h["status"].append(np.asarray(code, int).copy() if self.layout.joint else code)
        h["osqp_time"].append(math.nan if res is None else res.run_time)
        h["iterations"].append(-1 if res is None else res.iterations)
        h["slack"].append(slack)
        h["v_eq"].append(mem.v_eq)
        h["v_lin"].append(mem.lin.v_lin)
        h["x0"].append(np.asarray(x0, float).copy())
        h["d"].append(np.asarray(d, float).copy())
        h["plan"].append(self._nan_plan() if U is None else np.asarray(U, float).copy())
        h["lin"].append(mem.lin)

    def _nan_plan(self) -> np.ndarray:
        N = self.settings.horizon
        return np.full((N, self.nu), np.nan) if self.layout.joint else np.full(N, np.nan)

    def _record_fail(self, mem: LoopState, cmd) -> None:
        """Record a held command (status 3) of a member whose state or step failed."""
        if not self.record:
            return
        nx = mem.lin.Ad.shape[0]
        N = self.settings.horizon
        self._record(mem, cmd, math.nan, self.layout.failed(3), None, 0.0, np.full(nx, np.nan),
                     np.full(N, np.nan), None)  # fmt: skip

    def history(self) -> dict[str, np.ndarray]:
        """Per-sample record of the last run, arrays with leading axes ``(batch, samples)``.

        Keys of every layout: ``t (S,)``; ``u`` applied command (``(B, S)`` with one CAV of the
        paper's kinds, ``(B, S, n_cav)`` for a string); ``status`` (:data:`STATUS_CODES`, per
        CAV for a string); ``osqp_time`` (s, OSQP run time, NaN when not solved);
        ``iterations``; ``slack`` (largest spacing slack, m); ``v_eq``; ``x0 (B, S, nx)`` error
        state (ring: projected; without delay or lag states); ``d (B, S, N)`` head prediction;
        ``plan`` optimal model inputs (``(B, S, N)``, a string's ``(B, S, N, n_cav)``);
        ``predicted_states (B, S, N+1, nx)``; ``state_names``.

        One CAV of the paper's kinds adds ``u_model`` model input (CF-LCC: ``u_hat``),
        ``v_lin``, ``step_time`` (s, whole controller step), ``predicted_velocity`` and
        ``predicted_spacing`` ``(B, S, N+1, V)`` absolute values for the modelled vehicles
        ``-m..n_model`` (``state_names`` tells the order; FD-LCC's CAV spacing column is NaN)
        and ``pred_time (N+1,)`` offsets (s).
        """
        if not self._members or not self.record:
            return {}
        N = self.settings.horizon
        members = self._members
        S = min(len(m.hist["u"]) for m in members)
        out: dict[str, Any] = {"t": np.array(self._t[:S])}
        for key in ("u", "status", "osqp_time", "iterations", "slack", "v_eq", "x0", "d",
                    "plan"):
            out[key] = np.array([np.array(m.hist[key][:S]) for m in members])
        nx = self._lin0.model.nx  # the delay and lag states are left out
        out["x0"] = out["x0"][..., :nx]
        out["predicted_states"] = predicted_states([m.hist for m in members], S, N, nx)
        self.layout.history(self, out, S)
        out["state_names"] = np.array(self._lin0.model.state_names)
        return out

    # ---------------------------------------------------------------- reports

    def describe(self) -> dict[str, Any]:
        """Horizon, weights, constraints, prediction, solver, the layout and the fallback."""
        return self._describe(*self.layout.describe(self))

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable summary (:meth:`describe`)."""
        return self.layout.as_dict(self)

    def stats(self) -> dict[str, Any]:
        """Solve-time distribution, fallbacks, QP failures, slack use and measured violations.

        Times are in milliseconds: ``step_time_ms`` is the whole controller step of one batch
        member (state, QP update and solve, fallback), ``osqp_time_ms`` OSQP's own run time.
        ``violation_steps`` / ``max_violation_m`` compare the MEASURED spacing with
        ``s_min + t_gap v_i`` (``constraints.spacing = "equilibrium"``: the spacing error from
        the reference spacing with ``spacing_error``) at every sample; ``slack_steps`` /
        ``max_slack_m`` are the predicted violations the QP accepted. A string's fallback
        counters count CAV-samples, and ``per_cav`` gives for each ``u_i`` its fallback
        counts, their reasons (OSQP status, ``nonfinite_state``, ``error``) and its measured
        violations.
        """
        return self.layout.stats(self, step_statistics(self._st))


#: The same class as :class:`MPCController` (the joint MPC of a platoon or ring is the one MPC;
#: :mod:`lcc_synth.mpc` exports it under this name too).
JointMPCController = MPCController
