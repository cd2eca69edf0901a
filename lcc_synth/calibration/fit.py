"""Calibration of OVM and IDM drivers on recorded platoons, with identifiability.

Calibration method
------------------
For each follower ``i`` of a :class:`~lcc_synth.schema.trajectories.Trajectory`, its recorded
leader ``i - 1`` drives a simulated follower from the recorded initial gap and speed
(:func:`~lcc_synth.calibration.replay.replay_pairs`), and the parameters minimise by bounded
least squares (``scipy.optimize.least_squares``, trust-region reflective) the residuals

    r = [ s_sim - s_rec ,  w (v_sim - v_rec) ]   at every sample after the first,

spacing in m and speed in m/s weighted by ``w = VELOCITY_WEIGHT = 1 s`` (1 m/s counts as 1 m;
spacing-based calibration is the robust choice for car-following models, speed keeps the
dynamics honest). The parameters are scaled to ``u in [0, 1]`` over their bounds; the
Jacobian is central differences of step ``1e-5`` in ``u``, all ``2p`` perturbed runs in one
batched replay. Several starts: the first at the model's default (the paper's OVM, the
package's IDM), the others uniform in the bounds from ``numpy.random.default_rng(seed)``; the
best is kept, and the report says how many starts reached its cost (within 1 %). The
**pooled** fit is one parameter set for every follower (their residuals stacked).

Calibration bounds (:data:`BOUNDS`)
-----------------------------------
OVM (eq. 2-4): the paper's nominal driver (alpha 0.6, beta 0.9, s_st 5, s_go 35, v_max 30;
Sec. V) and its heterogeneous range (Appendix: alpha 0.6 ± 0.1, beta 0.9 ± 0.1, s_go 35 ± 5)
lie well inside alpha in [0.05, 2] 1/s, beta in [0, 2] 1/s, s_st in [0, 15] m, s_go in
[15.5, 80] m (so s_st < s_go always), v_max in [5, 40] m/s. IDM: around the typical values of
Treiber & Kesting, *Traffic Flow Dynamics* (Springer 2013), ch. 11 (v0 54-120 km/h, T 1-1.8 s,
s0 2 m, a 1 m/s², b 1.5-3 m/s², delta 4) with wide margins: v0 in [5, 40] m/s, T in [0.3, 3]
s, s0 in [0.5, 8] m, a in [0.2, 4] m/s², b in [0.3, 5] m/s², delta in [1, 8].

Vehicle length in a calibration
-------------------------------
Fixed (``length``, default 5 m), never fitted: a recorded headway includes the length of the
vehicle ahead, and shifting ``L`` is exactly undone by shifting s_st and s_go (OVM) or s0 (IDM)
by the same amount, so ``L`` and those parameters are not separately identifiable from
spacings. The fitted s_st, s_go, s0 are therefore *gaps for that L*.

Identifiability of the parameters
---------------------------------
At the optimum, with ``J = dr/du`` (scaled parameters) and its SVD ``J = U S V^T``:

1. a direction with ``S_k / S_1 < NULL_RATIO = 1e-6`` is flat (the data do not move when the
   parameters move along it); every parameter with a component above 0.1 in a flat direction
   is **not identified**;
2. otherwise the 95 % interval half-width is ``1.96 sqrt(sigma^2 (J^T J)^-1_jj)`` with
   ``sigma^2 = |r|^2 / (N - p)`` inflated by ``(1 + rho) / (1 - rho)``, ``rho`` the lag-1
   autocorrelation of the residuals (clipped to [0, 0.99]): replay residuals are strongly
   correlated in time, and the i.i.d. formula would claim far too much precision. A parameter
   whose interval is wider than ``IDENT_WIDTH = 0.25`` of its bound range is **not
   identified**; the report shows it as such, not as a precise number.

The classic flat case (``tests/test_calibration.py``): a leader at constant speed and a
follower at equilibrium; the follower never moves off ``V(s*) = v*``, so alpha and beta (OVM)
have no effect at all on the data, and s_st, s_go and v_max act only through the single value
``V(s*)``.

Consistency of the recorded data
--------------------------------
``data_rmse_m``: the RMS difference between a follower's recorded gap and its initial gap plus
the integral of its recorded relative speed. A few cm on every NGSIM I-80 follower except lane
2's vehicle 1 (4.5 m: a glitch in its recorded headway), a floor no model can beat in spacing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lcc_synth.calibration.replay import PARAMS, gaps, replay_pairs, replay_platoon
from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import IDM, OVM
from lcc_synth.schema.trajectories import Trajectory, read_trajectory

__all__ = [
    "BOUNDS",
    "IDENT_WIDTH",
    "NULL_RATIO",
    "VELOCITY_WEIGHT",
    "Calibration",
    "FollowerFit",
    "Fit",
    "calibrate",
    "data_rmse",
    "fit_followers",
]

#: Weight of a speed residual (s): 1 m/s counts as 1 m of spacing.
VELOCITY_WEIGHT = 1.0
#: A parameter whose 95 % interval is wider than this fraction of its bound range is not
#: identified.
IDENT_WIDTH = 0.25
#: Singular-value ratio below which a direction of the Jacobian is flat.
NULL_RATIO = 1e-6
_STEP = 1e-5

#: Bounds of every fitted parameter (see the module docstring).
BOUNDS: dict[str, dict[str, tuple[float, float]]] = {
    "ovm": {"alpha": (0.05, 2.0), "beta": (0.0, 2.0), "s_st": (0.0, 10.0),
            "s_go": (10.5, 80.0), "v_max": (5.0, 40.0)},
    "idm": {"v0": (5.0, 40.0), "T": (0.3, 3.0), "s0": (0.5, 8.0), "a": (0.2, 4.0),
            "b": (0.3, 5.0), "delta": (1.0, 8.0)},
}  # fmt: skip
_DEFAULTS = {"ovm": OVM(), "idm": IDM()}


@dataclass(frozen=True)
class Fit:
    """One fitted parameter set.

    Attributes
    ----------
    params : dict
        Best parameters by name.
    identified : dict
        ``True`` where the data identify the parameter (module docstring).
    ci95 : dict
        ``(lo, hi)``: the 95 % interval, clipped to the bounds (the whole range when flat).
    rmse_spacing, rmse_velocity : float
        Of the pairwise replay with these parameters (m, m/s).
    starts_at_best : int
        Starts whose cost came within 1 % of the best.
    at_bound : tuple of str
        Parameters at a bound (within 1e-3 of the range): the bound, not the data, set them.
    """

    params: dict[str, float]
    identified: dict[str, bool]
    ci95: dict[str, tuple[float, float]]
    rmse_spacing: float
    rmse_velocity: float
    starts_at_best: int
    at_bound: tuple[str, ...] = ()


@dataclass(frozen=True)
class FollowerFit:
    """The calibration of one follower (file index ``index``, its leader ``index - 1``).

    Attributes
    ----------
    fit : Fit
        Its own parameters (pairwise replay).
    nominal_rmse_spacing, nominal_rmse_velocity : float
        The paper's nominal OVM in the same pairwise replay.
    platoon_rmse_spacing, platoon_rmse_velocity : float
        The platoon replay (only vehicle 0 recorded) with every follower's own fit.
    nominal_platoon_rmse_spacing, nominal_platoon_rmse_velocity : float
        The platoon replay with the paper's nominal OVM for every follower.
    data_rmse_m : float
        Consistency of the recorded gap with the recorded speeds (module docstring).
    """

    index: int
    fit: Fit
    nominal_rmse_spacing: float
    nominal_rmse_velocity: float
    platoon_rmse_spacing: float
    platoon_rmse_velocity: float
    nominal_platoon_rmse_spacing: float
    nominal_platoon_rmse_velocity: float
    data_rmse_m: float


@dataclass(frozen=True)
class Calibration:
    """The calibration of every follower of a recorded platoon, and the pooled fit."""

    path: str
    model: str
    length: float
    starts: int
    seed: int
    dt: float
    samples: int
    followers: tuple[FollowerFit, ...]
    pooled: Fit
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)

    def as_dict(self) -> dict:
        """The stable JSON shape of ``lcc-synth calibrate --json`` (docs/guide/calibration.md)."""
        def fit(f: Fit) -> dict:
            return {"params": f.params, "identified": f.identified,
                    "ci95": {k: list(v) for k, v in f.ci95.items()},
                    "rmse_spacing_m": f.rmse_spacing, "rmse_velocity_ms": f.rmse_velocity,
                    "starts_at_best": f.starts_at_best, "at_bound": list(f.at_bound)}  # fmt: skip

        return {
            "file": self.path, "model": self.model, "vehicle_length_m": self.length,
            "starts": self.starts, "seed": self.seed, "dt_s": self.dt, "samples": self.samples,
            "bounds": {k: list(v) for k, v in self.bounds.items()},
            "followers": [{
                "index": f.index, **fit(f.fit),
                "nominal": {"rmse_spacing_m": f.nominal_rmse_spacing,
                            "rmse_velocity_ms": f.nominal_rmse_velocity},
                "platoon": {"rmse_spacing_m": f.platoon_rmse_spacing,
                            "rmse_velocity_ms": f.platoon_rmse_velocity,
                            "nominal_rmse_spacing_m": f.nominal_platoon_rmse_spacing,
                            "nominal_rmse_velocity_ms": f.nominal_platoon_rmse_velocity},
                "data_rmse_m": f.data_rmse_m,
            } for f in self.followers],
            "pooled": fit(self.pooled),
        }  # fmt: skip


def _nominal_vector(model: str) -> np.ndarray:
    d = _DEFAULTS[model]
    return np.array([float(getattr(d, k)) for k in PARAMS[model]])


def _bounds(model: str) -> tuple[np.ndarray, np.ndarray]:
    if model not in PARAMS:
        raise ConfigError("--model", f'must be "ovm" or "idm", got {model!r}')
    lo, hi = zip(*(BOUNDS[model][k] for k in PARAMS[model]), strict=True)
    return np.array(lo), np.array(hi)


def _rmse(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def data_rmse(traj: Trajectory, i: int) -> float:
    """RMS difference (m) between follower ``i``'s recorded headway and its first value plus
    the trapezoidal integral of ``v_{i-1} - v_i``."""
    rel = traj.v[i - 1] - traj.v[i]
    integ = np.concatenate(([0.0], np.cumsum(0.5 * (rel[1:] + rel[:-1]) * traj.dt)))
    return _rmse(traj.headway[i] - traj.headway[i, 0] - integ)


def _identify(J: np.ndarray, r: np.ndarray):
    """``(identified, half-width of the 95 % interval in u)`` per parameter."""
    p = J.shape[1]
    _, S, Vt = np.linalg.svd(J, full_matrices=False)
    flat_dirs = S <= NULL_RATIO * S[0] if S[0] > 0 else np.ones_like(S, dtype=bool)
    flat = np.any(np.abs(Vt[flat_dirs]) > 0.1, axis=0) if flat_dirs.any() else np.zeros(p, bool)
    dof = max(r.size - p, 1)
    rho = float(np.dot(r[1:], r[:-1]) / np.dot(r, r)) if np.dot(r, r) > 0 else 0.0
    rho = min(max(rho, 0.0), 0.99)
    sigma2 = float(np.dot(r, r)) / dof * (1.0 + rho) / (1.0 - rho)
    keep = ~flat_dirs
    cov = (Vt[keep].T / S[keep] ** 2) @ Vt[keep] * sigma2
    half = 1.96 * np.sqrt(np.maximum(np.diag(cov), 0.0))
    half[flat] = np.inf
    identified = ~flat & (2.0 * half <= IDENT_WIDTH)
    return identified, half


def fit_followers(
    model: str, leader_v: np.ndarray, s_rec: np.ndarray, v_rec: np.ndarray, dt: float,
    starts: int = 5, seed: int = 0, substeps: int = 1,
) -> Fit:
    """One parameter set fitted to every follower given (pooled when there are several).

    Parameters
    ----------
    model : {"ovm", "idm"}
    leader_v : ndarray, shape (F, T)
        Each follower's recorded leader speed (m/s).
    s_rec, v_rec : ndarray, shape (F, T)
        Each follower's recorded gap (m, headway minus the vehicle length) and speed (m/s).
    dt : float
        Sample period (s).
    starts : int
        Optimiser starts (>= 1): the model's default, then uniform draws in the bounds.
    seed : int
        Seed of the starts.
    substeps : int
        Integration steps per sample of the replay.

    Returns
    -------
    Fit
    """
    lo, hi = _bounds(model)
    span = hi - lo
    leader_v, s_rec, v_rec = (np.atleast_2d(np.asarray(x, dtype=float))
                              for x in (leader_v, s_rec, v_rec))  # fmt: skip
    F, T = leader_v.shape

    def residuals(U: np.ndarray) -> np.ndarray:  # (K, p) -> (K, 2 F (T - 1))
        K = U.shape[0]
        theta = np.repeat(lo + span * U, F, axis=0)
        s, v = replay_pairs(model, theta, np.tile(leader_v, (K, 1)), np.tile(s_rec[:, 0], K),
                            np.tile(v_rec[:, 0], K), dt, substeps)  # fmt: skip
        es = (s[:, 1:] - np.tile(s_rec[:, 1:], (K, 1))).reshape(K, -1)
        ev = VELOCITY_WEIGHT * (v[:, 1:] - np.tile(v_rec[:, 1:], (K, 1))).reshape(K, -1)
        return np.concatenate((es, ev), axis=1)

    def jac(u: np.ndarray) -> np.ndarray:
        p = u.size
        up = np.minimum(u + _STEP * np.eye(p), 1.0)
        um = np.maximum(u - _STEP * np.eye(p), 0.0)
        R = residuals(np.vstack((up, um)))
        return ((R[:p] - R[p:]) / (np.diag(up) - np.diag(um))[:, None]).T

    rng = np.random.default_rng(seed)
    x0s = [np.clip((_nominal_vector(model) - lo) / span, 0.0, 1.0)]
    x0s += list(rng.uniform(size=(max(starts, 1) - 1, lo.size)))
    from scipy.optimize import least_squares  # here: `import lcc_synth` stays light

    results = [least_squares(lambda u: residuals(u[None])[0], x0, jac=jac, bounds=(0.0, 1.0),
                             method="trf", x_scale=1.0, max_nfev=200) for x0 in x0s]  # fmt: skip
    costs = np.array([res.cost for res in results])
    best = results[int(np.argmin(costs))]
    u = best.x
    r = residuals(u[None])[0]
    identified, half = _identify(jac(u), r)
    names = PARAMS[model]
    theta = lo + span * u
    n_s = F * (T - 1)
    ci = {k: (float(max(lo[j], theta[j] - half[j] * span[j])),
              float(min(hi[j], theta[j] + half[j] * span[j]))) for j, k in enumerate(names)}
    at_bound = tuple(k for j, k in enumerate(names) if min(u[j], 1.0 - u[j]) < 1e-3)
    return Fit(
        params={k: float(theta[j]) for j, k in enumerate(names)},
        identified={k: bool(identified[j]) for j, k in enumerate(names)},
        ci95=ci,
        rmse_spacing=_rmse(r[:n_s]),
        rmse_velocity=_rmse(r[n_s:] / VELOCITY_WEIGHT),
        starts_at_best=int(np.sum(costs <= costs.min() * 1.01 + 1e-12)),
        at_bound=at_bound,
    )


def calibrate(
    traj: Trajectory | str | Path, model: str = "ovm", length: float = 5.0, starts: int = 5,
    seed: int = 0, substeps: int = 1, progress: Callable[[str], None] | None = None,
) -> Calibration:
    """Calibrate ``model`` on every follower of ``traj``, pooled too, and compare with the
    paper's nominal OVM in the pairwise and the platoon replay: ``lcc-synth calibrate`` and
    the flat API's ``lcc.calibrate``.

    Parameters
    ----------
    traj : Trajectory, str or Path
        A recorded platoon, or its file (read by
        :func:`lcc_synth.schema.trajectories.read_trajectory`; a bad file is one error naming
        the column and row).
    model : {"ovm", "idm"}, default "ovm"
    length : float
        Vehicle length (m), > 0 and below the smallest follower headway: gap = headway -
        length.
    starts, seed : int
        Optimiser starts (1..100) and their seed (>= 0).
    substeps : int
        Integration steps per sample (1..20).
    progress : callable, optional
        Called with a line before each follower's fit.

    Returns
    -------
    Calibration
        ``followers`` (per follower: ``fit.params``, ``fit.identified``, ``fit.ci95``, the
        spacing / velocity RMSE, the nominal OVM's, the platoon replay's) and ``pooled``;
        ``as_dict()`` is the command's ``--json``. Bad values are a ConfigError named by the
        command's option (``--model``, ``--length``, ``--starts``, ``--seed``, ``--substeps``).

    Examples
    --------
    Lane 1 of NGSIM I-80 (4 followers and the pooled fit, 5 starts each): about 10 s on this
    2-core machine, so not run as a doctest (``tests/test_api_calibrate.py`` runs a short file):

    >>> import lcc_synth as lcc
    >>> cal = lcc.calibrate("problems/data/ngsim_i80/i80_lane1.csv", "ovm")  # doctest: +SKIP
    >>> f = cal.followers[0]                                                  # doctest: +SKIP
    >>> f.fit.rmse_spacing < f.nominal_rmse_spacing                           # doctest: +SKIP
    True
    """
    if not isinstance(traj, Trajectory):
        traj = read_trajectory(Path(traj), "data")
    _bounds(model)
    min_headway = float(traj.headway[1:].min())
    if not (np.isfinite(length) and 0 < length < min_headway):
        raise ConfigError("--length", f"must be > 0 and < the smallest follower headway of the "
                          f"file ({min_headway:.3g} m), got {length!r}")
    if not 1 <= starts <= 100:
        raise ConfigError("--starts", f"must be in [1, 100], got {starts!r}")
    if seed < 0:
        raise ConfigError("--seed", f"must be >= 0, got {seed!r}")
    if not 1 <= substeps <= 20:
        raise ConfigError("--substeps", f"must be in [1, 20], got {substeps!r}")
    s_all = gaps(traj.headway, length)
    F = traj.n_vehicles - 1
    fits = []
    for i in range(1, traj.n_vehicles):
        if progress:
            progress(f"fitting follower {i} of {F} ({model}, {starts} starts)")
        fits.append(fit_followers(model, traj.v[i - 1], s_all[i], traj.v[i], traj.dt, starts,
                                  seed, substeps))  # fmt: skip
    if progress:
        progress(f"fitting the pooled set ({F} followers)")
    pooled = fit_followers(model, traj.v[:-1], s_all[1:], traj.v[1:], traj.dt, starts, seed,
                           substeps)  # fmt: skip
    nominal = np.tile(_nominal_vector("ovm"), (F, 1))
    ns, nv = replay_pairs("ovm", nominal, traj.v[:-1], s_all[1:, 0], traj.v[1:, 0], traj.dt,
                          substeps)  # fmt: skip
    own = np.array([[f.params[k] for k in PARAMS[model]] for f in fits])
    ps, pv = replay_platoon(model, own, traj.v[0], s_all[1:, 0], traj.v[1:, 0], traj.dt,
                            substeps)  # fmt: skip
    qs, qv = replay_platoon("ovm", nominal, traj.v[0], s_all[1:, 0], traj.v[1:, 0], traj.dt,
                            substeps)  # fmt: skip
    out = []
    for j, f in enumerate(fits):
        i = j + 1
        s_rec, v_rec = s_all[i, 1:], traj.v[i, 1:]
        out.append(FollowerFit(
            i, f, _rmse(ns[j, 1:] - s_rec), _rmse(nv[j, 1:] - v_rec), _rmse(ps[j, 1:] - s_rec),
            _rmse(pv[j, 1:] - v_rec), _rmse(qs[j, 1:] - s_rec), _rmse(qv[j, 1:] - v_rec),
            data_rmse(traj, i),
        ))
    return Calibration(traj.path, model, float(length), starts, seed, traj.dt, len(traj.t),
                       tuple(out), pooled, dict(BOUNDS[model]))  # fmt: skip
