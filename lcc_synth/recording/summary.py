"""The text of ``lcc-synth review --summary``: one screen by default, everything with ``--full``.

:func:`summary_lines` (the default) fits a recording of the default ``lcc-synth run`` (200
entities, 16 runs, 13 |Γ| reports, 2 synthesis reports; 1318 lines in full) in 46 lines: the
file, its status, one line per top-level entity group, the comparison metrics as one table
(a row per scenario and controller) and one line of key facts per report; every section is
capped (``... N more``) so that no recording exceeds :data:`MAX_LINES`. :func:`full_lines`
prints every entity and every metrics, status and report document, as the summary did before.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

from lcc_synth.metrics import METRIC_DISPLAY, format_metric
from lcc_synth.recording.reader import RecordingSummary

__all__ = ["FACT_DISPLAY", "MAX_LINES", "full_lines", "markdown_pairs", "summary_lines"]

#: The compact summary never prints more lines than this (one screen).
MAX_LINES = 60
#: Metrics shown in the compact comparison table, in this order, when a recording has them.
KEY_METRICS = ("aave", "fuel_ml", "min_spacing", "min_ttc", "max_abs_command",
               "max_jerk_1s_cav", "aeb_activations", "collisions")  # fmt: skip
#: Facts shown for a report document, when present.
KEY_FACTS = ("verdict", "gamma_peak", "gamma_peak_omega", "why", "string_verdict", "h2_true",
             "h2_lmi_bound")  # fmt: skip
#: How a numeric report fact is shown: its label and unit, and the format of its value.
FACT_DISPLAY = {
    "gamma_peak": ("max |Γ|", "", ".3f"),
    "gamma_peak_omega": ("at ω", " rad/s", ".3f"),
    "h2_true": ("true H2", "", ".4g"),
    "h2_lmi_bound": ("H2 LMI bound", "", ".4g"),
}
_CAPS = {"groups": 10, "metrics": 24, "reports": 14}


def _header(summary: RecordingSummary) -> list[str]:
    tr = summary.time_range
    views = f" ({len(summary.views)} views)" if summary.views else ""
    lines = [
        f"recording    {summary.path} ({summary.size_bytes / 1e6:.2f} MB)",
        f"application  {summary.application_id}; recording id {', '.join(summary.recording_ids)}",
        f"blueprint    {'yes' if summary.has_blueprint else 'no'}{views}",
    ]
    if not summary.finalized:
        lines.append("file         not finalised (the writing process was killed); data up to then")
    lines.append(f"time range   {f'{tr[0]:g} .. {tr[1]:g} s' if tr else 'none (static data only)'}")
    return lines


def full_lines(summary: RecordingSummary) -> list[str]:
    """Every entity (samples, series, time range) and every metrics / status / report text."""
    lines = _header(summary)
    lines.append(f"entities     {len(summary.entities)}")
    width = max((len(p) for p in summary.entities), default=10)
    for path, ent in sorted(summary.entities.items()):
        kinds = sorted({c.split(":")[0] for c in ent.components})
        if ent.static:
            what = "static"
        else:
            series = f", {ent.series} series" if ent.series > 1 else ""
            what = f"{ent.samples} samples{series}, t {ent.t_min:g}..{ent.t_max:g} s"
        lines.append(f"  {path:<{width}}  {'/'.join(kinds)}: {what}")
    kinds = ("/metrics", "/status", "/report")
    for path, text in sorted((p, t) for p, t in summary.texts.items() if p.endswith(kinds)):
        lines += ["", f"--- {path}", *text.rstrip().splitlines()]
    return lines


_ROW = re.compile(r"^\|(.*)\|\s*$")


def _table_rows(text: str) -> list[list[str]]:
    """The cells of every markdown table row of ``text`` (separator rows dropped)."""
    rows = []
    for line in text.splitlines():
        m = _ROW.match(line.strip())
        if m:
            cells = [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", m.group(1))]
            if not all(set(c) <= set("-: ") for c in cells):
                rows.append(cells)
    return rows


def markdown_pairs(text: str) -> dict[str, str]:
    """``{key: value}`` of the two-column markdown tables of a document (first one wins)."""
    out: dict[str, str] = {}
    for cells in _table_rows(text):
        if len(cells) == 2 and cells[0] not in out:
            out[cells[0]] = cells[1]
    return out


def _comparison(text: str) -> tuple[list[str], dict[str, dict[str, str]]] | None:
    """``(controllers, {metric: {controller: value}})`` of a ``/<scenario>/metrics`` table."""
    rows = _table_rows(text)
    if not rows or rows[0][0] != "metric":
        return None
    ctrls = rows[0][1:]
    return ctrls, {r[0]: dict(zip(ctrls, r[1:], strict=False)) for r in rows[1:]}


def _capped(lines: list[str], cap: int, what: str) -> list[str]:
    if len(lines) <= cap:
        return lines
    return [*lines[: cap - 1], f"  ... {len(lines) - cap + 1} more {what} (--full)"]


def _groups(summary: RecordingSummary) -> list[str]:
    groups: dict[str, list] = {}
    for path, ent in summary.entities.items():
        groups.setdefault("/" + path.strip("/").split("/")[0], []).append((path, ent))
    width = max((len(g) for g in groups), default=10)
    lines = []
    for g, ents in sorted(groups.items()):
        timed = [e for _, e in ents if not e.static]
        parts = [p[len(g) :].strip("/").split("/") for p, _ in ents]
        subs = sorted({q[0] for q in parts if len(q) > 1})  # the runs (controllers) of a group
        what = f"{len(ents)} entities"
        if g not in ("/analysis", "/synthesis") and len(subs) > 1:
            what += f" of {len(subs)}: " + ", ".join(subs[:8]) + (", ..." if len(subs) > 8 else "")
        if timed:
            lo, hi = min(e.samples for e in timed), max(e.samples for e in timed)
            t0, t1 = min(e.t_min for e in timed), max(e.t_max for e in timed)
            what += f"; {lo}-{hi} samples per timed entity, t {t0:g}..{t1:g} s"
        else:
            what += " (static)"
        lines.append(f"  {g:<{width}}  {what}")
    return lines


def _metrics(texts: Mapping[str, str]) -> list[str]:
    tables = []
    for path, text in sorted(texts.items()):
        parsed = _comparison(text) if path.endswith("/metrics") else None
        if parsed:
            tables.append((path.strip("/").split("/")[0], *parsed))
    if not tables:
        return []
    present = {k for _, _, rows in tables for k in rows}
    # the rows are labelled with units (METRIC_DISPLAY); recordings before that used the keys
    label = {k: METRIC_DISPLAY[k][0] for k in KEY_METRICS}
    keys = ([label[k] for k in KEY_METRICS if label[k] in present]
            or [k for k in KEY_METRICS if k in present] or sorted(present)[:6])  # fmt: skip
    head = ["scenario", "controller", *keys]
    def label(c: str, rows: Mapping[str, Mapping[str, str]]) -> str:
        verdict = rows.get("safety", {}).get(c, "")  # the recording's safety row, if any
        return f"{c} ({verdict.split(':')[0]})" if verdict and verdict != "safe" else c

    body = [[s if i == 0 else "", label(c, rows), *(rows.get(k, {}).get(c, "") for k in keys)]
            for s, ctrls, rows in tables for i, c in enumerate(ctrls)]  # fmt: skip
    widths = [max(len(r[j]) for r in [head, *body]) for j in range(len(head))]
    fmt = "  " + "  ".join(f"{{:<{w}}}" for w in widths)
    lines = [fmt.format(*r).rstrip() for r in body]
    return [f"metrics      ({len(tables)} comparison tables)", fmt.format(*head).rstrip(),
            *_capped(lines, _CAPS["metrics"], "rows")]  # fmt: skip


def _reports(texts: Mapping[str, str]) -> list[str]:
    paths = sorted(p for p in texts if p.endswith("/report") and p != "/analysis/report")
    if not paths:
        return []
    width = max(len(p) - len("/report") for p in paths)
    lines = []
    for p in paths:
        pairs = markdown_pairs(texts[p])
        facts = ", ".join(_fact(k, pairs[k]) for k in KEY_FACTS if pairs.get(k) not in (None, ""))
        lines.append(f"  {p[: -len('/report')]:<{width}}  {facts or '(see --full)'}")
    return [f"reports      {len(paths)}", *_capped(lines, _CAPS["reports"], "reports")]


def _fact(key: str, value: str) -> str:
    """``key value`` of a report, a number rounded and labelled as :data:`FACT_DISPLAY` says
    (``gamma_peak_omega 0.451821`` -> ``at ω 0.452 rad/s``); anything else as written."""
    if key not in FACT_DISPLAY:
        return f"{key} {value}"
    label, unit, fmt = FACT_DISPLAY[key]
    try:
        return f"{label} {format_metric(float(value), fmt)}{unit}"
    except ValueError:  # "None", "n/a": not a number
        return f"{label} {value}"


def summary_lines(summary: RecordingSummary) -> list[str]:
    """What a recording holds in at most :data:`MAX_LINES` lines (all of it: :func:`full_lines`)."""
    lines = _header(summary)
    for path, text in sorted(summary.texts.items()):
        if path.endswith("/status"):
            body = " ".join(x for x in text.splitlines() if x and not x.startswith("#"))
            lines.append(f"status       {path}: {body.replace('**', '')}")
    lines.append(f"entities     {len(summary.entities)} (each one with --full)")
    lines += _capped(_groups(summary), _CAPS["groups"], "groups")
    lines += _metrics(summary.texts)
    lines += _reports(summary.texts)
    if len(lines) > MAX_LINES:
        lines = [*lines[: MAX_LINES - 1], f"... {len(lines) - MAX_LINES + 1} more lines (--full)"]
    return lines
