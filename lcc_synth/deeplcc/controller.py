"""DeeP-LCC: data-enabled predictive leading cruise control (Wang, Zheng, Li, Chen et al.,
IEEE T-CST 2023), a controller of :mod:`lcc_synth.controllers.base` for one or several CAVs.

At every sample (the data's ``dt``; the simulator holds the command in between):

1. **Equilibrium.** ``v_eq`` is the moving average (``equilibrium_window``) of the head
   vehicle's velocity (``equilibrium = "fixed"``, the default for FD-LCC: the system's
   ``v*``), ``s_eq`` the nominal HDV model's equilibrium spacing at ``v_eq`` plus each CAV's
   offset ``s_ref - s*`` from the context.
2. **Past window.** The last ``Tini`` pairs ``(u_{k-1}, e_{k-1}, y_k)``
   (:mod:`lcc_synth.deeplcc.hankel`) from ABSOLUTE measurements kept in a ring, re-expressed
   as errors from the current ``v_eq`` / ``s_eq``; ``u_{k-1}`` is the CAV's own velocity change
   over the sample divided by ``dt`` (the acceleration the simulator APPLIED, limits and
   emergency braking included). Before ``Tini`` samples exist the string is taken to have
   cruised at its first measured state (as the simulator's history before ``t_start``).
3. **Future head error** 0 after the current sample; the current one, ``e_t``, is measured.
4. **QP** (:mod:`lcc_synth.deeplcc.qp`) on the exact reduction of the QP in ``g``, solved by
   OSQP (one workspace per batch member set up at :meth:`reset`, vectors updated per step,
   warm start from the shifted previous solution, status checked:
   :class:`lcc_synth.mpc.solver.OSQPSolver`), or with ``solver.method = "daqp"`` by DAQP from
   the previous active set (:class:`lcc_synth.mpc.active_set.DAQPSolver`, the MPC's option).
   The spacing bound of every CAV is the absolute safe spacing, or with
   ``constraints.spacing = "equilibrium"`` the paper's ``lo <= s - s_eq <= hi`` on its
   spacing error (the rows of ``y`` with no time gap, plus upper rows:
   :func:`lcc_synth.deeplcc.qp.formulate`).
5. **Exact re-solve.** When OSQP stops unsolved (``max_iter`` = 200 by default), the same QP
   is solved by DAQP, an exact active-set solver (:class:`lcc_synth.deeplcc.qp.ExactSolver`);
   ``solver.exact = false`` skips it. Measured on the two-CAV platoon brake
   (``benchmarks/bench_deeplcc.py`` section 4, controller CPU per step): with OSQP alone
   (``max_iter`` 10000) median 2.9 ms, p99 181 ms, max 350 ms, one fallback, because 2 % of
   the steps need 2000-10000 ADMM iterations (the data nearly fix the CAV spacings);
   rescaling the inputs to an identity Hessian made every step slower (median 275 instead of
   50 iterations); DAQP solved every step of that run (17-34 ms CPU, cold). With the cap at
   200 (17 % of the steps re-solved) median 1.5 ms, p99 34 ms, max 40 ms, no fallback.
6. **Fallback chain** as the MPC's (:mod:`lcc_synth.mpc.controller`): when the QP is not
   solved (any status but ``solved``, non-finite data, an exception) the previous plan shifted
   by one step while it lasts, then a static gain: the paper's Section V-B gain
   (:func:`lcc_synth.mpc.settings.paper_fallback_gains`) applied around each CAV (``s_0, v_0``
   its own errors, ``s_i, v_i`` those ``i`` vehicles behind it), clipped to the limits; the
   simulator's emergency braking is the last layer. Nothing raises inside the loop.

The CAVs are ``ctx.cavs`` when the context has them (several CAVs: the command is
``(batch, n_c)``), else the single CAV ``ctx.m + 1`` (command ``(batch,)``). The CAV's whole
acceleration is the input (as in the data).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lcc_synth.controllers.base import ControlContext, Observation
from lcc_synth.deeplcc.data import ExcitationReport, check_excitation
from lcc_synth.deeplcc.hankel import DataSet, ReducedQP, reduce, spacing_rows, windows
from lcc_synth.deeplcc.qp import DeepQP, ExactSolver, formulate
from lcc_synth.deeplcc.settings import DeePLCCSettings
from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import CarFollowingModel, free_speed
from lcc_synth.mpc.active_set import DAQPSolver, make_solver, solver_label
from lcc_synth.mpc.formulation import error_bound, spacing_families
from lcc_synth.mpc.report import new_step_record, step_statistics
from lcc_synth.mpc.scaffold import STATUS_CODES, SampleLoop, update_equilibrium
from lcc_synth.mpc.settings import paper_fallback_gains
from lcc_synth.mpc.solver import OSQPSolver
from lcc_synth.mpc.step_cache import LastValue
from lcc_synth.resources import single_thread_blas

__all__ = ["DeePLCCController", "NO_RING", "STATUS_CODES"]

#: Why DeeP-LCC refuses a ring (its data and its prediction are driven by the head vehicle).
NO_RING = ("DeeP-LCC needs an open string with a head vehicle (its external input); a ring "
           "has none: use kind = \"platoon\" for an open string of the same vehicles")  # fmt: skip

@dataclass
class _Member:
    """Solver and loop state of one batch member (the fields :class:`~lcc_synth.mpc.scaffold.
    SampleLoop` and :func:`~lcc_synth.mpc.scaffold.update_equilibrium` use, plus the rings)."""

    solver: OSQPSolver | DAQPSolver
    s_off: np.ndarray
    v_buf: np.ndarray
    vel: np.ndarray  # (Tini + 1, nv) absolute velocities, oldest first
    spc: np.ndarray  # (Tini + 1, n_c) absolute CAV spacings
    u: np.ndarray  # (Tini, n_c) applied accelerations u_{t-Tini} .. u_{t-1}
    past: np.ndarray  # (1, n_c) the last applied command
    started: bool = False
    v_buf_n: int = 0
    v_buf_i: int = 0
    v_eq: float = 0.0
    plan: np.ndarray | None = None
    plan_age: int = 0
    warm: tuple | None = None
    s_eq: LastValue = field(default_factory=LastValue)  # the HDVs' spacing at the last v_eq
    hist: dict[str, list] = field(default_factory=dict)


@single_thread_blas
def _set_up(data: DataSet, settings: DeePLCCSettings, nv: int, n_c: int,
            W: np.ndarray) -> tuple[ExcitationReport, ReducedQP]:  # fmt: skip
    """The persistency-of-excitation check and the exact reduction of the data, with one
    BLAS thread (as a Dask worker of a sweep has): the result does not depend on the
    machine's cores (two threads moved ``Gamma`` by 4e-12 and the closed loop by less than
    the showcase's pins, rel. 1e-6), and on a loaded 2-core machine OpenBLAS's second thread
    made the set-up of one ``problems/sweep_robustness.toml`` scenario cost 3.1 s of CPU
    (10.5 s wall) instead of 0.35 s (1.1 s wall)."""
    Tini, N = settings.t_ini, settings.horizon
    excitation = check_excitation(data, Tini + N + 2 * (nv - 1), settings.data.field)
    w = settings.weights
    q = np.concatenate([np.full(nv - 1, w.velocity), np.full(n_c, w.spacing)])
    r = np.full(n_c, w.input)
    reduced = reduce(windows(data, Tini, N), q, r, w.lambda_g, w.lambda_y, W,
                     exact_past=w.past_outputs == "exact")  # fmt: skip
    return excitation, reduced


class DeePLCCController(SampleLoop):
    """DeeP-LCC on one data set (module docstring), on the MPC's sample loop
    (:class:`~lcc_synth.mpc.scaffold.SampleLoop`).

    Parameters
    ----------
    name : str
    settings : DeePLCCSettings
    data : DataSet
        The offline data (:func:`lcc_synth.deeplcc.data.load_or_collect`).
    kind : str
        The system's kind (fixes the equilibrium default and the fallback gain).
    hdv : CarFollowingModel
        Nominal HDV model (equilibrium spacing at ``v_eq``).
    v_star : float
        Design equilibrium velocity.
    n_vehicles : int
        Vehicles of the string, head included.
    cavs : tuple of int
        Array columns of the CAVs (the data's input order).
    data_key : str
        Cache key of the data (for :meth:`describe`).
    record : bool
        Keep the per-step history.
    """

    def __init__(
        self,
        name: str,
        settings: DeePLCCSettings,
        data: DataSet,
        kind: str,
        hdv: CarFollowingModel,
        v_star: float,
        n_vehicles: int,
        cavs: tuple[int, ...],
        data_key: str = "",
        record: bool = True,
    ):
        self.name = name
        self.settings = settings
        self.sample_time = settings.sample_time
        self.kind = kind
        self.hdv = hdv
        self.v_star = float(v_star)
        self.nv = int(n_vehicles)
        self.cavs = tuple(int(c) for c in cavs)
        self._cav_cols = list(self.cavs)  # the same, as an index list (per step)
        self.n_c = len(self.cavs)
        self.p = self.nv - 1 + self.n_c
        self.data_key = data_key
        self.record = record
        f = settings.data.field
        if data.n_c != self.n_c or data.p != self.p:
            raise ConfigError(f, f"the data have {data.n_c} inputs and {data.p} outputs; the "
                              f"string needs {self.n_c} and {self.p}")  # fmt: skip
        if abs(data.dt - self.sample_time) > 1e-9 * self.sample_time:
            raise ConfigError(f"{f}.dt", f"the data were sampled at {data.dt} s, not "
                              f"{self.sample_time} s")  # fmt: skip
        Tini, N = settings.t_ini, settings.horizon
        t0 = time.perf_counter()
        c = settings.constraints
        # the paper's target bounds the spacing error alone (t_gap 0), on both sides
        self._fams = spacing_families(0, 0, 0, c)
        W = spacing_rows(N, self.p, [col - 1 for col in self.cavs],
                         c.t_gap if c.spacing == "safe" else 0.0)
        self.excitation: ExcitationReport
        self.reduced: ReducedQP
        self.excitation, self.reduced = _set_up(data, settings, self.nv, self.n_c, W)
        w = settings.weights
        self.qp: DeepQP = formulate(self.reduced, w.slack, w.slack_quadratic,
                                    upper=c.spacing != "safe")
        self.data = data
        self.spacing_rows = W
        self.setup_time = time.perf_counter() - t0
        self.data_columns = data.T - Tini - N + 1
        self._shift_z, self._shift_y = self.qp.shift_indices(self.n_c)
        fb_kind = "fd_lcc" if kind == "fd_lcc" else "cf_lcc"
        # the paper's gain reaches two vehicles behind; columns past the tail are skipped
        self.fallback = paper_fallback_gains(fb_kind, 2)
        self._fb = [(name[0], int(name.split("_")[1]), float(g))
                    for name, g in self.fallback.gains.items()]  # fmt: skip
        self._v_hi = free_speed(hdv)
        self._members: list[_Member] = []
        self._ctx: ControlContext | None = None
        self._exact: ExactSolver | None = None
        self._st = new_step_record()
        self._st["exact_solves"] = 0
        self._t: list[float] = []
        self.force_failure = False  # test hook: every solve reports a failure

    # ---------------------------------------------------------------- protocol

    def reset(self, ctx: ControlContext) -> None:
        """Check the string, set up one OSQP workspace per batch member."""
        if getattr(ctx, "ring", False):
            raise ConfigError(f"controllers.{self.name}", NO_RING)
        cavs = tuple(int(c) for c in getattr(ctx, "cavs", (ctx.m + 1,)))
        if cavs != self.cavs or ctx.n_vehicles != self.nv:
            raise ConfigError(f"controllers.{self.name}", f"the data are of a string of {self.nv} "
                              f"vehicles with CAVs at columns {list(self.cavs)}; the scenario "
                              f"has {ctx.n_vehicles} with {list(cavs)}")  # fmt: skip
        self._ctx = ctx
        c = self.settings.constraints
        self._a_min = max(c.a_min, ctx.a_min)
        self._a_max = min(c.a_max, ctx.a_max)
        self._st = new_step_record()
        self._st["exact_solves"] = 0
        self._t = []
        Tini = self.settings.t_ini
        Wn = self._window(self.settings.equilibrium_window)
        self._members = []
        n_w = self.qp.n_w
        for b in range(ctx.batch):
            q, lo, hi = self.qp.vectors(np.zeros(2 * n_w), self._a_min, self._a_max,
                                        np.full(n_w, -np.inf))  # fmt: skip
            solver = make_solver(self.qp.qp, q, lo, hi, self.settings.solver)
            s_off = np.asarray(ctx.spacing_reference()[b], float) - float(ctx.s_star[b])
            s_off = np.nan_to_num(s_off, nan=0.0)[self._cav_cols]
            mem = _Member(solver, s_off, np.zeros(Wn), np.zeros((Tini + 1, self.nv)),
                          np.zeros((Tini + 1, self.n_c)), np.zeros((Tini, self.n_c)),
                          np.zeros((1, self.n_c)), v_eq=float(ctx.v_star[b]))  # fmt: skip
            mem.hist = {k: [] for k in ("u", "status", "v_eq", "slack", "plan")}
            self._members.append(mem)

    def __call__(self, obs: Observation) -> np.ndarray:
        """The commands of one sample: ``(batch,)`` with one CAV, ``(batch, n_c)`` with
        several."""
        out = np.zeros((0 if self._ctx is None else self._ctx.batch, self.n_c))
        self._run_members(obs, out)
        return out[:, 0] if self.n_c == 1 else out

    def _on_error(self, mem: _Member) -> np.ndarray:
        cmd = self._hold(mem)
        self._record(mem, cmd, 3, None, 0.0)
        return cmd

    # ---------------------------------------------------------------- one member, one step

    def _observe(self, b: int, mem: _Member, obs: Observation) -> None:
        """Push the sample into the rings and update ``v_eq``."""
        vel = np.asarray(obs.velocity[b], float)
        cols = self._cav_cols
        spc = np.asarray(obs.spacing[b], float)[cols]
        if not mem.started:
            mem.vel[:] = vel
            mem.spc[:] = spc
            mem.u[:] = 0.0
            mem.started = True
        else:
            u_prev = (vel[cols] - mem.vel[-1, cols]) / self.sample_time
            mem.u[:-1] = mem.u[1:]
            mem.u[-1] = u_prev
            mem.vel[:-1] = mem.vel[1:]
            mem.vel[-1] = vel
            mem.spc[:-1] = mem.spc[1:]
            mem.spc[-1] = spc
        if self.settings.equilibrium_mode(self.kind) == "fixed":
            mem.v_eq = float(self._ctx.v_star[b])
        else:
            update_equilibrium(mem, float(vel[0]))

    def parameters(self, mem: _Member) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(b, y_ini, s_eq)`` of the QP from a member's rings (module docstring)."""
        v_eq = mem.v_eq
        s_eq = mem.s_eq.get(self.hdv, self._clip_v(v_eq)) + mem.s_off
        e = mem.vel[:, 0] - v_eq  # samples t-Tini .. t
        N = self.settings.horizon
        e_f = np.zeros(N)
        e_f[0] = e[-1]
        b = np.concatenate([mem.u.ravel(), e[:-1], e_f])
        y = np.empty((mem.spc.shape[0] - 1, self.p))
        np.subtract(mem.vel[1:, 1:], v_eq, out=y[:, :self.nv - 1])
        np.subtract(mem.spc[1:], s_eq, out=y[:, self.nv - 1:])
        return b, y.ravel(), s_eq

    def _step(self, b: int, mem: _Member, obs: Observation) -> np.ndarray:
        st = self._st
        self._observe(b, mem, obs)
        c = self.settings.constraints
        v_c = np.asarray(obs.velocity[b], float)[self._cav_cols]
        s_c = mem.spc[-1]
        bvec, y_ini, s_eq = self.parameters(mem)
        if c.spacing == "safe":  # the largest shortfall over the CAVs, NaN skipped
            short = (c.s_min + c.t_gap * v_c - s_c).tolist()
            viol = max((x for x in short if x == x), default=-math.inf)
        else:  # the spacing error from s_eq (module docstring, step 4)
            err = s_c - s_eq
            lo, hi = c.spacing_error
            with np.errstate(invalid="ignore"):
                viol = np.nanmax(np.maximum(lo - err, err - hi), initial=-np.inf)
        if viol > 1e-6:
            st["violation_steps"] += 1
            st["max_violation"] = max(st["max_violation"], float(viol))
        if not (np.isfinite(bvec).all() and np.isfinite(y_ini).all()):
            return self._fallback(mem, obs, b, s_eq, "nonfinite_state")
        red, qp = self.reduced, self.qp
        cvec = red.Cb @ bvec + red.Cy @ y_ini
        N = self.settings.horizon
        if c.spacing == "safe":
            b_w = np.tile(c.s_min + c.margin + c.t_gap * mem.v_eq - s_eq, N)  # (N n_c,)
            q, lo, hi = qp.vectors(cvec, self._a_min, self._a_max, b_w)
        else:  # y's spacing errors are from s_eq: constant bounds (mpc.formulation.error_bound)
            b_w = np.full(qp.n_w, error_bound(self._fams[0], c.margin))
            b_up = np.full(qp.n_up, error_bound(self._fams[1], c.margin))
            q, lo, hi = qp.vectors(cvec, self._a_min, self._a_max, b_w, b_up)
        mem.solver.force_failure = self.force_failure
        res = mem.solver.solve(q, lo, hi, *self._warm_start(mem))
        self._count_solve(res)
        z, y = res.z, res.y
        if not res.ok:
            exact = self._exact_solve(q, lo, hi)
            if exact is None:
                return self._fallback(mem, obs, b, s_eq, res.status)
            z, y = exact
            st["exact_solves"] += 1
        mem.warm = (z, y)
        plan = qp.plan(z).reshape(N, self.n_c)
        slack = float(qp.slack(z).max())
        self._note_slack(slack)
        mem.plan = plan
        mem.plan_age = 0
        cmd = np.minimum(np.maximum(plan[0], self._a_min), self._a_max)  # np.clip's values
        self._record(mem, cmd, 0, plan, slack)
        return cmd

    def _exact_solve(self, q, lo, hi):
        """DAQP on the QP OSQP did not solve (``solver.exact``; never with a forced failure),
        set up on first use: ``(z, y)`` or None."""
        if not self.settings.exact or self.force_failure:
            return None
        if self._exact is None:
            self._exact = ExactSolver(self.qp.qp)
        return self._exact.solve(q, lo, hi)

    def _static(self, mem: _Member, obs: Observation, b: int, s_eq) -> np.ndarray:
        """The static fallback gain around every CAV (module docstring)."""
        ctx = self._ctx
        vel = np.asarray(obs.velocity[b], float)
        spc = np.asarray(obs.spacing[b], float)
        s_ref = np.asarray(ctx.spacing_reference()[b], float) - float(ctx.s_star[b])
        s_nom = float(self.hdv.equilibrium_spacing(self._clip_v(mem.v_eq)))
        out = np.zeros(self.n_c)
        for j, col in enumerate(self.cavs):
            u = 0.0
            for what, i, g in self._fb:
                k = col + i
                if k >= self.nv:
                    continue
                if what == "v":
                    u += g * (vel[k] - mem.v_eq)
                elif i == 0:
                    u += g * (spc[k] - s_eq[j])
                else:
                    u += g * (spc[k] - s_nom - np.nan_to_num(s_ref[k]))
            out[j] = u
        return out

    def _fallback(self, mem: _Member, obs: Observation, b: int, s_eq, why: str) -> np.ndarray:
        st = self._st
        N = self.settings.horizon
        if mem.plan is not None and mem.plan_age + 1 < N:
            mem.plan_age += 1
            cmd = np.clip(mem.plan[mem.plan_age], self._a_min, self._a_max)
            st["fallback_shifted"] += 1
            self._record(mem, cmd, 1, None, 0.0)
            return cmd
        cmd = self._static(mem, obs, b, s_eq)
        if not np.all(np.isfinite(cmd)):
            cmd = self._hold(mem)
            self._record(mem, cmd, 3, None, 0.0)
            return cmd
        mem.plan = None
        st["fallback_static"] += 1
        cmd = np.clip(cmd, self._a_min, self._a_max)
        self._record(mem, cmd, 2, None, 0.0)
        return cmd

    def _hold(self, mem: _Member) -> np.ndarray:
        self._st["fallback_hold"] += 1
        prev = np.where(np.isfinite(mem.past[0]), mem.past[0], 0.0)
        return np.clip(prev, self._a_min, self._a_max)

    # ---------------------------------------------------------------- history and reports

    def _record(self, mem: _Member, cmd, code: int, plan, slack: float) -> None:
        if not self.record:
            return
        h = mem.hist
        N = self.settings.horizon
        h["u"].append(np.array(cmd, float).reshape(self.n_c))
        h["status"].append(code)
        h["v_eq"].append(mem.v_eq)
        h["slack"].append(slack)
        h["plan"].append(np.full((N, self.n_c), np.nan) if plan is None else plan.copy())

    def history(self) -> dict[str, np.ndarray]:
        """Per-sample record of the last run, leading axes ``(batch, samples)``: ``t (S,)``,
        ``u`` applied command, ``status`` (:data:`STATUS_CODES`), ``v_eq``, ``slack`` (largest
        spacing slack, m), ``step_time`` (s), ``pred_time (N,)`` and the planned inputs: for
        one CAV ``u (B, S)`` and ``plan (B, S, N)`` (the MPC's layout), for several
        ``u (B, S, n_c)`` and ``plan_cavs (B, S, N, n_c)``."""
        if not self._members or not self.record:
            return {}
        B = len(self._members)
        S = min(len(m.hist["u"]) for m in self._members)
        out: dict[str, Any] = {"t": np.array(self._t[:S])}
        for key in ("u", "status", "v_eq", "slack", "plan"):
            out[key] = np.array([np.array(m.hist[key][:S]) for m in self._members])
        out["step_time"] = np.array(self._st["step_time"][: S * B]).reshape(S, B).T
        if self.n_c == 1:  # the MPC's layout (recordings plot it): (B, S) and (B, S, N)
            out["u"] = out["u"][..., 0]
            out["plan"] = out["plan"][..., 0]
        else:
            out["plan_cavs"] = out.pop("plan")
        out["pred_time"] = np.arange(self.settings.horizon) * self.sample_time
        return out

    def describe(self) -> dict[str, Any]:
        """Settings, data size and excitation, QP size, fallback gain."""
        d = self.settings.as_dict()
        d.update({
            "type": "deep_lcc",
            "name": self.name,
            "kind": self.kind,
            "cavs": list(self.cavs),
            "sample_time": self.sample_time,
            "equilibrium": self.settings.equilibrium_mode(self.kind),
            "data_key": self.data_key,
            "excitation": self.excitation.as_dict(),
            "qp": {
                "formulation": "exact reduction of the QP in g (lcc_synth.deeplcc.hankel), "
                               "CasADi, built once",
                "g_columns": self.data_columns,
                "variables": self.qp.n_var,
                "constraints": self.qp.qp.A.shape[0],
                "setup_time_s": self.setup_time,
                "solver": solver_label(self.settings.solver),
            },
            "fallback": {"source": "paper", "semantics": self.fallback.semantics,
                         "gains": dict(self.fallback.gains)},
        })  # fmt: skip
        return d

    def as_dict(self) -> dict[str, Any]:
        """What defines the controller (settings, string, data key), without run-time facts
        such as the set-up time: two loads of one problem file give equal dicts."""
        return {"type": "deep_lcc", "name": self.name, "kind": self.kind,
                "cavs": list(self.cavs), "n_vehicles": self.nv, "data_key": self.data_key,
                **self.settings.as_dict()}  # fmt: skip

    def stats(self) -> dict[str, Any]:
        """Step and solve times (ms), fallbacks, QP failures, slack use, measured violations
        (as :meth:`lcc_synth.mpc.controller.MPCController.stats`), and ``exact_solves``: the
        steps OSQP stopped unsolved (counted in ``qp_failures``) that DAQP solved."""
        return {**step_statistics(self._st), "exact_solves": int(self._st.get("exact_solves", 0))}
