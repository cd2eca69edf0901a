"""Static LCC state feedback (eq. 23) and the closed loop it makes.

Gains are keyed by state name, ``s_i`` for the spacing-error gain ``mu_i`` and ``v_i`` for
the velocity-error gain ``k_i`` of vehicle ``i`` (``-p_0`` for the FD-LCC position state), so
a TOML table reads ``gains = { s_-2 = 1.0, v_-2 = -1.0 }``.

Two semantics, both used by the paper:

``added``    eq. (23), Sections IV and V-A: the CAV keeps the HDV law towards the vehicle ahead
             and the gains are added, ``u = a1 s0 - a2 v0 + a3 v_-1 + sum(mu_i s_i + k_i v_i)``
             (a gain on ``s_0``/``v_0`` adds to ``a1``/``-a2``).
``replace``  the Section V-B demo gains: ``u = sum(gain * state)`` is the whole command
             (e.g. FD-LCC ``u = -0.5 v0 - 0.2 s1 + 0.05 v1 - 0.1 s2 + 0.05 v2``).

All functions express the CAV's command as ``u_cav = K x + kh v_h`` on an
:class:`~lcc_synth.models.linear.LCCModel`'s state ``x``; ``kh`` is non-zero only when the HDV law
needs the head velocity (no HDV ahead). Sign convention: ``u = +K x`` (no minus sign).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.gains import valid_gain
from lcc_synth.models.linear import LCCModel
from lcc_synth.models.records import Record

__all__ = ["SEMANTICS", "StaticGains", "hdv_law", "cav_feedback", "input_feedback", "closed_loop"]

SEMANTICS = ("added", "replace")
_STATE_RE = re.compile(r"^(-p_0|[sv]_-?\d+)$")


@dataclass(frozen=True, repr=False)
class StaticGains(Record):
    """Static feedback gains of the CAV (eq. 23).

    Parameters
    ----------
    gains : mapping of str to float
        State name to gain, e.g. ``{"s_1": -1.0, "v_1": -1.0}``; missing states have gain 0.
    semantics : {"added", "replace"}
        See the module docstring.
    """

    gains: Mapping[str, float] = field(default_factory=dict)
    semantics: str = "added"

    def __post_init__(self) -> None:
        if self.semantics not in SEMANTICS:
            raise ConfigError(
                "semantics", f"must be one of {list(SEMANTICS)}, got {self.semantics!r}"
            )
        clean = {}
        for name, value in dict(self.gains).items():
            if not _STATE_RE.match(str(name)):
                raise ConfigError(
                    f"gains.{name}", "state names look like s_-2, v_-2, s_0, v_1 or -p_0"
                )
            clean[str(name)] = valid_gain(f"gains.{name}", value)
        object.__setattr__(self, "gains", clean)

    @classmethod
    def from_mu_k(cls, mu: Mapping[int, float], k: Mapping[int, float], semantics="added"):
        """Build from the paper's ``mu_i`` (spacing) and ``k_i`` (velocity) per vehicle."""
        g = {f"s_{i}": v for i, v in mu.items()}
        g.update({f"v_{i}": v for i, v in k.items()})
        return cls(g, semantics)

    def vehicles(self) -> list[int]:
        """Vehicle indices with a non-zero gain (the information the CAV needs)."""
        out = set()
        for name, value in self.gains.items():
            if value != 0.0:
                out.add(0 if name == "-p_0" else int(name.split("_", 1)[1]))
        return sorted(out)

    def check(self, model: LCCModel) -> None:
        """Raise :class:`ConfigError` when a gain names a state the model does not have."""
        for name in self.gains:
            if name not in model.state_names:
                raise ConfigError(
                    f"gains.{name}",
                    f"state not in the {model.kind} model (m={model.m}, n={model.n}); "
                    f"allowed: {list(model.state_names)}",
                )
        if self.semantics == "added" and model.kind == "fd_lcc":
            raise ConfigError(
                "semantics",
                "'added' needs a vehicle ahead to follow with the HDV law; FD-LCC has none: "
                "use 'replace'",
            )

    def input_feedback(self, model: LCCModel) -> tuple[np.ndarray, float]:
        """:func:`input_feedback` of these gains on ``model`` (the method
        :class:`~lcc_synth.models.platoon.PlatoonGains` has too)."""
        return input_feedback(model, self)

    def vector(self, model: LCCModel) -> np.ndarray:
        """The gains as a row vector ``(nx,)`` on the model's states (no HDV law)."""
        self.check(model)
        K = np.zeros(model.nx)
        for name, value in self.gains.items():
            K[model.index(name)] = value
        return K


def hdv_law(model: LCCModel) -> tuple[np.ndarray, float]:
    """The CAV's HDV law ``a1 s0 - a2 v0 + a3 v_-1`` as ``(K, kh)`` on the model's state."""
    c = model.coefficients[0]
    K = np.zeros(model.nx)
    b = model.block(0)
    K[b.start] = c.alpha1
    K[b.start + 1] = -c.alpha2
    if model.m > 0:
        K[model.block(-1).start + 1] = c.alpha3
        return K, 0.0
    return K, c.alpha3


def cav_feedback(model: LCCModel, gains: StaticGains) -> tuple[np.ndarray, float]:
    """CAV acceleration command ``u_cav = K x + kh v_h`` for ``gains`` on ``model``."""
    K = gains.vector(model)
    if gains.semantics == "replace":
        return K, 0.0
    K_law, kh = hdv_law(model)
    return K + K_law, kh


def input_feedback(model: LCCModel, gains: StaticGains) -> tuple[np.ndarray, float]:
    """Feedback on the model's own input (``u``, or ``u_hat`` for CF-LCC, whose ``A`` already
    holds the CAV's HDV law): ``input = K x + kh v_h``."""
    K, kh = cav_feedback(model, gains)
    if model.kind == "cf_lcc":
        K_law, kh_law = hdv_law(model)
        return K - K_law, kh - kh_law
    return K, kh


def closed_loop(model, K: np.ndarray, kh=0.0) -> tuple[np.ndarray, np.ndarray]:
    """Closed loop ``dx = (A + B K) x + (H + B kh) v_h`` for ``input = K x + kh v_h``.

    ``model`` is any linear model with ``A, B, H`` (one CAV: ``K`` of ``nx`` entries, ``kh`` a
    number; several CAVs: ``K`` one row per input column of ``B``, ``kh`` one entry each).
    """
    nu = model.B.shape[1]
    K = np.asarray(K, dtype=float)
    K = K.reshape(1, -1) if nu == 1 else np.atleast_2d(K)
    if K.shape != (nu, model.nx):
        want = f"{model.nx} entries" if nu == 1 else f"shape ({nu}, {model.nx})"
        got = K.shape[1] if nu == 1 else K.shape
        raise ConfigError("gain", f"needs {want} for this model, got {got}")
    kh = np.asarray(kh, dtype=float).reshape(-1, 1)
    if kh.shape[0] != nu:
        raise ConfigError("gain", f"needs {nu} head-velocity gain(s), got {kh.shape[0]}")
    return model.A + model.B @ K, model.H + model.B @ kh
