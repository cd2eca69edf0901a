"""Dynamic structured synthesis on the loop as it runs: the gain *and* the controller's dynamics.

:mod:`lcc_synth.synthesis.as_run` designs the static gain with the estimator, the filter and
the sample time held fixed. Here they are design variables too. The controller is the one the
simulator runs (:class:`~lcc_synth.controllers.static.StaticGainController`, equilibrium
"estimated"): the static gain ``g`` on its pattern, the time constant ``tau`` of the
equilibrium estimate, the time constant ``tau_f`` of the filter on every received value, and
the sample time ``T`` from a set of candidates. The loop is that of
:func:`lcc_synth.analysis.as_run.as_run_loop` (exact ZOH plant, estimator, filter, V2V delay
line), and its head-to-tail response ``|Gamma(e^{j w T})|`` is evaluated on a log grid over
``[1e-3, 3]`` rad/s in one vectorised Hessenberg solve per loop.

Problem
-------
``minimise J(x) = H2(x)`` subject to ``max_w |Gamma_l(w)| <= bound`` at every latency ``l``
(0 and 0.1 s) and closed-loop stability at every latency, with
``x = (g on the pattern, log tau, log tau_f)`` in the box ``tau in [0.1, 100]`` s,
``tau_f in [0.01, 5]`` s; ``H2`` is :func:`lcc_synth.analysis.as_run_h2.as_run_h2` of the
continuous-limit as-run loop (estimator and filter included) from the design's acceleration
noise to its weighted states and command. The sampled-data H2 of the same loop (also
:func:`as_run_h2`) costs 20-50 times more per evaluation and differs little: for the
showcase's h2 on string10 (estimate 1 s, filter 0.3 s) 7.290 at ``T = 0.01`` s and 7.314 at
``T = 0.1`` s; the reports give it for the chosen design. ``bound = 1`` asks for string
stability; the verdict is then decided on the exact loop by
:func:`~lcc_synth.analysis.as_run.as_run_report` (the grid is only the search's measure).
The sample time is a discrete choice: a latency that is not a multiple of ``T`` has no exact
loop (:class:`~lcc_synth.analysis.as_run.NotRepresentable`), so the candidates must divide
every latency; each candidate is searched on its own.

Method of the dynamic design
----------------------------
Non-smooth optimisation of a fixed-structure controller from many starts, in the spirit of
hinfstruct / systune: the peak of ``|Gamma|`` is a max over frequencies (not differentiable
where the arg max jumps), and gradients with respect to ``tau`` and ``tau_f`` would mean
differentiating the exact sampled loop (ZOH, filter, delay line); with 8 variables and 26 ms
per evaluation a derivative-free search is affordable. So: scipy's Nelder-Mead (adaptive
simplex) on the quadratic penalty ``J / J_0 + rho sum_l max(0, peak_l - bound)^2`` (``rho =
1e3``; with ``gap_bound`` also ``rho max(0, gap / gap_max - 1)^2``; the box and an unstable
loop give a constant barrier value). The feasible-direction descent of
:mod:`lcc_synth.synthesis.as_run` needs the dynamics fixed (its gradient is that of a static
output feedback) and cannot move ``tau``, ``tau_f``, ``T``. :func:`lowest_peak` minimises
``max_l peak_l`` itself from the same starts: the lowest peak the structure reaches (the
certificate when no design meets the bound). Starts: the given design and ``starts - 1``
random ones (each gain scaled by a log-uniform factor in [1/3, 3], ``tau`` and ``tau_f``
log-uniform in their box; a start whose loop is unstable is counted and skipped).

Measured (string10 of the showcase, pattern CAV + HDVs 1, 2, "replace", ``T = 0.1`` s,
240 frequencies; ``benchmarks/bench_as_run_dynamics.py``): one evaluation (two sampled loops
of 28 and 33 states, the continuous H2 and gap response) 26 ms of CPU; the exact verdicts of
both loops about 0.1-0.2 s, the sampled-data H2 66 ms. ``examples/as_run_front.py --starts 3
--maxfev 300 --cert-starts 8``: 2291 evaluations for the 8-start lowest-peak search.

Results (``examples/as_run_front.py``, bounds 1.12 / 1.08 / 1.04 / 1) and the certificate
-----------------------------------------------------------------------------------------
Today's h2 (estimate 1 s, filter 0.3 s, every 0.01 s): peak 1.161 / 1.169 (latency 0 / 0.1 s).
Every design drives the filter to its lower bound (0.01-0.04 s; its phase lag amplifies) and
the estimate to 1.2-2.2 s. Peaks are of the exact verdict (:func:`as_run_report`).

* H2 with the peak bound alone: 1.112 / 1.116 (no AEB; head_brake AAVE +1.0 %, min gap
  4.4 m instead of 9.0 m), 1.078 / 1.080 (AEB 92 steps in heterogeneous), 1.039 / 1.040 and
  1.003 / 1.003 (AEB in both). The lowest peak from 8 starts is 1.0000 at both latencies, the
  verdict "boundary" (peak at 1.4e-5 rad/s): reached only as the CAV gives up its own gap
  (``g_s0 = 3e-6``), with AEB 98 / 154 steps. No start found a strictly string-stable loop.
* With ``gap_bound = 1`` (the CAV's gap response no worse than today's h2): 1.109 / 1.115
  (no AEB; head_brake / heterogeneous AAVE -2.7 % / -4.4 %, fuel -2.8 % / -3.9 %, min gap
  8.7 / 6.4 m, but 0.8 s above ISO 15622's jerk limit in heterogeneous), 1.077 / 1.080
  (heterogeneous fuel +2.7 %, 1.1 s above the jerk limit), 1.039 / 1.041 (heterogeneous AAVE
  +68 %), 1.014 / 1.015 (a collision in heterogeneous). The lowest peak from 8 random starts
  under this bound was 1.061 / 1.064; the warm-started front reached 1.015.

The sample time was held at 0.1 s in these searches: the chosen design (1.109 / 1.115) run
every 0.01 / 0.02 / 0.05 s peaks at 1.107 / 1.108 / 1.110 (latency 0.1 s), so faster sampling
lowers the peak by < 0.01 and changes none of the verdicts.

So the structure (static gain on CAV + HDVs 1, 2, first-order estimate, first-order filter)
reaches string stability as run only at its boundary and only without its own gap; with the
gap kept, no design found is string stable, and those below 1.08 lose the heterogeneous case.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from lcc_synth.analysis.as_run import (
    AsRunLoop,
    AsRunReport,
    NotRepresentable,
    as_run_loop,
    as_run_report,
    law_of_gains,
)
from lcc_synth.analysis.as_run_h2 import as_run_h2
from lcc_synth.analysis.transfer import hessenberg_solver
from lcc_synth.errors import ConfigError
from lcc_synth.synthesis.h2 import H2Plant

__all__ = [
    "DynamicsSettings",
    "AsRunPoint",
    "DynamicDesign",
    "gap_response",
    "evaluate_point",
    "design_dynamics",
    "lowest_peak",
]

_BARRIER = 1e6  # objective value of an unstable loop or a point outside the box


@dataclass(frozen=True)
class DynamicsSettings:
    """Settings of the search (module docstring).

    Attributes
    ----------
    sample_times : tuple of float
        Candidate controller periods (s), each > 0 and dividing every latency.
    latencies : tuple of float
        V2V latencies (s, >= 0) at which the loop must meet the bound.
    tau_bounds, filter_bounds : (float, float)
        Boxes of the estimator's and the filter's time constants (s), ``0 < lo < hi``.
    omega : (float, float)
        Frequency band (rad/s) of the peak, ``0 < lo < hi``; ``points`` log-spaced frequencies.
    starts : int
        Starts of the search (>= 1), the given design first.
    maxfev : int
        Objective evaluations per start (>= 10).
    seed : int
        Seed of the random starts.
    penalty : float
        ``rho`` of the quadratic penalty (> 0).
    gap_bound : float or None
        Bound on the CAV's gap response as a multiple of the first start's (>= 1; ``None``:
        none): ``max_w |s_0(jw) / v_h(jw)|`` of the continuous-limit loop, the spacing the CAV
        gives up per m/s of a head speed change (a head brake's minimum gap).
    """

    sample_times: tuple[float, ...] = (0.1,)
    latencies: tuple[float, ...] = (0.0, 0.1)
    tau_bounds: tuple[float, float] = (0.1, 100.0)
    filter_bounds: tuple[float, float] = (0.01, 5.0)
    omega: tuple[float, float] = (1e-3, 3.0)
    points: int = 240
    starts: int = 8
    maxfev: int = 600
    seed: int = 0
    penalty: float = 1e3
    gap_bound: float | None = None

    def __post_init__(self) -> None:
        def bad(name: str, rng: str, value) -> ConfigError:
            return ConfigError(f"as_run_dynamics.{name}", f"must be {rng}, got {value!r}")

        lats = tuple(self.latencies)
        if not lats or not all(math.isfinite(x) and x >= 0 for x in lats):
            raise bad("latencies", "a non-empty list of seconds >= 0", self.latencies)
        ts = tuple(self.sample_times)
        if not ts or not all(math.isfinite(x) and x > 0 for x in ts):
            raise bad("sample_times", "a non-empty list of seconds > 0", self.sample_times)
        for T in ts:
            for lat in lats:
                r = lat / T
                if abs(r - round(r)) > 1e-9 * max(1.0, r):
                    raise ConfigError(
                        "as_run_dynamics.sample_times",
                        f"{T:g} s does not divide the latency {lat:g} s: use a sample time "
                        "that does (the loop has no exact model otherwise)",
                    )
        for name in ("tau_bounds", "filter_bounds", "omega"):
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
                raise bad(name, "a pair (lo, hi) with 0 < lo < hi", getattr(self, name))
        for name, lo in (("points", 10), ("starts", 1), ("maxfev", 10)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise bad(name, f"an integer >= {lo}", v)
        if not (math.isfinite(self.penalty) and self.penalty > 0):
            raise bad("penalty", "a number > 0", self.penalty)
        gb = self.gap_bound
        if gb is not None and not (math.isfinite(gb) and gb >= 1.0):
            raise bad("gap_bound", "a multiple >= 1 of the first start's gap response", gb)

    @property
    def grid(self) -> np.ndarray:
        lo, hi = self.omega
        return np.logspace(math.log10(lo), math.log10(hi), self.points)


@dataclass(frozen=True)
class AsRunPoint:
    """One controller of the structure and its as-run figures.

    ``gains``: the gain on its pattern by state name; ``peaks`` / ``peak_omegas``: the grid
    peak of ``|Gamma|`` and its frequency (rad/s) at each latency of the settings; ``h2``: the
    continuous-limit as-run H2 norm (``inf`` if unstable); ``gap_peak``: ``max_w |s_0 / v_h|``
    (s) of the continuous-limit loop on the grid.
    """

    gains: dict[str, float]
    equilibrium_tau: float
    measurement_filter: float
    sample_time: float
    latencies: tuple[float, ...]
    peaks: tuple[float, ...]
    peak_omegas: tuple[float, ...]
    h2: float
    gap_peak: float = math.nan

    @property
    def peak(self) -> float:
        """The largest peak over the latencies."""
        return max(self.peaks)

    def controller_table(self, semantics: str = "replace", kind: str = "cf_lcc") -> dict:
        """The ``[controllers.NAME]`` table (type "static") of this controller."""
        return {
            "type": "static", "kind": kind, "semantics": semantics,
            "gains": dict(self.gains), "equilibrium": "estimated",
            "equilibrium_tau": self.equilibrium_tau,
            "measurement_filter": self.measurement_filter, "sample_time": self.sample_time,
        }  # fmt: skip


@dataclass(frozen=True)
class DynamicDesign:
    """Result of a search: the best point, the exact verdicts and what the search cost.

    ``reports``: :class:`~lcc_synth.analysis.as_run.AsRunReport` at each latency (exact grid
    method); ``h2_sampled``: the sampled-data H2 of the latency-0 loop; ``bound``: the peak
    bound of the search (``None`` for :func:`lowest_peak`); ``starts``: the starts run,
    ``unstable_starts`` those skipped; ``history``: ``(start, objective)`` of every start.
    """

    point: AsRunPoint
    reports: tuple[AsRunReport, ...]
    h2_sampled: float | None
    bound: float | None
    starts: int
    unstable_starts: int
    evaluations: int
    seconds: float
    history: list[tuple[int, float]] = field(default_factory=list)

    @property
    def string_stable(self) -> bool:
        """String stable (exact verdict) at every latency."""
        return all(r.string_stable for r in self.reports)


# --------------------------------------------------------------------------------------------
# Evaluation
# --------------------------------------------------------------------------------------------


def _pattern(plant: H2Plant, mask: np.ndarray) -> np.ndarray:
    idx = np.flatnonzero(np.asarray(mask, bool))
    if idx.size == 0:
        raise ConfigError("pattern", "needs at least one gain entry")
    return idx


def _loops(plant: H2Plant, g: np.ndarray, tau: float, tf: float, T: float | None, lats):
    law = law_of_gains(plant.model, plant.gains(g))
    return [as_run_loop(plant.model, law, T, lat, tau, tf) for lat in lats]


def gap_response(loop: AsRunLoop, omega) -> np.ndarray:
    """``s_0(jw) / v_h(jw)`` (s) of a continuous-limit loop (``sample_time = None``): the CAV's
    spacing error per m/s of head velocity. With the equilibrium estimated it tends to the
    slope ``s_e'(v*)`` of the equilibrium spacing as ``w -> 0`` (the CAV settles at its new
    equilibrium gap)."""
    if loop.sample_time is not None:
        raise ConfigError("loop", "the gap response is of the continuous-limit loop")
    c = np.zeros(loop.A.shape[0])
    c[loop.states.index("s_0")] = 1.0
    return hessenberg_solver(loop.A, loop.h, c)(1j * np.asarray(omega, float))


def evaluate_point(
    plant: H2Plant,
    gains: np.ndarray,
    equilibrium_tau: float,
    measurement_filter: float,
    sample_time: float,
    settings: DynamicsSettings | None = None,
) -> AsRunPoint | None:
    """The :class:`AsRunPoint` of design gain ``gains`` (on ``plant``'s states) with the given
    dynamics, or ``None`` when the loop is unstable at a latency."""
    st = settings or DynamicsSettings()
    g = np.asarray(gains, float)
    w = st.grid
    peaks, at = [], []
    for loop in _loops(plant, g, equilibrium_tau, measurement_filter, sample_time,
                       st.latencies):  # fmt: skip
        if np.max(np.abs(np.linalg.eigvals(loop.A))) >= 1.0 - 1e-9:
            return None
        mag = np.abs(loop.response(w))
        k = int(np.argmax(mag))
        peaks.append(float(mag[k]))
        at.append(float(w[k]))
    (cont,) = _loops(plant, g, equilibrium_tau, measurement_filter, None, (0.0,))
    h2 = as_run_h2(cont, plant.Bw, plant.Q, plant.r)
    if h2 is None or not math.isfinite(h2):
        return None
    gap = float(np.max(np.abs(gap_response(cont, w))))
    names = plant.state_names
    return AsRunPoint(
        {names[i]: float(g[i]) for i in np.flatnonzero(g)}, float(equilibrium_tau),
        float(measurement_filter), float(sample_time), tuple(st.latencies), tuple(peaks),
        tuple(at), float(h2), gap,
    )  # fmt: skip


# --------------------------------------------------------------------------------------------
# Search
# --------------------------------------------------------------------------------------------


def _starts(idx, g0, tau0, tf0, st: DynamicsSettings, extra):
    rng = np.random.default_rng(st.seed)
    first = [np.r_[g0[idx], math.log(tau0), math.log(tf0)]]
    first += [np.asarray(x, float) for x in extra]
    (tl, th), (fl, fh) = st.tau_bounds, st.filter_bounds
    out = list(first)
    while len(out) < st.starts + len(extra):
        scale = np.exp(rng.uniform(-math.log(3.0), math.log(3.0), idx.size))
        out.append(np.r_[g0[idx] * scale, rng.uniform(math.log(tl), math.log(th)),
                         rng.uniform(math.log(fl), math.log(fh))])  # fmt: skip
    return out


def _search(plant, mask, g0, tau0, tf0, st, bound, extra=()):
    from scipy.optimize import minimize

    t0 = time.perf_counter()
    idx = _pattern(plant, mask)
    g0 = np.asarray(g0, float)
    lo = np.log([st.tau_bounds[0], st.filter_bounds[0]])
    hi = np.log([st.tau_bounds[1], st.filter_bounds[1]])
    nfev = [0]

    def point(x, T):
        if np.any(x[-2:] < lo - 1e-12) or np.any(x[-2:] > hi + 1e-12):
            return None
        g = np.zeros(plant.nx)
        g[idx] = x[:-2]
        nfev[0] += 1
        try:
            return evaluate_point(plant, g, math.exp(x[-2]), math.exp(x[-1]), T, st)
        except (np.linalg.LinAlgError, NotRepresentable, ValueError):
            return None

    first = point(np.r_[g0[idx], math.log(tau0), math.log(tf0)], st.sample_times[0])
    if first is None:
        raise ConfigError("as_run_dynamics", "the initial controller's as-run loop is unstable: "
                          "start from a stabilising design")  # fmt: skip
    J0 = first.h2
    gap_max = None if st.gap_bound is None else st.gap_bound * first.gap_peak

    def objective(x, T):
        p = point(x, T)
        if p is None:
            return _BARRIER
        gap = 0.0 if gap_max is None else max(0.0, p.gap_peak / gap_max - 1.0) ** 2
        if bound is None:
            return p.peak + st.penalty * gap
        excess = gap + sum(max(0.0, pk - bound) ** 2 for pk in p.peaks)
        return p.h2 / J0 + st.penalty * excess

    best, best_f, unstable, history, k = None, math.inf, 0, [], 0
    for T in st.sample_times:
        for x0 in _starts(idx, g0, tau0, tf0, st, extra):
            k += 1
            if objective(x0, T) >= _BARRIER:
                unstable += 1
                continue
            res = minimize(objective, x0, args=(T,), method="Nelder-Mead", options={
                "maxfev": st.maxfev, "xatol": 1e-5, "fatol": 1e-8, "adaptive": True})
            history.append((k, float(res.fun)))
            if res.fun < best_f:
                best, best_f = (res.x.copy(), T), float(res.fun)
    if best is None:
        raise ConfigError("as_run_dynamics.starts", "every start was unstable: raise starts")
    p = point(*best)
    g = np.zeros(plant.nx)
    g[idx] = best[0][:-2]
    loops = _loops(plant, g, p.equilibrium_tau, p.measurement_filter, p.sample_time,
                   st.latencies)  # fmt: skip
    reports = tuple(as_run_report(loop) for loop in loops)
    h2s = as_run_h2(loops[0], plant.Bw, plant.Q, plant.r) if st.latencies[0] == 0 else None
    return DynamicDesign(p, reports, h2s, bound, k, unstable, nfev[0],
                         time.perf_counter() - t0, history)  # fmt: skip


def design_dynamics(
    plant: H2Plant,
    mask: np.ndarray,
    gains: np.ndarray,
    equilibrium_tau: float,
    measurement_filter: float,
    bound: float,
    settings: DynamicsSettings | None = None,
    extra_starts=(),
) -> DynamicDesign:
    """Minimise the as-run H2 cost subject to ``peak <= bound`` at every latency.

    Parameters
    ----------
    plant : H2Plant
        The design plant (:func:`lcc_synth.synthesis.h2.make_plant`; its model has a head).
    mask : array of bool
        The gain's pattern on ``plant``'s states.
    gains, equilibrium_tau, measurement_filter : the first start (a stabilising controller).
    bound : float
        Bound on the grid peak of ``|Gamma|`` (>= 1; 1 asks for string stability).
    settings : DynamicsSettings, optional
    extra_starts : sequence of arrays
        More starts ``(g on the pattern, log tau, log tau_f)``, e.g. a neighbour of the front.

    Raises
    ------
    ConfigError
        A bound below 1, an unstable first start, every start unstable.
    """
    if not (math.isfinite(bound) and bound >= 1.0):
        raise ConfigError("bound", f"must be a peak |Gamma| >= 1 (|Gamma(0)| = 1), got {bound!r}")
    st = settings or DynamicsSettings()
    return _search(plant, mask, gains, equilibrium_tau, measurement_filter, st, float(bound),
                   extra_starts)  # fmt: skip


def lowest_peak(
    plant: H2Plant,
    mask: np.ndarray,
    gains: np.ndarray,
    equilibrium_tau: float,
    measurement_filter: float,
    settings: DynamicsSettings | None = None,
) -> DynamicDesign:
    """The lowest ``max_l peak_l`` the structure reaches from ``settings.starts`` starts (the
    certificate of the module docstring); arguments as :func:`design_dynamics`."""
    st = settings or DynamicsSettings()
    return _search(plant, mask, gains, equilibrium_tau, measurement_filter, st, None)
