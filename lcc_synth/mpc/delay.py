"""HDV reaction delays in the MPC's discrete prediction model (``prediction.delay``).

The simulator's HDV with reaction delay ``tau`` reacts to the state ``tau`` seconds old (the
"full" delay model of :class:`~lcc_synth.simulation.scenario.Scenario`: spacing, relative
speed and own speed delayed), so its linearised velocity row (eq. 8) is the delay
differential equation ``dv_i/dt = a1 s_i(t - tau) - a2 v_i(t - tau) + a3 v_{i-1}(t - tau)``
(the head velocity error ``d(t - tau)`` when vehicle ``i - 1`` is the head), while the
kinematic rows ``ds_i/dt = v_{i-1} - v_i`` and the CAV's rows are not delayed. Split
``[A | H] = G_nd + sum_g G_g`` into the undelayed rows and the rows of the HDVs with delay
``tau_g`` (one group per distinct delay: heterogeneous delays share one register) acting on
``w = [x; d]``::

    dx/dt = A_nd x(t) + H_nd d(t) + B u(t) + sum_g G_g w(t - tau_g)

Over one sample ``[k Ts, (k+1) Ts]`` the command ``u`` and the head prediction ``d`` of the
undelayed rows are held (as today's ZOH model; exact for ``u``) and the delayed ``w`` is
**interpolated linearly** between its samples (exact for the CAV's velocity when its
acceleration is the held command: LCC, FD-LCC). The delay is not rounded: with ``tau = (l +
phi) Ts`` (``0 <= phi < 1``) the delayed argument ``t - tau`` crosses the samples ``k-l-1,
k-l`` for ``s < phi Ts`` and ``k-l, k-l+1`` after, so the exact discretisation of that
piecewise-linear input is::

    x_{k+1} = E x_k + Gam (B u_k + H_nd d_k) + sum_i W_i^{(l, phi)} G w_{k-l+1-i},  i = 0, 1, 2

with ``E = expm(A_nd Ts)``, ``Gam = int_0^Ts expm(A_nd s) ds`` and the weights ``W`` integrals
of ``expm(A_nd (Ts - s))`` times the interpolation weights over the two pieces (matrix
exponentials of the block matrix ``[[A_nd, I, 0], [0, 0, I], [0, 0, 0]]``, Van Loan). For
``phi = 0`` this is the first-order hold ``(Gam - Gam1) G w_{k-l} + Gam1 G w_{k-l+1}``. A delay
below one sample (``l = 0``) would need ``w_{k+1}``; it is extrapolated as ``2 w_k - w_{k-1}``.
The state is augmented with the past samples ``r_j = w_{k-j}[C]``, ``j = 1 .. D = ceil(max
tau / Ts)``, of the entries ``C`` the delayed rows use (a shift register), so the prediction
stays ``z_{k+1} = Ad z_k + Bd u_k + Hd d_k`` and the condensed QP of
:mod:`lcc_synth.mpc.formulation` keeps its form. With no delayed row the model is today's
(``lcc_delay_model`` returns ``None`` and the MPC's matrices are bit for bit unchanged).

Approximation error (measured, ``tests/test_mpc_delay.py``): CF-LCC with 4 HDVs behind, OVM
(alpha 0.6, beta 0.9) at 15 m/s, ``Ts`` = 0.1 s, from a non-equilibrium state held as the
history, with a +1 m/s^2 step of the CAV's added input for 2 s, against Heun's method on the
delay differential equation at 1 ms with the exact delays (converged: at 0.5 ms the errors
below agree to 1e-5). Largest error of any state over 10 s relative to the largest response:
0.95 % for 0.4 s on every HDV, 1.3 % for 0.45 s, 1.3 % for 0.2 / 0.35 / 0.6 / 0.47 s; 4.0x
smaller at ``Ts`` = 0.05 s (second order). For comparison: holding the delayed state over the
sample (``F = Gam G_l``) gives 48 %, rounding 0.45 s to 0.5 s 68 % and the delay-free model
76 %: the string's response is very sensitive to the delay, hence no rounding. Delays below
``Ts`` (extrapolation): 0.1-0.9 % (0.9 % for a 0.1 ms delay, against the undelayed model).

Cost (``benchmarks/bench_mpc_delay.py``, head brake with the HDVs delayed 0.4 s, N = 50): 4
HDVs at 0.4 s add 4 samples of 9 entries (46 states in all), 10 HDVs 4 x 21 (106). The
condensed QP keeps its variables and constraints, so the step time does not move (median 0.42
vs 0.38 ms, p99 5.1 vs 4.9 ms with 4 HDVs; 0.41 / 7.9 vs 0.38 / 4.9 ms with 10); building the
formulation (0.19 vs 0.13 s; 0.43 vs 0.07 s) and one evaluation of its matrices, i.e. one
re-linearisation (25 vs 7 ms; 98 vs 8 ms), grow with the state.

Limits (measured on ``problems/mpc_head_brake.toml``, every HDV delayed, default weights):
the predicted cost of a delayed string grows fast with the delay, because the string amplifies
the head's brake from HDV to HDV (the terminal weight's largest entry with 10 HDVs predicted:
188 at 0.4 s, 3.3e3 at 0.5 s, 1.1e5 at 0.6 s), so with all 10 HDVs predicted and a delay of
0.5 s or more the l1 penalty on the safe spacing is no longer exact: the CAV trades its gap for
the tail (with 0.6 s predicted, 97-103 steps with slack up to 10 m and emergency braking, true
delays 0.2-0.6 s). Predicting the 4 HDVs behind (``n_model = 4``, as
``problems/sweep_robustness.toml``) keeps the slack at 0 up to 0.4 s predicted. A string whose
HDVs all react 0.6 s late collides by itself in this brake (the all-HDV baseline: HDVs 8 / 9 at
49 s); the MPCs that predict 4 HDVs with 0.4 or 0.6 s do not prevent a collision at its tail
either (the delay-free one and 0.2 s happen to).

The controller (:class:`StateHistory`) keeps the last ``D`` observed ``w`` (absolute spacings
minus their offsets, velocities, the reference velocity) at its own period and forms ``r_j``
from them with the CURRENT equilibrium (the linear model is about one fixed equilibrium);
before the first ``D`` samples the history is the first observation held. The delays are given
(``prediction.delay``); estimating them from the observed HDVs is not implemented.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from lcc_synth.errors import ConfigError

__all__ = ["DelayModel", "delay_samples", "delay_model", "lcc_delay_model", "pad", "StateHistory"]


@dataclass(frozen=True, eq=False)
class DelayModel:
    """The augmented discrete model of :func:`delay_model`.

    Attributes
    ----------
    Ad, Bd, Hd : numpy.ndarray
        ``(nz, nz)``, ``(nz, k)``, ``(nz, 1)`` with ``nz = nx + D |C|``.
    nx : int
        States of the undelayed model (the first ``nx`` entries of ``z``).
    delays : numpy.ndarray
        Delay (samples, ``tau / Ts``) of every row of ``x`` (0 = undelayed).
    columns : numpy.ndarray
        ``C``: the entries of ``w = [x; d]`` (index ``nx`` = ``d``) kept in the register.
    depth : int
        ``D``, the register depth: the largest delay in samples, rounded up.
    """

    Ad: np.ndarray
    Bd: np.ndarray
    Hd: np.ndarray
    nx: int
    delays: np.ndarray
    columns: np.ndarray
    depth: int

    def history(self) -> StateHistory:
        """The per-member register of past observations (:class:`StateHistory`)."""
        return StateHistory(self)

    @property
    def nz(self) -> int:
        """Size of the augmented state."""
        return self.Ad.shape[0]


def delay_samples(delay: float | Sequence[float], hdvs: Sequence[int], Ts: float,
                  field_name: str = "prediction.delay") -> dict[int, float]:
    """Delays ``tau_i / Ts`` (in samples, not rounded) of the HDVs ``hdvs`` (paper indices,
    front to tail); ``delay`` is one delay for every HDV or one per HDV in ``hdvs`` order (s).

    Raises
    ------
    ConfigError
        ``field_name`` for a delay outside [0, 5] s or a list of the wrong length.
    """
    values = np.atleast_1d(np.asarray(delay, dtype=float))
    if values.size == 1:
        values = np.full(len(hdvs), float(values[0]))
    if values.ndim != 1 or values.size != len(hdvs):
        raise ConfigError(field_name, f"needs one delay or {len(hdvs)} (one per HDV the MPC "
                          f"models, front to tail), got {np.asarray(delay).size}")  # fmt: skip
    if not np.all(np.isfinite(values)) or np.any(values < 0) or np.any(values > 5.0):
        raise ConfigError(field_name, f"must be in [0, 5] s, got {list(values)}")
    return {int(i): float(t / Ts) for i, t in zip(hdvs, values, strict=True)}


def _van_loan(A: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``expm(A t)``, ``int_0^t expm(A (t - s)) ds`` and ``int_0^t expm(A (t - s)) s ds`` from
    one exponential of ``[[A, I, 0], [0, 0, I], [0, 0, 0]] t``."""
    n = A.shape[0]
    M = np.zeros((3 * n, 3 * n))
    M[:n, :n] = A
    M[:n, n:2 * n] = np.eye(n)
    M[n:2 * n, 2 * n:] = np.eye(n)
    X = sla.expm(M * t)
    return X[:n, :n], X[:n, n:2 * n], X[:n, 2 * n:]


def _weights(A: np.ndarray, Ts: float, phi: float, full) -> tuple[np.ndarray, ...]:
    """``(W_{l+1}, W_l, W_{l-1})``: ``int_0^Ts expm(A (Ts - s)) w(s - tau) ds`` for the delay
    ``tau = (l + phi) Ts`` and ``w`` linear between its samples, as weights of ``w_{k-l-1},
    w_{k-l}, w_{k-l+1}`` (``full`` = the integrals over the whole sample)."""
    E, J0, J1 = full
    if phi > 0.0:
        c = phi * Ts
        _, J0c, J1c = _van_loan(A, c)
        P = sla.expm(A * (Ts - c))
        Ia0, Ia1 = P @ J0c, P @ J1c  # s in [0, c]: w between samples k-l-1 and k-l
    else:
        Ia0 = Ia1 = np.zeros_like(A)
    Ib0, Ib1 = J0 - Ia0, J1 - Ia1  # s in [c, Ts]: between k-l and k-l+1
    Ta = Ia1 / Ts + (1.0 - phi) * Ia0
    Tb = Ib1 / Ts - phi * Ib0
    return Ia0 - Ta, Ta + Ib0 - Tb, Tb


def delay_model(A: np.ndarray, B: np.ndarray, H: np.ndarray, row_delays: np.ndarray,
                Ts: float, columns: np.ndarray | None = None) -> DelayModel:
    """Discretise ``dx = A x + B u + H d`` whose rows ``i`` react ``row_delays[i]`` samples late.

    Parameters
    ----------
    A, B, H : numpy.ndarray
        The continuous model, ``(nx, nx)``, ``(nx, k)``, ``(nx, 1)``.
    row_delays : numpy.ndarray
        ``(nx,)`` delay of each row in samples (``tau / Ts``, any value >= 0; the HDVs'
        velocity rows; 0 = undelayed).
    Ts : float
        Sample time (s).
    columns : numpy.ndarray, optional
        The entries of ``w = [x; d]`` to keep in the register (default: those the delayed rows
        of ``[A | H]`` use). Give the structural pattern when the model is re-linearised, so the
        augmented state keeps its size when a coefficient happens to be zero.

    Returns
    -------
    DelayModel
        See the module docstring for the method.
    """
    A = np.asarray(A, float)
    nx = A.shape[0]
    B = np.asarray(B, float).reshape(nx, -1)
    H = np.asarray(H, float).reshape(nx, 1)
    tau = np.round(np.asarray(row_delays, dtype=float).reshape(nx), 9)
    G = np.hstack([A, H])
    delayed = tau > 0
    G_nd = np.where(delayed[:, None], 0.0, G)
    A_nd = G_nd[:, :nx]
    full = _van_loan(A_nd, Ts)
    E, Gam = full[0], full[1]
    D = int(np.ceil(tau.max(initial=0.0)))
    if columns is not None:
        cols = np.asarray(columns, dtype=int) if D else np.zeros(0, int)
    else:
        cols = np.flatnonzero(np.any(G[delayed] != 0.0, axis=0)) if D else np.zeros(0, int)
    if np.any(G[delayed][:, np.setdiff1d(np.arange(nx + 1), cols)] != 0.0):
        raise ValueError("delay_model: a delayed row uses an entry outside columns")
    nc = cols.size
    nz = nx + D * nc
    Ad = np.zeros((nz, nz))
    Hd = np.zeros((nz, 1))
    Ad[:nx, :nx] = E
    Hd[:nx] = Gam @ G_nd[:, nx:]
    Bd = np.zeros((nz, B.shape[1]))
    Bd[:nx] = Gam @ B

    def add(j: int, M: np.ndarray) -> None:
        """Add ``M w_{k-j}`` to the x rows (``w_k = [x_k; d_k]``, else register slot j)."""
        if j == 0:
            Ad[:nx, :nx] += M[:, :nx]
            Hd[:nx] += M[:, nx:]
        else:
            Ad[:nx, nx + (j - 1) * nc: nx + j * nc] += M[:, cols]

    for value in np.unique(tau[delayed]):
        G_g = np.where((tau == value)[:, None], G, 0.0)
        lag = int(np.floor(value))
        phi = float(value - lag)
        W_older, W_lag, W_newer = _weights(A_nd, Ts, phi, full)
        if phi > 0.0:
            add(lag + 1, W_older @ G_g)
        add(lag, W_lag @ G_g)
        if lag > 0:
            add(lag - 1, W_newer @ G_g)
        else:  # a delay below Ts: w_{k+1} is not known yet, extrapolated 2 w_k - w_{k-1}
            add(0, 2.0 * W_newer @ G_g)
            add(1, -W_newer @ G_g)
    if D:
        sel = np.zeros((nc, nx + 1))
        sel[np.arange(nc), cols] = 1.0
        Ad[nx:nx + nc, :nx] = sel[:, :nx]  # r_1 <- w_k[C]
        Hd[nx:nx + nc, 0] = sel[:, nx]
        for j in range(2, D + 1):  # r_j <- r_{j-1}
            rows = slice(nx + (j - 1) * nc, nx + j * nc)
            Ad[rows, nx + (j - 2) * nc: nx + (j - 1) * nc] = np.eye(nc)
    return DelayModel(Ad, Bd, Hd, nx, tau, cols, D)


def lcc_delay_model(model, delay, Ts: float) -> DelayModel | None:
    """The delayed discrete model of an :class:`~lcc_synth.models.linear.LCCModel` whose HDVs
    (not the CAV) react ``delay`` seconds late (one value, or one per HDV of the model front to
    tail: vehicles ``-m..-1, 1..n``); ``None`` when every delay is 0 (today's model).

    The register keeps the structural entries of the HDV rows (``s_i, v_i`` and the velocity of
    the vehicle ahead, or ``d`` for the HDV behind the head), whatever the coefficients.
    """
    hdvs = [i for i in model.vehicles if i != 0]
    samples = delay_samples(delay, hdvs, Ts)
    nx = model.nx
    row = np.zeros(nx)
    cols: set[int] = set()
    for j, i in enumerate(model.vehicles):
        if i != 0 and samples[i] > 0:
            row[2 * j + 1] = samples[i]
            cols.update((2 * j, 2 * j + 1, 2 * j - 1 if j > 0 else nx))
    if not np.any(row):
        return None
    return delay_model(model.A, model.B, model.H, row, Ts, np.array(sorted(cols)))


def pad(v: np.ndarray, n: int) -> np.ndarray:
    """``v`` (a vector of the undelayed model) with zeros for the register entries, length
    ``n``: the register carries no weight, gain or steady-state offset."""
    v = np.asarray(v, dtype=float).reshape(-1)
    return np.concatenate([v, np.zeros(n - v.size)])


class StateHistory:
    """The last ``depth`` observed ``w = [x; d]`` in absolute terms, at the controller period.

    :meth:`push` takes the current error state ``x``, head error ``d`` and the equilibrium
    ``(s_eq, v_eq)`` they are taken from; it returns the augmented state ``z = [x, r_1, ..,
    r_D]`` with ``r_j = (w_{k-j} + eq_{k-j} - eq_k)[C]`` (the past absolute values as errors
    from the CURRENT equilibrium), then stores this sample. Before ``D`` samples the history is
    the first sample held.

    Parameters
    ----------
    model : DelayModel
    """

    def __init__(self, model: DelayModel):
        self.columns = model.columns
        self.depth = model.depth
        spacing = np.zeros(model.nx + 1, dtype=bool)
        spacing[0:model.nx:2] = True
        self._spacing = spacing[self.columns]
        self._buf: np.ndarray | None = None

    def push(self, x: np.ndarray, d: float, s_eq: float, v_eq: float, **_) -> np.ndarray:
        """The augmented state of this sample (see the class docstring; other keywords, the
        observation of :class:`lcc_synth.mpc.lag.LagState`, are ignored)."""
        eq = np.where(self._spacing, s_eq, v_eq)
        w_abs = np.append(x, d)[self.columns] + eq
        if self._buf is None:
            self._buf = np.repeat(w_abs[None, :], self.depth, axis=0)
        r = (self._buf - eq).reshape(-1)
        self._buf[1:] = self._buf[:-1]
        self._buf[0] = w_abs
        return np.concatenate([x, r])
