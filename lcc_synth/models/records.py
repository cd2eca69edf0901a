"""Small result records: ``as_dict()`` and a readable ``__repr__`` for the package's dataclasses,
equality by value, and the TOML text of problem-file tables.

:class:`Record` is a mixin for frozen dataclasses (declare them with ``repr=False`` so that the
mixin's ``__repr__`` is used): ``as_dict()`` gives plain Python values (dicts, lists, floats,
strings; numpy arrays become nested lists, tuples lists), ``repr()`` one line with numbers to
6 significant digits and arrays larger than :data:`REPR_ITEMS` entries shown by shape only.
:func:`same` compares two values by value (numpy arrays included), and :class:`ValueEq` makes
it the ``==`` of a dataclass that holds arrays or controllers (declared ``eq=False``).
:func:`toml_text` writes nested tables (``None`` values left out: a missing key is the loader's
default) with ``tomli_w``; floats are written with Python's shortest round-trip ``repr``, so a
number read back is bit for bit the number written.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "REPR_ITEMS", "Record", "ValueEq", "plain", "same", "short", "toml_text", "drop_none",
    "system_tables",
]  # fmt: skip

#: Arrays and lists with more entries than this are shown by shape / length in ``repr``.
REPR_ITEMS = 8


def plain(x: Any) -> Any:
    """``x`` as plain Python values: objects with ``as_dict()`` (records, controllers),
    dataclasses and mappings -> dict, sequences and arrays -> list, numpy scalars -> Python
    scalars, paths -> str."""
    if isinstance(x, Record) or callable(getattr(x, "as_dict", None)):
        return plain(x.as_dict())
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {f.name: plain(getattr(x, f.name)) for f in dataclasses.fields(x)}
    if isinstance(x, Mapping):
        return {str(k): plain(v) for k, v in x.items()}
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, list | tuple):
        return [plain(v) for v in x]
    if isinstance(x, Path):
        return str(x)
    return x


def short(x: Any) -> str:
    """A compact text of ``x`` for ``repr``: 6 significant digits, long arrays by shape."""
    if isinstance(x, bool) or x is None:
        return repr(x)
    if isinstance(x, float | np.floating):
        return f"{float(x):.6g}" if math.isfinite(x) else repr(float(x))
    if isinstance(x, np.ndarray):
        if x.size > REPR_ITEMS:
            return f"array(shape={x.shape}, dtype={x.dtype})"
        return short(x.tolist())
    if isinstance(x, list | tuple):
        if len(x) > REPR_ITEMS:
            return f"[{len(x)} items]"
        inner = ", ".join(short(v) for v in x)
        return f"({inner}{',' if len(x) == 1 else ''})" if isinstance(x, tuple) else f"[{inner}]"
    if isinstance(x, Mapping):
        if len(x) > REPR_ITEMS:
            return f"{{{len(x)} entries}}"
        return "{" + ", ".join(f"{k!r}: {short(v)}" for k, v in x.items()) + "}"
    return repr(x)


def _nan(x: Any) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isnan(x)


def same(a: Any, b: Any) -> bool:
    """Are ``a`` and ``b`` the same value?

    Arrays are equal when their shapes and entries are (NaN equal to NaN); mappings when
    their keys are and each key's values are the same; lists and tuples (of one type) entry
    by entry; dataclasses of one type field by field (fields with ``compare=False`` left out;
    their own ``__eq__`` is not used, so a dataclass holding arrays compares too); numbers by
    value (``1 == 1.0``; NaN equal to NaN); other objects with an ``as_dict()`` (the
    controllers: what defines them, not their run-time state) of one type by that dict;
    anything else by ``==``.
    """
    if a is b:
        return True
    a, b = (x.item() if isinstance(x, np.generic) else x for x in (a, b))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray)) or a.shape != b.shape:
            return False
        try:
            return bool(np.array_equal(a, b, equal_nan=True))
        except TypeError:  # entries that cannot be NaN (strings, objects)
            return bool(np.array_equal(a, b))
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, numbers.Number) and isinstance(b, numbers.Number):
        return bool(a == b) or (_nan(a) and _nan(b))
    if type(a) is not type(b):
        return False
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if dataclasses.is_dataclass(a):
        return all(
            same(getattr(a, f.name), getattr(b, f.name))
            for f in dataclasses.fields(a)
            if f.compare
        )
    if callable(getattr(a, "as_dict", None)):
        return same(a.as_dict(), b.as_dict())
    return bool(a == b)


class ValueEq:
    """Mixin: ``==`` by value (:func:`same`) for a dataclass declared ``eq=False`` whose fields
    hold numpy arrays or controllers (the generated ``__eq__`` compares arrays with ``==``,
    which raises, and controllers by identity). Such objects are not hashable."""

    __slots__ = ()

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return same(self, other)

    __hash__ = None  # type: ignore[assignment]


class Record:
    """Mixin for result dataclasses: :meth:`as_dict` and a one-line ``__repr__``."""

    __slots__ = ()

    def as_dict(self) -> dict[str, Any]:
        """Every field as plain Python values (see :func:`plain`)."""
        return {f.name: plain(getattr(self, f.name)) for f in dataclasses.fields(self)}

    def __repr__(self) -> str:
        parts = (
            f"{f.name}={short(getattr(self, f.name))}"
            for f in dataclasses.fields(self)
            if f.repr
        )
        return f"{type(self).__name__}({', '.join(parts)})"


def drop_none(x: Any) -> Any:
    """``x`` (plain values) without ``None`` entries in its tables, recursively."""
    if isinstance(x, Mapping):
        return {k: drop_none(v) for k, v in x.items() if v is not None}
    if isinstance(x, list):
        return [drop_none(v) for v in x]
    return x


def toml_text(tables: Mapping[str, Any]) -> str:
    """The TOML text of ``tables`` (``None`` values left out)."""
    import tomli_w

    return tomli_w.dumps(drop_none(plain(tables)), multiline_strings=True)


def system_tables(system: Any) -> dict[str, Any]:
    """The ``[hdv]`` and ``[system]`` tables of a :class:`lcc_synth.problem.System` (a platoon
    or ring: ``size``, ``cavs``, ``v_star`` (a ring given by its ``circumference``: that) and
    every position's ``[system.hdv_values]``)."""
    P = getattr(system, "platoon", None)
    if P is not None:
        hdv = system.hdv.toml_table()
        params = [k for k in hdv if k != "model"]
        given = {"circumference": float(P.circumference)} if P.circumference is not None else (
            {"v_star": float(system.v_star)})  # a ring given by its length keeps it
        sys_t = {
            "kind": system.kind, "size": int(P.size), "cavs": [int(c) for c in P.cavs],
            **given,
            "hdv_values": {k: [float(getattr(h, k)) for h in P.hdv] for k in params},
        }  # fmt: skip
        if P.vehicle_length:
            sys_t["vehicle_length"] = float(P.vehicle_length)
        return {"hdv": hdv, "system": sys_t}
    return {
        "hdv": system.hdv.toml_table(),
        "system": {"kind": system.kind, "m": int(system.m), "n": int(system.n),
                   "v_star": float(system.v_star)},
    }  # fmt: skip
