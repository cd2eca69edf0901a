"""Problem-file tables of the ``regions`` command: ``[regions]`` and ``[maps.NAME]`` (Figs. 7-8).

``[maps.NAME]`` names the vehicle whose gains ``(mu_i, k_i)`` vary, the fixed gains of the
others, the grid and an optional baseline map (the expansion of Fig. 7(c)-(f) over Fig. 7(a)(b));
``[regions]`` holds the shared grid and frequency options. The maps themselves are computed by
:func:`lcc_synth.analysis.regions.region_map`.

On an open platoon (``kind = "platoon"``) the table speaks the platoon's vocabulary: ``cav``
is the position of the CAV whose gains vary (may be left out with one CAV), ``vehicle`` a
position in that CAV's segment (an HDV between the neighbouring CAVs) and ``gains`` the other
gains as per-CAV tables, ``gains.u_5 = { s_6 = 0.5, v_6 = -0.5 }``. A gain that crosses into
another CAV's segment, a map vehicle another CAV hears, and a ring (no head vehicle) are
ConfigErrors naming the field (:func:`lcc_synth.analysis.regions.platoon_segments`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from lcc_synth.analysis.regions import (
    STRING_STABLE,
    RegionMap,
    platoon_segments,
    region_frequency_grid,
    region_map,
)
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.models.linear import LCCModel

__all__ = [
    "grid_axis", "RegionSpec", "region_specs_from", "regions_tables", "run_region_specs",
    "expansion",
]  # fmt: skip


def grid_axis(
    lo: float, hi: float, step: float, field_name: str = "grid", step_field: str | None = None
) -> np.ndarray:
    """Inclusive grid ``lo, lo + step, ..., hi`` (``hi`` kept when it is on the lattice).

    Errors name ``field_name`` (the range) or ``step_field`` (default ``field_name.step``).
    """
    step_field = step_field or f"{field_name}.step"
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ConfigError(field_name, f"must be [low, high] with low < high, got {[lo, hi]}")
    if not (np.isfinite(step) and step > 0):
        raise ConfigError(step_field, f"must be > 0, got {step}")
    count = int(np.floor((hi - lo) / step + 1e-9)) + 1
    if count > 20001:
        raise ConfigError(
            step_field, f"gives {count} points on {field_name} = [{lo}, {hi}]; at most 20001"
        )
    return lo + step * np.arange(count)


@dataclass(frozen=True)
class RegionSpec:
    """One ``[maps.NAME]`` table: which vehicle's gains vary, the fixed gains, the grid
    (``cav``: the CAV position of an open platoon's map, ``None`` for one CAV)."""

    name: str
    vehicle: int
    mu: np.ndarray
    k: np.ndarray
    gains: Gains
    baseline: str | None = None
    title: str = ""
    cav: int | None = None

    def toml_table(self) -> dict:
        """The ``[maps.NAME]`` table of this map, its grid explicit (``mu``, ``k``, ``step``);
        a grid that :func:`grid_axis` does not rebuild bit for bit is a ConfigError."""
        (mu, st), (k, st_k) = (_axis_table(a, f"maps.{self.name}.{n}")
                               for a, n in ((self.mu, "mu"), (self.k, "k")))  # fmt: skip
        if st != st_k:
            raise ConfigError(f"maps.{self.name}.step", "mu and k have different steps")
        out = {"title": self.title, "vehicle": int(self.vehicle), "semantics":
               self.gains.semantics, "gains": self.gains.as_table(), "baseline": self.baseline,
               "mu": mu, "k": k, "step": st}  # fmt: skip
        return out if self.cav is None else {**out, "cav": int(self.cav)}


def _axis_table(axis: np.ndarray, field_name: str) -> tuple[list[float], float]:
    """``([lo, hi], step)`` that :func:`grid_axis` turns into ``axis`` exactly."""
    if axis.size >= 2:
        step = float(f"{(axis[-1] - axis[0]) / (axis.size - 1):.12g}")
        hi = float(f"{axis[-1]:.12g}")
        if np.array_equal(grid_axis(float(axis[0]), hi, step), axis):
            return [float(axis[0]), hi], step
    raise ConfigError(field_name, "this grid is not lo, lo + step, ..., hi: no TOML form")


def region_specs_from(
    data: Mapping, model: LCCModel, source: str | None = None, step: float | None = None
) -> tuple[dict[str, RegionSpec], np.ndarray]:
    """Parse ``[regions]`` (grid and frequency defaults) and ``[maps.NAME]`` tables.

    ``step`` (e.g. from the command line) overrides every grid step. Returns the specs in file
    order and the frequency grid. Errors name the dotted field and the file.
    """
    from lcc_synth.problem import warn_large_gains
    from lcc_synth.schema import declared

    try:
        platoon = model.kind == "platoon"
        if model.kind == "fd_lcc" or not (platoon or tuple(model.cavs) == (0,)):
            raise ConfigError(
                "system.kind", "region maps (Figs. 7-8) vary one CAV's gains behind a head "
                f"vehicle (lcc, cf_lcc, ccc or an open platoon), not {model.kind}"
                + (": a ring has no head vehicle" if model.kind == "ring" else "")
            )
        R = declared("regions")
        opts = declared("").get(data, "regions", "")
        R.check(opts, "regions")
        d_step = R.get(opts, "step", "regions")
        d_mu = R.get(opts, "mu", "regions")
        d_k = R.get(opts, "k", "regions")
        step_field = "--step" if step is not None else "regions.step"
        d_step_used = step if step is not None else d_step
        mu_default = grid_axis(*d_mu, d_step_used, "regions.mu", step_field)
        k_default = grid_axis(*d_k, d_step_used, "regions.k", step_field)
        w_lo = R.get(opts, "omega_min", "regions")
        w_hi = R.get(opts, "omega_max", "regions", lo=w_lo)
        per_dec = R.get(opts, "per_decade", "regions")
        dn_lo = R.get(opts, "dense_min", "regions")
        dn_hi = R.get(opts, "dense_max", "regions", lo=dn_lo)
        dn_per = R.get(opts, "dense_per_decade", "regions")
        omega = region_frequency_grid(w_lo, w_hi, per_dec, (dn_lo, dn_hi), dn_per)

        maps = declared("").get(data, "maps", "")
        M = declared("maps.NAME")
        if not maps:
            raise ConfigError("maps", "needs at least one [maps.NAME] table")
        allowed_vehicles = [i for i in model.vehicles if i != 0]
        specs: dict[str, RegionSpec] = {}
        for name, t in maps.items():
            field = f"maps.{name}"
            if not isinstance(t, dict):
                raise ConfigError(field, f"must be a table, got {t!r}")
            M.check(t, field)
            vehicle = M.get(t, "vehicle", field)
            if platoon:
                specs[name] = _platoon_spec(name, t, model, M, vehicle)
            elif "cav" in t:
                raise ConfigError(f"{field}.cav", f"is for kind = 'platoon' (the CAV whose "
                                  f"gains vary); a {model.kind} system has one CAV: remove "
                                  "it")  # fmt: skip
            elif vehicle not in allowed_vehicles:
                raise ConfigError(
                    f"{field}.vehicle",
                    f"must be one of {allowed_vehicles} (an HDV of this m={model.m}, "
                    f"n={model.n} system), got {vehicle}",
                )
            if not platoon:
                semantics = M.get(t, "semantics", field)
                raw = M.get(t, "gains", field)
                warn_large_gains(raw, f"{field}.gains")
                try:
                    gains = Gains.named(raw, semantics)
                    gains.check(model)
                except ConfigError as err:
                    raise ConfigError(f"{field}.{err.field}", err.message) from None
                for own in (f"s_{vehicle}", f"v_{vehicle}"):
                    if own in gains.gains:
                        raise ConfigError(
                            f"{field}.gains.{own}", "is the map's own axis; remove it from gains"
                        )
            if any(key in t for key in ("mu", "k", "step")):
                st = step if step is not None else M.get(t, "step", field, default=d_step)
                sf = step_field if step is not None else f"{field}.step"
                lo_hi = M.get(t, "mu", field, default=d_mu)
                mu = grid_axis(*lo_hi, st, f"{field}.mu", sf)
                lo_hi = M.get(t, "k", field, default=d_k)
                k = grid_axis(*lo_hi, st, f"{field}.k", sf)
            else:
                mu, k = mu_default, k_default
            baseline = M.get(t, "baseline", field)
            title = M.get(t, "title", field, default=name)
            if platoon:
                p = specs[name]
                specs[name] = RegionSpec(name, vehicle, mu, k, p.gains, baseline, title, p.cav)
            else:
                specs[name] = RegionSpec(name, vehicle, mu, k, gains, baseline, title)
        for name, spec in specs.items():
            if spec.baseline is None:
                continue
            base = specs.get(spec.baseline)
            if base is None:
                raise ConfigError(
                    f"maps.{name}.baseline", f"names no map; maps: {sorted(specs)}"
                )
            if (
                base.vehicle != spec.vehicle
                or base.cav != spec.cav
                or base.mu.shape != spec.mu.shape
                or base.k.shape != spec.k.shape
                or not np.allclose(base.mu, spec.mu)
                or not np.allclose(base.k, spec.k)
            ):
                raise ConfigError(
                    f"maps.{name}.baseline",
                    f"map {spec.baseline!r} must have the same vehicle, CAV and grid",
                )
        return specs, omega
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None


def _platoon_spec(name: str, t: Mapping, model, M, vehicle: int) -> RegionSpec:
    """The CAV, vehicle and fixed gains of an open platoon's ``[maps.NAME]`` (grid and title
    filled in by :func:`region_specs_from`); errors name ``maps.NAME.FIELD``."""
    from lcc_synth.problem import warn_large_gains

    field_ = f"maps.{name}"
    cav = M.get(t, "cav", field_)
    if cav is None and len(model.cavs) == 1:
        cav = model.cavs[0]
    semantics = M.get(t, "semantics", field_)
    raw = M.get(t, "gains", field_)
    for u, row in raw.items():
        if isinstance(row, Mapping):
            warn_large_gains(row, f"{field_}.gains.{u}")
    try:
        gains = Gains.from_table(raw, model, semantics, field="gains")
        platoon_segments(model, gains, cav, vehicle)
    except ConfigError as err:
        raise ConfigError(f"{field_}.{err.field}", err.message) from None
    own = raw.get(f"u_{cav}", {})
    for state in (f"s_{vehicle}", f"v_{vehicle}"):
        if state in own:
            raise ConfigError(
                f"{field_}.gains.u_{cav}.{state}", "is the map's own axis; remove it from gains"
            )
    return RegionSpec(name, vehicle, np.empty(0), np.empty(0), gains, cav=int(cav))


def regions_tables(specs: Mapping[str, RegionSpec], omega: np.ndarray) -> dict:
    """The ``[maps.*]`` tables of ``specs`` (:meth:`RegionSpec.toml_table`); the frequency
    grid must be the default one (:func:`region_frequency_grid`), which ``[regions]`` then
    leaves out: other grids have no TOML form (ConfigError)."""
    if not np.array_equal(omega, region_frequency_grid()):
        raise ConfigError("regions", "only the default frequency grid has a TOML form")
    return {"maps": {name: spec.toml_table() for name, spec in specs.items()}}


def run_region_specs(
    model: LCCModel,
    specs: Mapping[str, RegionSpec],
    omega: np.ndarray | None = None,
    on_rows: Callable[[str, int], None] | None = None,
) -> dict[str, RegionMap]:
    """Compute every map of :func:`region_specs_from`; ``on_rows(name, rows)`` after each chunk
    of ``rows`` grid rows of map ``name`` (a progress bar)."""
    out = {}
    for name, s in specs.items():
        step = None if on_rows is None else (lambda rows, name=name: on_rows(name, rows))
        out[name] = region_map(model, s.vehicle, s.mu, s.k, gains=s.gains, omega=omega,
                               name=name, on_rows=step, cav=s.cav)  # fmt: skip
    return out


def expansion(rm: RegionMap, baseline: RegionMap) -> dict[str, float | bool]:
    """How ``rm`` changes the string-stable set of ``baseline`` (same grid): fraction gained,
    fraction lost and whether the baseline region is kept entirely (Fig. 7(c)-(f))."""
    a = baseline.labels == STRING_STABLE
    b = rm.labels == STRING_STABLE
    return {
        "gained_fraction": float(np.count_nonzero(b & ~a)) / a.size,
        "lost_fraction": float(np.count_nonzero(a & ~b)) / a.size,
        "contains_baseline": bool(not np.any(a & ~b)),
    }
