"""README.md stays short, and every time it quotes is measured: its "Measured on this machine"
block is ``benchmarks/commands.md`` verbatim (written by ``benchmarks/bench_commands.py
--update-readme``), and no other line of it claims a duration or a size."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BEGIN = "<!-- begin benchmarks/commands.md -->"
END = "<!-- end benchmarks/commands.md -->"

#: A duration or a size: a number (``8``, ``1.5``, ``~1.5``, ``1,000``) and a unit of time or
#: of bytes.
TIMING = re.compile(
    r"(?<![\d.,])\d(?:[\d,]*\d)?(?:\.\d+)?\s*"
    r"(?:ms|µs|us|s|sec|secs|seconds?|min|mins|minutes?|h|hrs?|hours?|[kKMGT]i?B)\b"
)
#: Two metrics of the showcase table, not claims: the column "max 1 s jerk" (a 1 s window) and
#: a cell "| over 0.30 s |" (the time above ISO 15622's jerk limit).
METRICS = re.compile(r"max 1 s jerk|\| over \d+(?:\.\d+)? s(?= \|)")


def timing_claim(line: str) -> bool:
    return TIMING.search(METRICS.sub("|", line)) is not None


def readme() -> str:
    return (ROOT / "README.md").read_text()


def split_at_the_block(text: str) -> tuple[str, str, str]:
    """``(before, between, after)`` of the markers' lines; exactly one pair, in order."""
    assert text.count(BEGIN) == 1 and text.count(END) == 1, "one begin and one end marker"
    before, rest = text.split(BEGIN, 1)
    between, after = rest.split(END, 1)
    return before, between, after


def test_the_measured_block_is_benchmarks_commands_md():
    """Fails until ``benchmarks/commands.md`` exists and ``bench_commands.py --update-readme``
    has copied it between the markers."""
    _, between, _ = split_at_the_block(readme())
    table = ROOT / "benchmarks" / "commands.md"
    assert table.is_file(), "benchmarks/commands.md is missing: run benchmarks/bench_commands.py"
    # the markers' own line ends aside, the text between them is the file's, verbatim
    assert between.strip("\n") == table.read_text().strip("\n"), (
        "README.md's measured block differs from benchmarks/commands.md: run "
        "python benchmarks/bench_commands.py --update-readme"
    )


def test_no_timing_claim_outside_the_measured_block():
    before, _, after = split_at_the_block(readme())
    claims = [
        f"README.md:{i}: {line.strip()}"
        for i, line in enumerate((before + after).splitlines(), 1)
        if timing_claim(line)
    ]
    assert claims == []


@pytest.mark.parametrize(
    "line",
    ["lcc-synth run  # ~1.5 min", "8 MB of recording", "about 25 s to build", "11.4 min",
     "pytest (1,000 s)", "a 2 GB file", "over 0.30 s", "| over 1 min |", "takes 90 seconds",
     "~5 s", "in 0.3 ms", "1.5-3 min"],
)  # fmt: skip
def test_the_timing_pattern_catches_claims(line):
    assert timing_claim(line), line


@pytest.mark.parametrize(
    "line",
    ["| max 1 s jerk (m/s³) |", "| over 0.30 s |", "min TTC (s)", "AAVE (m/s)", "Figs. 7-8",
     "Python >= 3.11", "window=(20.0, 40.0)", "the CAV, 10 HDVs behind it",
     "lcc.system(\"fd_lcc\", n=10)"],
)  # fmt: skip
def test_the_timing_pattern_spares_units_and_names(line):
    assert not timing_claim(line), line


def test_readme_is_short():
    assert len(readme().splitlines()) <= 260


def test_the_showcase_table_shows_table_ii():
    """The ``brake_behind`` rows of README's showcase table are the paper's Table II (AAVE,
    fuel) as ``tests/test_api.py`` pins them: all-HDV and the paper's CF-LCC gain."""
    from test_api import TABLE2

    rows = {}
    for line in readme().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0] == "brake_behind":
            rows[cells[1]] = (float(cells[2]), float(cells[3]))
    assert rows["all_hdv"] == TABLE2["all_hdv"]
    assert rows["paper"] == TABLE2["cf_lcc"]
