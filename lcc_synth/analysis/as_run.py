"""The loop as it runs: plant, equilibrium estimator, sample-and-hold, V2V latency, filter.

:mod:`lcc_synth.analysis.string_stability` analyses the bare gain ``u = K x`` in continuous
time. The simulator runs more than that (:class:`~lcc_synth.controllers.static.LinearLaw`):

* the whole CAV command (its HDV law included, "added" semantics) is computed from the
  *received* measurements at the controller's samples ``t_k = k T`` and held in between
  (zero-order hold); ``T`` is the controller's ``sample_time``, or the simulator step;
* every value the CAV receives over V2V (every vehicle but the CAV itself, the head's velocity
  included) is ``latency`` seconds old; the CAV's own spacing and velocity are exact;
* optionally each received value passes a first-order filter ``tau_f dy_f/dt = y - y_f``
  (``measurement_filter`` seconds; 0 = off), discretised exactly at ``T`` with the received
  value held over the period, as the simulator runs it: the law reads the filter's state, which
  then takes the new value in, ``y_f,k+1 = a y_f,k + (1 - a) y_k``, ``a = e^(-T/tau_f)`` (so
  ``tau_f -> 0`` is one sample of delay, not the unfiltered law);
* with ``equilibrium = "estimated"`` the errors are taken from an estimate ``w = v_hat - v*``
  of the equilibrium velocity, a low-pass of the (received, filtered) velocity ``y`` of the
  vehicle right ahead, updated after it is used: ``w_k+1 = b w_k + (1 - b) y_k``,
  ``b = equilibrium_decay = e^(-T/tau)``. Linearised, every spacing error becomes
  ``s_i - s_e'(v*) w`` and every velocity error ``v_i - w`` (``s_e' = (a2 - a3) / a1``, the
  slope of the nominal HDV's equilibrium spacing: ``F(s_e(v), 0, v) = 0``); the HDV law is
  not shifted (it acts on raw spacings and speeds). The clipping of ``v_hat`` is inactive
  near ``v*``.

:func:`as_run_loop` builds that loop exactly, as a linear discrete-time system on
``xi = [x, w, y_f, delay line]`` driven by the head velocity ``v_h`` at the samples: the plant
is discretised exactly with ZOH on the command at ``T`` (:func:`lcc_synth.models.platoon.
discretize`), the head velocity enters it with a first-order hold (linear between samples;
``x = zeta + Lam v_h`` makes that causal, with a feed-through ``d = c Lam`` to the tail), and
a latency of ``d T`` is ``d`` copies of the received vector (a shift register). A latency
that is not a multiple of ``T`` is refused (:class:`NotRepresentable`): the caller says so
and measures instead. ``T = None`` gives the continuous-time limit (the law evaluated
continuously, no latency).

Frequency response and verdict
------------------------------
``Gamma(e^{j w T}) = c (e^{j w T} I - Phi)^-1 gamma + d``: tail velocity over head velocity at
the samples. The verdict reuses :func:`~lcc_synth.analysis.string_stability.
loop_string_stability` on the bilinear (Tustin) image ``z = (1 + s T/2) / (1 - s T/2)``:
the unit circle maps onto the imaginary axis with ``nu = (2/T) tan(w T/2)``, so
``|Gamma_c(j nu)| = |Gamma_d(e^{j w T})|`` exactly, the disc onto the left half plane
(plant stability preserved), ``z = 1`` onto ``s = 0`` (the double zero of
``|Gamma|^2 - 1`` at ``w = 0`` that the decision function removes stays there). The supremum,
the margin ``-max q`` (``q`` is a function of the transfer function only, so reparametrising
the frequency does not change its maximum) and the verdict are therefore those of the
discrete loop; only the frequencies are mapped back, ``w = (2/T) arctan(nu T / 2)``. The image
has a feed-through (``loop_string_stability(..., d=)``). This reuses the band, the exact
``w = 0`` treatment and the calibrated grid search instead of duplicating them on the circle.

What the first-order hold of the head costs: a sine is not piecewise linear; the error is
``O((w T)^2 / 12)`` (< 1e-4 at ``w = 0.3``, ``T = 0.1``). A zero-order hold of the head (its
delay ``T/2`` against the measured head) was 0.1-0.3 % off the simulator at ``T = 0.1``.

Several CAVs: an open platoon
-----------------------------
The same function builds the loop of every CAV of an open platoon (``kind = "platoon"``, a
:class:`~lcc_synth.models.platoon.PlatoonModel`): the law has a row per CAV, every CAV samples
at the same ``T`` with the same latency and filter (the settings are scalars) and holds its
own command; the plant's ``B`` has a column per CAV. As the simulator runs it
(:mod:`lcc_synth.simulation.kernels`), every CAV's own spacing and velocity are exact to every
CAV (the CAVs are connected), every other received value (the HDVs', the head's velocity) is
one copy, delayed and filtered once, whichever CAV reads it; the output is the tail's
velocity. The equilibrium estimate is one CAV's (its predecessor's velocity): a platoon's
controllers run with a fixed equilibrium, so ``equilibrium_tau`` on a platoon is a
ConfigError naming it. A ring has no head vehicle: ConfigError naming ``system.kind``.
Measured (tests/test_as_run_platoon.py): a platoon with one CAV gives the paper's one-CAV
loop (``kind = "lcc"``) entry for entry; the continuous loop is the platoon's closed loop
(:func:`~lcc_synth.analysis.string_stability.gains_string_stability`: the same peak and
margin); on a two-CAV platoon of 6 with ``T = 0.1`` s, 0.2 s latency and a 0.3 s filter the
simulator's tail/head ratio at ``dt = 0.01`` s is within 5.3e-5, 2.1e-4, 2.2e-3 of ``|Gamma|`` at
0.05, 0.1, 0.3 rad/s (Euler's first-order error, halved at ``dt / 2``; Richardson
extrapolation 7e-5). The loop of the showcase's ``platoon8`` (8 vehicles, CAVs 3 and 6,
``T = 0.05`` s) builds and is decided in 0.04 s.

H2 norm: :func:`lcc_synth.analysis.as_run_h2.as_run_h2` (one CAV).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg as sla

from lcc_synth.analysis.string_stability import StringStabilityReport, loop_string_stability
from lcc_synth.analysis.transfer import check_head, hessenberg_solver
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains, cav_feedback, hdv_law
from lcc_synth.models.linear import LCCModel, discretize
from lcc_synth.models.platoon import PLATOON_KINDS, PlatoonModel, hdv_law_rows

__all__ = [
    "NotRepresentable",
    "LoopLaw",
    "AsRunLoop",
    "AsRunReport",
    "equilibrium_slope",
    "estimator_shift",
    "law_of_gains",
    "law_of_linear",
    "as_run_loop",
    "law_loop",
    "tustin",
    "as_run_report",
]


class NotRepresentable(ConfigError):
    """The loop has no exact finite-dimensional linear model (e.g. a fractional latency)."""


# --------------------------------------------------------------------------------------------
# The CAV's law on the model's states
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LoopLaw:
    """The CAV's whole command ``u = K x + kh v_h - e w`` on an :class:`LCCModel`'s states,
    or every CAV's on an open platoon's (:class:`~lcc_synth.models.platoon.PlatoonModel`).

    ``K, kh`` include the CAV's HDV law when it drives with it ("added"), which is also given
    alone as ``K_hdv, kh_hdv`` (``None``: no HDV law; the H2 cost weighs the command without
    it, as the design does); ``e`` multiplies the equilibrium estimate ``w = v_hat - v*``
    (:func:`estimator_shift` of the error gains; unused with a fixed equilibrium). One CAV:
    ``K`` of ``nx`` entries and numbers; a platoon: ``K`` (and ``K_hdv``) one row per CAV
    (``model.cavs`` order) and ``kh``, ``kh_hdv`` one entry each (``e`` unused: a platoon runs
    with a fixed equilibrium).
    """

    K: np.ndarray
    kh: float | np.ndarray
    e: float = 0.0
    K_hdv: np.ndarray | None = None
    kh_hdv: float | np.ndarray = 0.0


def equilibrium_slope(model: LCCModel) -> float:
    """``s_e'(v*) = (a2 - a3) / a1`` of the CAV's nominal HDV law (equilibrium spacing slope)."""
    c = model.coefficients[0]
    return (c.alpha2 - c.alpha3) / c.alpha1


def estimator_shift(model: LCCModel) -> np.ndarray:
    """``E`` with ``e = gains @ E``: every spacing error moves by ``s_e' w``, every velocity
    error by ``w`` (on the model's states; ``-p_0`` does not move)."""
    se = equilibrium_slope(model)
    return np.array(
        [se if nm.startswith("s_") else (1.0 if nm.startswith("v_") else 0.0)
         for nm in model.state_names]
    )


def law_of_gains(model: LCCModel | PlatoonModel, gains: Gains) -> LoopLaw:
    """The :class:`LoopLaw` of static gains (eq. 23) on ``model`` (one CAV, or a row per CAV
    of a platoon: :meth:`Gains.input_feedback <lcc_synth.models.feedback.Gains.input_feedback>`
    with each CAV's HDV law, :func:`~lcc_synth.models.platoon.hdv_law_rows`, for "added")."""
    if model.kind in PLATOON_KINDS:
        K, kh = gains.input_feedback(model)
        if gains.semantics == "added":
            K0, kh0 = _platoon_hdv_law(model)
            return LoopLaw(np.asarray(K, float), np.asarray(kh, float), 0.0, K0, kh0)
        return LoopLaw(np.asarray(K, float), np.asarray(kh, float), 0.0)
    K, kh = cav_feedback(model, gains)
    e = float(gains.matrix(model)[0] @ estimator_shift(model))
    if gains.semantics == "added":
        K_law, kh_law = hdv_law(model)
        return LoopLaw(np.asarray(K, float), float(kh), e, K_law, float(kh_law))
    return LoopLaw(np.asarray(K, float), float(kh), e)


def _platoon_hdv_law(model: PlatoonModel) -> tuple[np.ndarray, np.ndarray]:
    """Every CAV's HDV law on an open platoon's states: rows and head-velocity entries (the
    CAV at position 1 follows the head)."""
    kh = np.array([model.coefficients[i - 1].alpha3 if (i == 1 and not model.ring) else 0.0
                   for i in model.cavs])
    return hdv_law_rows(model), kh


def _law_of_rows(model: PlatoonModel, law) -> LoopLaw:
    """:func:`law_of_linear` on an open platoon: ``Ks``, ``Kv`` one row per CAV (or one row
    for every CAV) by vehicle column, column ``i`` = position ``i``, column 0 the head."""
    nc, nv = len(model.cavs), model.platoon.size + 1
    Ks, Kv = (np.atleast_2d(np.asarray(x, float)) for x in (law.Ks, law.Kv))
    if Ks.shape[0] == 1:
        Ks, Kv = np.repeat(Ks, nc, axis=0), np.repeat(Kv, nc, axis=0)
    if Ks.shape != (nc, nv) or Kv.shape != Ks.shape:
        raise ConfigError("law", f"needs {nc} row(s) of {nv} gains per kind of error")
    if np.any(Ks[:, 0] != 0.0):
        raise ConfigError("law", "no gain on the head's spacing (it has none)")
    if np.any(np.asarray(getattr(law, "Kp", 0.0), float) != 0.0):
        raise ConfigError("law", "a platoon has no position state: Kp must be 0")
    K = np.zeros((nc, model.nx))
    K[:, 0::2] = Ks[:, 1:]
    K[:, 1::2] = Kv[:, 1:]
    kh = Kv[:, 0].copy()
    if law.hdv_law:
        K0, kh0 = _platoon_hdv_law(model)
        return LoopLaw(K + K0, kh + kh0, 0.0, K0, kh0)
    return LoopLaw(K, kh, 0.0)


def law_of_linear(model: LCCModel | PlatoonModel, law) -> LoopLaw:
    """The :class:`LoopLaw` of a simulator law (``Ks``, ``Kv`` by vehicle column, ``Kp``,
    ``hdv_law``; :class:`~lcc_synth.controllers.static.LinearLaw`) on ``model`` (one CAV, or
    an open platoon: a row per CAV)."""
    if model.kind in PLATOON_KINDS:
        return _law_of_rows(model, law)
    m = model.m
    K = np.zeros(model.nx)
    Ks = np.asarray(law.Ks, float)
    Kv = np.asarray(law.Kv, float)
    if Ks.shape != (model.m + model.n + 2,) or Kv.shape != Ks.shape:
        raise ConfigError("law", f"needs {model.m + model.n + 2} gains per kind of error")
    if Ks[0] != 0.0:
        raise ConfigError("law", "no gain on the head's spacing (it has none)")
    kh = float(Kv[0])
    for col in range(1, Ks.size):
        i = col - m - 1
        if Ks[col] != 0.0:
            name = "-p_0" if (model.kind == "fd_lcc" and i == 0) else f"s_{i}"
            K[model.index(name)] += Ks[col]
        if Kv[col] != 0.0:
            K[model.index(f"v_{i}")] += Kv[col]
    if getattr(law, "Kp", 0.0):
        K[model.index("-p_0")] += float(law.Kp)
    e = float(K @ estimator_shift(model) + kh)
    if law.hdv_law:
        K_law, kh_law = hdv_law(model)
        return LoopLaw(K + K_law, kh + kh_law, e, K_law, float(kh_law))
    return LoopLaw(K, kh, e)


# --------------------------------------------------------------------------------------------
# The loop
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class AsRunLoop:
    """The closed loop as it runs: ``xi' = A xi + h v_h``, tail velocity ``c xi + d v_h``.

    Discrete-time (``xi_k+1``) when ``sample_time`` is set, else continuous (``dxi/dt``).
    ``u_row, u_v``: the CAV's command ``u = u_row xi + u_v v_h`` (one CAV: a row and a number;
    an open platoon: a row and an entry per CAV); ``u_gain``: the same without the HDV law
    (what the H2 design weighs); ``measured_head``: the law or the estimator reads
    the head's velocity; ``nx``: the plant states come first; ``plant``: the physical plant
    ``(A, B, H)`` (the CAV's HDV law removed); ``settings``: what is in the loop.
    """

    A: np.ndarray
    h: np.ndarray
    c: np.ndarray
    sample_time: float | None
    states: tuple[str, ...]
    u_row: np.ndarray
    u_v: float
    nx: int
    plant: tuple[np.ndarray, np.ndarray, np.ndarray]
    settings: dict = field(default_factory=dict)
    u_gain: tuple[np.ndarray, float] | None = None
    measured_head: bool = False
    d: float = 0.0

    def response(self, omega) -> np.ndarray:
        """``Gamma`` at ``omega`` (rad/s): ``Gamma(e^{j w T})`` or ``Gamma(j w)``."""
        w = np.asarray(omega, dtype=float)
        s = np.exp(1j * w * self.sample_time) if self.sample_time else 1j * w
        return hessenberg_solver(self.A, self.h, self.c)(s) + self.d


def _physical_plant(model: LCCModel | PlatoonModel, actuator_lag: float):
    """``(A, B, H, names, own)`` of the string whose CAVs apply their whole commands ``u``.

    CF-LCC's ``A`` holds the CAV's HDV law (its input is the additional command): it is taken
    out, since the simulator computes the whole command from samples. ``own``: states the CAVs
    measure themselves (exact, not delayed): the CAV's spacing and velocity, and on a platoon
    every CAV's (the simulator gives every CAV the exact values of every CAV,
    :mod:`lcc_synth.simulation.kernels`). The CAVs' actuator lag: with
    ``actuator_lag = tau_a > 0`` a state ``a_i`` (CAV ``i``'s acceleration) is appended per
    CAV, ``dv_i/dt = a_i``, ``tau_a da_i/dt = u_i - a_i``.
    """
    A = np.array(model.A, dtype=float)
    B = np.array(model.B, dtype=float)
    H = np.array(model.H, dtype=float)
    if model.kind == "cf_lcc":
        K_law, kh_law = hdv_law(model)
        A = A - B @ K_law.reshape(1, -1)
        H = H - B * kh_law
    names = list(model.state_names)
    own = np.zeros(model.nx, dtype=bool)
    for cav in model.cavs:
        own[model.block(cav)] = True
    lag = float(actuator_lag)
    if not (math.isfinite(lag) and lag >= 0):
        raise ConfigError("actuator_lag", f"must be a time constant >= 0 s, got {actuator_lag!r}")
    if lag > 0:  # each CAV's velocity row is dv_i/dt = u_i here (no other term): u_i -> a_i
        nx, nc = model.nx, B.shape[1]
        A2 = np.zeros((nx + nc, nx + nc))
        A2[:nx, :nx] = A
        A2[:nx, nx:] = B
        A2[nx:, nx:] = -np.eye(nc) / lag
        B2 = np.zeros((nx + nc, nc))
        B2[nx:, :] = np.eye(nc) / lag
        A, B, H = A2, B2, np.vstack([H, np.zeros((nc, 1))])
        names += [f"a_{cav}" for cav in model.cavs]
        own = np.append(own, np.ones(nc, dtype=bool))
    return A, B, H, tuple(names), own


def _steps(value: float, T: float, what: str) -> int:
    r = value / T
    d = int(round(r))
    if abs(r - d) > 1e-9 * max(1.0, r):
        raise NotRepresentable(
            what,
            f"{value:g} s is not a multiple of the sample time {T:g} s: no exact finite-state "
            "model (measure the loop in the simulator instead)",
        )
    return d


def as_run_loop(
    model: LCCModel | PlatoonModel,
    law: LoopLaw,
    sample_time: float | None = None,
    latency: float = 0.0,
    equilibrium_tau: float | None = None,
    measurement_filter: float = 0.0,
    actuator_lag: float = 0.0,
) -> AsRunLoop:
    """The loop of the module docstring, of one CAV or of every CAV of an open platoon.

    Parameters
    ----------
    model : LCCModel or PlatoonModel
        A model with a head vehicle (the plant; its linear coefficients at ``v*``): a paper
        layout, or an open platoon (``kind = "platoon"``; a ring has no head: refused).
    law : LoopLaw
        The CAVs' whole commands (:func:`law_of_gains`, :func:`law_of_linear`).
    sample_time : float, optional
        Controller period ``T`` (s); ``None``: continuous-time limit (then ``latency = 0``).
    latency : float
        Age (s) of every received V2V value; a multiple of ``T``.
    equilibrium_tau : float, optional
        Time constant (s) of the equilibrium estimate; ``None`` = fixed equilibrium (the only
        one on a platoon: its controllers run with a fixed equilibrium).
    measurement_filter : float
        Time constant (s) of the filter on each received value; 0 = off.
    actuator_lag : float
        The CAV's actuator time constant (s); 0 = none (see ``_physical_plant``).

    Raises
    ------
    ConfigError
        ``system.kind`` for a layout with no head vehicle (a ring, FD-LCC);
        ``equilibrium_tau`` on a platoon.
    NotRepresentable
        A latency that is not a multiple of ``T`` (or any latency in continuous time).
    """
    check_head(model)
    A0, B0, H0, pnames, own = _physical_plant(model, actuator_lag)
    nx = A0.shape[0]
    nc = B0.shape[1]  # one row of the law per CAV
    K = np.zeros((nc, nx))
    K[:, : model.nx] = np.asarray(law.K, float).reshape(nc, model.nx)
    kh = np.broadcast_to(np.asarray(law.kh, float), (nc,))
    T = None if sample_time is None else float(sample_time)
    if T is not None and not (math.isfinite(T) and T > 0):
        raise ConfigError("sample_time", f"must be > 0 s, got {sample_time!r}")
    lat = float(latency)
    if not (math.isfinite(lat) and lat >= 0):
        raise ConfigError("latency", f"must be >= 0 s, got {latency!r}")
    if T is None and lat > 0:
        raise NotRepresentable(
            "latency", "a latency needs a sample time (a continuous delay has no finite state)"
        )
    d = 0 if lat == 0 else _steps(lat, T, "latency")
    est = equilibrium_tau is not None
    if est and model.kind in PLATOON_KINDS:
        raise ConfigError(
            "equilibrium_tau",
            f"must be unset (a fixed equilibrium) on kind = {model.kind!r}: a platoon's "
            "controllers run with equilibrium = \"fixed\" (the estimate follows one CAV's "
            "predecessor)",
        )
    if est and not (math.isfinite(equilibrium_tau) and equilibrium_tau > 0):
        raise ConfigError("equilibrium_tau", f"must be > 0 s, got {equilibrium_tau!r}")
    tf = float(measurement_filter or 0.0)
    if not (math.isfinite(tf) and tf >= 0):
        raise ConfigError("measurement_filter", f"must be >= 0 s, got {measurement_filter!r}")

    K_hdv = np.zeros((nc, nx))
    if law.K_hdv is not None:
        K_hdv[:, : model.nx] = np.asarray(law.K_hdv, float).reshape(nc, model.nx)
    kh_hdv = np.broadcast_to(np.asarray(law.kh_hdv, float), (nc,))
    # received channels: non-own states the law or the estimator reads, and the head velocity
    ahead = "v_h" if model.m == 0 else "v_-1"
    reads = np.any((K != 0.0) | (K_hdv != 0.0), axis=0)  # by any CAV: one received copy each
    chans = [j for j in range(nx) if not own[j] and (reads[j] or (est and pnames[j] == ahead))]
    use_head = bool(np.any(kh != 0.0) or np.any(kh_hdv != 0.0) or (est and ahead == "v_h"))
    nr = len(chans) + int(use_head)
    R = np.zeros((nr, nx))
    for r, j in enumerate(chans):
        R[r, j] = 1.0
    rh = np.zeros(nr)
    if use_head:
        rh[-1] = 1.0
    y_idx = (chans.index(pnames.index(ahead)) if ahead != "v_h" else nr - 1) if est else None

    # state layout
    names = list(pnames)
    i_w = len(names) if est else None
    if est:
        names.append("w")
    i_f = len(names) if tf > 0 else None
    if tf > 0:
        names += [f"f[{k}]" for k in range(nr)]
    i_d = len(names)
    for lag in range(1, d + 1):
        names += [f"r[{k}](-{lag})" for k in range(nr)]
    N = len(names)

    def sel(i0, n):  # rows selecting a block of xi
        M = np.zeros((n, N))
        M[:, i0 : i0 + n] = np.eye(n)
        return M

    X = sel(0, nx)
    # sampled loop: the plant block of xi is zeta = x - Lam v_h (first-order hold of the head,
    # see the module docstring), so x_k = zeta_k + Lam v_h,k; continuous: Lam = 0
    if T is None:
        Lam = np.zeros(nx)
    else:
        Ad, BHd = discretize(A0, np.hstack([B0, H0]), T)
        Bd, Hd = BHd[:, :nc], BHd[:, nc]
        M3 = np.zeros((nx + 2, nx + 2))
        M3[:nx, :nx] = A0
        M3[:nx, nx] = H0[:, 0]
        M3[nx, nx + 1] = 1.0
        Lam = sla.expm(M3 * T)[:nx, nx + 1] / T
    # received values r (as a map of (xi, v_h)): raw now, or the oldest delay-line copy
    r_raw = (R @ X, rh + R @ Lam)
    r_now = r_raw if d == 0 else (sel(i_d + (d - 1) * nr, nr), np.zeros(nr))
    if tf == 0:
        f_now = r_now
    elif T is None:
        f_now = (sel(i_f, nr), np.zeros(nr))
    else:  # the law reads the filter's state, then the state takes the new value in
        a_f = math.exp(-T / tf)
        f_now = (sel(i_f, nr), np.zeros(nr))

    def command(Kx, kh):  # (row on xi, coefficient of v_h) of Kx x + kh v_h as measured
        Kr = np.array([Kx[j] for j in chans] + ([kh] if use_head else []))
        Ko = np.where(own, Kx, 0.0)
        return Ko @ X + Kr @ f_now[0], float(Ko @ Lam + Kr @ f_now[1])

    rows = [command(K[k], kh[k]) for k in range(nc)]
    U, u_v = np.array([r for r, _ in rows]), np.array([v for _, v in rows])
    if est:  # one CAV (refused on a platoon above)
        U[0] = U[0] - law.e * sel(i_w, 1)[0]
    rows = [command(K_hdv[k], kh_hdv[k]) for k in range(nc)]
    U_hdv, hdv_v = np.array([r for r, _ in rows]), np.array([v for _, v in rows])

    A = np.zeros((N, N))
    h = np.zeros(N)
    if T is None:
        A[:nx] = A0 @ X + B0 @ U
        h[:nx] = H0[:, 0] + (B0 * u_v).sum(axis=1)
        if est:
            tau = float(equilibrium_tau)
            A[i_w] = (f_now[0][y_idx] - sel(i_w, 1)[0]) / tau
            h[i_w] = f_now[1][y_idx] / tau
        if tf > 0:
            A[i_f : i_f + nr] = (r_now[0] - sel(i_f, nr)) / tf
            h[i_f : i_f + nr] = r_now[1] / tf
    else:
        A[:nx] = Ad @ X + Bd @ U
        h[:nx] = Ad @ Lam + Hd - Lam + (Bd * u_v).sum(axis=1)
        if est:
            b = math.exp(-T / float(equilibrium_tau))
            A[i_w] = b * sel(i_w, 1)[0] + (1 - b) * f_now[0][y_idx]
            h[i_w] = (1 - b) * f_now[1][y_idx]
        if tf > 0:
            A[i_f : i_f + nr] = a_f * sel(i_f, nr) + (1 - a_f) * r_now[0]
            h[i_f : i_f + nr] = (1 - a_f) * r_now[1]
        if d > 0:
            A[i_d : i_d + nr] = r_raw[0]
            h[i_d : i_d + nr] = r_raw[1]
            for lag in range(2, d + 1):
                A[i_d + (lag - 1) * nr : i_d + lag * nr] = sel(i_d + (lag - 2) * nr, nr)
    c = np.zeros(N)
    c[pnames.index(f"v_{model.vehicles[-1]}")] = 1.0  # the tail
    d_tail = float(c[:nx] @ Lam)
    settings = {
        "sample_time": T,
        "latency": lat,
        "latency_steps": d,
        "equilibrium": "estimated" if est else "fixed",
        "equilibrium_tau": float(equilibrium_tau) if est else None,
        "measurement_filter": tf,
        "actuator_lag": float(actuator_lag),
        "states": N,
    }
    u_gain = (U - U_hdv, u_v - hdv_v)
    if model.kind not in PLATOON_KINDS:  # one CAV: a row and a number
        U, u_v, u_gain = U[0], float(u_v[0]), (u_gain[0][0], float(u_gain[1][0]))
    return AsRunLoop(
        A, h, c, T, tuple(names), U, u_v, nx, (A0, B0, H0), settings,
        u_gain=u_gain, measured_head=use_head, d=d_tail,
    )  # fmt: skip


def law_loop(
    model: LCCModel, law, period: float, latency: float = 0.0, actuator_lag: float = 0.0
) -> AsRunLoop:
    """The loop of a simulator law (:class:`~lcc_synth.controllers.static.LinearLaw`) that is
    evaluated every ``period`` seconds (its ``sample_time``, or the simulator step).

    The estimate's time constant is recovered from ``law.equilibrium_decay = e^(-T/tau)``, the
    filter's from ``getattr(law, "measurement_filter", 0.0)`` (seconds).
    """
    tau = None
    decay = getattr(law, "equilibrium_decay", None)
    if decay is not None:
        if not 0.0 < decay < 1.0:
            raise ConfigError("equilibrium_decay", f"must be in (0, 1), got {decay!r}")
        tau = -float(period) / math.log(decay)
    return as_run_loop(
        model, law_of_linear(model, law), period, latency, tau,
        float(getattr(law, "measurement_filter", 0.0) or 0.0), actuator_lag,
    )  # fmt: skip


# --------------------------------------------------------------------------------------------
# Verdict
# --------------------------------------------------------------------------------------------


def tustin(A: np.ndarray, b: np.ndarray, c: np.ndarray, T: float):
    """Continuous ``(Ac, bc, cc, dc)`` with ``Gamma_c(s) = Gamma_d((1 + sT/2) / (1 - sT/2))``.

    ``M = I + A``: ``Ac = (2/T) M^-1 (A - I)``, ``bc = sqrt(4/T) M^-1 b``,
    ``cc = sqrt(4/T) c M^-1``, ``dc = -c M^-1 b``. Needs no eigenvalue of ``A`` at -1.
    """
    n = A.shape[0]
    M = np.eye(n) + A
    lu = sla.lu_factor(M)
    Ac = (2.0 / T) * sla.lu_solve(lu, A - np.eye(n))
    Mb = sla.lu_solve(lu, b)
    cM = sla.lu_solve(lu, c, trans=1)
    k = math.sqrt(4.0 / T)
    return Ac, k * Mb, k * cM, -float(c @ Mb)


@dataclass(frozen=True)
class AsRunReport:
    """String stability of an as-run loop (frequencies in rad/s of the real time axis).

    ``string``: the :class:`StringStabilityReport` (of the Tustin image for a sampled loop,
    with its frequencies mapped back); ``loop``: what the loop holds; ``h2``: :func:`as_run_h2`
    when weights were given (else ``None``).
    """

    string: StringStabilityReport
    loop: dict
    h2: float | None = None

    verdict = property(lambda self: self.string.verdict)
    gamma_peak = property(lambda self: self.string.gamma_peak)
    gamma_peak_omega = property(lambda self: self.string.gamma_peak_omega)
    margin = property(lambda self: self.string.margin)
    string_stable = property(lambda self: self.string.string_stable)
    plant_stable = property(lambda self: self.string.plant_stable)

    def as_dict(self) -> dict:
        out = self.string.as_dict()
        out["as_run"] = dict(self.loop)
        out["h2_as_run"] = self.h2
        return out


def as_run_report(loop: AsRunLoop, h2: float | None = None) -> AsRunReport:
    """Plant and string stability of ``loop`` (grid method; see the module docstring)."""
    T = loop.sample_time
    if T is None:
        rep = loop_string_stability(loop.A, loop.h, loop.c)
    else:
        ev = np.linalg.eigvals(loop.A)
        if np.any(np.abs(ev + 1.0) < 1e-12):
            raise NotRepresentable("loop", "an eigenvalue at z = -1 has no Tustin image")
        Ac, bc, cc, dc = tustin(loop.A, loop.h, loop.c, T)
        rep = loop_string_stability(Ac, bc, cc, d=dc + loop.d)

        def back(nu):
            return float((2.0 / T) * math.atan(nu * T / 2.0)) if math.isfinite(nu) else nu

        rep = replace(
            rep,
            gamma_peak_omega=back(rep.gamma_peak_omega),
            interior_peak_omega=back(rep.interior_peak_omega),
            margin_omega=back(rep.margin_omega),
            max_real_eig=float(np.log(np.max(np.abs(ev))) / T),
        )
    return AsRunReport(rep, dict(loop.settings), h2)
