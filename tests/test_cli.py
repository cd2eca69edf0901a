"""``lcc-synth`` as a user meets it: --version, usage on a bad option, options that do not
apply, errors that name the file, help without internal labels, readable human output."""

from __future__ import annotations

import json
import os
import re
import tomllib
from pathlib import Path

import pytest

from lcc_synth.cli.main import COMMANDS, build_parser, main
from lcc_synth.cli.output import controller_stats_lines, sig

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ROOT / "problems"

#: Internal labels that must not reach users: "(contract 3)", "contract 4", "(issue 5)"...
LABEL = re.compile(r"\bcontract \d|\(contract\b|\bissue \d|\(issue\b|\bissue #\d", re.I)
#: A float printed with all its digits (as ``json.dumps`` or ``repr`` do).
LONG_FLOAT = re.compile(r"\d\.\d{7,}")


def _error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _subparsers():
    parser = build_parser()
    [action] = [a for a in parser._actions if a.dest == "command"]
    return action.choices


# ---------------------------------------------------------------------------------- --version


def test_version_is_the_package_version(capsys):
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"lcc-synth {version}"


# ----------------------------------------------------------------- usage of the right command


@pytest.mark.parametrize("command", COMMANDS)
def test_unknown_option_prints_the_commands_usage(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "some.toml", "--no-such-option", "3"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"usage: lcc-synth {command} "), err
    assert f"lcc-synth {command}: error: unrecognized arguments: --no-such-option 3" in err


def test_simulate_out_is_simulates_error(capsys):
    """The issue's example: ``simulate --out res`` (an option of ``run``, not of simulate)."""
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--out", "res"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: lcc-synth simulate ") and "--out" in err.splitlines()[-1]
    assert "{run,analyze" not in err  # not the top-level usage


def test_unknown_command_prints_the_top_level_usage(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulat"])
    assert exc.value.code == 2
    assert capsys.readouterr().err.startswith("usage: lcc-synth [-h] [--version]")


# ------------------------------------------------------------- options that apply, and no more

_RECORD = {"--rrd", "--no-record", "--overwrite"}
_STEPS = {"--record-every", "--max-recording-size"}
#: Every command's options (the audit): a simulation records steps (--record-every, and its
#: size is limited: --max-recording-size); analyze, regions, synthesize and sweep record no
#: steps; review reads a recording.
#: Every command: --quiet (its alias --no-progress).
_QUIET = {"--quiet", "--no-progress"}
EXPECTED_OPTIONS = {
    "run": {"--json", "--scenarios", "--controllers", "--out", "--no-figures", "--format",
            "--verbose", *_QUIET, *_RECORD, *_STEPS},
    "analyze": {"--json", "--png", *_QUIET, *_RECORD},
    "regions": {"--json", "--png", "--step", *_QUIET, *_RECORD},
    "simulate": {"--json", "--seeds", "--record-seeds", "--export", "--export-format", *_QUIET,
                 *_RECORD, *_STEPS},
    "synthesize": {"--json", "--out", "--figure", *_QUIET, *_RECORD},
    "sweep": {"--json", "--count", "--batch-size", "--seed", "--scheduler", "--workers", "--resume",
              "--controllers", "--out", "--no-figures", "--format", *_QUIET, *_RECORD},
    "review": {"--summary", "--json", "--web", "--web-port", "--port", *_QUIET},
    "calibrate": {"--model", "--json", "--out", "--length", "--starts", "--seed", "--substeps",
                  "--overwrite", *_QUIET},
}  # fmt: skip


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_has_exactly_its_options(command):
    parser = _subparsers()[command]
    options = {s for a in parser._actions for s in a.option_strings if s.startswith("--")}
    if command == "review":  # its summary may gain options; it must never record or write
        assert options >= EXPECTED_OPTIONS[command]
        assert not options & {"--rrd", "--no-record", "--record-every", "--out"}
        return
    assert options - {"--help"} == EXPECTED_OPTIONS[command]


def test_run_options_are_the_ones_the_guide_lists():
    """The guide's "Options:" line of ``lcc-synth run`` (docs/guide/getting_started.md) is an
    independent list of run's options."""
    text = (ROOT / "docs" / "guide" / "getting_started.md").read_text()
    line = re.search(r"^Options: (.*?)\.$", text, re.M | re.S).group(1)
    listed = set(re.findall(r"`(--[a-z-]+)", line))
    assert listed == EXPECTED_OPTIONS["run"]


@pytest.mark.parametrize(
    "argv",
    [
        ["analyze", "p.toml", "--record-every", "5"],
        ["regions", "p.toml", "--record-every", "5"],
        ["synthesize", "p.toml", "--record-every", "5"],
        ["sweep", "p.toml", "--record-every", "5"],
        ["run", "--seeds", "3"],
        ["review", "x.rrd", "--out", "d"],
    ],
)
def test_options_of_another_command_are_usage_errors(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"usage: lcc-synth {argv[0]} ") and "unrecognized arguments" in err


@pytest.mark.parametrize(
    ("argv", "field"),
    [
        (["simulate", "paper_table2.toml", "--no-record", "--record-every", "5"],
         "--record-every"),
        (["run", "showcase.toml", "--no-record", "--record-every", "5"], "--record-every"),
        (["simulate", "paper_table2.toml", "--no-record", "--max-recording-size", "3GB"],
         "--max-recording-size"),
        (["simulate", "paper_table2.toml", "--no-record", "--record-seeds", "0"],
         "--record-seeds"),
        (["simulate", "paper_table2.toml", "--record-seeds", "0"], "--record-seeds"),
        (["sweep", "sweep_robustness.toml", "--scheduler", "tcp://127.0.0.1:1", "--workers", "2"],
         "--workers"),
        (["synthesize", "synth_cf_lcc_pattern.toml", "--no-record", "--figure", "f.png"],
         "--figure"),
        (["review", "x.rrd", "--json"], "--json"),
    ],
)  # fmt: skip
def test_options_that_do_not_apply_together_exit_2(argv, field, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing lands in the repository
    argv = [argv[0], str(PROBLEMS / argv[1]) if argv[1].endswith(".toml") else argv[1], *argv[2:]]
    assert main(argv) == 2
    line = _error_line(capsys)
    assert line.startswith(f"lcc-synth {argv[0]}: error: ") and f"{field}: " in line, line
    assert list(tmp_path.iterdir()) == []  # failed before writing anything (e.g. f.png)


def test_the_same_options_apply_where_they_belong():
    """Positive control of the two tests above: the flags parse where they apply."""
    parser = build_parser()
    args = parser.parse_args(["simulate", "p.toml", "--record-every", "5", "--seeds", "3",
                              "--record-seeds", "0,2"])  # fmt: skip
    assert (args.record_every, args.seeds, args.record_seeds) == (5, 3, "0,2")
    assert parser.parse_args(["run", "--record-every", "4"]).record_every == 4
    assert parser.parse_args(["sweep", "p.toml", "--workers", "1"]).workers == 1
    assert parser.parse_args(["sweep", "p.toml"]).workers is None  # default 2 at run time


# ----------------------------------------------------------------- errors that name the file


@pytest.mark.parametrize("name", ["paper_table2.toml", "showcase.toml"])
def test_synthesize_without_synthesis_table_says_so(name, capsys):
    path = PROBLEMS / name
    assert "synthesis" not in tomllib.loads(path.read_text())  # the premise
    assert main(["synthesize", str(path), "--no-record"]) == 2
    line = _error_line(capsys)
    assert line.startswith(f"lcc-synth synthesize: error: {path}: synthesis: "), line
    assert "no [synthesis] table" in line


def _with(path: Path, old: str, new: str, tmp_path: Path) -> Path:
    text = path.read_text()
    assert text.count(old) >= 1, old
    out = tmp_path / path.name
    out.write_text(text.replace(old, new))
    return out


@pytest.mark.parametrize(
    ("command", "problem", "old", "new", "field"),
    [
        ("simulate", "paper_table2.toml", 'type = "hdv"', 'type = "hdv"\nsample_time = 0.015',
         "controllers.all_hdv.sample_time"),
        ("simulate", "mpc_head_brake.toml", "sample_time = 0.1", "sample_time = 0.015",
         "controllers.mpc.sample_time"),
        ("simulate", "mpc_head_brake.toml", "sample_time = 0.1", "sample_time = 0.001",
         "controllers.mpc.sample_time"),
        ("simulate", "mpc_head_brake.toml", "sample_time = 0.1", "sample_time = 0",
         "controllers.mpc.sample_time"),
        ("run", "showcase.toml", "sample_time = 0.1", "sample_time = 0.015",
         "controllers.mpc.sample_time"),
    ],
)  # fmt: skip
def test_sample_time_errors_name_the_file(command, problem, old, new, field, tmp_path, capsys,
                                          monkeypatch):  # fmt: skip
    """A period that is not a positive multiple of dt = 0.01 s (1.5 steps, 0.1 step) or not
    positive: one line naming the file and the controller's field, before any simulation."""
    path = _with(PROBLEMS / problem, old, new, tmp_path)
    monkeypatch.chdir(tmp_path)
    argv = [command, str(path), "--no-record"]
    if command == "run":
        argv += ["--controllers", "all_hdv,mpc", "--no-progress", "--out", str(tmp_path / "r")]
    assert main(argv) == 2
    line = _error_line(capsys)
    assert line.startswith(f"lcc-synth {command}: error: {path}: {field}: "), line
    assert not [f for f in tmp_path.rglob("*") if f.is_file() and f != path]  # nothing written


def test_a_multiple_of_dt_is_accepted_by_the_load_check():
    """Control of the test above: 0.02 s = 2 steps passes the same check."""
    from lcc_synth.controllers.static import HDVController
    from lcc_synth.errors import ConfigError
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.simulation.timestep import check_time_step

    sc = load_spec(PROBLEMS / "paper_table2.toml").scenario
    check_time_step(sc, {"a": HDVController("a", 0.02)})
    with pytest.raises(ConfigError, match=r"controllers\.a\.sample_time"):
        check_time_step(sc, {"a": HDVController("a", 0.025)})


def test_error_without_a_file_gets_the_problem_file(tmp_path, capsys, monkeypatch):
    """A field error raised without a source (deep in a run) still names the problem file;
    an option's error does not pretend to come from the file."""
    import lcc_synth.cli.simulate as sim
    from lcc_synth.errors import ConfigError

    def boom(args):
        raise ConfigError("scenario.dt", "too coarse")

    monkeypatch.setattr(sim, "load", boom)
    path = PROBLEMS / "paper_table2.toml"
    assert main(["simulate", str(path), "--no-record"]) == 2
    assert _error_line(capsys) == f"lcc-synth simulate: error: {path}: scenario.dt: too coarse"
    monkeypatch.undo()
    assert main(["simulate", str(path), "--no-record", "--seeds", "0"]) == 2
    assert _error_line(capsys) == "lcc-synth simulate: error: --seeds: must be >= 1, got 0"


#: What a command that refuses its input must not have imported: the solvers and the
#: simulator's compiler (SciPy, numba, CVXPY) and Rerun.
STACKS = ("scipy", "numba", "cvxpy", "rerun")


def test_a_refused_input_loads_no_solver_or_recorder(tmp_path):
    """In a fresh interpreter, ``simulate`` (a gains file that contradicts its K, a seed study
    over the recording limit: the whole problem loaded and estimated), ``run`` (an unknown
    scenario of the showcase, a results root that is a file), ``sweep`` (the same root) and
    the first look at ``regions`` and ``synthesize`` (a missing file) exit 2 before any
    heavy import; the same names then load on use."""
    import subprocess
    import sys

    gains = {"kind": "fd_lcc", "m": 0, "n": 10, "semantics": "replace", "state_names": ["x"],
             "K": [1.0], "gains": {}}  # fmt: skip
    (tmp_path / "g.json").write_text(json.dumps(gains))
    table2 = (PROBLEMS / "paper_table2.toml").read_text()
    (tmp_path / "p.toml").write_text(f'{table2}\n[controllers.gf]\ntype = "gains_file"\n'
                                     'file = "g.json"\n')  # fmt: skip
    (tmp_path / "blocker").write_text("a file")
    runs = [
        ["simulate", "p.toml", "--no-record"],
        ["simulate", str(PROBLEMS / "paper_table2.toml"), "--seeds", "100000000"],
        ["run", str(PROBLEMS / "showcase.toml"), "--scenarios", "nope", "--no-record"],
        ["run", str(PROBLEMS / "showcase.toml"), "--no-record", "--out", "blocker"],
        ["sweep", str(PROBLEMS / "sweep_robustness.toml"), "--no-record", "--out", "blocker"],
        ["regions", "missing.toml", "--no-record"],
        ["synthesize", "missing.toml", "--no-record"],
    ]
    code = (
        "import json, sys\n"
        "from lcc_synth.cli.main import main\n"
        f"codes = [main(argv) for argv in {runs!r}]\n"
        f"heavy = sorted(m for m in {STACKS!r} if m in sys.modules)\n"
        "from importlib import import_module\n"
        "packages = [import_module(f'lcc_synth.{p}') for p in ('mpc', 'recording', 'synthesis')]\n"
        "names = {p.__name__: all(hasattr(p, n) for n in p.__all__) for p in packages}\n"
        "print(json.dumps([codes, heavy, names]))\n"
    )  # fmt: skip
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                          text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    codes, heavy, names = json.loads(proc.stdout)
    errors = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert codes == [2] * len(runs), proc.stderr
    assert [e.split(": error: ")[0] for e in errors] == [
        f"lcc-synth {argv[0]}" for argv in runs], proc.stderr  # one line each
    for part in ("gains.x: 0.0 disagrees with K", "--seeds: the recording would be about",
                 "--scenarios: unknown name(s) ['nope']", "--out:", "--out:",
                 "missing.toml: path: no such problem file",
                 "missing.toml: path: no such problem file"):  # fmt: skip
        assert part in errors.pop(0)
    assert heavy == []
    assert names == {"lcc_synth.mpc": True, "lcc_synth.recording": True,
                     "lcc_synth.synthesis": True}  # fmt: skip


# ---------------------------------------------------------------------- no internal labels


def test_label_pattern_catches_labels():
    """The pattern of the next test finds what it is meant to find."""
    for text in ("the gains file (contract 3)", "contract 1 verdict", "(issue 5)", "issue 13"):
        assert LABEL.search(text), text
    for text in ("a contractible loop", "the issue of stability", "(see issues)"):
        assert not LABEL.search(text), text


def test_no_internal_labels_in_sources_readme_guide_problems_and_help():
    files = [*sorted((ROOT / "lcc_synth").rglob("*.py")), ROOT / "README.md",
             *sorted((ROOT / "docs" / "guide").glob("*.md")),
             *sorted((ROOT / "problems").iterdir()), *sorted((ROOT / "examples").glob("*.py"))]
    hits = []
    for f in files:
        if f.is_file():
            for i, line in enumerate(f.read_text().splitlines(), 1):
                if LABEL.search(line):
                    hits.append(f"{f.relative_to(ROOT)}:{i}: {line.strip()}")
    parser = build_parser()
    helps = {"lcc-synth": parser.format_help()}
    helps.update({f"lcc-synth {n}": p.format_help() for n, p in _subparsers().items()})
    for name, text in helps.items():
        assert len(text) > 100, name
        hits += [f"{name} --help: {ln}" for ln in text.splitlines() if LABEL.search(ln)]
    assert hits == []


# --------------------------------------------------------------------- readable human output


def test_sig_digits():
    assert [sig(x) for x in (0.35019700044358615, 5.414282189412915, 16.8, 850, 0.0)] == [
        "0.350", "5.41", "16.8", "850", "0"]  # fmt: skip
    assert sig(2.5e-6) == "2.50e-06" and sig(None) == "n/a" and sig(float("nan")) == "nan"


def _mpc_row(out: str) -> dict[str, str]:
    lines = out.splitlines()
    [i] = [k for k, ln in enumerate(lines) if ln.startswith("controller ") and "step ms" in ln]
    header = re.split(r"\s{2,}", lines[i].strip())
    assert set(lines[i + 1].replace(" ", "")) == {"-"}
    return dict(zip(header, re.split(r"\s{2,}", lines[i + 2].strip()), strict=True))


def test_simulate_human_output_is_tables_without_raw_json(capsys):
    path = str(PROBLEMS / "mpc_head_brake.toml")
    assert main(["simulate", path, "--no-record", "--json"]) == 0
    stats = json.loads(capsys.readouterr().out)["results"]["mpc"]["controller_stats"]
    # the machine face keeps its shape and every digit
    assert {"step_time_ms", "osqp_time_ms", "iterations", "fallbacks", "qp_failures"} <= set(stats)
    assert {"median", "p99", "max", "mean", "count"} == set(stats["step_time_ms"])
    assert main(["simulate", path, "--no-record"]) == 0
    out = capsys.readouterr().out
    assert "{" not in out and "stats:" not in out, out
    assert not LONG_FLOAT.search(out), LONG_FLOAT.search(out)
    row = _mpc_row(out)
    assert row["controller"] == "mpc" and row["steps"] == str(stats["steps"])
    assert row["solves"] == str(stats["solves"]) and row["fallbacks"] == str(stats["fallbacks"])
    it = stats["iterations"]
    assert row["iterations"] == f"{it['median']:g} / {it['max']}"
    for col in ("step ms median", "p99", "max"):  # times of this run: 3 significant digits
        assert float(row[col]) > 0 and len(row[col].replace(".", "").lstrip("0")) == 3, row[col]


def test_controller_stats_lines_digits_and_counts():
    """Formatting against hand-written expectations (a fixed stats dict)."""
    st = {"steps": 600, "solves": 1800, "fallbacks": 2, "qp_failures": {"max_iter": 3,
          "primal_infeasible": 1}, "slack_steps": 7, "errors": 0,
          "step_time_ms": {"median": 0.35019700044358615, "p99": 5.414282189412915,
                           "max": 13.07, "mean": 0.6, "count": 1800},
          "iterations": {"median": 25.5, "max": 850}}  # fmt: skip
    st["error_messages"] = ["QP raised: boom"]
    lines = controller_stats_lines({"head_brake/mpc": st, "paper": {}, "x": {"k": 0.123456789}})
    assert lines[0].startswith("MPC solver")
    assert re.split(r"\s{2,}", lines[3]) == [
        "head_brake/mpc", "600", "1800", "0.350", "5.41", "13.1", "25.5 / 850", "2", "4", "7", "0"
    ]  # fmt: skip
    assert lines[4:] == ["head_brake/mpc: solver errors, the first: QP raised: boom",
                         "x: k = 0.123"]
    assert controller_stats_lines({"a": {}, "b": {}}) == []


@pytest.mark.slow  # the same stats table: test_simulate_human_output_is_tables_without_raw_json
def test_run_human_output_shows_mpc_stats_as_a_table(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = ["run", "--scenarios", "head_sine", "--controllers", "all_hdv,mpc", "--no-figures",
            "--no-record", "--no-progress", "--out", str(tmp_path)]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "{" not in out and not LONG_FLOAT.search(out)
    row = _mpc_row(out)
    assert row["controller"] == "head_sine/mpc" and row["fallbacks"] == "0"
    [run_dir] = tmp_path.glob("showcase-*")
    details = json.loads((run_dir / "details.json").read_text())
    stats = details["controller_stats"]["head_sine"]["mpc"]
    assert row["steps"] == str(stats["steps"])
    assert row["step ms median"] == sig(stats["step_time_ms"]["median"])
