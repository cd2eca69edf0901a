"""Human output of the commands: aligned text tables and numbers with sensible digits.

The ``--json`` documents are the machine face and keep every digit; what a person reads goes
through :func:`text_table` and :func:`sig`: times with 3 significant digits (``0.350 ms``,
``5.41 ms``), counts as integers, no Python or JSON literals among the rows.

:func:`write_and_report` is the one ending of the commands that compute a report and then write
files of it (``analyze``, ``calibrate``, ``regions``, ``synthesize``): the files are written
through :mod:`lcc_synth.outputs` by the command's own writer, and a file that cannot be written
(a full disk) does not hide the report, which is printed first; its error is one stderr line and
exit status 1.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any

__all__ = ["LINE_WIDTH", "sig", "text_table", "controller_stats_lines", "write_and_report"]


def sig(value: Any, digits: int = 3) -> str:
    """``value`` with ``digits`` significant digits (``"n/a"`` for ``None``, ``"nan"``...).

    Examples
    --------
    >>> sig(0.35019700044358615), sig(5.414282189412915), sig(850), sig(1234.5), sig(None)
    ('0.350', '5.41', '850', '1234', 'n/a')
    >>> sig(9.9996), sig(0.99951), sig(0.0099996)  # rounding up to the next decade
    ('10.0', '1.00', '0.0100')
    """
    if value is None:
        return "n/a"
    x = float(value)
    if not math.isfinite(x):
        return str(x)
    if x == 0:
        return "0"
    # the decade of x rounded to ``digits`` (9.9996 is 10.0: its digits are counted from 10)
    exponent = math.floor(math.log10(abs(float(f"{x:.{digits - 1}e}"))))
    if exponent < -4:
        return f"{x:.{digits - 1}e}"
    return f"{x:.{max(0, digits - 1 - exponent)}f}"  # 1234.5 -> "1234": no exponent


def text_table(
    header: Sequence[str], rows: Sequence[Sequence[str]], width: int | None = None
) -> list[str]:
    """Lines of a left-aligned table: the header, a rule, one line per row (cells as given);
    with ``width``, split into blocks of columns no wider, each repeating the first column
    (:func:`lcc_synth.experiments.tables.column_blocks`)."""
    from lcc_synth.experiments.tables import column_blocks

    return column_blocks(header, rows, width, keep=1)


#: The longest line of a command's text output (``run``'s tables wrap their columns to it).
LINE_WIDTH = 100

_MPC_HEADER = ["controller", "steps", "solves", "step ms median", "p99", "max", "iterations",
               "fallbacks", "QP failures", "slack steps", "errors"]  # fmt: skip


def _count(value: Any) -> str:
    if isinstance(value, Mapping):  # e.g. qp_failures = {status: count}
        return str(sum(int(v) for v in value.values()))
    return "n/a" if value is None else str(int(value))


def _whole(value: Any) -> str:
    """A count that may be a half (the median of an even number of counts)."""
    return "n/a" if value is None else f"{float(value):g}"


def controller_stats_lines(
    stats: Mapping[str, Mapping[str, Any]], width: int | None = None
) -> list[str]:
    """The run statistics of the controllers that have some (``{label: stats}``, the MPC's
    :meth:`~lcc_synth.mpc.controller.MPCController.stats`) as a short table.

    MPC statistics give one row each: samples (``steps``), QP solves (all batch members),
    controller step time per batch member (median / p99 / max, ms), OSQP iterations
    (median / max), fallbacks, QP failures (every non-solved status), steps that used the
    safety slack, and errors (then the first error message). Other controllers' statistics
    follow as ``label: key = value``.
    Empty when no controller has statistics. ``width``: the table's columns wrap to it
    (:func:`text_table`).
    """
    rows, other = [], []
    for label, st in stats.items():
        if not st:
            continue
        if "step_time_ms" not in st:
            other.append(
                f"{label}: " + ", ".join(
                    f"{k} = {sig(v) if isinstance(v, float) else v}" for k, v in st.items()
                )
            )  # fmt: skip
            continue
        t = st["step_time_ms"]
        it = st.get("iterations", {})
        rows.append([
            label, _count(st.get("steps")), _count(st.get("solves")), sig(t.get("median")),
            sig(t.get("p99")), sig(t.get("max")),
            f"{_whole(it.get('median'))} / {_count(it.get('max'))}", _count(st.get("fallbacks")),
            _count(st.get("qp_failures")), _count(st.get("slack_steps")),
            _count(st.get("errors")),
        ])  # fmt: skip
        if st.get("error_messages"):
            other.append(f"{label}: solver errors, the first: {st['error_messages'][0]}")
    lines = []
    if rows:
        lines.append("MPC solver (step time per batch member, ms; iterations median / max):")
        lines += text_table(_MPC_HEADER, rows, width)
    return lines + other


def write_and_report(
    command: str,
    as_json: bool,
    write: Callable[[list[str]], None],
    document: Callable[[list[str], bool], Mapping[str, Any]],
    report: Callable[[], None],
) -> int:
    """Write a command's files, print its result, and give its exit status.

    Parameters
    ----------
    command
        The command's name, for the error line (``lcc-synth COMMAND: error: ...``).
    as_json
        ``--json``: print ``document`` as one JSON object; else call ``report`` and print
        ``wrote PATH`` for each file written.
    write
        Writes the files (through :mod:`lcc_synth.outputs`), appending the path of each file
        written to the list it is given, in order; may raise
        :class:`~lcc_synth.errors.FileError`, which stops the writing (the files written before
        it stay listed).
    document
        ``document(written, ok)``: the JSON object (``ok``: no file failed).
    report
        Prints the text report.

    Returns
    -------
    int
        0, or 1 after a file that could not be written (its one line on stderr, after the
        report).
    """
    from lcc_synth.errors import FileError

    written: list[str] = []
    error: FileError | None = None
    try:  # a file that cannot be written (a full disk) does not hide the report printed below
        write(written)
    except FileError as err:
        error = err
    if as_json:
        print(json.dumps(document(written, error is None)))
    else:
        report()
        for w in written:
            print(f"wrote {w}")
    if error is None:
        return 0
    print(f"lcc-synth {command}: error: {error}", file=sys.stderr)
    return 1
