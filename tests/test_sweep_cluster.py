"""A sweep on a Dask cluster the sweep did not start: `dask scheduler` and two `dask worker`
processes on 127.0.0.1 (single-threaded, as docs/guide/sweeps.md advises), started and stopped
by PID.

The independent truth is the same sweep run task by task in this process (``client=None``):
each scenario's draws come from (seed, index) only, so the cluster's samples must equal it bit
for bit — also when a worker (its nanny and its process together, as when a machine goes away)
is killed while it holds tasks: Dask recomputes them on the other worker.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from cli_subprocess import PROBLEMS, run_cli

from lcc_synth.experiments.sweep import load_sweep, run_sweep

DASK = Path(sys.executable).parent / "dask"

#: Slow (deselected by a plain ``pytest``, run in CI): the sweep on a local Dask cluster equals
#: the serial one in tests/test_sweep.py::test_local_cluster_equals_serial.
pytestmark = [
    pytest.mark.skipif(not DASK.exists(), reason="the dask command is not installed"),
    pytest.mark.slow,
]

# the robustness sweep, small: the static controllers and the MPC (so that a task lasts long
# enough to lose a worker in the middle of it)
SWEEP = """
[sweep]
count = 8
batch_size = 1
[controllers.all_hdv]
type = "hdv"
[controllers.paper]
type = "static"
kind = "cf_lcc"
semantics = "replace"
gains = { s_0 = 0.1, v_0 = -0.5, s_1 = -0.2, v_1 = 0.05, s_2 = -0.1, v_2 = 0.05 }
[controllers.mpc]
type = "mpc"
"""


def _problem(tmp: Path) -> Path:
    text = (PROBLEMS / "sweep_robustness.toml").read_text()
    head = text[: text.index("[sweep]")].replace("duration = 40.0", "duration = 20.0")
    head = head.replace("window = [5.0, 40.0]", "window = [5.0, 20.0]")
    path = tmp / "sweep_small.toml"
    path.write_text(head + SWEEP)
    return path


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start(args: list[str], tmp: Path, tag: str) -> subprocess.Popen:
    log = open(tmp / f"{tag}.log", "w")  # noqa: SIM115 - closed with the process
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.Popen(
        [str(DASK), *args], stdout=log, stderr=subprocess.STDOUT, cwd=tmp, env=env,
        start_new_session=True,  # its own process group: nanny and worker are stopped together
    )  # fmt: skip


def _stop(proc: subprocess.Popen, sig=signal.SIGTERM) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, sig)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=20)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """(address, {worker name: Popen}) of a scheduler and two workers started here."""
    from dask.distributed import Client

    tmp = tmp_path_factory.mktemp("dask")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    sched = _start(["scheduler", "--host", "127.0.0.1", "--port", str(port),
                    "--no-dashboard"], tmp, "scheduler")  # fmt: skip
    workers = {
        name: _start(["worker", address, "--nthreads", "1", "--nworkers", "1", "--name", name,
                      "--no-dashboard", "--local-directory", str(tmp / name)], tmp, name)
        for name in ("w0", "w1")
    }  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                with Client(address, timeout="5s") as c:
                    c.wait_for_workers(2, timeout=max(1.0, deadline - time.monotonic()))
                break
            except OSError:
                if time.monotonic() > deadline or sched.poll() is not None:
                    raise
                time.sleep(0.5)
        yield address, workers
    finally:
        for proc in (*workers.values(), sched):
            _stop(proc)
        assert all(p.poll() is not None for p in (*workers.values(), sched))


@pytest.fixture(scope="module")
def local(tmp_path_factory):
    """The same sweep, task by task in this process."""
    path = _problem(tmp_path_factory.mktemp("local"))
    return path, run_sweep(load_sweep(path), client=None, progress=False)


def _same(a, b) -> None:
    assert list(a.samples) == list(b.samples)
    for c in a.samples:
        for k in a.samples[c]:
            np.testing.assert_array_equal(a.samples[c][k], b.samples[c][k], err_msg=f"{c}.{k}")


def test_cli_sweep_on_an_external_cluster_equals_the_local_run(cluster, local, tmp_path):
    address, _ = cluster
    path, ref = local
    out = run_cli(["sweep", path, "--scheduler", address, "--json", "--no-figures",
                   "--no-progress", "--out", tmp_path / "res"], cwd=tmp_path, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    doc = json.loads(out.stdout)
    assert doc["sweep"]["scheduler"] == address and doc["sweep"]["tasks"] == 8
    samples = Path(next((tmp_path / "res").glob("*/samples.csv")))
    got = np.genfromtxt(samples, delimiter=",", names=True, dtype=None, encoding="utf-8")
    for c in ref.samples:
        rows = got[got["controller"] == c]
        common = [k for k in ref.samples[c] if k in got.dtype.names]
        assert {"aave", "collisions"} <= set(common)
        for k in common:
            np.testing.assert_array_equal(rows[k], ref.samples[c][k], err_msg=f"{c}.{k}")


def test_a_lost_worker_costs_time_not_results(cluster, local):
    from dask.distributed import Client

    address, workers = cluster
    path, ref = local
    spec = load_sweep(path)
    with Client(address, timeout="10s") as client:
        info = client.scheduler_info()["workers"]
        victim = next(a for a, w in info.items() if w["name"] == "w0")
        import threading

        box = {}
        t = threading.Thread(target=lambda: box.setdefault("r", run_sweep(spec, client, False)))
        t.start()
        deadline = time.monotonic() + 120
        while not client.processing().get(victim) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert client.processing().get(victim), "w0 never received a task"
        _stop(workers["w0"], signal.SIGKILL)  # the machine goes away mid-task
        t.join(timeout=600)
        assert not t.is_alive() and "r" in box
        assert len(client.scheduler_info()["workers"]) == 1
    _same(box["r"], ref)
