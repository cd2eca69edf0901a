"""Work that cannot finish (issue 28, rows 12 and 13) and the recording's size.

The real ``lcc-synth`` in a subprocess (``tests/cli_subprocess.py``): a seed study whose
recording would exceed the limit (``--max-recording-size``, default 1 GB) or whose memory
would not fit exits 2 at once, with one line naming what to change, and writes nothing.
Running such a study to find out is what the estimate avoids, so the escapes (a higher
limit, ``--no-record``, the default ``minmax``) are proven on the checks themselves, in
process. Independent truth for the estimates: the sizes on disk of files written by the real
recorder (``lcc_synth.recording.size`` states a margin and a factor, held here for exact and
``minmax`` recordings of several problems) and, for the default ``lcc-synth run``, the file of
the real command.
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import pytest
from cli_subprocess import PROBLEMS, one_line_error, rrd_verifies, run_cli

pytest.importorskip("rerun")

from lcc_synth.cli.main import build_parser, main  # noqa: E402
from lcc_synth.errors import ConfigError  # noqa: E402
from lcc_synth.experiments.spec import load_spec  # noqa: E402
from lcc_synth.recording.size import (  # noqa: E402
    ESTIMATE_FACTOR,
    ESTIMATE_MARGIN,
    estimate_simulation_recording,
    parse_size,
)

#: A refusal comes before any simulation: the command's imports and the estimate (about 1 s
#: here), with room for a loaded machine.
FAST_S = 30.0
#: What names the ways out of a recording over the limit.
ESCAPES = ("--record-seeds", "--no-record", "--max-recording-size")


def _error(proc) -> str:
    assert proc.returncode == 2, proc.stderr
    assert one_line_error(proc.stderr), proc.stderr
    return proc.stderr.strip().splitlines()[-1]


def _nothing_written(directory: Path, keep: tuple[str, ...] = ()) -> None:
    assert sorted(p.name for p in directory.rglob("*")) == sorted(keep)


def test_a_hundred_million_seeds_are_refused_at_once(tmp_path):
    """Row 12: ``simulate --seeds 100000000`` (about 132 TB of recording, 216 GiB of metrics)."""
    args = ["simulate", PROBLEMS / "paper_table2.toml", "--seeds", "100000000"]
    t0 = time.monotonic()
    line = _error(run_cli(args, cwd=tmp_path, timeout=300))
    assert time.monotonic() - t0 < FAST_S
    assert re.search(r"error: --seeds: the recording would be about [\d.]+ TB \(100000000 draws "
                     r"x 3 controllers recorded, minmax\), over the default limit \(1 GB\)", line)
    assert all(flag in line for flag in ESCAPES), line
    # without a recording, or with any limit, the memory it needs refuses it
    for extra in (["--no-record"], ["--max-recording-size", "1PB"]):
        t0 = time.monotonic()
        line = _error(run_cli([*args, *extra], cwd=tmp_path, timeout=300))
        assert time.monotonic() - t0 < FAST_S
        assert re.search(r"error: --seeds: the run needs about [\d.]+ [TGP]iB of memory "
                         r"\(100000000 draws x 3 controllers\)", line), line
    _nothing_written(tmp_path)


def test_appendix_c_with_200_exact_seeds_is_refused_and_the_ways_out_pass(
    tmp_path, monkeypatch, capsys
):
    """Row 12: ``simulate problems/paper_appendix_c.toml --seeds 200`` wrote 2.08 GB without a
    word when it recorded every step; it still does with ``--record-every 1``: refused."""
    problem = PROBLEMS / "paper_appendix_c.toml"
    exact = ["simulate", problem, "--seeds", "200", "--record-every", "1"]
    line = _error(run_cli(exact, cwd=tmp_path, timeout=300))
    assert re.search(r"--seeds: the recording would be about [23]\.\d+ GB \(200 draws x 3 "
                     r"controllers recorded, every 1 step\(s\)\)", line), line
    assert all(flag in line for flag in (*ESCAPES, "--record-every minmax")), line
    _nothing_written(tmp_path)

    # the ways out, on the checks that run before the simulation (200 draws take ~70 s)
    from lcc_synth.cli.simulate import check_simulation

    monkeypatch.chdir(tmp_path)  # the default recording directory's checks probe in here
    spec = load_spec(problem, seeds=200)
    parser = build_parser()
    cases = {
        "limit raised": [*map(str, exact), "--max-recording-size", "5GB"],
        "no recording": ["simulate", str(problem), "--seeds", "200", "--no-record"],
        "minmax (the default)": ["simulate", str(problem), "--seeds", "200"],
    }
    got = {}
    for name, argv in cases.items():
        capsys.readouterr()
        got[name] = check_simulation(parser.parse_args(argv), spec)
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("lcc-synth simulate: estimate: 200 draws x 3 "
                                                   "controllers, ~"), (name, err)  # > 10 s
        assert ("recording ~" in err[0]) == (name != "no recording")
    assert 1e9 < got["limit raised"].recording < parse_size("5GB")
    assert got["no recording"].recording is None
    assert got["minmax (the default)"].recording < 1e9 / 2  # minmax: a fraction of it
    assert got["no recording"].seconds < got["limit raised"].seconds
    _nothing_written(tmp_path)


TABLE2_BATCH = "t_start = 0.01\nbatch = 10000000\n"


def test_a_batch_of_ten_million_in_the_problem_file_exits_2_in_seconds(tmp_path):
    """Row 13: ``batch = 10000000`` in ``[scenario]`` gave no answer in 2 minutes (the layout
    of ten million seed tabs, before the memory guard): refused, naming the field."""
    text = (PROBLEMS / "paper_table2.toml").read_text()
    assert text.count("t_start = 0.01\n") == 1
    problem = tmp_path / "table2_batch.toml"
    problem.write_text(text.replace("t_start = 0.01\n", TABLE2_BATCH))
    t0 = time.monotonic()
    line = _error(run_cli(["simulate", problem], cwd=tmp_path, timeout=300))
    assert time.monotonic() - t0 < FAST_S
    assert f"{problem}: scenario.batch: the recording would be about" in line, line
    _nothing_written(tmp_path, keep=(problem.name,))


def test_memory_guards_run_before_the_draws_are_made(tmp_path, monkeypatch, capsys):
    """Row 13 without a recording, and through the Python API: the draws of ten million
    scenarios (a random generator each) and the results are checked before any allocation,
    on a machine with 8 GiB available."""
    from dataclasses import replace

    import lcc_synth.resources as resources
    from lcc_synth.simulation.engine import simulate_many

    monkeypatch.setattr(resources, "available_memory", lambda: 8 * 2**30)
    problem = tmp_path / "table2_batch.toml"
    problem.write_text((PROBLEMS / "paper_table2.toml").read_text().replace(
        "t_start = 0.01\n", TABLE2_BATCH))  # fmt: skip
    monkeypatch.chdir(tmp_path)
    t0 = time.monotonic()
    assert main(["simulate", str(problem), "--no-record"]) == 2
    err = capsys.readouterr().err.strip()
    assert re.fullmatch(r"lcc-synth simulate: error: \S+table2_batch.toml: scenario.batch: the "
                        r"run needs about [\d.]+ GiB of memory \(10000000 draws x 3 "
                        r"controllers\) but only 8 GiB is available; run fewer scenarios .*",
                        err), err
    spec = load_spec(PROBLEMS / "paper_table2.toml")
    big = replace(spec.scenario, batch=10_000_000)
    with pytest.raises(ConfigError, match=r"^scenario.batch: .* \(random draws of 10000000 "):
        big.draw()
    with pytest.raises(ConfigError, match=r"^scenario.batch: .* \(3 results of 10000 steps"):
        simulate_many(big, spec.controllers)
    assert time.monotonic() - t0 < FAST_S
    _nothing_written(tmp_path, keep=(problem.name,))


NOISY = """
name = "noisy"
[hdv]
model = "ovm"
[system]
kind = "cf_lcc"
m = 0
n = 10
v_star = 15.0
[scenario]
dt = 0.01
duration = 40.0
seed = 0
hdv_accel_noise = 0.1
spacing_reference = "own_equilibrium"
heterogeneity = { alpha = 0.1, beta = 0.1, s_go = 5.0 }
delay = { mean = 0.4, spread = 0.1 }
v2v = { loss_rate = 0.2, latency = 0.1, spacing_noise = 0.1, velocity_noise = 0.05 }
[[scenario.perturbations]]
type = "brake_profile"
start = 10.0
decel = -3.0
decel_time = 2.0
hold_time = 3.0
accel = 2.0
accel_time = 3.0
[controllers.all_hdv]
type = "hdv"
[metrics]
window = [10.0, 40.0]
"""


def _problem(tmp_path: Path, name: str) -> Path:
    """A problem file: ``noisy`` (above), a shortened ring, or one of ``problems/``."""
    if name == "noisy":
        path = tmp_path / "noisy.toml"
        path.write_text(NOISY)
        return path
    if name == "ring60":
        path = tmp_path / "ring60.toml"
        text = (PROBLEMS / "ring_stop_and_go.toml").read_text()
        path.write_text(re.sub(r"\nduration = [\d.]+\n", "\nduration = 60.0\n", text, count=1)
                        .replace("window = [200.0, 300.0]", "window = [30.0, 60.0]"))
        return path
    return PROBLEMS / name


@pytest.mark.parametrize(
    ("name", "seeds", "how"),
    [
        ("paper_table2.toml", 1, "minmax"),
        ("paper_table2.toml", 1, "1"),
        ("paper_table2.toml", 1, "10"),
        ("paper_appendix_c.toml", 3, "minmax"),
        ("paper_appendix_c.toml", 3, "1"),
        ("mpc_head_brake.toml", 1, "minmax"),
        ("mpc_head_brake.toml", 1, "1"),
        ("noisy", 1, "minmax"),
        ("noisy", 1, "1"),
        ("ring60", 1, "minmax"),
    ],
)  # fmt: skip
def test_the_size_estimate_bounds_the_real_recording(tmp_path, name, seeds, how, capsys):
    """The estimate made before the run vs the file the real command writes: never below it
    by more than ESTIMATE_MARGIN, at most ESTIMATE_FACTOR times it (exact and minmax, one CAV
    and a ring, static gains, an MPC with its plans, noisy HDVs, several seeds)."""
    problem = _problem(tmp_path, name)
    path = tmp_path / "run.rrd"
    extra = ["--seeds", str(seeds)] if seeds > 1 else []
    assert main(["simulate", str(problem), "--json", "--rrd", str(path), "--record-every", how,
                 *extra]) == 0  # fmt: skip
    capsys.readouterr()
    spec = load_spec(problem, seeds=seeds if seeds > 1 else None)
    every = how if how == "minmax" else int(how)
    est = estimate_simulation_recording(spec.scenario, spec.controllers, seeds, every)
    real = path.stat().st_size
    assert real * (1 - ESTIMATE_MARGIN) <= est.bytes <= ESTIMATE_FACTOR * real, (
        est.bytes, real)


@pytest.mark.slow
def test_the_default_run_recording_is_at_most_8_mb(tmp_path):
    """The default ``lcc-synth run`` (problems/showcase.toml, 24 runs, about a minute): its
    recording is at most 8 MB (19.1 MB before minmax kept lines, noise bands, frames and plans
    apart), complete, holds every run's entities and the MPCs' plans, and the estimate of
    ``lcc-synth run``'s check bounds it."""
    from lcc_synth.cli.run import default_problem
    from lcc_synth.experiments.comparison import load_suite
    from lcc_synth.experiments.suite_size import suite_recording_estimate
    from lcc_synth.recording import summarize_recording

    rrd = tmp_path / "showcase.rrd"
    proc = run_cli(["run", "--rrd", rrd, "--out", tmp_path / "res", "--no-figures",
                    "--no-progress", "--json"], cwd=tmp_path, timeout=1200)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    size = rrd.stat().st_size
    assert size <= 8_000_000, size
    assert rrd_verifies(rrd)
    est = suite_recording_estimate(load_suite(default_problem()))
    assert size * (1 - ESTIMATE_MARGIN) <= est.bytes <= ESTIMATE_FACTOR * size, (est.bytes, size)
    table = json.loads(proc.stdout)["results"]
    s = summarize_recording(rrd)
    runs = [(sc, c) for sc, per in table.items() for c in per]
    assert len(runs) == 24
    for sc, c in runs:
        for entity in ("velocity", "spacing", "acceleration", "road", "cav/u_cmd",
                       "cav/aeb_active", "metrics", "controller"):
            assert f"/{sc}/{c}/{entity}" in s.entities, (sc, c, entity)
    plans = [e for e in s.entities if e.endswith("/mpc/predicted/velocity")]
    assert len(plans) >= 6 and all(s.entities[e].samples >= 10 for e in plans)
    origins = {v["space_origin"] for v in s.views}
    assert {f"/{sc}/{c}/road" for sc, c in runs} <= origins  # every run keeps its views


def test_the_check_of_lcc_synth_run_refuses_its_recording_over_the_limit(tmp_path, monkeypatch):
    """What ``lcc-synth run`` calls before the work (check_suite_recording): the default run's
    recording (estimated about 16 MB for 6.6 MB real) passes the default limit and is refused
    below its estimate, naming what to change; nothing is checked with --no-record."""
    from lcc_synth.cli.run import default_problem
    from lcc_synth.experiments.comparison import load_suite
    from lcc_synth.experiments.suite_size import check_suite_recording

    monkeypatch.chdir(tmp_path)
    suite = load_suite(default_problem())
    parser = build_parser()
    est = check_suite_recording(parser.parse_args(["run"]), suite)
    assert 6.6e6 < est.bytes < 4 * 6.6e6 and est.runs >= 24
    with pytest.raises(ConfigError) as err:
        check_suite_recording(parser.parse_args(["run", "--max-recording-size", "5MB"]), suite)
    assert err.value.field == "--scenarios"
    for flag in ("--controllers", "--no-record", "--max-recording-size"):
        assert flag in err.value.message
    assert check_suite_recording(parser.parse_args(["run", "--no-record"]), suite) is None
    _nothing_written(tmp_path)


def test_sizes_and_seed_counts_parse_as_documented():
    from lcc_synth.recording import format_size, parse_record_seeds, record_seed_count

    assert parse_size("1GB") == 10**9 and parse_size("500 mb") == 5 * 10**8
    assert parse_size("1.5GiB") == 3 * 2**29 and parse_size("2048") == 2048
    assert format_size(2.08e9) == "2.08 GB" and format_size(640_000) == "640 kB"
    for bad in ("", "GB", "1XB", "-1GB", "0", "nan"):
        with pytest.raises(ConfigError, match="--max-recording-size"):
            parse_size(bad)
    for value, batch in [(None, 5), ("0,3", 5), ("2-5", 8), ("1-3,2-4,7", 9), ("all", 7)]:
        assert record_seed_count(value, batch) == len(parse_record_seeds(value, batch))
    assert record_seed_count(None, 10**8) == 10**8  # counted, not listed
    assert record_seed_count("0-99999999", 10**8) == 10**8
    for value, batch in [("2-5", 4), ("7", 3), ("x", 3), ("5-2", 9)]:
        with pytest.raises(ConfigError) as a:
            record_seed_count(value, batch)
        with pytest.raises(ConfigError) as b:
            parse_record_seeds(value, batch)
        assert str(a.value) == str(b.value)
