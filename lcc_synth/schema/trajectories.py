"""The one reader of recorded trajectory files: platoons of real drivers, one row per sample.

A trajectory file is the NGSIM I-80 layout (``problems/data/ngsim_i80/README.md``): optional
``#`` comment lines, a header line, then one comma-separated row per sample::

    # free text (source, units): kept as the header comments
    frame,t,v0,a0,headway0,v1,a1,headway1,...

- ``t`` in s, strictly increasing and uniformly sampled (any rate); ``frame`` and any other
  extra column are ignored;
- ``v<k>`` (m/s, >= 0) and ``headway<k>`` (m, >= 0) for every vehicle ``k = 0 .. N-1``,
  ``0`` the front vehicle, ``N >= 2``; ``a<k>`` (m/s²) is optional (kept, never required);
- ``headway<k>`` is front to front (it includes the length of the vehicle ahead); ``0`` means
  "no vehicle ahead recorded", allowed for the front vehicle only: every follower's leader is
  vehicle ``k - 1`` of the file.

:func:`read_trajectory` reads it through :func:`lcc_synth.schema.readers.read_file` (a
missing, unreadable or binary file is one :class:`~lcc_synth.errors.ConfigError` naming the
path) and checks every value: each defect is one line naming the file, the column and the row
(``row`` counts data rows from 1; ``line`` is the line of the file).

Uniform sampling is checked to ``1e-3 dt`` around the median step ``dt`` (a time printed to a
few decimals, e.g. ``0.1 k`` with four, passes; a dropped frame, a 2 dt step, does not).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.schema.readers import read_file

__all__ = ["Trajectory", "read_trajectory", "UNIFORM_TOL"]

#: Largest deviation of a time step from the mean step, relative to it.
UNIFORM_TOL = 1e-3

_VEHICLE_COLUMN = re.compile(r"^(v|a|headway)(\d+)$")


@dataclass(frozen=True)
class Trajectory:
    """A recorded platoon.

    Attributes
    ----------
    path : str
        The file it was read from.
    t : ndarray, shape (T,)
        Sample times (s), uniform.
    v, headway : ndarray, shape (N, T)
        Speed (m/s) and front-to-front headway (m) of every vehicle, front (0) to tail.
    a : ndarray, shape (N, T) or None
        Recorded accelerations (m/s²) when the file has every ``a<k>`` column.
    comments : tuple of str
        The ``#`` lines before the header, without the ``#``.
    """

    path: str
    t: np.ndarray
    v: np.ndarray
    headway: np.ndarray
    a: np.ndarray | None
    comments: tuple[str, ...]

    @property
    def n_vehicles(self) -> int:
        """Vehicles in the file (front vehicle included)."""
        return int(self.v.shape[0])

    @property
    def dt(self) -> float:
        """Sample period (s)."""
        return float((self.t[-1] - self.t[0]) / (len(self.t) - 1))

    @property
    def rate(self) -> float:
        """Sample rate (Hz)."""
        return 1.0 / self.dt

    @property
    def columns(self) -> tuple[str, ...]:
        """The per-vehicle columns held (``v0``, ``headway0``, ...)."""
        out = []
        for k in range(self.n_vehicles):
            out += [f"v{k}", f"headway{k}"] + ([f"a{k}"] if self.a is not None else [])
        return tuple(out)

    def column(self, name: str, field: str = "column") -> np.ndarray:
        """The series of column ``name`` (e.g. ``"v0"``); a :class:`ConfigError` naming
        ``field`` and the columns there are otherwise."""
        match = _VEHICLE_COLUMN.match(name) if isinstance(name, str) else None
        if match is None or name not in self.columns:
            raise ConfigError(
                field, f"{self.path} has no column {name!r}; columns: {', '.join(self.columns)}"
            )
        kind, k = match.group(1), int(match.group(2))
        return {"v": self.v, "a": self.a, "headway": self.headway}[kind][k]


def _fail(path: Path, column: str, where: str, message: str) -> ConfigError:
    return ConfigError(f"column {column}", f"{where}: {message}", str(path))


def read_trajectory(
    path: str | Path, field: str = "file", source: str | None = None
) -> Trajectory:
    """Read and check a trajectory file (layout in the module docstring).

    Parameters
    ----------
    path : str or Path
        The CSV file.
    field : str
        The field or option that named the file (in the error of a file that cannot be read).
    source : str, optional
        The problem file that names it.

    Returns
    -------
    Trajectory

    Raises
    ------
    ConfigError
        One line naming the file, the column and the row: no header; a missing ``t``, ``v<k>``
        or ``headway<k>`` column; fewer than two vehicles or two rows; a row of the wrong
        length; a value that is not a finite number (NaN); a negative speed or headway; time
        not strictly increasing or not uniform; a follower's headway 0 (its leader missing).
    """
    p = Path(path)
    text = read_file(p, field, source, "trajectory file")
    comments: list[str] = []
    header: list[str] | None = None
    header_line = 0
    rows: list[tuple[int, list[str]]] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            if header is None:
                comments.append(line.lstrip("#").strip())
            continue
        if header is None:
            header, header_line = [c.strip() for c in line.split(",")], lineno
            continue
        rows.append((lineno, [c.strip() for c in line.split(",")]))
    if header is None:
        raise _fail(p, "t", "header", "no header line (expected t,v0,headway0,v1,headway1,...)")
    index = {name: j for j, name in enumerate(header)}
    if len(index) != len(header):
        dup = sorted({c for c in header if header.count(c) > 1})
        raise _fail(p, dup[0], f"header (line {header_line})", "column named twice")
    if "t" not in index:
        raise _fail(p, "t", f"header (line {header_line})", "missing (the time in s)")
    vehicles = sorted({int(m.group(2)) for c in header if (m := _VEHICLE_COLUMN.match(c))})
    n = len(vehicles)
    if vehicles != list(range(n)):
        missing = min(set(range(max(vehicles) + 1)) - set(vehicles))
        raise _fail(p, f"v{missing}", f"header (line {header_line})",
                    f"missing: vehicles are numbered 0..N-1 without gaps, got {vehicles}")
    for k in vehicles:
        for kind in ("v", "headway"):
            if f"{kind}{k}" not in index:
                raise _fail(p, f"{kind}{k}", f"header (line {header_line})",
                            f"missing (vehicle {k} needs v{k} and headway{k})")
    if n < 2:
        raise _fail(p, "v1", f"header (line {header_line})",
                    f"missing: a platoon needs at least two vehicles (a leader and a follower), "
                    f"got {n}")
    if len(rows) < 2:
        raise _fail(p, "t", "rows", f"needs at least two rows of samples, got {len(rows)}")
    has_a = all(f"a{k}" in index for k in vehicles)
    wanted = ["t"] + [f"{kind}{k}" for k in vehicles
                      for kind in (("v", "headway", "a") if has_a else ("v", "headway"))]
    values = np.empty((len(rows), len(wanted)))
    for r, (lineno, cells) in enumerate(rows, start=1):
        where = f"row {r} (line {lineno})"
        if len(cells) != len(header):
            raise _fail(p, header[min(len(cells), len(header) - 1)], where,
                        f"has {len(cells)} values, the header {len(header)}")
        for j, name in enumerate(wanted):
            cell = cells[index[name]]
            try:
                x = float(cell)
            except ValueError:
                raise _fail(p, name, where, f"not a number: {cell!r}") from None
            if not math.isfinite(x):
                raise _fail(p, name, where, f"must be a finite number, got {cell!r}")
            values[r - 1, j] = x
    col = {name: values[:, j] for j, name in enumerate(wanted)}
    t = col["t"]
    step = np.diff(t)
    if np.any(step <= 0):
        r = int(np.argmax(step <= 0)) + 2
        raise _fail(p, "t", f"row {r} (line {rows[r - 1][0]})",
                    f"time must increase strictly, got {float(t[r - 1])!r} after "
                    f"{float(t[r - 2])!r}")
    dt = float(np.median(step))
    off = np.abs(step - dt) > UNIFORM_TOL * dt
    if np.any(off):
        r = int(np.argmax(off)) + 2
        raise _fail(p, "t", f"row {r} (line {rows[r - 1][0]})",
                    f"time must be uniformly sampled (step {dt:.6g} s), got a step of "
                    f"{step[r - 2]:.6g} s (a missing or repeated sample?)")
    for k in vehicles:
        for kind in ("v", "headway"):
            name = f"{kind}{k}"
            bad = col[name] < 0
            if np.any(bad):
                r = int(np.argmax(bad)) + 1
                raise _fail(p, name, f"row {r} (line {rows[r - 1][0]})",
                            f"must be >= 0, got {float(col[name][r - 1])!r}")
        if k >= 1:
            zero = col[f"headway{k}"] == 0
            if np.any(zero):
                r = int(np.argmax(zero)) + 1
                raise _fail(p, f"headway{k}", f"row {r} (line {rows[r - 1][0]})",
                            f"is 0 (no vehicle ahead recorded), but vehicle {k - 1} of the "
                            "file is its leader: a follower needs its headway at every sample")
    v, headway = (np.array([col[f"{kind}{k}"] for k in vehicles]) for kind in ("v", "headway"))
    a = np.array([col[f"a{k}"] for k in vehicles]) if has_a else None
    return Trajectory(str(p), t.copy(), v, headway, a, tuple(comments))
