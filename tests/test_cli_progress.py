"""What a command shows while it works, and how ``run`` writes what it found.

* ``--quiet`` silences every bar, stage line and estimate on stderr (results stay on stdout);
  without it ``run`` prints its estimate first, then a bar per stage.
* ``run``'s text lines are at most 100 characters; its table wraps its columns into blocks
  whose cells are those of the one-block table (checked cell by cell, independently parsed
  from the rules' column spans).
* ``--format svg|pdf`` writes files of that type (their magic bytes); a bad format is one line
  and exit 2, before any work.
* The estimate counts the work of the tables (runs, curves) as the suite defines it.

The real command runs in a subprocess (``tests/cli_subprocess.py``) on two linear controllers
of one scenario of ``problems/showcase.toml`` (a few seconds).
"""

from __future__ import annotations

import math

import pytest
from cli_subprocess import PROBLEMS, run_cli

from lcc_synth.experiments.comparison import load_suite
from lcc_synth.experiments.suite_size import estimate_suite
from lcc_synth.experiments.tables import SUITE_METRICS, column_blocks, format_table

SMALL = ["run", str(PROBLEMS / "showcase.toml"), "--scenarios", "brake_behind",
         "--controllers", "all_hdv,paper", "--no-record"]  # fmt: skip


def _results(out_root):
    (run_dir,) = out_root.iterdir()
    return run_dir


@pytest.mark.slow  # CI runs it; by default: run's estimate, bars and short lines (next test)
def test_quiet_run_prints_nothing_on_stderr_and_writes_svg(tmp_path):
    proc = run_cli([*SMALL, "--quiet", "--format", "svg", "--out", "r"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""  # no estimate, no bar
    assert "brake_behind" in proc.stdout and "0.8928" in proc.stdout  # Table II's all-HDV AAVE
    run_dir = _results(tmp_path / "r")
    figures = sorted(p.name for p in run_dir.iterdir() if p.suffix in (".svg", ".png", ".pdf"))
    assert figures == ["gamma_string10.svg", "profiles_brake_behind.svg"]
    for name in figures:
        head = (run_dir / name).read_bytes()[:200]
        assert head.startswith(b"<?xml") and b"<svg" in head


def test_run_prints_its_estimate_then_bars_and_short_lines(tmp_path):
    proc = run_cli([*SMALL, "--format", "pdf", "--out", "r"], tmp_path)  # short paths
    assert proc.returncode == 0, proc.stderr
    first = proc.stderr.splitlines()[0]
    assert first.startswith("lcc-synth run: estimate: 1 scenario × 2 controllers (2 runs, "
                            "2 |Γ| curves), about ")  # fmt: skip
    for stage in ("controllers (synthesis, MPC set-up)", "simulations",
                  "string stability as run", "figures"):  # fmt: skip
        assert f"{stage}: 100%" in proc.stderr, stage
    lines = proc.stdout.splitlines()
    assert max(len(line) for line in lines) <= 100
    run_dir = _results(tmp_path / "r")
    for name in ("gamma_string10.pdf", "profiles_brake_behind.pdf"):
        assert (run_dir / name).read_bytes()[:5] == b"%PDF-"
    # the |Γ| lines are in the file, one summary line on stdout points to it
    text = (run_dir / "string_stability.txt").read_text().splitlines()
    assert [t.split(":")[0] for t in text] == ["|Γ| string10/all_hdv", "|Γ| string10/paper"]
    assert not any(line.startswith("|Γ| string10") for line in lines)
    summary = [line for line in lines if line.startswith("|Γ| as run:")]
    assert summary == ["|Γ| as run: 2 curves, 0 string stable, 0 measured (not linear): "
                       "string_stability.txt"]  # fmt: skip
    assert f"results: {run_dir.relative_to(tmp_path)}" in lines


def test_verbose_prints_the_gamma_lines(tmp_path):
    proc = run_cli([*SMALL, "-q", "--verbose", "--no-figures", "--out", "r"], tmp_path)
    assert proc.returncode == 0 and proc.stderr == ""
    run_dir = _results(tmp_path / "r")
    gamma = (run_dir / "string_stability.txt").read_text().splitlines()
    shown = proc.stdout.splitlines()
    for line in gamma:  # each as written, or wrapped at 100 characters with an indent
        assert line in shown or line.split(" -> ")[0][:90] in proc.stdout
    assert max(len(line) for line in shown) <= 100


@pytest.mark.parametrize("command", ["run", "sweep"])
def test_bad_format_is_one_line_before_any_work(tmp_path, command):
    problem = PROBLEMS / ("showcase.toml" if command == "run" else "sweep_robustness.toml")
    proc = run_cli([command, str(problem), "--format", "jpg", "--no-record", "--out",
                    tmp_path / "r"], tmp_path)  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [
        f"lcc-synth {command}: error: --format: must be one of png, pdf, svg, got 'jpg'"
    ]
    assert proc.stdout == "" and not (tmp_path / "r").exists()


def test_quiet_is_every_command_s_flag_and_no_progress_its_alias():
    from lcc_synth.cli.main import COMMANDS, build_parser

    parser = build_parser()
    for command in COMMANDS:
        args = parser.parse_args([command, "x.rrd" if command == "review" else "p.toml", "-q"])
        assert args.quiet is True
        if command != "review":
            again = parser.parse_args([command, "p.toml", "--no-progress"])
            assert again.quiet is True


# ---------------------------------------------------------------- the table's wrapped columns


def _cells(line: str, rule: str) -> list[str]:
    """The cells of a table line, cut at the column spans of its rule line (``---  ----``)."""
    spans, i = [], 0
    for part in rule.split("  "):
        spans.append((i, i + len(part)))
        i += len(part) + 2
    return [line[a:b].strip() for a, b in spans]


def _parse(lines: list[str]) -> list[list[list[str]]]:
    """Blocks (separated by empty lines) of rows of cells."""
    blocks, cur = [], []
    for line in [*lines, ""]:
        if line == "":
            if cur:
                blocks.append(cur)
            cur = []
        else:
            cur.append(line)
    out = []
    for block in blocks:
        r = next(k for k, line in enumerate(block) if set(line) <= {"-", " "})
        out.append([_cells(line, block[r]) for line in block[r + 1:]])
    return out


def _table():
    per = {}
    for k, name in enumerate(("all_hdv", "paper", "h2", "mpc_delay")):
        row = {key: 1.0 + k + i / 7 for i, key in enumerate(SUITE_METRICS)}
        row.update(aeb_activations=0, collisions=0, failed_steps=0, collided=False,
                   min_spacing=10.0 + k, min_ttc=math.inf, jerk_1s_over_limit_s=0.0)
        per[name] = row
    per["unsafe"] = {**per["paper"], "aeb_activations": 45, "min_spacing": 1.5}
    return {"heterogeneous": per, "brake_behind": dict(per)}


@pytest.mark.parametrize("width", [60, 100, 140])
def test_wrapped_table_has_the_cells_of_the_one_block_table(width):
    table = _table()
    whole = format_table(table).splitlines()
    wrapped = format_table(table, width=width).splitlines()
    assert max(len(line) for line in wrapped) <= width
    (one,) = _parse(whole)
    blocks = _parse(wrapped)
    assert len(blocks) > 1 or width >= 140  # the whole table is 110-140 characters wide
    joined = [r[:2] + [c for b in blocks for c in b[i][2:]] for i, r in enumerate(blocks[0])]
    assert joined == one
    # every block repeats the scenario and controller columns
    for b in blocks:
        assert [r[:2] for r in b] == [r[:2] for r in one]


def test_column_blocks_gives_an_over_wide_column_its_own_block():
    lines = column_blocks(["name", "x" * 30, "y"], [["a", "1", "2"]], width=20)
    assert max(len(line) for line in lines if not set(line) <= {"-", " "}) > 20  # kept whole
    assert sum(1 for line in lines if line == "") == 1  # two blocks: the wide one, then y


# --------------------------------------------------------------------------- the estimate


def test_estimate_counts_the_runs_and_curves_of_the_showcase():
    """6 scenarios; per scenario the controllers that run there (``only_scenarios``,
    ``only_layouts``), and a |Γ| curve per controller and (layout, latency) setting of the
    layouts with a head vehicle: the counts of the run's own table (24 rows) and its
    ``string_stability.txt`` (17 lines with a verdict: 14 on the single-CAV strings, 3 on
    platoon8, whose all_hdv, h2 and mpc run in platoon_brake; ring20 has no head)."""
    suite = load_suite(PROBLEMS / "showcase.toml")
    est = estimate_suite(suite)
    assert est.scenarios == 6 and est.controllers == (3, 6)
    assert est.runs == 24 and est.curves == 17
    assert est.seconds["recording"] == 0.0
    assert 10 < est.total < 600  # the model's order of magnitude (measured 37 s CPU)
    assert est.line().startswith("6 scenarios × 3–6 controllers (24 runs, 17 |Γ| curves)")


def test_run_estimate_costs_each_predictive_controller_at_its_solver(tmp_path, monkeypatch):
    """The estimate's simulations cost an MPC or DeeP-LCC step at its QP solver's figure
    (``resources.qp_step_seconds``): the showcase (DAQP, its file) is estimated cheaper than
    the same file with OSQP, and exactly as costly once the DAQP figures are set to OSQP's."""
    import lcc_synth.resources as res

    text = (PROBLEMS / "showcase.toml").read_text()
    assert text.count('solver = { method = "daqp" }') == 3  # mpc, mpc_delay, deep_lcc
    osqp = tmp_path / "showcase.toml"
    osqp.write_text(text.replace('solver = { method = "daqp" }\n', ""))
    exact, admm = (load_suite(PROBLEMS / "showcase.toml"), load_suite(osqp))
    sims = [estimate_suite(s).seconds["simulations"] for s in (exact, admm)]
    assert sims[0] < 0.6 * sims[1]
    monkeypatch.setattr(res, "MPC_DAQP_STEP_S", res.MPC_STEP_S)
    monkeypatch.setattr(res, "DEEPLCC_DAQP_STEP_S", res.DEEPLCC_STEP_S)
    sims = [estimate_suite(s).seconds["simulations"] for s in (exact, admm)]
    assert sims[0] == pytest.approx(sims[1], rel=1e-12)
