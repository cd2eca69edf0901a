"""``simulate --seeds N`` records every scenario (or ``--record-seeds``); the default layout
opens on the whole run."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rerun")

from rerun.chunk import RrdReader  # noqa: E402

from lcc_synth import recording as R  # noqa: E402
from lcc_synth.errors import ConfigError  # noqa: E402
from lcc_synth.recording.cli import parse_record_seeds  # noqa: E402
from lcc_synth.recording.layout import _span, plot_ranges, seeds_blueprint  # noqa: E402

PROBLEM = """
name = "seeds"
[system]
kind = "fd_lcc"
m = 0
n = 2
v_star = 15.0
[scenario]
dt = 0.01
duration = 2.0
[scenario.hdv_spread]
alpha = 0.1
[[scenario.perturbations]]
type = "brake"
vehicle = 1
start = 0.5
duration = 0.5
decel = -4.0
[controllers.all_hdv]
type = "hdv"
[controllers.fd_lcc]
type = "static"
kind = "fd_lcc"
semantics = "replace"
gains = { v_0 = -0.5, s_1 = -0.2, v_1 = 0.05, s_2 = -0.1, v_2 = 0.05 }
[metrics]
window = [0.5, 2.0]
baseline = "all_hdv"
"""


def _velocity_entities(path) -> dict[str, np.ndarray]:
    """``{entity: first velocity samples}`` of every ``.../velocity`` entity in the file."""
    out: dict[str, list] = {}
    for chunk in RrdReader(path).stream():
        entity = str(chunk.entity_path)
        if entity.endswith("/velocity"):
            out.setdefault(entity, []).append(chunk)
    return {e: c for e, c in out.items()}


def _problem(tmp_path, text=PROBLEM):
    p = tmp_path / "seeds.toml"
    p.write_text(text.replace("[scenario.hdv_spread]\nalpha = 0.1\n", ""))
    return p


def test_seeds_records_every_scenario(tmp_path, capsys):
    from lcc_synth.cli.main import main

    path = tmp_path / "all.rrd"
    assert main(["simulate", str(_problem(tmp_path)), "--seeds", "3", "--json",
                 "--rrd", str(path), "--record-every", "1"]) == 0  # fmt: skip
    s = R.summarize_recording(path)
    assert s.finalized
    for c in ("all_hdv", "fd_lcc"):
        for k in range(3):
            vel = s.entities[f"/seeds/{c}_seed{k}/velocity"]
            assert vel.samples == 200 and vel.series == 4
            assert f"| seed | {k} |" in s.texts[f"/seeds/{c}_seed{k}/metrics"]
    assert "/seeds/fd_lcc/velocity" not in s.entities
    assert set(_velocity_entities(path)) == {
        f"/seeds/{c}_seed{k}/velocity" for c in ("all_hdv", "fd_lcc") for k in range(3)
    }
    assert len(s.views) > 0


def test_record_seeds_selects_a_subset(tmp_path, capsys):
    from lcc_synth.cli.main import main

    problem = _problem(tmp_path)
    path = tmp_path / "some.rrd"
    args = ["simulate", str(problem), "--seeds", "4", "--record-seeds", "0,3", "--json"]
    assert main([*args, "--rrd", str(path)]) == 0
    got = set(_velocity_entities(path))
    assert got == {f"/seeds/{c}_seed{k}/velocity" for c in ("all_hdv", "fd_lcc") for k in (0, 3)}
    # a bad selection fails before the simulation, naming the flag; nothing is written
    bad = tmp_path / "bad.rrd"
    capsys.readouterr()
    assert main([*args[:-1], "--record-seeds", "7", "--rrd", str(bad)]) == 2
    assert "--record-seeds" in capsys.readouterr().err
    assert not bad.exists()


def test_one_seed_keeps_the_plain_entity_names(tmp_path):
    from lcc_synth.cli.main import main

    path = tmp_path / "one.rrd"
    assert main(["simulate", str(_problem(tmp_path)), "--json", "--rrd", str(path)]) == 0
    assert set(_velocity_entities(path)) == {"/seeds/all_hdv/velocity", "/seeds/fd_lcc/velocity"}


def test_parse_record_seeds():
    assert parse_record_seeds(None, 3) == [0, 1, 2]
    assert parse_record_seeds("all", 2) == [0, 1]
    assert parse_record_seeds("3,0, 1-2", 5) == [0, 1, 2, 3]
    for bad in ("5", "x", "-1", "", "1-9"):
        with pytest.raises(ConfigError, match="--record-seeds"):
            parse_record_seeds(bad, 5)


def test_layout_opens_on_the_whole_run():
    class Result:
        t = np.linspace(0.0, 60.0, 601)
        velocity = np.full((1, 601, 4), 15.0)
        spacing = np.full((1, 601, 4), 20.0)
        acceleration = np.zeros((1, 601, 4))
        u_cmd = np.zeros((1, 601))

    r = plot_ranges(Result())
    assert r["time"] == (0.0, 60.0)
    lo, hi = r["velocity"]  # a flat 15 m/s opens on a readable axis, not 14.9999998 .. 15
    assert hi - lo >= 1.0 and lo < 15.0 < hi
    assert r["u_cmd"][0] < 0.0 and r["u_cmd"][1] > 1.0  # the AEB flag 0/1 is in view
    assert _span(float("nan"), 1.0) == (0.0, 1.0)
    bp = R.simulation_blueprint("x", ["a", "b"], ["b"], r)
    assert bp.root_container is not None
    assert seeds_blueprint("x", ["a"], [0, 2], [], r).root_container is not None
