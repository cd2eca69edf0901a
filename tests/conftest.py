"""Test-session set-up: the ``slow`` and ``sumo`` markers, and DeeP-LCC's data cache kept out
of the repository.

**Slow checks.** A test marked ``@pytest.mark.slow`` repeats, at greater length, what a faster
test already checks (a whole default run, every signal, a long scenario). A plain ``pytest``
deselects them, so that the default suite stays within a few minutes of CPU on two cores; they
run in CI (``CI=true``, as ``.ci/run`` sets it), with ``pytest --run-slow``, with a ``-m``
expression naming ``slow`` (``pytest -m slow`` runs only them), or when a test is named by its
node id (``pytest tests/test_x.py::test_y``).

**SUMO.** A test marked ``@pytest.mark.sumo`` needs libsumo (the ``sumo`` extra): it is
skipped when libsumo is not importable, except in CI (``CI=true``), where it runs and a
missing SUMO fails (:func:`have_sumo`, checked by ``tests/test_sumo.py``).

**DeeP-LCC's data cache.**
Problem files name the cache relative to the working directory (``results/deeplcc`` by
default); during the tests a cache directory that would land inside the repository is
redirected into one temporary directory of the session (a test that changes to its own
directory, or names an absolute one, is left alone). The data are still cached and reused
within the session.

**One simulated head brake.** :func:`mpc_head_brake_run`: ``lcc-synth simulate
problems/mpc_head_brake.toml --json --rrd`` run once per session in a subprocess, for the
tests that read its JSON or its recording (they only read them).
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
from dataclasses import replace
from pathlib import Path

import pytest

IN_CI = os.environ.get("CI", "").lower() == "true"


def have_sumo() -> bool:
    """Is libsumo importable? (Its import prints a banner: silenced.)"""
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            import libsumo  # noqa: F401
    except ImportError:
        return False
    return True


def pytest_addoption(parser):
    parser.addoption("--run-slow", action="store_true", default=False,
                     help="also run the tests marked slow (deselected by default, except "
                          "in CI: CI=true)")  # fmt: skip


def pytest_configure(config):
    config.addinivalue_line("markers", 'sumo: needs libsumo (pip install -e ".[sumo]"); '
                            "skipped without it, except in CI")  # fmt: skip


def runs_slow_tests(config) -> bool:
    """Do the tests marked ``slow`` run in this session? In CI, with ``--run-slow``, or with a
    ``-m`` expression that names ``slow`` (the user chose)."""
    return IN_CI or config.getoption("--run-slow") or "slow" in (config.option.markexpr or "")


def _named_node_ids(config) -> list[str]:
    """The node ids given on the command line (``tests/test_x.py::test_y``), rootdir-relative."""
    out = []
    for arg in config.args:
        path, sep, rest = arg.partition("::")
        if sep:
            rel = Path(os.path.relpath(Path(path).resolve(), config.rootpath)).as_posix()
            out.append(f"{rel}::{rest}")
    return out


def _deselect_slow(config, items) -> None:
    if runs_slow_tests(config):
        return
    named = _named_node_ids(config)

    def chosen(item) -> bool:
        return any(item.nodeid == n or item.nodeid.startswith((n + "[", n + "::")) for n in named)

    slow = [item for item in items if "slow" in item.keywords and not chosen(item)]
    if slow:
        config.hook.pytest_deselected(items=slow)
        dropped = set(slow)
        items[:] = [item for item in items if item not in dropped]


def pytest_collection_modifyitems(config, items):
    _deselect_slow(config, items)
    if IN_CI or have_sumo():
        return
    skip = pytest.mark.skip(reason='SUMO not installed (pip install -e ".[sumo]")')
    for item in items:
        if "sumo" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session", autouse=True)
def _deeplcc_cache_outside_the_repository(tmp_path_factory):
    import lcc_synth.deeplcc.build as build
    import lcc_synth.deeplcc.data as data

    root = tmp_path_factory.mktemp("deeplcc_cache")
    repo = Path(__file__).resolve().parents[1]
    original = data.load_or_collect

    @functools.wraps(original)  # the package's docstring checks see the real function's
    def load_or_collect(base, settings):
        where = (Path.cwd() / settings.cache_dir).resolve()
        if where.is_relative_to(repo):
            settings = replace(settings, cache_dir=str(root / where.relative_to(repo)))
        return original(base, settings)

    mp = pytest.MonkeyPatch()
    mp.setattr(data, "load_or_collect", load_or_collect)
    mp.setattr(build, "load_or_collect", load_or_collect)
    yield root
    mp.undo()


@pytest.fixture(scope="session")
def mpc_head_brake_run(tmp_path_factory):
    """``(JSON document, recording path)`` of ``lcc-synth simulate
    problems/mpc_head_brake.toml --json --rrd`` (the real CLI in a subprocess), run once."""
    import json

    from cli_subprocess import PROBLEMS, run_cli

    tmp = tmp_path_factory.mktemp("mpc_head_brake")
    rrd = tmp / "hb.rrd"
    proc = run_cli(["simulate", PROBLEMS / "mpc_head_brake.toml", "--json", "--rrd", rrd],
                   cwd=tmp)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout), rrd
