"""``lcc.calibrate``: the flat API's calibration is the command's (``lcc-synth calibrate
--json``, the same fits to the last digit), takes a path or a trajectory already read, and bad
values are the command's one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import lcc_synth as lcc
from lcc_synth.cli.main import main
from lcc_synth.schema.trajectories import read_trajectory

ROOT = Path(__file__).resolve().parents[1]
LANE1 = ROOT / "problems" / "data" / "ngsim_i80" / "i80_lane1.csv"


def _short(tmp_path: Path) -> Path:
    """Lane 1's first three vehicles over its first 8 s (a small file of the same layout)."""
    lines = LANE1.read_text().splitlines()
    comments = [x for x in lines if x.startswith("#")]
    rows = [x for x in lines if not x.startswith("#")]
    keep = [",".join(r.split(",")[:11]) for r in rows[:81]]  # header + 80 samples
    path = tmp_path / "short.csv"
    path.write_text("\n".join(comments + keep) + "\n")
    return path


def test_api_calibrate_is_the_command(tmp_path, capsys):
    path = _short(tmp_path)
    cal = lcc.calibrate(path, "ovm", starts=1)
    assert main(["calibrate", str(path), "--model", "ovm", "--starts", "1", "--json", "-q"]) == 0
    doc = json.loads(capsys.readouterr().out)
    mine = json.loads(json.dumps(cal.as_dict()))  # the same JSON conversion of floats
    assert [f["params"] for f in mine["followers"]] == [f["params"] for f in doc["followers"]]
    assert mine["pooled"]["params"] == doc["pooled"]["params"]
    assert len(cal.followers) == 2
    again = lcc.calibrate(read_trajectory(path), "ovm", starts=1)  # a trajectory already read
    assert again.as_dict() == cal.as_dict()


@pytest.mark.parametrize(("kw", "field"), [({"model": "gipps"}, "--model"),
                                           ({"starts": 0}, "--starts"),
                                           ({"length": -1.0}, "--length")])
def test_api_calibrate_bad_values_name_the_option(tmp_path, kw, field):
    with pytest.raises(lcc.ConfigError, match=field):
        lcc.calibrate(_short(tmp_path), **kw)


def test_api_calibrate_missing_file_names_it(tmp_path):
    with pytest.raises(lcc.ConfigError, match="nope.csv"):
        lcc.calibrate(tmp_path / "nope.csv")
