"""The flat API on every layout: ``lcc.system(size=..., cavs=[...])`` and ``lcc.ring(...)``
build the platoons and rings of the problem files, the analysis functions take a System, and a
script and a problem file give equal objects and identical runs.

Independent truth: the problem files themselves (``problems/platoon_deeplcc_brake.toml``, the
DeeP-LCC paper's platoon, and ``problems/ring_stop_and_go.toml``), read once by :mod:`tomllib`
(not by the package) for the values a script states and once by :func:`lcc.load_problem` (the
CLI's route); the simulator's output of the file route, compared bit for bit; the linear models
the package's own model builders give for the same layout (``platoon_model``,
``model_from_hdv``); the validation messages of a problem file with the same values.
"""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import tomli_w

import lcc_synth as lcc
from lcc_synth.errors import ConfigError
from lcc_synth.models.feedback import Gains
from lcc_synth.models.platoon import platoon_model
from lcc_synth.problem import system_from

ROOT = Path(__file__).resolve().parent.parent
PLATOON = ROOT / "problems/platoon_deeplcc_brake.toml"
RING = ROOT / "problems/ring_stop_and_go.toml"
RESULT_FIELDS = ("position", "velocity", "acceleration", "spacing", "u_cmd", "aeb_active")


def _file_copy(
    path: Path, tmp_path: Path, keep: tuple[str, ...], window: list[float] | None = None,
    **scenario,
) -> Path:
    """The problem file with only the controllers ``keep`` (DeeP-LCC's data collection and the
    synthesised ones are not what is compared here), ``scenario`` keys and the metric
    ``window`` replaced."""
    data = tomllib.loads(path.read_text())
    if window is not None:
        data["metrics"]["window"] = window
    data["controllers"] = {k: v for k, v in data["controllers"].items() if k in keep}
    for c in data["controllers"].values():
        c.pop("fallback", None)
    data["scenario"].update(scenario)
    out = tmp_path / path.name
    out.write_text(tomli_w.dumps(data))
    return out


def _same_runs(a, b) -> None:
    for name in RESULT_FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


# --------------------------------------------------------------------------------------------
# lcc.system / lcc.ring: the problem file's vocabulary and validation
# --------------------------------------------------------------------------------------------


def test_system_builds_the_platoon_and_the_ring_of_the_files():
    for path in (PLATOON, RING):
        data = tomllib.loads(path.read_text())
        t, h = dict(data["system"]), dict(data["hdv"])
        hdv = lcc.OVM(**{k: v for k, v in h.items() if k != "model"})
        kind = t.pop("kind")
        api = (lcc.ring(hdv=hdv, **t) if kind == "ring" else lcc.system(hdv=hdv, **t))
        assert api == system_from(data) == lcc.load_problem(path).system
    platoon = lcc.system(size=8, cavs=[3, 6])  # no kind: the platoon vocabulary says it
    assert lcc.system(size=8, cavs=np.array([3, 6])) == lcc.system(size=8, cavs=(3, 6)) == platoon
    assert platoon.kind == "platoon" and platoon.platoon.cavs == (3, 6)
    assert (platoon.m, platoon.n) == (2, 6)  # vehicles ahead of / behind the first CAV
    ring = lcc.ring(20, cavs=[20])
    assert ring.kind == "ring" and ring.platoon.ring and ring.columns == 20
    assert lcc.system("ring", size=20, cavs=[20]) == ring  # the same thing, spelt as a file


@pytest.mark.parametrize(
    ("call", "table", "field"),
    [
        (lambda: lcc.system(size=0, cavs=[]), {"kind": "platoon", "size": 0, "cavs": []},
         "system.size"),
        (lambda: lcc.system(size=8, cavs=[3, 9]), {"kind": "platoon", "size": 8, "cavs": [3, 9]},
         "system.cavs"),
        (lambda: lcc.system("platoon", cavs=[3]), {"kind": "platoon", "cavs": [3]},
         "system.size"),
        (lambda: lcc.system("platoon", m=1, size=4), {"kind": "platoon", "m": 1, "size": 4},
         "system.m"),
        (lambda: lcc.system("fd_lcc", n=3, cavs=[1]), {"kind": "fd_lcc", "n": 3, "cavs": [1]},
         "system.cavs"),
        (lambda: lcc.system(size=3, cavs=[1], hdv_values={"alpha": [0.6, 0.6]}),
         {"kind": "platoon", "size": 3, "cavs": [1], "hdv_values": {"alpha": [0.6, 0.6]}},
         "system.hdv_values.alpha"),
        (lambda: lcc.ring(20, cavs=[20], v_star=15.0, circumference=400.0),
         {"kind": "ring", "size": 20, "cavs": [20], "v_star": 15.0, "circumference": 400.0},
         "system.circumference"),
        (lambda: lcc.system("lcc", n=2), {"kind": "lcc", "n": 2}, "system.m"),
        (lambda: lcc.system(size=8, cavs=3), {"kind": "platoon", "size": 8, "cavs": 3},
         "system.cavs"),
        (lambda: lcc.system(size=8, cavs=["3"]), {"kind": "platoon", "size": 8, "cavs": ["3"]},
         "system.cavs"),
    ],
)  # fmt: skip
def test_bad_layouts_fail_as_in_a_problem_file(call, table, field):
    with pytest.raises(ConfigError) as in_file:
        system_from({"system": table})
    with pytest.raises(ConfigError) as in_python:
        call()
    assert in_python.value.field == in_file.value.field
    assert in_python.value.field.startswith(field)
    assert str(in_python.value) == str(in_file.value)


# --------------------------------------------------------------------------------------------
# The analysis entry points take a System
# --------------------------------------------------------------------------------------------


def test_analysis_takes_a_system_or_its_model():
    string = lcc.system("lcc", m=1, n=2)
    model = string.linear_model()
    assert lcc.controllability(string).as_dict() == lcc.controllability(model).as_dict()
    assert lcc.observability(string).as_dict() == lcc.observability(model).as_dict()
    assert lcc.control_energy(lcc.system("fd_lcc", n=2), 10.0).as_dict() == (
        lcc.control_energy(lcc.model("fd_lcc", n=2), 10.0).as_dict())
    g = lcc.gains({"s_1": -0.5, "v_1": -0.5}, semantics="added")
    assert lcc.string_stability(string, g).as_dict() == lcc.string_stability(model, g).as_dict()
    ax = [-1.0, 0.0, 1.0]
    a, b = (lcc.region_map(m, 1, ax, ax) for m in (string, model))
    assert np.array_equal(a.labels, b.labels)
    # a platoon and a ring: the model of the package's platoon builder
    platoon = lcc.system(size=8, cavs=[3, 6])
    rep = lcc.controllability(platoon)
    assert rep.as_dict() == lcc.controllability(platoon_model(platoon.platoon)).as_dict()
    ring = lcc.ring(20, cavs=[20])
    rep = lcc.controllability(ring)
    assert rep.verdict == "controllable" and rep.conserved_mode  # on its invariant hyperplane
    assert lcc.observability(ring).verdict == "observable"


def test_analysis_of_something_else_says_what_to_pass():
    for wrong in ("fd_lcc", {"A": np.eye(2)}, np.eye(2)):
        with pytest.raises(ConfigError) as err:
            lcc.controllability(wrong)
        assert err.value.field == "model" and "lcc.system(...)" in err.value.message
    with pytest.raises(ConfigError, match="^model: "):
        lcc.string_stability(None, lcc.gains({}, semantics="added"))


def test_platoon_gains_are_stated_and_checked():
    platoon = lcc.system(size=8, cavs=[3, 6])
    table = {"u_3": {"s_3": 0.2, "v_3": -0.3}, "u_6": {"v_5": 0.1}}
    g = lcc.gains(table, semantics="added", model=platoon)
    direct = Gains.from_table(table, platoon.linear_model(), "added")
    assert np.array_equal(g.K, direct.K) and g.semantics == "added"
    rep = lcc.string_stability(platoon, g)
    assert rep.as_dict() == lcc.string_stability(platoon.linear_model(), direct).as_dict()
    with pytest.raises(ConfigError, match="^model: per-CAV gain tables"):
        lcc.gains(table, semantics="added")  # which platoon?
    with pytest.raises(ConfigError, match=r"^gains\.u_4: not a CAV input"):
        lcc.gains({"u_4": {"s_4": 1.0}}, semantics="added", model=platoon)
    with pytest.raises(ConfigError, match=r"^gain: .* for a platoon or ring, one table per CAV"):
        lcc.string_stability(platoon, lcc.gains({"s_3": 1.0}, semantics="added"))
    with pytest.raises(ConfigError, match=r"^gain: .* for one CAV .*, got gains for CAVs \[3, 6\]"):
        lcc.string_stability(lcc.model("lcc", 1, 1), g)
    with pytest.raises(ConfigError, match='^gain: a plain mapping does not say'):
        lcc.string_stability(platoon, table)


# --------------------------------------------------------------------------------------------
# A script and a problem file: equal objects, identical runs
# --------------------------------------------------------------------------------------------


def test_the_platoon_of_a_script_is_the_platoon_of_its_file(tmp_path):
    """``problems/platoon_deeplcc_brake.toml`` (its all-HDV and LQR controllers) written as a
    script: the DeeP-LCC paper's platoon, brake profile and heterogeneous HDVs."""
    data = tomllib.loads(PLATOON.read_text())
    objs = lcc.load_problem(_file_copy(PLATOON, tmp_path, ("all_hdv", "lqr")))
    platoon = lcc.system(
        size=8, cavs=[3, 6], v_star=15.0,
        hdv_values={"alpha": [0.45, 0.75, 0.6, 0.70, 0.50, 0.6, 0.40, 0.80],
                    "beta": [0.60, 0.95, 0.9, 0.95, 0.75, 0.9, 0.80, 1.00],
                    "s_go": [38.0, 31.0, 35.0, 33.0, 37.0, 35.0, 39.0, 34.0]},
    )  # fmt: skip
    head = lcc.Profile((1.0, 3.0, 8.0, 13.0), (-5.0, 0.0, 2.0, 0.0), "accel", vehicle="head")
    brake = lcc.scenario(platoon, [head], dt=0.05, duration=40.0, cav_aeb=True, hdv_aeb=True,
                         accel_noise_uniform=0.1, seed=0)  # fmt: skip
    lqr = lcc.gains(data["controllers"]["lqr"]["gains"], semantics="added", model=platoon)
    controllers = {"all_hdv": lcc.hdv_controller("all_hdv"),
                   "lqr": lcc.static_controller(platoon, lqr, "lqr")}  # fmt: skip
    metrics = lcc.MetricsConfig((0.0, 40.0), "first_cav_and_behind", "all_hdv", 9)
    assert platoon == objs.system and brake == objs.scenario and metrics == objs.metrics
    assert brake.cavs == (3, 6) and brake.spacing_reference == "own_equilibrium"
    built = lcc.build_problem(objs.name, platoon, brake, controllers, metrics).simulation
    assert built == replace(objs.simulation, source="python")  # every object, by value
    for name, ctrl in controllers.items():
        assert ctrl.as_dict() == objs.controllers[name].as_dict()
        _same_runs(lcc.simulate(brake, ctrl), lcc.simulate(objs.scenario, objs.controllers[name]))
    # and the analysis of the same objects
    assert lcc.controllability(platoon).as_dict() == lcc.controllability(objs.model).as_dict()
    rep = lcc.string_stability(platoon, lqr)
    assert rep.as_dict() == lcc.string_stability(objs.model, objs.controllers["lqr"].gains
                                                 ).as_dict()  # fmt: skip


def test_the_ring_of_a_script_is_the_ring_of_its_file(tmp_path):
    """``problems/ring_stop_and_go.toml`` (its all-HDV run and the MPC, 20 s) written as a
    script: 20 vehicles at 15 m/s, the last automated, vehicle 1 brakes at 5 s."""
    objs = lcc.load_problem(_file_copy(RING, tmp_path, ("all_hdv", "mpc"), [10.0, 20.0],
                                       duration=20.0))
    ring = lcc.ring(20, cavs=[20], v_star=15.0)
    wave = lcc.scenario(ring, [lcc.Brake(vehicle=1, start=5.0, duration=1.0, decel=-1.0)],
                        dt=0.01, record_every=5, duration=20.0, cav_aeb=True, hdv_aeb=True)
    controllers = {"all_hdv": lcc.hdv_controller("all_hdv"),
                   "mpc": lcc.mpc(ring, sample_time=0.1, horizon=50)}  # fmt: skip
    assert ring == objs.system and wave == objs.scenario
    assert wave.ring and wave.cavs == (19,)  # the ring's column j is position j + 1
    for name, ctrl in controllers.items():
        assert ctrl.as_dict() == objs.controllers[name].as_dict()
        _same_runs(lcc.simulate(wave, ctrl), lcc.simulate(objs.scenario, objs.controllers[name]))
    v = lcc.simulate(wave, controllers["all_hdv"]).velocity
    assert np.ptp(v[0, -1]) > 0  # the brake reached the ring (the comparison is not vacuous)


def test_scenario_checks_the_layout_as_a_file_does():
    platoon = lcc.system(size=8, cavs=[3, 6])
    with pytest.raises(ConfigError, match=r"^scenario\.perturbations\[0\]\.vehicle: must be an "
                                          r"integer position in \[1, 8\]"):  # fmt: skip
        lcc.scenario(platoon, [lcc.Brake(vehicle=9)])
    with pytest.raises(ConfigError, match=r"^scenario\.perturbations\[0\]\.vehicle"):
        lcc.scenario(lcc.ring(20, cavs=[20]), [lcc.Brake(vehicle="head")])  # a ring has none
    with pytest.raises(ConfigError, match=r"^scenario\.hdv_values: kind = 'platoon' takes"):
        lcc.scenario(platoon, hdv_values={"alpha": np.full(9, 0.6)})
    with pytest.raises(ConfigError, match=r"^scenario\.spacing_reference: must be "):
        lcc.scenario(platoon, spacing_reference="nominal")
    with pytest.raises(ConfigError, match=r"^system\.cavs: simulate needs at least one CAV"):
        lcc.scenario(lcc.system(size=4, cavs=[]))
    with pytest.raises(ConfigError, match=r"^scenario\.perturbations\[0\]\.start"):
        lcc.scenario(lcc.system("fd_lcc", n=2), [lcc.Brake(vehicle=1, start=200.0)])


# --------------------------------------------------------------------------------------------
# The public string-stability analysis on every layout
# --------------------------------------------------------------------------------------------

_LAYOUTS = {
    "one_cav": lambda: lcc.system("lcc", m=1, n=2),
    "two_cav": lambda: lcc.system(size=5, cavs=[2, 4]),
    "ring": lambda: lcc.ring(6, cavs=[6]),
}


def _layout_gains(name, system):
    """Gains on every CAV's own spacing and velocity, added to its HDV law (one CAV: and the
    tail's velocity, in the paper's vocabulary)."""
    if name == "one_cav":
        return lcc.gains({"s_0": 0.2, "v_0": -0.3, "v_2": 0.1}, semantics="added")
    cavs = system.platoon.cavs
    return lcc.gains({f"u_{c}": {f"s_{c}": 0.2, f"v_{c}": -0.3} for c in cavs},
                     semantics="added", model=system)  # fmt: skip


@pytest.mark.parametrize("name", list(_LAYOUTS))
def test_public_string_stability_on_every_layout(name):
    """``lcc.string_stability`` of a System: on the open layouts its peak of |Gamma| is the
    peak of the head-to-tail transfer ``e_tail (jw I - A - B K)^-1 (H + B k_h)`` written out
    here from the model's matrices and the gains' ``input_feedback`` (a dense frequency grid
    refined around its best point; 1e-9 relative), the verdict its comparison with 1; a ring
    has no head vehicle: one ConfigError naming ``system.kind``."""
    system = _LAYOUTS[name]()
    model = system.linear_model(warn=False)
    g = _layout_gains(name, system)
    if model.ring:
        with pytest.raises(ConfigError) as err:
            lcc.string_stability(system, g)
        assert err.value.field == "system.kind" and "no head vehicle" in err.value.message
        return
    K, kh = g.input_feedback(model)
    B = np.asarray(model.B, float).reshape(model.nx, -1)
    Acl = model.A + B @ np.atleast_2d(K)
    h = np.asarray(model.H, float).reshape(model.nx, -1)[:, 0] + B @ np.atleast_1d(kh)
    assert model.state_names[-1] == f"v_{model.vehicles[-1]}"  # the tail's velocity

    def gamma(w):
        return np.linalg.solve(1j * w[:, None, None] * np.eye(model.nx) - Acl, h)[:, -1]

    w = np.logspace(-3, 2, 4001)
    j = int(np.argmax(np.abs(gamma(w))))
    fine = np.linspace(w[max(j - 1, 0)], w[min(j + 1, w.size - 1)], 4001)
    peak = max(1.0, float(np.abs(gamma(fine)).max()))
    rep = lcc.string_stability(system, g)
    assert rep.plant_stable and np.linalg.eigvals(Acl).real.max() < 0
    assert rep.gamma_peak == pytest.approx(peak, rel=1e-9)
    assert rep.verdict == ("string_stable" if peak <= 1.0 + 1e-9 else "string_unstable")


def test_synthesize_h2_has_h2_problems_parameters_and_designs_every_layout():
    """``help(lcc.synthesize_h2)`` shows the options it takes (those of ``h2_problem``, not
    ``*args``), and the same call designs a platoon's gain as its problem file does."""
    import inspect

    sig = inspect.signature(lcc.synthesize_h2).parameters
    assert list(sig)[1:] == list(inspect.signature(lcc.h2_problem).parameters)[1:]
    system = lcc.system(size=6, cavs=[2, 5])
    rep = lcc.synthesize_h2(system, "structured", comm_range=1, weights={"q_s": 0.5})
    spec = lcc.h2_problem(system, "structured", comm_range=1, weights={"q_s": 0.5})
    again = lcc.synthesize_h2(spec)  # the same spec, whichever way it is given
    assert again.K == rep.K and again.check == rep.check  # (the timings differ)
    assert rep.patterns == {"u_2": [1, 2, 3], "u_5": [4, 5, 6]}
    with pytest.raises(ConfigError, match="a spec alone"):
        lcc.synthesize_h2(spec, comm_range=2)
