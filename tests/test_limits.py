"""Resource limits (refused before allocating, exit 2), progress lines and Ctrl-C (exit 130)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest
from cli_subprocess import start_cli

from lcc_synth.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ROOT / "problems"


def _mutate(tmp_path, name, pattern, repl):
    src = (PROBLEMS / name).read_text()
    out = re.sub(pattern, repl, src, count=1, flags=re.M)
    assert out != src
    p = tmp_path / name
    p.write_text(out)
    return p


def _refused(capsys, argv, field, budget=20.0):
    t0 = time.perf_counter()
    assert main(argv) == 2
    assert time.perf_counter() - t0 < budget
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and field in err[0] and "Traceback" not in err[0], err
    return err[0]


def test_duration_refused_with_estimate(tmp_path, capsys):
    p = _mutate(tmp_path, "mpc_head_brake.toml", r"^duration = .*$", "duration = 1e9")
    msg = _refused(capsys, ["simulate", str(p), "--no-record"], "scenario.duration")
    assert "TiB" in msg and "available" in msg


def test_mpc_horizon_refused(tmp_path, capsys):
    p = _mutate(tmp_path, "mpc_head_brake.toml", r"^horizon = .*$", "horizon = 100000")
    msg = _refused(capsys, ["simulate", str(p), "--no-record"], "controllers.mpc.horizon")
    assert "limit 500" in msg


def test_synthesis_size_refused(tmp_path, capsys):
    # dense cones (string-aware design): refused with the KKT memory estimate
    p = _mutate(tmp_path, "synth_string_stable_m2n2.toml", r"^n = 2$", "n = 150")
    msg = _refused(capsys, ["synthesize", str(p), "--no-record"], "system.n")
    # the way out named is one that solves no LMI (string_stable solves it with any method)
    assert "design = 'structured' and method = 'direct'" in msg and "GiB" in msg
    assert "limit 100" in msg


def test_long_structured_design_is_accepted():
    """402 states (n = 200), refused before the Newton polishing, is within the limit now."""
    import pytest

    from lcc_synth.errors import ConfigError
    from lcc_synth.problem import load_problem
    from lcc_synth.synthesis.config import spec_from_problem
    from lcc_synth.synthesis.design import MAX_CHORDAL_VEHICLES, check_size

    assert MAX_CHORDAL_VEHICLES >= 200
    spec = spec_from_problem(load_problem(PROBLEMS / "synth_cf_lcc_pattern.toml"))
    spec = replace(spec, system=replace(spec.system, n=200))
    check_size(spec, 402)  # no ConfigError
    # the structured restriction (small chordal cones) has its own, larger limit
    longer = replace(spec, system=replace(spec.system, kind="lcc", m=5))
    with pytest.raises(ConfigError, match="m \\+ n = 205 is above the limit 200.*'direct'"):
        check_size(longer, 412)


@pytest.mark.parametrize("kind", ["lcc", "platoon"])
def test_the_way_out_of_an_lmi_size_refusal_is_one_that_passes(kind):
    """Every design's size refusal names settings under which the same spec is accepted."""
    import lcc_synth as lcc
    from lcc_synth.errors import ConfigError
    from lcc_synth.problem import load_problem
    from lcc_synth.synthesis.config import spec_from_problem
    from lcc_synth.synthesis.design import check_size

    spec = spec_from_problem(load_problem(PROBLEMS / "synth_cf_lcc_pattern.toml"))
    long = (replace(spec.system, kind="lcc", m=110, n=110) if kind == "lcc"
            else lcc.system(size=221, cavs=[111]))  # fmt: skip
    cases = {  # design -> (the refused settings, the settings its message names)
        "full_state": ({"method": "lmi"}, {"method": "riccati", "cross_check": False}),
        "structured": ({"method": "lmi"}, {"method": "direct"}),
        "string_stable": ({}, {"design": "structured", "method": "direct"}),
    }
    for design, (bad, good) in cases.items():
        sp = replace(spec, system=long, design=design, cross_check=True, **bad)
        nx = 2 * 221  # 221 vehicles: past both limits
        with pytest.raises(ConfigError) as err:
            check_size(sp, nx)
        named = re.findall(r"(\w+) = '?(\w+)'?", err.value.message.split("use ")[-1])
        assert {k: {"false": False}.get(v, v) for k, v in named} == good
        check_size(replace(sp, **good), nx)  # no ConfigError


def test_memory_estimate_against_available(monkeypatch):
    import pytest

    from lcc_synth import resources
    from lcc_synth.errors import ConfigError

    monkeypatch.setattr(resources, "available_memory", lambda: 1 << 30)
    resources.require_memory("x", 1 << 20, "small")
    with pytest.raises(ConfigError, match="x: the run needs about 2 GiB"):
        resources.require_memory("x", 2 << 30, "large")


def test_synthesis_progress_on_stderr(capsys):
    assert main(["synthesize", str(PROBLEMS / "synth_cf_lcc_pattern.toml"), "--no-record"]) == 0
    err = capsys.readouterr().err
    for stage in ("Riccati", "LMI solve", "polish iteration", "done in"):
        assert "lcc-synth: synthesis: " in err and stage in err, err
    assert main(["synthesize", str(PROBLEMS / "synth_cf_lcc_pattern.toml"), "--no-record",
                 "--no-progress"]) == 0
    assert "lcc-synth: synthesis:" not in capsys.readouterr().err


@pytest.mark.slow  # SIGINT of simulate at a random moment: tests/test_fail_signals.py
def test_ctrl_c_exits_130_in_one_line(tmp_path):
    """Ctrl-C while the MPC runs, at two moments (most of the run is inside OSQP solves, where
    a signal late in a converging solve used to be swallowed: 8 of 32 tries ran to the end)."""
    p = _mutate(tmp_path, "mpc_head_brake.toml", r"^duration = .*$", "duration = 3000.0")
    for delay in (5.0, 6.5):
        proc = start_cli(
            ["simulate", p, "--no-record"], cwd=tmp_path,
            # a shell's background job ignores SIGINT and a child inherits that: restore it
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )  # fmt: skip
        time.sleep(delay)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, (delay, err, out[-400:])
        assert "Traceback" not in err
        assert err.strip().splitlines()[-1] in ("lcc-synth simulate: interrupted",
                                                "lcc-synth simulate: interrupted by SIGINT")


def test_osqp_interrupt_flag_is_read_after_a_converged_solve():
    """The flag that OSQP's own SIGINT handler sets is the one the MPC reads after each solve;
    a set flag turns a converged solve into KeyboardInterrupt."""
    import ctypes

    import numpy as np
    import pytest
    from osqp import ext_builtin

    from lcc_synth.mpc import solver as mpc_solver

    flag = mpc_solver._osqp_interrupt_flag()
    assert flag is not None, "this OSQP build does not export osqp_is_interrupted"
    lib = ctypes.CDLL(ext_builtin.__file__)
    lib.osqp_start_interrupt_listener()
    try:
        assert flag() == 0
        signal.raise_signal(signal.SIGINT)  # OSQP's handler is installed: it only sets the flag
        assert flag() != 0  # OSQP stores the signal number
    finally:
        lib.osqp_end_interrupt_listener()

    class _Solved:
        status_val, status, status_polish, iter, run_time = 1, "solved", 1, 3, 1e-4

    class _Solution:
        x, y = np.zeros(2), np.zeros(2)

    class _Ext:  # the extension's workspace, which OSQPSolver.solve calls directly
        info, solution = _Solved(), _Solution()

        def update_data_vec(self, q=None, l=None, u=None):
            pass

        def solve(self):
            pass

    s = mpc_solver.OSQPSolver.__new__(mpc_solver.OSQPSolver)
    s.settings = type("S", (), {"warm_start": False})()
    s._silent, s.force_failure, s._infty = None, False, 1e30
    s._solver = type("O", (), {"_solver": _Ext()})()
    s._interrupted = lambda: 1
    with pytest.raises(KeyboardInterrupt):
        s.solve(np.zeros(2), np.zeros(2), np.zeros(2))
    s._interrupted = lambda: 0
    assert s.solve(np.zeros(2), np.zeros(2), np.zeros(2)).ok


def test_available_memory_sees_an_address_space_limit():
    """A process limited below the machine's free memory (``ulimit -v``, the way a batch
    scheduler caps a job) gets the limit's room, not the machine's free memory."""
    code = ("import resource; resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30)); "
            "from lcc_synth.resources import available_memory; print(available_memory())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=60)  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert 0 < int(out.stdout) < 3 << 30
