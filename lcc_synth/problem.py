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

Errors are :class:`~lcc_synth.errors.ConfigError` naming the file and the dotted field. An
unknown key or table, at any level, is an error naming it and the closest known name
(:data:`TOP_LEVEL` lists the top-level tables of every command: a table another command reads
is allowed). Values that are valid but implausible (:func:`warn_implausible`) give an
:class:`~lcc_synth.errors.ImplausibleValueWarning`.
"""

from __future__ import annotations

import difflib
import math
import tomllib
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lcc_synth.errors import ConfigError, ImplausibleValueWarning
from lcc_synth.models.hdv import IDM, OVM, model_from_dict
from lcc_synth.models.linear import KINDS, LCCModel, model_from_hdv

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
    "system_from",
]


@dataclass(frozen=True)
class Problem:
    """A parsed TOML problem file: the raw tables plus where they came from."""

    path: Path
    data: Mapping[str, Any]

    @property
    def name(self) -> str:
        value = self.data.get("name", self.path.stem)
        if not isinstance(value, str) or not value:
            raise ConfigError("name", f"must be a non-empty string, got {value!r}", str(self.path))
        return value

    def table(self, key: str, required: bool = False) -> dict[str, Any]:
        """Top-level table ``key`` (empty dict when absent and not required)."""
        return get_table(self.data, key, key, required=required)


#: Largest problem file :func:`load_problem` reads (the shipped ones are a few KiB).
MAX_FILE_BYTES = 1 << 20


def load_problem(path: str | Path) -> Problem:
    """Read a TOML problem file; a missing, oversized (above :data:`MAX_FILE_BYTES`) or binary
    file, a TOML syntax error or an unknown top-level key is a ConfigError."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError("path", "no such problem file", str(p))
    size = p.stat().st_size
    if size > MAX_FILE_BYTES:
        raise ConfigError(
            "path",
            f"is {size / 2**20:.1f} MiB; a problem file is a small text file "
            f"(at most {MAX_FILE_BYTES // 2**20} MiB)",
            str(p),
        )
    try:
        with p.open("rb") as fh:
            data = tomllib.loads(fh.read().decode("utf-8"))
    except UnicodeDecodeError as err:
        raise ConfigError(
            "toml", f"not a UTF-8 text file (byte {err.start}): a binary file?", str(p)
        ) from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError("toml", f"not valid TOML: {err}", str(p)) from None
    except RecursionError:
        raise ConfigError("toml", "nested too deeply", str(p)) from None
    try:
        check_top_level(data)
    except ConfigError as err:
        raise err.with_source(str(p)) from None
    return Problem(p, data)


#: Every top-level key of a problem file, with the commands that read it. One registry for all
#: commands: a file may carry the tables of several commands (each reads its own, ignores the
#: others), but a key no command reads is an error naming the closest known one.
TOP_LEVEL: dict[str, tuple[str, ...]] = {
    "name": ("all",),
    "description": ("all",),
    "hdv": ("all",),
    "system": ("simulate", "sweep", "synthesize", "analyze", "regions"),
    "scenario": ("simulate", "sweep"),
    "metrics": ("simulate", "sweep", "run"),
    "controllers": ("simulate", "sweep", "run"),
    "sweep": ("sweep",),
    "layouts": ("run",),
    "scenarios": ("run",),
    "synthesis": ("synthesize",),
    "analysis": ("analyze",),
    "cases": ("analyze",),
    "regions": ("regions",),
    "maps": ("regions",),
}

_SCALAR_TOP = ("name", "description")


def check_top_level(data: Mapping[str, Any]) -> None:
    """Reject top-level keys of a problem file that no command reads (see :data:`TOP_LEVEL`)."""
    for key, value in data.items():
        if key in TOP_LEVEL:
            continue
        close = difflib.get_close_matches(key, list(TOP_LEVEL), n=1, cutoff=0.6)
        if isinstance(value, dict):
            hint = f"; did you mean [{close[0]}]?" if close else "."
            known = ", ".join(f"[{k}]" for k in TOP_LEVEL if k not in _SCALAR_TOP)
            raise ConfigError(key, f"unknown table [{key}]{hint} Known tables: {known}")
        hint = f"; did you mean {close[0]!r}?" if close else "."
        raise ConfigError(
            key, f"unknown top-level key{hint} Known keys: name, description and the tables"
        )


# --------------------------------------------------------------------------------------------
# Field readers: each names the dotted field in its error
# --------------------------------------------------------------------------------------------

_MISSING = object()


def check_keys(table: Mapping[str, Any], allowed: Iterable[str], field: str) -> None:
    """Reject keys of ``table`` not in ``allowed`` (typos must not pass silently); the error
    names the key and the closest allowed one."""
    if not field:  # the top level of a file: one registry for every command
        check_top_level(table)
        return
    allowed = set(allowed)
    for key in table:
        if key not in allowed:
            where = f"{field}.{key}" if field else key
            close = difflib.get_close_matches(str(key), sorted(allowed), n=1, cutoff=0.6)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise ConfigError(where, f"unknown key; {hint}allowed keys: {sorted(allowed)}")


#: Above this magnitude a static feedback gain (per unit: 1/s² on a spacing, 1/s on a
#: velocity) is valid but implausible: the paper's gains are of order 1.
GAIN_LIMIT = 100.0


def warn_implausible(name: str, message: str) -> None:
    """Warn (:class:`ImplausibleValueWarning`, on stderr) that field ``name`` is valid but
    implausible."""
    warnings.warn(f"{name}: {message}", ImplausibleValueWarning, stacklevel=3)


def warn_large_gains(gains: Mapping[str, Any], field: str, limit: float = GAIN_LIMIT) -> None:
    """Warn for every gain of ``gains`` (a ``gains`` table) with magnitude above ``limit``."""
    for key, value in gains.items():
        if isinstance(value, int | float) and not isinstance(value, bool):
            if math.isfinite(value) and abs(value) > limit:
                warn_implausible(
                    f"{field}.{key}",
                    f"gain {value:g} has magnitude above {limit:g} per unit (the paper's gains "
                    "are of order 1); check the units",
                )


def _lookup(table: Mapping[str, Any], key: str, field: str, default: Any, requirement: str):
    """``(dotted name, value, present)``: ``table[key]``, or ``default`` when absent (a required
    key, ``default is _MISSING``, raises naming the field and ``requirement``)."""
    name = f"{field}.{key}" if field else key
    if key in table:
        return name, table[key], True
    if default is _MISSING:
        raise ConfigError(name, f"is required{requirement}")
    return name, default, False


def _fmt_range(lo, hi, lo_open, hi_open) -> str:
    parts = []
    if lo is not None:
        parts.append(f"{'>' if lo_open else '>='} {lo}")
    if hi is not None:
        parts.append(f"{'<' if hi_open else '<='} {hi}")
    return " and ".join(parts) if parts else "a finite number"


def get_number(
    table: Mapping[str, Any],
    key: str,
    field: str,
    default: Any = _MISSING,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
) -> float:
    """A finite number ``table[key]`` within the bounds; ``default`` when absent."""
    name, value, present = _lookup(
        table, key, field, default, f" ({_fmt_range(lo, hi, lo_open, hi_open)})"
    )
    if not present:
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(name, f"must be a number, got {value!r}")
    return check_range(name, float(value), lo, hi, lo_open, hi_open)


def check_range(
    name: str,
    value: float,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    shown: Any = _MISSING,
) -> float:
    """``value`` when finite and within the bounds, else a :class:`ConfigError` for ``name``
    (``shown``, default ``value``, is what the message says was given)."""
    ok = math.isfinite(value)
    if ok and lo is not None:
        ok = value > lo if lo_open else value >= lo
    if ok and hi is not None:
        ok = value < hi if hi_open else value <= hi
    if not ok:
        shown = value if shown is _MISSING else shown
        raise ConfigError(name, f"must be {_fmt_range(lo, hi, lo_open, hi_open)}, got {shown!r}")
    return value


def get_int(
    table: Mapping[str, Any],
    key: str,
    field: str,
    default: Any = _MISSING,
    lo: int | None = None,
    hi: int | None = None,
) -> int:
    """An integer ``table[key]`` in ``[lo, hi]``; ``default`` when absent."""
    name, value, present = _lookup(
        table, key, field, default, f" (an integer {_fmt_range(lo, hi, 0, 0)})"
    )
    if not present:
        return value
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(name, f"must be an integer, got {value!r}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ConfigError(name, f"must be an integer {_fmt_range(lo, hi, 0, 0)}, got {value}")
    return value


def get_bool(table: Mapping[str, Any], key: str, field: str, default: Any = _MISSING) -> bool:
    """A boolean ``table[key]``; ``default`` when absent."""
    name, value, present = _lookup(table, key, field, default, " (true or false)")
    if not present:
        return value
    if not isinstance(value, bool):
        raise ConfigError(name, f"must be true or false, got {value!r}")
    return value


def get_str(
    table: Mapping[str, Any],
    key: str,
    field: str,
    default: Any = _MISSING,
    choices: Iterable[str] | None = None,
) -> str:
    """A string ``table[key]``, one of ``choices`` when given; ``default`` when absent."""
    extra = f" (one of {sorted(choices)})" if choices is not None else ""
    name, value, present = _lookup(table, key, field, default, extra)
    if not present:
        return value
    if not isinstance(value, str):
        raise ConfigError(name, f"must be a string, got {value!r}")
    if choices is not None and value not in set(choices):
        raise ConfigError(name, f"must be one of {sorted(choices)}, got {value!r}")
    return value


def get_table(
    table: Mapping[str, Any], key: str, field: str, required: bool = False
) -> dict[str, Any]:
    """A sub-table ``table[key]`` (empty dict when absent and not required)."""
    if key not in table:
        if required:
            raise ConfigError(field, "table is required")
        return {}
    value = table[key]
    if not isinstance(value, dict):
        raise ConfigError(field, f"must be a table, got {value!r}")
    return value


def get_number_list(
    table: Mapping[str, Any],
    key: str,
    field: str,
    default: Any = _MISSING,
    length: int | None = None,
    lo: float | None = None,
    hi: float | None = None,
) -> list[float]:
    """A list of finite numbers (optionally of fixed ``length`` and within bounds)."""
    name, value, present = _lookup(table, key, field, default, " (a list of numbers)")
    if not present:
        return value
    if not isinstance(value, list):
        raise ConfigError(name, f"must be a list of numbers, got {value!r}")
    if length is not None and len(value) != length:
        raise ConfigError(name, f"must have {length} entries, got {len(value)}")
    wrapper = {str(i): v for i, v in enumerate(value)}
    return [get_number(wrapper, str(i), name, lo=lo, hi=hi) for i in range(len(value))]


# --------------------------------------------------------------------------------------------
# Common tables: [hdv] and [system]
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class System:
    """The ``[hdv]`` + ``[system]`` tables: nonlinear HDV model, layout and equilibrium."""

    kind: str
    m: int
    n: int
    v_star: float
    hdv: OVM | IDM

    @property
    def s_star(self) -> float:
        """Equilibrium spacing of the HDV model at ``v_star``."""
        return float(self.hdv.equilibrium_spacing(self.v_star))

    def linear_model(self, warn: bool = True) -> LCCModel:
        """The homogeneous linearised model of this system."""
        return model_from_hdv(self.kind, self.m, self.n, self.hdv, self.v_star, warn=warn)


#: The sizes each kind of system must state: a size the kind fixes (m = 0 for CF-/FD-LCC, n = 0
#: for CCC) may be left out, a size it leaves free may not (it never silently becomes 0).
REQUIRED_SIZES = {"lcc": ("m", "n"), "cf_lcc": ("n",), "fd_lcc": ("n",), "ccc": ("m",)}
_SIZE_MEANING = {"m": "HDVs ahead of the CAV", "n": "HDVs behind the CAV"}
_SIZE_MAX = {"m": 50, "n": 200}


def system_from(data: Mapping[str, Any], source: str | None = None) -> System:
    """Parse ``[hdv]`` and ``[system]`` of a problem file into a :class:`System`
    (the sizes of :data:`REQUIRED_SIZES` must be given)."""
    try:
        hdv = model_from_dict(get_table(data, "hdv", "hdv"), "hdv")
        sys_t = get_table(data, "system", "system", required=True)
        check_keys(sys_t, ["kind", "m", "n", "v_star"], "system")
        kind = get_str(sys_t, "kind", "system", "lcc", choices=KINDS)
        for key in REQUIRED_SIZES[kind]:
            if key not in sys_t:
                raise ConfigError(
                    f"system.{key}",
                    f"is required for kind = {kind!r}{'' if 'kind' in sys_t else ' (the default)'}"
                    f": the number of {_SIZE_MEANING[key]}, an integer in [0, {_SIZE_MAX[key]}]",
                )
        m = get_int(sys_t, "m", "system", 0, lo=0, hi=50)
        n = get_int(sys_t, "n", "system", 0, lo=0, hi=200)
        v_star = get_number(sys_t, "v_star", "system", 15.0, lo=0.0, lo_open=True)
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
