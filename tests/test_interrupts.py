"""lcc_synth.interrupts in-process: a call in a forked child gives the in-process result bit
for bit and raises its errors here; outside the command's signal handling it never forks."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from lcc_synth.errors import ConfigError, Interrupted
from lcc_synth.interrupts import call_in_child, handling, interruption_behind


def _pid_and_eig(a):
    return os.getpid(), np.linalg.eigvalsh(a)


def _fails():
    raise ConfigError("x.y", "must be > 0, got -1", "f.toml")


def test_a_child_computes_the_same_bits_and_raises_its_errors():
    rng = np.random.default_rng(3)
    a = rng.standard_normal((60, 60))
    a = a + a.T
    with handling():
        pid, w = call_in_child(_pid_and_eig, a)
        assert pid != os.getpid()  # it ran in another process
        with pytest.raises(ConfigError) as info:
            call_in_child(_fails)
    assert str(info.value) == "f.toml: x.y: must be > 0, got -1"
    np.testing.assert_array_equal(w, np.linalg.eigvalsh(a))


def test_outside_the_command_it_runs_in_process():
    """No fork outside :func:`handling`: a fork after an in-process Clarabel solve would wait
    forever for Clarabel's thread pool (module docstring)."""
    pid, _ = call_in_child(_pid_and_eig, np.eye(3))
    assert pid == os.getpid()


def _wrapped_stop(args):
    """What a numba kernel's dispatcher raises when the signal handler fires as it returns."""
    try:
        raise Interrupted(signal.SIGINT)
    except Interrupted as err:
        msg = "CPUDispatcher(<function k>) returned a result with an exception set"
        raise SystemError(msg) from err


def test_a_signal_wrapped_by_native_code_still_stops_the_command(monkeypatch, capsys):
    """CI caught ``run`` exiting 1 with a traceback: SIGINT arrived as a numba kernel returned
    and surfaced as a ``SystemError`` caused by :class:`Interrupted`. It is a stop: 130, one
    line."""
    import lcc_synth.cli.simulate as simulate
    from lcc_synth.cli.main import main

    monkeypatch.setattr(simulate, "run", _wrapped_stop)
    assert main(["simulate", "problems/paper_table2.toml"]) == 128 + signal.SIGINT
    err = capsys.readouterr().err
    assert err.strip().splitlines() == ["lcc-synth simulate: interrupted by SIGINT"]


def test_an_error_without_a_signal_behind_it_is_not_a_stop(monkeypatch):
    import lcc_synth.cli.simulate as simulate
    from lcc_synth.cli.main import main

    def fails(args):
        raise SystemError("native failure")

    assert interruption_behind(SystemError("x")) is None
    monkeypatch.setattr(simulate, "run", fails)
    with pytest.raises(SystemError, match="native failure"):
        main(["simulate", "problems/paper_table2.toml"])
