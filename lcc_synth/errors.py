"""The package's one error type for bad input."""

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

    def with_source(self, source: str) -> ConfigError:
        """Return the same error attributed to ``source`` (a file path)."""
        return ConfigError(self.field, self.message, source)


class ImplausibleValueWarning(UserWarning):
    """A value that is valid but implausible (e.g. a static gain of magnitude above 100): the
    run goes on, the warning on stderr names the field."""


def require(cond: bool, field: str, message: str) -> None:
    """Raise :class:`ConfigError` for ``field`` unless ``cond`` holds."""
    if not cond:
        raise ConfigError(field, message)
