"""The tables of an experiment: the comparison table's columns (:data:`SUITE_METRICS`) and its
terminal, Markdown, CSV and JSON forms, JSON-safe copies and the run's results directory.

Safety before efficiency: unsafe and failed runs rank last, in every form
(:func:`rank_failed_last`; file order otherwise):

* a run that was *unsafe* (:func:`~lcc_synth.metrics.unsafe_reasons`: the CAV's emergency
  braking acted on some step, or some vehicle came closer than 2 m to the one ahead or within
  1 s of hitting it) is marked ``NAME (unsafe)`` and comes after every safe run, whatever its
  AAVE and fuel (which are still shown): a run that emergency braking saved is not the best
  of its table. The thresholds: 2 m is about the standstill gap a driver keeps in a queue
  (the OVM's ``s_st`` is 5 m), 1 s a time to collision below which an emergency brake warning
  is due (common FCW thresholds are 1.5-2.5 s; 1 s marks a run as unsafe without flagging
  ordinary close following). They are judged on the table's worst case: ``min spacing`` and
  ``min TTC`` of every vehicle behind the head (the HDVs included: the CAV is there to lead
  them), ``AEB steps`` of the CAVs;
* a run whose controller's solver failed on some steps (``"failed_steps": k > 0``: QP steps
  that fell back to a shifted plan, the static gain or a held command, and controller errors;
  :func:`failed_steps`) is marked ``NAME (QP failed on k steps)`` and comes after the clean
  runs;
* a run that collided (``"collided": true``, else ``collisions > 0``) has NaN AAVE and fuel
  (:mod:`lcc_synth.metrics`), is marked ``NAME (collided)`` and comes after those (the
  ranking key, :func:`failure_rank`: not run, collided, unsafe, solver failures);
* a controller that could not run at all (``"failed": "why"``, e.g. its synthesis failed) has
  no metrics (``n/a``), is marked ``NAME (not run)`` (the commands print why) and comes last.

CSV has the columns ``collided``, ``unsafe`` (the reasons, separated by semicolons),
``failed_steps`` and ``not_run`` for them; JSON rows carry ``"unsafe": [reasons]`` (empty
when safe).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.metrics import METRIC_DISPLAY, UNSAFE_RULE, format_metric, unsafe_reasons

__all__ = [
    "SUITE_METRICS",
    "json_safe",
    "collided",
    "failed_steps",
    "failure_rank",
    "row_label",
    "rank_failed_last",
    "unsafe_lines",
    "format_table",
    "column_blocks",
    "markdown_table",
    "write_markdown",
    "write_csv",
    "json_rows",
    "write_json",
    "run_directory",
]

#: Metrics of the comparison table: key of :func:`lcc_synth.metrics.summary` -> (header, format),
#: as every table shows them (:data:`lcc_synth.metrics.METRIC_DISPLAY`). Format ``"iso"``: the
#: time above ISO 15622's jerk limit as a verdict, ``ok`` or ``over X s``.
SUITE_METRICS: dict[str, tuple[str, str]] = {
    k: METRIC_DISPLAY[k]
    for k in ("aave", "fuel_ml", "min_spacing", "min_ttc", "max_abs_command", "rms_jerk_cav",
              "max_jerk_1s_cav", "jerk_1s_over_limit_s", "aeb_activations", "collisions")
}  # fmt: skip


def run_directory(root: str | Path, name: str, stamp: str) -> Path:
    """A new directory ``root/<name>-<stamp>`` (:func:`lcc_synth.outputs.new_directory`)."""
    from lcc_synth.outputs import new_directory

    return new_directory(root, name, stamp)


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


def failed_steps(stats: Mapping[str, Any] | None) -> int:
    """Steps on which a controller's solver failed, from its run statistics (an MPC's or
    DeeP-LCC's ``stats()``): the steps that used a fallback (shifted plan, static gain, held
    command) plus the steps that raised an error. A QP that OSQP left unfinished but DeeP-LCC's
    exact re-solve finished is not a failure. 0 for a controller without statistics."""
    if not stats:
        return 0
    return int(stats.get("fallbacks", 0) or 0) + int(stats.get("errors", 0) or 0)


def failure_rank(metrics: Mapping[str, Any]) -> tuple[bool, bool, bool, bool]:
    """Sort key of a row: safe clean runs, then safe runs with solver failures, then unsafe
    runs (:func:`unsafe_reasons`; those with solver failures after the others), then
    collisions, then controllers that did not run."""
    return (bool(metrics.get("failed")), collided(metrics), bool(unsafe_reasons(metrics)),
            bool(metrics.get("failed_steps") or 0))  # fmt: skip


def row_label(name: str, metrics: Mapping[str, Any]) -> str:
    """``NAME`` with its failure marks: ``(not run)`` (the reason is printed under the table),
    ``(collided)`` or else ``(unsafe)`` (:func:`unsafe_lines` say why), ``(QP failed on k
    steps)``."""
    if metrics.get("failed"):
        return f"{name} (not run)"
    marks = []
    if collided(metrics):
        marks.append("collided")
    elif unsafe_reasons(metrics):
        marks.append("unsafe")
    k = int(metrics.get("failed_steps") or 0)
    if k:
        marks.append(f"QP failed on {k} step{'s' if k != 1 else ''}")
    return f"{name} ({', '.join(marks)})" if marks else name


def rank_failed_last(table: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> dict[str, dict]:
    """The table with, within every scenario, the runs whose solver failed, then the unsafe
    runs, then those that collided, then the controllers that did not run, moved after the
    safe clean runs (:func:`failure_rank`; a stable sort: file order otherwise)."""
    return {
        sname: dict(sorted(per.items(), key=lambda item: failure_rank(item[1])))
        for sname, per in table.items()
    }


def unsafe_lines(table: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> list[str]:
    """One line per unsafe run that did not collide (collisions have their own report):
    ``unsafe: SCENARIO/CONTROLLER: reason, reason``, then the rule once."""
    lines = [f"unsafe: {sname}/{cname}: {', '.join(why)}"
             for sname, per in rank_failed_last(table).items() for cname, m in per.items()
             if not m.get("failed") and not collided(m) and (why := unsafe_reasons(m))]  # fmt: skip
    return [*lines, UNSAFE_RULE] if lines else lines


def _rows(table: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> list[list[str]]:
    rows = []
    for sname, per in rank_failed_last(table).items():
        for cname, metrics in per.items():
            rows.append(
                [sname, row_label(cname, metrics)]
                + [format_metric(metrics.get(k), fmt) for k, (_, fmt) in SUITE_METRICS.items()]
            )
    return rows


def _headers() -> list[str]:
    return ["scenario", "controller"] + [h for h, _ in SUITE_METRICS.values()]


def format_table(
    table: Mapping[str, Mapping[str, Mapping[str, Any]]], width: int | None = None
) -> str:
    """Plain-text table (one row per scenario and controller) for the terminal.

    With ``width`` (characters), no line is longer: the headers' units go on a second header
    line and the metric columns are split into blocks, each repeating the scenario and
    controller columns (:func:`column_blocks`); the cells are the same either way.
    """
    head = _headers()
    rows = _rows(table)
    if width is not None:
        head = [h.replace(" (", "\n(", 1) for h in head]
        return "\n".join(column_blocks(head, rows, width, keep=2, blank_repeats=True))
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


def column_blocks(
    header: Sequence[str],
    rows: Sequence[Sequence[str]],
    width: int | None = None,
    keep: int = 1,
    blank_repeats: bool = False,
) -> list[str]:
    """Lines of a left-aligned text table no wider than ``width`` characters.

    Parameters
    ----------
    header : sequence of str
        Column titles; a ``"\\n"`` in a title splits it over header lines (e.g. the unit
        under the name).
    rows : sequence of sequence of str
        Cells, as they are to be shown (never changed or cut).
    width : int, optional
        The longest line allowed; the columns after the first ``keep`` are split into
        consecutive blocks that fit, each block repeating the first ``keep`` columns and
        separated by an empty line. ``None``: one block. A column too wide on its own gets a
        block of its own.
    keep : int
        Leading columns repeated in every block (the row names).
    blank_repeats : bool
        Show the first column only where it changes (a scenario name over its rows).
    """
    parts = [h.split("\n") for h in header]
    depth = max(len(p) for p in parts)
    parts = [p + [""] * (depth - len(p)) for p in parts]
    widths = [max([len(x) for x in parts[i]] + [len(r[i]) for r in rows])
              for i in range(len(header))]  # fmt: skip
    shown = [list(r) for r in rows]
    if blank_repeats:
        for prev, r in zip(rows, shown[1:], strict=False):
            if r[0] == prev[0]:
                r[0] = ""
    fixed = list(range(keep))
    base = sum(widths[:keep]) + 2 * max(keep - 1, 0)
    blocks: list[list[int]] = []
    used = base
    for i in range(keep, len(header)):
        if not blocks or (width is not None and used + 2 + widths[i] > width):
            blocks.append([])
            used = base
        blocks[-1].append(i)
        used += 2 + widths[i]
    lines: list[str] = []
    for b, block in enumerate(blocks or [[]]):
        cols = fixed + block
        if b:
            lines.append("")
        for level in range(depth):  # a header line this block leaves empty is not shown
            if any(parts[i][level] for i in cols):
                lines.append("  ".join(parts[i][level].ljust(widths[i]) for i in cols).rstrip())
        lines.append("  ".join("-" * widths[i] for i in cols))
        for r in shown:
            lines.append("  ".join(r[i].ljust(widths[i]) for i in cols).rstrip())
    return lines


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
    table: Mapping[str, Mapping[str, Mapping[str, Any]]], path: str | Path, title: str = "",
    overwrite: bool = True,
) -> Path:  # fmt: skip
    """Write :func:`markdown_table` (with an optional heading) to ``path`` atomically
    (:func:`lcc_synth.outputs.write_text`; ``overwrite`` false: the next free name if the
    file exists); returns the name written."""
    from lcc_synth.outputs import write_text

    text = (f"# {title}\n\n" if title else "") + markdown_table(table)
    return write_text(path, text, overwrite)


def write_csv(
    table: Mapping[str, Mapping[str, Mapping[str, Any]]], path: str | Path,
    overwrite: bool = True,
) -> Path:  # fmt: skip
    """CSV with columns ``scenario, controller``, the :data:`SUITE_METRICS` keys (full
    precision; ``inf`` for a time to collision that never occurs, empty for NaN) and
    ``collided`` (``true`` / ``false``), ``failed_steps``, ``not_run`` (the reason, empty
    when it ran) and ``unsafe`` (:func:`~lcc_synth.metrics.unsafe_reasons`, separated by
    semicolons; empty when safe): unsafe and failed rows last in their scenario. Written
    atomically (as :func:`write_markdown`)."""
    import csv
    import io

    from lcc_synth.outputs import write_text

    fh = io.StringIO()
    w = csv.writer(fh)
    w.writerow(["scenario", "controller", *SUITE_METRICS, "collided", "failed_steps",
                "not_run", "unsafe"])  # fmt: skip
    for sname, per in rank_failed_last(table).items():
        for cname, metrics in per.items():
            vals = []
            for k in SUITE_METRICS:
                v = metrics.get(k)
                if v is None or (isinstance(v, float) and math.isnan(v)):
                    vals.append("")
                else:
                    vals.append(repr(float(v)) if isinstance(v, float) else str(v))
            w.writerow([sname, cname, *vals, str(collided(metrics)).lower(),
                        int(metrics.get("failed_steps") or 0), metrics.get("failed") or "",
                        "; ".join(unsafe_reasons(metrics))])  # fmt: skip
    return write_text(path, fh.getvalue(), overwrite)


def json_rows(table: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> dict[str, dict]:
    """The rows as ``run --json`` and ``table.json`` give them: ranked (:func:`rank_failed_last`)
    and each with ``"unsafe"``, the list of :func:`unsafe_reasons` (empty when safe)."""
    return {sname: {cname: {**m, "unsafe": unsafe_reasons(m)} for cname, m in per.items()}
            for sname, per in rank_failed_last(table).items()}  # fmt: skip


def write_json(
    table: Mapping[str, Any], path: str | Path, overwrite: bool = True, **extra: Any
) -> Path:
    """``{"results": json_rows(table), **extra}`` as JSON (non-finite numbers as ``null``),
    written atomically (as :func:`write_markdown`)."""
    import json

    from lcc_synth.outputs import write_text

    doc = {"results": json_rows(table), **extra}
    return write_text(path, json.dumps(json_safe(doc), indent=2) + "\n", overwrite)
