"""The user-facing commands against their time budgets, each in a fresh interpreter.

Each row runs one command as a subprocess of this script (its own session, output to a log
file in a temporary directory) and measures its wall time and its CPU time: user + system of
the child and of every descendant it waited for (``os.wait4``: the Dask workers of a sweep,
the CLI subprocesses of the tests), so a command that uses both cores counts both.

======== ===================================================================== ============
row      command                                                               budget
======== ===================================================================== ============
run      ``lcc-synth run`` (the default problem, recording and figures)        30 s CPU
sweep10  ``lcc-synth sweep problems/sweep_robustness.toml --count 10``         20 s wall
sweep1000 the same with ``--count 1000`` (every controller of the file)        300 s wall
pytest   ``pytest -q -p no:cacheprovider`` (``CI`` unset: the default suite)   360 s CPU
docs     ``sphinx-build -W --keep-going -q -b html docs <tmp>``                60 s wall
install  ``pip install -e ".[dev]"`` into a fresh venv (needs the package      wall, no
         index; measured only when named: ``--only install``)                  budget
======== ===================================================================== ============

``run`` and the sweeps run in an empty temporary directory, so their default outputs
(``results/``, ``logs/``) land there; the tests and the docs run in the repository. The
children see this checkout first (``PYTHONPATH``), ``RERUN_ANALYTICS=0`` and
``MPLBACKEND=Agg``, with Python's bytecode cache on and written before the first row
(:func:`warm_bytecode`: a sandbox that sets ``PYTHONDONTWRITEBYTECODE`` made every process
compile each edited module again). A command still running at 10x its budget (a loaded
machine) is stopped (its whole session) and reported over budget.

Every measured row is stored in ``benchmarks/commands.json`` with the UTC date, the load
average of the machine when it started, its CPU count and the last lines of the command's
output; ``--only NAME[,NAME]`` measures
those rows again and keeps the others. ``benchmarks/commands.md`` is written from the JSON:
the table ``| command | budget | CPU (s) | wall (s) | within budget | measured |`` and the
load averages under it; ``--update-readme`` copies it, verbatim, between the lines
``<!-- begin benchmarks/commands.md -->`` and ``<!-- end benchmarks/commands.md -->`` of
``README.md`` (an error naming README.md when they are missing). Progress, one line per row
with an estimate before it, goes to stderr.

Where the time goes (2026-12-02, the 2-core machine at a load average of about 2, numba's
cache warm; the phases in CPU seconds of the process, ``time.perf_counter`` read as
``time.process_time``; the items from cProfile):

* ``lcc-synth run``: 40 s CPU (41.3 s here with its children; main before these changes
  47.7 s and this branch 48.3 s at a load of 12-15). String stability as run 20.1 s: five
  simulator measurements of the controllers that are not linear (mpc on string10 and sec5a;
  mpc, mpc_delay and deep_lcc at 0.1 s latency), 205.6 s of simulated time each with about
  2,056 QPs (4,112 for DeeP-LCC), nearly all of it OSQP's solves. The suite's simulations
  11.8 s (OSQP again: 20,560 solves over both phases, 30 of 72 profiled seconds), the
  controllers (four H2 LMI designs, one per layout) 2.1 s, the rest 6 s (imports about 3 s;
  figures, recording, tables). A fresh checkout compiles the simulator's numba kernels once
  (43 of 115 profiled seconds; cached in ``__pycache__`` after that).
* ``lcc-synth sweep problems/sweep_robustness.toml``: per scenario, with one BLAS thread as a
  worker has, 1.78 s CPU: deep_lcc 1.08 s (its data, its set-up about 0.35 s, the 40 s run
  with 800 QPs), mpc 0.36 s, mpc_delay 0.31 s, all_hdv, paper and h2 0.01 s each; a
  worker's first task 0.9 s more (it builds the controllers). The client synthesises h2
  (1.3 s) and, at the end, writes the figure and the recordings and simulates the hardest
  scenario again with every controller. ``--count 10``: the tasks 14.5-23 s of the 30 s
  wall. 1000 scenarios: about 1,780 s CPU, 15 min wall on 2 workers (budget 5 min).
* The same sweep on 2026-12-04 (one process, one BLAS thread, 12 scenarios): 0.51-0.52 s CPU
  per scenario, deep_lcc 0.33 s (its data 0.07 s, its set-up 0.13 s: the reduction in the
  890 weighted rows instead of the 1931 x 1931 Hessian, 0.19 -> 0.11 s), mpc 0.066 s,
  mpc_delay 0.072 s, the three static controllers 0.009 s each. On the local cluster the
  workers spent about 10 % more per scenario than one process, of which Dask's 10 ms stack
  profiler and 20 ms event-loop ticks took 6 % (``LOCAL_CLUSTER_CONFIG`` turns them down).

Usage: python benchmarks/bench_commands.py [--only run,sweep10] [--update-readme]
       [--table-only]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
JSON_PATH = ROOT / "benchmarks" / "commands.json"
MD_PATH = ROOT / "benchmarks" / "commands.md"
README = ROOT / "README.md"
BEGIN = "<!-- begin benchmarks/commands.md -->"
END = "<!-- end benchmarks/commands.md -->"
#: Last lines of a command's output kept in commands.json (its own account of its time).
TAIL_LINES = 6
#: A command still running at this multiple of its budget is stopped.
TIMEOUT_FACTOR = 10.0


@dataclass(frozen=True)
class Row:
    """One command: ``kind`` is what its budget limits (``"cpu"``, ``"wall"``; ``None``: no
    budget), ``estimate`` the wall seconds printed before a first measurement."""

    name: str
    command: str
    kind: str | None
    budget: float | None
    estimate: float
    default: bool = True  # measured without --only


ROWS: dict[str, Row] = {r.name: r for r in (
    Row("run", "lcc-synth run", "cpu", 30.0, 60.0),
    Row("sweep10", "lcc-synth sweep problems/sweep_robustness.toml --count 10", "wall", 20.0,
        30.0),
    Row("sweep1000", "lcc-synth sweep problems/sweep_robustness.toml --count 1000", "wall",
        300.0, 1800.0),
    Row("pytest", "pytest -q -p no:cacheprovider", "cpu", 360.0, 400.0),
    Row("docs", "sphinx-build -W --keep-going -q -b html docs <tmp>", "wall", 60.0, 30.0),
    Row("install", 'pip install -e ".[dev]" (fresh venv)', None, None, 180.0, default=False),
)}  # fmt: skip


def _argv(name: str, tmp: Path) -> tuple[list[str], Path]:
    """The command line of row ``name`` and its working directory."""
    py = sys.executable
    cli = [py, "-m", "lcc_synth.cli.main"]
    sweep = str(ROOT / "problems" / "sweep_robustness.toml")
    if name == "run":
        return [*cli, "run"], tmp
    if name == "sweep10":
        return [*cli, "sweep", sweep, "--count", "10"], tmp
    if name == "sweep1000":
        return [*cli, "sweep", sweep, "--count", "1000"], tmp
    if name == "pytest":
        return [py, "-m", "pytest", "-q", "-p", "no:cacheprovider"], ROOT
    if name == "docs":
        return [py, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", "docs",
                str(tmp / "html")], ROOT  # fmt: skip
    if name == "install":
        venv = tmp / "venv"
        script = (f'"{py}" -m venv "{venv}" && "{venv}/bin/pip" install -q -e '
                  f'"{ROOT}[dev]"')  # fmt: skip
        return ["sh", "-c", script], tmp
    raise KeyError(name)


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("CI", None)  # the default suite, as a user runs it
    # Python's bytecode cache on, as on a user's machine: with PYTHONDONTWRITEBYTECODE set (this
    # sandbox sets it) every process compiles again each module edited since its cache was
    # last written, and the suite starts a few hundred processes
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    env.update(RERUN_ANALYTICS="0", MPLBACKEND="Agg")
    return env


def measure(argv: Sequence[str], cwd: Path, log: Path, timeout: float | None = None,
            env: Mapping[str, str] | None = None) -> dict:  # fmt: skip
    """Run ``argv`` in ``cwd`` (stdout and stderr to ``log``): ``{"cpu_s", "wall_s",
    "exit", "timed_out"}``; CPU = user + system of the child and its waited-for descendants
    (``os.wait4``). After ``timeout`` s its whole session is killed."""
    import subprocess

    with open(log, "wb") as out:
        t0 = time.perf_counter()
        proc = subprocess.Popen(list(argv), cwd=cwd, stdout=out, stderr=subprocess.STDOUT,
                                env=None if env is None else dict(env),
                                start_new_session=True)  # fmt: skip
        timed_out = False
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid == proc.pid:
                break
            if timeout is not None and time.perf_counter() - t0 > timeout and not timed_out:
                timed_out = True
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except OSError:
                    pass
            time.sleep(0.05)
        wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here, not by Popen
    return {"cpu_s": usage.ru_utime + usage.ru_stime, "wall_s": wall,
            "exit": proc.returncode, "timed_out": timed_out}  # fmt: skip


def _budget_text(row: Row) -> str:
    if row.budget is None:
        return "-"
    return f"<= {row.budget:g} s {'CPU' if row.kind == 'cpu' else 'wall'}"


def within(row: Row, rec: Mapping) -> str:
    """``"yes"``, ``"no"``, or why there is no answer (a failed or stopped command)."""
    if rec.get("timed_out"):
        return f"no (stopped at {TIMEOUT_FACTOR:g}x the budget)"
    if rec.get("exit"):
        return f"failed (exit {rec['exit']})"
    if row.budget is None:
        return "-"
    value = rec["cpu_s"] if row.kind == "cpu" else rec["wall_s"]
    return "yes" if value <= row.budget else "no"


def format_table(records: Mapping[str, Mapping]) -> str:
    """``benchmarks/commands.md``: the table of every row (``records``: the stored rows by
    name; a row never measured shows dashes) and the load averages under it."""
    lines = ["| command | budget | CPU (s) | wall (s) | within budget | measured |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    notes = []
    for name, row in ROWS.items():
        rec = records.get(name)
        if rec is None:
            lines.append(f"| `{row.command}` | {_budget_text(row)} | - | - | not measured | - |")
            continue
        lines.append(f"| `{row.command}` | {_budget_text(row)} | {rec['cpu_s']:.1f} | "
                     f"{rec['wall_s']:.1f} | {within(row, rec)} | {rec['date']} |")  # fmt: skip
        load = "/".join(f"{x:.2f}" for x in rec["loadavg"])
        ref = f", reference {rec['reference_s']:.3f} s" if "reference_s" in rec else ""
        notes.append(f"{name} {load} ({rec['cpus']} CPUs{ref})")
    text = "\n".join(lines) + "\n"
    if notes:
        text += ("\nLoad average (1/5/15 min) of the machine when each row started: "
                 + "; ".join(notes) + ". CPU: user + system of the command and of every "
                 "process it waited for. Reference: the CPU time of a fixed single-threaded "
                 "workload just before the row (best of 3): CPU times compare only as their "
                 "references do. `python benchmarks/bench_commands.py` measures "
                 "again.\n")  # fmt: skip
    return text


def replace_between_markers(readme: Path, text: str) -> str:
    """The content of ``readme`` with the lines between :data:`BEGIN` and :data:`END`
    replaced by ``text`` (the markers kept).

    Raises
    ------
    ValueError
        One line naming the file when a marker is missing, repeated or out of order.
    """
    lines = readme.read_text(encoding="utf-8").splitlines(keepends=True)
    where = {m: [i for i, ln in enumerate(lines) if ln.strip() == m] for m in (BEGIN, END)}
    if len(where[BEGIN]) != 1 or len(where[END]) != 1 or where[BEGIN][0] > where[END][0]:
        raise ValueError(f"{readme.name} ({readme}) needs the lines {BEGIN!r} and {END!r}, "
                         "once each and in that order, around the benchmark table; add them "
                         "where the table goes")  # fmt: skip
    b, e = where[BEGIN][0], where[END][0]
    body = text if text.endswith("\n") else text + "\n"
    return "".join(lines[: b + 1]) + body + "".join(lines[e:])


def _write(path: Path, text: str) -> None:
    from lcc_synth.outputs import write_text

    write_text(path, text, overwrite=True)


def load_records(path: Path | None = None) -> dict[str, dict]:
    """The stored rows of ``path`` (default :data:`JSON_PATH`), ``{}`` before a first run."""
    path = JSON_PATH if path is None else path
    if not path.exists():
        return {}
    return json.loads(path.read_text(encoding="utf-8")).get("rows", {})


def _estimate(row: Row, last: Mapping | None) -> str:
    if last is None:
        return f"about {row.estimate:.0f} s wall (first measurement)"
    return f"about {last['wall_s']:.0f} s wall (last: {last['date']})"


def reference_seconds() -> float:
    """CPU seconds of a fixed single-threaded workload (a pure-Python loop of 3 million
    multiply-adds), best of 3: how fast this machine's cores are right now. On this VM the
    same work has taken 30 % more CPU seconds while the host was busy, so a row's CPU time
    is read against the reference measured with it."""
    best = float("inf")
    for _ in range(3):
        t0 = time.process_time()
        acc = 0
        for i in range(3_000_000):
            acc += i * i
        best = min(best, time.process_time() - t0)
    return best


def warm_bytecode() -> None:
    """Write the bytecode cache of the package, the tests, the examples and the benchmarks
    (``compileall``, not measured): every row then measures a second invocation, as a user's
    machine runs it once the package has been imported once."""
    import compileall

    for part in ("lcc_synth", "tests", "examples", "benchmarks"):
        compileall.compile_dir(ROOT / part, quiet=1)


def run_rows(names: Sequence[str], records: dict[str, dict]) -> dict[str, dict]:
    """Measure ``names`` (progress on stderr); returns ``records`` with them replaced."""
    out = dict(records)
    warm_bytecode()
    for k, name in enumerate(names, 1):
        row = ROWS[name]
        print(f"[{k}/{len(names)}] {name}: {row.command}; {_estimate(row, records.get(name))}",
              file=sys.stderr, flush=True)  # fmt: skip
        ref = reference_seconds()
        load = list(os.getloadavg())
        with tempfile.TemporaryDirectory(prefix=f"lcc-bench-{name}-") as tmp:
            argv, cwd = _argv(name, Path(tmp))
            timeout = None if row.budget is None else TIMEOUT_FACTOR * row.budget
            log = Path(tmp) / "output.log"
            rec = measure(argv, cwd, log, timeout, _env())
            lines = log.read_text(errors="replace").splitlines()
            if rec["exit"] and not rec["timed_out"]:
                print("\n".join(f"    {ln}" for ln in lines[-15:]), file=sys.stderr)
            # the command's own account of its time (run: "time: controllers ...")
            rec["output_tail"] = [ln[-300:] for ln in lines[-TAIL_LINES:]]
        rec.update(date=datetime.now(UTC).strftime("%Y-%m-%d"), loadavg=load,
                   cpus=os.cpu_count(), reference_s=ref)  # fmt: skip
        out[name] = rec
        print(f"    {name}: CPU {rec['cpu_s']:.1f} s, wall {rec['wall_s']:.1f} s; budget "
              f"{_budget_text(row)}: {within(row, rec)}", file=sys.stderr, flush=True)  # fmt: skip
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", metavar="NAME[,NAME]",
                    help=f"measure these rows only, keep the others ({', '.join(ROWS)})")
    ap.add_argument("--update-readme", action="store_true",
                    help="copy benchmarks/commands.md into README.md between its markers")
    ap.add_argument("--table-only", action="store_true",
                    help="measure nothing: write commands.md from commands.json")
    args = ap.parse_args(argv)
    if args.only:
        names = [n.strip() for n in args.only.split(",") if n.strip()]
        bad = [n for n in names if n not in ROWS]
        if bad:
            ap.error(f"--only: unknown row {bad[0]!r}; the rows are {', '.join(ROWS)}")
    else:
        names = [n for n, r in ROWS.items() if r.default]
    records = load_records()
    if args.update_readme and not args.table_only:
        # the pytest row runs tests/test_readme.py: the README's block and commands.md must
        # agree while it runs (both are written again from the new figures below)
        _write(MD_PATH, format_table(records))
        _write(README, replace_between_markers(README, format_table(records)))
    if not args.table_only:
        records = run_rows(names, records)
        _write(JSON_PATH, json.dumps({"rows": records}, indent=2, sort_keys=True) + "\n")
    text = format_table(records)
    _write(MD_PATH, text)
    print(text, end="")
    if args.update_readme:
        try:
            _write(README, replace_between_markers(README, text))
        except ValueError as err:
            print(f"bench_commands: {err}", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
