"""Issue 28, row 11: a gains file's ``K`` and ``gains`` must agree, and an empty ring gain is an
error, not a zero gain.

A gains file (``lcc-synth synthesize --out``; read by ``[controllers.NAME] type =
"gains_file"``) holds the gain twice: ``K`` on ``state_names`` and the ``gains`` table.
:mod:`lcc_synth.synthesis.gains_file` reads both and refuses a ``K`` of the wrong shape, a
missing ``K`` and a ``K`` that contradicts ``gains`` (they used to be ignored: ``K`` was never
read), and on a platoon or ring an empty ``gains`` (which used to run as a zero gain), in a
gains file or in the problem file. Each case runs the real ``lcc-synth simulate`` in a
subprocess: exit 2, one line naming the field; the valid files load (the positive controls,
in-process).
"""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import pytest
from cli_subprocess import PROBLEMS, one_line_error, run_cli

from lcc_synth.controllers.static import PlatoonGainController, StaticGainController
from lcc_synth.experiments.spec import load_spec
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import model_from_hdv

# --------------------------------------------------------------------------------------------
# the single-CAV gains file (Table II's fd_lcc string)
# --------------------------------------------------------------------------------------------

TABLE2 = (PROBLEMS / "paper_table2.toml").read_text()
NAMES = list(model_from_hdv("fd_lcc", 0, 10, OVM(), 15.0, warn=False).state_names)
GAINS = {"v_0": -0.5, "s_1": -0.2, "v_1": 0.05, "s_2": -0.1, "v_2": 0.05}
DROP = object()  #: a key left out of the file


def _with(doc: dict, change: dict) -> dict:
    doc.update(change)
    return {k: v for k, v in doc.items() if v is not DROP}


def gains_doc(**change) -> dict:
    doc = {"kind": "fd_lcc", "m": 0, "n": 10, "semantics": "replace", "state_names": NAMES,
           "K": [GAINS.get(n, 0.0) for n in NAMES], "gains": dict(GAINS)}  # fmt: skip
    return _with(doc, change)


def write_single(tmp: Path, doc: dict) -> Path:
    (tmp / "g.json").write_text(json.dumps(doc))
    path = tmp / "p.toml"
    path.write_text(TABLE2 + '\n[controllers.gf]\ntype = "gains_file"\nfile = "g.json"\n')
    return path


def fails_naming(tmp: Path, path: Path, *parts: str) -> str:
    proc = run_cli(["simulate", path.name, "--no-record"], cwd=tmp, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert one_line_error(proc.stderr), proc.stderr
    line = proc.stderr.strip().splitlines()[-1]
    for part in parts:
        assert part in line, (part, line)
    return line


def test_valid_gains_file_loads(tmp_path):
    spec = load_spec(write_single(tmp_path, gains_doc()))
    ctrl = spec.controllers["gf"]
    assert isinstance(ctrl, StaticGainController) and ctrl.describe()["gains"] == GAINS


@pytest.mark.parametrize(
    "case, change, parts",
    [
        ("K_too_short", {"K": [0.0, -0.5, -0.2, 0.05]},
         ["controllers.gf.file: g.json: K: must be a list: 22 numbers", "got 4 entries"]),
        ("K_a_matrix", {"K": [[GAINS.get(n, 0.0) for n in NAMES]]},
         ["controllers.gf.file: g.json: K: must be a list: 22 numbers", "got 1 entries"]),
        ("K_missing", {"K": DROP},
         ["controllers.gf.file: g.json: K: missing key of a gains file"]),
        ("K_contradicts_gains", {"K": [-0.4 if n == "v_0" else GAINS.get(n, 0.0)
                                       for n in NAMES]},
         ["controllers.gf.file: g.json: gains.v_0: -0.5 disagrees with K (-0.4)"]),
        ("gain_not_in_K", {"gains": {**GAINS, "s_3": 0.3}},
         ["controllers.gf.file: g.json: gains.s_3: 0.3 disagrees with K (0.0)"]),
    ],
)
def test_single_cav_gains_file_K(case, change, parts, tmp_path):
    fails_naming(tmp_path, write_single(tmp_path, gains_doc(**change)), "p.toml: ", *parts)


# --------------------------------------------------------------------------------------------
# the ring (Sugiyama's 22 vehicles, the AV at position 22)
# --------------------------------------------------------------------------------------------

RING = (PROBLEMS / "ring_sugiyama.toml").read_text()
RING_ROW = tomllib.loads(RING)["controllers"]["h2"]["gains"]["u_22"]
RING_NAMES = [f"{q}_{i}" for i in range(1, 23) for q in "sv"]


def ring_doc(**change) -> dict:
    doc = {"kind": "ring", "size": 22, "cavs": [22], "ring": True, "semantics": "added",
           "state_names": RING_NAMES, "K": [[RING_ROW.get(n, 0.0) for n in RING_NAMES]],
           "gains": {"u_22": dict(RING_ROW)}, "h2_true": None}  # fmt: skip
    return _with(doc, change)


def ring_problem(tmp: Path, controller: str) -> Path:
    """The Sugiyama ring with its all-HDV baseline and ``controller`` only."""
    head = RING.split("[controllers.follower_stopper]")[0]
    assert "[controllers.all_hdv]" in head
    path = tmp / "ring.toml"
    path.write_text(head + controller + "\n")
    return path


def write_ring(tmp: Path, doc: dict) -> Path:
    (tmp / "ring.json").write_text(json.dumps(doc))
    return ring_problem(tmp, '[controllers.av]\ntype = "gains_file"\nfile = "ring.json"\n')


def test_valid_ring_gains_file_loads(tmp_path):
    ctrl = load_spec(write_ring(tmp_path, ring_doc())).controllers["av"]
    assert isinstance(ctrl, PlatoonGainController)
    assert ctrl.gains.K.shape == (1, 44) and ctrl.gains.K[0, 0] == RING_ROW["s_1"]


@pytest.mark.parametrize(
    "case, change, parts",
    [
        ("gains_empty", {"gains": {}},
         ["controllers.av.file: ring.json: gains: is empty", "not a zero gain"]),
        ("gains_empty_row", {"gains": {"u_22": {}}},
         ["controllers.av.file: ring.json: gains: is empty"]),
        ("gains_empty_K_zero", {"gains": {}, "K": [[0.0] * 44]},
         ["controllers.av.file: ring.json: gains: is empty"]),
        ("K_missing", {"K": DROP},
         ["controllers.av.file: ring.json: K: missing key of a platoon gains file"]),
        ("K_row_too_short", {"K": [[0.1] * 43]},
         ["controllers.av.file: ring.json: K[0]: must be CAV 22's row: 44 numbers"]),
        ("K_contradicts_gains", {"K": [[0.5] + [RING_ROW.get(n, 0.0) for n in RING_NAMES[1:]]]},
         ["controllers.av.file: ring.json: gains: u_22.s_1 = -0.6337 disagrees with K[0][0]"]),
    ],
)
def test_ring_gains_file_K(case, change, parts, tmp_path):
    fails_naming(tmp_path, write_ring(tmp_path, ring_doc(**change)), "ring.toml: ", *parts)


def test_ring_problem_with_an_empty_gains_table(tmp_path):
    """``gains = {}`` in a ring's problem file is an error too, not the HDV law in disguise."""
    table = re.search(r"\[controllers\.h2\].*?(?=\n\[controllers\.mpc\])", RING, re.S).group(0)
    full = ring_problem(tmp_path, table)
    assert isinstance(load_spec(full).controllers["h2"].inner, PlatoonGainController)
    empty = table.split("[controllers.h2.gains.u_22]")[0] + "gains = {}\n"
    fails_naming(tmp_path, ring_problem(tmp_path, empty),
                 "ring.toml: controllers.h2.gains: is empty")  # fmt: skip
