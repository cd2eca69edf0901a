"""Issue 28, row 16: values valid one by one that mean nothing in their run are errors, and a
reduction of a round-off baseline is not a percentage.

Each case runs the real ``lcc-synth`` in a subprocess from a temporary working directory:
exit 2, one line naming the field. Cases: a ``t_start`` of nan / inf; an HDV reaction delay or
a V2V latency as long as the run; a perturbation or a controller's ``start`` after the run's
last sample; an IDM with ``T = 0``; a bad value in a scenario of ``lcc-synth run`` that
``--scenarios`` leaves out (every scenario of a file is checked). Then the reduction versus
the baseline (``simulate`` with ``[metrics] baseline``): with a baseline AAVE at round-off level
there is no percentage (``None`` in JSON, ``n/a`` in the table, the reason printed), while a
real baseline gives the percentages of before.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from cli_subprocess import PROBLEMS, one_line_error, run_cli

from lcc_synth.cli.simulate import report
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.comparison import load_suite
from lcc_synth.experiments.spec import load_spec
from lcc_synth.simulation.backends import run_scenario

TABLE2 = (PROBLEMS / "paper_table2.toml").read_text()  # duration 100 s, t_start 0.01 s
SHOWCASE = (PROBLEMS / "showcase.toml").read_text()


def edit(text: str, pattern: str, repl: str) -> str:
    new, k = re.subn(pattern, repl, text, count=1, flags=re.M)
    assert k == 1, pattern
    return new


def fails_naming(tmp: Path, args: list[str], *parts: str) -> str:
    proc = run_cli(args, cwd=tmp, timeout=180)
    assert proc.returncode == 2, proc.stderr
    assert one_line_error(proc.stderr), proc.stderr
    line = proc.stderr.strip().splitlines()[-1]
    for part in parts:
        assert part in line, (part, line)
    return line


IDM = '[hdv]\nmodel = "idm"\nv0 = 30.0\nT = 0.0\ns0 = 2.0\na = 1.0\nb = 1.5\ndelta = 4.0\n'


@pytest.mark.parametrize(
    "case, pattern, repl, parts",
    [
        ("t_start_nan", r"^t_start = 0\.01$", "t_start = nan",
         ["scenario.t_start: must be a finite number, got nan"]),
        ("t_start_inf", r"^t_start = 0\.01$", "t_start = inf",
         ["scenario.t_start: must be a finite number, got inf"]),
        ("delay_mean", r"^hdv_aeb = false$", "hdv_aeb = false\ndelay = { mean = 100.0 }",
         ["scenario.delay.mean: must be shorter than the run (duration = 100 s), got 100 s"]),
        ("delay_spread", r"^hdv_aeb = false$",
         "hdv_aeb = false\ndelay = { mean = 60.0, spread = 50.0 }",
         ["scenario.delay.spread: mean + spread must be shorter than the run"]),
        ("latency", r"^hdv_aeb = false$", "hdv_aeb = false\nv2v = { latency = 150.0 }",
         ["scenario.v2v.latency: must be shorter than the run (duration = 100 s), got 150 s"]),
        ("perturbation_after_the_end", r"^start = 20\.0$", "start = 100.0",
         ["scenario.perturbations[0].start: must be before the run's last sample, t = 100 s",
          "got 100: the perturbation would never act"]),
        ("perturbation_before_the_start", r"^start = 20\.0$", "start = -5.0",
         ["scenario.perturbations[0].start: the perturbation's window [-5, -4] s ends before "
          "the run's first sample, t_start = 0.01 s"]),
        ("controller_start_after_the_end", r'^type = "hdv"$', 'type = "hdv"\nstart = 150.0',
         ["controllers.all_hdv.start: must be before the run's last sample, t = 100 s",
          "got 150: controller 'all_hdv' would never act"]),
        ("idm_T_zero", r"^\[hdv\]\n(?:[a-z_]+ = .*\n)+", IDM, ["hdv.T: must be > 0, got 0.0"]),
    ],
)
def test_meaningless_values_in_simulate(case, pattern, repl, parts, tmp_path):
    (tmp_path / "p.toml").write_text(edit(TABLE2, pattern, repl))
    fails_naming(tmp_path, ["simulate", "p.toml", "--no-record"], "p.toml: ", *parts)


def test_the_edits_alone_are_valid(tmp_path):
    """Positive controls: the same keys with meaningful values load (in-process)."""
    text = edit(TABLE2, r"^hdv_aeb = false$", "hdv_aeb = false\ndelay = { mean = 0.5, "
                "spread = 0.1 }\nv2v = { latency = 0.1 }")  # fmt: skip
    text = edit(text, r'^type = "hdv"$', 'type = "hdv"\nstart = 99.9')
    text = edit(text, r"^\[hdv\]\n(?:[a-z_]+ = .*\n)+", IDM.replace("T = 0.0", "T = 1.0"))
    (tmp_path / "p.toml").write_text(text)
    spec = load_spec(tmp_path / "p.toml")
    assert spec.scenario.v2v.latency == 0.1 and spec.scenario.hdv.T == 1.0
    assert spec.controllers["all_hdv"].start == 99.9


def test_a_bad_value_in_a_scenario_not_selected_by_run(tmp_path):
    """``--scenarios brake_behind``: ``head_sine`` is not run, and still read and checked."""
    assert list(load_suite(PROBLEMS / "showcase.toml", ["brake_behind"]).scenarios) == [
        "brake_behind"]
    text = edit(SHOWCASE, r'^title = "Section V-A: head-vehicle sine \(m = n = 2\)"$',
                'title = "Section V-A"\ndelay = { mean = 500.0 }')  # fmt: skip
    (tmp_path / "suite.toml").write_text(text)
    with pytest.raises(ConfigError, match="scenarios.head_sine.delay.mean"):
        load_suite(tmp_path / "suite.toml", ["brake_behind"])
    fails_naming(tmp_path, ["run", "suite.toml", "--scenarios", "brake_behind", "--no-record",
                            "--no-figures", "--no-progress", "--out", str(tmp_path / "out")],
                 "suite.toml: scenarios.head_sine.delay.mean: must be shorter than the run "
                 "(duration = 70 s)")  # fmt: skip
    assert not (tmp_path / "out").exists()
    bad_t = edit(SHOWCASE, r"^duration = 70\.0$", "duration = 70.0\nt_start = nan")
    (tmp_path / "suite.toml").write_text(bad_t)
    with pytest.raises(ConfigError, match=r"scenarios\.head_sine\.t_start: must be a finite"):
        load_suite(tmp_path / "suite.toml", ["brake_behind"])


def test_a_controller_start_after_the_end_of_one_scenario_of_run(tmp_path):
    text = edit(SHOWCASE, r'^\[controllers\.all_hdv\]\ntype = "hdv"$',
                '[controllers.all_hdv]\ntype = "hdv"\nstart = 65.0')  # fmt: skip
    (tmp_path / "suite.toml").write_text(text)
    with pytest.raises(ConfigError) as err:  # brake_behind lasts 60 s, the others longer
        load_suite(tmp_path / "suite.toml", ["head_sine"])
    assert err.value.field == "controllers.all_hdv.start"
    assert "in scenario 'brake_behind'" in err.value.message


# --------------------------------------------------------------------------------------------
# the reduction versus the baseline
# --------------------------------------------------------------------------------------------


def _quiet(tmp: Path) -> Path:
    """Table II without its brake, 30 s: nothing happens, every AAVE is round-off (~1e-12)."""
    text = re.sub(r"\[\[scenario\.perturbations\]\]\n(?:[a-z_]+ = .*\n)+", "", TABLE2)
    text = edit(text, r"^duration = 100\.0$", "duration = 30.0")
    text = edit(text, r"^window = \[20\.0, 40\.0\]$", "window = [20.0, 30.0]")
    path = tmp / "quiet.toml"
    path.write_text(text)
    return path


def _report(path: Path):
    spec = load_spec(path)
    draws = spec.scenario.draw()
    results = {n: run_scenario(spec.scenario, c, draws) for n, c in spec.controllers.items()}
    return spec, results, report(spec, results)


def test_reduction_of_a_round_off_baseline_is_not_a_percentage(tmp_path):
    spec, results, rep = _report(_quiet(tmp_path))
    a0 = rep["all_hdv"]["aave"]
    assert 0 < a0 < 1e-10  # the old report said a 27.67 % "reduction" of such numbers
    floor = np.finfo(float).eps * 15.0 * spec.scenario.steps  # eps max|v| steps: 1e-11 m/s
    assert a0 < floor < 1e-10
    for name in ("fd_lcc", "cf_lcc"):
        red = rep[name]["reduction_vs_baseline"]
        assert red["aave_pct"] is None and red["aave_pct_std"] is None
        assert "round-off" in red["aave_pct_note"] and "not meaningful" in red["aave_pct_note"]
        assert red["fuel_pct"] == pytest.approx(0.0, abs=1e-6)  # fuel is no round-off number
    proc = run_cli(["simulate", "quiet.toml", "--no-record", "--json"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    red = json.loads(proc.stdout)["results"]["fd_lcc"]["reduction_vs_baseline"]
    assert red["aave_pct"] is None and "round-off" in red["aave_pct_note"]
    assert red["fuel_pct"] is not None
    proc = run_cli(["simulate", "quiet.toml", "--no-record"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    row = next(ln for ln in proc.stdout.splitlines() if ln.startswith("fd_lcc"))
    assert row.split()[3] == "n/a" and "%" not in row
    assert "AAVE red. % n/a: not meaningful: the baseline all_hdv's AAVE" in proc.stdout


def test_reduction_of_a_real_baseline_is_unchanged(tmp_path):
    """Table II (shortened to 45 s, the window 20-40 s): the percentages are the paired
    relative changes, exactly as before."""
    text = edit(TABLE2, r"^duration = 100\.0$", "duration = 45.0")
    (tmp_path / "t2.toml").write_text(text)
    spec, results, rep = _report(tmp_path / "t2.toml")
    a0 = rep["all_hdv"]["aave"]
    assert a0 == pytest.approx(0.8928, abs=1e-4)  # Table II
    for name in ("fd_lcc", "cf_lcc"):
        red = rep[name]["reduction_vs_baseline"]
        assert "aave_pct_note" not in red
        assert red["aave_pct"] == 100.0 * (a0 - rep[name]["aave"]) / a0
    assert round(rep["fd_lcc"]["reduction_vs_baseline"]["aave_pct"], 2) == 34.97
