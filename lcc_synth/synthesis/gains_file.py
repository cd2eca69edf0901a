"""The gains file: JSON written by ``lcc-synth synthesize --out``.

Keys: ``kind, m, n, semantics, state_names, K, gains`` (``K`` = the gains in ``state_names``
order, ``gains`` = ``{state_name: value}``; ``u = +K x`` with the semantics of ``feedback.py``),
plus ``pattern, weights, h2_true, h2_lmi_bound, gamma_peak, gamma_peak_omega, string_stable,
plant_stable`` and extra information (``design``, ``v_star``, ``input_K``, ``input_kh``,
``h2_unstructured``, ``max_real_eig``, ``problem``). Non-finite numbers are written as null.

Platoon / ring gains file (``[system] kind = "platoon" | "ring"``, read by
:func:`read_platoon_gains`): keys ``kind, size, cavs, ring, semantics, state_names, K, gains,
h2_true`` (:data:`PLATOON_REQUIRED_KEYS`). ``state_names`` = ``s_1, v_1, ..., s_N, v_N``;
``K`` = one row per CAV (``cavs`` order, positions 1-based) on ``state_names``; ``gains`` =
the same as ``{"u_i": {state_name: value}}`` (non-zero entries only, the form of
:meth:`lcc_synth.models.platoon.PlatoonGains.as_table`); ``u = +K x`` with the semantics of
:class:`~lcc_synth.models.platoon.PlatoonGains` (``"replace"``: the CAV's whole acceleration;
``"added"``: added to its HDV law). Extra keys: ``v_star, circumference`` (ring), ``patterns``
(``{"u_i": [positions heard]}``), ``comm_range``, ``weights, disturbances, design, problem,
h2_unstructured, max_real_eig`` (on ``stability_subspace``), ``input_K, input_kh`` (the
whole inputs ``u = input_K x + input_kh v_h``), ``conserved`` (ring: the unit direction
``c``; a ring gain is defined modulo ``c``: ``K + k c`` acts identically) and ``robust``
(per-member H2 summary of a robust design, or null).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import SEMANTICS, StaticGains
from lcc_synth.models.linear import KINDS
from lcc_synth.models.platoon import PlatoonGains
from lcc_synth.synthesis.platoon_report import PlatoonReport
from lcc_synth.synthesis.report import SynthesisReport, _jsonable

__all__ = ["gains_document", "write_gains", "read_gains", "REQUIRED_KEYS",
           "PLATOON_REQUIRED_KEYS", "platoon_gains_document", "read_platoon_gains"]

REQUIRED_KEYS = ("kind", "m", "n", "semantics", "state_names", "K", "gains")

#: Keys every platoon / ring gains file has.
PLATOON_REQUIRED_KEYS = ("kind", "size", "cavs", "ring", "semantics", "state_names", "K",
                         "gains", "h2_true")  # fmt: skip


def platoon_gains_document(rep: PlatoonReport) -> dict[str, Any]:
    """The gains-file JSON object of a platoon / ring synthesis report."""
    c = rep.check
    doc = {
        "kind": rep.kind, "size": rep.size, "cavs": list(rep.cavs), "ring": rep.ring,
        "semantics": rep.semantics, "state_names": list(rep.state_names), "K": rep.K,
        "gains": rep.gains, "h2_true": c.h2, "v_star": rep.v_star,
        "circumference": rep.circumference, "patterns": rep.patterns,
        "comm_range": rep.comm_range, "weights": rep.weights,
        "disturbances": rep.disturbances, "design": rep.design, "problem": rep.problem,
        "h2_unstructured": rep.h2_unstructured, "max_real_eig": c.max_real_eig,
        "stability_subspace": c.subspace, "input_K": rep.input_K, "input_kh": rep.input_kh,
        "conserved": rep.conserved,
        "robust": None if rep.robust is None else {
            k: {kk: vv for kk, vv in v.items() if kk != "members"} if isinstance(v, dict)
            else v for k, v in rep.robust.items()},
    }  # fmt: skip
    return _jsonable(doc)


def read_platoon_gains(path: str | Path, model=None) -> tuple[PlatoonGains, dict[str, Any]]:
    """Read and validate a platoon / ring gains file; returns the gains and the document.

    Parameters
    ----------
    model : PlatoonModel, optional
        When given, the file must be for its CAVs and states (and ``K`` is checked against
        ``gains`` through :meth:`~lcc_synth.models.platoon.PlatoonGains.from_table`).

    Raises
    ------
    ConfigError
        Missing file, invalid JSON, a missing key, or inconsistent contents.
    """
    doc = _load_json(path)
    src = str(path)
    for key in PLATOON_REQUIRED_KEYS:
        if key not in doc:
            raise ConfigError(key, "missing key of a platoon gains file", src)
    if doc["kind"] not in ("platoon", "ring"):
        raise ConfigError("kind", f"must be 'platoon' or 'ring', got {doc['kind']!r}", src)
    names, K, cavs = doc["state_names"], doc["K"], doc["cavs"]
    if not (isinstance(K, list) and isinstance(cavs, list) and len(K) == len(cavs)
            and all(isinstance(r, list) and len(r) == len(names) for r in K)):
        raise ConfigError("K", "must be one row per CAV, each as long as state_names", src)
    if doc["semantics"] not in SEMANTICS:
        raise ConfigError("semantics", f"must be one of {list(SEMANTICS)}", src)
    try:
        gains = PlatoonGains(np.array(K, float), tuple(cavs), doc["semantics"])
        if model is not None:
            table = PlatoonGains.from_table(doc["gains"], model, doc["semantics"])
            if tuple(model.cavs) != gains.cavs or not np.array_equal(table.K, gains.K):
                raise ConfigError("gains", "disagrees with K or with the model's CAVs/states")
    except ConfigError as err:
        raise err.with_source(src) from None
    return gains, doc


def _load_json(path: str | Path) -> dict:
    p = Path(path)
    src = str(p)
    if not p.is_file():
        raise ConfigError("file", "no such gains file", src)
    try:
        doc = json.loads(p.read_text())
    except json.JSONDecodeError as err:
        raise ConfigError("file", f"not valid JSON: {err}", src) from None
    if not isinstance(doc, dict):
        raise ConfigError("file", "must hold a JSON object", src)
    return doc


def gains_document(rep: SynthesisReport | PlatoonReport) -> dict[str, Any]:
    """The gains-file JSON object of a synthesis report."""
    if isinstance(rep, PlatoonReport):
        return platoon_gains_document(rep)
    c = rep.check
    doc = {
        "kind": rep.kind,
        "m": rep.m,
        "n": rep.n,
        "semantics": rep.semantics,
        "state_names": list(rep.state_names),
        "K": list(rep.K),
        "gains": dict(rep.gains),
        "pattern": list(rep.pattern),
        "weights": dict(rep.weights),
        "h2_true": c.h2,
        "h2_lmi_bound": rep.h2_lmi_bound,
        "gamma_peak": c.gamma_peak,
        "gamma_peak_omega": c.gamma_peak_omega,
        "string_stable": c.string_stable,
        "string_verdict": c.string_verdict,
        "string_margin": c.string_margin,
        "plant_stable": bool(c.max_real_eig < 0) if c.plant_stable is None else c.plant_stable,
        "design": rep.design,
        "problem": rep.problem,
        "v_star": rep.v_star,
        "disturbances": list(rep.disturbances),
        "input_K": list(rep.input_K),
        "input_kh": rep.input_kh,
        "h2_unstructured": rep.h2_unstructured,
        "max_real_eig": c.max_real_eig,
        "max_real_eig_model": c.max_real_eig_model,
    }
    return _jsonable(doc)


def write_gains(
    path: str | Path, rep: SynthesisReport | PlatoonReport, overwrite: bool = True
) -> Path:
    """Write the gains file of ``rep`` to ``path`` atomically (parent directories created;
    :func:`lcc_synth.outputs.write_text`; an existing file is replaced only with
    ``overwrite``, else the next free name ``NAME-2.json`` is used); returns the name written."""
    from lcc_synth.outputs import write_text

    return write_text(path, json.dumps(gains_document(rep), indent=2) + "\n", overwrite)


def read_gains(path: str | Path) -> tuple[StaticGains, dict[str, Any]]:
    """Read and validate a gains file; returns the gains and the whole document.

    Raises
    ------
    ConfigError
        Missing file, invalid JSON, a missing key, or inconsistent contents.
    """
    src = str(Path(path))
    doc = _load_json(path)
    if doc.get("kind") in ("platoon", "ring"):
        raise ConfigError("kind", f"{doc['kind']!r}: a platoon gains file (one row per CAV); "
                          "read it with read_platoon_gains", src)  # fmt: skip
    for key in REQUIRED_KEYS:
        if key not in doc:
            raise ConfigError(key, "missing key of a gains file", src)
    if doc["kind"] not in KINDS:
        raise ConfigError("kind", f"must be one of {list(KINDS)}, got {doc['kind']!r}", src)
    for key in ("m", "n"):
        if isinstance(doc[key], bool) or not isinstance(doc[key], int) or doc[key] < 0:
            raise ConfigError(key, f"must be an integer >= 0, got {doc[key]!r}", src)
    if doc["semantics"] not in SEMANTICS:
        raise ConfigError(
            "semantics", f"must be one of {list(SEMANTICS)}, got {doc['semantics']!r}", src
        )
    if not isinstance(doc["gains"], dict):
        raise ConfigError("gains", "must be an object {state_name: value}", src)
    names, K = doc["state_names"], doc["K"]
    if not (isinstance(names, list) and isinstance(K, list) and len(names) == len(K)):
        raise ConfigError("K", "state_names and K must be lists of the same length", src)
    for name, value in zip(names, K, strict=True):
        if doc["gains"].get(name, 0.0) != value:
            raise ConfigError(f"gains.{name}", f"disagrees with K ({value!r})", src)
    try:
        gains = StaticGains(doc["gains"], doc["semantics"])
    except ConfigError as err:
        raise err.with_source(src) from None
    return gains, doc
