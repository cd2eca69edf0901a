"""The gains files a problem names, read for its system: a ``type = "gains_file"``
controller's ``file`` and an MPC's ``fallback_gains_file``.

Paths are relative to the problem file's folder. The files are read and validated by
:func:`lcc_synth.synthesis.gains_file.read_gains` (the single-CAV form, or the platoon / ring
form with one row per CAV, both into one :class:`~lcc_synth.models.feedback.Gains`) and
checked against the problem's ``[system]``; every error names the problem file, the field
that named the gains file, the gains file and the key. ``run`` and ``sweep``
read them when they load the problem (:func:`check_gains_files`), before any design or
simulation; the controllers read them again when built.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from lcc_synth.errors import ConfigError
from lcc_synth.schema import declared

__all__ = ["check_gains_files", "gains_file_path", "read_fallback_file", "read_gains_file"]


def gains_file_path(rel: str, source: str | None) -> Path:
    """The path of a gains file named in a problem file: relative to its folder."""
    path = Path(rel)
    return path if path.is_absolute() or not source else Path(source).parent / path


def read_gains_file(
    table: Mapping[str, Any], field: str, system: Any, source: str | None = None
):
    """The gains of a ``type = "gains_file"`` table: ``(Gains, document)`` of its ``file``
    (:func:`lcc_synth.synthesis.gains_file.read_gains`, for ``system``'s layout)."""
    from lcc_synth.synthesis.gains_file import read_gains

    T = declared("controllers.NAME:gains_file")
    return read_gains(gains_file_path(T.get(table, "file", field), source), f"{field}.file",
                      source, system)  # fmt: skip


def read_fallback_file(
    table: Mapping[str, Any], field: str, system: Any, source: str | None = None
):
    """The gains of an MPC table's ``fallback_gains_file``
    (:func:`lcc_synth.synthesis.gains_file.read_gains`; for the MPC's own ``kind``): ``(gains,
    path)``, or ``None`` without one."""
    from lcc_synth.synthesis.gains_file import read_gains

    value = declared("controllers.NAME:mpc").raw(table, "fallback_gains_file")
    if value is None:
        return None
    where = f"{field}.fallback_gains_file"
    if not isinstance(value, str) or not value:
        raise ConfigError(where, f"must be the path of a gains file, got {value!r}", source)
    path = gains_file_path(value, source)
    gains, doc = read_gains(path, where, source, system)
    if doc["kind"] != system.kind:
        raise ConfigError(where, f"{path} holds gains for kind={doc['kind']!r}; the MPC "
                          f"controls kind={system.kind!r}", source)  # fmt: skip
    return gains, path


def check_gains_files(
    tables: Mapping[str, Any], system: Any, source: str | None = None
) -> None:
    """Read every gains file the controller ``tables`` name (``gains_file``, an MPC's
    ``fallback_gains_file``) for ``system``."""
    for name, table in tables.items():
        if not isinstance(table, dict):
            continue
        if table.get("type") == "gains_file" and "file" in table:
            read_gains_file(table, f"controllers.{name}", system, source)
        elif table.get("type") == "mpc":
            read_fallback_file(table, f"controllers.{name}", system, source)
