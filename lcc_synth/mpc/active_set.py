"""The MPC's exact active-set option: DAQP on the dense condensed QP (``method = "daqp"``).

``[controllers.NAME.solver] method = "daqp"`` solves the same QP as the default OSQP
(:mod:`lcc_synth.mpc.formulation`: ``min 1/2 z'Hz + q'z, l <= Az <= u``) with DAQP (Arnström,
Bemporad & Axehill, "A dual active-set solver for embedded quadratic programming using
recursive LDL' updates", IEEE TAC 2022; the ``daqp`` package). DAQP is a dual active-set
method: it factors the constant Hessian once (``H = R'R``), works on the dual of the
least-distance problem, and stops at the exact optimum of the QP (to its pivot and feasibility
tolerances, 1e-6 on the constraints), so its first move agrees with any other exact solution
to rounding (``tests/test_mpc_active_set.py``: within 1e-9 m/s^2 of CasADi's DAQP on the
constrained steps of ``problems/mpc_head_brake.toml``, 1e-3 required).

One DAQP workspace per batch member is set up once (``daqp.Model.setup``: the factorisation
and the constraint map ``A R^-1``); a step updates the vectors only (``update(f=, bupper=,
blower=)``) and starts from the previous step's active set (DAQP's own warm start; the shifted
OSQP warm start is not used). Re-linearising re-runs the setup with the new matrices.
Infinite bounds are passed as ``±1e30`` (DAQP's infinity).

Measured (``benchmarks/bench_mpc.py``, n = 10, N = 50, 100 variables, 200 constraints, the
head-brake closed loop on the shared 2-core machine, thread CPU time of the whole controller
step): DAQP median 0.07 ms, p99 0.18 ms (its solve 0.025 ms median, 1 active-set iteration,
51 at most); OSQP median 0.31 ms, p99 5.6 ms (25 ADMM iterations median, 850 at most). In the
robustness sweep (``problems/sweep_robustness.toml``, 200 draws) DAQP's samples differ from
OSQP's by at most 3e-11 and its MPC takes 0.05 s of CPU per scenario against OSQP's 0.27 s.
They are not OSQP's bit for bit (OSQP stops at its 1e-6 tolerances, then polishes), so OSQP
stays the default. ``problems/showcase.toml`` and ``problems/sweep_robustness.toml`` select
DAQP for their MPCs and DeeP-LCC (the showcase's table within 7e-13 of its OSQP run, relative,
every metric; 100 sweep draws within 3e-7, the sweep 2.5 times faster).

The OSQP keys of the table (``eps_abs``, ``eps_rel``, ``polish``, ``warm_start``) do not
apply to DAQP; ``max_iter`` is DAQP's iteration limit and ``time_limit`` its time limit.

Inside :func:`exact_qp` every workspace that would be a polishing OSQP is a DAQP one: the
small-signal measurements of :mod:`lcc_synth.experiments.string_as_run` solve the
controller's QP exactly, which is what OSQP's successful polish returns (measured on the
showcase: the same ratios to 12 digits at 1/7 of the CPU time).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

import numpy as np

from lcc_synth.mpc.formulation import QPMatrices
from lcc_synth.mpc.settings import SolverSettings
from lcc_synth.mpc.solver import OSQPSolver, SolveResult

__all__ = ["DAQP_INFINITY", "DAQPSolver", "exact_qp", "make_solver", "solver_label"]

#: DAQP treats bounds at or beyond this magnitude as absent.
DAQP_INFINITY = 1e30

#: DAQP exit flags (``daqp.solve`` documentation): > 0 success.
_EXITFLAGS = {
    1: "solved",
    2: "soft_optimal",
    -1: "infeasible",
    -2: "cycling",
    -3: "unbounded",
    -4: "iteration_limit",
    -5: "nonconvex",
    -6: "overdetermined_initial_active_set",
    -7: "time_limit",
}


def _dense(qp: QPMatrices) -> tuple[np.ndarray, np.ndarray]:
    Pu = qp.P.toarray()
    return Pu + np.triu(Pu, 1).T, np.ascontiguousarray(qp.A.toarray())


def _finite(v) -> np.ndarray:
    return np.clip(np.asarray(v, dtype=float), -DAQP_INFINITY, DAQP_INFINITY)


class DAQPSolver:
    """One DAQP workspace for the whole run (the interface of
    :class:`~lcc_synth.mpc.solver.OSQPSolver`).

    Parameters
    ----------
    qp : QPMatrices
        Initial matrices.
    q, l, u : numpy.ndarray
        Initial vectors.
    settings : SolverSettings
    """

    def __init__(self, qp: QPMatrices, q, l, u, settings: SolverSettings):
        import daqp

        self.settings = settings
        self._model = daqp.Model()
        self._setup(qp, q, l, u)
        self.force_failure = False  # test hook, as OSQPSolver's

    def _setup(self, qp: QPMatrices, q, l, u) -> None:
        H, A = _dense(qp)
        flag = self._model.setup(H, np.asarray(q, float), A, _finite(u), _finite(l))
        flag = flag[0] if isinstance(flag, tuple) else flag
        if flag < 0:
            raise RuntimeError(f"DAQP setup failed: {_EXITFLAGS.get(flag, flag)}")
        s = {"iter_limit": int(self.settings.max_iter)}
        if self.settings.time_limit > 0:
            s["time_limit"] = float(self.settings.time_limit)
        self._model.settings = s
        self._q, self._l, self._u = q, l, u

    def update_matrices(self, qp: QPMatrices) -> None:
        """New matrices (re-linearisation): a new factorisation, the last vectors kept."""
        self._setup(qp, self._q, self._l, self._u)

    def solve(self, q, l, u, warm_z=None, warm_y=None) -> SolveResult:
        """Update the vectors and solve from the previous active set (``warm_z``, ``warm_y``
        are accepted for the interface and not used)."""
        t0 = time.perf_counter()
        self._q, self._l, self._u = q, l, u
        self._model.update(f=np.asarray(q, float), bupper=_finite(u), blower=_finite(l))
        x, _, flag, info = self._model.solve()
        run_time = time.perf_counter() - t0
        ok = flag > 0 and not self.force_failure
        z = np.array(x, dtype=float)
        if ok and not np.isfinite(z).all():
            ok = False
        status = "forced_failure" if self.force_failure else _EXITFLAGS.get(flag, f"exit {flag}")
        lam = info.get("lam")
        return SolveResult(
            ok, status, int(flag), 0, z, None if lam is None else np.array(lam, dtype=float),
            int(info.get("iterations", -1)), run_time,
        )  # fmt: skip


#: The swaps of the innermost :func:`exact_qp` block (``None``: outside any).
_EXACT: ContextVar[list[str] | None] = ContextVar("lcc_synth_exact_qp", default=None)


@contextmanager
def exact_qp() -> Iterator[list[str]]:
    """Within the block, :func:`make_solver` sets up DAQP where the settings ask for an OSQP
    that polishes (``method = "osqp"``, ``polish = true``, the MPC's and DeeP-LCC's default):
    the same QP, solved to its exact optimum, which a successful polish returns. An OSQP that
    does not polish is kept (its solutions are ADMM iterates at its tolerance). Yields the
    list of the workspaces swapped (one ``"osqp -> daqp"`` per workspace), empty when the
    block set up none; it reaches controllers inside wrappers, which build their solvers at
    ``reset``."""
    swaps: list[str] = []
    token = _EXACT.set(swaps)
    try:
        yield swaps
    finally:
        _EXACT.reset(token)


def make_solver(qp: QPMatrices, q, l, u, settings: SolverSettings):
    """The solver workspace of ``settings.method``: :class:`OSQPSolver` or :class:`DAQPSolver`
    (DAQP for a polishing OSQP inside :func:`exact_qp`)."""
    if settings.method == "daqp":
        return DAQPSolver(qp, q, l, u, settings)
    swaps = _EXACT.get()
    if swaps is not None and settings.polish:
        swaps.append("osqp -> daqp")
        return DAQPSolver(qp, q, l, u, settings)
    return OSQPSolver(qp, q, l, u, settings)


def solver_label(settings: SolverSettings) -> str:
    """``"osqp 1.1.3"`` / ``"daqp 0.11.0"``: the method and its installed version."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return f"{settings.method} {version(settings.method)}"
    except PackageNotFoundError:  # pragma: no cover - declared dependencies
        return settings.method
