"""QP solvers of the MPC: OSQP set up once (the real-time path), an exact reference solver
and the naive rebuild-every-step variant (for tests and benchmarks only).

OSQP statuses are checked on every solve: only ``solved`` is accepted (``solved inaccurate``,
``maximum iterations reached``, infeasibility, time limit... are failures that trigger the
controller's fallback chain). A failed polish (``status_polish < 0``) is counted but the ADMM
solution, converged to the tight default tolerances (1e-6), is still used.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import time
from dataclasses import dataclass

import numpy as np

from lcc_synth.mpc.formulation import QPMatrices
from lcc_synth.mpc.settings import SolverSettings

__all__ = ["SolveResult", "OSQPSolver", "solve_exact", "solve_rebuild"]

OSQP_SOLVED = 1
OSQP_SIGINT = 10  # osqp.SolverStatus.OSQP_SIGINT: interrupted by Ctrl-C
POLISH_NAMES = {
    -2: "linsys_error",
    -1: "failed",
    0: "not_performed",
    1: "success",
    2: "no_active_set_found",
}


@dataclass
class SolveResult:
    """Outcome of one QP solve."""

    ok: bool
    status: str
    status_val: int
    polish: int
    z: np.ndarray | None
    y: np.ndarray | None
    iterations: int
    run_time: float


def _osqp_interrupt_flag():
    """``osqp_is_interrupted`` of the loaded OSQP extension, or ``None`` if it is not exported.

    OSQP replaces the SIGINT handler while it solves and only looks at the flag between ADMM
    iterations: a Ctrl-C that lands in the last iterations of a converging solve is consumed
    and the solve reports ``solved`` (measured: 5 of 20 interrupted MPC runs went on to the
    end and exited 0). The flag stays set until the next solve starts, so reading it after
    every solve turns each such Ctrl-C into :class:`~lcc_synth.errors.Interrupted` (a
    ``KeyboardInterrupt``; :func:`lcc_synth.interrupts.deliver`).
    """
    try:
        from osqp import ext_builtin

        fn = ctypes.CDLL(ext_builtin.__file__).osqp_is_interrupted
    except (ImportError, OSError, AttributeError):  # pragma: no cover - another OSQP build
        return None
    fn.restype, fn.argtypes = ctypes.c_int, []
    return fn


class _SilentStdout:
    """Discard what C code prints on file descriptor 1 inside the block.

    OSQP prints "Polishing not needed - no active set detected at optimal point" with
    ``printf`` even when ``verbose`` is off, which would corrupt ``--json`` output. The block
    flushes Python's and C's buffers, points fd 1 at /dev/null and restores it (a few
    microseconds per solve).
    """

    def __init__(self):
        self._null = os.open(os.devnull, os.O_WRONLY)
        try:
            self._libc = ctypes.CDLL(None)
        except OSError:  # pragma: no cover - no C library handle (not on Linux/macOS)
            self._libc = None
        self._saved = -1

    def __enter__(self):
        try:
            sys.stdout.flush()
        except (AttributeError, ValueError):  # pragma: no cover - closed / replaced stdout
            pass
        if self._libc is not None:
            self._libc.fflush(None)
        self._saved = os.dup(1)
        os.dup2(self._null, 1)
        return self

    def __exit__(self, *exc):
        if self._libc is not None:
            self._libc.fflush(None)
        os.dup2(self._saved, 1)
        os.close(self._saved)
        self._saved = -1
        return False


class OSQPSolver:
    """One OSQP workspace for the whole run: vectors updated per step, matrices only when the
    model is re-linearised (same sparsity pattern, ``update(Px=..., Ax=...)``).

    Parameters
    ----------
    qp : QPMatrices
        Initial matrices.
    q, l, u : numpy.ndarray
        Initial vectors.
    settings : SolverSettings
    """

    def __init__(self, qp: QPMatrices, q, l, u, settings: SolverSettings):
        import osqp

        self.settings = settings
        self._P_pattern = (qp.P.indptr.copy(), qp.P.indices.copy())
        self._A_pattern = (qp.A.indptr.copy(), qp.A.indices.copy())
        self._solver = osqp.OSQP()
        # OSQP keeps the arrays given to setup() as its workspace and writes later matrix
        # updates into them: give it private copies (the QPMatrices are cached and shared by
        # the batch members and by later re-linearisations).
        self._solver.setup(qp.P.copy(), q, qp.A.copy(), l, u, **settings.osqp_kwargs())
        self._infty = float(self._solver.constant("OSQP_INFTY"))
        self._silent = _SilentStdout() if settings.polish else None
        self._interrupted = _osqp_interrupt_flag()
        self.force_failure = False  # test hook: make every solve report a failure

    def update_matrices(self, qp: QPMatrices) -> None:
        """New numeric values on the same sparsity pattern (re-linearisation)."""
        for M, (indptr, indices), what in (
            (qp.P, self._P_pattern, "P"),
            (qp.A, self._A_pattern, "A"),
        ):
            if not (np.array_equal(M.indptr, indptr) and np.array_equal(M.indices, indices)):
                raise RuntimeError(f"the sparsity pattern of {what} changed")
        self._solver.update(Px=qp.P.data.copy(), Ax=qp.A.data.copy())

    def solve(self, q, l, u, warm_z=None, warm_y=None) -> SolveResult:
        """Update the vectors, warm-start (optional) and solve.

        Calls the extension's workspace directly: the same C calls as ``osqp.OSQP.update`` /
        ``warm_start`` / ``solve`` (bounds clipped to ``OSQP_INFTY`` as there) without the
        Python interface's per-call bookkeeping (its info namespace and derivative cache,
        about 40 us of a 0.3 ms step; the results are bit for bit the same).
        """
        ext = self._solver._solver
        ext.update_data_vec(q=q, l=np.maximum(l, -self._infty), u=np.minimum(u, self._infty))
        if warm_z is not None and self.settings.warm_start:
            ext.warm_start(warm_z, warm_y)
        if self._silent is not None:
            with self._silent:
                ext.solve()
        else:
            ext.solve()
        info = ext.info
        status_val = int(info.status_val)
        # OSQP catches Ctrl-C during a solve: hand it back to Python, also when the solve
        # converged after the signal (the status then says "solved")
        if status_val == OSQP_SIGINT or (self._interrupted is not None
                                         and self._interrupted()):
            from lcc_synth.interrupts import deliver

            deliver(signal.SIGINT)  # Interrupted (a KeyboardInterrupt), as the CLI's handler
        ok = status_val == OSQP_SOLVED and not self.force_failure
        sol = ext.solution
        x, y = sol.x, sol.y
        z = None if x is None else np.array(x)
        if ok and (z is None or not np.isfinite(z).all()):
            ok = False
        status = "forced_failure" if self.force_failure else str(info.status)
        return SolveResult(
            ok, status, status_val, int(info.status_polish), z,
            None if y is None else np.array(y), int(info.iter), float(info.run_time),
        )  # fmt: skip


def solve_exact(qp: QPMatrices, q, l, u, solver: str = "daqp") -> np.ndarray:
    """Exact solution of the same QP with an active-set solver bundled with CasADi.

    Parameters
    ----------
    solver : {"daqp", "qpoases"}
        CasADi ``conic`` plugin.

    Raises
    ------
    RuntimeError
        When the solver does not report success.
    """
    import casadi as ca

    Pu = qp.P.toarray()
    H = Pu + np.triu(Pu, 1).T
    A = qp.A.toarray()
    big = 1e20
    lo = np.where(np.isfinite(l), l, -big)
    hi = np.where(np.isfinite(u), u, big)
    opts = {"error_on_fail": False}
    if solver == "qpoases":
        opts.update({"printLevel": "none"})
    conic = ca.conic(
        "exact", solver, {"h": ca.DM(H).sparsity(), "a": ca.DM(A).sparsity()}, opts
    )
    sol = conic(h=H, g=np.asarray(q, float), a=A, lba=lo, uba=hi)
    if not conic.stats().get("success", False):
        raise RuntimeError(f"{solver} failed: {conic.stats().get('return_status')}")
    return np.array(sol["x"]).reshape(-1)


def solve_rebuild(formulation, lin, q, l, u, settings: SolverSettings) -> tuple[SolveResult, float]:
    """The naive variant: evaluate the QP matrices and set up a new OSQP workspace, then solve.

    Returns the result and the wall time (s) of the whole step. Used by the benchmark to show
    what re-creating the solver on every step costs.
    """
    t0 = time.perf_counter()
    qp = formulation.matrices(lin)
    s = OSQPSolver(qp, q, l, u, settings)
    res = s.solve(q, l, u)
    return res, time.perf_counter() - t0
