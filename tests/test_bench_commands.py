"""``benchmarks/bench_commands.py``: its table writer, its README updater (on a temporary
README) and what its measurement counts; no timings are asserted."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_commands",
                                                  ROOT / "benchmarks" / "bench_commands.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)


def _rec(cpu, wall, exit=0, timed_out=False):
    return {"cpu_s": cpu, "wall_s": wall, "exit": exit, "timed_out": timed_out,
            "date": "2026-12-02", "loadavg": [1.5, 1.25, 1.0], "cpus": 2}  # fmt: skip


def test_table_rows_and_verdicts(bench):
    records = {"run": _rec(31.04, 40.0), "sweep10": _rec(50.0, 19.96),
               "pytest": _rec(10.0, 10.0, exit=1), "docs": _rec(5.0, 250.0, timed_out=True)}
    text = bench.format_table(records)
    lines = text.splitlines()
    assert lines[0] == "| command | budget | CPU (s) | wall (s) | within budget | measured |"
    assert lines[1] == "|---|---|---|---|---|---|"
    body = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]]
            for ln in lines[2:2 + len(bench.ROWS)]}  # fmt: skip
    assert len(body) == len(bench.ROWS)
    # run's budget is CPU: 31.04 s > 30 s although its wall is larger still
    assert body["`lcc-synth run`"] == ["<= 30 s CPU", "31.0", "40.0", "no", "2026-12-02"]
    # sweep10's budget is wall: 19.96 s <= 20 s although the CPU is 50 s
    assert body["`lcc-synth sweep problems/sweep_robustness.toml --count 10`"][1:4] == [
        "50.0", "20.0", "yes"]
    assert body["`pytest -q -p no:cacheprovider`"][3] == "failed (exit 1)"
    assert body["`sphinx-build -W --keep-going -q -b html docs <tmp>`"][3].startswith("no (stopped")
    assert body["`lcc-synth sweep problems/sweep_robustness.toml --count 1000`"] == [
        "<= 300 s wall", "-", "-", "not measured", "-"]
    note = [ln for ln in lines if ln.startswith("Load average")]
    assert len(note) == 1 and "run 1.50/1.25/1.00 (2 CPUs)" in note[0]


def test_readme_between_markers_is_replaced_verbatim(bench, tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text(f"# Title\n\nbefore\n{bench.BEGIN}\nold table\nold note\n{bench.END}\n"
                      "after\n")  # fmt: skip
    text = bench.format_table({"run": _rec(20.0, 25.0)})
    new = bench.replace_between_markers(readme, text)
    assert new == f"# Title\n\nbefore\n{bench.BEGIN}\n{text}{bench.END}\nafter\n"
    readme.write_text(new)
    assert bench.replace_between_markers(readme, text) == new  # idempotent


@pytest.mark.parametrize("content", [
    "no markers\n",
    "<!-- begin benchmarks/commands.md -->\nonly the first\n",
    "<!-- end benchmarks/commands.md -->\n<!-- begin benchmarks/commands.md -->\n",
    "<!-- begin benchmarks/commands.md -->\n<!-- begin benchmarks/commands.md -->\n"
    "<!-- end benchmarks/commands.md -->\n",
])  # fmt: skip
def test_readme_without_its_markers_is_an_error_naming_it(bench, tmp_path, content):
    readme = tmp_path / "README.md"
    readme.write_text(content)
    with pytest.raises(ValueError, match=r"^README\.md .*begin benchmarks/commands\.md"):
        bench.replace_between_markers(readme, "table\n")
    assert readme.read_text() == content


def test_main_update_readme_fails_with_exit_2_when_the_markers_are_missing(bench, tmp_path,
                                                                         monkeypatch, capsys):
    for name in ("JSON_PATH", "MD_PATH", "README"):
        monkeypatch.setattr(bench, name, tmp_path / {"JSON_PATH": "c.json", "MD_PATH": "c.md",
                                                     "README": "README.md"}[name])  # fmt: skip
    (tmp_path / "README.md").write_text("nothing here\n")
    assert bench.main(["--table-only", "--update-readme"]) == 2
    assert "README.md" in capsys.readouterr().err
    assert (tmp_path / "c.md").read_text() == bench.format_table({})
    (tmp_path / "README.md").write_text(f"x\n{bench.BEGIN}\n{bench.END}\n")
    assert bench.main(["--table-only", "--update-readme"]) == 0
    assert (tmp_path / "README.md").read_text() == (
        f"x\n{bench.BEGIN}\n{bench.format_table({})}{bench.END}\n")


def test_measure_counts_the_cpu_of_grandchildren(bench, tmp_path):
    """The command's CPU includes a process it started and waited for: at least what that
    grandchild reports for itself (resource.getrusage of its own process)."""
    burn = ("import resource\nx = 0\nfor i in range(3_000_000):\n    x += i * i\n"
            "u = resource.getrusage(resource.RUSAGE_SELF)\nprint(u.ru_utime + u.ru_stime)\n")
    child = f"import subprocess, sys\nsubprocess.run([sys.executable, '-c', {burn!r}])\n"
    log = tmp_path / "log"
    rec = bench.measure([sys.executable, "-c", child], tmp_path, log)
    assert rec["exit"] == 0 and not rec["timed_out"]
    reported = float(log.read_text().split()[-1])
    assert reported > 0 and rec["cpu_s"] >= reported


def test_measure_stops_a_command_past_its_timeout_and_reports_its_exit(bench, tmp_path):
    rec = bench.measure([sys.executable, "-c", "import time; time.sleep(60)"], tmp_path,
                        tmp_path / "log", timeout=0.5)  # fmt: skip
    assert rec["timed_out"] and rec["exit"] != 0
    rec = bench.measure([sys.executable, "-c", "raise SystemExit(3)"], tmp_path, tmp_path / "l")
    assert rec["exit"] == 3 and not rec["timed_out"]
