"""Issue 28, row 9: an H2 synthesis that fails inside ``simulate`` or ``run``.

An infeasible string-stable design used to end ``simulate`` in a traceback and made ``run``
discard every other controller's results while its recording said "complete". Now the
controller that cannot be designed (and an MPC falling back to it) is reported, every other
controller runs and is written, the recording's status is "partial", and the exit code is 1.
"""

from __future__ import annotations

import json

import pytest
from cli_subprocess import PAPER_HDV, one_line_error, rrd_verifies, run_cli

from lcc_synth.recording import summarize_recording

HDV = "\n" + PAPER_HDV
#: A string-stable design hearing only HDV 1 of m = n = 2: the LMI is infeasible.
H2 = """
type = "h2"
design = "string_stable"
semantics = "added"
pattern = [1]
string = { gamma = 1.0, polish_steps = 5 }
weights = { q_s = 1.0, q_v = 1.0, r = 1.0, head = 1.0, accel = 1.0 }
"""
BRAKE = """
duration = 30.0
perturbations = [{ type = "brake", vehicle = 1, start = 5.0, duration = 1.0, decel = -3.0 }]
"""

SIMULATE = (f'name = "h2_fails"\n{HDV}\n[system]\nkind = "lcc"\nm = 2\nn = 2\nv_star = 15.0\n'
            f"[scenario]{BRAKE}\n[controllers.all_hdv]\ntype = \"hdv\"\n[controllers.h2]{H2}\n"
            '[controllers.mpc]\ntype = "mpc"\nfallback = "h2"\n'
            "[metrics]\nwindow = [5.0, 30.0]\n")  # fmt: skip

SUITE = (f'name = "h2_fails_suite"\n{HDV}\n[layouts.m2n2]\nkind = "lcc"\nm = 2\nn = 2\n'
         f"v_star = 15.0\n[scenarios.brake]\nlayout = \"m2n2\"{BRAKE}\n"
         "[scenarios.brake.metrics]\nwindow = [5.0, 30.0]\n"
         '[controllers.all_hdv]\ntype = "hdv"\n[controllers.h2]' + H2)  # fmt: skip


def test_simulate_runs_the_others_and_exits_1(tmp_path):
    (tmp_path / "p.toml").write_text(SIMULATE)
    proc = run_cli(["simulate", "p.toml", "--rrd", "x.rrd"], cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "all_hdv" in proc.stdout and "0.1970" in proc.stdout  # the others' results
    assert "h2 (not run)" in proc.stdout and "mpc (not run)" in proc.stdout
    assert "failed: h2: not run: synthesis failed" in proc.stderr
    assert "failed: mpc: not run: its fallback 'h2' could not be designed" in proc.stderr
    assert rrd_verifies(tmp_path / "x.rrd")
    s = summarize_recording(tmp_path / "x.rrd")
    assert "**partial**" in s.texts["/h2_fails/status"]
    assert "/h2_fails/all_hdv/velocity" in s.entities
    proc = run_cli(["simulate", "p.toml", "--json", "--no-record"], cwd=tmp_path)
    doc = json.loads(proc.stdout)["results"]
    assert doc["h2"]["failed"].startswith("synthesis failed") and "aave" not in doc["h2"]
    assert list(doc) == ["all_hdv", "h2", "mpc"]  # those that did not run rank last


@pytest.mark.slow  # the same failure in simulate: test_simulate_runs_the_others_and_exits_1
def test_run_keeps_the_other_rows_and_exits_1(tmp_path):
    (tmp_path / "s.toml").write_text(SUITE)
    proc = run_cli(["run", "s.toml", "--no-progress", "--rrd", "s.rrd", "--out", "res"],
                   cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 1, proc.stderr
    assert "failed: m2n2/h2: not run: synthesis failed" in proc.stderr
    (run_dir,) = (tmp_path / "res").iterdir()
    table = json.loads((run_dir / "table.json").read_text())["results"]["brake"]
    assert table["all_hdv"]["aave"] > 0 and table["h2"]["aave"] is None
    assert table["h2"]["failed"].startswith("synthesis failed")
    assert "h2 (not run)" in (run_dir / "table.md").read_text()
    status = summarize_recording(tmp_path / "s.rrd").texts["/h2_fails_suite/status"]
    assert "**partial**" in status and "complete" not in status


def test_synthesize_failure_is_one_line(tmp_path):
    """``synthesize`` itself: the same design is a one-line failure, exit 1."""
    text = (f'name = "h2_fails"\n{HDV}\n[system]\nkind = "lcc"\nm = 2\nn = 2\nv_star = 15.0\n'
            "[synthesis]" + H2.replace('type = "h2"\n', ""))  # fmt: skip
    (tmp_path / "p.toml").write_text(text)
    proc = run_cli(["synthesize", "p.toml", "--no-record", "--no-progress"], cwd=tmp_path)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().splitlines()[-1].startswith("lcc-synth synthesize: synthesis failed")
    assert one_line_error(proc.stderr) or len(proc.stderr.strip().splitlines()) == 1
