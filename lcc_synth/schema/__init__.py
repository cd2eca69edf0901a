"""One schema for problem files: every table and key of every command, declared once.

Each key has a type, a default (or "required"), an allowed range or choice list, a unit, a
one-line meaning, and its table says which commands read it. The loaders take their keys,
defaults and ranges from here (:func:`declared` gives a :class:`~lcc_synth.schema.spec.Table`:
``declared("scenario").get(sc, "dt", "scenario")``), so the validation, the error messages
(``scenario.dt: must be > 0, got -1.0``), the "did you mean" suggestions and the reference page
``problems/REFERENCE.md`` (:func:`reference_markdown`; ``python -m lcc_synth.schema``) come
from the same declaration. Reading an undeclared key raises
:class:`~lcc_synth.schema.spec.UndeclaredKeyError`; ``tests/test_schema.py`` loads every
shipped problem file and checks that every declared key is read and the committed reference is
current.

Size: 43 tables (a table with several forms, e.g. ``[controllers.NAME]`` per ``type``, is
declared once per form) with 239 key rows, 206 distinct keys (a key shared by several forms is
one object); 15 top-level keys.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from typing import Any

from lcc_synth.errors import ConfigError
from lcc_synth.schema import controllers as _controllers
from lcc_synth.schema import design as _design
from lcc_synth.schema import simulate as _simulate
from lcc_synth.schema.reference import reference_markdown as _reference
from lcc_synth.schema.spec import READS, REQUIRED, Derived, Key, Table, UndeclaredKeyError

__all__ = [
    "READS",
    "REQUIRED",
    "TABLES",
    "TOP_LEVEL",
    "Derived",
    "Key",
    "Table",
    "UndeclaredKeyError",
    "check_top_level",
    "reference_markdown",
    "declared",
]

#: Every declared table by id (``path`` or ``path:variant``), in reference order.
TABLES: dict[str, Table] = {
    t.id: t for t in (*_simulate.TABLES, *_controllers.TABLES, *_design.TABLES)
}
if len(TABLES) != len(_simulate.TABLES) + len(_controllers.TABLES) + len(_design.TABLES):
    raise RuntimeError("lcc_synth.schema: two tables share an id")


def declared(table_id: str) -> Table:
    """The declared table ``table_id`` (e.g. ``"scenario"``, ``"controllers.NAME:mpc"``)."""
    try:
        return TABLES[table_id]
    except KeyError:
        raise UndeclaredKeyError(f"lcc_synth.schema declares no table {table_id!r}") from None


_TOP = TABLES[""]

#: Every top-level key of a problem file, with the commands that read it (a file may carry the
#: tables of several commands; each reads its own, ignores the others).
def _commands(name: str) -> tuple[str, ...]:
    out: dict[str, None] = {}
    for t in TABLES.values():
        if t.path in (name, f"{name}.NAME"):
            out.update(dict.fromkeys(t.commands))
    return tuple(out)


TOP_LEVEL: dict[str, tuple[str, ...]] = {
    k.name: _commands(k.name) if k.type == "table" else ("all",) for k in _TOP.keys
}

_SCALAR_TOP = tuple(k.name for k in _TOP.keys if k.type != "table")


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


def reference_markdown() -> str:
    """``problems/REFERENCE.md``: every table and key with type, default, range, unit,
    meaning and the commands that read it."""
    return _reference(TABLES, TOP_LEVEL)
