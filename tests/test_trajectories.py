"""The reader of recorded trajectory files: the shipped NGSIM platoons read as documented, and
every defect of a file is one error naming the file, the column and the row."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lcc_synth.errors import ConfigError
from lcc_synth.schema.trajectories import read_trajectory

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "problems" / "data" / "ngsim_i80"

GOOD = """# a comment
# units
frame,t,v0,a0,headway0,v1,a1,headway1
1,0.0,10.0,0.0,0,9.0,0.0,20.0
2,0.1,10.0,0.0,0,9.1,1.0,20.1
3,0.2,10.0,0.0,30.0,9.2,1.0,20.2
"""


def _write(tmp_path: Path, text: str, name: str = "p.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_ngsim_files_read_as_documented():
    for lane, frames, lo, hi in ((1, 240, 9.0, 16.0), (2, 369, 0.6, 12.0)):
        tr = read_trajectory(DATA / f"i80_lane{lane}.csv")
        assert tr.n_vehicles == 5 and tr.t.shape == (frames,)
        assert tr.rate == pytest.approx(10.0) and tr.dt == pytest.approx(0.1)
        assert tr.t[-1] == pytest.approx((frames - 1) * 0.1)
        assert lo - 0.1 < tr.v.min() and tr.v.max() < hi + 0.5
        assert np.abs(tr.a).max() <= 3.4139  # the source's clipping
        assert tr.comments[0].startswith("NGSIM I-80") and len(tr.comments) == 2
        assert np.all(tr.headway[1:] > 0)
    # the first row of lane 1, as printed in the file
    tr = read_trajectory(DATA / "i80_lane1.csv")
    assert tr.v[:, 0] == pytest.approx([11.6586, 10.6528, 10.1712, 10.6680, 9.1684])
    assert tr.headway[:, 0] == pytest.approx([51.8221, 20.6319, 15.0266, 20.6289, 29.4193])
    assert tr.column("v3")[0] == pytest.approx(10.6680)


def test_good_file_and_columns(tmp_path):
    tr = read_trajectory(_write(tmp_path, GOOD))
    assert tr.comments == ("a comment", "units")
    assert tr.v.shape == (2, 3) and tr.headway[0, 0] == 0  # headway0 = 0 is allowed
    assert tr.column("a1") == pytest.approx([0.0, 1.0, 1.0])
    with pytest.raises(ConfigError, match=r"has no column 'v7'; columns: v0, headway0, a0"):
        tr.column("v7", "scenario.perturbations[0].column")
    # acceleration columns are optional
    tr = read_trajectory(_write(tmp_path, "t,v0,headway0,v1,headway1\n0,1,0,1,9\n1,1,0,1,9\n"))
    assert tr.a is None and tr.dt == 1.0


BAD = {
    "missing column": ("t,v0,headway0,v1\n0,1,0,1\n0.1,1,0,1\n",
                       "column headway1: header (line 1): missing (vehicle 1 needs v1 and "
                       "headway1)"),
    "no time": ("v0,headway0,v1,headway1\n1,0,1,9\n1,0,1,9\n",
                "column t: header (line 1): missing (the time in s)"),
    "one vehicle": ("t,v0,headway0\n0,1,0\n0.1,1,0\n",
                    "column v1: header (line 1): missing: a platoon needs at least two "
                    "vehicles (a leader and a follower), got 1"),
    "non-monotonic time": ("t,v0,headway0,v1,headway1\n0,1,0,1,9\n0.1,1,0,1,9\n0.1,1,0,1,9\n",
                           "column t: row 3 (line 4): time must increase strictly, got 0.1 "
                           "after 0.1"),
    "non-uniform time": ("t,v0,headway0,v1,headway1\n0,1,0,1,9\n0.1,1,0,1,9\n0.3,1,0,1,9\n"
                         "0.4,1,0,1,9\n", "column t: row 3 (line 4): time must be uniformly "
                         "sampled (step 0.1 s), got a step of 0.2 s (a missing or repeated "
                         "sample?)"),
    "NaN": ("t,v0,headway0,v1,headway1\n0,1,0,1,9\n0.1,1,0,nan,9\n",
            "column v1: row 2 (line 3): must be a finite number, got 'nan'"),
    "text": ("t,v0,headway0,v1,headway1\n0,1,0,1,9\n0.1,1,0,fast,9\n",
             "column v1: row 2 (line 3): not a number: 'fast'"),
    "short row": ("t,v0,headway0,v1,headway1\n0,1,0,1,9\n0.1,1,0,1\n",
                  "column headway1: row 2 (line 3): has 4 values, the header 5"),
    "follower without leader": ("t,v0,headway0,v1,headway1\n0,1,0,1,9\n0.1,1,0,1,0\n",
                                "column headway1: row 2 (line 3): is 0 (no vehicle ahead "
                                "recorded), but vehicle 0 of the file is its leader"),
    "negative speed": ("t,v0,headway0,v1,headway1\n0,1,0,1,9\n0.1,-1,0,1,9\n",
                       "column v0: row 2 (line 3): must be >= 0, got -1.0"),
    "one row": ("t,v0,headway0,v1,headway1\n0,1,0,1,9\n",
                "column t: rows: needs at least two rows of samples, got 1"),
    "no header": ("# only a comment\n", "column t: header: no header line"),
    "gap in vehicles": ("t,v0,headway0,v2,headway2\n0,1,0,1,9\n0.1,1,0,1,9\n",
                        "column v1: header (line 1): missing: vehicles are numbered 0..N-1"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_file_is_one_error_naming_file_column_and_row(case, tmp_path):
    text, expected = BAD[case]
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as exc:
        read_trajectory(path)
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith(f"{path}: {expected}"), msg


def test_missing_file_names_the_field(tmp_path):
    with pytest.raises(ConfigError, match=r"^DATA: .*no such trajectory file"):
        read_trajectory(tmp_path / "nope.csv", "DATA")
