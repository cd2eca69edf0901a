"""Trajectories out (``lcc-synth simulate --export DIR``, :mod:`lcc_synth.simulation.export`).

* Exactness: the file read back equals the simulation's arrays bit for bit (velocity, spacing,
  position, acceleration, the CAVs' commands and braking flags), on a single-CAV string, a
  platoon of two CAVs and a ring, in CSV and Parquet.
* The spacing convention, checked on the exported positions alone: ``spacing[j] =
  position[j-1] - position[j] - L`` and, on a ring (positions not wrapped), ``spacing[0] =
  position[N-1] + C - position[0] - L``. With ``L = 0`` it is the simulator's own arithmetic
  (exact); with a vehicle length the positions were shifted by ``j L`` (one rounding each), so
  the check allows ``4 eps (max|position| + C)``.
* The real CLI: the files, the header's SHA-256 of the problem file against hashlib, the same
  numbers as the API's simulation of the same file; an unwritable or impossible ``DIR`` is one
  line naming ``--export`` and the path, exit 2, before any simulation.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np
import pytest
from cli_subprocess import PROBLEMS, one_line_error, run_cli

import lcc_synth as lcc
from lcc_synth.errors import ConfigError
from lcc_synth.simulation.export import (
    COLUMNS,
    HEADER_TAG,
    export_name,
    read_trajectories,
    write_trajectories,
)

EPS = np.finfo(float).eps


def _layouts():
    brake = [lcc.Brake(vehicle=1, start=3.0, duration=1.0, decel=-4.0)]
    head = [lcc.Brake(vehicle="head", start=3.0, duration=1.0, decel=-4.0)]
    string = lcc.scenario(lcc.system("lcc", m=2, n=3), head, duration=12.0)
    platoon = lcc.scenario(lcc.system(size=6, cavs=[2, 5], vehicle_length=4.5), brake,
                           duration=12.0)  # fmt: skip
    ring = lcc.scenario(lcc.ring(8, cavs=[8], vehicle_length=5.0), brake, duration=40.0)
    ring0 = lcc.scenario(lcc.ring(8, cavs=[8]), brake, duration=40.0)
    return {"string": string, "platoon": platoon, "ring": ring, "ring_no_length": ring0}


LAYOUTS = _layouts()


@pytest.fixture(scope="module", params=list(LAYOUTS))
def run(request):
    return request.param, lcc.simulate(LAYOUTS[request.param], lcc.hdv_controller())


def _same(a, b) -> bool:
    return np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float), equal_nan=True)


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_the_file_read_back_is_the_simulation_bit_for_bit(run, fmt, tmp_path):
    if fmt == "parquet":
        pytest.importorskip("pyarrow")
    name, res = run
    (path,) = write_trajectories(res, tmp_path, name, {"version": "x"}, fmt)
    assert path.name == f"{name}_all_hdv.{fmt}"
    back = read_trajectories(path)
    assert tuple(back.columns) == COLUMNS
    assert _same(back.grid("velocity"), res.velocity[0])
    assert _same(back.grid("spacing"), res.spacing[0])
    assert _same(back.grid("position"), res.position[0])
    assert _same(back.grid("accel"), res.acceleration[0])
    assert _same(back.grid("t")[:, 0], res.t)
    cavs = list(res.cavs)
    assert _same(back.grid("u_cmd")[:, cavs], res.u_columns()[0])
    assert _same(back.grid("aeb")[:, cavs], res.aeb_columns()[0])
    others = [j for j in range(res.n_vehicles) if j not in cavs]
    assert np.isnan(back.grid("u_cmd")[:, others]).all()
    assert list(back.grid("label")[0]) == res.vehicle_labels()
    roles = list(back.grid("role")[0])
    assert [j for j, r in enumerate(roles) if r == "cav"] == cavs
    assert (roles[0] == "head") != res.ring
    assert back.header["vehicle_length"] == res.vehicle_length
    assert back.header["ring"] == res.ring and back.header["version"] == "x"
    assert np.abs(res.u_columns()).max() > 0.01  # the brake reached the CAVs: real data


def test_spacing_is_the_position_difference_minus_the_vehicle_length(run, tmp_path):
    """From the exported columns only (the header's vehicle length and circumference)."""
    name, res = run
    back = read_trajectories(write_trajectories(res, tmp_path, name)[0])
    p, s = back.grid("position"), back.grid("spacing")
    L = back.header["vehicle_length"]
    want = np.empty_like(p)
    want[:, 1:] = p[:, :-1] - p[:, 1:] - L
    if back.header["ring"]:
        C = back.header["circumference"]
        want[:, 0] = p[:, -1] + C - p[:, 0] - L
        assert p[:, 0].max() - p[:, 0].min() > C  # a lap: the positions are not wrapped
        assert name != "ring" or C == pytest.approx(8 * (LAYOUTS[name].circumference / 8 + 5))
    else:
        C = 0.0
        want[:, 0] = np.nan
        assert np.isnan(s[:, 0]).all()
    if L == 0:
        assert _same(s, want)  # the simulator's own arithmetic
    else:
        tol = 4 * EPS * (np.abs(p).max() + C)
        assert np.nanmax(np.abs(s - want)) <= tol
        assert np.nanmax(np.abs(s - (want + L))) > 1.0  # the length is not ignored


def test_a_batch_is_one_file_per_draw_named_by_its_index_in_the_study(tmp_path):
    sc = lcc.scenario(lcc.system("fd_lcc", n=3), [lcc.Brake(vehicle=1, start=2.0)],
                      duration=6.0, batch=3, heterogeneity={"alpha": 0.2}, seed=4)  # fmt: skip
    res = lcc.simulate(sc, lcc.hdv_controller())
    paths = write_trajectories(res, tmp_path, "hetero", first_index=5)
    assert [p.name for p in paths] == [f"hetero_all_hdv_seed{k}.csv" for k in (5, 6, 7)]
    for b, p in enumerate(paths):
        back = read_trajectories(p)
        assert back.header["draw"] == 5 + b
        assert _same(back.grid("velocity"), res.velocity[b])
    assert not _same(res.velocity[0], res.velocity[1])  # the draws differ


def test_names_are_made_safe_and_existing_files_are_kept(tmp_path):
    assert export_name("../x y", "a/b") == "_._x_y_a_b.csv"
    sc = lcc.scenario(lcc.system("fd_lcc", n=1), duration=1.0)
    res = lcc.simulate(sc, lcc.hdv_controller())
    first = write_trajectories(res, tmp_path, "s")[0]
    second = write_trajectories(res, tmp_path, "s")[0]
    assert (first.name, second.name) == ("s_all_hdv.csv", "s_all_hdv-2.csv")
    assert sorted(os.listdir(tmp_path)) == ["s_all_hdv-2.csv", "s_all_hdv.csv"]  # no temp files
    with pytest.raises(ConfigError, match="--export-format"):
        write_trajectories(res, tmp_path, "s", fmt="xlsx")


def test_a_file_that_is_not_an_export_is_refused_naming_the_path(tmp_path):
    bad = tmp_path / "other.csv"
    bad.write_text("t,v\n1,2\n")
    with pytest.raises(ConfigError, match="path: .*other.csv is not a trajectories file"):
        read_trajectories(bad)


SHORT = 12.0  # s of paper_table2 (brake at 20 s: moved to 5 s; metrics over 5-12 s)


def _short_problem(tmp: Path) -> Path:
    text = (PROBLEMS / "paper_table2.toml").read_text()
    text = text.replace("duration = 100.0", f"duration = {SHORT}").replace(
        "start = 20.0", "start = 5.0").replace("window = [20.0, 40.0]", "window = [5.0, 12.0]")
    assert f"duration = {SHORT}" in text and "start = 5.0" in text and "[5.0, 12.0]" in text
    path = tmp / "table2_short.toml"
    path.write_text(text)
    return path


def test_the_cli_exports_every_controller_with_its_provenance(tmp_path):
    from lcc_synth.experiments.spec import load_spec

    problem = _short_problem(tmp_path)
    out = tmp_path / "deep" / "traj"  # created
    proc = run_cli(["simulate", problem, "--no-record", "--export", out], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "trajectories: 3 file(s)" in proc.stderr
    spec = load_spec(problem)
    assert sorted(os.listdir(out)) == sorted(f"paper_table2_{c}.csv" for c in spec.controllers)
    sha = hashlib.sha256(problem.read_bytes()).hexdigest()
    for name, ctrl in spec.controllers.items():
        path = out / f"paper_table2_{name}.csv"
        assert path.read_text().startswith(HEADER_TAG)
        back = read_trajectories(path)
        assert back.header["problem"]["sha256"] == sha
        assert back.header["controller"] == name and back.header["version"] == lcc.__version__
        res = lcc.simulate(spec.scenario, ctrl)  # the same file in this process
        assert _same(back.grid("velocity"), res.velocity[0])
        assert _same(back.grid("spacing"), res.spacing[0])


def test_an_unwritable_export_directory_is_one_line_before_any_simulation(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    proc = run_cli(["simulate", PROBLEMS / "paper_table2.toml", "--no-record", "--export",
                    blocker / "traj"], cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 2 and one_line_error(proc.stderr), proc.stderr
    assert "error: --export:" in proc.stderr and str(blocker) in proc.stderr
    assert proc.stdout == ""  # no table: nothing was simulated


def test_a_read_only_export_directory_is_one_line_naming_it(tmp_path):
    from cli_subprocess import tmpfs

    with tmpfs(tmp_path / "ro", "ro,size=1m") as ro:
        proc = run_cli(["simulate", PROBLEMS / "paper_table2.toml", "--no-record", "--export",
                        ro], cwd=tmp_path)  # fmt: skip
        assert proc.returncode == 2 and one_line_error(proc.stderr), proc.stderr
        assert f"--export: cannot write in {ro}: Read-only file system" in proc.stderr
        assert os.listdir(ro) == [] and proc.stdout == ""


def test_export_format_alone_is_a_usage_error(tmp_path):
    proc = run_cli(["simulate", PROBLEMS / "paper_table2.toml", "--no-record",
                    "--export-format", "parquet"], cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 2 and one_line_error(proc.stderr), proc.stderr
    assert "--export-format: applies with --export DIR only" in proc.stderr
