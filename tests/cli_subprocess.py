"""The real ``lcc-synth`` command in a subprocess, for the tests of failure paths, and the
problem text the tests share.

``run_cli`` runs it to the end; ``start_cli`` starts it and returns the ``Popen`` (to send a
signal at a chosen moment). Both run the installed console script (``lcc-synth``), the way a
user does, from a working directory of the test's choosing, with Rerun's analytics off and a
non-interactive matplotlib (:func:`cli_env`, unless the test passes its own environment); the
package they import is always this checkout's (its root first on ``PYTHONPATH``, also in an
environment the test passes), never another worktree's installed one.

``PAPER_HDV`` is the ``[hdv]`` table of the paper's OVM drivers that the tests' short problem
files start from.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PROBLEMS = REPO / "problems"

#: The paper's OVM drivers (Sec. V: alpha = 0.6, beta = 0.9, s_st = 5 m, s_go = 35 m,
#: v_max = 30 m/s) as a problem file's ``[hdv]`` table.
PAPER_HDV = """[hdv]
model = "ovm"
alpha = 0.6
beta = 0.9
s_st = 5.0
s_go = 35.0
v_max = 30.0
"""


def cli_command() -> list[str]:
    """The console script next to this interpreter (the venv's), else ``python -m``."""
    script = Path(sys.executable).with_name("lcc-synth")
    if script.is_file():
        return [str(script)]
    found = shutil.which("lcc-synth")
    if found:
        return [found]
    return [sys.executable, "-m", "lcc_synth.cli.main"]


def cli_env(**extra: str) -> dict[str, str]:
    """This process's environment with Rerun's analytics off, matplotlib non-interactive,
    unbuffered output, then ``extra``."""
    env = dict(os.environ)
    env.update(RERUN_ANALYTICS="0", MPLBACKEND="Agg", PYTHONUNBUFFERED="1")
    env.update(extra)
    return env


def _this_checkout(env: dict[str, str]) -> dict[str, str]:
    """``env`` with this checkout's root first on ``PYTHONPATH``."""
    rest = [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p and p != str(REPO)]
    return {**env, "PYTHONPATH": os.pathsep.join([str(REPO), *rest])}


def run_cli(
    args: Sequence[str], cwd: str | Path, timeout: float = 300, env: dict | None = None,
    preexec_fn: Callable[[], None] | None = None,
) -> subprocess.CompletedProcess:  # fmt: skip
    """``lcc-synth ARGS`` to the end; text output captured."""
    return subprocess.run(
        [*cli_command(), *map(str, args)], cwd=cwd, env=_this_checkout(env or cli_env()),
        capture_output=True, text=True, timeout=timeout, preexec_fn=preexec_fn,
    )  # fmt: skip


def start_cli(
    args: Sequence[str], cwd: str | Path, env: dict | None = None,
    preexec_fn: Callable[[], None] | None = None,
) -> subprocess.Popen:  # fmt: skip
    """``lcc-synth ARGS`` started (stdout and stderr piped, text)."""
    return subprocess.Popen(
        [*cli_command(), *map(str, args)], cwd=cwd, env=_this_checkout(env or cli_env()),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=preexec_fn,
    )  # fmt: skip


def wait_for(predicate: Callable[[], bool], timeout: float, poll: float = 0.01) -> bool:
    """Poll ``predicate`` until it holds (True) or ``timeout`` seconds pass (False)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(poll)
    return predicate()


def one_line_error(stderr: str) -> bool:
    """Does ``stderr`` end with exactly one ``lcc-synth ...: error: ...`` line and hold no
    traceback?"""
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ": error: " in ln]
    return "Traceback" not in stderr and len(errors) == 1 and lines[-1] == errors[0]


def rerun_binary() -> str:
    """The ``rerun`` command of this environment (for ``rerun rrd verify``)."""
    script = Path(sys.executable).with_name("rerun")
    return str(script) if script.is_file() else "rerun"


def rrd_verifies(path: str | Path) -> bool:
    """Does ``rerun rrd verify PATH`` accept the file (complete, footer included)?"""
    proc = subprocess.run(
        [rerun_binary(), "rrd", "verify", str(path)], capture_output=True, text=True,
        timeout=120, env=cli_env(CI="1"),
    )  # fmt: skip
    return proc.returncode == 0


@contextlib.contextmanager
def tmpfs(where: Path, options: str) -> Iterator[Path]:
    """A fresh ``tmpfs`` mounted on the directory ``where`` (created) with ``options`` (e.g.
    ``"size=8m"``, ``"ro,size=1m"``): a small disk that can be filled, or a read-only one.
    Skips the test where this machine does not allow it (not root, no ``mount``); unmounted
    afterwards."""
    import pytest

    where.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a tmpfs needs root and mount(8)")
    proc = subprocess.run(["mount", "-t", "tmpfs", "-o", options, f"lcc-{uuid.uuid4().hex[:6]}",
                           str(where)], capture_output=True, text=True)  # fmt: skip
    if proc.returncode != 0:
        pytest.skip(f"mount -t tmpfs not permitted here: {proc.stderr.strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], capture_output=True)


def stop_fill_continue(proc: subprocess.Popen, disk: Path, appeared: Callable[[], bool]) -> None:
    """Stop ``proc`` (SIGSTOP) once ``appeared()``, :func:`fill` ``disk``, let it go on
    (SIGCONT): a disk that fills while the command writes."""
    assert wait_for(lambda: appeared() or proc.poll() is not None, 120, poll=0.001)
    assert proc.poll() is None, "the command ended before its output appeared"
    os.kill(proc.pid, signal.SIGSTOP)
    try:
        fill(disk)
    finally:
        os.kill(proc.pid, signal.SIGCONT)


def fill(directory: str | Path) -> None:
    """Fill the file system of ``directory`` to the last byte (one file, written until ENOSPC)."""
    block = b"\0" * (1 << 16)
    with open(Path(directory) / "filler", "wb", buffering=0) as fh:
        try:
            while True:
                fh.write(block)
        except OSError:
            pass
        try:  # the last partial block
            while True:
                fh.write(b"\0" * 512)
        except OSError:
            pass
