"""Issue 11's integration: ``type = "h2"`` for platoon / ring layouts in ``run``, ``sweep``
and ``simulate``, the joint MPC's fallback table, ``only_layouts``, the ring's time step, the
figures and recording of the new layouts."""

from __future__ import annotations

import json
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lcc_synth.cli.main import main
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.comparison import applies, load_suite, prepare_controllers
from lcc_synth.experiments.spec import load_spec
from lcc_synth.models.platoon import hdv_law_rows
from lcc_synth.models.records import system_tables
from lcc_synth.problem import system_from
from lcc_synth.simulation.engine import simulate
from lcc_synth.simulation.timestep import TimeStepWarning, check_time_step

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ROOT / "problems"
SHOWCASE = PROBLEMS / "showcase.toml"
RING = PROBLEMS / "ring_stop_and_go.toml"
PLATOON = PROBLEMS / "platoon_deeplcc_brake.toml"


def _synthesized_gains(tmp_path, problem: Path) -> dict:
    out = tmp_path / f"{problem.stem}.json"
    assert main(["synthesize", str(problem), "--no-record", "--out", str(out)]) == 0
    return json.loads(out.read_text())


def test_ring_h2_of_run_is_the_gain_of_synthesize_on_the_same_tables(tmp_path, capsys):
    suite = load_suite(SHOWCASE, scenarios=["ring_wave"])
    tables, designs = prepare_controllers(
        suite.controllers, suite.layouts["ring20"], "ring20", suite.source,
        suite.name, fallbacks=suite.fallbacks,
    )  # fmt: skip
    doc = _synthesized_gains(tmp_path, PROBLEMS / "ring_n20_cr5.toml")
    capsys.readouterr()
    assert tables["h2"]["type"] == "static" and tables["h2"]["kind"] == "ring"
    assert tables["h2"]["semantics"] == doc["semantics"] == "replace"
    assert tables["h2"]["gains"] == doc["gains"]  # bit for bit: the same problem, solved once
    assert designs["h2"].check.h2 == pytest.approx(2.093416, abs=5e-7)
    # the MPC's fallback is the same table, in the platoon form, zero gains dropped
    fb = tables["mpc"]["fallback"]
    assert fb["controller"] == "h2" and fb["kind"] == "ring"
    want = {u: {k: g for k, g in row.items() if g} for u, row in doc["gains"].items()}
    assert fb["gains"] == want
    # the paper's single-CAV gains are not for the ring: no row
    assert "paper" not in tables and set(tables) == {"all_hdv", "h2", "mpc"}


def test_simulate_with_type_h2_equals_the_gains_file_that_synthesize_writes(tmp_path, capsys):
    spec = load_spec(RING)  # av: type = "h2", the tables of ring_n20_cr5.toml
    doc = _synthesized_gains(tmp_path, PROBLEMS / "ring_n20_cr5.toml")
    capsys.readouterr()
    text = RING.read_text().split("[controllers.av]")[0]
    text += f'[controllers.av]\ntype = "gains_file"\nfile = "{tmp_path / "ring_n20_cr5.json"}"\n'
    (tmp_path / "ring.toml").write_text(text)
    other = load_spec(tmp_path / "ring.toml")
    assert np.array_equal(spec.controllers["av"].gains.K, other.controllers["av"].gains.K)
    assert doc["gains"] == spec.controllers["av"].gains.as_table()
    sc = replace(spec.scenario, duration=20.0)
    a, b = simulate(sc, spec.controllers["av"]), simulate(sc, other.controllers["av"])
    assert np.array_equal(a.velocity, b.velocity) and np.array_equal(a.spacing, b.spacing)


def test_platoon_h2_is_the_riccati_gain_and_the_lqr_table_to_its_digits():
    import scipy.linalg as sla

    spec = load_spec(PLATOON)
    M = spec.system.linear_model(warn=False)
    A = M.A + M.B @ hdv_law_rows(M)  # "added": each CAV keeps its HDV law
    Q = np.diag([2.0, 1.0] * M.platoon.size)
    X = sla.solve_continuous_are(A, M.B, Q, np.eye(M.B.shape[1]))
    K = -(M.B.T @ X)
    h2 = spec.controllers["h2"].gains
    assert h2.semantics == "added"
    assert np.allclose(h2.K, K, rtol=0, atol=1e-9 * np.abs(K).max())
    assert np.array_equal(np.round(h2.K, 4), spec.controllers["lqr"].gains.K)
    # the joint MPC's fallback rows are the h2 gain
    mpc = spec.controllers["mpc"]
    assert mpc.fallback_source == "controller h2"
    assert np.array_equal(mpc.fallback.K, h2.K) and mpc.fallback.semantics == "added"


def test_only_layouts_names_known_layouts_and_drops_the_controller_elsewhere(tmp_path):
    suite = load_suite(SHOWCASE)
    assert applies(suite.controllers["paper"], "string10")
    assert not applies(suite.controllers["paper"], "ring20")
    assert applies(suite.controllers["h2"], "ring20")
    text = SHOWCASE.read_text().replace('only_layouts = ["string10", "sec5a"]',
                                        'only_layouts = ["string10", "nowhere"]')
    (tmp_path / "s.toml").write_text(text)
    with pytest.raises(ConfigError, match=r"controllers\.paper\.only_layouts"):
        load_suite(tmp_path / "s.toml")
    (tmp_path / "s.toml").write_text(SHOWCASE.read_text().replace(
        'only_layouts = ["string10", "sec5a"]', "only_layouts = []"))
    with pytest.raises(ConfigError, match=r"controllers\.paper\.only_layouts"):
        load_suite(tmp_path / "s.toml")


def test_ring_time_step_is_judged_by_the_growth_rate_of_its_wave():
    spec = load_spec(RING)
    ctrl = {"all_hdv": spec.controllers["all_hdv"]}
    # the all-HDV ring's growing pair, from the platoon model on the invariant hyperplane
    from lcc_synth.models.feedback import Gains

    M = spec.system.linear_model(warn=False)
    A = Gains.zero(M, "added").closed_loop(M)[0]
    V = M.invariant_basis()
    lam = np.linalg.eigvals(V.T @ A @ V)
    top = lam[np.argmax(lam.real)]
    assert top.real > 0
    for dt, warns in ((0.05, True), (0.01, False)):
        growth = np.log(abs(1 + top * dt)) / dt / top.real - 1  # Euler's over-amplification
        assert (growth > 0.1) == warns
        sc = replace(spec.scenario, dt=dt, record_every=1)
        with warnings.catch_warnings(record=True) as got:
            warnings.simplefilter("always")
            checks = check_time_step(sc, ctrl)
        assert any(issubclass(w.category, TimeStepWarning) for w in got) == warns
        c = checks[0]
        if warns:  # the verdict names the growing mode, not the conserved one (never judged)
            assert c.mode == pytest.approx(complex(top.real, abs(top.imag)), rel=1e-9) or (
                c.mode == pytest.approx(complex(top.real, -abs(top.imag)), rel=1e-9))
            assert c.damping == pytest.approx(growth, rel=1e-9)


def test_system_tables_of_a_ring_given_by_its_circumference_read_back_equal():
    data = {"hdv": {"model": "ovm"}, "system": {"kind": "ring", "size": 12, "cavs": [12],
                                                "circumference": 250.0}}  # fmt: skip
    sy = system_from(data)
    back = system_from(system_tables(sy))
    assert back.platoon.circumference == 250.0 and back.v_star == sy.v_star


def test_profile_figure_styles_several_cavs_and_the_ring():
    from lcc_synth.figures.style import PALETTE, vehicle_style

    # platoon, CAV columns 3 and 6: both blue, one legend entry; 4, 5, 7, 8 behind
    assert vehicle_style(3, 3, (3, 6))["label"] == "CAVs"
    assert vehicle_style(6, 3, (3, 6))["color"] == PALETTE.cav
    assert vehicle_style(6, 3, (3, 6))["label"] is None
    assert vehicle_style(4, 3, (3, 6))["label"] == "HDVs behind"
    assert vehicle_style(7, 3, (3, 6))["label"] is None
    assert vehicle_style(2, 3, (3, 6))["ls"] == "--"
    # ring: column 0 is vehicle 1, an HDV (no head)
    assert vehicle_style(0, 19, (19,), ring=True)["label"] == "HDVs"
    assert vehicle_style(19, 19, (19,), ring=True)["color"] == PALETTE.cav
    # one CAV on an open string: unchanged
    assert vehicle_style(0, 1) == vehicle_style(0, 1, (1,))
    assert vehicle_style(2, 1) == vehicle_style(2, 1, (1,))


@pytest.mark.slow  # the platoon's and the ring's recordings: tests/test_recording_platoon.py
def test_run_records_the_platoon_mpc_and_draws_both_new_layouts(tmp_path, capsys):
    pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    rrd = tmp_path / "s.rrd"
    code = main(["run", str(SHOWCASE), "--scenarios", "platoon_brake", "--controllers",
                 "all_hdv,mpc", "--out", str(tmp_path), "--rrd", str(rrd), "--no-progress",
                 "--json"])  # fmt: skip
    assert code == 0
    table = json.loads(capsys.readouterr().out)["results"]["platoon_brake"]
    spec = load_spec(PLATOON)  # the same scenario in its simulate file: the same numbers
    for name in ("all_hdv", "mpc"):
        res = simulate(spec.scenario, spec.controllers[name])
        from lcc_synth.metrics import summary

        s = summary(res, spec.metrics)
        assert table[name]["fuel_ml"] == pytest.approx(s["fuel_ml"], rel=1e-12)
        assert table[name]["min_spacing"] == pytest.approx(s["min_spacing"], rel=1e-12)
    entities = {ch.entity_path for ch in RrdReader(rrd).stream()}
    assert any(e.endswith("/mpc/status") for e in entities)
    assert any(e.endswith("/mpc/predicted/u") for e in entities)
    assert list(tmp_path.glob("*/profiles_platoon_brake.png"))
