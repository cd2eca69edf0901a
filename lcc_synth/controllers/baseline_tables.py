"""``baseline_from_table``: a baseline controller (:mod:`lcc_synth.controllers.baselines`) from
its ``[controllers.NAME]`` problem table, every key read through the schema."""

from __future__ import annotations

from dataclasses import fields

from lcc_synth.controllers.baselines import BASELINE_TYPES, BaselineController
from lcc_synth.errors import ConfigError
from lcc_synth.schema import declared

__all__ = ["baseline_from_table"]


def baseline_from_table(name: str, kind: str, table) -> BaselineController:
    """The controller of a ``[controllers.NAME]`` table with ``type = kind`` (one of
    :data:`BASELINE_TYPES`); a bad value is a ConfigError naming ``controllers.NAME.key``."""
    field = f"controllers.{name}"
    T = declared(f"controllers.NAME:{kind}")
    T.check(table, field)
    cls = BASELINE_TYPES[kind]
    kwargs = {}
    for f in fields(cls):
        value = T.get(table, f.name, field)
        kwargs[f.name] = tuple(value) if isinstance(value, list) else value
    try:
        params = cls(**kwargs)
        return BaselineController(name, kind, params, T.get(table, "sample_time", field),
                                  T.get(table, "length", field))  # fmt: skip
    except ConfigError as err:
        raise ConfigError(f"{field}.{err.field}", err.message) from None
