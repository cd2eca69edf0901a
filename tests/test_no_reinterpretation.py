"""No silent reinterpretation (issue 20): inputs whose meaning is wrong are errors naming the
field (exit code 2, one line) or, for a coarse time step, a warning; nothing is quietly
turned into something else."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from lcc_synth.cli.main import main
from lcc_synth.controllers.static import HDVController
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.comparison import load_suite
from lcc_synth.experiments.spec import load_spec
from lcc_synth.experiments.sweep import load_sweep
from lcc_synth.metrics import MetricsConfig, aave
from lcc_synth.problem import system_from
from lcc_synth.simulation.engine import simulate
from lcc_synth.simulation.perturbations import Brake, BrakeProfile
from lcc_synth.simulation.scenario import Scenario

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"


def _edited(tmp_path, name: str, old: str, new: str) -> Path:
    text = (PROBLEMS / name).read_text()
    assert text.count(old) == 1, old
    path = tmp_path / name
    path.write_text(text.replace(old, new))
    return path


def _cli_error(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err  # one line, no traceback
    return err


# -------------------------------------------------------------------------- metric window


def test_window_past_the_end_is_an_error(tmp_path, capsys):
    # was: accepted, AAVE 0.0475 instead of 0.2255 (the 380 s window against 80 s simulated)
    path = _edited(tmp_path, "mpc_head_brake.toml", "window = [20.0, 60.0]", "window = [20, 400]")
    with pytest.raises(ConfigError, match=r"metrics\.window: \[20, 400\] leaves the simulated "
                       r"time \[0, 60\] s"):
        load_spec(path)
    err = _cli_error(capsys, ["simulate", str(path), "--no-record"])
    assert "metrics.window" in err and "t1 <= 60" in err


def test_window_before_the_start_and_in_suites_and_sweeps(tmp_path):
    path = _edited(tmp_path, "paper_table2.toml", "window = [20.0, 40.0]", "window = [0.0, 40.0]")
    with pytest.raises(ConfigError, match=r"metrics\.window: \[0, 40\] leaves the simulated time "
                       r"\[0.01, 100.01\] s"):
        load_spec(path)  # t_start = 0.01: the run starts after 0
    path = _edited(tmp_path, "showcase.toml", "metrics = { window = [20.0, 40.0] }",
                   "metrics = { window = [20.0, 80.0] }")
    with pytest.raises(ConfigError, match=r"scenarios\.brake_behind\.metrics\.window: \[20, 80\]"):
        load_suite(path)
    path = _edited(tmp_path, "sweep_robustness.toml", "window = [5.0, 40.0]",
                   "window = [5.0, 400.0]")
    with pytest.raises(ConfigError, match=r"metrics\.window: \[5, 400\] leaves"):
        load_sweep(path)


def test_window_ending_at_the_end_of_the_run_is_fine_and_the_mask_checks_too():
    # duration 60, window [20, 60]: the last sample (59.99 s) stands for the step ending at 60
    spec = load_spec(PROBLEMS / "mpc_head_brake.toml")
    assert spec.metrics.window == (20.0, 60.0)
    res = simulate(Scenario(m=0, n=1, duration=5.0), HDVController())
    assert aave(res, (1.0, 5.0))[0] == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ConfigError, match="leaves the simulated time"):
        aave(res, (1.0, 6.0))
    with pytest.raises(ConfigError, match="t1 > t0"):
        MetricsConfig(window=(5.0, 1.0))


# -------------------------------------------------------------------------- signs


def test_positive_brake_deceleration_is_an_error(tmp_path, capsys):
    # was: vehicle 1 accelerated at +5 m/s^2 and the run looked plausible
    path = _edited(tmp_path, "paper_table2.toml", "decel = -5.0", "decel = 5.0")
    err = _cli_error(capsys, ["simulate", str(path), "--no-record"])
    assert "scenario.perturbations[0].decel: is the braking acceleration and must be < 0" in err
    assert "got 5.0" in err
    with pytest.raises(ConfigError, match="decel"):
        Brake(1, decel=0.0)


def test_brake_profile_signs(tmp_path, capsys):
    path = _edited(tmp_path, "mpc_head_brake.toml", "accel = 2.0", "accel = -2.0")
    err = _cli_error(capsys, ["simulate", str(path), "--no-record"])
    assert "scenario.perturbations[0].accel: is the recovery acceleration and must be > 0" in err
    path = _edited(tmp_path, "mpc_head_brake.toml", "decel = -5.0", "decel = 5.0")
    err = _cli_error(capsys, ["simulate", str(path), "--no-record"])
    assert "scenario.perturbations[0].decel" in err and "must be < 0" in err
    with pytest.raises(ConfigError, match="accel"):
        BrakeProfile(accel=0.0)
    # in a suite the field names the scenario
    path = _edited(tmp_path, "showcase.toml", "decel = -5.0\n\n# Section V-A",
                   "decel = 5.0\n\n# Section V-A")
    with pytest.raises(ConfigError, match=r"scenarios\.brake_behind\.perturbations\[0\]\.decel"):
        load_suite(path)


# -------------------------------------------------------------------------- sizes


@pytest.mark.parametrize(
    ("kind", "given", "missing"),
    [("lcc", "m = 2", "n"), ("lcc", "n = 2", "m"), (None, "n = 2", "m"), ("cf_lcc", "m = 0", "n"),
     ("fd_lcc", "", "n"), ("ccc", "n = 0", "m")],
)
def test_missing_size_is_an_error_naming_it(kind, given, missing):
    table = {"v_star": 15.0}
    if kind:
        table["kind"] = kind
    if given:
        key, value = given.split(" = ")
        table[key] = int(value)
    with pytest.raises(ConfigError, match=rf"^system\.{missing}: is required for kind = "):
        system_from({"system": table})


def test_sizes_a_kind_fixes_may_be_left_out(tmp_path, capsys):
    assert system_from({"system": {"kind": "cf_lcc", "n": 3}}).m == 0
    assert system_from({"system": {"kind": "ccc", "m": 2}}).n == 0
    # was: an lcc file without n ran with n = 0
    path = _edited(tmp_path, "paper_sec5a.toml", "n = 2\n", "")
    err = _cli_error(capsys, ["simulate", str(path), "--no-record"])
    assert "system.n: is required for kind = 'lcc'" in err
    path = _edited(tmp_path, "showcase.toml", "m = 2\nn = 2\n", "m = 2\n")
    with pytest.raises(ConfigError, match=r"layouts\.sec5a\.n: is required"):
        load_suite(path)


# -------------------------------------------------------------------------- time step


def test_euler_figures():
    from lcc_synth.simulation.timestep import damping_error, euler_check, mode_error

    # a real mode -1/tau: stable iff dt < 2 tau; the errors vanish with dt, as |lambda| dt / 2
    tau = 0.5
    assert euler_check(np.array([[-1 / tau]]), 0.999).stable
    assert not euler_check(np.array([[-1 / tau]]), 1.0).stable
    lam = complex(-0.6, 1.7)
    assert mode_error(lam, 1e-4) == pytest.approx(abs(lam) * 1e-4 / 2, rel=1e-3)
    dt_e = 2 * abs(lam.real) / abs(lam) ** 2
    assert damping_error(lam, dt_e * (1 - 1e-9)) == pytest.approx(1.0, abs=1e-6)
    check = euler_check(np.diag([0.0, -1.0]), 0.01)  # the integrator lambda = 0 is not judged
    assert check.stable and check.mode == -1.0


def test_error_threshold_is_where_the_euler_loop_stops_settling():
    from lcc_synth.simulation.timestep import check_time_step, loop_matrix

    spec = load_spec(PROBLEMS / "paper_table2.toml")
    c = check_time_step(spec.scenario, {"fd": spec.controllers["fd_lcc"]})[0]
    A, _ = loop_matrix(spec.controllers["fd_lcc"], spec.scenario)
    nonzero = [x for x in np.linalg.eigvals(A) if abs(x) > 1e-9]  # the -p_0 integrator aside
    for dt, settles in ((c.dt_stable * 0.999, True), (c.dt_stable * 1.001, False)):
        rho = max(abs(1 + x * dt) for x in nonzero)  # eigenvalues of I + A dt
        assert (rho < 1) == settles


def test_coarse_dt_warns_and_meaningless_dt_is_an_error(tmp_path, capsys):
    from lcc_synth.simulation.timestep import TimeStepWarning

    # was: dt = 1.0 accepted silently, minimum spacing 5.9 m instead of 17.1 m
    path = _edited(tmp_path, "paper_table2.toml", "dt = 0.01", "dt = 1.0")
    with pytest.warns(TimeStepWarning, match=r"scenario\.dt = 1 s is coarse for the closed loop "
                      r"of controller 'fd_lcc': explicit Euler misstates its mode .* by 81 %"):
        load_spec(path)
    with pytest.warns(TimeStepWarning, match="use dt <= 0.091 s"):
        load_spec(_edited(tmp_path, "paper_table2.toml", "dt = 0.01", "dt = 0.1"))
    path = _edited(tmp_path, "paper_table2.toml", "dt = 0.01", "dt = 1.25")
    err = _cli_error(capsys, ["simulate", str(path), "--no-record"])
    assert "scenario.dt: must be < 1.23 s, got 1.25: explicit Euler is unstable" in err


def test_shipped_problems_are_within_the_step_thresholds():
    from lcc_synth.simulation.timestep import TimeStepWarning, check_time_step

    with warnings.catch_warnings():
        warnings.simplefilter("error", TimeStepWarning)
        for name in ("paper_table2", "paper_sec5a", "paper_appendix_c", "mpc_head_brake",
                     "mpc_head_brake_hetero", "mpc_table2_cf", "mpc_table2_fd"):
            spec = load_spec(PROBLEMS / f"{name}.toml")
            assert max(c.excess for c in check_time_step(spec.scenario, spec.controllers)) < 0.25


def test_suite_and_sweep_check_the_step_before_running(tmp_path):
    from test_failed_runs import SUITE, SWEEP

    from lcc_synth.experiments.comparison import run_suite
    from lcc_synth.experiments.sweep import run_sweep

    path = tmp_path / "suite.toml"
    path.write_text(SUITE.replace("duration = 60.0", "duration = 60.0\ndt = 1.2"))
    with pytest.raises(ConfigError, match=r"scenarios\.brake\.dt: must be < 1.09 s, got 1.2"):
        run_suite(load_suite(path), progress=False)
    path = tmp_path / "sweep.toml"
    path.write_text(SWEEP.replace("duration = 60.0", "duration = 60.0\ndt = 1.2"))
    with pytest.raises(ConfigError, match=r"sweep\.toml: scenario\.dt: must be < 1.09 s, got 1.2"):
        run_sweep(load_sweep(path), client=None, progress=False)
