"""H2 designs with the CAVs' actuator lag in the plant (``[synthesis] cav_lag = tau``).

The design plant of :func:`lcc_synth.synthesis.h2.make_plant` (one CAV) gets the lag state
``a_0`` (:mod:`lcc_synth.models.lag`): the gain's command ``u`` drives ``da_0/dt = (u - a_0) /
tau`` and ``dv_0/dt = a_0``; that of :func:`lcc_synth.synthesis.h2.make_platoon_plant` (a
platoon or ring) one state ``a_i`` per CAV, every CAV with the same ``tau`` (the key is one
number). The gain acts on the model's states only: the ``a_i`` are in no pattern (their
entries are 0), because the simulator's linear laws (static and H2 gains) read spacings and
velocities, not the CAV's acceleration. (The CACC literature feeds back the measured
acceleration; that would be a gain on ``a_i``, not implemented.) Consequences, one CAV:

* ``design = "full_state"`` is the structured design over every vehicle (``method =
  "direct"``: polishing from the truncated Riccati gain of the lagged plant), since the
  Riccati / LMI optimum feeds back ``a_0``; no Riccati-vs-LMI cross-check.
* ``"structured"`` runs with ``method = "direct"`` (the default ``"lmi"`` is replaced; an
  explicit ``method = "lmi"`` or ``cross_check = true`` is a ConfigError naming the key, on
  every layout): the convex
  restriction (and the string-stability LMI) puts ``a_0`` in a block of ``X`` of its own,
  uncoupled from ``v_0``, and is infeasible (measured: m = n = 2 at ``tau`` = 0.6 s, CF-LCC
  n = 10 with the showcase's pattern at 0.3 s).
* ``"string_stable"`` starts its string-stable-feasible polishing from that direct structured
  gain instead of the LMI's (it must be string stable with the lag, else SynthesisError).
* Every check of the report (stability, H2, string stability) is of the lagged loop
  (:func:`lcc_synth.analysis.lag_string.lag_string_stability`).
* ``"sparsity"`` and ``[synthesis.as_run]`` are refused with a lag (their loops do not model
  it).

A platoon or ring (:func:`lcc_synth.synthesis.design.synthesize`'s platoon stages):

* ``"full_state"`` is the structured design with every vehicle heard (the start from the
  truncated Riccati gain of the lagged plant, else the penalty continuation, then the
  polish); the Riccati stage is the bound of a gain that feeds back the ``a_i``.
* ``"structured"`` (``comm_range`` / ``[synthesis.patterns]``) and ``[synthesis.robust]`` run
  as without lag, on the lagged plant (every sampled member gets the lag).
* ``"sparsity"`` is refused as for one CAV.
* The checks are of the lagged loop: stability and the true H2 on the lagged state (a ring on
  its invariant hyperplane, which the lag states do not change), and for an open platoon the
  head-to-tail string stability of
  :func:`~lcc_synth.analysis.lag_string.lag_string_stability`
  (:func:`lcc_synth.synthesis.report.check_platoon_gain`).

A one-CAV open platoon (``cavs = [m + 1]``) and ``kind = "lcc"`` with the same ``m, n`` have
the same lagged plant bit for bit, and their designs agree to round-off (measured 5e-15: the
same start and Newton steps; ``tests/test_lag_platoon.py``).

Measured figures: ``docs/guide/lag.md`` and ``tests/test_actuator_lag.py``.
"""

from __future__ import annotations

from lcc_synth.errors import ConfigError
from lcc_synth.models.lag import check_lag

__all__ = ["check_lag_design", "lag_note"]


def check_lag_design(tau, design: str, as_run) -> float:
    """``tau`` of ``[synthesis] cav_lag`` if the design supports it (every layout); else a
    ConfigError naming ``synthesis.cav_lag``."""
    tau = check_lag(tau, "synthesis.cav_lag")
    if tau == 0.0:
        return tau
    if design == "sparsity":
        raise ConfigError("synthesis.cav_lag", "design = 'sparsity' has no actuator lag: use 0")
    if as_run is not None:
        raise ConfigError("synthesis.cav_lag", "[synthesis.as_run] has no actuator lag: use 0")
    return tau


def lag_note(spec) -> str:
    """The report's note on a design with ``spec.cav_lag > 0``."""
    if spec.system.platoon is not None:
        extra = ("; full_state = structured with every vehicle heard, the a_i not fed back"
                 if spec.design == "full_state" else "")  # fmt: skip
        return (f"CAV actuator lag tau = {spec.cav_lag:g} s in the plant (a state a_i per "
                f"CAV, not in the gain){extra}; every check is of the lagged loop")  # fmt: skip
    extra = (
        "; full_state = structured over every vehicle (direct), a_0 not fed back"
        if spec.design == "full_state" else
        "; structured: method = 'direct'" if spec.design == "structured" else
        "; string_stable: polished from the direct structured gain (no LMI)"
    )
    return (
        f"CAV actuator lag tau = {spec.cav_lag:g} s in the plant (state a_0, not in the "
        f"gain){extra}; every check is of the lagged loop"
    )
