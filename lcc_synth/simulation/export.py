"""Trajectories out: every vehicle's time series of a simulation as a tidy CSV or Parquet file
(``lcc-synth simulate PROBLEM --export DIR``, ``lcc-synth run --export DIR``).

One file per (scenario, controller) run, ``<scenario>_<controller>.csv`` (a study of several
draws, ``--seeds N``: one per draw, ``<scenario>_<controller>_seed<k>.csv``, ``k`` the draw's
index in the study, as the recordings name them). Tidy: one row per (sample, vehicle), time
major (all vehicles of the first sample, then the next sample), with the columns of
:data:`COLUMNS`:

========== ======= =========================================================================
column     unit    meaning
========== ======= =========================================================================
t          s       sample time (the scenario's ``t_start + k dt``, every ``record_every``)
vehicle    \\-      column of the vehicle in the string (0 = the head; on a ring position 1)
label      \\-      its name in the tables and recordings: ``head``, ``-m .. -1``, ``CAV``,
                   ``1 .. n``; a platoon ``head``, ``1 .. N``; a ring ``1 .. N``; a CAV of a
                   platoon or ring ``CAV i``
role       \\-      ``head``, ``hdv`` or ``cav``
position   m       front bumper on the road (see below)
velocity   m/s
accel      m/s²    the applied acceleration (after limits, emergency braking, perturbations)
spacing    m       bumper-to-bumper gap to the vehicle ahead; ``nan`` for the head
u_cmd      m/s²    the CAV's command before limits and emergency braking (held between
                   controller samples); ``nan`` for every vehicle but a CAV
aeb        \\-      1 when that CAV's emergency braking overrode its command, else 0; ``nan``
                   for every vehicle but a CAV
========== ======= =========================================================================

After a collision every later sample of that run is ``nan`` (the simulator stops it).

Positions and spacings (the simulator's convention, :mod:`lcc_synth.simulation.engine`):
``spacing[j] = position[j-1] - position[j] - L`` with ``L`` the vehicle length
(``[scenario] vehicle_length``, 0 by default). On a ring positions are **not wrapped**: they
grow without bound along the road and column 0 follows column ``N-1``, so
``spacing[0] = position[N-1] + C - position[0] - L`` with ``C`` the circumference including
the vehicle lengths (the header's ``circumference``); ``position mod C`` is the place on the
ring.

The first line of a CSV file is one comment, ``# lcc_synth trajectories {...}``, holding a
JSON object: the package and its version, the problem file (name, path, SHA-256 of its bytes,
from :func:`lcc_synth.provenance.provenance`), the scenario, the controller, the draw, the
vehicle length, the circumference (rings), the creation time and the command line. The
second line is the column names. A Parquet file holds the same columns and the same JSON
under the schema metadata key ``lcc_synth``.

Floats are written exactly: Python's shortest round-trip representation (``repr``), so
reading the file back gives the simulation's arrays bit for bit (:func:`read_trajectories`;
``pandas.read_csv(path, comment="#")`` too). The cost is size and time. Measured on Table II's
run (10,000 samples x 12 vehicles = 120,000 rows, a perturbed run whose velocities carry all
17 digits): the CSV is 12.2 MB (102 bytes a row; :func:`export_bytes` assumes
:data:`ROW_BYTES` = 140 for the space check) and takes 1.4-2.1 s to write (in blocks of
20,000 rows: a few MB of text in memory whatever the run's length), 3.2-3.4 s to read back
(2 cores shared with other work); the Parquet file is 2.9 MB (24 bytes a row) and takes
0.45-0.6 s to write, 0.5-0.65 s to read.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError, FileError
from lcc_synth.outputs import child, path_part, writing

__all__ = [
    "COLUMNS",
    "EXPORT_FORMATS",
    "HEADER_TAG",
    "ROW_BYTES",
    "Trajectories",
    "check_format",
    "export_bytes",
    "export_name",
    "trajectory_columns",
    "write_trajectories",
    "read_trajectories",
]

#: Column names of an exported file, in order (the module docstring says what each holds).
COLUMNS = ("t", "vehicle", "label", "role", "position", "velocity", "accel", "spacing", "u_cmd",
           "aeb")  # fmt: skip
#: File formats of :func:`write_trajectories` (``parquet`` needs pyarrow, which Rerun brings).
EXPORT_FORMATS = ("csv", "parquet")
#: Start of the first line of a CSV file (the JSON header follows it).
HEADER_TAG = "# lcc_synth trajectories "
#: Bytes per row the space check assumes (102 measured on average for Table II's run).
ROW_BYTES = 140

_LINE = "%r,%d,%s,%s,%r,%r,%r,%r,%r,%r\n"


@dataclass(frozen=True)
class Trajectories:
    """An exported file read back (:func:`read_trajectories`).

    Attributes
    ----------
    header : dict
        The JSON header (provenance, scenario, controller, draw, vehicle length...).
    columns : dict
        ``{name: array}`` for every name of :data:`COLUMNS`: floats (``float64``), ``vehicle``
        ``int64``, ``label`` and ``role`` strings; one entry per row.
    """

    header: dict[str, Any]
    columns: dict[str, np.ndarray]

    def grid(self, name: str) -> np.ndarray:
        """Column ``name`` as ``(T, n_vehicles)`` (the simulator's per-run layout), from the
        time-major rows."""
        nv = int(self.columns["vehicle"].max()) + 1 if len(self.columns["vehicle"]) else 0
        return np.asarray(self.columns[name]).reshape(-1, nv)


def export_name(scenario: str, controller: str, draw: int | None = None,
                fmt: str = "csv") -> str:  # fmt: skip
    """The file name of one run: ``<scenario>_<controller>[_seed<k>].<fmt>``, each part made
    safe by :func:`lcc_synth.outputs.path_part`."""
    parts = [path_part(scenario, "scenario"), path_part(controller, "controller")]
    if draw is not None:
        parts.append(f"seed{int(draw)}")
    return "_".join(parts) + f".{fmt}"


def export_bytes(scenario: Any, runs: int = 1) -> float:
    """Upper estimate of the bytes :func:`write_trajectories` writes for ``runs`` runs of
    ``scenario`` (a :class:`~lcc_synth.simulation.scenario.Scenario`: its recorded samples,
    every ``record_every`` of its ``steps``, times its vehicles; :data:`ROW_BYTES` a row)."""
    samples = (int(scenario.steps) - 1) // int(scenario.record_every) + 1
    return float(ROW_BYTES) * samples * int(scenario.n_vehicles) * runs


def _roles(result: Any) -> list[str]:
    ring = bool(getattr(result, "ring", False))
    cavs = set(int(c) for c in result.cavs)
    return ["cav" if j in cavs else "head" if j == 0 and not ring else "hdv"
            for j in range(result.n_vehicles)]  # fmt: skip


def trajectory_columns(result: Any, draw: int = 0) -> dict[str, np.ndarray]:
    """The tidy columns (:data:`COLUMNS`) of run ``draw`` of a
    :class:`~lcc_synth.simulation.results.SimResult` batch: one entry per (sample, vehicle),
    time major.

    Raises
    ------
    ConfigError
        ``draw`` outside ``0 .. batch - 1``.
    """
    if not 0 <= draw < result.batch:
        raise ConfigError("draw", f"must be in 0..{result.batch - 1}, got {draw}")
    t = np.asarray(result.t, dtype=np.float64)
    T, nv = t.size, result.n_vehicles
    cavs = np.asarray(result.cavs, dtype=np.int64)
    u = np.full((T, nv), np.nan)
    aeb = np.full((T, nv), np.nan)
    u[:, cavs] = result.u_columns()[draw]
    aeb[:, cavs] = result.aeb_columns()[draw].astype(np.float64)
    labels = np.asarray(result.vehicle_labels(), dtype=object)
    roles = np.asarray(_roles(result), dtype=object)
    return {
        "t": np.repeat(t, nv),
        "vehicle": np.tile(np.arange(nv, dtype=np.int64), T),
        "label": np.tile(labels, T),
        "role": np.tile(roles, T),
        "position": np.asarray(result.position[draw], dtype=np.float64).ravel(),
        "velocity": np.asarray(result.velocity[draw], dtype=np.float64).ravel(),
        "accel": np.asarray(result.acceleration[draw], dtype=np.float64).ravel(),
        "spacing": np.asarray(result.spacing[draw], dtype=np.float64).ravel(),
        "u_cmd": u.ravel(),
        "aeb": aeb.ravel(),
    }


def _header(result: Any, scenario: str, draw: int | None,
            provenance: Mapping[str, Any] | None) -> dict[str, Any]:  # fmt: skip
    from lcc_synth import __version__

    prov = dict(provenance or {})
    head = {
        "package": "lcc_synth",
        "version": prov.get("version", __version__),
        "problem": prov.get("problem"),
        "scenario": scenario,
        "controller": result.controller,
        "draw": draw,
        "samples": int(np.asarray(result.t).size),
        "vehicles": int(result.n_vehicles),
        "dt": float(result.dt),
        "vehicle_length": float(result.vehicle_length),
        "ring": bool(result.ring),
        "circumference": float(result.circumference) if result.ring else None,
        "created": prov.get("created"),
        "command": prov.get("command"),
        "columns": list(COLUMNS),
    }
    return head


#: Rows formatted and written at a time (a few MB of text in memory, whatever the run's length).
_BLOCK = 20_000


def _make_parent(path: Path) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise FileError.from_os(path.parent, err, "create") from None


def _write_csv(path: Path, cols: Mapping[str, np.ndarray], header: Mapping[str, Any],
               overwrite: bool) -> Path:  # fmt: skip
    """The CSV file, written atomically (:func:`lcc_synth.outputs.writing`) in blocks of
    :data:`_BLOCK` rows."""
    _make_parent(path)
    n = len(cols["t"])
    with writing(path, overwrite) as out:
        with open(out.tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(HEADER_TAG + json.dumps(header, separators=(",", ":")) + "\n")
            fh.write(",".join(COLUMNS) + "\n")
            for a in range(0, n, _BLOCK):
                block = [np.asarray(cols[c][a : a + _BLOCK]).tolist() for c in COLUMNS]
                fh.write("".join(_LINE % row for row in zip(*block, strict=True)))
            fh.flush()
            os.fsync(fh.fileno())
    return out.path


def check_format(fmt: str) -> None:
    """Refuse a format not in :data:`EXPORT_FORMATS`, and ``parquet`` when pyarrow cannot be
    imported (:class:`~lcc_synth.errors.ConfigError` naming ``--export-format``)."""
    if fmt not in EXPORT_FORMATS:
        raise ConfigError("--export-format", f"must be one of {', '.join(EXPORT_FORMATS)}, "
                          f"got {fmt!r}")  # fmt: skip
    if fmt == "parquet":
        _pyarrow()


def _pyarrow():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as err:
        raise ConfigError(
            "--export-format", f"parquet needs pyarrow, which cannot be imported ({err}): "
            "install it (pip install pyarrow) or export csv",
        ) from None  # fmt: skip
    return pa, pq


def _write_parquet(path: Path, cols: Mapping[str, np.ndarray], header: Mapping[str, Any],
                   overwrite: bool) -> Path:  # fmt: skip
    pa, pq = _pyarrow()
    table = pa.table({c: (pa.array(cols[c].tolist(), pa.string()) if c in ("label", "role")
                          else pa.array(cols[c])) for c in COLUMNS})  # fmt: skip
    table = table.replace_schema_metadata({"lcc_synth": json.dumps(header)})
    _make_parent(path)
    with writing(path, overwrite) as out:
        pq.write_table(table, out.tmp)
    return out.path


def write_trajectories(
    result: Any,
    directory: str | Path,
    scenario: str,
    provenance: Mapping[str, Any] | None = None,
    fmt: str = "csv",
    first_index: int | None = None,
    overwrite: bool = False,
) -> list[Path]:
    """Write every run of ``result`` (a :class:`~lcc_synth.simulation.results.SimResult`) as
    one file in ``directory`` (created if missing) and return the names used.

    Parameters
    ----------
    result : SimResult
        One controller's runs (a batch, or a seed chunk of a larger study).
    directory : path-like
        The export directory. Check it first (before the simulation) with
        :func:`lcc_synth.outputs.check_directory` and :func:`export_bytes`.
    scenario : str
        The scenario's name (a problem's ``name`` for ``simulate``, the suite's scenario for
        ``run``).
    provenance : mapping, optional
        The run's :func:`lcc_synth.provenance.provenance` (version, problem file and SHA-256,
        created, command).
    fmt : {"csv", "parquet"}
        File format.
    first_index : int, optional
        Index in the study of the batch's first run: each run is then written as
        ``..._seed<k>`` (``None``: a single run, no suffix).
    overwrite : bool
        Replace a file of the same name (default: the next free name, ``NAME-2``...).

    Raises
    ------
    ConfigError
        ``fmt`` not one of :data:`EXPORT_FORMATS`, or ``parquet`` without pyarrow.
    FileError
        A file could not be written (one line naming it; nothing half-written remains).
    """
    check_format(fmt)
    directory = Path(directory)
    if first_index is None and result.batch > 1:
        first_index = 0
    written = []
    for b in range(result.batch):
        draw = None if first_index is None else first_index + b
        path = child(directory, export_name(scenario, result.controller, draw, fmt))
        cols = trajectory_columns(result, b)
        header = _header(result, scenario, draw, provenance)
        if fmt == "csv":
            written.append(_write_csv(path, cols, header, overwrite))
        else:
            written.append(_write_parquet(path, cols, header, overwrite))
    return written


def read_trajectories(path: str | Path) -> Trajectories:
    """Read a file of :func:`write_trajectories` back (CSV, or Parquet by its ``.parquet``
    extension), through :func:`lcc_synth.schema.readers.read_file` for a CSV.

    Raises
    ------
    ConfigError
        Field ``path``: the file cannot be read, is not an export of this package (no header
        line) or its columns are not :data:`COLUMNS`.
    """
    path = Path(path)
    if path.suffix == ".parquet":
        _, pq = _pyarrow()
        try:
            table = pq.read_table(path)
        except OSError as err:
            raise ConfigError("path", f"cannot read {path}: {err}") from None
        meta = (table.schema.metadata or {}).get(b"lcc_synth")
        if meta is None or tuple(table.column_names) != COLUMNS:
            raise ConfigError("path", f"{path} is not a trajectories file of lcc_synth")
        cols = {c: table.column(c).to_numpy(zero_copy_only=False) for c in COLUMNS}
        return Trajectories(json.loads(meta), _typed(cols))
    from lcc_synth.schema.readers import MAX_DATA_BYTES, read_file

    size = path.stat().st_size if path.is_file() else 0  # read whole: it is ours to read
    text = read_file(path, "path", what="trajectories file", max_bytes=max(MAX_DATA_BYTES, size))
    lines = text.splitlines()
    if len(lines) < 2 or not lines[0].startswith(HEADER_TAG):
        raise ConfigError("path", f"{path} is not a trajectories file of lcc_synth (its first "
                          f"line should start with {HEADER_TAG.strip()!r})")  # fmt: skip
    if tuple(lines[1].split(",")) != COLUMNS:
        raise ConfigError("path", f"{path}: the columns are {lines[1]!r}, expected "
                          f"{','.join(COLUMNS)}")  # fmt: skip
    header = json.loads(lines[0][len(HEADER_TAG):])
    fields = list(zip(*(ln.split(",") for ln in lines[2:]), strict=True)) if lines[2:] else [
        () for _ in COLUMNS]  # fmt: skip
    return Trajectories(header, _typed(dict(zip(COLUMNS, fields, strict=True))))


def _typed(cols: Mapping[str, Any]) -> dict[str, np.ndarray]:
    out = {}
    for c in COLUMNS:
        if c in ("label", "role"):
            out[c] = np.asarray(cols[c], dtype=object).astype(str)
        elif c == "vehicle":
            out[c] = np.asarray([int(x) for x in cols[c]], dtype=np.int64)
        else:
            out[c] = np.asarray([float(x) for x in cols[c]], dtype=np.float64)
    return out
