"""Reading recordings back (``lcc-synth review --summary``, tests) and the Rerun processes
we start (the viewer binary, its environment with analytics off)."""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lcc_synth.errors import ConfigError


def rerun_binary() -> Path:
    """The Rerun viewer/CLI executable shipped in the ``rerun-sdk`` wheel (not the Python
    ``rerun`` wrapper script, so that stopping it stops the viewer itself)."""
    import rerun_cli

    base = Path(rerun_cli.__file__).parent
    for cand in (
        base / "rerun",
        base / "rerun.exe",
        base / "Rerun.app" / "Contents" / "MacOS" / "Rerun",
    ):
        if cand.exists():
            return cand
    raise ConfigError(
        "rerun", f"the Rerun viewer binary is missing from {base} (reinstall rerun-sdk)"
    )


def viewer_environment(base: Mapping[str, str] | None = None) -> dict[str, str]:
    """Environment for Rerun processes we start: analytics off (``CI=1``, see module doc)."""
    env = dict(os.environ if base is None else base)
    env["CI"] = env.get("CI") or "1"
    return env


@dataclass
class EntitySummary:
    """What one entity holds: archetype components, samples (rows) and time range."""

    path: str
    components: list[str] = field(default_factory=list)
    samples: int = 0
    static: bool = False
    t_min: float = math.inf
    t_max: float = -math.inf
    series: int = 0


@dataclass
class RecordingSummary:
    """What a recording holds (see :func:`summarize_recording`)."""

    path: str
    size_bytes: int
    application_id: str
    recording_ids: list[str]
    has_blueprint: bool
    entities: dict[str, EntitySummary]
    texts: dict[str, str]
    views: list[dict[str, str]] = field(default_factory=list)
    #: False when the file has no footer: the writing process was killed (the data flushed
    #: before that is still readable).
    finalized: bool = True

    @property
    def time_range(self) -> tuple[float, float] | None:
        lo = min(
            (e.t_min for e in self.entities.values() if e.samples and not e.static),
            default=math.inf,
        )
        hi = max(
            (e.t_max for e in self.entities.values() if e.samples and not e.static),
            default=-math.inf,
        )
        return (lo, hi) if lo <= hi else None

    def to_json(self) -> dict[str, Any]:
        tr = self.time_range
        return {
            "path": self.path,
            "size_bytes": self.size_bytes,
            "application_id": self.application_id,
            "recording_ids": self.recording_ids,
            "has_blueprint": self.has_blueprint,
            "time_range": list(tr) if tr else None,
            "entities": {
                p: {
                    "components": e.components,
                    "samples": e.samples,
                    "static": e.static,
                    "series": e.series,
                    "time_range": [e.t_min, e.t_max] if e.samples and not e.static else None,
                }
                for p, e in sorted(self.entities.items())
            },
            "texts": dict(sorted(self.texts.items())),
            "views": self.views,
            "finalized": self.finalized,
        }


_VIEW_FIELDS = ("class_identifier", "display_name", "space_origin")


def _open_reader(path: str | Path):
    p = Path(path)
    if not p.is_file():
        raise ConfigError("path", "no such recording file", str(p))
    from rerun.chunk import RrdReader

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            reader = RrdReader(p)
            recordings = reader.recordings()
    except Exception as err:  # the bindings raise various errors on non-rrd input
        raise ConfigError("path", f"not a readable Rerun recording (.rrd): {err}", str(p)) from None
    if not recordings:
        raise ConfigError("path", "the file holds no Rerun recording", str(p))
    finalized = not any("no footer" in str(w.message) for w in caught)
    return reader, recordings, finalized


def summarize_recording(path: str | Path) -> RecordingSummary:
    """Read a recording back: entities, samples, time ranges, and every text document.

    Raises :class:`ConfigError` when the file is missing or is not a Rerun recording.
    """
    import pyarrow as pa

    reader, recordings, finalized = _open_reader(path)
    entities: dict[str, EntitySummary] = {}
    texts: dict[str, str] = {}
    try:
        chunks = list(reader.stream(store=recordings[0]))
        blueprints = reader.blueprints()
        bp_chunks = list(reader.stream(store=blueprints[0])) if blueprints else []
    except Exception as err:
        raise ConfigError("path", f"corrupt Rerun recording: {err}", str(path)) from None
    views = []
    for ch in bp_chunks:
        rb = ch.to_record_batch()
        if "ViewBlueprint:space_origin" in rb.schema.names:
            row = {
                k: rb.column(f"ViewBlueprint:{k}").to_pylist()[-1]
                for k in _VIEW_FIELDS
                if f"ViewBlueprint:{k}" in rb.schema.names
            }
            views.append({k: (v[-1] if isinstance(v, list) and v else v) for k, v in row.items()})
    views.sort(key=lambda v: (str(v.get("space_origin")), str(v.get("display_name"))))
    for ch in chunks:
        ep = ch.entity_path
        if ep.startswith("/__"):
            continue
        rb = ch.to_record_batch()
        ent = entities.setdefault(ep, EntitySummary(ep))
        for fld in rb.schema:
            meta = fld.metadata or {}
            if meta.get(b"rerun:kind") == b"data":
                comp = fld.name
                if comp not in ent.components:
                    ent.components.append(comp)
        if ch.is_static:
            ent.static = ent.static or not ent.samples
            if "TextDocument:text" in rb.schema.names:
                col = rb.column("TextDocument:text").to_pylist()
                if col and col[-1]:
                    texts[ep] = col[-1][-1]
            continue
        ent.static = False
        ent.samples += ch.num_rows
        if "time" in rb.schema.names and ch.num_rows:
            tcol = rb.column("time").cast(pa.int64()).to_numpy()
            ent.t_min = min(ent.t_min, float(tcol.min()) / 1e9)
            ent.t_max = max(ent.t_max, float(tcol.max()) / 1e9)
        for comp in ("Scalars:scalars", "Points2D:positions"):
            if comp in rb.schema.names and ch.num_rows:
                first = rb.column(comp)[0].values
                ent.series = max(ent.series, len(first) if first is not None else 0)
    # Static-only entities (texts, styles) count as static.
    for ent in entities.values():
        if ent.samples == 0:
            ent.static = True
    p = Path(path)
    return RecordingSummary(
        path=str(p),
        size_bytes=p.stat().st_size,
        application_id=recordings[0].application_id,
        recording_ids=[r.recording_id for r in recordings],
        has_blueprint=bool(blueprints),
        entities=entities,
        texts=texts,
        views=views,
        finalized=finalized,
    )
