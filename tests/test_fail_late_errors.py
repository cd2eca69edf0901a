"""Issue 28, row 15: a sweep whose random draws can make a value invalid fails on the client,
before any work, never on the Dask workers.

The heterogeneity half-widths are checked as bounds (every value ``nominal ± w`` a draw can
produce must be valid as a fixed ``[hdv]`` value: :class:`lcc_synth.simulation.scenario.Scenario`)
and a ``[lo, hi]`` range at both ends
(:func:`~lcc_synth.simulation.checks.check_ranges`), when ``load_sweep`` reads the file. Such
a sweep used to start its cluster, synthesise its controllers and lose every task on the
workers (8 "Compute Failed" tracebacks, retries of an error that cannot change). Now: exit 2,
one line naming the field and the allowed value, in about the time of the imports, without a
"scenarios" progress bar or anything from Dask.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest
from cli_subprocess import PROBLEMS, one_line_error, run_cli

from lcc_synth.errors import ConfigError
from lcc_synth.experiments.sweep import load_sweep

SWEEP = (PROBLEMS / "sweep_robustness.toml").read_text()


def sweep_file(tmp: Path, pattern: str, repl: str) -> Path:
    """``sweep_robustness.toml`` with the line matching ``pattern`` replaced."""
    text, k = re.subn(pattern, repl, SWEEP, count=1, flags=re.M)
    assert k == 1, pattern
    path = tmp / "sweep.toml"
    path.write_text(text)
    return path


def run_sweep_cli(tmp: Path, path: Path):
    t0 = time.monotonic()
    proc = run_cli(["sweep", path.name, "--count", "4", "--workers", "1", "--no-record",
                    "--no-figures", "--out", str(tmp / "out")], cwd=tmp, timeout=300)  # fmt: skip
    return proc, time.monotonic() - t0


def fails_before_any_work(proc, elapsed: float, *parts: str) -> str:
    assert proc.returncode == 2, proc.stderr
    assert one_line_error(proc.stderr), proc.stderr
    line = proc.stderr.strip().splitlines()[-1]
    for part in parts:
        assert part in line, (part, line)
    for sign in ("scenarios", "controllers (synthesis)", "Compute Failed", "distributed",
                 "Traceback"):  # fmt: skip
        assert sign not in proc.stderr.replace(line, ""), proc.stderr
    assert not (proc.stdout.strip()), proc.stdout
    assert elapsed < 60.0, f"{elapsed:.1f} s"  # the imports; the sweep itself takes minutes
    return line


def test_heterogeneity_that_can_draw_an_invalid_hdv(tmp_path):
    path = sweep_file(tmp_path, r"^alpha = 0\.1$", "alpha = 2.0")  # nominal alpha 0.6
    proc, elapsed = run_sweep_cli(tmp_path, path)
    fails_before_any_work(proc, elapsed, "sweep.toml: scenario.heterogeneity.alpha: must be < 0.6",
                          "(alpha must be > 0)", "got 2")  # fmt: skip
    assert not (tmp_path / "out").exists()


def test_range_whose_upper_bound_is_invalid(tmp_path):
    path = sweep_file(tmp_path, r"^latency = \[0\.05, 0\.15\]$", "latency = [0.05, 50.0]")
    proc, elapsed = run_sweep_cli(tmp_path, path)
    fails_before_any_work(proc, elapsed, "sweep.toml: scenario.v2v.latency: the range "
                          "[0.05, 50] can draw 50", "must be shorter than the run "
                          "(duration = 40 s)")  # fmt: skip


@pytest.mark.parametrize(
    "pattern, repl, field, text",
    [
        (r"^alpha = 0\.1$", "alpha = 0.6", "scenario.heterogeneity.alpha", "must be < 0.6"),
        (r"^s_go = 5\.0$", "s_go = 30.0", "scenario.heterogeneity.s_go", "must be < 30"),
        (r"^beta = 0\.1$", "beta = 0.95", "scenario.heterogeneity.beta", "must be <= 0.9"),
        (r"^s_go = 5\.0$", "s_go = 5.0\ns_st = 4.5\nv_max = 16.0",  # v* = 15 < v_max - w
         "scenario.heterogeneity.v_max", "must be < 15"),
        (r"^s_go = 5\.0$", "s_go = 26.0\ns_st = 4.0",  # each alone valid, not together
         "scenario.heterogeneity", "together can produce an invalid HDV (s_st must be < s_go)"),
    ],
)
def test_bounds_are_checked_as_bounds_in_load_sweep(tmp_path, pattern, repl, field, text):
    """At the edge: the largest valid half-width passes, the bound itself does not (alpha > 0
    strictly, beta >= 0), and half-widths valid one by one but not together."""
    with pytest.raises(ConfigError) as err:
        load_sweep(sweep_file(tmp_path, pattern, repl))
    assert err.value.field == field and text in err.value.message


def test_largest_valid_half_width_loads_and_draws(tmp_path):
    spec = load_sweep(sweep_file(tmp_path, r"^alpha = 0\.1$", "alpha = 0.599"))
    draws = spec.scenario.draw()  # every draw valid: alpha in (0.001, 1.199)
    hdv = spec.scenario.is_hdv()
    assert (draws.hdv_values["alpha"][:, hdv] > 0).all()
