"""The gains file: JSON written by ``lcc-synth synthesize --out``.

Keys: ``kind, m, n, semantics, state_names, K, gains`` (``K`` = the gains in ``state_names``
order, ``gains`` = ``{state_name: value}``; ``u = +K x`` with the semantics of ``feedback.py``),
plus ``pattern, weights, h2_true, h2_lmi_bound, gamma_peak, gamma_peak_omega, string_stable,
plant_stable`` and extra information (``design``, ``v_star``, ``input_K``, ``input_kh``,
``h2_unstructured``, ``max_real_eig``, ``problem``). Non-finite numbers are written as null.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import SEMANTICS, StaticGains
from lcc_synth.models.linear import KINDS
from lcc_synth.synthesis.report import SynthesisReport, _jsonable

__all__ = ["gains_document", "write_gains", "read_gains", "REQUIRED_KEYS"]

REQUIRED_KEYS = ("kind", "m", "n", "semantics", "state_names", "K", "gains")


def gains_document(rep: SynthesisReport) -> dict[str, Any]:
    """The gains-file JSON object of a synthesis report."""
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


def write_gains(path: str | Path, rep: SynthesisReport) -> Path:
    """Write the gains file of ``rep`` to ``path`` (parent directories created)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(gains_document(rep), indent=2) + "\n")
    return p


def read_gains(path: str | Path) -> tuple[StaticGains, dict[str, Any]]:
    """Read and validate a gains file; returns the gains and the whole document.

    Raises
    ------
    ConfigError
        Missing file, invalid JSON, a missing key, or inconsistent contents.
    """
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
