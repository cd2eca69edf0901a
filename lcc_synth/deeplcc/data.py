"""DeeP-LCC's offline data: collection in the nonlinear simulator, the persistency-of-
excitation check, and the ``.npz`` cache.

**Collection** (Wang et al. 2023, Section V): the CAV inputs are i.i.d. ``U[-a_u, a_u]``
accelerations (a controller object returning them; the simulator applies its limits and
emergency braking, and the APPLIED accelerations are recorded from the result), the head
vehicle's velocity is ``v* + e_k`` with i.i.d. ``e_k ~ U[-a_e, a_e]`` (``e_0 = 0``: the run
starts at the equilibrium), imposed through an ``accel_profile`` perturbation of the head
(``(e_{k+1} - e_k) / dt``, not clipped: it is the scenario's input), and ``e`` is read back
from the simulated head velocity. ``T + 1`` samples at ``dt`` give ``T`` pairs
``(u_k, e_k, y_{k+1})`` (:mod:`lcc_synth.deeplcc.hankel`). The scenario is the run's own (its
HDV parameters, heterogeneity, reaction delays, acceleration noise, limits) with the
perturbations replaced, ``batch = 1`` and the data table's ``dt``, ``seed`` and ``v_star``,
run in the scenario's simulator: with ``[scenario] backend = "sumo"`` the data come from SUMO
(the HDVs the controller will drive among: SUMO's car-following model and integration), and the
backend is part of the cache key, so SUMO's and the built-in simulator's data never mix.

**Persistency of excitation.** The fundamental lemma needs the inputs ``(u, e)`` persistently
exciting of order ``L + n_x`` (``L = Tini + N``, ``n_x = 2`` per vehicle behind the head):
the input Hankel matrix of that depth, ``(n_c + 1)(L + n_x)`` rows by ``T - L - n_x + 1``
columns, must have full row rank. It is judged by ``sigma_min / sigma_max`` of that matrix
against :data:`PE_THRESHOLD` = 1e-3, a scale-free test (measured at depth 92, one CAV): i.i.d.
inputs give about ``(1 - sqrt(rho)) / (1 + sqrt(rho))`` with ``rho`` = rows / columns
(Marchenko-Pastur; measured 0.53 at T = 2000, 0.47 on the collected head-brake data, 0.029
at T = 300, 0.004 at T = 276, one column more than rows), while rank-deficient data give
round-off (a period-8 sine: 4e-16; fewer columns than rows: 0). The threshold sits orders of
magnitude from both, so the verdict does not depend on rounding, and ``A = [U_p; E_p; E_f]``
of the reduction (:func:`lcc_synth.deeplcc.hankel.reduce`), a block of that matrix, has full
row rank. Data that fail are refused with a :class:`ConfigError` naming the data
table. A collision or emergency braking during collection is refused the same way (the
recorded inputs are then not the excitation).

**Progress.** A collection that runs longer than :data:`BAR_DELAY` = 1 s shows a progress bar
on stderr (one step per simulation sample; measured 0.55 s for T = 2000 on a loaded 2-core
machine, so usually nothing is printed); the reduction that follows is timed in the
controller's ``setup_time``.

**Cache.** The data are a deterministic function of the collection scenario and the data
table; the file ``deeplcc-<hash>.npz`` (SHA-256 of a canonical JSON of both, the package's
data-format version included) in ``cache_dir`` is reused by later runs.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import uuid
import zipfile
from dataclasses import dataclass, fields, is_dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.controllers.base import ControlContext, Observation
from lcc_synth.deeplcc.hankel import DataSet, hankel
from lcc_synth.errors import ConfigError
from lcc_synth.models.records import Record
from lcc_synth.resources import progress
from lcc_synth.schema.readers import read_file

__all__ = [
    "PE_THRESHOLD",
    "BAR_DELAY",
    "FORMAT_VERSION",
    "DataSettings",
    "Excitation",
    "ExcitationReport",
    "excitation",
    "check_excitation",
    "collection_scenario",
    "collection_bar",
    "collect",
    "data_key",
    "collection_key",
    "load_or_collect",
]

#: Smallest accepted ``sigma_min / sigma_max`` of the input Hankel matrix (module docstring).
PE_THRESHOLD = 1e-3
#: Bumped whenever the collected arrays change meaning (part of the cache key).
FORMAT_VERSION = 1


@dataclass(frozen=True, repr=False)
class DataSettings(Record):
    """The ``[controllers.NAME.data]`` table: how the offline data are collected.

    Attributes
    ----------
    T : int
        Number of data samples.
    dt : float
        Sample time (s); also the controller's period.
    seed : int
        Seed of the excitation (and of the scenario's own random draws).
    u_amplitude, e_amplitude : float
        Half widths of the uniform CAV-input (m/s^2) and head-velocity (m/s) excitation.
    v_star : float or None
        Equilibrium velocity of the collection; ``None``: the system's ``v*``.
    hdv_accel_noise : float or None
        HDV acceleration noise during collection; ``None``: the scenario's.
    cache : bool
        Reuse / write the ``.npz`` cache.
    cache_dir : str
        Folder of the cache files (relative to the working directory unless absolute).
    field : str
        Dotted name of the table (error messages).
    """

    T: int = 2000
    dt: float = 0.05
    seed: int = 0
    u_amplitude: float = 1.0
    e_amplitude: float = 1.0
    v_star: float | None = None
    hdv_accel_noise: float | None = None
    cache: bool = True
    cache_dir: str = "results/deeplcc"
    field: str = "data"


class Excitation:
    """The CAVs' excitation during collection: pre-drawn i.i.d. ``U[-a, a]`` commands.

    Returns ``(batch,)`` for one CAV and ``(batch, n_c)`` for several (the controller rule).

    Parameters
    ----------
    values : numpy.ndarray
        ``(steps, n_c)`` commands, one row per simulation step.
    """

    name = "deep_lcc_excitation"
    sample_time = None

    def __init__(self, values: np.ndarray, bar=None):
        self.values = np.asarray(values, dtype=float)
        self._k = 0
        self._batch = 1
        self.bar = bar  # a progress bar (tqdm) advanced by one per step, or None

    def reset(self, ctx: ControlContext) -> None:
        """Restart the sequence."""
        self._k = 0
        self._batch = ctx.batch

    def __call__(self, obs: Observation) -> np.ndarray:
        row = self.values[min(self._k, len(self.values) - 1)]
        self._k += 1
        if self.bar is not None:
            self.bar.update(1)
        if row.size == 1:
            return np.full(self._batch, row[0])
        return np.repeat(row[None, :], self._batch, axis=0)

    def describe(self) -> dict[str, Any]:
        """Size of the sequence."""
        return {"type": "deep_lcc_excitation", "steps": int(len(self.values))}

    def stats(self) -> dict[str, Any]:
        """Nothing to report."""
        return {}


@dataclass(frozen=True, repr=False)
class ExcitationReport(Record):
    """Persistency of excitation of one data set.

    Attributes
    ----------
    order : int
        Depth of the input Hankel matrix judged (``L + n_x``).
    rows, columns : int
    rank : int
        Numerical rank (singular values above ``max(rows, columns) eps sigma_max``).
    ratio : float
        ``sigma_min / sigma_max`` (0 when there are fewer columns than rows).
    ok : bool
        ``ratio >= PE_THRESHOLD``.
    """

    order: int
    rows: int
    columns: int
    rank: int
    ratio: float
    ok: bool


def excitation(u: np.ndarray, e: np.ndarray, order: int) -> ExcitationReport:
    """:class:`ExcitationReport` of the inputs ``u`` ``(T, n_c)`` and ``e`` ``(T,)`` at depth
    ``order``."""
    w = np.column_stack([np.asarray(u, float).reshape(len(e), -1), np.asarray(e, float)])
    T, d = w.shape
    rows = d * order
    cols = T - order + 1
    if cols < 1:
        return ExcitationReport(order, rows, max(cols, 0), 0, 0.0, False)
    s = np.linalg.svd(hankel(w, order), compute_uv=False)
    smax = float(s[0]) if s.size else 0.0
    if smax == 0.0 or not math.isfinite(smax):
        return ExcitationReport(order, rows, cols, 0, 0.0, False)
    rank = int(np.count_nonzero(s > max(rows, cols) * np.finfo(float).eps * smax))
    ratio = float(s[-1] / smax) if cols >= rows else 0.0
    return ExcitationReport(order, rows, cols, rank, ratio, ratio >= PE_THRESHOLD)


def check_excitation(data: DataSet, order: int, field: str) -> ExcitationReport:
    """Refuse data that are not persistently exciting of ``order`` (:class:`ConfigError`
    naming ``field``, the data table)."""
    rep = excitation(data.u, data.e, order)
    if not rep.ok:
        need = (data.n_c + 2) * order - 1
        raise ConfigError(
            field,
            f"the collected data are not rich enough: the input Hankel matrix of depth "
            f"{order} (Tini + N + n_x) is {rep.rows} x {rep.columns} with rank {rep.rank} and "
            f"sigma_min/sigma_max = {rep.ratio:.2e} < {PE_THRESHOLD:g} (persistency of "
            f"excitation); collect more samples (T >= {need} at the very least, the default "
            f"2000 is safe) with larger, i.i.d. excitation (u_amplitude, e_amplitude), or "
            f"shorten t_ini / horizon",
        )
    return rep


def _canonical(value: Any) -> Any:
    """JSON-able canonical form of settings and scenarios (dataclasses by field)."""
    if is_dataclass(value) and not isinstance(value, type):
        return {"__type__": type(value).__name__,
                **{f.name: _canonical(getattr(value, f.name)) for f in fields(value)}}
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
    if isinstance(value, list | tuple):
        return [_canonical(v) for v in value]
    if isinstance(value, np.ndarray):
        return {"shape": list(value.shape), "values": [_canonical(v) for v in value.ravel()]}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    return value


def data_key(scenario, settings: DataSettings, cavs: tuple[int, ...]) -> str:
    """SHA-256 (hex, 16 characters) of everything that determines the data."""
    base = replace(scenario, perturbations=())
    doc = {
        "version": FORMAT_VERSION,
        "scenario": _canonical(base),
        "cavs": list(cavs),
        "data": _canonical(replace(settings, cache=True, cache_dir="", field="")),
    }
    text = json.dumps(doc, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _cavs_of(scenario) -> tuple[int, ...]:
    cavs = getattr(scenario, "cavs", None)
    return tuple(int(c) for c in cavs) if cavs is not None else (int(scenario.cav),)


def collection_scenario(base, settings: DataSettings):
    """The collection scenario: ``base`` with the data table's ``dt``, ``T + 1`` samples,
    ``v_star``, ``seed``, one run, no perturbations (the head profile is added by
    :func:`collect`), starting from the equilibrium (not from a recording)."""
    from lcc_synth.simulation.scenario import Scenario

    if not isinstance(base, Scenario):
        raise TypeError("collection_scenario needs a Scenario")
    changes: dict[str, Any] = dict(
        dt=float(settings.dt), duration=(settings.T + 1) * float(settings.dt), t_start=0.0,
        batch=1, perturbations=(), seed=int(settings.seed), first_index=0, record_every=1,
        name="deep_lcc_data", initial_state=None,  # collected around the equilibrium
    )  # fmt: skip
    if settings.v_star is not None:
        changes["v_star"] = float(settings.v_star)
    if settings.hdv_accel_noise is not None:
        changes["hdv_accel_noise"] = float(settings.hdv_accel_noise)
    return replace(base, **changes)


#: Seconds a collection runs before its progress bar appears on stderr.
BAR_DELAY = 1.0


def collection_bar(steps: int):
    """The collection's progress bar on stderr (:func:`lcc_synth.resources.progress_bar`),
    shown only once the collection has run :data:`BAR_DELAY` s (a cached or quick collection
    prints nothing; ``--quiet``: never)."""
    from lcc_synth.resources import progress_bar

    return progress_bar(steps, "deep_lcc data", unit="step", delay=BAR_DELAY)


def collect(scenario, settings: DataSettings) -> DataSet:
    """Run the collection (module docstring) on the collection ``scenario``.

    Raises
    ------
    ConfigError
        A vehicle collided, or emergency braking overrode the excitation.
    """
    from lcc_synth.simulation.backends import run_scenario
    from lcc_synth.simulation.perturbations import Profile

    T, dt = int(settings.T), float(scenario.dt)
    cavs = _cavs_of(scenario)
    n_c = len(cavs)
    steps = scenario.steps  # T + 1
    rng_u = np.random.default_rng([int(settings.seed), 1])
    rng_e = np.random.default_rng([int(settings.seed), 2])
    u_cmd = rng_u.uniform(-settings.u_amplitude, settings.u_amplitude, (steps, n_c))
    e_cmd = np.zeros(steps + 1)
    e_cmd[1:steps] = rng_e.uniform(-settings.e_amplitude, settings.e_amplitude, steps - 1)
    times = scenario.t_start + dt * np.arange(steps + 1)
    accel = np.append(np.diff(e_cmd) / dt, 0.0)
    head = Profile(tuple(times.tolist()), tuple(accel.tolist()), "accel", "step", "head")
    sc = replace(scenario, perturbations=(head,))
    progress(f"deep_lcc: collecting {T} data samples at dt = {dt:g} s (seed {settings.seed})")
    with collection_bar(steps) as bar:  # in the scenario's simulator (SUMO too)
        res = run_scenario(sc, Excitation(u_cmd, bar))
    if res.collided.any():
        who = "; ".join(res.collision_report())
        raise ConfigError(settings.field, f"the data collection collided ({who}): lower "
                          "u_amplitude / e_amplitude or change the seed")  # fmt: skip
    if res.aeb_active.any():
        k = int(np.flatnonzero(res.aeb_active[0])[0])
        raise ConfigError(settings.field, f"emergency braking overrode the excitation at t = "
                          f"{res.t[k]:g} s during data collection: lower u_amplitude or "
                          "change the seed")  # fmt: skip
    v_star = float(scenario.v_star)
    vel = res.velocity[0]
    spc = res.spacing[0]
    s_ref = res.draws.initial_spacing[0]
    u = res.acceleration[0, :T][:, list(cavs)]
    e = vel[:T, 0] - v_star
    y = np.column_stack([vel[1:T + 1, 1:] - v_star,
                         spc[1:T + 1][:, list(cavs)] - s_ref[list(cavs)]])  # fmt: skip
    return DataSet(u, e, y, dt)


def collection_key(base, settings: DataSettings) -> str:
    """The cache key (:func:`data_key`) of the data of ``settings`` on ``base``'s collection
    scenario: known without collecting."""
    sc = collection_scenario(base, settings)
    return data_key(sc, settings, _cavs_of(sc))


def load_or_collect(base, settings: DataSettings) -> tuple[DataSet, str, bool]:
    """The data of ``settings`` on ``base``'s collection scenario, from the cache when present.

    Returns
    -------
    data : DataSet
    key : str
        The cache key (:func:`data_key`).
    cached : bool
        Whether the data came from the cache.
    """
    sc = collection_scenario(base, settings)
    key = collection_key(base, settings)
    path = Path(settings.cache_dir) / f"deeplcc-{key}.npz"
    if settings.cache and path.is_file():
        try:
            raw = read_file(path, f"{settings.field}.cache_dir", None,
                            "DeeP-LCC data cache", binary=True)  # fmt: skip
            with np.load(io.BytesIO(raw)) as z:
                if int(z["version"]) == FORMAT_VERSION and str(z["key"]) == key:
                    return DataSet(z["u"], z["e"], z["y"], float(z["dt"])), key, True
        except (ConfigError, OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
            pass  # unreadable or damaged: collect again and overwrite
    data = collect(sc, settings)
    if settings.cache:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            # a private temporary file, renamed atomically: concurrent runs (sweep workers)
            # collecting the same data never read a half-written cache
            tmp = path.with_name(f"{path.stem}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp.npz")
            np.savez(tmp, u=data.u, e=data.e, y=data.y, dt=data.dt, key=key,
                     version=FORMAT_VERSION)  # fmt: skip
            tmp.replace(path)
        except OSError as err:
            raise ConfigError(f"{settings.field}.cache_dir",
                              f"cannot write the data cache {path}: {err}") from None
    return data, key, False
