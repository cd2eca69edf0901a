"""Provenance of a result: which package, problem file, simulator, seeds and solvers made it.

Every machine-readable output of the commands (``--json``, ``table.json``, ``sweep.json``)
carries :func:`provenance` under the key ``"provenance"``, and every recording holds it as a
document (``/provenance``, :func:`lcc_synth.recording.record_provenance`), so that a number
can be traced back to the exact file (SHA-256 of its bytes) and settings that produced it.
"""

from __future__ import annotations

import hashlib
import sys
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

__all__ = ["file_sha256", "solver_of", "provenance"]


def file_sha256(path: str | Path) -> str | None:
    """Hex SHA-256 of the file's bytes, read by :func:`lcc_synth.schema.readers.read_file`
    (``None`` if it cannot be read)."""
    from lcc_synth.errors import ConfigError
    from lcc_synth.schema.readers import read_file

    try:
        data = read_file(path, "path", str(path), binary=True)
    except ConfigError:
        return None
    return hashlib.sha256(data).hexdigest()


def _version(module: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(module)
    except PackageNotFoundError:  # pragma: no cover - a dependency is always installed
        return "?"


def solver_of(table: Mapping[str, Any]) -> str | None:
    """The numerical solver a controller table runs with, as ``"name version"``: an MPC's or
    DeeP-LCC's QP solver (``[controllers.NAME.solver] method``, OSQP by default; DeeP-LCC's
    OSQP with the DAQP re-solve of ``exact``, on by default), an ``h2`` table's synthesis
    (Clarabel for the LMIs, SciPy for the Riccati and Lyapunov equations); ``None`` for a
    controller without one (a static gain, the HDV law, the baselines)."""
    kind = table.get("type")
    solver = table.get("solver") if isinstance(table.get("solver"), Mapping) else {}
    if kind in ("mpc", "deep_lcc"):
        method = str(solver.get("method", "osqp"))
        resolve = kind == "deep_lcc" and method == "osqp" and solver.get("exact", True)
        extra = f", daqp {_version('daqp')} re-solve" if resolve else ""
        return f"{method} {_version(method)}{extra}"
    if kind == "h2":
        return f"synthesis: clarabel {_version('clarabel')}, scipy {_version('scipy')}"
    return None


def provenance(
    problem: str | Path | None,
    *,
    backend: str | Mapping[str, str] | None = "builtin",
    seeds: Any = None,
    controllers: Mapping[str, Mapping[str, Any]] | None = None,
) -> dict[str, Any]:
    """The provenance document of a run.

    Parameters
    ----------
    problem : path-like or None
        The problem file (its name, path and SHA-256); ``None`` for the built-in default.
    backend : str, mapping or None
        The simulator (``"builtin"`` or ``"sumo"``), or ``{scenario: backend}``; ``None`` for a
        command that simulates nothing (``synthesize``, ``analyze``, ``regions``).
    seeds : any
        The random seeds (e.g. ``{"seed": 7, "draws": 100}`` or ``{scenario: seed}``).
    controllers : mapping, optional
        ``{name: controller table}``: the solver of each (:func:`solver_of`).

    Returns
    -------
    dict
        ``package``, ``version``, ``command`` (the command line), ``created`` (UTC),
        ``problem`` (``file``, ``path``, ``sha256``), ``backend``, ``seeds``, ``solvers``.
    """
    from lcc_synth import __version__

    prob = None
    if problem is not None:
        p = Path(problem)
        prob = {"file": p.name, "path": str(p.resolve()), "sha256": file_sha256(p)}
    argv = ["lcc-synth", *sys.argv[1:]] if sys.argv and "lcc-synth" in sys.argv[0] else None
    return {
        "package": "lcc_synth",
        "version": __version__,
        "command": " ".join(argv) if argv else None,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "problem": prob,
        "backend": dict(backend) if isinstance(backend, Mapping) else backend,
        "seeds": seeds,
        "solvers": {k: solver_of(t) for k, t in (controllers or {}).items()},
    }
