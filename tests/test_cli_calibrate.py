"""``lcc-synth calibrate`` as a user meets it: bad trajectory files and options are one error
line and exit 2 (the real command in a subprocess), the report marks unidentified parameters,
``--json`` has the documented shape, ``--out`` writes a problem file that loads."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cli_subprocess import one_line_error, run_cli

import lcc_synth as lcc
from lcc_synth.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
LANE1 = ROOT / "problems" / "data" / "ngsim_i80" / "i80_lane1.csv"

BAD_FILES = {
    "missing column": ("t,v0,headway0,v1\n0,1,0,1\n0.1,1,0,1\n",
                       "column headway1: header (line 1): missing"),
    "non-monotonic time": ("t,v0,headway0,v1,headway1\n0.1,1,0,1,9\n0,1,0,1,9\n",
                           "column t: row 2 (line 3): time must increase strictly"),
    "NaN": ("t,v0,headway0,v1,headway1\n0,1,0,1,9\n0.1,1,0,NaN,9\n",
            "column v1: row 2 (line 3): must be a finite number, got 'NaN'"),
    "one vehicle": ("t,v0,headway0\n0,1,0\n0.1,1,0\n",
                    "column v1: header (line 1): missing: a platoon needs at least two"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_file_is_one_line_and_exit_2(tmp_path, case):
    text, expected = BAD_FILES[case]
    path = tmp_path / "bad.csv"
    path.write_text(text)
    proc = run_cli(["calibrate", path, "--model", "ovm"], cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert one_line_error(proc.stderr), proc.stderr
    assert proc.stderr.strip().startswith(f"lcc-synth calibrate: error: {path}: {expected}")
    assert proc.stdout == ""


@pytest.mark.parametrize("args, expected", [
    (["missing.csv"], "DATA: "),
    ([LANE1, "--starts", "0"], "--starts: must be in [1, 100], got 0"),
    ([LANE1, "--length", "40"], "--length: must be > 0 and < the smallest follower headway"),
])  # fmt: skip
def test_bad_option_or_missing_file_is_one_line_and_exit_2(tmp_path, args, expected):
    proc = run_cli(["calibrate", *args], cwd=tmp_path)
    assert proc.returncode == 2 and one_line_error(proc.stderr), proc.stderr
    assert proc.stderr.strip().startswith(f"lcc-synth calibrate: error: {expected}"), proc.stderr


def test_existing_out_is_refused_before_any_work(tmp_path, capsys):
    out = tmp_path / "p.toml"
    out.write_text("keep")
    assert main(["calibrate", str(LANE1), "--out", str(out)]) == 2
    assert "--out: " in capsys.readouterr().err and out.read_text() == "keep"


def test_report_json_and_problem_file(tmp_path, capsys):
    out = tmp_path / "lane1.toml"
    args = ["calibrate", str(LANE1), "--model", "ovm", "--starts", "1", "--no-progress"]
    assert main([*args, "--json", "--out", str(out)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["ok"] and doc["written"] == [str(out)] and doc["model"] == "ovm"
    assert [f["index"] for f in doc["followers"]] == [1, 2, 3, 4]
    first = doc["followers"][0]
    assert set(first["params"]) == {"alpha", "beta", "s_st", "s_go", "v_max"}
    assert set(first["nominal"]) == {"rmse_spacing_m", "rmse_velocity_ms"}
    assert set(first["platoon"]) == {"rmse_spacing_m", "rmse_velocity_ms",
                                     "nominal_rmse_spacing_m", "nominal_rmse_velocity_ms"}
    objs = lcc.load_problem(out)
    assert objs.scenario.initial_state is not None
    assert objs.system.platoon.size == 4
    # the text report: every follower and the pooled row; unidentified values marked
    assert main(args) == 0
    text = capsys.readouterr().out
    rows = [ln.split()[0] for ln in text.splitlines() if ln.split()[:1] in (["1"], ["pooled"])]
    assert rows.count("1") == 2 and rows.count("pooled") == 2
    flat = [k for f in doc["followers"] for k, ok in f["identified"].items() if not ok]
    assert ("~" in text) == bool(flat)
