"""CAV actuator lag as extra states of a linear model: ``da_i/dt = (u_i - a_i) / tau_i``.

A CAV whose powertrain follows its command with a first-order lag ``tau`` (CACC work uses
``tau`` = 0.1-0.5 s, e.g. Ploeg et al. 2011: 0.1 s) no longer has ``dv_i/dt = u_i``: its
acceleration ``a_i`` is a state. For any linear model ``dx = A x + B u + H v_h`` whose CAV
velocity rows are ``r_i`` (the row ``dv_i/dt = A[r_i] x + B[r_i] u + H[r_i] v_h``: the command
the CAV's controller asks for, HDV law and all for CF-LCC's "added" input) the lagged model is

    dv_i/dt = a_i,        da_i/dt = (A[r_i] x + B[r_i] u + H[r_i] v_h - a_i) / tau_i,

every other row unchanged. The lag states are appended AFTER the model's states (state names
``a_<i>`` from the velocity state ``v_<i>``), so a gain on the original states extends by zeros
(:func:`pad_gain`) and every index into the original state stays valid: the models of
:mod:`lcc_synth.models.linear` and :mod:`lcc_synth.models.platoon` (two states per vehicle)
are not touched. ``tau -> 0`` recovers the model (the lag row is a singular perturbation whose
fast mode ``-1/tau`` leaves); ``tau = 0`` itself is refused here: use the model as it is.

The simulator integrates the same lag with Euler at its step ``dt``
(:mod:`lcc_synth.simulation.engine`): at ``dt`` = 0.01 s and ``tau`` >= 0.1 s the discrete
lag's pole ``1 - dt / tau`` is within 0.5 % of ``exp(-dt / tau)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.records import Record

__all__ = ["LaggedModel", "with_actuator_lag", "pad_gain", "check_lag"]


def check_lag(tau, field: str = "cav_lag", allow_zero: bool = True) -> float:
    """``float(tau)`` if it is a finite lag ``>= 0`` (``> 0`` unless ``allow_zero``); else a
    ConfigError naming ``field``."""
    try:
        x = float(tau)
    except (TypeError, ValueError):
        raise ConfigError(field, f"must be a number of seconds >= 0, got {tau!r}") from None
    if not np.isfinite(x) or x < 0 or (x == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ConfigError(field, f"must be a finite lag {bound} s, got {tau!r}")
    return x


@dataclass(frozen=True, eq=False, repr=False)
class LaggedModel(Record):
    """A linear model with the CAVs' actuator lags as extra states.

    Attributes
    ----------
    A, B, H : numpy.ndarray
        ``(nx + n_lag, nx + n_lag)``, ``(nx + n_lag, nu)``, ``(nx + n_lag, 1)``.
    state_names : tuple of str
        The model's names, then ``a_<i>`` per lagged CAV.
    rows : tuple of int
        The CAV velocity rows ``r_i`` of the original model (where each lag feeds in).
    tau : tuple of float
        Lag of each lagged CAV (s).
    nx0 : int
        States of the original model (the lag states are ``nx0 ..``).
    """

    A: np.ndarray
    B: np.ndarray
    H: np.ndarray
    state_names: tuple[str, ...]
    rows: tuple[int, ...]
    tau: tuple[float, ...]
    nx0: int

    @property
    def nx(self) -> int:
        """States of the lagged model."""
        return self.A.shape[0]

    def closed_loop(self, K: np.ndarray, kh=0.0) -> tuple[np.ndarray, np.ndarray]:
        """``(A_cl, H_cl)`` of ``u = K x + kh v_h``; ``K`` on the original or the lagged state
        (``(nu, nx0)`` is padded with zeros on the lag states)."""
        K = pad_gain(self, K)
        kh = np.asarray(kh, dtype=float).reshape(-1, 1)
        return self.A + self.B @ K, self.H + self.B @ kh


def with_actuator_lag(
    A: np.ndarray,
    B: np.ndarray,
    H: np.ndarray,
    cav_velocity_rows: Sequence[int],
    tau,
    state_names: Sequence[str] | None = None,
) -> LaggedModel:
    """Augment ``dx = A x + B u + H v_h`` with a first-order lag on each CAV's acceleration.

    Parameters
    ----------
    A, B, H : array_like
        The model (``B`` one column per CAV input, ``H`` the head input; any width).
    cav_velocity_rows : sequence of int
        The row of each lagged CAV's velocity (``model.index("v_0")``, platoon ``v_i``).
    tau : float or sequence of float
        The lag (s, > 0): one for every row or one per row.
    state_names : sequence of str, optional
        The model's state names (default ``x_0 ..``); the lag state of row ``r`` is named
        after it (``v_0`` -> ``a_0``).

    Returns
    -------
    LaggedModel
    """
    A = np.asarray(A, dtype=float)
    nx = A.shape[0]
    B = np.asarray(B, dtype=float).reshape(nx, -1)
    H = np.asarray(H, dtype=float).reshape(nx, -1)
    rows = tuple(int(r) for r in cav_velocity_rows)
    if not rows or len(set(rows)) != len(rows) or not all(0 <= r < nx for r in rows):
        raise ConfigError("cav_velocity_rows", f"must be distinct rows in [0, {nx}), got {rows}")
    taus = np.broadcast_to(np.asarray(tau, dtype=float), (len(rows),)) if np.ndim(tau) == 0 \
        else np.asarray(tau, dtype=float)
    if taus.shape != (len(rows),):
        raise ConfigError("cav_lag", f"needs one lag or one per CAV ({len(rows)}), got {tau!r}")
    taus = tuple(check_lag(t, allow_zero=False) for t in taus)
    names = tuple(state_names) if state_names is not None else tuple(f"x_{i}" for i in range(nx))
    nl = len(rows)
    N = nx + nl
    Aa = np.zeros((N, N))
    Aa[:nx, :nx] = A
    Ba = np.zeros((N, B.shape[1]))
    Ba[:nx] = B
    Ha = np.zeros((N, H.shape[1]))
    Ha[:nx] = H
    lag_names = []
    for j, (r, t) in enumerate(zip(rows, taus, strict=True)):
        la = nx + j
        Aa[la, :nx] = A[r] / t
        Aa[la, la] = -1.0 / t
        Ba[la] = B[r] / t
        Ha[la] = H[r] / t
        Aa[r] = 0.0
        Aa[r, la] = 1.0
        Ba[r] = 0.0
        Ha[r] = 0.0
        nm = names[r]
        lag_names.append("a_" + nm[2:] if nm.startswith("v_") else f"a_{nm}")
    return LaggedModel(Aa, Ba, Ha, names + tuple(lag_names), rows, taus, nx)


def pad_gain(lagged: LaggedModel, K) -> np.ndarray:
    """``K`` (``(nu, nx0)`` on the original states, or already ``(nu, nx)``) as a gain on the
    lagged state: zeros on the lag states (the CAV does not feed back its own acceleration)."""
    K = np.atleast_2d(np.asarray(K, dtype=float))
    if K.shape[1] == lagged.nx:
        return K
    if K.shape[1] != lagged.nx0:
        raise ConfigError(
            "gain", f"needs {lagged.nx0} (or {lagged.nx} with the lag states) entries, "
            f"got {K.shape[1]}"
        )
    return np.hstack([K, np.zeros((K.shape[0], lagged.nx - lagged.nx0))])
