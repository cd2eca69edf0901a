"""The declaration types of the problem-file schema: :class:`Key`, :class:`Table`,
:class:`Derived`, and the reader that takes every default, range and choice from them.

A loader reads a key only through its declared :class:`Table`: ``T.get(table, "dt", field)``
(a typed, range-checked value or the declared default), ``T.raw(table, "vehicles")`` (the raw
value, for keys a loader validates itself) and ``T.check(table, field)`` (unknown keys, with the
closest declared one). Reading an undeclared key raises :class:`UndeclaredKeyError` at once, so
a key cannot be read without being documented; every read is recorded in :data:`READS` (the
schema test loads every shipped problem file and checks that each declared key is read).
A default, bound or choice list that depends on other values (``end`` defaults to
``start + period``) is declared :class:`Derived` with its rule in words, and only such a value
may be passed by the loader.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import lcc_synth.schema.readers as rd
from lcc_synth.schema.readers import REQUIRED

__all__ = ["REQUIRED", "READS", "Derived", "Key", "Table", "UndeclaredKeyError", "TYPES"]

#: The value types a key may declare (``any``: a loader validates it itself, see ``Key.meaning``).
TYPES = ("number", "integer", "boolean", "string", "number list", "table", "any")

#: ``(table id, key)`` of every declared key read since import (the schema test's evidence).
READS: set[tuple[str, str]] = set()


class UndeclaredKeyError(KeyError):
    """A loader read a key its table does not declare (a programming error, not bad input)."""


@dataclass(frozen=True)
class Derived:
    """A default, bound or choice list computed by the loader from other values.

    ``rule`` says how, in words, for the reference page (e.g. ``"start + period"``).
    """

    rule: str

    def __str__(self) -> str:
        return self.rule


@dataclass(frozen=True)
class Key:
    """One key of a table.

    Attributes
    ----------
    name, type : str
        The key and its value type (one of :data:`TYPES`).
    meaning : str
        One line for the reference page.
    default : object
        Its value when absent: :data:`REQUIRED` (must be given), ``None`` (absent means
        "not set"), a value, or :class:`Derived`.
    lo, hi, lo_open, hi_open : bounds of a number (or of each entry of a number list; ``lo``,
        ``hi`` of an integer are closed); ``None``: unbounded.
    choices : tuple of str, optional
        The allowed strings.
    length : int, optional
        The length of a number list.
    unit : str
        SI unit ("" for none).
    """

    name: str
    type: str
    meaning: str
    default: Any = REQUIRED
    lo: float | Derived | None = None
    hi: float | Derived | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[str, ...] | Derived | None = None
    length: int | Derived | None = None
    unit: str = ""

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f"key {self.name!r}: type {self.type!r} is not one of {TYPES}")
        if not self.meaning.strip():
            raise ValueError(f"key {self.name!r}: a one-line meaning is required")

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    def resolved(self, given: Mapping[str, Any]) -> dict[str, Any]:
        """The declared attributes with every :class:`Derived` one replaced from ``given``
        (the loader's computed values); anything else in ``given`` is a programming error."""
        out = {}
        for attr in ("default", "lo", "hi", "choices", "length"):
            declared = getattr(self, attr)
            if isinstance(declared, Derived):
                if attr not in given:
                    raise TypeError(f"{self.name}.{attr} is derived ({declared}): pass it")
                out[attr] = given[attr]
            else:
                if attr in given:
                    raise TypeError(f"{self.name}.{attr} is declared in the schema: do not pass it")
                out[attr] = declared
        return out


@dataclass(frozen=True)
class Table:
    """One table of a problem file.

    Attributes
    ----------
    path : str
        As written in a file (``"scenario.v2v"``, ``"controllers.NAME.weights"``); upper-case
        parts are names the user chooses.
    meaning : str
        One line for the reference page.
    commands : tuple of str
        The commands that read it.
    keys : tuple of Key
        Its keys, in reference order.
    variant : str
        Which of several declarations of the same ``path`` (the controller ``type``);
        the table's id is ``path`` or ``path:variant``.
    includes : tuple of str
        Ids of tables whose keys this one also takes (``[layouts.NAME]`` takes ``[system]``'s).
    any_key : Key, optional
        For a table whose keys the user names (``gains``, ``heterogeneity``): what each is.
    notes : str
        Extra prose for the reference page (the rules between keys).
    """

    path: str
    meaning: str
    commands: tuple[str, ...]
    keys: tuple[Key, ...] = ()
    variant: str = ""
    includes: tuple[str, ...] = ()
    any_key: Key | None = None
    notes: str = ""
    _index: dict[str, Key] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for k in self.keys:
            if k.name in self._index:
                raise ValueError(f"table {self.id}: key {k.name!r} declared twice")
            self._index[k.name] = k

    @property
    def id(self) -> str:
        return f"{self.path}:{self.variant}" if self.variant else self.path

    @property
    def names(self) -> list[str]:
        """The declared key names."""
        return [k.name for k in self.keys]

    def key(self, name: str) -> Key:
        """The declared key ``name`` (:class:`UndeclaredKeyError` when not declared)."""
        try:
            return self._index[name]
        except KeyError:
            raise UndeclaredKeyError(
                f"table {self.id!r} of lcc_synth.schema declares no key {name!r}: declare it "
                "(type, default, range, unit, meaning) before reading it"
            ) from None

    def check(
        self, table: Mapping[str, Any], field: str, allowed: list[str] | None = None
    ) -> None:
        """Reject keys of ``table`` this table does not declare (the error names the closest
        declared one). A table whose keys the user names (``any_key``) takes its ``allowed``
        names from the loader (e.g. the ``[hdv]`` model's parameters), or accepts any."""
        if self.any_key is None:
            if allowed is not None:
                raise TypeError(f"table {self.id!r} declares its keys: do not pass allowed")
            allowed = self.names
        if allowed is not None:
            rd.check_keys(table, allowed, field)

    def raw(self, table: Mapping[str, Any], name: str, **given: Any) -> Any:
        """``table[name]`` unchecked (the loader validates it), else the declared default."""
        key = self.key(name)
        READS.add((self.id, name))
        if name in table:
            return table[name]
        default = key.resolved(given)["default"]
        return None if default is REQUIRED else default

    def get(self, table: Mapping[str, Any], name: str, field: str, **given: Any) -> Any:
        """``table[name]`` checked against the declared type, range and choices, or the declared
        default; ``field`` is the table's dotted path in the file (for the error).

        ``given`` holds the values of the key's :class:`Derived` attributes only.
        """
        key = self.key(name)
        READS.add((self.id, name))
        return _read(key, key.resolved(given), table, name, field)

    def get_each(self, table: Mapping[str, Any], field: str, **given: Any) -> dict[str, Any]:
        """Every key of ``table`` read as the declared ``any_key`` (in file order)."""
        if self.any_key is None:
            raise TypeError(f"table {self.id!r} declares its keys: read them with get()")
        READS.add((self.id, self.any_key.name))
        a = self.any_key.resolved(given)
        return {name: _read(self.any_key, a, table, name, field) for name in table}


def _read(key: Key, a: Mapping[str, Any], table: Mapping[str, Any], name: str, field: str):
    """``table[name]`` read as ``key`` with the resolved attributes ``a``."""
    default = a["default"]
    if key.type == "number":
        return rd.get_number(table, name, field, default, a["lo"], a["hi"], key.lo_open,
                             key.hi_open)  # fmt: skip
    if key.type == "integer":
        return rd.get_int(table, name, field, default, a["lo"], a["hi"])
    if key.type == "boolean":
        return rd.get_bool(table, name, field, default)
    if key.type == "string":
        return rd.get_str(table, name, field, default, a["choices"])
    if key.type == "number list":
        return rd.get_number_list(table, name, field, default, a["length"], a["lo"], a["hi"])
    if key.type == "table":
        sub = f"{field}.{name}" if field else name
        return rd.get_table(table, name, sub, required=default is REQUIRED)
    raise TypeError(f"{key.name} has type {key.type!r}: read it with raw()")
