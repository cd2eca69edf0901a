"""Cost of the string-stable region maps (Figs. 7-8) on the paper's full grid.

mu, k in [-10, 10] with step 0.02 (1001 x 1001 = 1,002,001 points) for each of vehicles -2, -1,
1, 2 (m = n = 2, OVM at v* = 15 m/s, no other gains), with the default frequency grid. Prints
the wall time and the cost per grid point, and for comparison the cost of the exact per-point
check (:func:`lcc_synth.analysis.string_stability.string_stability`) that the map replaces.
Then the same grid on an open platoon of 7 OVM vehicles with CAVs at 2 and 5 (each map the
varied CAV's segment times the other segment's fixed polynomials): CAV 2 on vehicles 1 and 3,
CAV 5 on vehicles 6 and 7, the other CAV's gains fixed.

Usage: python benchmarks/bench_regions.py [STEP]   (default 0.02)
"""

from __future__ import annotations

import sys
import time

import numpy as np

from lcc_synth.analysis.region_specs import grid_axis
from lcc_synth.analysis.regions import region_frequency_grid, region_map
from lcc_synth.analysis.string_stability import string_stability
from lcc_synth.models.feedback import Gains, input_feedback
from lcc_synth.models.hdv import OVM
from lcc_synth.models.linear import general_lcc
from lcc_synth.models.platoon import Platoon, platoon_model


def main(argv: list[str]) -> int:
    step = float(argv[0]) if argv else 0.02
    model = general_lcc(2, 2, OVM().linear_coefficients(15.0))
    axis = grid_axis(-10.0, 10.0, step)
    omega = region_frequency_grid()
    region_map(model, 1, axis[:3], axis[:3], omega=omega)  # warm-up (imports, caches)
    print(f"grid {axis.size} x {axis.size} = {axis.size**2:,} points, {omega.size} frequencies")
    total = 0.0
    for vehicle in (-2, -1, 1, 2):
        t0 = time.perf_counter()
        rm = region_map(model, vehicle, axis, axis, omega=omega)
        dt = time.perf_counter() - t0
        total += dt
        print(
            f"vehicle {vehicle:>2}: {dt:6.2f} s total, {1e6 * dt / rm.points:6.3f} us/point; "
            f"plant stable {100 * rm.plant_stable_fraction:6.2f}%, "
            f"string stable {100 * rm.string_stable_fraction:6.2f}%"
        )
    print(f"all four maps: {total:.2f} s")
    rng = np.random.default_rng(0)
    pts = rng.uniform(-10, 10, size=(100, 2))
    t0 = time.perf_counter()
    for mu, k in pts:
        K, kh = input_feedback(model, Gains.named({"s_1": mu, "v_1": k}))
        string_stability(model, K, kh)
    per = (time.perf_counter() - t0) / len(pts)
    print(
        f"exact per-point check (string_stability, vehicle 1): {1e3 * per:.2f} ms/point, "
        f"i.e. {per * axis.size**2 / 3600:.1f} h for one full map"
    )
    platoon = platoon_model(Platoon((OVM(),) * 7, (2, 5), 15.0), warn=False)
    fixed = {"u_2": {"s_3": -1.0, "v_3": -1.0}, "u_5": {"s_6": 0.5, "v_6": -0.5}}
    total = 0.0
    for cav, vehicle in ((2, 1), (2, 3), (5, 6), (5, 7)):
        table = {u: {n: g for n, g in row.items() if n[2:] != str(vehicle)}
                 for u, row in fixed.items()}  # fmt: skip
        gains = Gains.from_table(table, platoon, "added")
        t0 = time.perf_counter()
        rm = region_map(platoon, vehicle, axis, axis, gains, omega=omega, cav=cav)
        dt = time.perf_counter() - t0
        total += dt
        print(
            f"platoon CAV {cav}, vehicle {vehicle}: {dt:6.2f} s, {1e6 * dt / rm.points:6.3f} "
            f"us/point; plant stable {100 * rm.plant_stable_fraction:6.2f}%, string stable "
            f"{100 * rm.string_stable_fraction:6.2f}%, boundary {int(rm.boundary.sum())}"
        )
    print(f"all four platoon maps: {total:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
