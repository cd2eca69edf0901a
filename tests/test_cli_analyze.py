"""`lcc-synth analyze` and `lcc-synth regions` on the shipped problems and on malformed files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lcc_synth.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
FIG9 = ROOT / "problems" / "paper_fig9_cases.toml"
REGIONS = ROOT / "problems" / "paper_fig7_fig8_regions.toml"

HEADER = """
[hdv]
model = "ovm"
[system]
kind = "lcc"
m = 2
n = 2
v_star = 15.0
"""


def run_json(capsys, *argv):
    code = main([*argv, "--no-record"])  # recording is the recording helper's; tested there
    out = capsys.readouterr().out
    assert code == 0
    return json.loads(out)  # exactly one JSON object: json.loads rejects anything extra


def test_analyze_json_table_i(capsys):
    doc = run_json(capsys, "analyze", str(FIG9), "--json")
    cases = doc["cases"]
    assert list(cases) == ["hdv_only", "case_a", "case_b", "case_c", "case_d"]
    for e in cases.values():
        assert isinstance(e["plant_stable"], bool) and isinstance(e["string_stable"], bool)
        assert isinstance(e["gamma_peak"], float) and isinstance(e["gamma_peak_omega"], float)
        assert e["plant_stable"]
    assert [cases[n]["string_stable"] for n in cases] == [False, False, False, True, True]
    assert cases["hdv_only"]["gamma_peak"] == pytest.approx(1.1268833, abs=1e-6)
    assert cases["case_a"]["gamma_peak"] == pytest.approx(1.0513342, abs=1e-6)
    assert cases["case_c"]["gamma_peak"] == pytest.approx(1.0) and cases["case_c"][
        "gamma_peak_omega"] == 0.0
    # Theorem 2: vehicles ahead uncontrollable, CAV and vehicles behind controllable
    ct = doc["controllability"]
    assert ct["rank"] == 6 and ct["vehicles_outside"] == [-2, -1]
    assert ct["vehicles_in_subspace"] == [0, 1, 2]
    # Corollary 4: CAV states + v_n measured: observable
    assert doc["observability"]["observable"] and doc["observability"]["outputs"] == [
        "s_0", "v_0", "v_2"]
    lc = doc["linear_coefficients"]
    assert lc["eq13_holds"] and lc["alpha2"] == pytest.approx(1.5)
    assert doc["system"]["s_star"] == pytest.approx(20.0)


def test_analyze_human_and_png(capsys, tmp_path):
    png = tmp_path / "fig9.png"
    assert main(["analyze", str(FIG9), "--png", str(png), "--no-record"]) == 0
    out = capsys.readouterr().out
    assert "controllability: rank 6 of 10" in out
    assert "case_d" in out and "1.126883" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_analyze_fd_lcc_has_no_string_verdict(capsys, tmp_path):
    p = tmp_path / "fd.toml"
    p.write_text(
        '[system]\nkind = "fd_lcc"\nn = 3\n'
        '[cases.demo]\nsemantics = "replace"\ngains = { v_0 = -0.5, s_1 = -0.2, v_1 = 0.05 }\n'
    )
    doc = run_json(capsys, "analyze", str(p), "--json")
    e = doc["cases"]["demo"]
    assert isinstance(e["plant_stable"], bool) and e["string_stable"] is None
    assert doc["observability"]["outputs"] == ["v_3"]


def test_regions_json_and_png(capsys, tmp_path):
    png = tmp_path / "regions.png"
    doc = run_json(capsys, "regions", str(REGIONS), "--json", "--step", "0.5", "--png", str(png))
    maps = doc["maps"]
    assert list(maps) == ["fig7a", "fig7b", "fig7c", "fig7d", "fig7e", "fig7f", "fig8a", "fig8b"]
    for e in maps.values():
        assert e["shape"] == [41, 41]
        assert 0.0 <= e["string_stable_fraction"] <= e["plant_stable_fraction"] <= 1.0
    assert maps["fig8a"]["string_stable_fraction"] > 2 * maps["fig7a"]["string_stable_fraction"]
    assert maps["fig7c"]["baseline"] == "fig7a"
    assert maps["fig7c"]["expansion"]["contains_baseline"]
    assert maps["fig7c"]["expansion"]["gained_fraction"] > 0.1
    assert doc["written"] == [str(png)] and png.read_bytes()[:4] == b"\x89PNG"


def test_regions_human(capsys):
    assert main(["regions", str(REGIONS), "--step", "1.0", "--no-record"]) == 0
    out = capsys.readouterr().out
    assert "fig8b" in out and "21x21" in out and "string st." in out


BAD_ANALYZE = [
    ("[cases.a]\ngains = { s_9 = 1.0 }\n", "cases.a.gains.s_9"),
    ("[cases.a]\nsemantics = \"both\"\n", "cases.a.semantics"),
    ("[cases.a]\ngain = { s_1 = 1.0 }\n", "cases.a.gain"),
    ("[cases.a]\ngains = { s_1 = \"x\" }\n", "cases.a.gains.s_1"),
    ("[cases]\na = 3\n", "cases.a"),
    ("[analysis]\nmethod = \"local\"\n", "analysis.method"),
    ("[analysis]\noutputs = [\"x_1\"]\n", "analysis.outputs"),
    ("[analysis]\nomega_min = -1.0\n", "analysis.omega_min"),
]


@pytest.mark.parametrize("body,field", BAD_ANALYZE)
def test_analyze_malformed_exits_2(capsys, tmp_path, body, field):
    p = tmp_path / "bad.toml"
    p.write_text(HEADER + body)
    assert main(["analyze", str(p), "--json"]) == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    assert str(p) in cap.err and field in cap.err
    assert len(cap.err.strip().splitlines()) == 1


BAD_REGIONS = [
    ("[maps.m]\nvehicle = 0\n", "maps.m.vehicle", "[-2, -1, 1, 2]"),
    ("[maps.m]\nvehicle = 3\n", "maps.m.vehicle", "[-2, -1, 1, 2]"),
    ("[maps.m]\nvehicle = 1\nstep = -0.1\n", "maps.m.step", "> 0"),
    ("[maps.m]\nvehicle = 1\nbaseline = \"nope\"\n", "maps.m.baseline", "names no map"),
    ("[maps.m]\nvehicle = 1\ngains = { s_1 = 1.0 }\n", "maps.m.gains.s_1", "own axis"),
    ("[maps.m]\nvehicle = 1\ncolour = 1\n", "maps.m.colour", "allowed keys"),
    ("[regions]\nmu = [1.0, -1.0]\n[maps.m]\nvehicle = 1\n", "regions.mu", "low < high"),
    ("[regions]\nstep = 0.0001\n[maps.m]\nvehicle = 1\n", "regions.step", "at most"),
    ("[maps.m]\nvehicle = 1\nk = [2.0, 1.0]\n", "maps.m.k", "low < high"),
    ("[regions]\nk = [1.0]\n[maps.m]\nvehicle = 1\n", "regions.k", "2 entries"),
    ("", "maps", "required"),
]


@pytest.mark.parametrize("body,field,allowed", BAD_REGIONS)
def test_regions_malformed_exits_2(capsys, tmp_path, body, field, allowed):
    p = tmp_path / "bad.toml"
    p.write_text(HEADER + body)
    assert main(["regions", str(p), "--json"]) == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    assert str(p) in cap.err and field in cap.err and allowed in cap.err


def test_regions_rejects_fd_lcc_and_bad_files(capsys, tmp_path):
    p = tmp_path / "fd.toml"
    p.write_text('[system]\nkind = "fd_lcc"\nn = 2\n[maps.m]\nvehicle = 1\n')
    assert main(["regions", str(p)]) == 2
    assert "system.kind" in capsys.readouterr().err
    assert main(["regions", str(tmp_path / "missing.toml")]) == 2
    assert "no such problem file" in capsys.readouterr().err
    q = tmp_path / "syntax.toml"
    q.write_text("[system\n")
    assert main(["analyze", str(q)]) == 2
    assert "not valid TOML" in capsys.readouterr().err
    assert main(["regions", str(REGIONS), "--step", "0"]) == 2
    assert "--step" in capsys.readouterr().err
