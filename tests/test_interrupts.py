"""lcc_synth.interrupts in-process: a call in a forked child gives the in-process result bit
for bit and raises its errors here; outside the command's signal handling it never forks."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from lcc_synth.errors import ConfigError, Interrupted
from lcc_synth.interrupts import (
    call_in_child,
    checkpoint,
    deliver,
    handling,
    interrupted,
    interruption_behind,
)


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


@pytest.fixture
def signal_on_casadi_shape(monkeypatch):
    """SIGTERM to this process the first time CasADi reads an ``MX``'s ``.shape``, which its
    SWIG wrappers do while choosing an overload; the watchdog that would end the process after
    the deadline is disabled. Yields the list of signals sent."""
    import casadi as ca

    import lcc_synth.interrupts as interrupts

    monkeypatch.setattr(interrupts, "_watchdog", lambda signum: None)
    shape = ca.MX.shape
    sent: list[int] = []

    def sneaky(self):
        if not sent:
            sent.append(signal.SIGTERM)
            os.kill(os.getpid(), signal.SIGTERM)  # the handler runs before the next bytecode
        return shape.fget(self)

    monkeypatch.setattr(ca.MX, "shape", property(sneaky))
    return sent


def test_casadi_drops_a_signal_and_the_next_checkpoint_raises_it(signal_on_casadi_shape):
    """The cause of a CI failure: SIGTERM during the MPC's symbolic set-up was swallowed and
    ``run`` worked on until the clean-up deadline. CasADi clears the handler's exception (the
    product is computed as if nothing happened); :func:`checkpoint` raises it again."""
    import casadi as ca

    x = ca.MX.sym("x", 2, 2)
    with handling():
        y = x @ x  # the signal's exception is raised inside, and dropped by CasADi
        assert signal_on_casadi_shape == [signal.SIGTERM]
        assert y.shape == (2, 2) and interrupted() == signal.SIGTERM
        with pytest.raises(Interrupted) as info:
            checkpoint()
    assert info.value.signum == signal.SIGTERM


def test_a_signal_during_the_mpc_set_up_stops_it(signal_on_casadi_shape):
    import lcc_synth as lcc

    system = lcc.system("cf_lcc", n=4)
    with handling(), pytest.raises(Interrupted):
        lcc.mpc(system, horizon=20, n_model=4)
    assert signal_on_casadi_shape == [signal.SIGTERM]


def test_checkpoint_is_quiet_without_a_signal_and_in_the_clean_up(monkeypatch):
    """No signal: nothing. Once the signal's exception is being handled (an ``except`` or a
    ``finally`` it unwinds through, and what they call), the clean-up is not interrupted
    again; outside :func:`handling` nothing either."""
    import lcc_synth.interrupts as interrupts

    monkeypatch.setattr(interrupts, "_watchdog", lambda signum: None)
    checkpoint()
    cleaned: list[str] = []
    with handling():
        checkpoint()
        try:
            try:
                deliver(signal.SIGINT)
            finally:
                checkpoint()  # the finally of a block the exception unwinds through
                cleaned.append("finally")
        except Interrupted:
            checkpoint()  # the handler's own clean-up
            cleaned.append("except")
        with pytest.raises(Interrupted):
            checkpoint()  # after the handler: work again, and the signal still stands
    checkpoint()  # outside handling(): the API never raises on its own
    assert cleaned == ["finally", "except"]
