"""How the SUMO backend drives the vehicles SUMO's car-following model would otherwise drive:
the HDVs' white acceleration noise (``[scenario] hdv_accel_noise``) and the CAV of a
controller switched on at a time (``[controllers.NAME] start``) before its switch.

Acceleration noise. The built-in simulator (:mod:`lcc_synth.simulation.kernels`) adds to every
HDV's car-following acceleration, at every step ``k``, ``sigma * z`` with ``z`` a standard
normal draw of its counter-based stream ``(seed, first_index + b, column j, step k, channel
0)`` (Box-Muller of two uniforms), then clips the sum to ``[a_min, a_max]`` and keeps the speed
``>= 0``. The SUMO backend does the same with SUMO's model in place of the built-in IDM law:
each step it asks SUMO for the speed its car-following model gives the HDV next
(``vehicle.getFollowSpeed(id, v, gap - minGap, v_lead, decel_lead, lead)``: SUMO's gap argument
excludes the follower's ``minGap``), i.e. its acceleration ``a_cf = (v_cf - v) / dt``, and
commands (speed mode 0) ``max(v + dt * clip(a_cf + sigma * z, a_min, a_max), 0)`` with the
same draws :func:`hdv_noise` takes from the built-in stream: the twin sees the same noise.
SUMO's own next speed of an IDM vehicle *is* ``getFollowSpeed`` (one IDM sub-step, no other
bound binding on a ring): with ``sigma`` so small that ``a_cf + sigma z == a_cf`` the commanded
run reproduces SUMO's own run to 1e-12 m/s (``tests/test_sumo_sugiyama.py``); ``sigma = 0``
leaves the HDVs to SUMO, bit for bit as before. Only SUMO's IDM is supported: Krauss and EIDM
add their own imperfection (``[scenario.sumo] sigma``) after the follow speed, and EIDM keeps
an internal state that the query would disturb.

Switching on. Before the switch sample (:func:`~lcc_synth.controllers.switch.switch_step`) the
CAV is an HDV of SUMO: its vehicle type is the HDV type of its HDV law (the built-in
simulator's: the nominal ``[hdv]`` model, or its platoon slot's values), released to SUMO's
car-following model (no noise, as the built-in CAV driving its HDV law has none); the V2V
observation is updated every step, as the built-in simulator does before a switch, but the
controller is not called. At the switch the CAV is commanded (speed mode 0, its speed cap
lifted: :func:`lift_speed_cap`) and the controller called from then on. The controller's own
state (a PI-with-saturation's window, an MPC's warm start, a static law's equilibrium estimate,
measurement filter and position reference) begins at the switch: it is called from Python.
"""

from __future__ import annotations

import numba
import numpy as np

from lcc_synth.simulation.kernels import _normal

__all__ = ["hdv_noise", "lift_speed_cap", "cav_law_params"]


@numba.njit(cache=True)
def hdv_noise(sigma, seed, sid, k, hdv, out):
    """``out[j] = sigma * z`` for every HDV column ``j`` (``hdv[j]``), ``z`` the built-in
    simulator's normal draw ``(seed, sid, j, k, 0)`` (module docstring); 0 elsewhere."""
    for j in range(out.shape[0]):
        out[j] = sigma * _normal(seed, sid, j, k, 0) if hdv[j] else 0.0
    return out


def lift_speed_cap(sumo, vid: str, cap: float) -> None:
    """Raise vehicle ``vid``'s maximum speed to ``cap`` (m/s): a CAV commanded from its switch
    on is not held to the desired speed of the HDV type it drove with before."""
    sumo.vehicle.setMaxSpeed(vid, float(cap))


def cav_law_params(sc, params: dict[str, np.ndarray], col: int) -> dict[str, float]:
    """IDM parameters of the CAV in column ``col`` driving as an HDV: the nominal ``[hdv]``
    model, or its own slot's values when the system lists its CAVs (as the built-in
    simulator's HDV law of the CAV)."""
    if sc.cavs is None:
        return {k: float(getattr(sc.hdv, k)) for k in params}
    return {k: float(params[k][col]) for k in params}
