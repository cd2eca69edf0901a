"""The tables of an experiment: the comparison table's columns (:data:`SUITE_METRICS`) and its
terminal, Markdown, CSV and JSON forms, JSON-safe copies and the run's results directory.

Failed runs rank last: a row whose run collided (``"collided": true``, else ``collisions > 0``)
has NaN AAVE and fuel (:mod:`lcc_synth.metrics`), is marked (``NAME (collided)`` in the
terminal and Markdown, a ``collided`` column in CSV, the ``collided`` key in JSON) and comes
after the scenario's other rows in every form (:func:`rank_failed_last`; file order otherwise).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError

__all__ = [
    "SUITE_METRICS",
    "json_safe",
    "collided",
    "rank_failed_last",
    "format_table",
    "markdown_table",
    "write_markdown",
    "write_csv",
    "write_json",
    "run_directory",
]

#: Metrics of the comparison table: key of :func:`lcc_synth.metrics.summary` -> (header, format).
#: Format ``"iso"``: the time above ISO 15622's jerk limit as a verdict, ``ok`` or ``over X s``.
SUITE_METRICS: dict[str, tuple[str, str]] = {
    "aave": ("AAVE (m/s)", ".4f"),
    "fuel_ml": ("fuel (mL)", ".2f"),
    "min_spacing": ("min spacing (m)", ".2f"),
    "min_ttc": ("min TTC (s)", ".2f"),
    "max_abs_command": ("max |u| (m/s²)", ".3f"),
    "rms_jerk_cav": ("RMS jerk (m/s³)", ".2f"),
    "max_jerk_1s_cav": ("max 1 s jerk (m/s³)", ".2f"),
    "jerk_1s_over_limit_s": ("ISO 15622 jerk", "iso"),
    "aeb_activations": ("AEB steps", "d"),
    "collisions": ("collisions", "d"),
}


def run_directory(root: str | Path, name: str, stamp: str) -> Path:
    """A new directory ``root/<name>-<stamp>`` (``-2``, ``-3``... appended if it exists)."""
    from lcc_synth.recording import entity_name

    base = Path(root) / f"{entity_name(name)}-{stamp}"
    path, k = base, 1
    while True:
        try:
            path.mkdir(parents=True, exist_ok=False)
            return path
        except FileExistsError:
            k += 1
            path = base.with_name(f"{base.name}-{k}")
        except OSError as err:
            raise ConfigError("--out", f"cannot create {str(path)!r}: {err}") from None


def json_safe(x: Any) -> Any:
    """JSON-ready copy: numpy scalars to Python, NaN and infinities to ``None``."""
    if isinstance(x, Mapping):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def collided(metrics: Mapping[str, Any]) -> bool:
    """Whether a table row's run had a collision (its ``collided`` flag, else ``collisions``)."""
    if "collided" in metrics:
        return bool(metrics["collided"])
    return bool(metrics.get("collisions") or 0)


def rank_failed_last(table: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> dict[str, dict]:
    """The table with, within every scenario, the rows whose run collided moved after the
    others (a stable sort: file order otherwise)."""
    return {
        sname: dict(sorted(per.items(), key=lambda item: collided(item[1])))
        for sname, per in table.items()
    }


def _cell(value: Any, fmt: str) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if fmt == "d":
        return str(int(value))
    if fmt == "iso":
        return "ok" if value == 0 else f"over {float(value):.2f} s"
    return format(float(value), fmt)


def _rows(table: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> list[list[str]]:
    rows = []
    for sname, per in rank_failed_last(table).items():
        for cname, metrics in per.items():
            rows.append(
                [sname, f"{cname} (collided)" if collided(metrics) else cname]
                + [_cell(metrics.get(k), fmt) for k, (_, fmt) in SUITE_METRICS.items()]
            )
    return rows


def _headers() -> list[str]:
    return ["scenario", "controller"] + [h for h, _ in SUITE_METRICS.values()]


def format_table(table: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> str:
    """Plain-text table (one row per scenario and controller) for the terminal."""
    head = _headers()
    rows = _rows(table)
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in
              enumerate(head)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True))]
    lines.append("  ".join("-" * w for w in widths))
    prev = None
    for r in rows:
        shown = list(r)
        if r[0] == prev:
            shown[0] = ""
        prev = r[0]
        lines.append("  ".join(v.ljust(w) for v, w in zip(shown, widths, strict=True)).rstrip())
    return "\n".join(lines)


def markdown_table(table: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> str:
    """The table as GitHub Markdown."""
    head = [_md_escape(h) for h in _headers()]
    align = ["---"] * 2 + ["---:"] * (len(head) - 2)
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(_md_escape(c) for c in r) + " |" for r in _rows(table)]
    return "\n".join(lines) + "\n"


def _md_escape(cell: str) -> str:
    """Escape ``|`` so that a cell like ``max |u|`` does not split a Markdown column."""
    return cell.replace("|", "\\|")


def write_markdown(
    table: Mapping[str, Mapping[str, Mapping[str, Any]]], path: str | Path, title: str = ""
) -> Path:
    """Write :func:`markdown_table` (with an optional heading) to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = (f"# {title}\n\n" if title else "") + markdown_table(table)
    path.write_text(text)
    return path


def write_csv(table: Mapping[str, Mapping[str, Mapping[str, Any]]], path: str | Path) -> Path:
    """CSV with columns ``scenario, controller``, the :data:`SUITE_METRICS` keys (full
    precision; ``inf`` for a time to collision that never occurs, empty for NaN) and
    ``collided`` (``true`` / ``false``; those rows last in their scenario)."""
    import csv

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["scenario", "controller", *SUITE_METRICS, "collided"])
        for sname, per in rank_failed_last(table).items():
            for cname, metrics in per.items():
                vals = []
                for k in SUITE_METRICS:
                    v = metrics.get(k)
                    if v is None or (isinstance(v, float) and math.isnan(v)):
                        vals.append("")
                    else:
                        vals.append(repr(float(v)) if isinstance(v, float) else str(v))
                w.writerow([sname, cname, *vals, str(collided(metrics)).lower()])
    return path


def write_json(table: Mapping[str, Any], path: str | Path, **extra: Any) -> Path:
    """``{"results": table, **extra}`` as JSON (non-finite numbers as ``null``; collided rows
    last in their scenario)."""
    import json

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = {"results": rank_failed_last(table), **extra}
    path.write_text(json.dumps(json_safe(doc), indent=2) + "\n")
    return path
