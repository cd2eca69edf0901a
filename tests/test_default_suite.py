"""Which tests a plain ``pytest`` runs: the ones marked ``slow`` are deselected, except in CI
(``CI=true``), with ``--run-slow``, with a ``-m`` expression naming ``slow``, or when named by
node id (``tests/conftest.py``). Checked by collecting, in a subprocess, a small test file
next to a copy of the real ``tests/conftest.py``; and ``.ci/run`` still runs every test."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

TESTS = """
import pytest


def test_quick():
    pass


@pytest.mark.slow
def test_long():
    pass


@pytest.mark.slow
@pytest.mark.parametrize("n", [1, 2])
def test_long_cases(n):
    pass
"""
ALL = {"test_quick", "test_long", "test_long_cases[1]", "test_long_cases[2]"}


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    root = tmp_path_factory.mktemp("suite")
    (root / "tests").mkdir()
    shutil.copy(ROOT / "tests" / "conftest.py", root / "tests" / "conftest.py")
    (root / "tests" / "test_some.py").write_text(TESTS)
    (root / "pytest.ini").write_text("[pytest]\nmarkers =\n    slow: long\n    sumo: SUMO\n")
    return root


def collected(project: Path, *args: str, ci: bool = False) -> set[str]:
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    if ci:
        env["CI"] = "true"
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider", *args],
        cwd=project, env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return set(re.findall(r"^tests/test_some\.py::(\S+)$", proc.stdout, re.M))


def test_a_plain_pytest_deselects_the_slow_tests(project):
    assert collected(project) == {"test_quick"}


@pytest.mark.parametrize("args", [(), ("--run-slow",)])
def test_ci_or_run_slow_runs_every_test(project, args):
    assert collected(project, *args, ci=not args) == ALL


@pytest.mark.slow  # the deselection itself: test_a_plain_pytest_deselects_the_slow_tests
def test_a_marker_expression_naming_slow_is_the_users_choice(project):
    assert collected(project, "-m", "slow") == ALL - {"test_quick"}
    assert collected(project, "-m", "not slow") == {"test_quick"}


@pytest.mark.slow  # the deselection itself: test_a_plain_pytest_deselects_the_slow_tests
def test_a_slow_test_named_by_node_id_runs(project):
    assert collected(project, "tests/test_some.py::test_long") == {"test_long"}
    assert collected(project, "tests/test_some.py::test_long_cases") == {
        "test_long_cases[1]", "test_long_cases[2]"
    }  # fmt: skip
    assert collected(project, "tests/test_some.py") == {"test_quick"}


def test_ci_runs_pytest_with_ci_true():
    """``.ci/run`` exports ``CI=true`` before its plain ``pytest``: CI runs the slow tests."""
    lines = (ROOT / ".ci" / "run").read_text().splitlines()
    export = next(i for i, ln in enumerate(lines) if re.match(r"export .*\bCI=true\b", ln))
    run = lines.index("pytest")
    assert export < run
    assert not any(re.match(r"(unset CI|export .*\bCI=(?!true))", ln) for ln in lines[export:run])
