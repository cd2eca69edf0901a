"""Typed field readers of problem-file tables, each naming the dotted field in its error, and
the one reader of user files (:func:`read_file`, :func:`read_json`).

These are the primitives behind :class:`lcc_synth.schema.Table`: a loader never calls them with
its own default or range, it asks the declared key (``declared("scenario").get(sc, "dt", f)``),
which passes the declared default, bounds and choices here. The messages are those of the
strict-inputs corpus (``tests/test_strict_problems.py``): ``FIELD: must be > 0, got -1.0``,
``FIELD: is required (>= 0)``, ``FIELD: unknown key; did you mean 'dt'? allowed keys: [...]``.

Every file the package reads from a user (a problem file, a gains file, a profile CSV, a
DeeP-LCC data cache) is read by :func:`read_file` (:func:`read_json` for JSON): a missing,
unreadable (permissions, a directory, an I/O error), oversized, binary or UTF-16 file, and
invalid or too deeply nested JSON, is a :class:`~lcc_synth.errors.ConfigError` naming the field
that named the file, the file itself and the reason, never a traceback.
"""

from __future__ import annotations

import difflib
import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from lcc_synth.errors import ConfigError

__all__ = [
    "MAX_DATA_BYTES",
    "REQUIRED",
    "check_keys",
    "check_range",
    "fmt_range",
    "get_bool",
    "get_int",
    "get_number",
    "get_number_list",
    "get_str",
    "get_table",
    "read_file",
    "read_json",
]

#: The default of a required key.
REQUIRED = _MISSING = object()


def check_keys(table: Mapping[str, Any], allowed: Iterable[str], field: str) -> None:
    """Reject keys of ``table`` not in ``allowed`` (typos must not pass silently); the error
    names the key and the closest allowed one."""
    allowed = set(allowed)
    for key in table:
        if key not in allowed:
            where = f"{field}.{key}" if field else key
            close = difflib.get_close_matches(str(key), sorted(allowed), n=1, cutoff=0.6)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise ConfigError(where, f"unknown key; {hint}allowed keys: {sorted(allowed)}")


def _lookup(table: Mapping[str, Any], key: str, field: str, default: Any, requirement: str):
    """``(dotted name, value, present)``: ``table[key]``, or ``default`` when absent (a required
    key, ``default is _MISSING``, raises naming the field and ``requirement``)."""
    name = f"{field}.{key}" if field else key
    if key in table:
        return name, table[key], True
    if default is _MISSING:
        raise ConfigError(name, f"is required{requirement}")
    return name, default, False


def fmt_range(lo, hi, lo_open, hi_open) -> str:
    """A range as error text, e.g. ``>= 0 and < 1`` (``a finite number`` without bounds)."""
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
        table, key, field, default, f" ({fmt_range(lo, hi, lo_open, hi_open)})"
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
        raise ConfigError(name, f"must be {fmt_range(lo, hi, lo_open, hi_open)}, got {shown!r}")
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
        table, key, field, default, f" (an integer {fmt_range(lo, hi, 0, 0)})"
    )
    if not present:
        return value
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(name, f"must be an integer, got {value!r}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ConfigError(name, f"must be an integer {fmt_range(lo, hi, 0, 0)}, got {value}")
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
# User files
# --------------------------------------------------------------------------------------------

#: Largest data file (gains JSON, profile CSV, data cache) :func:`read_file` reads by default:
#: the gains file of a 400-vehicle ring is a few MiB; a larger file is not one of them.
MAX_DATA_BYTES = 64 << 20

#: Byte-order marks of UTF-16 and UTF-32 text (a text editor's "Unicode" encoding).
_BOMS = {b"\xff\xfe\x00\x00": "UTF-32", b"\x00\x00\xfe\xff": "UTF-32",
         b"\xff\xfe": "UTF-16", b"\xfe\xff": "UTF-16"}  # fmt: skip


def _file_error(path: Path, field: str, source: str | None, reason: str) -> ConfigError:
    """``SOURCE: FIELD: PATH: REASON`` (the path left out when it is the source itself)."""
    where = "" if source is not None and str(path) == str(source) else f"{path}: "
    return ConfigError(field, f"{where}{reason}", source)


def read_file(
    path: str | Path,
    field: str,
    source: str | None = None,
    what: str = "file",
    max_bytes: int = MAX_DATA_BYTES,
    binary: bool = False,
    content_field: str | None = None,
) -> str | bytes:
    """The contents of a user file: UTF-8 text (``binary``: the bytes).

    Parameters
    ----------
    path : str or Path
        The file.
    field : str
        The field that named it (``"controllers.NAME.file"``); the error names it.
    source : str, optional
        The problem file that holds ``field`` (``None``: the file is not named by one).
    what : str
        What the file is, for the messages (``"gains file"``).
    max_bytes : int
        Largest size read (:data:`MAX_DATA_BYTES` by default).
    binary : bool
        Return the bytes (no decoding).
    content_field : str, optional
        The field of an error in the contents (not UTF-8); default ``field``. A problem file
        names ``toml`` there, ``path`` for the file itself.

    Raises
    ------
    ConfigError
        ``field``, naming ``path``: no such file; not a regular file; cannot be read (the
        operating system's reason, e.g. "Permission denied"); larger than ``max_bytes``; not
        UTF-8 text (a binary, UTF-16 or UTF-32 file).
    """
    p = Path(path)
    try:
        if not p.exists():
            raise _file_error(p, field, source, f"no such {what}")
        if not p.is_file():
            raise _file_error(p, field, source, f"is not a regular file (a {what} is expected)")
        with p.open("rb") as fh:
            data = fh.read(max_bytes + 1)
    except OSError as err:
        reason = err.strerror or str(err) or type(err).__name__
        raise _file_error(p, field, source, f"cannot read the {what}: {reason}") from None
    if len(data) > max_bytes:
        size = p.stat().st_size if p.exists() else len(data)
        limit = f"{max_bytes / 2**20:g} MiB" if max_bytes >= 2**20 else f"{max_bytes} bytes"
        kind = "file" if binary else "text file"
        raise _file_error(p, field, source, f"is {size / 2**20:.1f} MiB; a {what} is a small "
                          f"{kind} (at most {limit})")  # fmt: skip
    if binary:
        return data
    inside = content_field or field
    for bom, name in _BOMS.items():
        if data.startswith(bom):
            raise _file_error(p, inside, source, f"is {name} text (byte-order mark): not a "
                              f"UTF-8 text file; save the {what} as UTF-8")  # fmt: skip
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise _file_error(p, inside, source, f"not a UTF-8 text file (byte {err.start}): a "
                          "binary file?") from None  # fmt: skip


def read_json(
    path: str | Path, field: str, source: str | None = None, what: str = "JSON file"
) -> Any:
    """The JSON document of a user file (read by :func:`read_file`).

    Raises
    ------
    ConfigError
        As :func:`read_file`, and for invalid JSON or JSON nested too deeply to parse.
    """
    text = read_file(path, field, source, what)
    try:
        return json.loads(text)
    except RecursionError:
        raise _file_error(Path(path), field, source, f"the {what} is nested too deeply to "
                          "be read") from None  # fmt: skip
    except ValueError as err:  # json.JSONDecodeError, an integer of too many digits
        raise _file_error(Path(path), field, source, f"not valid JSON: {err}") from None
