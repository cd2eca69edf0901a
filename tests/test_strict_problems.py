"""Issue 13: a corpus of malformed problem files through every command.

Every case must end with exit code 2 and a one-line message naming the offending field, no
traceback, within a few seconds. Unknown tables and keys (at every level) are errors naming the
closest known name; a table another command reads stays allowed; implausible but valid values
warn; every shipped problem file still loads with every command that reads it.
"""

from __future__ import annotations

import re
import time
import warnings
from pathlib import Path

import pytest
from cli_subprocess import run_cli

from lcc_synth.cli.main import main
from lcc_synth.errors import ConfigError, ImplausibleValueWarning
from lcc_synth.problem import (
    MAX_FILE_BYTES,
    TOP_LEVEL,
    check_keys,
    check_top_level,
    load_problem,
)

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ROOT / "problems"

#: command -> (shipped base file, extra CLI options that keep the run from writing anything)
BASES = {
    "simulate": ("paper_table2", ["--no-record"]),
    "run": ("showcase", ["--no-record", "--no-figures", "--no-progress"]),
    "sweep": ("sweep_robustness", ["--no-record", "--no-figures", "--no-progress"]),
    "synthesize": ("synth_string_stable_m2n2", ["--no-record"]),
    "analyze": ("paper_fig9_cases", ["--no-record"]),
    "regions": ("paper_fig7_fig8_regions", ["--no-record"]),
}
COMMANDS = list(BASES)


def _base(cmd: str) -> str:
    return (PROBLEMS / f"{BASES[cmd][0]}.toml").read_text()


def _sub(pattern: str, repl: str):
    """A mutation replacing the first line matching ``pattern`` (must match)."""

    def mutate(text: str) -> str:
        new, k = re.subn(pattern, repl, text, count=1, flags=re.M)
        assert k == 1, pattern
        return new

    return mutate


def _replace_table(name: str, line: str):
    """A mutation dropping the table ``[name]`` (header and keys) and starting the file with
    ``line`` instead."""

    def mutate(text: str) -> str:
        pattern = rf"^\[{re.escape(name)}\][^\n]*\n(?:(?!\[)[^\n]*\n)*"
        new, k = re.subn(pattern, "", text, count=1, flags=re.M)
        assert k == 1, name
        return line + "\n" + new

    return mutate


def _append(extra: str):
    return lambda text: text + "\n" + extra + "\n"


# (case id, mutation, expected field, extra text the message must hold); the mutation gets the
# command's base file text and returns the file's text (str) or bytes.
COMMON = [
    ("misspelled_table_metric", _append("[metric]\nwindow = [1.0, 2.0]"), "metric",
     "did you mean [metrics]?"),
    ("misspelled_table_sytem", _append("[sytem]\nn = 2"), "sytem", "did you mean [system]?"),
    ("unknown_table", _append("[zzzz]\nx = 1"), "zzzz", "unknown table"),
    ("misspelled_key_nmae", lambda t: "nmae = 3\n" + t, "nmae", "did you mean 'name'?"),
    ("name_wrong_type", _sub(r"^name = .*$", "name = 3"), "name", "non-empty string"),
    ("hdv_misspelled_key", _sub(r"^\[hdv\]$", "[hdv]\nalfa = 0.6"), "hdv.alfa",
     "did you mean 'alpha'?"),
    ("hdv_nan", _sub(r"^alpha = .*$", "alpha = nan"), "hdv.alpha", "nan"),
    ("hdv_inf", _sub(r"^beta = .*$", "beta = inf"), "hdv.beta", "inf"),
    ("hdv_wrong_type", _sub(r"^alpha = .*$", 'alpha = "fast"'), "hdv.alpha", "number"),
    ("hdv_not_a_table", _replace_table("hdv", "hdv = 3"), "hdv", "table"),
    ("empty", lambda t: "", None, "required"),
    ("binary", lambda t: b"\x00\xff\xfe\x89PNG\r\n\x1a\n" * 64, "toml", "UTF-8"),
    ("bad_toml", lambda t: t + "\n[system\n", "toml", "not valid TOML"),
    ("oversized", lambda t: t + ("# padding\n" * (MAX_FILE_BYTES // 10 + 1)), "path", "MiB"),
]

SYSTEM = [  # every command reading [system] (all but run, which reads [layouts])
    ("system_misspelled_key", _sub(r"^\[system\]$", "[system]\nkindd = 1"), "system.kindd",
     "did you mean 'kind'?"),
    ("system_huge_n", _sub(r"^n = \d+$", "n = 1000000000"), "system.n", "200"),
    ("system_huge_m", _sub(r"^m = \d+$", "m = 99999999999"), "system.m", "50"),
    ("system_n_float", _sub(r"^n = \d+$", "n = 2.5"), "system.n", "integer"),
    ("system_v_star_nan", _sub(r"^v_star = .*$", "v_star = nan"), "system.v_star", "nan"),
    ("system_v_star_inf", _sub(r"^v_star = .*$", "v_star = -inf"), "system.v_star", "inf"),
    ("system_v_star_huge", _sub(r"^v_star = .*$", "v_star = 1e308"), "system.v_star", None),
    ("system_not_a_table", _replace_table("system", "system = [1, 2]"), "system", "table"),
]

SPECIFIC = {
    "simulate": [
        ("scenario_misspelled_key", _sub(r"^\[scenario\]$", "[scenario]\ndurration = 3.0"),
         "scenario.durration", "did you mean 'duration'?"),
        ("scenario_dt_nan", _sub(r"^dt = .*$", "dt = nan"), "scenario.dt", "nan"),
        ("metrics_misspelled_key", _sub(r"^window = .*$", "windw = [20.0, 40.0]"),
         "metrics.windw", "did you mean 'window'?"),
        ("controller_misspelled_key", _sub(r"^\[controllers.all_hdv\]$",
                                           "[controllers.all_hdv]\ntpye = 1"),
         "controllers.all_hdv.tpye", None),
        ("controllers_missing", lambda t: re.sub(r"^\[controllers\.", "[controllerz.", t,
                                                 flags=re.M), "controllerz", "controllers"),
    ],
    "run": [
        ("layout_misspelled_key", _sub(r"^\[layouts.sec5a\]$", "[layouts.sec5a]\nv_str = 1.0"),
         "layouts.sec5a.v_str", "v_star"),
        ("layout_huge_n", _sub(r"^n = 10$", "n = 1000000000"), "layouts.string10.n", None),
        ("layout_v_star_nan", _sub(r"^v_star = .*$", "v_star = nan"), "layouts.string10.v_star",
         None),
        ("scenarios_misspelled", lambda t: t.replace("[scenarios.", "[scenario."), "scenarios",
         "required"),
    ],
    "sweep": [
        ("sweep_misspelled_key", _sub(r"^\[sweep\]$", "[sweep]\ncont = 3"), "sweep.cont",
         "did you mean 'count'?"),
        ("scenario_delay_key", _sub(r"^\[scenario.delay\]$", "[scenario.delay]\nmaen = 0.1"),
         "scenario.delay.maen", "did you mean 'mean'?"),
    ],
    "synthesize": [
        ("synthesis_misspelled_key", _sub(r"^\[synthesis\]$", "[synthesis]\ndesgin = 1"),
         "synthesis.desgin", "did you mean 'design'?"),
        ("synthesis_weights_key", _sub(r"^\[synthesis.weights\]$", "[synthesis.weights]\nzz = 1"),
         "synthesis.weights.zz", None),
        ("synthesis_missing", lambda t: re.sub(r"^\[synthesis", "[synthesys", t, flags=re.M),
         "synthesys", "did you mean [synthesis]?"),
        ("baseline_gain_nan", _sub(r"^gains = \{ s_-2 = 1.0", "gains = { s_-2 = nan"),
         "synthesis.baseline.gains.s_-2", "finite"),
    ],
    "analyze": [
        ("analysis_misspelled_key", _sub(r"^\[analysis\]$", "[analysis]\npoint = 3"),
         "analysis.point", "did you mean 'points'?"),
        ("case_misspelled_key", _sub(r"^\[cases.case_a\]$", "[cases.case_a]\nlabl = 'x'"),
         "cases.case_a.labl", "did you mean 'label'?"),
    ],
    "regions": [
        ("regions_misspelled_key", _sub(r"^\[regions\].*$", "[regions]\nsetp = 0.1"),
         "regions.setp", "did you mean 'step'?"),
        ("regions_huge_per_decade", _sub(r"^per_decade = .*$", "per_decade = 10000000"),
         "regions.per_decade", None),
        ("map_misspelled_key", _sub(r"^\[maps.fig7a\]$", "[maps.fig7a]\nvehicel = 1"),
         "maps.fig7a.vehicel", "did you mean 'vehicle'?"),
    ],
}


def _cases():
    for cmd in COMMANDS:
        cases = COMMON + (SYSTEM if cmd != "run" else []) + SPECIFIC[cmd]
        for case_id, mutate, field, text in cases:
            yield pytest.param(cmd, mutate, field, text, id=f"{cmd}-{case_id}")


def _write(tmp_path: Path, cmd: str, mutate) -> Path:
    content = mutate(_base(cmd))
    path = tmp_path / f"{cmd}_bad.toml"
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


@pytest.mark.parametrize("cmd, mutate, field, text", list(_cases()))
def test_malformed_file_exits_2_naming_the_field(
    cmd, mutate, field, text, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)  # nothing a command might write lands in the repository
    path = _write(tmp_path, cmd, mutate)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main([cmd, str(path), *BASES[cmd][1]])
    elapsed = time.perf_counter() - t0
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, err
    assert len(lines) == 1, err
    assert lines[0].startswith(f"lcc-synth {cmd}: error: {path}: "), err
    if field is not None:
        assert f": {field}: " in lines[0], err
    if text is not None:
        assert text in lines[0], err
    assert "Traceback" not in err
    assert elapsed < 5.0, f"{elapsed:.1f} s"


@pytest.mark.parametrize(
    "cmd, case",
    [("simulate", "misspelled_table_metric"), ("synthesize", "binary"), ("run", "oversized"),
     ("regions", "system_v_star_nan")],
)
def test_malformed_file_in_a_subprocess(cmd, case, tmp_path):
    """The real entry point: exit 2, one line on stderr, no traceback, in a few seconds."""
    mutate = next(c[1] for c in COMMON + SYSTEM if c[0] == case)
    path = _write(tmp_path, cmd, mutate)
    t0 = time.perf_counter()
    proc = run_cli([cmd, path, *BASES[cmd][1]], cwd=tmp_path, timeout=60)
    assert time.perf_counter() - t0 < 20.0
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert lines[0].startswith(f"lcc-synth {cmd}: error: ")


def test_review_rejects_non_recordings(tmp_path, capsys):
    for content in (b"", b"\x00\xff\xfe" * 100, b"[system]\nn = 2\n"):
        path = tmp_path / "bad.rrd"
        path.write_bytes(content)
        assert main(["review", "--summary", str(path)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err and "path" in err


# --------------------------------------------------------------------------------------------
# The registry of top-level tables
# --------------------------------------------------------------------------------------------


def test_registry_covers_every_table_the_commands_read():
    """Every table a parser reads from the top level of a file is in :data:`TOP_LEVEL`."""
    read = set()
    for src in (ROOT / "lcc_synth").rglob("*.py"):
        text = src.read_text()
        # a top-level table is read through the schema's top-level declaration
        read |= set(re.findall(r"(?:get_table\(|declared\(\"\"\)\.get\()\s*"
                               r"(?:data|problem\.data|prob\.data),\s*\"(\w+)\"", text))
    assert read, "no top-level get_table found"
    assert read <= set(TOP_LEVEL), read - set(TOP_LEVEL)


def test_another_commands_tables_are_allowed(tmp_path, capsys):
    """A synthesis file may carry [scenario], [controllers] ...; a simulate file [synthesis]."""
    sim = (PROBLEMS / "paper_table2.toml").read_text()
    both = tmp_path / "both.toml"
    both.write_text(sim + '\n[synthesis]\ndesign = "structured"\n')
    load_problem(both)
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.synthesis.config import spec_from_problem

    spec_from_problem(load_problem(both))
    load_spec(both)


def test_unknown_top_level_messages():
    with pytest.raises(ConfigError) as e:
        check_top_level({"metric": {}})
    assert e.value.field == "metric" and "did you mean [metrics]?" in e.value.message
    with pytest.raises(ConfigError) as e:
        check_top_level({"nmae": 3})
    assert e.value.field == "nmae" and "did you mean 'name'?" in e.value.message
    with pytest.raises(ConfigError) as e:
        check_top_level({"qqqqqq": {}})
    assert "did you mean" not in e.value.message and "[metrics]" in e.value.message
    with pytest.raises(ConfigError) as e:  # the top level of check_keys is the registry
        check_keys({"sytem": {}}, ["name"], "")
    assert "did you mean [system]?" in e.value.message
    with pytest.raises(ConfigError) as e:
        check_keys({"windw": 1}, ["window", "vehicles"], "metrics")
    assert e.value.field == "metrics.windw" and "did you mean 'window'?" in e.value.message


# --------------------------------------------------------------------------------------------
# Shipped files still load with every command that reads them
# --------------------------------------------------------------------------------------------


def _readers(path: Path) -> list[str]:
    data = load_problem(path).data
    cmds = []
    if "scenario" in data and "controllers" in data and "sweep" not in data:
        cmds.append("simulate")
    if "sweep" in data:
        cmds.append("sweep")
    if "layouts" in data:
        cmds.append("run")
    if "synthesis" in data:
        cmds.append("synthesize")
    if "maps" in data:
        cmds.append("regions")
    if "system" in data:
        cmds.append("analyze")
    return cmds


@pytest.mark.parametrize("path", sorted(PROBLEMS.glob("*.toml")), ids=lambda p: p.stem)
def test_shipped_problem_files_load_with_every_reader(path):
    from lcc_synth.analysis.cases import analysis_options_from, cases_from
    from lcc_synth.analysis.region_specs import region_specs_from
    from lcc_synth.experiments.comparison import load_suite
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.experiments.sweep import load_sweep
    from lcc_synth.problem import system_from
    from lcc_synth.synthesis.config import spec_from_problem

    cmds = _readers(path)
    assert cmds, path
    prob = load_problem(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ImplausibleValueWarning)  # no shipped value is odd
        for cmd in cmds:
            if cmd == "simulate":
                load_spec(path)
            elif cmd == "sweep":
                load_sweep(path)
            elif cmd == "run":
                load_suite(path)
            elif cmd == "synthesize":
                spec_from_problem(prob)
            else:
                model = system_from(prob.data, str(path)).linear_model(warn=False)
                if cmd == "regions":
                    region_specs_from(prob.data, model, str(path), step=0.5)
                else:
                    analysis_options_from(prob.data, str(path))
                    cases_from(prob.data, model, str(path))


# --------------------------------------------------------------------------------------------
# Implausible but valid values warn
# --------------------------------------------------------------------------------------------


def _static_problem(tmp_path: Path, gain: float) -> Path:
    path = tmp_path / "gain.toml"
    path.write_text(
        f"""
[system]
kind = "lcc"
m = 1
n = 1
[scenario]
duration = 2.0
[controllers.big]
type = "static"
gains = {{ s_1 = {gain!r}, v_0 = -0.5 }}
"""
    )
    return path


def test_huge_static_gain_warns_naming_the_field(tmp_path):
    from lcc_synth.controllers.registry import build_controller
    from lcc_synth.experiments.spec import load_spec
    from lcc_synth.problem import system_from

    prob = load_problem(_static_problem(tmp_path, 1e12))
    system = system_from(prob.data)
    table = prob.data["controllers"]["big"]
    with pytest.warns(ImplausibleValueWarning, match=r"controllers\.big\.gains\.s_1") as rec:
        build_controller("big", table, system)
    assert issubclass(ImplausibleValueWarning, UserWarning)
    assert len([w for w in rec if w.category is ImplausibleValueWarning]) == 1
    assert "1e+12" in str(rec[0].message) and "100" in str(rec[0].message)
    # simulate warns first, then refuses the step this gain's closed loop cannot take
    with pytest.warns(ImplausibleValueWarning), pytest.raises(ConfigError, match="scenario.dt"):
        load_spec(prob)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ImplausibleValueWarning)
        for gain in (-2.0, 100.0, -100.0):  # plain gains say nothing
            build_controller("big", {**table, "gains": {"s_1": gain}}, system)


def test_huge_gain_warning_on_stderr_of_the_cli(tmp_path):
    path = tmp_path / "cases.toml"
    base = (PROBLEMS / "paper_fig9_cases.toml").read_text()
    path.write_text(base + "\n[cases.huge]\ngains = { s_1 = 1e12 }\n")
    proc = run_cli(["analyze", path, "--no-record", "--json"], cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "ImplausibleValueWarning" in proc.stderr and "cases.huge.gains.s_1" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_huge_gains_warn_in_analyze_regions_and_synthesis_baseline(tmp_path):
    from lcc_synth.analysis.cases import cases_from
    from lcc_synth.analysis.region_specs import region_specs_from
    from lcc_synth.problem import system_from
    from lcc_synth.synthesis.config import spec_from_problem

    base = (PROBLEMS / "paper_fig9_cases.toml").read_text()
    p = tmp_path / "cases.toml"
    p.write_text(base + "\n[cases.huge]\ngains = { s_1 = 500.0 }\n")
    prob = load_problem(p)
    model = system_from(prob.data).linear_model(warn=False)
    with pytest.warns(ImplausibleValueWarning, match=r"cases\.huge\.gains\.s_1"):
        cases_from(prob.data, model)

    base = (PROBLEMS / "paper_fig7_fig8_regions.toml").read_text()
    p.write_text(base + "\n[maps.huge]\nvehicle = 1\ngains = { v_2 = -300.0 }\n")
    prob = load_problem(p)
    with pytest.warns(ImplausibleValueWarning, match=r"maps\.huge\.gains\.v_2"):
        region_specs_from(prob.data, model, step=0.5)

    base = (PROBLEMS / "synth_string_stable_m2n2.toml").read_text()
    p.write_text(base.replace("s_2 = -1.0", "s_2 = -1e6"))
    with pytest.warns(ImplausibleValueWarning, match=r"synthesis\.baseline\.gains\.s_2"):
        spec_from_problem(load_problem(p))


# --------------------------------------------------------------------------------------------
# Keys first documented by the schema (problems/REFERENCE.md): their errors are as good
# --------------------------------------------------------------------------------------------

SCHEMA_CASES = [
    ("synthesize", "as_run_misspelled_key", _append("[synthesis.as_run]\nmargni = 1e-3"),
     "synthesis.as_run.margni", "did you mean 'margin'?"),
    ("synthesize", "weight_q_a_negative", _sub(r"^\[synthesis.weights\]$",
                                               "[synthesis.weights]\nq_a = -1.0"),
     "synthesis.weights.q_a", "must be >= 0.0, got -1.0"),
    ("sweep", "count_zero", _sub(r"^count = .*$", "count = 0"), "sweep.count",
     "must be an integer >= 1 and <= 10000000, got 0"),
    ("run", "scenario_title_not_a_string",
     _sub(r'^title = "Table II: .*$', "title = 3"),
     "scenarios.brake_behind.title", "must be a string, got 3"),
    ("simulate", "measurement_filter_negative",
     _sub(r"^\[controllers.cf_lcc\]$", "[controllers.cf_lcc]\nmeasurement_filter = -1.0"),
     "controllers.cf_lcc.measurement_filter", "must be >= 0.0, got -1.0"),
]


@pytest.mark.parametrize(
    "cmd, mutate, field, text",
    [pytest.param(c, m, f, t, id=f"{c}-{i}") for c, i, m, f, t in SCHEMA_CASES],
)
def test_schema_documented_keys_exit_2_naming_the_field(
    cmd, mutate, field, text, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    path = _write(tmp_path, cmd, mutate)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main([cmd, str(path), *BASES[cmd][1]])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"lcc-synth {cmd}: error: {path}: {field}: "), err
    assert text in lines[0], err
