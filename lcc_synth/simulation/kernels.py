"""The simulator's compiled loops (numba): HDV laws, V2V observation, the stepping kernel.

Random draws inside the loop are counter based (``_u01``): the same value for
``(seed, scenario, vehicle, step, channel)`` on any thread and in any batch. The driver is
:func:`lcc_synth.simulation.engine.simulate`.

Speed (``benchmarks/bench_simulator.py``, heterogeneous Appendix C batch of 400 with delays,
2 threads, this 2-core machine): 116 M vehicle-steps/s, from 74 M before three changes that
leave every result bit for bit the same (``benchmarks/bench_simulator_ab.py``):

- ``error_model="numpy"`` on every kernel (74 -> 104 M/s): numba's default ("python") tests
  every division and modulo for a zero divisor so that it can raise ``ZeroDivisionError``;
  the tests sit inside the vehicle loop and keep LLVM from optimising it. No divisor here can
  be zero (spacings are tested for collision first, ``s_go > s_st`` is validated, ``L`` and the
  record stride are >= 1), and the IEEE arithmetic is the same in both models.
- the delay history is scenario-major, ``hp[b, slot, j]``: one scenario's ``L x nv`` history
  is contiguous (a few pages instead of one page per slot), and a delayed slot is
  ``k % L - d`` wrapped once instead of an integer modulo per vehicle and step.
- the perturbation overrides are read only in the columns that have any (``ovr``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

_NAN = np.nan


@numba.njit(cache=True, inline="always", error_model="numpy")
def _mix(x):
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@numba.njit(cache=True, inline="always", error_model="numpy")
def _u01(seed, b, j, k, ch):
    """Counter-based uniform in (0, 1): the same draw for (seed, b, j, k, ch) on any thread."""
    x = _mix(np.uint64(seed) + np.uint64(0x9E3779B97F4A7C15))
    x = _mix(x ^ np.uint64(b))
    x = _mix(x ^ (np.uint64(j) + np.uint64(0x632BE59BD9B4E019)))
    x = _mix(x ^ np.uint64(k))
    x = _mix(x ^ np.uint64(ch))
    return (float(x >> np.uint64(11)) + 0.5) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True, inline="always", error_model="numpy")
def _normal(seed, b, j, k, ch):
    u1 = _u01(seed, b, j, k, ch)
    u2 = _u01(seed, b, j, k, ch + 1)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@numba.njit(cache=True, inline="always", error_model="numpy")
def _hdv_accel(code, pr, s, ds, v):
    """OVM (code 0) or IDM (code 1) acceleration; mirrors hdv.ovm_accel / hdv.idm_accel."""
    return _hdv_accel6(code, pr[0], pr[1], pr[2], pr[3], pr[4], pr[5], s, ds, v)


@numba.njit(cache=True, inline="always", error_model="numpy")
def _hdv_accel6(code, p0, p1, p2, p3, p4, p5, s, ds, v):
    """:func:`_hdv_accel` with the six parameters as scalars (no array view in the loop)."""
    if code == 0:
        sc = min(max(s, p2), p3)
        vd = 0.5 * p4 * (1.0 - math.cos(math.pi * (sc - p2) / (p3 - p2)))
        return p0 * (vd - v) + p1 * ds
    v0, T, s0, a, b, delta = p0, p1, p2, p3, p4, p5
    vp = max(v, 0.0)
    s_des = s0 + max(vp * T - vp * ds / (2.0 * math.sqrt(a * b)), 0.0)
    return a * (1.0 - (vp / v0) ** delta - (s_des / max(s, 1e-3)) ** 2)


@numba.njit(cache=True, inline="always", error_model="numpy")
def _eq_spacing(code, pr, v):
    """Equilibrium spacing at ``v``; mirrors OVM / IDM ``equilibrium_spacing``."""
    if code == 0:
        return pr[2] + (pr[3] - pr[2]) / math.pi * math.acos(1.0 - 2.0 * v / pr[4])
    return (pr[2] + v * pr[1]) / math.sqrt(1.0 - (v / pr[0]) ** pr[5])


@numba.njit(cache=True, inline="always", error_model="numpy")
def _gap(p, b, j, ring, circ):
    """Spacing of column ``j``: to column ``j - 1``; on the ring column 0's is to the last
    column, one circumference ahead (positions are not wrapped)."""
    if j > 0:
        return p[b, j - 1] - p[b, j]
    if ring:
        return p[b, p.shape[1] - 1] + circ - p[b, 0]
    return _NAN


@numba.njit(cache=True, error_model="numpy")
def _observe(b, k, p, v, hp, hv, L, lat, loss, noise, seed, sid0, is_cav, ring, circ,
             obs_s, obs_v, obs_p):  # fmt: skip
    """Update the CAVs' received values of scenario ``b`` at sample ``k`` (V2V model; every
    CAV's own entries exact)."""
    nv = p.shape[1]
    for j in range(nv):
        if is_cav[j] >= 0:
            obs_p[b, j] = p[b, j]
            obs_v[b, j] = v[b, j]
            obs_s[b, j] = _gap(p, b, j, ring, circ)
            continue
        if loss[j] > 0.0 and _u01(seed, sid0 + b, j, k, 2) < loss[j]:
            continue  # packet lost: hold the last value
        if lat == 0:
            pj = p[b, j]
            vj = v[b, j]
            sj = _gap(p, b, j, ring, circ)
        else:
            slot = (k - lat + L) % L
            pj = hp[b, slot, j]
            vj = hv[b, slot, j]
            if j > 0:
                sj = hp[b, slot, j - 1] - hp[b, slot, j]
            elif ring:
                sj = hp[b, slot, nv - 1] + circ - hp[b, slot, 0]
            else:
                sj = _NAN
        if noise[0] > 0.0 and (j > 0 or ring):
            sj += noise[0] * _normal(seed, sid0 + b, j, k, 3)
        if noise[1] > 0.0:
            vj += noise[1] * _normal(seed, sid0 + b, j, k, 5)
        if noise[2] > 0.0:
            pj += noise[2] * _normal(seed, sid0 + b, j, k, 7)
        obs_s[b, j] = sj
        obs_v[b, j] = vj
        obs_p[b, j] = pj


@numba.njit(cache=True, error_model="numpy")
def _ring_first(
    b, k, p, v, hp, hv, L, delay_steps, delay_own, code, params, a_min, a_max, abs_min, kc,
    u_hold, cav_aeb, hdv_aeb, noise_std, seed, sid0, circ, aeb,
):  # fmt: skip
    """Acceleration of the ring's column 0 (before noise and overrides): as every other
    vehicle's in :func:`_advance`, its predecessor the last column, ``circ`` ahead."""
    last = p.shape[1] - 1
    if kc >= 0:
        a = min(max(u_hold[b, kc], a_min), a_max)
        if cav_aeb:
            s0 = p[b, last] + circ - p[b, 0]
            if (v[b, 0] ** 2 - v[b, last] ** 2) / (2.0 * s0) >= abs_min:
                a = a_min
                aeb[kc] = True
        return a
    d = delay_steps[b, 0]
    if d == 0:
        s = p[b, last] + circ - p[b, 0]
        ds = v[b, last] - v[b, 0]
        vv = v[b, 0]
    else:
        sl = (k - d + L) % L
        s = hp[b, sl, last] + circ - hp[b, sl, 0]
        ds = hv[b, sl, last] - hv[b, sl, 0]
        vv = hv[b, sl, 0] if delay_own else v[b, 0]
    a = _hdv_accel6(
        code, params[b, 0, 0], params[b, 0, 1], params[b, 0, 2],
        params[b, 0, 3], params[b, 0, 4], params[b, 0, 5], s, ds, vv,
    )  # fmt: skip
    if noise_std > 0.0:
        a += noise_std * _normal(seed, sid0 + b, 0, k, 0)
    a = min(max(a, a_min), a_max)
    if hdv_aeb:
        s = p[b, last] + circ - p[b, 0]
        if (v[b, 0] ** 2 - v[b, last] ** 2) / (2.0 * s) >= abs_min:
            a = a_min
    return a


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _advance(
    b0, b1, k0, k1, p, v, hp, hv, L, delay_steps, delay_own, code, params, law_code,
    law_params, dt, t_start, a_min, a_max, cavs, is_cav, ring, circ, cav_aeb, hdv_aeb,
    noise_std, unif_noise, seed, sid0,
    acc_ovr, spd_ovr, ovr, mode, ratio, u_hold, Ks, Kv, Kp, hdv_law, v_star, s_ref, p_ref,
    est_decay, v_lo, v_hi, v_hat, meas_decay, f_s, f_v,
    loss, lat, obs_noise, obs_s, obs_v, obs_p, alive, collided, ctime,
    stride, out_p, out_v, out_a, out_s, out_u, out_aeb, lag_f, a_lag,
):  # fmt: skip
    """Advance scenarios ``b0 .. b1 - 1`` from sample ``k0`` to ``k1`` (exclusive).

    Releases the GIL: disjoint scenario ranges run on several threads at once.

    ``cavs`` (``(n_cav,)``) are the CAV columns, ``is_cav[j]`` the CAV index of column ``j``
    (-1 for a vehicle that is not a CAV). ``ring``: no head vehicle, column 0 follows the last
    column at ``circ`` ahead (:func:`_gap`). ``mode`` 1 evaluates the linear law at every
    ``ratio``-th sample: CAV ``c`` commands ``[F(law_params[b, c]) if hdv_law] +
    Ks[c] . (s - s_ref - sh) + Kv[c] . (v - ve) - Kp[c] (p - p_ref[b, c] - v* t)``; mode 0
    applies the held commands ``u_hold`` (``(batch, n_cav)``, set by a Python controller).
    ``est_decay >= 0`` takes the law's errors from the equilibrium estimate ``v_hat``
    (``(batch,)``, updated in place from the velocity ahead of the first CAV; see
    :class:`~lcc_synth.controllers.static.LinearLaw`), ``est_decay < 0`` from ``v_star``.
    ``meas_decay >= 0`` makes the law read the measurement filter's outputs: ``f_s``, ``f_v``
    (``(batch, n_vehicles)``, the filter states, NaN until the first sample) in place of every
    received spacing and velocity; ``meas_decay < 0`` the values as received.
    ``noise_std``: Gaussian acceleration noise on every HDV before the limits;
    ``unif_noise``: ``U[-w, w]`` on every vehicle but the head after the limits.
    ``acc_ovr``, ``spd_ovr`` (``(steps, n_vehicles)``, NaN when free) are the perturbations'
    acceleration overrides and speed targets; ``ovr[j]`` says whether column ``j`` has any
    (the others skip both reads).
    ``lag_f[c] = dt / tau_c`` (0: no lag; ``lag_f = a_lag = None``: no CAV has one, and the
    kernel is compiled without the lag) puts CAV ``c`` behind a first-order actuator lag:
    its command (clipped, or ``a_min`` from emergency braking) drives the acceleration state
    ``a_lag[b, c]``, which is what the vehicle applies (then noise, overrides and the
    standstill floor as for every vehicle); the state is then Euler-updated from the applied
    acceleration, ``a <- a + dt / tau (command - a)``.
    """
    nv = p.shape[1]
    n_cav = cavs.shape[0]
    j0 = 0 if ring else 1  # first column with a vehicle ahead
    abs_min = abs(a_min)
    acc = np.empty(nv)
    ys = np.empty(nv)  # spacings and velocities the law reads at a sample
    yv = np.empty(nv)
    aeb = np.zeros(n_cav, dtype=np.bool_)
    cmd = np.zeros(n_cav)  # the lagged CAVs' commands at this sample
    for b in range(b0, b1):
        for k in range(k0, k1):
            rec = k % stride == 0
            r = k // stride
            if not alive[b]:
                if rec:
                    for j in range(nv):
                        out_p[b, r, j] = _NAN
                        out_v[b, r, j] = _NAN
                        out_a[b, r, j] = _NAN
                        out_s[b, r, j] = _NAN
                    for c in range(n_cav):
                        out_u[b, r, c] = _NAN
                continue
            t = t_start + k * dt
            slot = 0
            if L > 1:
                slot = k % L
                for j in range(nv):
                    hp[b, slot, j] = p[b, j]
                    hv[b, slot, j] = v[b, j]
            hit = False
            for j in range(j0, nv):
                if _gap(p, b, j, ring, circ) <= 0.0:
                    collided[b, j] = True
                    ctime[b, j] = t
                    hit = True
            if rec:
                for j in range(nv):
                    out_p[b, r, j] = p[b, j]
                    out_v[b, r, j] = v[b, j]
                    out_s[b, r, j] = _gap(p, b, j, ring, circ)
            if hit:
                alive[b] = False
                if rec:
                    for j in range(nv):
                        out_a[b, r, j] = _NAN
                    for c in range(n_cav):
                        out_u[b, r, c] = _NAN
                continue
            # ---- CAV commands (sampled, zero-order hold) ----
            if mode == 1 and k % ratio == 0:
                _observe(b, k, p, v, hp, hv, L, lat, loss, obs_noise, seed, sid0, is_cav, ring,
                         circ, obs_s, obs_v, obs_p)  # fmt: skip
                for j in range(nv):
                    ys[j] = obs_s[b, j]
                    yv[j] = obs_v[b, j]
                if meas_decay >= 0.0:
                    for j in range(nv):
                        if is_cav[j] >= 0:
                            continue  # the CAVs' own values are exact: not filtered
                        if f_v[b, j] != f_v[b, j]:  # first sample: start at the received value
                            f_s[b, j] = ys[j]
                            f_v[b, j] = yv[j]
                        y_s, y_v = ys[j], yv[j]
                        ys[j] = f_s[b, j]
                        yv[j] = f_v[b, j]
                        f_s[b, j] = y_s + (f_s[b, j] - y_s) * meas_decay
                        f_v[b, j] = y_v + (f_v[b, j] - y_v) * meas_decay
                ve = v_star[b]
                sh = 0.0
                if est_decay >= 0.0:
                    ve = min(max(v_hat[b], v_lo), v_hi)
                    sh = _eq_spacing(law_code, law_params[b, 0], ve) - _eq_spacing(
                        law_code, law_params[b, 0], v_star[b]
                    )
                    y = yv[cavs[0] - 1]
                    v_hat[b] = y + (v_hat[b] - y) * est_decay
                for c in range(n_cav):
                    cav = cavs[c]
                    ahead = cav - 1 if cav > 0 else nv - 1
                    u = 0.0
                    if hdv_law:
                        u = _hdv_accel6(
                            law_code, law_params[b, c, 0], law_params[b, c, 1],
                            law_params[b, c, 2], law_params[b, c, 3], law_params[b, c, 4],
                            law_params[b, c, 5], ys[cav], yv[ahead] - yv[cav], yv[cav],
                        )  # fmt: skip
                    for j in range(j0, nv):
                        if Ks[c, j] != 0.0:
                            u += Ks[c, j] * (ys[j] - (s_ref[b, j] + sh))
                    for j in range(nv):
                        if Kv[c, j] != 0.0:
                            u += Kv[c, j] * (yv[j] - ve)
                    if Kp[c] != 0.0:
                        u -= Kp[c] * (obs_p[b, cav] - p_ref[b, c] - v_star[b] * (t - t_start))
                    u_hold[b, c] = u
            for c in range(n_cav):
                aeb[c] = False
            # ---- accelerations ----
            for j in range(nv):
                kc = is_cav[j]
                if j == 0:
                    if ring:  # the ring's column 0 follows the last column, C ahead
                        a = _ring_first(b, k, p, v, hp, hv, L, delay_steps, delay_own, code,
                                        params, a_min, a_max, abs_min, kc, u_hold, cav_aeb,
                                        hdv_aeb, noise_std, seed, sid0, circ, aeb)  # fmt: skip
                    else:
                        a = 0.0  # the head: cruising unless a perturbation drives it
                elif kc >= 0:
                    a = min(max(u_hold[b, kc], a_min), a_max)
                    if cav_aeb:
                        s0 = p[b, j - 1] - p[b, j]
                        if (v[b, j] ** 2 - v[b, j - 1] ** 2) / (2.0 * s0) >= abs_min:
                            a = a_min
                            aeb[kc] = True
                else:
                    d = delay_steps[b, j]
                    if d == 0:
                        s = p[b, j - 1] - p[b, j]
                        ds = v[b, j - 1] - v[b, j]
                        vv = v[b, j]
                    else:
                        sl = slot - d  # (k - d) mod L, d <= L - 1
                        if sl < 0:
                            sl += L
                        s = hp[b, sl, j - 1] - hp[b, sl, j]
                        ds = hv[b, sl, j - 1] - hv[b, sl, j]
                        vv = hv[b, sl, j] if delay_own else v[b, j]
                    a = _hdv_accel6(
                        code, params[b, j, 0], params[b, j, 1], params[b, j, 2],
                        params[b, j, 3], params[b, j, 4], params[b, j, 5], s, ds, vv,
                    )  # fmt: skip
                    if noise_std > 0.0:
                        a += noise_std * _normal(seed, sid0 + b, j, k, 0)
                    a = min(max(a, a_min), a_max)
                    if hdv_aeb:
                        s = p[b, j - 1] - p[b, j]
                        if (v[b, j] ** 2 - v[b, j - 1] ** 2) / (2.0 * s) >= abs_min:
                            a = a_min
                if lag_f is not None:  # None: compiled without (numba prunes the branch)
                    if kc >= 0 and lag_f[kc] > 0.0:  # actuator lag: apply the state
                        cmd[kc] = a
                        a = a_lag[b, kc]
                if unif_noise > 0.0 and (j > 0 or ring):
                    a += unif_noise * (2.0 * _u01(seed, sid0 + b, j, k, 9) - 1.0)
                if ovr[j]:
                    ov = acc_ovr[k, j]
                    if ov == ov:
                        a = ov
                        if kc >= 0:
                            aeb[kc] = False
                    sv = spd_ovr[k, j]
                    if sv == sv:
                        a = min(max((sv - v[b, j]) / dt, a_min), a_max)
                        if kc >= 0:
                            aeb[kc] = False
                if v[b, j] + dt * a < 0.0:
                    a = -v[b, j] / dt
                acc[j] = a
            if rec:
                for j in range(nv):
                    out_a[b, r, j] = acc[j]
                for c in range(n_cav):
                    out_u[b, r, c] = u_hold[b, c]
                    out_aeb[b, r, c] = aeb[c]
            if lag_f is not None:
                for c in range(n_cav):
                    if lag_f[c] > 0.0:
                        al = acc[cavs[c]]
                        a_lag[b, c] = al + lag_f[c] * (cmd[c] - al)
            for j in range(nv):
                p[b, j] += dt * v[b, j]
                v[b, j] += dt * acc[j]


@numba.njit(cache=True, error_model="numpy")
def _observe_all(
    k, p, v, hp, hv, L, lat, loss, noise, seed, sid0, is_cav, ring, circ, obs_s, obs_v, obs_p,
    alive,
):
    B = p.shape[0]
    nv = p.shape[1]
    if L > 1:
        slot = k % L
        for b in range(B):
            for j in range(nv):
                hp[b, slot, j] = p[b, j]
                hv[b, slot, j] = v[b, j]
    for b in range(B):
        if alive[b]:
            _observe(b, k, p, v, hp, hv, L, lat, loss, noise, seed, sid0, is_cav, ring, circ,
                     obs_s, obs_v, obs_p)
