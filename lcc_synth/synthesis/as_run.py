"""Design what runs: the equilibrium estimator, sampling and latency in the synthesis loop.

With ``equilibrium = "estimated"`` the law is ``u = g (x - E w)`` (:mod:`lcc_synth.analysis.
as_run`: ``w`` the estimate of ``v - v*``, ``E`` the shift of every error), a static *output*
feedback on ``xi = [x; w]``:

    d xi/dt = A_a xi + B_a g C xi + B_w,a noise,   C = [I, -E],
    A_a = [[A, 0], [y / tau, -1 / tau]]              (y: the velocity ahead, a state or v_h)

with ``g`` on the pattern. :func:`output_cost` is the true H2 cost ``J = tr((Q_a + r C' g' g C)
L)`` of that loop, its gradient ``2 (r g C L C' + B_a' P L C')`` and the Anderson-Moore step
``r g*_P (C L C')_PP = -(B_a' P L C')_P`` (the structured polish of
:mod:`lcc_synth.synthesis.structured`, with ``L`` replaced by ``C L C'``). On CF-LCC the estimate
reads only the head's velocity: with acceleration noise alone ``J`` is the fixed-equilibrium
cost exactly (the head-velocity weight makes it differ).

:func:`as_run_design`:

1. ``weight > 0``: a trade-off from the structured H2 gain, minimising
   ``J(g) / J(g_0) + weight * A(g)`` over the pattern (L-BFGS-B, finite differences), with
   ``A(g) = mean_k max(0, |Gamma(j w_k)|^2 - 1)^2`` the amplification of the continuous as-run
   loop on a log grid over [1e-3, 3] rad/s (120 points per decade);
2. if the gain is then string stable *as run* (the exact loop: sampling, latency, filter; the
   verdict of :func:`lcc_synth.analysis.as_run.as_run_report`) with ``margin >= margin``, the
   output-feedback descent polishes it on ``J``, accepting only steps whose as-run loop stays
   so (a feasible-direction method, as :mod:`lcc_synth.synthesis.string_lmi`).

Otherwise the design is returned with its as-run verdict (no step could be accepted): the
report says so (``as_run.string_stable = false``), never silently.

An open platoon (a gain row per CAV; :func:`check_platoon`): the loop of every CAV at once
(:func:`lcc_synth.analysis.as_run.as_run_loop`, every CAV sampled at the same period with the
same latency and filter), a fixed equilibrium (``C = I``: ``J`` is the platoon's true H2
cost), the Anderson-Moore step row by row. No trade-off step (``weight > 0`` is refused): when
the structured gain is not string stable as run, the polish starts instead from the string
LMI's gain on the same patterns (:func:`lcc_synth.synthesis.string_lmi.string_lmi`, passed as
``fallback``) if that one is; ``info["start"]`` says which. A platoon of one CAV runs the one
CAV's computation on its row: the ``kind = "lcc"`` string's gain bit for bit while the
structured gain is string stable as run (the string has no fallback, so they differ when it
is not: the string reports NOT string stable). Measured (tests/test_as_run_design_platoon.py,
2 cores, shared): the open platoon of 4 (CAVs 2 and 4, CAV 2 hearing vehicles 1-3, 14 free
entries, ``q_s0 = 10``) sampled at 0.1 s with 0.2 s latency: the structured gain peaks at
``|Gamma|`` 1.0236 as run (margin -0.094); the string LMI start and 7 accepted steps end
string stable as run at margin 1.0e-3 for an H2 of 3.7060 against 3.6509, in 1.6 s (each
trial costs one as-run loop and verdict, 16 states). With CAV 2 hearing only 1-3 on a platoon
of 4 whose CAVs are 2 and 3 the LMI is infeasible: the report's note says so.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np
import scipy.linalg as sla

from lcc_synth.analysis.as_run import (
    as_run_loop,
    as_run_report,
    estimator_shift,
    law_of_gains,
)
from lcc_synth.errors import ConfigError
from lcc_synth.synthesis.h2 import STABILITY_TOL, H2Plant, PlatoonPlant, SynthesisError

__all__ = ["AsRunSettings", "output_cost", "as_run_check", "amplification", "check_platoon",
           "as_run_note", "as_run_design"]


@dataclass(frozen=True)
class AsRunSettings:
    """The ``[synthesis.as_run]`` table (problems/README.md).

    ``equilibrium_tau``: the estimate's time constant (s), ``None`` = fixed equilibrium;
    ``sample_time``: the controller period (s), ``None`` = every simulator step ``dt``;
    ``latency``: V2V latency (s) of the string check; ``measurement_filter`` (s, 0 = off);
    ``margin``: relative string-stability margin every accepted step keeps; ``weight``: the
    trade-off weight on the amplification (0 = none); ``polish_steps``.
    """

    equilibrium_tau: float | None = None
    sample_time: float | None = None
    dt: float = 0.01
    latency: float = 0.0
    measurement_filter: float = 0.0
    margin: float = 1e-3
    weight: float = 0.0
    polish_steps: int = 200

    @property
    def period(self) -> float:
        return float(self.dt if self.sample_time is None else self.sample_time)

    def as_dict(self) -> dict:
        return asdict(self)


# --------------------------------------------------------------------------------------------
# The augmented loop and its H2 cost
# --------------------------------------------------------------------------------------------


def _augmented(plant: H2Plant, st: AsRunSettings):
    """``(A_a, B_a, C, B_w,a, Q_a)`` of the module docstring on the design states."""
    model = plant.model
    n = plant.nx
    if st.equilibrium_tau is None:
        return plant.A, plant.B, np.eye(n), plant.Bw, plant.Q
    tau = float(st.equilibrium_tau)
    A = np.zeros((n + 1, n + 1))
    A[:n, :n] = plant.A
    A[n, n] = -1.0 / tau
    names = list(plant.state_names)
    Bw = np.vstack([plant.Bw, np.zeros((1, plant.Bw.shape[1]))])
    if model.m > 0:
        A[n, names.index("v_-1")] = 1.0 / tau
    elif "v_h" in plant.w_names:  # the head-velocity noise drives the estimate
        Bw[n, list(plant.w_names).index("v_h")] = plant.weights.head / tau
    B = np.vstack([plant.B, [[0.0]]])
    E = estimator_shift(model)[plant.keep]
    C = np.hstack([np.eye(n), -E.reshape(-1, 1)])
    Q = np.zeros((n + 1, n + 1))
    Q[:n, :n] = plant.Q
    return A, B, C, Bw, Q


def output_cost(aug, r: float, g: np.ndarray):
    """``(J, L, P)`` of ``u = g C xi`` on the augmented loop (``inf, None, None`` if unstable)."""
    A, B, C, Bw, Q = aug
    K = np.atleast_2d(np.asarray(g, float)) @ C  # a row per CAV (one CAV: one row)
    AK = A + B @ K
    if np.max(np.linalg.eigvals(AK).real) >= -STABILITY_TOL:
        return math.inf, None, None
    L = sla.solve_continuous_lyapunov(AK, -Bw @ Bw.T)
    Qk = Q + r * (K.T @ K)
    P = sla.solve_continuous_lyapunov(AK.T, -Qk)
    J = float(np.trace(Qk @ (0.5 * (L + L.T))))
    if not math.isfinite(J) or J < 0:
        return math.inf, None, None
    return J, 0.5 * (L + L.T), 0.5 * (P + P.T)


def _directions(aug, r, g, L, P, mask):
    A, B, C, _, _ = aug
    CLC = C @ L @ C.T
    if np.ndim(g) == 2:  # a platoon: a row per CAV (fixed equilibrium, C = I)
        return _row_directions(r, g, CLC, B.T @ P @ L @ C.T, mask)
    BPLC = (B.T @ P @ L @ C.T).ravel()
    grad = 2.0 * (r * g @ CLC + BPLC)
    grad = np.where(mask, grad, 0.0)
    idx = np.flatnonzero(mask)
    d = np.zeros_like(g)
    try:
        d[idx] = np.linalg.solve(r * CLC[np.ix_(idx, idx)].T, -BPLC[idx]) - g[idx]
    except np.linalg.LinAlgError:
        pass
    return grad, d


def _row_directions(r, G, CLC, BPLC, mask):
    """:func:`_directions` of a gain with a row per CAV: the gradient ``2 (r G CLC + BPLC)``
    and the Anderson-Moore step row by row (``R = r I``)."""
    grad = np.where(mask, 2.0 * (r * G @ CLC + BPLC), 0.0)
    d = np.zeros_like(G)
    for k in range(G.shape[0]):
        idx = np.flatnonzero(mask[k])
        try:
            d[k, idx] = np.linalg.solve(r * CLC[np.ix_(idx, idx)].T, -BPLC[k, idx]) - G[k, idx]
        except np.linalg.LinAlgError:
            continue
    return grad, d


def _polish(aug, r, g0, mask, accept, steps: int, tol: float = 1e-7):
    """Output-feedback descent on ``J`` (Anderson-Moore step, then the gradient; Armijo) that
    accepts only steps ``accept`` holds for. Returns ``(g, J, iterations)``."""
    g = np.where(mask, np.asarray(g0, float), 0.0)
    J, L, P = output_cost(aug, r, g)
    if not math.isfinite(J):
        raise SynthesisError("as-run polish needs a stabilising initial gain")
    it = 0
    for it in range(1, steps + 1):  # noqa: B007
        grad, am = _directions(aug, r, g, L, P, mask)
        if np.linalg.norm(grad) <= tol * max(1.0, J):
            break
        found = False
        for d in (am, -grad):
            slope = float(grad.ravel() @ d.ravel())
            if not slope < 0:
                continue
            t, refused = 1.0, 0
            for _ in range(30):
                trial = g + t * d
                Jt, Lt, Pt = output_cost(aug, r, trial)
                if Jt <= J + 1e-4 * t * slope:
                    if accept(trial):
                        found = True
                        break
                    refused += 1
                    if refused > 8:
                        break
                t *= 0.5
            if found:
                break
        if not found:
            break
        rel = (J - Jt) / max(J, 1e-300)
        g, J, L, P = trial, Jt, Lt, Pt
        if rel < tol**2:
            break
    return g, J, it


# --------------------------------------------------------------------------------------------
# String stability as run
# --------------------------------------------------------------------------------------------


def _law(plant: H2Plant, g):
    return law_of_gains(plant.model, plant.gains(g))


def as_run_check(plant: H2Plant, g: np.ndarray, st: AsRunSettings):
    """:class:`~lcc_synth.analysis.as_run.AsRunReport` of design gain ``g`` on the exact loop."""
    loop = as_run_loop(
        plant.model, _law(plant, g), st.period, st.latency, st.equilibrium_tau,
        st.measurement_filter,
    )  # fmt: skip
    return as_run_report(loop)


_GRID = np.logspace(-3, math.log10(3.0), 421)


def amplification(plant: H2Plant, g: np.ndarray, st: AsRunSettings) -> float:
    """``A(g)`` of the module docstring (``inf`` when the continuous as-run loop is unstable)."""
    loop = as_run_loop(
        plant.model, _law(plant, g), None, 0.0, st.equilibrium_tau, st.measurement_filter
    )
    if np.max(np.linalg.eigvals(loop.A).real) >= -STABILITY_TOL:
        return math.inf
    mag2 = np.abs(loop.response(_GRID)) ** 2
    return float(np.mean(np.maximum(mag2 - 1.0, 0.0) ** 2))


def _tradeoff(plant, aug, mask, g0, st):
    from scipy.optimize import minimize

    idx = np.flatnonzero(mask)
    J0 = output_cost(aug, plant.r, g0)[0]

    def full(x):
        g = np.zeros(plant.nx)
        g[idx] = x
        return g

    def f(x):
        g = full(x)
        J = output_cost(aug, plant.r, g)[0]
        if not math.isfinite(J):
            return 1e6
        a = amplification(plant, g, st)
        return J / J0 + st.weight * a if math.isfinite(a) else 1e6

    res = minimize(f, g0[idx], method="L-BFGS-B", options={"maxiter": 200, "eps": 1e-7})
    g = full(res.x)
    return g if math.isfinite(output_cost(aug, plant.r, g)[0]) else g0


def check_platoon(ring: bool, st: AsRunSettings) -> None:
    """Refuse what the as-run design of a platoon (``ring``: a ring) cannot run (see the
    module docstring).

    Raises
    ------
    ConfigError
        ``synthesis.as_run`` on a ring (no head vehicle, no head-to-tail loop);
        ``synthesis.as_run.equilibrium`` = "estimated" on a platoon (the simulator has no
        per-CAV equilibrium estimator); ``synthesis.as_run.weight`` > 0 on a platoon (the
        trade-off step is of one CAV's loop).
    """
    if ring:
        raise ConfigError("synthesis.as_run", "needs a head vehicle: kind = 'ring' has none (no "
                          "head-to-tail loop to check as run); use kind = 'platoon' or drop "
                          "[synthesis.as_run]")  # fmt: skip
    if st.equilibrium_tau is not None:
        raise ConfigError("synthesis.as_run.equilibrium", 'must be "fixed" on a platoon: the '
                          "simulator has no per-CAV equilibrium estimator (a platoon's "
                          "controllers run with the fixed v*)")  # fmt: skip
    if st.weight > 0:
        raise ConfigError("synthesis.as_run.weight", f"must be 0 on a platoon, got "
                          f"{st.weight:g}: the trade-off step is of one CAV's loop (the "
                          "polish from a gain string stable as run works on platoons)")  # fmt: skip


def as_run_note(st: AsRunSettings, info: dict) -> str:
    """The report's note on a design :func:`as_run_design` left NOT string stable as run."""
    after = info["after"]
    note = ("as run (" + ("estimated" if st.equilibrium_tau else "fixed")
            + f" equilibrium, period {st.period:g} s): NOT string stable "
            f"(peak |Gamma| {after['gamma_peak']:.4f}, margin {after['margin']:.3g}); no "
            "step could be accepted")  # fmt: skip
    tried = info.get("fallback")
    if tried:  # a platoon's string LMI start: failed, or not string stable as run either
        note += ("; the string LMI start: " + tried["error"] if "error" in tried else
                 f"; nor the string LMI start (peak |Gamma| {tried['gamma_peak']:.4f} as run)")
    return note


def as_run_design(
    plant: H2Plant | PlatoonPlant,
    mask: np.ndarray,
    g0: np.ndarray,
    st: AsRunSettings,
    fallback: Callable[[], np.ndarray] | None = None,
):
    """The design of the module docstring from the structured H2 gain ``g0``.

    ``plant``: one CAV (``g0``, ``mask`` on the design states) or an open platoon (``n_cav x
    nx``, a row per CAV; fixed equilibrium, no trade-off: :func:`check_platoon`). A platoon of
    one CAV runs on its one row, the computation of the ``kind = "lcc"`` string it is.
    ``fallback``: called when ``g0`` is not string stable as run with the margin; its gain (on
    the pattern) starts the polish instead if it is (the platoon's string LMI gain; a
    :class:`SynthesisError` it raises is reported, not raised).

    Returns ``(g, info)``; ``info`` holds the settings, the as-run reports before and after,
    the H2 norms (augmented loop; ``h2_before`` is ``g0``'s), whether the polish ran and the
    timings; with a ``fallback`` also ``start`` (``"design"`` or ``"fallback"``) and
    ``fallback`` (its as-run report, or the error that stopped it; ``None`` if not needed).

    Raises
    ------
    ConfigError
        ``fd_lcc`` (no head vehicle) and the refusals of :func:`check_platoon`.
    """
    if plant.model.kind == "fd_lcc":
        raise ConfigError("synthesis.as_run", "needs a head vehicle (not fd_lcc)")
    shape = np.shape(g0)  # (a platoon's refusals, check_platoon: when its spec is read)
    if len(shape) == 2 and shape[0] == 1:  # one row: one CAV's computation
        g0, mask = np.ravel(g0), np.ravel(mask)
    t0 = time.perf_counter()
    aug = _augmented(plant, st)
    mask = np.asarray(mask, bool)
    before = as_run_check(plant, g0, st)
    g = g0 if st.weight <= 0 else _tradeoff(plant, aug, mask, g0, st)
    t_trade = time.perf_counter() - t0
    rep = as_run_check(plant, g, st)
    start, tried = "design", None
    if fallback is not None and not (rep.string_stable and rep.margin >= st.margin):
        try:
            g1 = np.where(mask, np.reshape(fallback(), mask.shape), 0.0)
        except SynthesisError as err:
            tried = {"error": str(err)}
        else:
            r1 = as_run_check(plant, g1, st)
            tried = r1.as_dict()
            if r1.string_stable and r1.margin >= st.margin:
                g, rep, start = g1, r1, "fallback"
    polished = False
    iters = 0
    if rep.string_stable and rep.margin >= st.margin:

        def accept(trial):
            r = as_run_check(plant, trial, st)
            return bool(r.string_stable and r.margin >= st.margin)

        g, _, iters = _polish(aug, plant.r, g, mask, accept, st.polish_steps)
        rep = as_run_check(plant, g, st)
        polished = True
    info = {
        "settings": st.as_dict(),
        "before": before.as_dict(),
        "after": rep.as_dict(),
        "string_stable": bool(rep.string_stable and rep.margin >= st.margin),
        "h2_before": math.sqrt(output_cost(aug, plant.r, g0)[0]),
        "h2_after": math.sqrt(output_cost(aug, plant.r, g)[0]),
        "polished": polished,
        "polish_iterations": iters,
        "timings": {"tradeoff": t_trade, "total": time.perf_counter() - t0},
    }
    if fallback is not None:
        info["start"], info["fallback"] = start, tried
    return np.reshape(g, shape), info
