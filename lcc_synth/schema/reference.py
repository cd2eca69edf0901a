"""The reference page of the problem-file schema (``problems/REFERENCE.md``), generated."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from lcc_synth.schema.spec import REQUIRED, Derived, Key, Table

__all__ = ["reference_markdown", "format_default", "format_range"]

_HEADER = """# Problem-file reference

Generated from `lcc_synth.schema` by `python -m lcc_synth.schema > problems/REFERENCE.md`; do
not edit by hand (`tests/test_schema.py` fails when this file is stale). How the files work,
with examples: [README.md](README.md).

Every key is optional unless its default says **required** (a top-level table: required by the
commands that read it); "none" means absent = not set (the meaning says what then happens);
*italics* are computed from other values. Ranges: `(lo, hi)` open, `[lo, hi]` closed.
Upper-case parts of a table name (`NAME`, `LAYOUT`) are names you choose. An unknown table or
key is an error naming it and the closest declared one; a wrong type or a value out of range is
an error naming the file and the dotted field (exit code 2).

State names in gains (tables and gains files) have one meaning: `s_i` / `v_i` are the spacing
and velocity errors of vehicle `i` of the problem's layout (`-p_0`: FD-LCC's position state).
The paper's one-CAV kinds (`lcc`, `cf_lcc`, `fd_lcc`, `ccc`) number the vehicles from the CAV:
`0` is the CAV (`s_0`, `v_0`: its own errors), `1..n` the HDVs behind it, `-1..-m` those ahead
(the paper's `mu_i`, `k_i`). Platoons and rings number the positions `1..size` from the head,
and a gain table is per CAV input `u_i` (the CAV at position `i`). A gains file states its
`kind` (and a platoon's `cavs`), and is read only for a problem of that layout.
"""


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, float) and math.isfinite(v):
        return repr(v) if 1e-3 <= abs(v) < 1e6 or v == 0 else f"{v:g}"
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "empty" if not v else str(v)
    return str(v)


def format_default(key: Key) -> str:
    """The default as the reference shows it."""
    d = key.default
    if d is REQUIRED:
        return "**required**"
    if d is None:
        return "none"
    if isinstance(d, Derived):
        return f"*{d.rule}*"
    if isinstance(d, dict) and not d:
        return "empty"
    return f"`{_value(d)}`"


def format_range(key: Key) -> str:
    """The allowed values as the reference shows them."""
    if key.choices is not None:
        if isinstance(key.choices, Derived):
            return f"*{key.choices.rule}*"
        return " \\| ".join(f"`{_value(c)}`" for c in key.choices)
    parts = []
    if key.lo is not None or key.hi is not None:
        lo = "-∞" if key.lo is None else _value(key.lo)
        hi = "∞" if key.hi is None else _value(key.hi)
        left = "(" if key.lo_open or key.lo is None else "["
        right = ")" if key.hi_open or key.hi is None else "]"
        parts.append(f"{left}{lo}, {hi}{right}")
    if key.length is not None:
        parts.append(f"{key.length} entries")
    return ", ".join(parts)


def _commands(commands: tuple[str, ...]) -> str:
    if tuple(commands) == ("all",):
        return "every command"
    return ", ".join(f"`{c}`" for c in commands)


def _title(t: Table) -> str:
    if not t.path:
        return "Top level"
    name = f"[[{t.path}]]" if t.path == "scenario.perturbations" else f"[{t.path}]"
    if not t.variant:
        return f"`{name}`"
    typed = t.path.startswith(("controllers.", "scenario.perturbations"))
    form = f'type = "{t.variant}"' if typed and t.variant != "suite" else t.variant
    return f"`{name}` (`{form}`)"


def _row(k: Key, read_by: tuple[str, ...] = ()) -> str:
    meaning = k.meaning.replace("|", "\\|")
    if read_by:
        meaning += f" Read by {_commands(read_by)}."
    return (f"| `{k.name}` | {k.type} | {format_default(k)} | {format_range(k)} | {k.unit} | "
            f"{meaning} |")  # fmt: skip


def reference_markdown(
    tables: Mapping[str, Table], top_level: Mapping[str, tuple[str, ...]]
) -> str:
    """Markdown of every table of ``tables`` (in order) and its keys; ``top_level`` gives the
    commands that read each top-level key."""
    out = [_HEADER]
    out.append("## Contents\n")
    for t in tables.values():
        out.append(f"- {_title(t)}: {t.meaning}")
    out.append("")
    for t in tables.values():
        out.append(f"## {_title(t)}\n")
        if t.path:
            out.append(f"{t.meaning} Read by {_commands(t.commands)}.\n")
        else:
            out.append(f"{t.meaning}\n")
        if t.includes:
            inc = ", ".join(f"`[{tables[i].path}]`" for i in t.includes)
            out.append(f"Also takes every key of {inc}.\n")
        if t.notes:
            out.append(f"{t.notes}\n")
        rows = list(t.keys) + ([t.any_key] if t.any_key is not None else [])
        if rows:
            out.append("| key | type | default | allowed | unit | meaning |")
            out.append("|---|---|---|---|---|---|")
            out.extend(_row(k, top_level.get(k.name, ()) if not t.path else ()) for k in rows)
            out.append("")
    return "\n".join(out).rstrip() + "\n"
