"""The package's error types: bad input (:class:`ConfigError`), a file that cannot be read
or written (:class:`FileError`), and a run stopped by a signal (:class:`Interrupted`)."""

from __future__ import annotations


class ConfigError(ValueError):
    """Bad user input: a problem file, a parameter or a CLI option.

    The message always names the offending field (and the file when there is one) and what
    is allowed. The CLI turns it into a one-line message and exit code 2.

    Parameters
    ----------
    field : str
        Dotted path of the offending field, e.g. ``"hdv.alpha"`` or ``"controllers.fd.gains"``.
    message : str
        What is wrong and what is allowed.
    source : str, optional
        The file the value came from.
    """

    def __init__(self, field: str, message: str, source: str | None = None):
        self.field = field
        self.message = message
        self.source = source
        where = f"{source}: " if source else ""
        super().__init__(f"{where}{field}: {message}")

    def __reduce__(self):  # picklable (from a child process or a Dask worker)
        return (type(self), (self.field, self.message, self.source))

    def with_source(self, source: str) -> ConfigError:
        """Return the same error attributed to ``source`` (a file path)."""
        return ConfigError(self.field, self.message, source)


class FileError(OSError):
    """A file or directory that cannot be read or written while the work runs (a full disk,
    a directory made read-only meanwhile, ...): one line naming the path and the reason.

    Bad paths found *before* the work (an unwritable ``--out``, too little space for the
    estimate) are :class:`ConfigError` naming the flag (exit 2); a :class:`FileError` comes
    after work was done (exit 1), and what was computed is still printed.

    Parameters
    ----------
    path : str or path-like
        The file or directory.
    reason : str
        What went wrong (e.g. ``"No space left on device"``).
    action : str
        What was being done (``"write"``, ``"read"``...).
    """

    def __init__(self, path, reason: str, action: str = "write"):
        self.path = str(path)
        self.reason = reason
        self.action = action
        super().__init__(f"cannot {action} {self.path}: {reason}")

    def __str__(self) -> str:
        return f"cannot {self.action} {self.path}: {self.reason}"

    def __reduce__(self):
        return (type(self), (self.path, self.reason, self.action))

    @classmethod
    def from_os(cls, path, err: OSError, action: str = "write") -> FileError:
        """The :class:`FileError` of an ``OSError`` (its ``strerror``, else its text)."""
        return cls(path, err.strerror or str(err) or type(err).__name__, action)


class Interrupted(KeyboardInterrupt):
    """The run was stopped by a signal (SIGINT: Ctrl-C, or SIGTERM: what a batch scheduler
    sends); :mod:`lcc_synth.interrupts` raises it in the main thread. A subclass of
    ``KeyboardInterrupt``, so that code which finalises on Ctrl-C finalises on SIGTERM too.

    Parameters
    ----------
    signum : int
        The signal's number; the CLI exits with ``128 + signum`` (130, 143).
    """

    def __init__(self, signum: int):
        import signal

        self.signum = int(signum)
        try:
            self.signame = signal.Signals(self.signum).name
        except ValueError:  # pragma: no cover - not a known signal
            self.signame = f"signal {self.signum}"
        super().__init__(self.signame)

    def __reduce__(self):
        return (type(self), (self.signum,))


class ImplausibleValueWarning(UserWarning):
    """A value that is valid but implausible (e.g. a static gain of magnitude above 100): the
    run goes on, the warning on stderr names the field."""


def require(cond: bool, field: str, message: str) -> None:
    """Raise :class:`ConfigError` for ``field`` unless ``cond`` holds."""
    if not cond:
        raise ConfigError(field, message)
