"""Problem files: TOML loading and field validation shared by every command.

A problem file has a few common tables, and each command reads its own:

.. code-block:: toml

    name = "paper_table2"          # optional; default: the file's stem
    description = "..."            # optional

    [hdv]                          # nonlinear HDV model (default: the paper's OVM)
    model = "ovm"                  # "ovm" | "idm"
    alpha = 0.6
    beta = 0.9
    s_st = 5.0
    s_go = 35.0
    v_max = 30.0

    [system]
    kind = "fd_lcc"                # "lcc" | "cf_lcc" | "fd_lcc" | "ccc"
    m = 0                          # HDVs ahead of the CAV (required for lcc and ccc)
    n = 10                         # HDVs behind the CAV (required for lcc, cf_lcc, fd_lcc)
    v_star = 15.0                  # equilibrium velocity (m/s)

Every table and key, with its type, default, range, unit and meaning, is declared once in
:mod:`lcc_synth.schema` (the reference page ``problems/REFERENCE.md`` is generated from it);
the loaders read keys only through it. Errors are :class:`~lcc_synth.errors.ConfigError`
naming the file and the dotted field. An unknown key or table, at any level, is an error
naming it and the closest known name (:data:`TOP_LEVEL` lists the top-level tables of every
command: a table another command reads is allowed). Values that are valid but implausible
(:func:`warn_implausible`) give an :class:`~lcc_synth.errors.ImplausibleValueWarning`.
"""

from __future__ import annotations

import math
import tomllib
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from lcc_synth.errors import ConfigError, ImplausibleValueWarning
from lcc_synth.models.gains import GAIN_MAX
from lcc_synth.models.hdv import IDM, OVM, model_from_dict
from lcc_synth.models.linear import LCCModel, model_from_hdv
from lcc_synth.models.platoon import PLATOON_KINDS, Platoon, PlatoonModel, platoon_model
from lcc_synth.schema import TOP_LEVEL, check_top_level, declared
from lcc_synth.schema import readers as _readers
from lcc_synth.schema.readers import (  # re-exported: the typed readers behind the schema
    check_range,
    get_bool,
    get_int,
    get_number,
    get_number_list,
    get_str,
    get_table,
)

__all__ = [
    "Problem",
    "load_problem",
    "MAX_FILE_BYTES",
    "TOP_LEVEL",
    "GAIN_LIMIT",
    "check_keys",
    "check_top_level",
    "warn_implausible",
    "warn_large_gains",
    "check_range",
    "get_number",
    "get_int",
    "get_bool",
    "get_str",
    "get_table",
    "get_number_list",
    "System",
    "REQUIRED_SIZES",
    "PLATOON_KINDS",
    "system_from",
]


@dataclass(frozen=True)
class Problem:
    """A parsed TOML problem file: the raw tables plus where they came from."""

    path: Path
    data: Mapping[str, Any]

    @property
    def name(self) -> str:
        value = _TOP.raw(self.data, "name", default=self.path.stem)
        if not isinstance(value, str) or not value:
            raise ConfigError("name", f"must be a non-empty string, got {value!r}", str(self.path))
        return value

    def table(self, key: str, required: bool = False) -> dict[str, Any]:
        """Top-level table ``key`` (empty dict when absent and not required)."""
        return get_table(self.data, key, key, required=required)


#: Largest problem file :func:`load_problem` reads (the shipped ones are a few KiB).
MAX_FILE_BYTES = 1 << 20


def load_problem(path: str | Path) -> Problem:
    """Read a TOML problem file; a missing, unreadable, oversized (above
    :data:`MAX_FILE_BYTES`) or binary file (:func:`lcc_synth.schema.readers.read_file`), a TOML
    syntax error or an unknown top-level key is a ConfigError naming the file."""
    p = Path(path)
    text = _readers.read_file(p, "path", str(p), "problem file", MAX_FILE_BYTES,
                              content_field="toml")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError("toml", f"not valid TOML: {err}", str(p)) from None
    except RecursionError:
        raise ConfigError("toml", "nested too deeply", str(p)) from None
    except ValueError as err:  # e.g. an integer of too many digits
        raise ConfigError("toml", f"not valid TOML: {err}", str(p)) from None
    try:
        check_top_level(data)
    except ConfigError as err:
        raise err.with_source(str(p)) from None
    return Problem(p, data)


# --------------------------------------------------------------------------------------------
# Field readers: each names the dotted field in its error
# --------------------------------------------------------------------------------------------

def check_keys(table: Mapping[str, Any], allowed: Iterable[str], field: str) -> None:
    """Reject keys of ``table`` not in ``allowed`` (typos must not pass silently); the error
    names the key and the closest allowed one. ``field = ""`` is the top level of a file
    (:func:`check_top_level`). Loaders use their declared table's ``check`` instead."""
    if not field:  # the top level of a file: one registry for every command
        check_top_level(table)
        return
    _readers.check_keys(table, allowed, field)


#: Above this magnitude a static feedback gain (per unit: 1/s² on a spacing, 1/s on a
#: velocity) is valid but implausible: the paper's gains are of order 1.
GAIN_LIMIT = 100.0


def warn_implausible(name: str, message: str) -> None:
    """Warn (:class:`ImplausibleValueWarning`, on stderr) that field ``name`` is valid but
    implausible."""
    warnings.warn(f"{name}: {message}", ImplausibleValueWarning, stacklevel=3)


def warn_large_gains(gains: Mapping[str, Any], field: str, limit: float = GAIN_LIMIT) -> None:
    """Warn for every gain of ``gains`` (a ``gains`` table) with magnitude above ``limit``
    (one beyond :data:`~lcc_synth.models.gains.GAIN_MAX` is an error, raised where the gain is
    read: :func:`lcc_synth.models.gains.valid_gain`)."""
    for key, value in gains.items():
        if isinstance(value, int | float) and not isinstance(value, bool):
            if math.isfinite(value) and limit < abs(value) <= GAIN_MAX:
                warn_implausible(
                    f"{field}.{key}",
                    f"gain {value:g} has magnitude above {limit:g} per unit (the paper's gains "
                    "are of order 1); check the units",
                )


# --------------------------------------------------------------------------------------------
# Common tables: [hdv] and [system]
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class System:
    """The ``[hdv]`` + ``[system]`` tables: nonlinear HDV model, layout and equilibrium.

    For ``kind = "platoon"`` / ``"ring"`` the layout is ``platoon`` (``size`` vehicles,
    CAVs at ``cavs``, per-vehicle HDV models); ``m`` and ``n`` are then the vehicles ahead of
    and behind the first CAV (``m = size``, ``n = 0`` without a CAV).
    """

    kind: str
    m: int
    n: int
    v_star: float
    hdv: OVM | IDM
    platoon: Platoon | None = None

    @property
    def s_star(self) -> float:
        """Equilibrium spacing of the HDV model at ``v_star``."""
        return float(self.hdv.equilibrium_spacing(self.v_star))

    @property
    def ring(self) -> bool:
        """Whether the road is a ring (``kind = "ring"``); the paper's strings are open."""
        return self.platoon is not None and self.platoon.ring

    @property
    def numbering(self) -> tuple[int, bool] | None:
        """How the vehicles of this layout are named: ``(size, ring)`` when by position
        ``1..size`` (a platoon or ring), ``None`` when by the paper's index ``-m..n`` from the
        CAV (:func:`lcc_synth.simulation.perturbations.vehicle_column` reads either)."""
        return None if self.platoon is None else (self.platoon.size, self.platoon.ring)

    @property
    def vehicle_length(self) -> float:
        """Length (m) of every vehicle: the platoon's or ring's ``vehicle_length``, 0 for the
        paper's strings (point vehicles)."""
        return 0.0 if self.platoon is None else self.platoon.vehicle_length

    @property
    def columns(self) -> int:
        """Vehicles the simulator runs: ``m + n + 2`` (the head included), ``size`` on a ring."""
        return self.platoon.size if self.ring else self.m + self.n + 2

    def linear_model(self, warn: bool = True) -> LCCModel | PlatoonModel:
        """The linearised model of this system (homogeneous for the paper's kinds; each
        vehicle at its own equilibrium for a platoon or ring)."""
        if self.platoon is not None:
            return platoon_model(self.platoon, warn=warn)
        return model_from_hdv(self.kind, self.m, self.n, self.hdv, self.v_star, warn=warn)


#: The sizes each kind of system must state: a size the kind fixes (m = 0 for CF-/FD-LCC, n = 0
#: for CCC) may be left out, a size it leaves free may not (it never silently becomes 0).
REQUIRED_SIZES = {"lcc": ("m", "n"), "cf_lcc": ("n",), "fd_lcc": ("n",), "ccc": ("m",),
                  "platoon": ("size",), "ring": ("size",)}
_SIZE_MEANING = {"m": "HDVs ahead of the CAV", "n": "HDVs behind the CAV",
                 "size": "vehicles (the head not counted)"}
_TOP = declared("")
_SYSTEM = declared("system")


def system_from(data: Mapping[str, Any], source: str | None = None) -> System:
    """Parse ``[hdv]`` and ``[system]`` of a problem file into a :class:`System`
    (the sizes of :data:`REQUIRED_SIZES` must be given)."""
    try:
        hdv = model_from_dict(_TOP.get(data, "hdv", ""), "hdv")
        sys_t = _TOP.get(data, "system", "")
        _SYSTEM.check(sys_t, "system")
        kind = _SYSTEM.get(sys_t, "kind", "system")
        for key in REQUIRED_SIZES[kind]:
            if key not in sys_t:
                size = _SYSTEM.key(key)
                raise ConfigError(
                    f"system.{key}",
                    f"is required for kind = {kind!r}{'' if 'kind' in sys_t else ' (the default)'}"
                    f": the number of {_SIZE_MEANING[key]}, an integer in [{size.lo}, {size.hi}]",
                )
        if kind in PLATOON_KINDS:
            return _platoon_system(kind, sys_t, hdv)
        for key in ("size", "cavs", "circumference", "hdv_values", "vehicle_length"):
            if key in sys_t:
                if key != "cavs":  # a value out of range: that error first
                    _SYSTEM.get(sys_t, key, "system")
                raise ConfigError(
                    f"system.{key}", f"only kind = 'platoon' or 'ring' has one (kind = {kind!r})"
                )
        m = _SYSTEM.get(sys_t, "m", "system")
        n = _SYSTEM.get(sys_t, "n", "system")
        v_star = _SYSTEM.get(sys_t, "v_star", "system")
        try:
            hdv.equilibrium_spacing(v_star)
        except ConfigError as err:
            raise ConfigError("system.v_star", err.message) from None
        if kind in ("cf_lcc", "fd_lcc") and m != 0:
            raise ConfigError("system.m", f"must be 0 for {kind}, got {m}")
        if kind in ("cf_lcc", "fd_lcc") and n < 1:
            raise ConfigError("system.n", f"must be >= 1 for {kind}, got {n}")
        if kind == "ccc" and n != 0:
            raise ConfigError("system.n", f"must be 0 for ccc, got {n}")
        return System(kind, m, n, v_star, hdv)
    except ConfigError as err:
        raise err.with_source(source) if source and not err.source else err from None


def _platoon_system(kind: str, sys_t: Mapping[str, Any], hdv: OVM | IDM) -> System:
    """The :class:`System` of a ``platoon`` or ``ring`` table."""
    for key in ("m", "n"):
        if key in sys_t:
            raise ConfigError(
                f"system.{key}", f"is not used by kind = {kind!r}: give size and cavs instead"
            )
    size = _SYSTEM.get(sys_t, "size", "system")
    cavs = _SYSTEM.raw(sys_t, "cavs")
    if not isinstance(cavs, list) or any(
        isinstance(c, bool) or not isinstance(c, int) for c in cavs
    ):
        raise ConfigError(
            "system.cavs", f"must be a list of integer positions in [1, {size}], got {cavs!r}"
        )
    ring = kind == "ring"
    circumference = _SYSTEM.get(sys_t, "circumference", "system")
    v_star = _SYSTEM.get(sys_t, "v_star", "system")
    if ring and circumference is not None:
        if "v_star" in sys_t:
            raise ConfigError(
                "system.circumference",
                "give system.v_star or system.circumference for a ring, not both",
            )
        v_star = None
    hv_t = _SYSTEM.get(sys_t, "hdv_values", "system")
    params = [f.name for f in fields(hdv) if f.name != "name"]
    HV = declared("system.hdv_values")
    HV.check(hv_t, "system.hdv_values", allowed=params)
    each = HV.get_each(hv_t, "system.hdv_values", length=size)
    models = []
    for i in range(size):
        kw = {key: float(vals[i]) for key, vals in each.items()}
        try:
            models.append(replace(hdv, **kw))
        except ConfigError as err:
            raise ConfigError(
                f"system.hdv_values.{err.field}", f"vehicle {i + 1}: {err.message}"
            ) from None
    length = _SYSTEM.get(sys_t, "vehicle_length", "system")
    platoon = Platoon(tuple(models), tuple(cavs), v_star, ring, circumference, length)
    first = platoon.cavs[0] if platoon.cavs else size + 1
    return System(kind, first - 1, size + 1 - first, float(platoon.v_star), hdv, platoon)
