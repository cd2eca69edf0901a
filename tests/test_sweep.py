"""Monte Carlo sweeps: chunked runs equal one direct batched simulation, whatever the batch
size and wherever they run (in process or on a local Dask cluster, even if a worker dies)."""

from __future__ import annotations

import os
import signal
import threading
import time
from dataclasses import replace

import numpy as np
import pytest
from cli_subprocess import PAPER_HDV

from lcc_synth.cli.main import main
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.comparison import build_controllers
from lcc_synth.experiments.sweep import (
    SWEEP_METRICS,
    aggregate,
    chunks,
    load_sweep,
    run_sweep,
    scenario_metrics,
)
from lcc_synth.simulation.engine import simulate

SWEEP = """
name = "small_sweep"

""" + PAPER_HDV + """
[system]
kind = "cf_lcc"
m = 0
n = 3
v_star = 15.0

[scenario]
duration = 12.0
seed = 11
hdv_accel_noise = 0.2
spacing_reference = "own_equilibrium"
heterogeneity = { alpha = 0.1, beta = 0.1, s_go = 5.0 }
delay = { mean = 0.3, spread = 0.2 }
v2v = { loss_rate = 0.3, latency = 0.05, spacing_noise = 0.2, velocity_noise = 0.1 }

[[scenario.perturbations]]
type = "brake_profile"
start = 2.0
decel = -5.0
decel_time = 1.5
hold_time = 2.0
accel = 2.0
accel_time = 3.0

[metrics]
window = [2.0, 12.0]

[sweep]
count = 8
batch_size = 3

[controllers.all_hdv]
type = "hdv"

[controllers.paper]
type = "static"
semantics = "replace"
gains = { s_0 = 0.1, v_0 = -0.5, s_1 = -0.2, v_1 = 0.05, s_2 = -0.1, v_2 = 0.05 }

[controllers.mpc]
type = "mpc"
sample_time = 0.1
horizon = 10
"""

KEYS = (*SWEEP_METRICS, "collisions", "aeb_activations")


@pytest.fixture(scope="module")
def problem_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("sweep") / "small.toml"
    path.write_text(SWEEP)
    return path


@pytest.fixture(scope="module")
def direct(problem_file):
    """Every scenario of the sweep in ONE batch, straight through simulate + metrics."""
    spec = load_sweep(problem_file)
    sc = replace(spec.scenario, batch=spec.count)
    draws = sc.draw()
    ctrls = build_controllers(spec.controllers, spec.system, spec.source)
    out, fallbacks = {}, {}
    for name, ctrl in ctrls.items():
        res = simulate(sc, ctrl, draws)
        out[name] = scenario_metrics(res, spec.metrics)
        fallbacks[name] = int(res.controller_stats.get("fallbacks", 0))
    return out, fallbacks


@pytest.fixture(scope="module")
def serial(problem_file):
    return run_sweep(load_sweep(problem_file), client=None, progress=False)


def _assert_same_samples(a, b):
    assert list(a) == list(b)
    for c in a:
        for k in KEYS:
            np.testing.assert_array_equal(
                np.asarray(a[c][k]), np.asarray(b[c][k]), err_msg=f"{c}.{k}"
            )


def test_scenarios_are_random_and_varied(direct):
    out, _ = direct
    aave = out["all_hdv"]["aave"]
    assert np.all(np.isfinite(aave))
    assert np.unique(aave).size == aave.size  # every scenario draws its own HDVs and noise


@pytest.mark.parametrize("batch_size", [1, 3, 8])
def test_chunked_sweep_equals_one_batch(problem_file, direct, batch_size):
    spec = load_sweep(problem_file, batch_size=batch_size)
    res = run_sweep(spec, client=None, progress=False)
    assert res.info["tasks"] == len(chunks(8, batch_size))
    out, fallbacks = direct
    _assert_same_samples(res.samples, out)
    assert res.fallbacks == fallbacks


def test_aggregate_matches_numpy(serial, direct):
    out, fallbacks = direct
    summary = serial.summary
    for c, per in out.items():
        for k in SWEEP_METRICS:
            x = per[k][np.isfinite(per[k])]
            assert summary[c][k]["n"] == x.size
            assert summary[c][k]["mean"] == pytest.approx(x.mean(), rel=1e-12)
            assert summary[c][k]["p5"] == pytest.approx(np.percentile(x, 5), rel=1e-12)
            assert summary[c][k]["p95"] == pytest.approx(np.percentile(x, 95), rel=1e-12)
        assert summary[c]["collisions"] == int(per["collisions"].sum())
        assert summary[c]["collision_scenarios"] == int(np.count_nonzero(per["collisions"]))
        assert summary[c]["aeb_activations"] == int(per["aeb_activations"].sum())
        assert summary[c]["fallbacks"] == fallbacks[c]
        assert summary[c]["scenarios"] == 8
    # hand-made case: NaN (a collided run) is left out, counts add up
    agg = aggregate(
        {"x": {**{k: np.array([1.0, np.nan, 3.0]) for k in SWEEP_METRICS},
               "collisions": np.array([0, 2, 0]), "aeb_activations": np.array([0, 5, 1]),
               "jerk_1s_over_limit_s": np.array([0.0, 0.0, 0.3])}},
        {"x": 4},
    )["x"]
    assert agg["aave"]["mean"] == 2.0 and agg["aave"]["n"] == 2
    assert (agg["collisions"], agg["collision_scenarios"]) == (2, 1)
    assert (agg["aeb_activations"], agg["aeb_scenarios"], agg["fallbacks"]) == (6, 2, 4)
    assert agg["jerk_scenarios"] == 1


def test_seed_changes_the_draws(problem_file, serial):
    other = run_sweep(load_sweep(problem_file, seed=12, count=3), client=None, progress=False)
    assert not np.array_equal(other.samples["paper"]["aave"], serial.samples["paper"]["aave"][:3])


@pytest.fixture(scope="module")
def client():
    from dask.distributed import Client

    from lcc_synth.experiments.sweep import local_cluster, stop_cluster

    cluster = local_cluster(2)
    cl = Client(cluster)
    yield cl
    scratch = cluster.lcc_scratch.peek()[2][0]  # (object, function, args, kwargs)
    stop_cluster(cluster, cl)
    assert not os.path.exists(scratch)  # the lcc-sweep-dask-* scratch space: removed


def test_local_cluster_equals_serial(problem_file, client, serial):
    res = run_sweep(load_sweep(problem_file, batch_size=2), client=client, progress=False)
    assert res.info["scheduler"].startswith("tcp://127.0.0.1")
    assert res.info["tasks"] == 4
    _assert_same_samples(res.samples, serial.samples)
    assert res.summary == serial.summary


def test_provenance_names_the_qp_solver_that_runs():
    """provenance.solver_of reads an MPC's and DeeP-LCC's solver.method (DeeP-LCC ran DAQP
    and was recorded as OSQP before) and DeeP-LCC's exact re-solve, on by default."""
    from importlib.metadata import version

    from lcc_synth.provenance import solver_of

    osqp, daqp = f"osqp {version('osqp')}", f"daqp {version('daqp')}"
    assert solver_of({"type": "mpc"}) == osqp
    assert solver_of({"type": "mpc", "solver": {"method": "daqp"}}) == daqp
    assert solver_of({"type": "deep_lcc"}) == f"{osqp}, {daqp} re-solve"
    assert solver_of({"type": "deep_lcc", "solver": {"exact": False}}) == osqp
    assert solver_of({"type": "deep_lcc", "solver": {"method": "daqp"}}) == daqp
    assert solver_of({"type": "static"}) is None


def test_local_cluster_workers_run_without_the_profiler(client):
    """The local cluster's workers and their nannies run with LOCAL_CLUSTER_CONFIG (no 10 ms
    stack sampling, fewer event-loop wake-ups; the measurement is in its comment), and a
    worker's profiler has recorded nothing after the module's sweeps ran on it; the client's
    own configuration is untouched."""
    import dask

    from lcc_synth.experiments.sweep_cluster import LOCAL_CLUSTER_CONFIG

    def worker_view(dask_worker):
        return ({k: dask.config.get(k) for k in LOCAL_CLUSTER_CONFIG},
                dask_worker.profile_recent["count"])  # fmt: skip

    client.submit(sum, [1, 2]).result()  # at least one task ran on a worker
    for config, samples in client.run(worker_view).values():
        assert config == LOCAL_CLUSTER_CONFIG
        assert samples == 0
    assert dask.config.get("distributed.worker.profile.enabled") is True


def test_connect_gives_the_client_after_the_synthesis(problem_file, client, serial,
                                                      monkeypatch):
    """``connect`` (the CLI starts its cluster while the controllers are synthesised) is
    called once, after the controllers exist, and its client gives the serial samples; what
    it raises comes out of run_sweep unchanged."""
    import lcc_synth.experiments.comparison as comparison

    calls = []
    prepare = comparison.prepare_controllers

    def prepared(*args, **kwargs):
        calls.append("synthesis")
        return prepare(*args, **kwargs)

    def connect():
        calls.append("connect")
        return client

    monkeypatch.setattr(comparison, "prepare_controllers", prepared)
    res = run_sweep(load_sweep(problem_file, batch_size=2), progress=False, connect=connect)
    assert calls == ["synthesis", "connect"]
    assert res.info["scheduler"].startswith("tcp://127.0.0.1")
    _assert_same_samples(res.samples, serial.samples)

    def refused():
        raise ConfigError("--scheduler", "cannot connect (test)")

    with pytest.raises(ConfigError, match="cannot connect"):
        run_sweep(load_sweep(problem_file, count=1), progress=False, connect=refused)


def test_worker_death_loses_nothing(problem_file, client, serial):
    """Kill a worker process while tasks run: Dask recomputes its tasks elsewhere."""
    spec = load_sweep(problem_file, batch_size=1)
    box = {}
    thread = threading.Thread(
        target=lambda: box.setdefault("res", run_sweep(spec, client=client, progress=False))
    )
    pids = client.run(os.getpid)  # {worker address: process id} (local cluster)
    thread.start()
    killed = None
    deadline = time.monotonic() + 60
    while killed is None and time.monotonic() < deadline and thread.is_alive():
        busy = [w for w, tasks in client.processing().items() if tasks]
        if busy:
            killed = busy[0]
            os.kill(pids[killed], signal.SIGKILL)  # dies in the middle of its task
        time.sleep(0.01)
    thread.join(timeout=180)
    assert killed is not None
    assert "res" in box
    _assert_same_samples(box["res"].samples, serial.samples)
    # the nanny restarted the killed worker under a new address
    deadline = time.monotonic() + 30
    while killed in client.scheduler_info()["workers"] and time.monotonic() < deadline:
        time.sleep(0.2)
    assert killed not in client.scheduler_info()["workers"]


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"count": 0}, "--count"),
        ({"count": 10**9}, "--count"),
        ({"batch_size": 0}, "--batch-size"),
        ({"seed": -1}, "--seed"),
        ({"controllers": ["nope"]}, "--controllers"),
    ],
)
def test_bad_overrides(problem_file, kwargs, field):
    with pytest.raises(ConfigError) as info:
        load_sweep(problem_file, **kwargs)
    assert info.value.field == field


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ("count = 8", "count = 0", "sweep.count"),
        ("batch_size = 3", "batch_size = -2", "sweep.batch_size"),
        ("batch_size = 3", "batch_size = 3\nworkers = 2", "sweep.workers"),
        ("loss_rate = 0.3", "loss_rate = 1.5", "scenario.v2v.loss_rate"),
        ('type = "hdv"', 'type = "hdv"\nlayouts = { x = {} }', "controllers.all_hdv.layouts"),
    ],
)
def test_bad_sweep_files(tmp_path, old, new, field):
    path = tmp_path / "bad.toml"
    assert old in SWEEP
    path.write_text(SWEEP.replace(old, new, 1))
    with pytest.raises(ConfigError) as info:
        load_sweep(path)
    assert info.value.field == field
    assert info.value.source == str(path)


def test_cli_bad_counts_exit_2(problem_file, capsys):
    assert main(["sweep", str(problem_file), "--count", "0"]) == 2
    assert "--count" in capsys.readouterr().err
    assert main(["sweep", str(problem_file), "--workers", "0"]) == 2
    assert "--workers" in capsys.readouterr().err
    assert main(["sweep", str(problem_file), "--controllers", "lqr"]) == 2


def test_cli_sweep_json_and_files(problem_file, serial, capsys, tmp_path):
    import json

    from lcc_synth.experiments.tables import json_safe

    rrd = tmp_path / "rec" / "sweep.rrd"
    code = main([
        "sweep", str(problem_file), "--count", "4", "--batch-size", "3", "--workers", "1",
        "--json", "--no-progress", "--out", str(tmp_path / "res"), "--rrd", str(rrd),
    ])
    assert code == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)  # exactly one JSON object on stdout
    assert f"recording: {rrd}" in cap.err
    assert list(doc) == ["results", "sweep", "provenance"]
    from lcc_synth.provenance import file_sha256

    prov = doc["provenance"]  # what made these numbers: the file's bytes, seeds, solvers
    assert prov["problem"]["sha256"] == file_sha256(problem_file)
    assert prov["backend"] == "builtin" and prov["seeds"] == {"seed": 11, "draws": 4}
    assert set(prov["solvers"]) == set(doc["results"]) and prov["solvers"]["mpc"].startswith("osqp")
    assert doc["sweep"]["count"] == 4 and doc["sweep"]["tasks"] == 2
    first4 = {c: {k: v[:4] for k, v in per.items()} for c, per in serial.samples.items()}
    # fallbacks are per-run totals: compare everything else with the serial samples
    expect = json_safe(aggregate(first4, dict.fromkeys(first4, 0)))
    for c, want in expect.items():
        got = doc["results"][c]
        assert got["fallbacks"] >= 0  # run totals: not comparable with a sub-sample
        for key, value in want.items():
            if isinstance(value, dict):
                assert got[key] == pytest.approx(value, rel=1e-12), (c, key)
            elif key != "fallbacks":
                assert got[key] == value, (c, key)
    (run_dir,) = (tmp_path / "res").iterdir()
    assert {p.name for p in run_dir.iterdir()} == {"sweep.json", "samples.csv",
                                                    "distributions.png"}
    assert json.loads((run_dir / "sweep.json").read_text()) == doc
    # the recording holds samples.csv's values: every metric, controller and scenario
    rows = np.genfromtxt(run_dir / "samples.csv", delimiter=",", names=True, dtype=None,
                         encoding="utf-8")  # fmt: skip
    recorded = pytest.importorskip("test_recording_sweep").recorded_samples(rrd, "small_sweep")
    assert set(recorded) == {*SWEEP_METRICS, "jerk_1s_over_limit_s", "collisions",
                             "aeb_activations"}  # fmt: skip
    for metric, (index, values, names) in recorded.items():
        np.testing.assert_array_equal(index, np.arange(4))
        for k, c in enumerate(names):
            want = rows[rows["controller"] == c][metric].astype(float)
            np.testing.assert_array_equal(values[:, k], want, err_msg=f"{metric} {c}")
    # next to it: the hardest scenario (smallest spacing in samples.csv), every controller on it
    from lcc_synth.experiments.sweep_review import hardest_scenario
    from lcc_synth.recording import summarize_recording

    per = {c: {k: rows[rows["controller"] == c][k].astype(float)
               for k in ("min_spacing", "collisions")} for c in doc["results"]}  # fmt: skip
    hard = hardest_scenario(per)
    second = rrd.with_name(f"sweep-scenario{hard.index}.rrd")
    assert sorted(p.name for p in rrd.parent.iterdir()) == sorted(["sweep.rrd", second.name])
    assert f"hardest scenario {hard.index}: {hard.controller}" in cap.err
    entities = summarize_recording(second).entities
    for c in doc["results"]:
        assert f"/small_sweep_scenario{hard.index}/{c}/velocity" in entities


@pytest.mark.slow  # CI runs it; by default: task_size's arithmetic (test_sweep_tasks)
def test_cli_sizes_the_tasks_for_its_workers(problem_file, serial, capsys, tmp_path):
    """Without --batch-size, 4 scenarios on 1 worker run as 4 tasks of one (the file's
    batch_size = 3 is the largest task), with the serial sweep's samples, bit for bit."""
    import json

    code = main(["sweep", str(problem_file), "--count", "4", "--workers", "1", "--json",
                 "--no-progress", "--no-record", "--no-figures", "--out", str(tmp_path)])
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert (doc["sweep"]["batch_size"], doc["sweep"]["tasks"]) == (1, 4)
    (run_dir,) = tmp_path.iterdir()
    rows = np.genfromtxt(run_dir / "samples.csv", delimiter=",", names=True, dtype=None,
                         encoding="utf-8")  # fmt: skip
    for c, per in serial.samples.items():
        for k in SWEEP_METRICS:
            np.testing.assert_array_equal(rows[rows["controller"] == c][k].astype(float),
                                          np.asarray(per[k][:4], float), err_msg=f"{c}.{k}")


def test_a_config_error_on_a_worker_is_not_retried_and_ends_as_one_line(
    problem_file, tmp_path, capsys, monkeypatch
):
    """Bad input met on a worker (here every task raises a ConfigError, as an unreadable
    fallback gains file would) is not retried: each task runs once, the sweep stops at the
    first one and the command ends with one line, exit 2 (Dask would retry a raised exception
    3 times, and a ConfigError does not even survive pickling as one)."""
    from cli_subprocess import one_line_error
    from dask.distributed import LocalCluster

    import lcc_synth.experiments.sweep as sweep_module

    calls = []

    def bad(scenario, system, tables, config, source, start, stop, ranges=None, gains=None):
        calls.append((start, stop))
        raise ConfigError("controllers.mpc.fallback_gains_file", "cannot read g.json", source)

    monkeypatch.setattr(sweep_module, "run_chunk", bad)  # the workers are threads here
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, protocol="tcp",
                      host="127.0.0.1",
                      dashboard_address="127.0.0.1:0") as cluster:  # fmt: skip
        code = main(["sweep", str(problem_file), "--scheduler", cluster.scheduler_address,
                     "--no-record", "--no-progress", "--out", str(tmp_path / "res")])
    err = capsys.readouterr().err
    assert code == 2 and one_line_error(err), err
    assert f"error: {problem_file}: controllers.mpc.fallback_gains_file: cannot read" in err
    assert 1 <= len(calls) == len(set(calls)) <= 3  # 3 tasks of <= 3 scenarios, each once
    assert list((tmp_path / "res").iterdir()) == []  # nothing finished: no results directory


def test_an_interrupted_sweep_resumes_to_the_same_results(problem_file, serial, tmp_path):
    """Stopped after its first task, written as partial files, read back and continued: the
    samples, the summary and every count (MPC fallbacks too) equal the uninterrupted run's."""
    from lcc_synth.experiments.sweep import SweepProgress
    from lcc_synth.experiments.sweep_files import ResultsWriter, read_partial

    spec = load_sweep(problem_file)  # 8 scenarios in 3 tasks
    done = SweepProgress.new(spec)

    def stop(progress):
        raise KeyboardInterrupt  # as a signal after the first finished task would

    with pytest.raises(KeyboardInterrupt):
        run_sweep(spec, client=None, progress=False, done=done, on_task=stop)
    assert list(done.tasks) == [(0, 3)]
    assert ResultsWriter(tmp_path, spec).partial(done, "interrupted by SIGINT")
    partial = read_partial(tmp_path)
    partial.check(spec, problem_file)
    again = partial.progress(spec)
    assert list(again.tasks) == [(0, 3)] and again.digests == done.digests
    res = run_sweep(spec, client=None, progress=False, done=again)
    _assert_same_samples(res.samples, serial.samples)
    assert res.summary == serial.summary and res.fallbacks == serial.fallbacks
    assert res.info["resumed_tasks"] == 1 and res.info["tasks"] == 3


def _gains_doc(n: int) -> dict:
    gains = {"s_0": 0.1, "v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}
    names = [f"{q}_{i}" for i in range(n + 1) for q in ("s", "v")]
    return {"kind": "cf_lcc", "m": 0, "n": n, "semantics": "replace", "state_names": names,
            "K": [gains.get(s, 0.0) for s in names], "gains": {s: gains.get(s, 0.0) for s in names}}


def test_gains_file_is_read_in_the_client(tmp_path, serial):
    import json

    (tmp_path / "g.json").write_text(json.dumps(_gains_doc(3)))
    text = SWEEP + '\n[controllers.from_file]\ntype = "gains_file"\nfile = "g.json"\n'
    (tmp_path / "p.toml").write_text(text)
    spec = load_sweep(tmp_path / "p.toml", count=3, controllers=["paper", "from_file"])
    res = run_sweep(spec, client=None, progress=False)
    assert res.tables["from_file"]["type"] == "static"  # plain data for remote workers
    for k in KEYS:
        np.testing.assert_array_equal(res.samples["from_file"][k], res.samples["paper"][k])
        np.testing.assert_array_equal(res.samples["paper"][k], serial.samples["paper"][k][:3])
    (tmp_path / "g.json").write_text(json.dumps(_gains_doc(4)))
    with pytest.raises(ConfigError, match="m=0, n=4"):
        run_sweep(load_sweep(tmp_path / "p.toml", count=1), client=None, progress=False)


def test_workers_drop_only_the_heartbeat_failure_record():
    """The record a worker logs (with a traceback) when its heartbeat meets a scheduler that
    a finished sweep has already stopped is dropped; the worker's other records, including
    an unexpected heartbeat error, are kept. The message is Dask's own (read from its
    source), so a change of wording in Dask fails here rather than on a user's terminal."""
    import inspect
    import logging

    from distributed.worker import Worker

    from lcc_synth.experiments import sweep_cluster

    source = inspect.getsource(Worker.heartbeat)
    assert sweep_cluster.HEARTBEAT_FAILURE in source
    import signal

    logger = logging.getLogger("distributed.worker")
    before = list(logger.filters)
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        sweep_cluster.dask_setup(None)

        def passes(msg):
            record = logger.makeRecord(logger.name, logging.ERROR, __file__, 1, msg, (), None)
            return logger.filter(record)

        assert not passes(sweep_cluster.HEARTBEAT_FAILURE + ".")
        assert passes("Unexpected exception during heartbeat. Closing worker.")
        assert passes("Compute Failed")
    finally:
        logger.filters[:] = before
        for s, handler in handlers.items():
            signal.signal(s, handler)
