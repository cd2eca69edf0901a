"""How a sweep is cut into Dask tasks: :func:`lcc_synth.experiments.sweep_cluster.task_size`
(a pure function of the count, the workers and the file's largest batch) and what
``load_sweep`` makes of it; a scenario's samples do not depend on the cut
(``tests/test_sweep.py::test_chunked_sweep_equals_one_batch``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from lcc_synth.errors import ConfigError
from lcc_synth.experiments.sweep import chunks, load_sweep
from lcc_synth.experiments.sweep_cluster import TASKS_PER_WORKER, task_size


@pytest.mark.parametrize(
    "count, workers, batch, want",
    [
        (10, 2, 50, 1),  # the quick look: 10 tasks of one, both workers busy, the bar moves
        (1, 2, 50, 1),
        (16, 2, 50, 1),
        (32, 2, 50, 2),
        (100, 2, 50, 6),
        (1000, 2, 50, 50),  # large sweeps keep the file's batch
        (1000, 2, 20, 20),
        (1000, 8, 50, 15),
        (10_000_000, 256, 100_000, 4882),
    ],
)
def test_task_size(count, workers, batch, want):
    assert task_size(count, workers, batch) == want


def test_every_worker_gets_tasks_and_the_tasks_cover_the_count():
    for count in (1, 2, 7, 10, 31, 100, 999, 1000, 4321):
        for workers in (1, 2, 3, 8):
            for batch in (1, 5, 50):
                b = task_size(count, workers, batch)
                assert 1 <= b <= batch
                parts = chunks(count, b)
                assert [s for s, _ in parts] == list(range(0, count, b))
                assert parts[-1][1] == count
                # as many tasks as the count allows, up to TASKS_PER_WORKER per worker
                assert len(parts) >= min(count, workers * TASKS_PER_WORKER,
                                         -(-count // batch))  # fmt: skip


@pytest.mark.parametrize("args, field", [((0, 2, 50), "count"), ((10, 0, 50), "--workers"),
                                         ((10, 2, 0), "batch_size"), ((10, True, 5), "--workers"),
                                         ((10.0, 2, 5), "count")])  # fmt: skip
def test_task_size_refuses_bad_input(args, field):
    with pytest.raises(ConfigError) as err:
        task_size(*args)
    assert err.value.field == field


def test_load_sweep_sizes_tasks_for_the_workers_unless_the_batch_is_given():
    problem = Path(__file__).resolve().parents[1] / "problems" / "sweep_robustness.toml"
    assert load_sweep(problem).batch_size == 50  # [sweep] batch_size = 50
    assert load_sweep(problem, count=10).batch_size == 10  # no workers: the file's, capped
    assert load_sweep(problem, count=10, workers=2).batch_size == 1
    assert load_sweep(problem, count=1000, workers=2).batch_size == 50
    assert load_sweep(problem, count=200, workers=2).batch_size == 12
    assert load_sweep(problem, count=10, batch_size=4, workers=2).batch_size == 4  # as given


def test_the_run_time_estimate_reads_each_qp_solver(tmp_path):
    """The sweep's run-time estimate costs an MPC or DeeP-LCC period at its solver's measured
    figure: DAQP (the robustness file's) at MPC_DAQP_SOLVE_S / DEEPLCC_DAQP_SOLVE_S, the
    same file with OSQP at MPC_SOLVE_S / DEEPLCC_SOLVE_S."""
    from lcc_synth.experiments.sweep_estimate import (
        DEEPLCC_DAQP_SOLVE_S,
        DEEPLCC_SOLVE_S,
        MPC_DAQP_SOLVE_S,
        MPC_SOLVE_S,
        estimate_sweep,
    )

    problem = Path(__file__).resolve().parents[1] / "problems" / "sweep_robustness.toml"
    osqp = tmp_path / "osqp.toml"
    osqp.write_text(problem.read_text().replace('solver = { method = "daqp" }\n', ""))
    names = ["mpc", "mpc_delay", "deep_lcc"]
    exact = estimate_sweep(load_sweep(problem, count=10, controllers=names), 2).per_scenario
    admm = estimate_sweep(load_sweep(osqp, count=10, controllers=names), 2).per_scenario
    for name, (daqp_s, osqp_s) in {"mpc": (MPC_DAQP_SOLVE_S, MPC_SOLVE_S),
                                   "mpc_delay": (MPC_DAQP_SOLVE_S, MPC_SOLVE_S),
                                   "deep_lcc": (DEEPLCC_DAQP_SOLVE_S, DEEPLCC_SOLVE_S)}.items():
        assert exact[name] / admm[name] == pytest.approx(daqp_s / osqp_s, rel=1e-12), name
        assert exact[name] < admm[name]
