"""SUMO versus the built-in simulator on the ring road and with several CAVs: the figures of
``tests/test_sumo_ring.py`` and ``docs/guide/sumo.md`` ("The ring road and several CAVs in SUMO").

* ``problems/sumo_ring_stop_and_go.toml`` (20 IDM vehicles, CAVs at 10 and 20): AAVE, fuel,
  minimum spacing per controller in both simulators, and the wall time of each run;
* Sugiyama's ring (22 IDM vehicles, 230 m with 5 m cars = 120 m of gaps, a 0.1 m/s dip):
  max |dv| and |ds| between the simulators up to 60 / 100 / 150 s at dt = 0.1 and 0.05 s, and
  the wave's growth rate (wavenumber 1 and 2) in each against its scheme's prediction;
* two CAVs on the open road (the tests' platoon): max |dv|, |ds|, AAVE and fuel per controller.

Wall times are the median of ``--repeat`` runs after one warm-up run (numba compilation,
netconvert).

    python benchmarks/bench_sumo_ring.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from lcc_synth.controllers.static import HDVController
from lcc_synth.experiments.spec import load_spec
from lcc_synth.metrics import MetricsConfig, aggregate, per_scenario
from lcc_synth.models.platoon import Platoon, platoon_model
from lcc_synth.simulation.backends import run_scenario
from lcc_synth.simulation.sumo_net import SumoSettings

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_sumo_ring import (  # noqa: E402
    C_SUGI,
    IDM_RING,
    L_CAR,
    N_SUGI,
    _platoon_case,
    _ring,
    _wave_rates,
)


def _timed(sc, ctrl, repeat: int):
    run_scenario(sc, ctrl)
    times, res = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = run_scenario(sc, ctrl)
        times.append(time.perf_counter() - t0)
    return res, float(np.median(times))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    spec = load_spec(ROOT / "problems" / "sumo_ring_stop_and_go.toml")
    print("problems/sumo_ring_stop_and_go.toml (SUMO / built-in)")
    for name, ctrl in spec.controllers.items():
        out = {}
        for tag, sc in (("sumo", spec.scenario), ("builtin", replace(spec.scenario,
                                                                     backend="builtin"))):
            res, wall = _timed(sc, ctrl, args.repeat)
            out[tag] = (aggregate(per_scenario(res, spec.metrics)), wall)
        (ms, ws), (mb, wb) = out["sumo"], out["builtin"]
        print(f"  {name:8s} AAVE {ms['aave']:.4f} / {mb['aave']:.4f}  fuel "
              f"{ms['fuel_ml']:.2f} / {mb['fuel_ml']:.2f}  min s {ms['min_spacing']:.2f} / "
              f"{mb['min_spacing']:.2f}  wall {ws:.2f} / {wb:.3f} s", flush=True)  # fmt: skip

    print("Sugiyama ring, all HDV (22 IDM, 120 m of gaps), SUMO euler vs built-in")
    A = platoon_model(Platoon((IDM_RING,) * N_SUGI, (), None, True, C_SUGI)).A
    phase = np.exp(-2j * np.pi * np.arange(N_SUGI) / N_SUGI)
    ctrl = HDVController("all_hdv")
    for dt in (0.1, 0.05):
        sc = _ring(N_SUGI, C_SUGI, (N_SUGI - 1,), {"type": "brake", "vehicle": 1, "start": 1.0,
                                                   "duration": 1.0, "decel": -0.1},
                   dt=dt, duration=150.0, sumo=SumoSettings(vehicle_length=L_CAR))  # fmt: skip
        rs, ws = _timed(sc, ctrl, args.repeat)
        rb, wb = _timed(replace(sc, backend="builtin"), ctrl, args.repeat)
        diffs = []
        for horizon in (60.0, 100.0, 150.0):
            k = rs.t <= horizon
            dv = np.max(np.abs(rs.velocity[0, k] - rb.velocity[0, k]))
            ds = np.max(np.abs(rs.spacing[0, k] - rb.spacing[0, k]))
            diffs.append(f"<= {horizon:g} s: |dv| {dv:.4f} |ds| {ds:.4f}")
        print(f"  dt={dt:g}: " + "; ".join(diffs) + f"  wall {ws:.2f} / {wb:.3f} s")
        w = (rs.t >= 50.0) & (rs.t <= 150.0)
        for res, scheme in ((rs, "euler"), (rb, "builtin")):
            pred = _wave_rates(A, dt, scheme, N_SUGI)
            got = [np.polyfit(res.t[w], np.log(np.abs(((res.velocity[0] - sc.v_star)
                                                       * phase**q).sum(axis=1))[w]), 1)[0]
                   for q in (1, 2)]  # fmt: skip
            print(f"    {scheme:8s} growth k=1 {got[0]:.5f} (scheme {pred[1]:.5f}), "
                  f"k=2 {got[1]:.5f} (scheme {pred[2]:.5f}) 1/s")  # fmt: skip

    print("two CAVs (3, 6) on the open road, IDM HDVs, head brake profile, dt = 0.01 s")
    sc, ctrls = _platoon_case()
    cfg = MetricsConfig(window=(0.0, 40.0), vehicles="first_cav_and_behind")
    for name, c in ctrls.items():
        rs, ws = _timed(sc, c, args.repeat)
        rb, wb = _timed(replace(sc, backend="builtin"), c, args.repeat)
        ms, mb = per_scenario(rs, cfg), per_scenario(rb, cfg)
        print(f"  {name:12s} |dv| {np.nanmax(np.abs(rs.velocity - rb.velocity)):.4f} |ds| "
              f"{np.nanmax(np.abs(rs.spacing - rb.spacing)):.4f}  AAVE {ms['aave'][0]:.4f} / "
              f"{mb['aave'][0]:.4f}  fuel {ms['fuel_ml'][0]:.2f} / {mb['fuel_ml'][0]:.2f}  "
              f"wall {ws:.2f} / {wb:.3f} s", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
