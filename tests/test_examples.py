"""Every script under ``examples/`` writes under one ``--out`` directory and prints each path.

Each script runs as a user would (a subprocess, from an empty working directory) with
``--out`` set to a temporary directory; the test checks that every ``wrote PATH`` line names an
existing file inside it, that every file inside it was printed, and that nothing was written
anywhere else (the working directory, the repository). All of them take under 30 s here
(3-6 s each); ``fig7_fig8_regions.py`` runs with ``--step 0.5`` (its default, the paper's grid
of 1001 x 1001 points per map, is far longer).
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"

#: Each example with the arguments of the run tested here (besides ``--out``).
RUNS = {
    "fig5_control_energy.py": ["--n-max", "8"],  # the default 30 takes minutes (multiprecision)
    "fig7_fig8_regions.py": ["--step", "0.5"],
    "fig9_frequency_response.py": [],
    "fig10_fig12_sec5a_profiles.py": [],
    "fig11_snapshots.py": [],
    "fig11_snapshots.py --appendix-c": ["--appendix-c"],
    "mpc_head_brake.py": [],
    "showcase.py": [],
    "sparsity_pareto.py": [],
    "synthesis_vs_paper.py": [],
    "synthesis_vs_paper.py --json": ["--json"],
    "table2.py": [],
    "paper_walkthrough.py": [],
    "ring_sugiyama.py": ["--controllers", "all_hdv,follower_stopper,h2"],  # the MPC takes 80 s
    "as_run_front.py": ["--starts", "1", "--maxfev", "30", "--cert-starts", "2"],  # default: min
}


def _repository_files() -> set[Path]:
    skip = {".git", "__pycache__", ".pytest_cache", ".ruff_cache"}
    return {
        p for p in ROOT.rglob("*")
        if p.is_file() and not skip.intersection(p.relative_to(ROOT).parts)
    }  # fmt: skip


def test_the_documentation_runs_the_examples_with_these_arguments():
    """The gallery's quick arguments (``docs/_ext/lcc_docs.py``, ``EXAMPLE_ARGS``) are the ones
    of a run tested here."""
    ext = str(ROOT / "docs" / "_ext")
    sys.path.insert(0, ext)
    try:
        lcc_docs = importlib.import_module("lcc_docs")
    finally:
        sys.path.remove(ext)
    assert lcc_docs.EXAMPLE_ARGS
    for name, args in lcc_docs.EXAMPLE_ARGS.items():
        assert RUNS[name] == args, name


def test_every_example_is_run_here():
    scripts = {p.name for p in EXAMPLES.glob("*.py")}
    listed = {key.split()[0] for key in RUNS}
    assert scripts <= listed, f"add {sorted(scripts - listed)} to RUNS"


#: Slow (deselected by a plain ``pytest``, run in CI): the longest runs. The quick ones left
#: check the same ``--out`` handling (``lcc_synth.cli.arguments.add_example_out``), and the
#: documentation build runs every example.
SLOW = {"fig5_control_energy.py", "fig7_fig8_regions.py", "fig9_frequency_response.py",
        "fig10_fig12_sec5a_profiles.py", "fig11_snapshots.py", "fig11_snapshots.py --appendix-c",
        "mpc_head_brake.py", "showcase.py", "paper_walkthrough.py", "ring_sugiyama.py",
        "synthesis_vs_paper.py --json", "as_run_front.py", "synthesis_vs_paper.py",
        "sparsity_pareto.py"}  # fmt: skip


@pytest.mark.parametrize(
    "key", [pytest.param(k, marks=pytest.mark.slow) if k in SLOW else k for k in RUNS]
)
def test_example_writes_only_under_out_and_prints_each_path(key, tmp_path):
    script = EXAMPLES / key.split()[0]
    if not script.is_file():
        pytest.skip(f"{script.name} is not in this checkout")
    cwd, out = tmp_path / "cwd", tmp_path / "out"
    cwd.mkdir()
    before = _repository_files()
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg", "RERUN_ANALYTICS": "0",
           "PYTHONDONTWRITEBYTECODE": "1"}  # fmt: skip
    proc = subprocess.run(
        [sys.executable, str(script), *RUNS[key], "--out", str(out)],
        cwd=cwd, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    if "--json" in RUNS[key]:
        json.loads(proc.stdout)  # stdout holds the JSON object alone
    printed = [
        Path(line.removeprefix("wrote ").strip())
        for line in (proc.stdout + proc.stderr).splitlines()
        if line.startswith("wrote ")
    ]
    assert printed, proc.stdout[-2000:]
    for path in printed:
        assert path.is_file() and path.stat().st_size > 0, path
        assert path.resolve().is_relative_to(out.resolve()), path
    written = {p.resolve() for p in out.rglob("*") if p.is_file()}
    assert written == {p.resolve() for p in printed}  # each file it wrote, printed
    assert list(cwd.iterdir()) == []
    assert _repository_files() == before
