"""``lcc-synth simulate PROBLEM --export DIR`` when DIR cannot take the files, is shared by two
runs, or holds a link that leads out of it: the real command in a subprocess.

The problem is Table II's string (``problems/paper_table2.toml``: the CAV, 10 HDVs behind, the
head cruising at v*) cut to 6 s (600 steps, the brake at 2 s): three controllers, three files
of about 0.68 MB (7,200 rows each), about 2 s a run here. Its ``--export`` space check asks
for 3 runs x 7,200 rows x 140 bytes = 3.0 MB, times 1.25, plus 1 MiB: 4.8 MB.

* **Full disk.** Too little free space is refused before any simulation (exit 2, one line
  naming ``--export``, the path and the free space; nothing written). A disk that fills while
  the files are written (the command is stopped after its first file, the file system filled
  to the last byte, the command continued) is exit 1, one line naming the file that could not
  be written, after the table; the files published before it are whole (read back, they equal
  an in-process simulation of the same file bit for bit) and no temporary file is left; in CSV
  and in Parquet (0.20-0.21 MB a file here).
* **Read-only.** A DIR to be created under a read-only mount, and an existing DIR on a file
  system remounted read-only, are one line naming ``--export`` and the directory, exit 2,
  before any simulation (no progress line, no table); what DIR held is untouched.
* **Two runs at once** into one DIR that already holds a user's file of an export's name:
  nothing is replaced (``NAME-2``, ``NAME-3``), each run's three files are whole and hold its
  own simulation: the head's velocity is the problem's v* at every sample, and the CAV's
  spacing at the first sample is the equilibrium spacing s*, checked against the paper's OVM
  law by the forward evaluation f_v(s*) = v* (eq. (3); the package computes s* by the
  inverse, arccos).
* **Inside DIR only.** The package promises that a run never writes outside its output
  directory (:mod:`lcc_synth.outputs`). A problem and a controller named with ``../`` and an
  ``--export`` given through ``..`` put every file directly in the directory DIR names; a
  symbolic link planted in DIR under an export's name, pointing outside (to a user's file, or
  to a name that does not exist yet), is not written through: exit 1 after the table, one
  line naming the link, the file outside untouched (or never created).

The mounts need root (``mount -t tmpfs``): those tests skip with the reason elsewhere.
"""

from __future__ import annotations

import hashlib
import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from cli_subprocess import (
    PROBLEMS,
    one_line_error,
    run_cli,
    start_cli,
    stop_fill_continue,
    tmpfs,
)

import lcc_synth as lcc
from lcc_synth.experiments.spec import load_spec
from lcc_synth.simulation.export import read_trajectories

EPS = np.finfo(float).eps
CONTROLLERS = ("all_hdv", "fd_lcc", "cf_lcc")  # the problem's order: the order of the files
SAMPLES, VEHICLES = 600, 12
#: The paper's OVM drivers (Sec. V), as in problems/paper_table2.toml.
S_ST, S_GO, V_MAX = 5.0, 35.0, 30.0


def _problem(tmp: Path, v_star: float = 15.0, stem: str = "short") -> Path:
    """Table II's problem cut to 6 s, the head cruising at ``v_star``; its ``name`` stays
    ``paper_table2`` (the exported files are ``paper_table2_<controller>.csv``)."""
    text = (PROBLEMS / "paper_table2.toml").read_text()
    for old, new in (("duration = 100.0", "duration = 6.0"), ("start = 20.0", "start = 2.0"),
                     ("window = [20.0, 40.0]", "window = [2.0, 6.0]"),
                     ("v_star = 15.0", f"v_star = {v_star!r}")):  # fmt: skip
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = tmp / f"{stem}.toml"
    path.write_text(text)
    return path


def _files(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


def _same(a, b) -> bool:
    return np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float), equal_nan=True)


def _simulated(problem: Path) -> dict:
    """Every controller's run of ``problem``, simulated in this process (the API)."""
    spec = load_spec(problem)
    return {name: lcc.simulate(spec.scenario, ctrl) for name, ctrl in spec.controllers.items()}


def _assert_whole(path: Path, problem: Path, runs: dict) -> None:
    """``path`` is a complete export of ``problem``: its header names the problem's bytes,
    every sample of every vehicle is there, and it equals the in-process simulation."""
    back = read_trajectories(path)
    assert back.header["problem"]["sha256"] == hashlib.sha256(problem.read_bytes()).hexdigest()
    assert len(back.columns["t"]) == SAMPLES * VEHICLES == back.header["samples"] * VEHICLES
    res = runs[back.header["controller"]]
    for col, arr in (("velocity", res.velocity), ("spacing", res.spacing),
                     ("position", res.position), ("accel", res.acceleration)):  # fmt: skip
        assert _same(back.grid(col), arr[0]), (path, col)


def _no_part_files(directory: Path) -> None:
    left = [p for p in directory.rglob("*") if ".part-" in p.name or ".lcc-synth-probe" in p.name]
    assert not left, left


@pytest.fixture
def small_disk(tmp_path):
    with tmpfs(tmp_path / "disk", "size=8m") as disk:  # a full disk is simulated there
        yield disk


# --- full disk ---------------------------------------------------------------------------


def test_too_little_space_is_refused_before_any_simulation(tmp_path):
    """4.8 MB needed (module docstring), 2 MiB on the file system: exit 2 before the work."""
    problem = _problem(tmp_path)
    with tmpfs(tmp_path / "tiny", "size=2m") as tiny:
        out = tiny / "traj"
        proc = run_cli(["simulate", problem, "--no-record", "--export", out], cwd=tmp_path)
        assert proc.returncode == 2 and one_line_error(proc.stderr), proc.stderr
        assert "error: --export:" in proc.stderr and f"{out} is on a file system with" in (
            proc.stderr) and "free" in proc.stderr  # fmt: skip
        assert proc.stdout == "" and "simulations" not in proc.stderr  # nothing simulated
        assert os.listdir(tiny) == []  # DIR not even created


# slow: Parquet (CI runs it; CSV checks the same keeping of whole files by default)
@pytest.mark.parametrize("fmt", ["csv", pytest.param("parquet", marks=pytest.mark.slow)])
def test_a_disk_that_fills_during_the_export_keeps_whole_files_and_prints_the_table(
    fmt, small_disk, tmp_path
):
    """8 MiB passes the check; the file system is filled once the first file is published.
    The next file cannot be written: exit 1 after the table, one line naming it, the files
    before it whole, the failed one and its temporary file gone, no later file started."""
    if fmt == "parquet":
        pytest.importorskip("pyarrow", reason="--export-format parquet needs pyarrow")
    problem = _problem(tmp_path)
    out = small_disk / "traj"
    proc = start_cli(["simulate", problem, "--no-record", "-q", "--export", out,
                      "--export-format", fmt], cwd=tmp_path)  # fmt: skip
    try:
        first = out / f"paper_table2_{CONTROLLERS[0]}.{fmt}"
        stop_fill_continue(proc, small_disk, first.exists)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 1, stderr
    assert one_line_error(stderr), stderr
    for name in CONTROLLERS:  # the table is printed all the same
        assert any(line.startswith(f"{name} ") for line in stdout.splitlines()), stdout
    published = _files(out)
    k = len(published)  # the files published before the disk was full, in the problem's order
    assert 1 <= k < len(CONTROLLERS), published
    assert published == sorted(f"paper_table2_{c}.{fmt}" for c in CONTROLLERS[:k])
    failed = out / f"paper_table2_{CONTROLLERS[k]}.{fmt}"
    last = stderr.rstrip().splitlines()[-1]  # pyarrow words ENOSPC its own way, errno included
    assert last.startswith(f"lcc-synth simulate: error: cannot write {failed}: ") and (
        "No space left on device" in last), last  # fmt: skip
    assert f"trajectories: {k} file(s) in {out}" in stderr
    runs = _simulated(problem)
    for name in published:
        _assert_whole(out / name, problem, runs)
    _no_part_files(small_disk)


# --- read-only ---------------------------------------------------------------------------


@pytest.mark.parametrize("where", ["to_create", "existing"])
def test_a_read_only_export_directory_is_one_line_before_any_simulation(where, tmp_path):
    """``to_create``: DIR two levels below a read-only mount; ``existing``: DIR exists and
    holds a user's file, then its file system is remounted read-only (root passes every mode
    bit: only a read-only mount stops it)."""
    problem = _problem(tmp_path)
    with tmpfs(tmp_path / "fs", "size=1m") as fs:
        if where == "existing":
            out = fs / "traj"
            out.mkdir()
            (out / "notes.txt").write_text("the user's notes")
            named = f"cannot write in {out}: Read-only file system"
        else:
            out = fs / "a" / "traj"
            named = f"cannot write in {fs} (to create {out}): Read-only file system"
        remount = subprocess.run(["mount", "-o", "remount,ro", str(fs)], capture_output=True,
                                 text=True)  # fmt: skip
        if remount.returncode != 0:
            pytest.skip(f"remounting read-only not permitted here: {remount.stderr.strip()}")
        before = sorted(str(p.relative_to(fs)) for p in fs.rglob("*"))
        proc = run_cli(["simulate", problem, "--no-record", "--export", out], cwd=tmp_path)
        assert proc.returncode == 2 and one_line_error(proc.stderr), proc.stderr
        assert f"lcc-synth simulate: error: --export: {named}" in proc.stderr
        assert proc.stdout == "" and "simulations" not in proc.stderr  # no work was done
        assert sorted(str(p.relative_to(fs)) for p in fs.rglob("*")) == before
        if where == "existing":
            assert (out / "notes.txt").read_text() == "the user's notes"


# --- two runs at once ----------------------------------------------------------------------


def _f_v(s: np.ndarray) -> np.ndarray:
    """The paper's OVM desired velocity between s_st and s_go (eq. (3))."""
    return V_MAX / 2 * (1 - np.cos(np.pi * (s - S_ST) / (S_GO - S_ST)))


def test_two_runs_at_once_into_one_directory_keep_every_file_whole(tmp_path):
    """Two problems of the same ``name`` (v* = 15 and 20 m/s) exported together into a DIR
    that holds a user's ``paper_table2_all_hdv.csv``."""
    v_stars = {15.0: _problem(tmp_path, 15.0, "v15"), 20.0: _problem(tmp_path, 20.0, "v20")}
    out = tmp_path / "traj"
    out.mkdir()
    users = out / "paper_table2_all_hdv.csv"
    users.write_text("the user's file")
    procs = [start_cli(["simulate", p, "--no-record", "-q", "--export", out], cwd=tmp_path)
             for p in v_stars.values()]  # fmt: skip
    results = [p.communicate(timeout=300) for p in procs]
    for p, (_, err) in zip(procs, results, strict=True):
        assert p.returncode == 0, err
        assert f"trajectories: 3 file(s) in {out}" in err
    assert users.read_text() == "the user's file"  # never replaced
    assert _files(out) == sorted(
        ["paper_table2_all_hdv.csv", "paper_table2_all_hdv-2.csv", "paper_table2_all_hdv-3.csv"]
        + [f"paper_table2_{c}{k}.csv" for c in CONTROLLERS[1:] for k in ("", "-2")]
    )
    sha = {hashlib.sha256(p.read_bytes()).hexdigest(): v for v, p in v_stars.items()}
    runs = {v: _simulated(p) for v, p in v_stars.items()}
    seen: dict[str, list[float]] = {c: [] for c in CONTROLLERS}
    for path in sorted(out.iterdir()):
        if path == users:
            continue
        back = read_trajectories(path)
        v_star = sha[back.header["problem"]["sha256"]]
        seen[back.header["controller"]].append(v_star)
        _assert_whole(path, v_stars[v_star], runs[v_star])
        head = back.columns["label"] == "head"
        assert np.all(back.columns["velocity"][head] == v_star)  # the head cruises at v*
        (cav,) = back.columns["vehicle"][:VEHICLES][back.columns["role"][:VEHICLES] == "cav"]
        s0 = back.grid("spacing")[0, cav]  # the CAV's spacing at the first sample
        assert back.columns["label"][cav] == "CAV" and S_ST < s0 < S_GO
        slope = V_MAX / 2 * np.pi / (S_GO - S_ST)  # |f_v'| <= this
        assert abs(_f_v(s0) - v_star) <= 4 * EPS * (V_MAX + slope * s0), (s0, v_star)
        if v_star == 15.0:  # v* = v_max / 2: the middle of [s_st, s_go]
            assert math.isclose(s0, (S_ST + S_GO) / 2, rel_tol=4 * EPS)
    assert all(sorted(v) == [15.0, 20.0] for v in seen.values()), seen  # one file per run
    _no_part_files(out)


# --- inside DIR only -------------------------------------------------------------------------


def test_names_with_dot_dot_and_an_export_path_through_dot_dot_stay_in_dir(tmp_path):
    """``name = "../../escape"``, a controller ``"../../fd"``, ``--export ../traj`` from a
    working directory ``work``: the three files are directly in ``traj``, nothing else is
    created anywhere under the test's directory."""
    text = _problem(tmp_path).read_text()
    text = text.replace('name = "paper_table2"', 'name = "../../escape"', 1).replace(
        "[controllers.fd_lcc]", '[controllers."../../fd"]', 1)
    problem = tmp_path / "escape.toml"
    problem.write_text(text)
    work = tmp_path / "work"
    work.mkdir()
    before = sorted(tmp_path.rglob("*"))
    proc = run_cli(["simulate", problem, "--no-record", "-q", "--export", "../traj"], cwd=work)
    assert proc.returncode == 0, proc.stderr
    out = tmp_path / "traj"
    assert _files(out) == ["_._.._escape__._.._fd.csv", "_._.._escape_all_hdv.csv",
                           "_._.._escape_cf_lcc.csv"]  # fmt: skip
    assert sorted(tmp_path.rglob("*")) == sorted([*before, out, *out.iterdir()])
    runs = _simulated(problem)
    assert sorted(runs) == ["../../fd", "all_hdv", "cf_lcc"]
    for path in out.iterdir():
        _assert_whole(path, problem, runs)


@pytest.mark.parametrize("target", ["users_file", "new_name"])
def test_a_link_in_dir_pointing_outside_is_not_written_through(target, tmp_path):
    """DIR/paper_table2_fd_lcc.csv is a symbolic link to a user's file outside DIR, or to a
    name outside DIR that does not exist yet: neither is written; the run prints its table,
    names the link in one line and exits 1; the file before it is whole."""
    problem = _problem(tmp_path)
    outside = tmp_path / "outside"
    outside.mkdir()
    victim = outside / ("victim.csv" if target == "users_file" else "new.csv")
    if target == "users_file":
        victim.write_text("the user's file")
    out = tmp_path / "traj"
    out.mkdir()
    link = out / "paper_table2_fd_lcc.csv"
    link.symlink_to(victim)
    proc = run_cli(["simulate", problem, "--no-record", "-q", "--export", out], cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert one_line_error(proc.stderr), proc.stderr
    last = proc.stderr.rstrip().splitlines()[-1]
    assert last.startswith(f"lcc-synth simulate: error: cannot write {link}: ") and (
        "symbolic link" in last and str(victim) in last), last  # fmt: skip
    for name in CONTROLLERS:  # the results are printed all the same
        assert any(line.startswith(f"{name} ") for line in proc.stdout.splitlines())
    if target == "users_file":
        assert victim.read_text() == "the user's file"
    assert _files(outside) == ([victim.name] if target == "users_file" else [])
    assert link.is_symlink() and os.readlink(link) == str(victim)
    assert _files(out) == ["paper_table2_all_hdv.csv", "paper_table2_fd_lcc.csv"]
    _assert_whole(out / "paper_table2_all_hdv.csv", problem, _simulated(problem))
    _no_part_files(out)
