"""What every predictive controller shares: the sample loop, the equilibrium estimate, the head
prediction, the linearisation cache, re-linearisation, the warm-started solve and its
statistics, the status codes and the pickling rule.

:class:`SampleLoop` is the loop of every predictive controller (the MPC and DeeP-LCC,
:class:`~lcc_synth.deeplcc.controller.DeePLCCController`): each batch member's step, the
equilibrium's window, the warm start, the count of each solve and slack. :class:`MPCScaffold`
is the base of the one MPC (:class:`~lcc_synth.mpc.controller.
MPCController`: the paper's error state of ``-m..n_model`` around one CAV, or one input per CAV
of a platoon or ring). It uses the one condensed QP of :class:`~lcc_synth.mpc.formulation.
Formulation` (``nu`` inputs); a layout supplies its prediction model (:func:`~lcc_synth.mpc.
formulation.linearize` or :func:`~lcc_synth.mpc.joint_prediction.linearize_joint`), its state
and its fallback arithmetic; the loop here runs each batch member's step, never raises inside it
(an exception is counted and the member holds its last command), and keeps the step record of
:mod:`lcc_synth.mpc.report`. Moving this code here from the controllers changed no
operation, so every pinned number is bit for bit the same (``tests/test_mpc*.py``,
``tests/test_deeplcc*.py``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lcc_synth.mpc.active_set import make_solver, solver_label
from lcc_synth.mpc.comfort import solve_prioritised
from lcc_synth.mpc.solver import POLISH_NAMES, OSQPSolver
from lcc_synth.mpc.step_cache import LastValue, clip

__all__ = [
    "STATUS_CODES", "Layout", "LoopState", "Sample", "SampleLoop", "MPCScaffold", "new_history",
    "update_equilibrium", "head_prediction",
]

#: Per-step (per-CAV for the joint MPC) outcome codes stored in ``history()["status"]``.
STATUS_CODES = {0: "qp", 1: "shifted_plan", 2: "static_gain", 3: "hold"}


@dataclass
class LoopState:
    """Solver and loop state of one batch member.

    ``v_buf`` is the moving-average window of the reference velocity (:func:`update_equilibrium`),
    ``plan`` the last optimal inputs (the shifted-plan fallback), ``warm`` the last primal and
    dual solution, ``past`` the applied commands, newest first (the comfort rows), ``u_prev``
    the previous input the cost penalises the change from (a float for one CAV, ``(n_cav,)``
    for a string), ``delay`` the delay register or lag state of the prediction; ``s_off``,
    ``s_off_cols``, ``p_ref``, ``cmd_prev`` and ``s_eq`` are the one-CAV layout's.
    """

    solver: OSQPSolver
    lin: Any
    qp: Any
    fb_K: np.ndarray
    fb_kh: Any
    v_buf: np.ndarray
    v_buf_n: int = 0
    v_buf_i: int = 0
    v_eq: float = 0.0
    v_ref_prev: float = math.nan
    plan: np.ndarray | None = None
    plan_age: int = 0
    warm: tuple | None = None
    past: np.ndarray = field(default_factory=lambda: np.zeros(1))
    hist: dict[str, list] = field(default_factory=dict)
    u_prev: Any = 0.0
    delay: Any = None  # delay.StateHistory (past observed states) or lag.LagState (a_0)
    s_off: np.ndarray = field(default_factory=lambda: np.zeros(0))
    s_off_cols: np.ndarray | None = None  # s_off of the modelled vehicles (state order)
    p_ref: float = math.nan
    cmd_prev: float = 0.0
    s_eq: LastValue = field(default_factory=LastValue)


@dataclass
class Sample:
    """What a layout observed at one sample: the QP's initial state ``x0`` and head
    prediction ``d_model``, the head prediction ``d`` and the layout's own measurements
    (``extra``: FD-LCC's position state and the measured spacing for one CAV; the reference
    spacings, velocities and spacings for a string)."""

    x0: np.ndarray
    d: np.ndarray
    d_model: np.ndarray
    extra: dict[str, Any] = field(default_factory=dict)


def new_history() -> dict[str, list]:
    """An empty per-step history of one batch member (what the MPC records at each sample)."""
    return {k: [] for k in ("u", "u_model", "status", "osqp_time", "iterations", "slack", "v_eq",
                            "v_lin", "x0", "d", "plan", "lin")}


def update_equilibrium(mem: LoopState, v_ref: float) -> None:
    """Push ``v_ref`` into the member's window and set ``mem.v_eq`` to the window's mean.

    The first finite value fills the whole window (no start-up transient); a non-finite
    ``v_ref`` leaves ``v_eq`` unchanged.
    """
    if not math.isfinite(v_ref):
        return
    W = mem.v_buf.size
    if mem.v_buf_n == 0:
        mem.v_buf[:] = v_ref
        mem.v_buf_n = W
    else:
        mem.v_buf[mem.v_buf_i] = v_ref
    mem.v_buf_i = (mem.v_buf_i + 1) % W
    mem.v_eq = float(mem.v_buf.sum()) / W  # the mean's own sum and division, bit for bit


def head_prediction(mem: LoopState, v_ref: float, N: int, Ts: float, prediction,
                    a_lo: float, a_hi: float) -> tuple[float, np.ndarray]:  # fmt: skip
    """``(d0, d)``: the reference vehicle's measured velocity error ``d0 = v_ref - v_eq`` (0
    when ``v_ref`` is not finite) and its prediction ``d_0..d_{N-1}`` (``prediction.head``).

    ``"constant"``: ``d_k = v_ref - v_eq`` held; ``"accel"``: plus the measured acceleration
    (difference of the last two samples, clipped to ``[a_lo, a_hi]``) held for
    ``head_accel_hold`` seconds, the velocity never below 0. Sets ``mem.v_ref_prev``.
    """
    v_eq = mem.v_eq
    d0 = (v_ref - v_eq) if math.isfinite(v_ref) else 0.0
    d = np.full(N, d0)
    if prediction.head == "accel" and math.isfinite(mem.v_ref_prev) and math.isfinite(v_ref):
        a = float(np.clip((v_ref - mem.v_ref_prev) / Ts, a_lo, a_hi))
        d = d0 + a * np.minimum(np.arange(N) * Ts, prediction.head_accel_hold)
        d = np.maximum(d, -v_eq)
    mem.v_ref_prev = v_ref
    return d0, d


class Layout:
    """What a layout of the one MPC holds: its system, settings and kind (a subclass adds its
    prediction model and state; :class:`~lcc_synth.mpc.controller.OneCAVLayout`,
    :class:`~lcc_synth.mpc.joint.StringLayout`).

    A layout sets ``nu`` (CAVs), ``v_hi`` (the fastest valid speed), ``v_design`` (where the
    prediction model is first linearised) and implements, for :class:`~lcc_synth.mpc.
    controller.MPCController`: ``linearize(v)``, ``state_weights(model)``,
    ``families(model)``, ``default_fallback(model)``, ``check_fallback(model, gains,
    source)``, ``feedback(model, gains)``, ``check_context(ctx, name)``, ``limits(a_min,
    a_max)``, ``member(mpc, ctx, b, W)``, ``empty_output(batch)``, ``output(out)``,
    ``observe(mpc, b, mem, obs)`` (a :class:`Sample`), ``count_violations(mpc, sample)``,
    ``spacing_bounds(mpc, mem, sample)``, ``jerk_bounds(sample)``, ``plan(U)``,
    ``command(mpc, mem, sample, U)``, ``fallback(mpc, mem, sample, why)``, ``hold(mpc, mem,
    why)``, ``failed(code)``, ``history(mpc, out, S)``, ``describe(mpc)``, ``as_dict(mpc)``
    and ``stats(mpc, out)``.
    """

    #: one input per CAV in the history and the command (``(batch, n_cav)``)
    joint = False
    #: the fallback's source label when the user gives none
    default_source = ""

    def __init__(self, system, settings) -> None:
        self.system = system
        self.settings = settings
        self.kind = system.kind


class SampleLoop:
    """The sample loop and bookkeeping of every predictive controller: the MPC of every layout
    (:class:`MPCScaffold`) and DeeP-LCC (:class:`~lcc_synth.deeplcc.controller.
    DeePLCCController`).

    A subclass sets ``name``, ``settings``, ``sample_time``, ``_v_hi``, ``_members`` (each with
    the fields ``v_buf``, ``v_buf_n``, ``v_buf_i``, ``v_eq``, ``warm`` and ``past`` of
    :class:`LoopState`), ``_ctx``, ``_st`` (:func:`~lcc_synth.mpc.report.new_step_record`),
    ``_t``, ``_shift_z``, ``_shift_y`` and implements ``_step(b, mem, obs)`` and
    ``_on_error(mem)`` (the command of a member whose step raised). State is real: the OSQP
    workspaces and the loop state.
    """

    def __getstate__(self) -> dict[str, Any]:
        """Picklable without the run state (OSQP workspaces); call :meth:`reset` after."""
        state = dict(self.__dict__)
        state["_members"] = []
        state["_ctx"] = None
        return state

    def toml_table(self) -> dict[str, Any]:
        """The ``[controllers.NAME]`` table that builds this controller."""
        return self.settings.toml_table()

    # ---------------------------------------------------------------- shared helpers

    def _clip_v(self, v: float) -> float:
        return clip(v, 1.0, self._v_hi - 1.0)

    def _window(self, seconds: float) -> int:
        """Samples of the equilibrium's moving average over ``seconds``."""
        return max(1, int(round(seconds / self.sample_time)))

    def _warm_start(self, mem) -> tuple[Any, Any]:
        """The member's last primal and dual solution shifted by one sample (None at first)."""
        warm = mem.warm
        if warm is None:
            return None, None
        return warm[0][self._shift_z], warm[1][self._shift_y]

    def _count_solve(self, res) -> None:
        """Count one solve in the step record: time, iterations, polish and failure status."""
        st = self._st
        st["solves"] += 1
        st["osqp_time"].append(res.run_time)
        st["iterations"].append(res.iterations)
        pname = POLISH_NAMES.get(res.polish, str(res.polish))
        st["polish"][pname] = st["polish"].get(pname, 0) + 1
        if not res.ok:
            st["qp_failures"][res.status] = st["qp_failures"].get(res.status, 0) + 1

    def _note_slack(self, slack: float) -> None:
        if slack > 1e-6:
            self._st["slack_steps"] += 1
            self._st["max_slack"] = max(self._st["max_slack"], slack)

    # ---------------------------------------------------------------- the loop

    def _run_members(self, obs, out: np.ndarray) -> None:
        """Every batch member's step into ``out[b]``; an exception is counted and held."""
        ctx = self._ctx
        if ctx is None:
            raise RuntimeError(f"{type(self).__name__}: call reset(ctx) before the first step")
        self._t.append(float(obs.t))
        for b in range(ctx.batch):
            t0 = time.perf_counter()
            mem = self._members[b]
            try:
                out[b] = self._step(b, mem, obs)
            except Exception as err:  # never raise inside the loop
                self._st["errors"] += 1
                if len(self._st["error_messages"]) < 5:
                    self._st["error_messages"].append(f"t={obs.t:g}: {type(err).__name__}: {err}")
                out[b] = self._on_error(mem)
            mem.past[1:] = mem.past[:-1]
            mem.past[0] = out[b]
            self._st["step_time"].append(time.perf_counter() - t0)
        self._st["steps"] += 1


class MPCScaffold(SampleLoop):
    """What the MPC of every layout adds to :class:`SampleLoop`: the linearisation cache,
    re-linearisation, the solver set-up, the comfort-prioritised solve and the description.

    A subclass also sets ``formulation``, ``_lin0`` and ``_cache`` and implements
    ``_linearize_at(v)`` (the prediction model at ``v``) and ``_feedback(model)`` (the
    fallback's ``(K, k_h)``).
    """

    def _new_solver(self, qp, u0, a_min, a_max):
        """One OSQP (or DAQP) workspace of ``qp`` at a zero state (set up once per run)."""
        form = self.formulation
        N = self.settings.horizon
        p = form.param(np.zeros(form.nx), np.zeros(N), u0)
        q, lo, hi = form.bounds(qp, p, a_min, a_max, np.full((len(form.families), N), -np.inf))
        return make_solver(qp, q, lo, hi, self.settings.solver)

    def _linearization(self, v: float):
        """Cached ``(lin, qp, fb_K, fb_kh)`` at ``v`` rounded to 0.01 m/s."""
        key = round(self._clip_v(v), 2)
        hit = self._cache.get(key)
        if hit is None:
            lin = self._lin0 if key == round(self._lin0.v_lin, 2) else self._linearize_at(key)
            qp = self.formulation.matrices(lin)
            K, kh = self._feedback(lin.model)
            hit = (lin, qp, K, kh)
            if len(self._cache) > 256:
                self._cache.clear()
            self._cache[key] = hit
        return hit

    def _relinearize(self, mem: LoopState) -> None:
        """Re-linearise when ``v_eq`` left ``v_lin`` by more than the threshold (option)."""
        pred = self.settings.prediction
        if not pred.relinearize or abs(mem.v_eq - mem.lin.v_lin) <= pred.relinearize_threshold:
            return
        t0 = time.perf_counter()
        grid = pred.relinearize_threshold / 4.0
        try:
            lin, qp, K, kh = self._linearization(round(mem.v_eq / grid) * grid)
            mem.solver.update_matrices(qp)
        except Exception as err:
            self._st["relinearize_failures"] += 1
            if len(self._st["error_messages"]) < 5:
                self._st["error_messages"].append(f"re-linearisation at {mem.v_eq:.2f}: {err}")
            return
        mem.lin, mem.qp, mem.fb_K, mem.fb_kh = lin, qp, K, kh
        self._st["relinearizations"] += 1
        self._st["relin_time"].append(time.perf_counter() - t0)

    def _solve(self, mem: LoopState, q, lo, hi):
        """Warm-started, comfort-prioritised solve; counts it in the step record."""
        z0, y0 = self._warm_start(mem)
        res = solve_prioritised(mem.solver, self.formulation, q, lo, hi, z0, y0, self._st)
        self._count_solve(res)
        if res.ok:
            mem.warm = (res.z, res.y)
        return res

    def _describe(self, layout: dict[str, Any], equilibrium: dict[str, Any], qp_label: str,
                  gains: Any) -> dict[str, Any]:  # fmt: skip
        """The settings plus ``type``, ``name``, ``kind``, the layout's keys, the equilibrium,
        the state names, the QP's size and solver and the fallback (key order kept)."""
        s = self.settings
        d = s.as_dict()
        d.update({"type": "mpc", "name": self.name, "kind": self.kind, **layout,
                  "equilibrium": s.prediction.equilibrium_mode(self.kind), **equilibrium,
                  "state_names": list(self._lin0.model.state_names),
                  "qp": {
                      "formulation": qp_label,
                      "variables": self.formulation.nz,
                      "constraints": self.formulation.nc,
                      "spacing_families": [f.vehicle for f in self.formulation.families],
                      "solver": solver_label(s.solver),
                  },
                  "fallback": {"source": self.fallback_source,
                               "semantics": self.fallback.semantics, "gains": gains}})  # fmt: skip
        d["solver"]["name"] = s.solver.method
        return d

