"""Head-to-tail transfer function and string stability of open platoons with several CAVs.

``Gamma(s) = V_N(s) / V_h(s)``: the last vehicle's velocity error over the head's, for static
gains :class:`~lcc_synth.models.platoon.PlatoonGains` (one row per CAV, ``"replace"`` or
``"added"``). Two independent computations:

* state space (:func:`platoon_gamma`): ``c (sI - A_cl)^-1 h_cl`` of the closed loop
  :meth:`PlatoonGains.closed_loop`, by the Hessenberg solve of
  :func:`lcc_synth.analysis.transfer.transfer_response` (compiled kernel, no eigenvectors);
* per-vehicle product (:func:`gamma_product`): when every CAV's command uses only its own
  ``s_c, v_c`` and its predecessor's ``v_{c-1}`` (``v_h`` for ``c = 1``),
  ``u_c = k_s s_c + k_v v_c + k_p v_{c-1}``, the string is a cascade and
  ``Gamma = prod_i T_i`` with ``T_i = phi_i / gamma_i = (a3 s + a1) / (s^2 + a2 s + a1)`` for an
  HDV (eq. 8) and ``T_c = (k_p s + k_s) / (s^2 - k_v s + k_s)`` for a CAV (from
  ``s V_c = u_c``, ``s S_c = V_{c-1} - V_c``). A CAV that hears anyone else breaks the cascade;
  :func:`local_cav_laws` says which one (python-control's ``interconnect`` is the independent
  check in general, see the tests).

String stability (Definition 1, eq. 25: ``|Gamma(jw)| < 1`` for ``w > 0``) is decided by
:func:`lcc_synth.analysis.string_stability.loop_string_stability` on the closed loop: the
decision function ``q(w)`` with the double zero at ``w = 0`` removed exactly, its band
``tau = 1e4 eps max|lambda|/min|lambda|``, the grid or Hamiltonian search, and the verdict
``"boundary"`` when a case is too close to call. Nothing is re-implemented here. For a cascade
the low-frequency curvature is the sum of the vehicles' own,
``c = sum_i (a3_i^2 - a2_i^2 + 2 a1_i) / a1_i^2`` (CAV: ``(k_p^2 - k_v^2 + 2 k_s) / k_s^2``),
the identity the tests use to build a case exactly on the boundary.

Measured (``python benchmarks/bench_platoon_analysis.py``): the two computations agree to
1.7e-15 relative on 400 frequencies in 1e-3..1e2 rad/s (DeeP-LCC platoon, two CAVs with local
gains; 0.4 ms for the state-space curve); one verdict on its 16-state loop takes 4 ms (grid or
Hamiltonian, the same verdict and peak 1.169167 at 0.3966 rad/s for the gains of the
benchmark). A cascade built exactly on the boundary (``c = 0``) has margin ~1e-16 against the
band 3.7e-12: ``"boundary"``; 1e-3 on ``k_v`` either way is decided (margin +-1.3e-4).
"""

from __future__ import annotations

import numpy as np

from lcc_synth.analysis.string_stability import StringStabilityReport, loop_string_stability
from lcc_synth.analysis.transfer import phi_gamma, transfer_response
from lcc_synth.errors import ConfigError
from lcc_synth.models.platoon import PlatoonGains, PlatoonModel

__all__ = [
    "platoon_loop",
    "platoon_gamma",
    "local_cav_laws",
    "vehicle_transfers",
    "gamma_product",
    "platoon_string_stability",
]


def _check_open(model: PlatoonModel) -> None:
    if not isinstance(model, PlatoonModel):
        raise ConfigError("system.kind", "needs a platoon model (kind = 'platoon')")
    if model.ring:
        raise ConfigError(
            "system.kind", "a ring has no head vehicle: the head-to-tail transfer is undefined"
        )


def platoon_loop(
    model: PlatoonModel, gains: PlatoonGains
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(A_cl, h, c)``: the closed loop with the head velocity error as input (``h``) and the
    last vehicle's velocity error as output (``c``)."""
    _check_open(model)
    Acl, Hcl = gains.closed_loop(model)
    c = np.zeros(model.nx)
    c[model.index(f"v_{model.platoon.size}")] = 1.0
    return Acl, Hcl.reshape(-1), c


def platoon_gamma(model: PlatoonModel, gains: PlatoonGains, omega) -> np.ndarray:
    """``Gamma(j omega)`` from the closed-loop state space (see the module docstring)."""
    Acl, h, c = platoon_loop(model, gains)
    return transfer_response(Acl, h, c, 1j * np.asarray(omega, dtype=float))


def local_cav_laws(model: PlatoonModel, gains: PlatoonGains) -> dict[int, tuple[float, ...]]:
    """``{c: (k_s, k_v, k_p)}``: every CAV's command ``u_c = k_s s_c + k_v v_c + k_p v_{c-1}``
    in the model's coordinates (``"added"``: with its HDV law).

    Raises
    ------
    ConfigError
        ``gains.u_c`` when CAV ``c`` uses another vehicle's state (or ``v_h`` when it does not
        follow the head): the string is then not a cascade of per-vehicle transfer functions.
    """
    _check_open(model)
    Ku, kh = gains.input_feedback(model)
    out = {}
    for row, (c, k_head) in enumerate(zip(model.cavs, kh, strict=True)):
        own_s, own_v = model.index(f"s_{c}"), model.index(f"v_{c}")
        pred = model.index(f"v_{c - 1}") if c > 1 else None
        allowed = {own_s, own_v} | ({pred} if pred is not None else set())
        other = [model.state_names[j] for j in np.nonzero(Ku[row])[0] if j not in allowed]
        if c > 1 and k_head != 0:
            other.append("v_h")
        if other:
            raise ConfigError(
                f"gains.u_{c}",
                f"uses {other}: only s_{c}, v_{c} and the predecessor's velocity keep the "
                "platoon a cascade of per-vehicle transfer functions",
            )
        k_p = float(Ku[row, pred]) if pred is not None else float(k_head)
        out[c] = (float(Ku[row, own_s]), float(Ku[row, own_v]), k_p)
    return out


def vehicle_transfers(model: PlatoonModel, gains: PlatoonGains, s) -> np.ndarray:
    """``(N,) + s.shape`` array: each vehicle's ``T_i(s) = V_i / V_{i-1}`` (module docstring)."""
    laws = local_cav_laws(model, gains)
    s = np.asarray(s, dtype=complex)
    out = np.empty((model.platoon.size,) + s.shape, dtype=complex)
    for i in range(1, model.platoon.size + 1):
        if i in laws:
            k_s, k_v, k_p = laws[i]
            num, den = np.array([k_p, k_s]), np.array([1.0, -k_v, k_s])
        else:
            num, den = phi_gamma(model.coefficients[i - 1])
        out[i - 1] = np.polyval(num, s) / np.polyval(den, s)
    return out


def gamma_product(model: PlatoonModel, gains: PlatoonGains, omega) -> np.ndarray:
    """``Gamma(j omega) = prod_i T_i(j omega)`` (every CAV with a local law, else ConfigError)."""
    s = 1j * np.asarray(omega, dtype=float)
    return np.prod(vehicle_transfers(model, gains, s), axis=0)


def platoon_string_stability(
    model: PlatoonModel, gains: PlatoonGains, method: str = "grid"
) -> StringStabilityReport:
    """Plant and head-to-tail string stability of an open platoon under ``gains``.

    Parameters
    ----------
    model : PlatoonModel
        An open platoon (a ring has no head vehicle: ConfigError naming ``system.kind``).
    gains : PlatoonGains
        One row per CAV.
    method : {"grid", "hamiltonian"}
        How :func:`~lcc_synth.analysis.string_stability.loop_string_stability` searches.

    Returns
    -------
    StringStabilityReport
        ``verdict`` ``"string_stable"``, ``"string_unstable"``, ``"plant_unstable"`` or
        ``"boundary"`` (too close to call at this precision).
    """
    Acl, h, c = platoon_loop(model, gains)
    return loop_string_stability(Acl, h, c, method=method)
