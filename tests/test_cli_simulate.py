"""``lcc-synth simulate``: table, JSON shape, seeds, exit codes."""

from __future__ import annotations

import json
from pathlib import Path

from lcc_synth.cli.main import main

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"


def test_table2_json_shape_and_values(capsys):
    assert main(["simulate", str(PROBLEMS / "paper_table2.toml"), "--json", "--no-record"]) == 0
    out = capsys.readouterr().out
    data = json.loads(out)  # exactly one JSON object on stdout
    res = data["results"]
    assert list(res) == ["all_hdv", "fd_lcc", "cf_lcc"]
    expected = {"all_hdv": (0.89, 392.86), "fd_lcc": (0.58, 321.94), "cf_lcc": (0.81, 340.56)}
    for name, (a, f) in expected.items():
        e = res[name]
        assert round(e["aave"], 2) == a and round(e["fuel_ml"], 2) == f
        assert isinstance(e["min_spacing"], float) and e["min_spacing"] > 17.0
        assert e["collisions"] == 0 and e["aeb_activations"] == 0
        pv = e["per_vehicle"]
        assert len(pv["max_abs_velocity_error"]) == 12 and len(pv["min_spacing"]) == 12
        assert pv["min_spacing"][0] is None  # the head has no spacing
        # head -> tail: vehicle 1 (the braking one, column 2) has the largest velocity error
        assert max(pv["max_abs_velocity_error"]) == pv["max_abs_velocity_error"][2]
    assert round(res["fd_lcc"]["reduction_vs_baseline"]["aave_pct"], 2) == 34.97


def test_table_output_and_seeds(capsys):
    assert main(["simulate", str(PROBLEMS / "paper_table2.toml"), "--no-record"]) == 0
    out = capsys.readouterr().out
    assert "0.8928" in out and "392.86" in out and "34.97" in out
    argv = ["simulate", str(PROBLEMS / "paper_appendix_c.toml"), "--seeds", "3", "--json"]
    argv.append("--no-record")
    assert main(argv) == 0
    res = json.loads(capsys.readouterr().out)["results"]
    assert len(res["fd_lcc"]["aave_all"]) == 3
    red = res["fd_lcc"]["reduction_vs_baseline"]
    assert red["baseline"] == "all_hdv" and red["aave_pct"] > 0 and red["aave_pct_std"] > 0


def test_bad_input_exits_2(tmp_path, capsys):
    assert main(["simulate", str(tmp_path / "missing.toml"), "--no-record"]) == 2
    assert "no such problem file" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text('[system]\nm = 0\nn = 1\n[scenario]\ndt = -1\n[controllers.h]\ntype = "hdv"\n')
    assert main(["simulate", str(bad), "--no-record"]) == 2
    err = capsys.readouterr().err
    assert "scenario.dt" in err and err.count("\n") == 1
    argv = ["simulate", str(PROBLEMS / "paper_table2.toml"), "--seeds", "0", "--no-record"]
    assert main(argv) == 2
    assert "--seeds" in capsys.readouterr().err


def test_seed_chunks_give_the_same_study():
    """Large seed studies run in memory-bounded chunks; the draws (and so every metric) do not
    depend on the chunking."""
    import argparse

    import numpy as np

    from lcc_synth.cli.simulate import chunks, collect, iter_results, load
    from lcc_synth.metrics import aave, min_spacing

    args = argparse.Namespace(problem=str(PROBLEMS / "paper_appendix_c.toml"), seeds=5)
    spec, whole = collect(args)
    one_run = 10000 * (12 * 32 + 9)
    assert [c.batch for c in chunks(spec.scenario, budget=2 * one_run)] == [2, 2, 1]
    assert [c.first_index for c in chunks(spec.scenario, budget=2 * one_run)] == [0, 2, 4]
    parts = {}
    for _chunk, name, r in iter_results(load(args), budget=2 * one_run):
        parts.setdefault(name, []).append((aave(r), min_spacing(r)))
    for name, res in whole.items():
        np.testing.assert_allclose(np.concatenate([p[0] for p in parts[name]]), aave(res))
        np.testing.assert_allclose(np.concatenate([p[1] for p in parts[name]]), min_spacing(res))
