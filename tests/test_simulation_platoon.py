"""The simulator with several CAVs and on the ring road, against independent truth.

* a platoon with one CAV is the paper's single-CAV string, bit for bit (same law, same gains);
* the ring with every vehicle driving as an HDV conserves the total spacing to round-off, and
  a small perturbation grows at the rate of the linear ring's most unstable mode (fitted from
  the velocity spread, which is exactly ``A e^{rt} / sqrt 2`` for a travelling Fourier mode);
* a two-CAV platoon with static gains follows the Euler discretisation of
  ``Gains.closed_loop`` up to the nonlinear terms, cubic in the size of the
  perturbation at the OVM's inflection ``v* = v_max / 2`` (checked by doubling it);
* emergency braking (eq. 29) and collisions per vehicle, checked on the recorded states;
* bad layouts are named-field errors and exit code 2.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lcc_synth.cli.main import main
from lcc_synth.controllers.static import HDVController, PlatoonGainController, StaticGainController
from lcc_synth.errors import ConfigError
from lcc_synth.experiments.spec import load_spec
from lcc_synth.metrics import aeb_activations, fuel, smooth_acceleration
from lcc_synth.models.feedback import Gains
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import model_from_hdv
from lcc_synth.models.platoon import Platoon, platoon_model
from lcc_synth.simulation.engine import simulate
from lcc_synth.simulation.perturbations import Brake, Profile
from lcc_synth.simulation.scenario import Scenario

ROOT = Path(__file__).resolve().parents[1]
RING = ROOT / "problems" / "ring_stop_and_go.toml"
PLATOON = ROOT / "problems" / "platoon_deeplcc_brake.toml"
EPS = np.finfo(float).eps


def _platoon_scenario(models, cavs, ring=False, **kw) -> Scenario:
    """A Scenario of a :class:`Platoon` (``cavs`` positions), as ``scenario_from`` builds it."""
    P = Platoon(tuple(models), tuple(cavs), 15.0, ring)
    nv = P.size if ring else P.size + 1
    cols = tuple(c - 1 if ring else c for c in P.cavs)
    off = 0 if ring else 1
    hdv = OVM()
    values = {}
    for key in ("alpha", "beta", "s_st", "s_go", "v_max"):
        full = np.full(nv, float(getattr(hdv, key)))
        full[off:] = [getattr(h, key) for h in models]
        values[key] = full
    base = dict(m=cols[0] - 1, n=nv - 1 - cols[0], hdv=hdv, v_star=15.0, cavs=cols, ring=ring,
                circumference=P.length, hdv_values=values, spacing_reference="own_equilibrium",
                cav_aeb=False)  # fmt: skip
    base.update(kw)
    return Scenario(**base), P


# --------------------------------------------------------------------------------------------
# one CAV: the same code path as the paper's string
# --------------------------------------------------------------------------------------------


def test_platoon_with_one_cav_is_the_single_cav_string_bit_for_bit():
    brake = dict(start=2.0, duration=1.0, decel=-3.0)
    single = Scenario(m=2, n=3, duration=20.0, perturbations=(Brake(vehicle=-2, **brake),))
    model = model_from_hdv("lcc", 2, 3, OVM(), 15.0, warn=False)
    g_single = {"s_-2": 0.1, "v_-1": 0.2, "s_0": -0.3, "v_0": -0.5, "v_2": 0.1}
    ctrl1 = StaticGainController("k", Gains.named(g_single, "added"), model)
    sc, P = _platoon_scenario([OVM()] * 6, [3], duration=20.0, cav_aeb=True,
                              perturbations=(Brake(vehicle=1, **brake),))  # fmt: skip
    pm = platoon_model(P, warn=False)
    table = {"u_3": {"s_1": 0.1, "v_2": 0.2, "s_3": -0.3, "v_3": -0.5, "v_5": 0.1}}
    ctrl2 = PlatoonGainController("k", Gains.from_table(table, pm, "added"), pm)
    for a, b in ((HDVController(), HDVController()), (ctrl1, ctrl2)):
        r1, r2 = simulate(single, a), simulate(sc, b)
        assert r1.u_cmd.shape == r2.u_cmd.shape == (1, single.steps)
        for key in ("position", "velocity", "acceleration", "spacing", "u_cmd"):
            assert np.array_equal(getattr(r1, key), getattr(r2, key), equal_nan=True), key


# --------------------------------------------------------------------------------------------
# the ring
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def ring_spec():
    return load_spec(RING)


def test_ring_all_hdv_conserves_the_total_spacing_to_round_off(ring_spec):
    sc = ring_spec.scenario
    r = simulate(sc, ring_spec.controllers["all_hdv"])
    C = sc.circumference
    total = r.spacing[0].sum(axis=1)
    # every spacing is a difference of positions of magnitude <= max|p| (+ C for column 0):
    # each carries <= eps (max|p| + C) of round-off, and so does the sum of N of them
    bound = 2 * sc.n_vehicles * EPS * (np.abs(r.position).max() + C)
    assert np.abs(total - C).max() <= bound
    assert r.ring and r.cavs == (19,) and not r.collided.any()
    # the wave: the velocity spread grows, vehicles nearly stop; the AV damps it
    av = simulate(sc, ring_spec.controllers["av"])
    std = r.velocity[0].std(axis=1)
    std_av = av.velocity[0].std(axis=1)
    k50, k250 = (int(round(t / r.dt)) for t in (50.0, 250.0))
    assert std[k250] > 10.0 > 1.0 > std[k50] and r.velocity[0, k250:].min() < 0.5
    assert std_av[k50] < 1e-3 and np.abs(av.velocity[0, k50:] - 15.0).max() < 1e-2
    assert np.abs(av.spacing[0].sum(axis=1) - C).max() <= bound


def test_ring_wave_grows_at_the_rate_of_the_linear_rings_unstable_mode(ring_spec):
    # dt = 0.005 s: Euler's growth rate within 1.7 % of the mode's (the file's 0.01 s: 3.4 %)
    sc = replace(ring_spec.scenario, duration=250.0, dt=0.005, record_every=10,
                 hdv_aeb=False, cav_aeb=False,
                 perturbations=(Brake(vehicle=1, start=5.0, duration=1.0, decel=-0.0005),))
    r = simulate(sc, HDVController())
    P = Platoon(tuple([sc.hdv] * 20), (20,), 15.0, True)
    M = platoon_model(P, warn=False)
    A = Gains.zero(M, "added").closed_loop(M)[0]
    V = M.invariant_basis()
    lam = np.linalg.eigvals(V.T @ A @ V)
    lam = lam[np.argsort(-lam.real)]
    # explicit Euler advances a mode by 1 + lam dt per step: the simulated growth rate
    rate = np.log(np.abs(1.0 + sc.dt * lam[0])) / sc.dt
    gap = lam[0].real - lam[2].real  # to the next mode pair
    t = r.t
    w = (t >= 100.0) & (t <= 250.0)
    std = r.velocity[0, w].std(axis=1)
    slope = np.polyfit(t[w], np.log(std), 1)[0]
    # the next mode's share decays as exp(-gap t): below exp(-gap * 100 s) = 0.7 % of the
    # fitted amplitude; the nonlinear terms are ~ amplitude (< 0.05 m/s) relative
    assert gap * 100.0 > 5.0 and std.max() < 0.05
    assert slope == pytest.approx(rate, rel=0.01)
    assert lam[0].real > 0 and rate == pytest.approx(lam[0].real, rel=0.03)


def test_ring_collision_of_position_1_with_position_n():
    sc, _ = _platoon_scenario([OVM()] * 5, [1], ring=True, duration=30.0,
                              perturbations=(Brake(vehicle=5, start=1.0, duration=3.0,
                                                   decel=-5.0),))  # fmt: skip
    pm = platoon_model(Platoon(tuple([OVM()] * 5), (1,), 15.0, True), warn=False)
    cruise = PlatoonGainController("cruise", Gains.zero(pm, "replace"), pm)
    r = simulate(sc, cruise)  # position 1 (column 0) keeps 15 m/s: it hits position 5
    assert r.collided[0].tolist() == [True, False, False, False, False]
    k = int(np.flatnonzero(r.t == r.collision_time[0, 0])[0])
    assert r.spacing[0, k, 0] <= 0.0 < r.spacing[0, k - 1, 0]
    assert np.isnan(r.velocity[0, k + 1:]).all()
    assert "vehicle CAV 1 hit vehicle 5" in r.collision_report()[0]


# --------------------------------------------------------------------------------------------
# two CAVs
# --------------------------------------------------------------------------------------------

_HETERO = [OVM(alpha=a, beta=b, s_go=g) for a, b, g in
           zip((0.45, 0.6, 0.7, 0.5, 0.6, 0.8), (0.6, 0.9, 0.95, 0.75, 0.9, 1.0),
               (38.0, 35.0, 33.0, 37.0, 35.0, 34.0), strict=True)]  # fmt: skip


def _lqr_gains(M) -> Gains:
    import scipy.linalg as sla

    from lcc_synth.models.platoon import hdv_law_rows

    A = M.A + M.B @ hdv_law_rows(M)
    X = sla.solve_continuous_are(A, M.B, np.eye(M.nx), np.eye(M.B.shape[1]))
    return Gains.on(M, -(M.B.T @ X), "added")


def test_two_cav_platoon_follows_the_linear_closed_loop_to_second_order():
    P = Platoon(tuple(_HETERO), (2, 5), 15.0)
    M = platoon_model(P, warn=False)
    gains = _lqr_gains(M)
    ctrl = PlatoonGainController("lqr", gains, M)
    A_cl, H_cl = gains.closed_loop(M)
    assert np.linalg.eigvals(A_cl).real.max() < 0

    def deviation(eps: float) -> tuple[float, float]:
        head = Profile((1.0, 3.0, 5.0), (-eps, eps, 0.0), vehicle="head")
        sc, _ = _platoon_scenario(_HETERO, [2, 5], dt=0.01, duration=30.0,
                                  perturbations=(head,))  # fmt: skip
        r = simulate(sc, ctrl)
        assert r.u_cmd.shape == (1, sc.steps, 2) and r.aeb_active.shape == (1, sc.steps, 2)
        s_eq = P.equilibrium_spacings
        x_sim = np.empty((sc.steps, M.nx))
        x_sim[:, 0::2] = r.spacing[0, :, 1:] - s_eq
        x_sim[:, 1::2] = r.velocity[0, :, 1:] - 15.0
        vh = r.velocity[0, :, 0] - 15.0  # the head's prescribed motion
        # the simulator's Euler scheme on the linear loop: x+ = x + dt (A_cl x + H_cl v_h)
        x = np.zeros(M.nx)
        err = 0.0
        for k in range(sc.steps):
            err = max(err, float(np.abs(x_sim[k] - x).max()))
            x = x + sc.dt * (A_cl @ x + H_cl[:, 0] * vh[k])
        return err, float(np.abs(x_sim).max())

    e1, size1 = deviation(0.05)
    e2, size2 = deviation(0.1)
    # at v* = v_max / 2 every OVM sits at the inflection of its optimal velocity (V''(s*) = 0
    # for any s_go): the leading nonlinear term is cubic, so doubling the perturbation
    # multiplies the deviation by 8; it stays a small fraction of the response
    assert e2 / e1 == pytest.approx(8.0, rel=0.05)
    assert e1 < 0.02 * size1 and size2 == pytest.approx(2 * size1, rel=0.02)


def test_emergency_braking_and_collisions_per_cav():
    head = Brake(vehicle="head", start=1.0, duration=2.5, decel=-5.0)
    pm = platoon_model(Platoon(tuple(_HETERO), (2, 5), 15.0), warn=False)
    cruise = PlatoonGainController("cruise", Gains.zero(pm, "replace"), pm)
    sc, _ = _platoon_scenario(_HETERO, [2, 5], dt=0.01, duration=20.0, cav_aeb=True,
                              perturbations=(head,))  # fmt: skip
    r = simulate(sc, cruise)  # the CAVs hold their speed: only eq. (29) brakes them
    aeb = r.aeb_active[0]
    assert aeb[:, 0].any() and aeb[:, 1].any() and not r.collided.any()
    v, s = r.velocity[0], r.spacing[0]
    for k_cav, col in enumerate((2, 5)):
        crit = (v[:, col] ** 2 - v[:, col - 1] ** 2) / (2 * s[:, col]) >= 5.0
        assert np.array_equal(aeb[:, k_cav], crit)  # eq. (29) on this CAV's own state
        on = aeb[:, k_cav]
        assert np.allclose(r.acceleration[0, on, col], -5.0)  # a_min (velocity > 0 there)
        assert np.all(r.acceleration[0, ~on, col] == 0.0)  # the held command 0
    assert aeb_activations(r)[0] == int(aeb.sum())
    # without emergency braking the first CAV hits the vehicle ahead of it
    r = simulate(replace(sc, cav_aeb=False), cruise)
    assert np.flatnonzero(r.collided[0]).tolist() == [2]
    k = int(np.flatnonzero(r.t == r.collision_time[0, 2])[0])
    assert r.spacing[0, k, 2] <= 0.0 < r.spacing[0, k - 1, 2]
    assert "vehicle CAV 2 hit vehicle 1" in r.collision_report()[0]


# --------------------------------------------------------------------------------------------
# fuel of the DeeP-LCC paper, problem files, gains files, bad input
# --------------------------------------------------------------------------------------------


def test_smoothed_fuel_is_the_moving_average_of_the_accelerations():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(2, 30, 3))
    sm = smooth_acceleration(a, 9)
    for k in range(30):  # the window shrinks at the ends (MATLAB movmean)
        lo, hi = max(0, k - 4), min(30, k + 5)
        assert np.allclose(sm[:, k], a[:, lo:hi].mean(axis=1), rtol=0, atol=1e-14)
    assert smooth_acceleration(a, 1) is not None and np.array_equal(smooth_acceleration(a, 1), a)


def test_platoon_problem_file_runs_and_its_fuel_uses_the_smoothed_accelerations():
    spec = load_spec(PLATOON)
    sc = spec.scenario
    assert sc.cav_columns == (3, 6) and sc.accel_noise_uniform == 0.1 and sc.dt == 0.05
    assert np.allclose(sc.hdv_values["alpha"], [0.6, 0.45, 0.75, 0.6, 0.7, 0.5, 0.6, 0.4, 0.8])
    r = simulate(sc, spec.controllers["all_hdv"])
    head = r.velocity[0, :, 0]
    assert head.min() == pytest.approx(5.0, abs=1e-9) and head[-1] == pytest.approx(15.0, abs=1e-9)
    # the uniform noise is added after the limits: accelerations up to a_max + 0.1
    assert 2.0 < np.nanmax(r.acceleration[0, :, 1:]) <= 2.1
    cols = np.arange(3, 9)
    v = r.velocity[:, :, cols]
    a_s = smooth_acceleration(r.acceleration[:, :, cols], 9)
    R = 0.333 + 0.00108 * v**2 + 1.2 * a_s
    f = np.where(R > 0, 0.444 + 0.09 * R * v + 0.054 * np.maximum(a_s, 0) ** 2 * v, 0.444)
    assert fuel(r, (0.0, 40.0), "first_cav_and_behind", 9)[0] == pytest.approx(
        f.sum() * r.dt, rel=1e-12
    )


# slow: the platoon file (45 s) runs in-process in
# test_platoon_problem_file_runs_and_its_fuel_uses_the_smoothed_accelerations; the CLI path is
# the ring's
@pytest.mark.parametrize("path", [pytest.param(PLATOON, marks=pytest.mark.slow), RING])
def test_cli_simulate_json_on_the_platoon_and_ring_files(path, capsys):
    assert main(["simulate", str(path), "--json", "--no-record"]) == 0
    rep = json.loads(capsys.readouterr().out)["results"]
    assert set(rep) >= {"all_hdv"} and len(rep) >= 2
    for e in rep.values():
        assert e["collisions"] == 0 and e["min_spacing"] > 0


def test_ring_gains_file_matches_the_inline_gains(tmp_path, ring_spec):
    av = ring_spec.controllers["av"]
    P = ring_spec.system.platoon
    data = {
        "kind": "ring", "size": P.size, "cavs": list(P.cavs), "ring": True,
        "semantics": "replace", "state_names": list(av.model.state_names),
        "K": av.gains.K.tolist(), "gains": av.gains.as_table(), "h2_true": 1.0,
    }  # fmt: skip
    (tmp_path / "gains.json").write_text(json.dumps(data))
    text = RING.read_text().split("[controllers.av]")[0]
    text += '[controllers.av]\ntype = "gains_file"\nfile = "gains.json"\n'
    (tmp_path / "ring.toml").write_text(text)
    spec = load_spec(tmp_path / "ring.toml")
    sc = replace(spec.scenario, duration=30.0)
    a, b = simulate(sc, spec.controllers["av"]), simulate(sc, av)
    assert np.array_equal(a.velocity, b.velocity)
    data["cavs"] = [19]
    (tmp_path / "gains.json").write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=r"controllers\.av\.file"):
        load_spec(tmp_path / "ring.toml")


def _variant(tmp_path, path: Path, old: str, new: str) -> Path:
    text = path.read_text()
    assert old in text
    out = tmp_path / path.name
    out.write_text(text.replace(old, new, 1))
    return out


@pytest.mark.parametrize(
    "path, old, new, field",
    [
        (PLATOON, "cavs = [3, 6]", "cavs = [3, 9]", r"system\.cavs"),
        (PLATOON, "cavs = [3, 6]", "cavs = []", r"system\.cavs"),
        (RING, "v_star = 15.0", "circumference = 60.0", r"system\.circumference"),
        (RING, "vehicle = 1\n", 'vehicle = "head"\n', r"scenario\.perturbations\[0\]\.vehicle"),
        (PLATOON, "[controllers.lqr.gains.u_3]", "[controllers.lqr.gains.u_4]",
         r"controllers\.lqr\.gains\.u_4"),
    ],
)
def test_bad_layouts_are_named_field_errors_and_exit_2(tmp_path, capsys, path, old, new, field):
    bad = _variant(tmp_path, path, old, new)
    with pytest.raises(ConfigError, match=field):
        load_spec(bad)
    assert main(["simulate", str(bad), "--json", "--no-record"]) == 2
    assert "Traceback" not in capsys.readouterr().err


class _PythonPath:
    """A controller without ``linear_law``: the simulator calls it from Python every sample."""

    def __init__(self, inner):
        self.inner, self.name, self.sample_time = inner, inner.name, inner.sample_time

    def reset(self, ctx):
        self.inner.reset(ctx)

    def __call__(self, obs):
        return self.inner(obs)

    def describe(self):
        return self.inner.describe()

    def stats(self):
        return {}


@pytest.mark.parametrize("ring", [False, True])
def test_python_controller_path_with_several_cavs_equals_the_compiled_law(ring):
    models = _HETERO[:5] if ring else _HETERO
    cavs = (2, 5)
    P = Platoon(tuple(models), cavs, 15.0, ring)
    M = platoon_model(P, warn=False)
    gains = _lqr_gains(M) if not ring else Gains.on(
        M, np.tile([-0.1, -0.5] * 5, (2, 1)) * 0.3, "added"
    )
    ctrl = PlatoonGainController("k", gains, M)
    pert = Brake(vehicle=1, start=1.0, duration=1.0, decel=-2.0)
    sc, _ = _platoon_scenario(models, cavs, ring=ring, duration=15.0, cav_aeb=True,
                              perturbations=(pert,))  # fmt: skip
    a = simulate(sc, ctrl)
    b = simulate(sc, _PythonPath(ctrl))
    assert b.u_cmd.shape == a.u_cmd.shape == (1, sc.steps, 2)
    np.testing.assert_allclose(b.u_cmd, a.u_cmd, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.velocity, a.velocity, rtol=0, atol=1e-9)
    assert np.ptp(a.u_cmd) > 0.1  # the law did something
    # the HDV law on every CAV, its own slot's parameters, both paths
    a = simulate(sc, HDVController())
    b = simulate(sc, _PythonPath(HDVController()))
    np.testing.assert_allclose(b.velocity, a.velocity, rtol=0, atol=1e-9)


def test_hdv_controller_drives_every_cav_with_its_own_slots_law():
    # every position its own parameters (the CAV slots too): with every CAV driving its HDV
    # law the run cannot depend on which positions are CAVs, bit for bit
    models = [OVM(alpha=a, beta=b, s_go=g) for a, b, g in
              zip((0.45, 0.55, 0.7, 0.5, 0.65, 0.8), (0.6, 0.85, 0.95, 0.75, 0.7, 1.0),
                  (38.0, 36.0, 33.0, 37.0, 34.5, 34.0), strict=True)]  # fmt: skip
    head = Brake(vehicle="head", start=1.0, duration=2.0, decel=-3.0)
    runs = []
    for cavs in ((2, 5), (1,), (6,)):
        sc, _ = _platoon_scenario(models, cavs, duration=20.0, perturbations=(head,))
        runs.append(simulate(sc, HDVController()))
    for r in runs[1:]:
        assert np.array_equal(r.velocity, runs[0].velocity)
        assert np.array_equal(r.spacing, runs[0].spacing, equal_nan=True)
    assert np.ptp(runs[0].velocity[0, :, 2]) > 2.0
