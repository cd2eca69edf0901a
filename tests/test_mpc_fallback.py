"""``fallback = "NAME"``: an MPC falls back to another controller's static gain, and
``lcc-synth run`` (``problems/showcase.toml``) makes it the synthesised H2 gain.

Independent truth: on a forced QP failure the applied command equals ``sum_i g_si s~_i +
g_vi v~_i`` evaluated here from the synthesised table's gains and the observed errors (no
library feedback code), and differs from what the paper's default fallback gain commands.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_mpc_controller import _ctx, _obs, _system

from lcc_synth.cli.main import main
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.comparison import load_suite, prepare_controllers
from lcc_synth.experiments.controller_tables import controller_from_table
from lcc_synth.experiments.spec import resolve_fallbacks
from lcc_synth.mpc.settings import paper_fallback_gains

SHOWCASE = __import__("pathlib").Path(__file__).resolve().parents[1] / "problems/showcase.toml"


def _command(gains: dict[str, float], x: np.ndarray) -> float:
    """``replace`` semantics on a CF-LCC error state ``(s~_0, v~_0, s~_1, v~_1, ...)``."""
    n = x.size // 2
    u = sum(gains.get(f"s_{i}", 0.0) * x[2 * i] + gains.get(f"v_{i}", 0.0) * x[2 * i + 1]
            for i in range(n))  # fmt: skip
    return float(np.clip(u, -5.0, 2.0))


def test_run_mpc_falls_back_to_the_synthesised_h2_gain():
    suite = load_suite(SHOWCASE, ["head_brake"], ["h2", "mpc"])
    system = suite.layouts["string10"]
    tables, designs = prepare_controllers(
        suite.controllers, system, "string10", suite.source, suite.name
    )
    h2 = tables["h2"]
    assert h2["type"] == "static" and h2["semantics"] == "replace"
    assert tables["mpc"]["fallback"]["controller"] == "h2"
    mpc = controller_from_table("mpc", dict(tables["mpc"]), system, suite.source)
    assert mpc.fallback_source == "controller h2"
    assert mpc.describe()["fallback"]["source"] == "controller h2"
    mpc.reset(_ctx(0, 10))
    for mem in mpc._members:
        mem.solver.force_failure = True
    paper = dict(paper_fallback_gains("cf_lcc", 4).gains)
    rng = np.random.default_rng(1)
    for k in range(6):
        x = rng.normal(scale=0.5, size=22)
        u = mpc(_obs(0.1 * k, x, 0, 0.0))[0]
        assert u == pytest.approx(_command(h2["gains"], x), abs=1e-12)
        assert abs(u - _command(paper, x)) > 1e-3  # not the paper's default fallback
    st = mpc.stats()
    assert st["fallback_static"] == 6 and st["qp_failures"] == {"forced_failure": 6}


def _tables(**mpc):
    return {
        "paper": {"type": "static", "kind": "cf_lcc", "semantics": "replace",
                  "gains": {"s_0": 0.1, "v_0": -0.5, "s_1": 0.0}},
        "all_hdv": {"type": "hdv"},
        "mpc": {"type": "mpc", **mpc},
    }  # fmt: skip


def test_resolved_fallback_is_plain_data_without_zero_gains():
    out = resolve_fallbacks(_tables(fallback="paper"), _system())
    assert out["mpc"]["fallback"] == {"controller": "paper", "kind": "cf_lcc",
                                      "semantics": "replace", "gains": {"s_0": 0.1, "v_0": -0.5}}
    assert resolve_fallbacks(_tables(), _system())["mpc"] == {"type": "mpc"}


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ({"fallback": "nope"}, "must name another controller"),
        ({"fallback": "mpc"}, "must name another controller"),
        ({"fallback": 3}, "controllers.mpc.fallback: must be a string, got 3"),
        ({"fallback": "all_hdv"}, "must be a static or h2 controller"),
        ({"fallback": "paper", "fallback_gains_file": "g.json"}, "not both"),
    ],
)
def test_bad_fallback_names_the_field(extra, message):
    with pytest.raises(ConfigError, match=message) as err:
        resolve_fallbacks(_tables(**extra), _system(), "p.toml")
    assert err.value.field == "controllers.mpc.fallback" and err.value.source == "p.toml"


def test_simulate_cli_bad_fallback_exits_2(tmp_path, capsys):
    text = """
[system]
kind = "cf_lcc"
m = 0
n = 3
[scenario]
duration = 1.0
[metrics]
window = [0.0, 1.0]
[controllers.paper]
type = "static"
kind = "cf_lcc"
semantics = "replace"
gains = { s_0 = 0.1, v_0 = -0.5 }
[controllers.mpc]
type = "mpc"
horizon = 5
fallback = "papr"
"""
    path = tmp_path / "fb.toml"
    path.write_text(text)
    assert main(["simulate", str(path), "--no-record", "--json"]) == 2
    err = capsys.readouterr().err.strip()
    assert "fb.toml" in err and "controllers.mpc.fallback" in err and "\n" not in err
    path.write_text(text.replace('"papr"', '"paper"'))
    assert main(["simulate", str(path), "--no-record", "--json"]) == 0
