"""The gains file: JSON written by ``lcc-synth synthesize --out`` (and ``run``), written by
:func:`write_gains` and read by :func:`read_gains`, for every layout.

Both forms below are read into one :class:`~lcc_synth.models.feedback.Gains`: the file's
``kind`` says which vehicles its state names index. A single-CAV file (``kind = "lcc" |
"cf_lcc" | "fd_lcc" | "ccc"``) uses the paper's indexing, vehicles counted from the CAV
(``s_0``/``v_0`` the CAV's own errors, ``s_1`` the first HDV behind it, ``s_-1`` the HDV
right ahead); a platoon or ring file uses positions from the head (``s_1`` the vehicle right
behind the head; ``cavs`` the CAV positions). So ``s_1`` means "vehicle 1 of the file's
layout" in both, and a file is only read for a problem of its own layout.

Single-CAV gains file:

Keys: ``kind, m, n, semantics, state_names, K, gains`` (``K`` = the gains in ``state_names``
order, ``gains`` = ``{state_name: value}``; ``u = +K x`` with the semantics of ``feedback.py``),
plus ``pattern, weights, h2_true, h2_lmi_bound, gamma_peak, gamma_peak_omega, string_stable,
plant_stable`` and extra information (``design``, ``v_star``, ``input_K``, ``input_kh``,
``h2_unstructured``, ``max_real_eig``, ``problem``; ``robust``, the per-member H2 summary, after
a ``[synthesis.robust]`` design). Non-finite numbers are written as null.

Platoon / ring gains file (``[system] kind = "platoon" | "ring"``): keys ``kind, size, cavs,
ring, semantics, state_names, K, gains, h2_true`` (:data:`PLATOON_REQUIRED_KEYS`).
``state_names`` = ``s_1, v_1, ..., s_N, v_N``; ``K`` = one row per CAV (``cavs`` order,
positions 1-based) on ``state_names``; ``gains`` = the same as ``{"u_i": {state_name:
value}}`` (non-zero entries only, the form of
:meth:`lcc_synth.models.feedback.Gains.as_table`); ``u = +K x`` with the semantics of
:class:`~lcc_synth.models.feedback.Gains` (``"replace"``: the CAV's whole acceleration;
``"added"``: added to its HDV law). Extra keys: ``v_star, circumference`` (ring), ``patterns``
(``{"u_i": [positions heard]}``), ``comm_range``, ``weights, disturbances, design, problem,
h2_unstructured, max_real_eig`` (on ``stability_subspace``), ``input_K, input_kh`` (the
whole inputs ``u = input_K x + input_kh v_h``), ``conserved`` (ring: the unit direction
``c``; a ring gain is defined modulo ``c``: ``K + k c`` acts identically) and ``robust``
(per-member H2 summary of a robust design, or null).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.models.gains import SEMANTICS, valid_gain
from lcc_synth.models.linear import KINDS, model_from_hdv
from lcc_synth.models.platoon import PLATOON_KINDS
from lcc_synth.problem import warn_large_gains
from lcc_synth.schema.readers import read_json

if TYPE_CHECKING:  # imported where a file is written: reading one loads no synthesis stack
    from lcc_synth.synthesis.report import SynthesisReport

__all__ = ["gains_document", "write_gains", "read_gains", "REQUIRED_KEYS",
           "PLATOON_REQUIRED_KEYS", "platoon_gains_document"]

REQUIRED_KEYS = ("kind", "m", "n", "semantics", "state_names", "K", "gains")

#: Keys every platoon / ring gains file has.
PLATOON_REQUIRED_KEYS = ("kind", "size", "cavs", "ring", "semantics", "state_names", "K",
                         "gains", "h2_true")  # fmt: skip


def platoon_gains_document(rep: SynthesisReport) -> dict[str, Any]:
    """The gains-file JSON object of a platoon / ring synthesis report."""
    from lcc_synth.synthesis.report import _jsonable

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
        "robust": _robust_summary(rep.robust),
    }  # fmt: skip
    return _jsonable(doc)


def _robust_summary(robust: dict[str, Any] | None) -> dict[str, Any] | None:
    """A robust design's information without its per-member rows (every layout)."""
    if robust is None:
        return None
    return {k: {kk: vv for kk, vv in v.items() if kk != "members"} if isinstance(v, dict)
            else v for k, v in robust.items()}  # fmt: skip


def _located(err: ConfigError, path: Path, field: str | None, source: str | None):
    """An error inside the gains file ``path``: ``FIELD: PATH: KEY: ...`` when a field of a
    problem file named it, else ``PATH: KEY: ...``."""
    if field is None:
        return err if err.source else err.with_source(str(path))
    return ConfigError(field, f"{path}: {err.field}: {err.message}", source)


def _label(path: Path, field: str | None) -> str:
    """How a warning names a key of the gains file: ``FIELD: PATH: `` or ``PATH: ``."""
    return f"{field}: {path}: " if field else f"{path}: "


def _read_document(path: Path, field: str | None, source: str | None) -> dict:
    """The JSON object of a gains file, read by :func:`lcc_synth.schema.readers.read_json`."""
    doc = read_json(path, field or "file", source if field else str(path), "gains file")
    if not isinstance(doc, dict):
        raise _located(ConfigError("file", "must hold a JSON object (the gains document of "
                                   "lcc-synth synthesize --out)"), path, field, source)
    return doc


def _string_list(doc: Mapping[str, Any], key: str) -> list[str]:
    names = doc[key]
    if not (isinstance(names, list) and names and all(isinstance(x, str) for x in names)
            and len(set(names)) == len(names)):
        raise ConfigError(key, f"must be a non-empty list of distinct state names, got "
                          f"{_short(names)}")  # fmt: skip
    return names


def _short(value: Any, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _number_row(row: Any, names: list[str], key: str, what: str) -> list[float]:
    """``row`` as one number per state of ``names`` (finite, within a gain's range)."""
    if not isinstance(row, list) or len(row) != len(names):
        got = f"{len(row)} entries" if isinstance(row, list) else _short(row)
        raise ConfigError(key, f"must be {what}: {len(names)} numbers, one per state of "
                          f"state_names, got {got}")  # fmt: skip
    return [valid_gain(f"{key}[{j}] ({nm})", x) for j, (x, nm) in enumerate(zip(row, names,
                                                                               strict=True))]


def _platoon_gains(doc: dict[str, Any], model, label: str) -> Gains:
    for key in PLATOON_REQUIRED_KEYS:
        if key not in doc:
            raise ConfigError(key, "missing key of a platoon gains file (the keys: "
                              f"{', '.join(PLATOON_REQUIRED_KEYS)})")  # fmt: skip
    if doc["kind"] not in ("platoon", "ring"):
        raise ConfigError("kind", f"must be 'platoon' or 'ring', got {_short(doc['kind'])}")
    size, cavs = doc["size"], doc["cavs"]
    if isinstance(size, bool) or not isinstance(size, int) or size < 1:
        raise ConfigError("size", f"must be an integer >= 1, got {_short(size)}")
    if not (isinstance(cavs, list) and cavs and all(
            isinstance(c, int) and not isinstance(c, bool) and 1 <= c <= size for c in cavs)
            and cavs == sorted(set(cavs))):  # fmt: skip
        raise ConfigError("cavs", f"must be a non-empty sorted list of distinct positions in "
                          f"[1, {size}], got {_short(cavs)}")  # fmt: skip
    if doc["ring"] is not (doc["kind"] == "ring"):
        raise ConfigError("ring", f"must be {str(doc['kind'] == 'ring').lower()} for kind = "
                          f"{doc['kind']!r}, got {_short(doc['ring'])}")  # fmt: skip
    if doc["semantics"] not in SEMANTICS:
        raise ConfigError("semantics", f"must be one of {list(SEMANTICS)}, got "
                          f"{_short(doc['semantics'])}")  # fmt: skip
    names = _string_list(doc, "state_names")
    if len(names) != 2 * size:
        raise ConfigError("state_names", f"must name the {2 * size} states s_1, v_1 .. "
                          f"s_{size}, v_{size}, got {len(names)}")  # fmt: skip
    K = doc["K"]
    if not isinstance(K, list) or len(K) != len(cavs):
        got = f"{len(K)} rows" if isinstance(K, list) else _short(K)
        raise ConfigError("K", f"must be one row per CAV ({len(cavs)}: cavs {cavs}), each "
                          f"with {len(names)} entries (state_names), got {got}")  # fmt: skip
    rows = [_number_row(r, names, f"K[{k}]", f"CAV {c}'s row") for k, (c, r)
            in enumerate(zip(cavs, K, strict=True))]  # fmt: skip
    table = doc["gains"]
    if not isinstance(table, dict) or not any(isinstance(r, dict) and r for r in table.values()):
        raise ConfigError("gains", "is empty: give each CAV's gains {\"u_i\": {state: gain}} "
                          "(an empty table is not a zero gain; drive the CAVs with type = "
                          "\"hdv\" for their HDV law)")  # fmt: skip
    inputs = [f"u_{c}" for c in cavs]
    for u, row in table.items():
        if u not in inputs:
            raise ConfigError(f"gains.{u}", f"not a CAV input of the file; its CAVs: {inputs}")
        if not isinstance(row, dict):
            raise ConfigError(f"gains.{u}", "must be an object {state: gain}")
        k = inputs.index(u)
        for nm, g in row.items():
            if nm not in names:
                raise ConfigError(f"gains.{u}.{nm}", "not a state of state_names")
            valid_gain(f"gains.{u}.{nm}", g)
        for j, nm in enumerate(names):
            if float(row.get(nm, 0.0)) != rows[k][j]:
                raise ConfigError("gains", f"{u}.{nm} = {row.get(nm, 0.0)!r} disagrees with "
                                  f"K[{k}][{j}] = {rows[k][j]!r}")  # fmt: skip
    for k, u in enumerate(inputs):
        if u not in table and any(rows[k]):
            raise ConfigError(f"gains.{u}", f"is missing, but K[{k}] is not zero")
    if model is not None:
        if tuple(model.cavs) != tuple(cavs) or tuple(model.state_names) != tuple(names):
            raise ConfigError("cavs", f"the file's CAVs {cavs} on {len(names)} states are not "
                              f"the model's: CAVs {list(model.cavs)} on {model.nx} states")
    warn_large_gains({f"{u}.{nm}": g for u, row in table.items() for nm, g in row.items()},
                     f"{label}gains")  # fmt: skip
    return Gains(np.array(rows, float), tuple(cavs), tuple(names), doc["semantics"])


def gains_document(rep: SynthesisReport) -> dict[str, Any]:
    """The gains-file JSON object of a synthesis report (a row per CAV: the platoon / ring
    form, :func:`platoon_gains_document`)."""
    from lcc_synth.synthesis.report import UNSET, _jsonable

    if rep.per_cav:
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
    if rep.robust is not UNSET and rep.robust is not None:  # [synthesis.robust]
        doc["robust"] = _robust_summary(rep.robust)
    return _jsonable(doc)


def write_gains(
    path: str | Path, rep: SynthesisReport, overwrite: bool = True
) -> Path:
    """Write the gains file of ``rep`` to ``path`` atomically (parent directories created;
    :func:`lcc_synth.outputs.write_text`; an existing file is replaced only with
    ``overwrite``, else the next free name ``NAME-2.json`` is used); returns the name written."""
    from lcc_synth.outputs import write_text

    return write_text(path, json.dumps(gains_document(rep), indent=2) + "\n", overwrite)


def read_gains(
    path: str | Path, field: str | None = None, source: str | None = None, system=None,
    model=None,
) -> tuple[Gains, dict[str, Any]]:
    """Read and validate a gains file of any layout; returns the gains and the whole document.

    A single-CAV file must hold every key of :data:`REQUIRED_KEYS`, ``K`` one number per state
    of ``state_names`` and ``gains`` the same gains by state name; a platoon or ring file
    (``kind = "platoon" | "ring"``) every key of :data:`PLATOON_REQUIRED_KEYS`, ``K`` one row
    per CAV of ``cavs`` and ``gains`` the same as ``{"u_i": {state: gain}}`` (not empty). In
    both, ``gains`` must agree with ``K`` entry for entry (a state missing from ``gains`` has
    gain 0 in ``K``).

    Parameters
    ----------
    path : str or Path
    field, source : str, optional
        The field of a problem file that named the file, and that problem file: errors are then
        ``SOURCE: FIELD: PATH: KEY: ...``; else ``PATH: KEY: ...``.
    system : lcc_synth.problem.System, optional
        When given, the file must be for its layout: a single-CAV file for its ``m`` and ``n``
        (on the states of the file's ``kind`` for them), a platoon / ring file for its kind,
        size, CAVs and road.
    model : LCCModel or PlatoonModel, optional
        When given, the file must be for its CAVs and states.

    Raises
    ------
    ConfigError
        A missing or unreadable file (:func:`lcc_synth.schema.readers.read_json`), invalid
        JSON, a missing key, inconsistent contents, or a file of another layout.
    """
    p = Path(path)
    doc = _read_document(p, field, source)
    try:
        platoon = doc.get("kind") in PLATOON_KINDS
        if system is not None and platoon != (system.platoon is not None):
            raise ConfigError("kind", f"{doc.get('kind')!r}: a gains file for " + (
                "a platoon or ring (one row per CAV)" if platoon else "one CAV") +
                f"; the problem has kind={system.kind!r}")  # fmt: skip
        if platoon:
            if system is not None and model is None:
                model = system.linear_model(warn=False)
            gains = _platoon_gains(doc, model, _label(p, field))
            if system is not None:
                _check_layout(doc, system)
        else:
            gains = _static_gains(doc, system, _label(p, field))
            if model is not None:
                gains.check(model)
    except ConfigError as err:
        raise _located(err, p, field, source) from None
    return gains, doc


def _check_layout(doc: dict[str, Any], system) -> None:
    """A :class:`ConfigError` (``kind``) unless the platoon / ring file ``doc`` is for the
    platoon or ring ``system``."""
    P = system.platoon
    got = (doc["kind"], doc.get("size"), doc.get("cavs"), doc.get("ring"))
    want = (system.kind, P.size, list(P.cavs), bool(P.ring))
    if got != want:
        raise ConfigError("kind", f"the file holds gains for kind={got[0]!r}, size={got[1]}, "
                          f"cavs={got[2]}, ring={got[3]}; the problem has kind={want[0]!r}, "
                          f"size={want[1]}, cavs={want[2]}, ring={want[3]}")  # fmt: skip


def _static_gains(doc: dict[str, Any], system, label: str) -> Gains:
    for key in REQUIRED_KEYS:
        if key not in doc:
            raise ConfigError(key, "missing key of a gains file (the keys: "
                              f"{', '.join(REQUIRED_KEYS)})")  # fmt: skip
    if doc["kind"] not in KINDS:
        raise ConfigError("kind", f"must be one of {list(KINDS)}, got {_short(doc['kind'])}")
    for key in ("m", "n"):
        if isinstance(doc[key], bool) or not isinstance(doc[key], int) or doc[key] < 0:
            raise ConfigError(key, f"must be an integer >= 0, got {_short(doc[key])}")
    if doc["semantics"] not in SEMANTICS:
        raise ConfigError(
            "semantics", f"must be one of {list(SEMANTICS)}, got {_short(doc['semantics'])}"
        )
    names = _string_list(doc, "state_names")
    K = _number_row(doc["K"], names, "K", "a list")
    table = doc["gains"]
    if not isinstance(table, dict):
        raise ConfigError("gains", f"must be an object {{state_name: value}}, got {_short(table)}")
    for name in table:
        if name not in names:
            raise ConfigError(f"gains.{name}", f"not a state of state_names {names}")
    for name, value in zip(names, K, strict=True):
        got = table.get(name, 0.0)
        if isinstance(got, bool) or not isinstance(got, int | float) or float(got) != value:
            raise ConfigError(f"gains.{name}", f"{_short(got)} disagrees with K ({value!r})")
    if system is not None:
        if (doc["m"], doc["n"]) != (system.m, system.n):
            raise ConfigError("m", f"the file holds gains for m={doc['m']}, n={doc['n']}; the "
                              f"problem has m={system.m}, n={system.n}")  # fmt: skip
        model = model_from_hdv(doc["kind"], system.m, system.n, system.hdv, system.v_star,
                               warn=False)  # fmt: skip
        if tuple(names) != tuple(model.state_names):
            raise ConfigError("state_names", f"are not the states of a {doc['kind']} model "
                              f"with m={system.m}, n={system.n}: {list(model.state_names)}")
    gains = Gains.named(table, doc["semantics"])
    warn_large_gains(gains.gains, f"{label}gains")
    return gains
