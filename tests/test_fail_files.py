"""Issue 28, row 10: a user file that cannot be read is one line naming it, never a traceback.

Every file the package reads from a user (the problem file, a gains file named by
``[controllers.NAME] file`` or an MPC's ``fallback_gains_file``, a perturbation's CSV) goes
through :func:`lcc_synth.schema.readers.read_file`: a binary, UTF-16 or deeply nested file, a
gain whose use would overflow, a file without read permission all end with exit code 2 and one
``lcc-synth simulate: error: ...`` line naming the file (and the field that named it).

Each case runs the real ``lcc-synth`` in a subprocess, from a temporary working directory.
Root reads files of mode 000, so those cases run the command without any capability (its
capability bounding set dropped before ``exec``: uid 0 is then subject to the permission bits
like any user; as a normal user nothing is changed); they are skipped where that is impossible.
"""

from __future__ import annotations

import ctypes
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from cli_subprocess import PROBLEMS, one_line_error, run_cli

from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import model_from_hdv

#: The base problem: Table II (fd_lcc, m = 0, n = 10), which reads nothing else.
BASE = (PROBLEMS / "paper_table2.toml").read_text()
NAMES = list(model_from_hdv("fd_lcc", 0, 10, OVM(), 15.0, warn=False).state_names)
GAINS = {"v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}


def gains_doc(**change) -> dict:
    """A valid gains file for the base problem (the form of ``lcc-synth synthesize --out``)."""
    doc = {"kind": "fd_lcc", "m": 0, "n": 10, "semantics": "replace", "state_names": NAMES,
           "K": [GAINS.get(n, 0.0) for n in NAMES], "gains": dict(GAINS)}  # fmt: skip
    doc.update(change)
    return doc


def problem(tmp: Path, extra: str, name: str = "p.toml") -> Path:
    """The base problem plus ``extra`` (its brake 200 s long is fine: nothing runs)."""
    path = tmp / name
    path.write_text(BASE + "\n" + extra + "\n")
    return path


def gains_file_problem(tmp: Path, gains: str | bytes, name: str = "g.json") -> Path:
    """The base problem with a ``gains_file`` controller ``gf`` reading ``name``."""
    target = tmp / name
    target.write_bytes(gains if isinstance(gains, bytes) else gains.encode())
    return problem(tmp, f'[controllers.gf]\ntype = "gains_file"\nfile = "{name}"')


def last_line(proc: subprocess.CompletedProcess) -> str:
    return [ln for ln in proc.stderr.splitlines() if ln.strip()][-1]


def fails_naming(proc: subprocess.CompletedProcess, *parts: str) -> str:
    """Exit 2, one error line and no traceback, naming every one of ``parts``."""
    assert proc.returncode == 2, proc.stderr
    assert one_line_error(proc.stderr), proc.stderr
    line = last_line(proc)
    for part in parts:
        assert part in line, (part, line)
    return line


def simulate(tmp: Path, path: Path, preexec=None) -> subprocess.CompletedProcess:
    return run_cli(["simulate", path.name, "--no-record"], cwd=tmp, timeout=120,
                   preexec_fn=preexec)  # fmt: skip


# --------------------------------------------------------------------------------------------
# contents that are not a gains file
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "case, contents, reason",
    [
        ("binary", bytes(range(256)) * 8, "not a UTF-8 text file (byte 128): a binary file?"),
        ("utf16", json.dumps(gains_doc()).encode("utf-16"), "is UTF-16 text"),
        ("nested", "[" * 100_000, "nested too deeply"),
    ],
)
def test_gains_file_that_is_no_text_or_too_deep(case, contents, reason, tmp_path):
    path = gains_file_problem(tmp_path, contents)
    line = fails_naming(simulate(tmp_path, path), "p.toml: controllers.gf.file: g.json: ", reason)
    assert "Traceback" not in line


def test_mpc_fallback_gains_file_in_utf16(tmp_path):
    (tmp_path / "fb.json").write_bytes(json.dumps(gains_doc()).encode("utf-16"))
    path = problem(tmp_path, '[controllers.mpc]\ntype = "mpc"\nfallback_gains_file = "fb.json"')
    fails_naming(simulate(tmp_path, path),
                 "p.toml: controllers.mpc.fallback_gains_file: fb.json: ", "UTF-16")  # fmt: skip


def test_a_gain_whose_use_overflows_is_refused_with_its_range(tmp_path):
    """-1e300 used to overflow in the time-step check (OverflowError): now refused where it is
    read, naming the entry and the allowed range; a TOML gain as well as a gains file's."""
    doc = gains_doc(K=[-1e300 if n == "v_0" else GAINS.get(n, 0.0) for n in NAMES],
                    gains={**GAINS, "v_0": -1e300})  # fmt: skip
    path = gains_file_problem(tmp_path, json.dumps(doc))
    line = fails_naming(simulate(tmp_path, path), "controllers.gf.file: g.json: ",
                        "(v_0)", "must be in [-1e+12, 1e+12]", "got -1e+300")  # fmt: skip
    assert "OverflowError" not in line
    text = re.sub(r"gains = \{ v_0 = -0.5,", "gains = { v_0 = -1e300,", BASE, count=1)
    assert text != BASE
    (tmp_path / "q.toml").write_text(text)
    proc = run_cli(["simulate", "q.toml", "--no-record"], cwd=tmp_path, timeout=120)
    fails_naming(proc, "q.toml: controllers.fd_lcc.gains.v_0: must be in [-1e+12, 1e+12]")


# --------------------------------------------------------------------------------------------
# files without read permission
# --------------------------------------------------------------------------------------------

_PR_CAPBSET_DROP = 24


def _drop_capabilities() -> None:  # pragma: no cover - runs in the child before exec
    libc = ctypes.CDLL(None, use_errno=True)
    for cap in range(64):
        libc.prctl(_PR_CAPBSET_DROP, cap, 0, 0, 0)


@pytest.fixture(scope="module")
def unprivileged(tmp_path_factory):
    """A ``preexec_fn`` under which mode 000 stops reads (``None`` for a normal user)."""
    if os.geteuid() != 0:
        return None
    tmp = tmp_path_factory.mktemp("probe")
    probe = tmp / "secret"
    probe.write_text("x")
    probe.chmod(0)
    try:
        proc = subprocess.run([sys.executable, "-c", f"open({str(probe)!r}).read()"],
                              preexec_fn=_drop_capabilities, capture_output=True, text=True,
                              timeout=60)  # fmt: skip
    except (OSError, subprocess.SubprocessError) as err:
        pytest.skip(f"cannot run a command without privileges here: {err}")
    if "PermissionError" not in proc.stderr:
        pytest.skip("running as root and dropping the capabilities does not stop reads here")
    return _drop_capabilities


def _unreadable(path: Path) -> Path:
    path.chmod(0)
    return path


def test_unreadable_problem_file(tmp_path, unprivileged):
    path = _unreadable(problem(tmp_path, ""))
    fails_naming(simulate(tmp_path, path, unprivileged),
                 "p.toml: path: cannot read the problem file: Permission denied")  # fmt: skip


def test_unreadable_gains_file(tmp_path, unprivileged):
    path = gains_file_problem(tmp_path, json.dumps(gains_doc()))
    assert simulate(tmp_path, path, unprivileged).returncode == 0  # readable: it runs
    _unreadable(tmp_path / "g.json")
    fails_naming(simulate(tmp_path, path, unprivileged),
                 "p.toml: controllers.gf.file: g.json: cannot read the gains file: Permission "
                 "denied")  # fmt: skip


def test_unreadable_csv_file(tmp_path, unprivileged):
    (tmp_path / "speed.csv").write_text("t,v\n20,15\n25,14\n30,15\n")
    path = problem(tmp_path, '[[scenario.perturbations]]\ntype = "speed_profile"\n'
                   'vehicle = "head"\ncsv = "speed.csv"')  # fmt: skip
    _unreadable(tmp_path / "speed.csv")
    fails_naming(simulate(tmp_path, path, unprivileged),
                 "p.toml: scenario.perturbations[1].csv: speed.csv: cannot read the CSV file: "
                 "Permission denied")  # fmt: skip
