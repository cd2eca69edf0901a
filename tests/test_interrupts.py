"""lcc_synth.interrupts in-process: a call in a forked child gives the in-process result bit
for bit and raises its errors here; outside the command's signal handling it never forks."""

from __future__ import annotations

import os

import numpy as np
import pytest

from lcc_synth.errors import ConfigError
from lcc_synth.interrupts import call_in_child, handling


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
