"""Nonlinear car-following models of human-driven vehicles (HDVs), Section II-A.

Every model is a validated frozen dataclass ``F(s, ds, v)`` (eq. 1): the acceleration of a
vehicle given its spacing ``s`` to the vehicle ahead, the relative speed ``ds = v_ahead - v``
and its own speed ``v``. ``accel`` accepts numpy arrays and broadcasts, so a batch of
heterogeneous vehicles is one call: build a parameter object whose fields are arrays
or call the module-level kernels (:func:`ovm_accel`, :func:`idm_accel`) directly.

Linearisation (eq. 8): :func:`linear_coefficients` gives ``alpha1 = dF/ds``,
``alpha2 = dF/d(ds) - dF/dv``, ``alpha3 = dF/d(ds)`` at the equilibrium ``(s*, v*)``;
analytic for OVM, by central differences of ``F`` for any other model.
"""

from __future__ import annotations

import difflib
import math
import warnings
from dataclasses import dataclass, fields
from typing import Protocol

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.records import Record

__all__ = [
    "CarFollowingModel",
    "OVM",
    "IDM",
    "LinearCoefficients",
    "ControllabilityWarning",
    "ovm_accel",
    "ovm_desired_velocity",
    "idm_accel",
    "linear_coefficients",
    "model_from_dict",
    "MODELS",
    "free_speed",
]


class ControllabilityWarning(UserWarning):
    """Linear coefficients violate eq. (13) or the sign conditions of Section II-B."""


class CarFollowingModel(Protocol):
    """What the rest of the package needs from an HDV model."""

    name: str

    def accel(self, s, ds, v):  # pragma: no cover - protocol
        """Acceleration F(s, ds, v)."""

    def equilibrium_spacing(self, v_star: float) -> float:  # pragma: no cover - protocol
        """Spacing s* with F(s*, 0, v*) = 0."""


# --------------------------------------------------------------------------------------------
# OVM, eqs. (2)-(4)
# --------------------------------------------------------------------------------------------


def ovm_desired_velocity(s, s_st, s_go, v_max):
    """Desired velocity V(s) of eq. (3)-(4): spacing clipped to [s_st, s_go], cosine policy."""
    sc = np.clip(s, s_st, s_go)
    return 0.5 * v_max * (1.0 - np.cos(np.pi * (sc - s_st) / (s_go - s_st)))


def ovm_accel(s, ds, v, alpha, beta, s_st, s_go, v_max):
    """OVM acceleration alpha (V(s) - v) + beta ds, eq. (2); broadcasts over all arguments."""
    return alpha * (ovm_desired_velocity(s, s_st, s_go, v_max) - v) + beta * ds


def _check_nonneg(name: str, value, strictly: bool = False) -> None:
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ConfigError(name, f"must be a finite number, got {value!r}")
    bad = arr <= 0 if strictly else arr < 0
    if np.any(bad):
        rel = "> 0" if strictly else ">= 0"
        raise ConfigError(name, f"must be {rel}, got {value!r}")


@dataclass(frozen=True, repr=False)
class OVM(Record):
    """Optimal velocity model, eq. (2)-(4). Defaults are the paper's parameters.

    Parameters
    ----------
    alpha, beta : float
        Headway and relative-speed gains (1/s), both > 0.
    s_st, s_go : float
        Stopping and free-flow spacings (m), 0 <= s_st < s_go.
    v_max : float
        Maximum desired velocity (m/s), > 0.
    """

    alpha: float = 0.6
    beta: float = 0.9
    s_st: float = 5.0
    s_go: float = 35.0
    v_max: float = 30.0
    name: str = "ovm"

    def __post_init__(self) -> None:
        _check_nonneg("alpha", self.alpha, strictly=True)
        _check_nonneg("beta", self.beta)
        _check_nonneg("s_st", self.s_st)
        _check_nonneg("v_max", self.v_max, strictly=True)
        _check_nonneg("s_go", self.s_go, strictly=True)
        if np.any(np.asarray(self.s_st) >= np.asarray(self.s_go)):
            raise ConfigError("s_st", f"must be < s_go, got s_st={self.s_st}, s_go={self.s_go}")

    def accel(self, s, ds, v):
        """Acceleration F(s, ds, v)."""
        return ovm_accel(s, ds, v, self.alpha, self.beta, self.s_st, self.s_go, self.v_max)

    def _check_v_star(self, v_star) -> None:
        if type(v_star) is float and type(self.v_max) in (float, int) and 0.0 < v_star < self.v_max:
            return  # the predictive controllers' call every sample (NaN fails the test)
        vs = np.asarray(v_star, dtype=float)
        if np.any(~np.isfinite(vs)) or np.any(vs <= 0) or np.any(vs >= np.asarray(self.v_max)):
            raise ConfigError(
                "v_star",
                f"must satisfy 0 < v* < v_max = {self.v_max} m/s for the OVM, got {v_star!r}",
            )

    def toml_table(self) -> dict:
        """The ``[hdv]`` table of this model (what :func:`model_from_dict` reads)."""
        out = {"model": self.name}
        out.update({f.name: float(getattr(self, f.name)) for f in fields(self) if f.name != "name"})
        return out

    def equilibrium_spacing(self, v_star):
        """s* = V^-1(v*) (inverse of eq. 4)."""
        self._check_v_star(v_star)
        ratio = 1.0 - 2.0 * np.asarray(v_star, dtype=float) / self.v_max
        out = self.s_st + (self.s_go - self.s_st) / np.pi * np.arccos(ratio)
        return float(out) if np.ndim(out) == 0 else out

    def linear_coefficients(self, v_star: float) -> LinearCoefficients:
        """Analytic alpha1 = alpha V'(s*), alpha2 = alpha + beta, alpha3 = beta."""
        s_star = self.equilibrium_spacing(v_star)
        width = self.s_go - self.s_st
        dv = self.v_max / 2.0 * np.pi / width * np.sin(np.pi * (s_star - self.s_st) / width)
        return LinearCoefficients(
            float(self.alpha * dv), float(self.alpha + self.beta), float(self.beta)
        )


# --------------------------------------------------------------------------------------------
# IDM (Treiber, Hennecke & Helbing 2000)
# --------------------------------------------------------------------------------------------


def idm_accel(s, ds, v, v0, T, s0, a, b, delta):
    """IDM acceleration a [1 - (v/v0)^delta - (s_des/s)^2], s_des = s0 + vT - v ds / (2 sqrt(ab)).

    ``ds`` is ``v_ahead - v`` (the paper's convention), so an approaching vehicle has ds < 0.
    The desired gap is floored at ``s0`` (no negative desired gap when the leader pulls away).
    """
    v_pos = np.maximum(v, 0.0)
    s_des = s0 + np.maximum(v_pos * T - v_pos * ds / (2.0 * np.sqrt(a * b)), 0.0)
    return a * (1.0 - (v_pos / v0) ** delta - (s_des / np.maximum(s, 1e-3)) ** 2)


@dataclass(frozen=True, repr=False)
class IDM(Record):
    """Intelligent driver model.

    Parameters
    ----------
    v0 : float
        Desired speed (m/s), > 0.
    T : float
        Safe time headway (s), > 0 (with ``T = 0`` the desired gap would not grow with speed:
        a driver keeping only ``s0`` at any speed).
    s0 : float
        Jam distance (m), >= 0.
    a, b : float
        Maximum acceleration and comfortable deceleration (m/s^2), > 0.
    delta : float
        Acceleration exponent, > 0 (usually 4).
    """

    v0: float = 30.0
    T: float = 1.5
    s0: float = 2.0
    a: float = 1.0
    b: float = 1.5
    delta: float = 4.0
    name: str = "idm"

    def __post_init__(self) -> None:
        _check_nonneg("v0", self.v0, strictly=True)
        _check_nonneg("T", self.T, strictly=True)
        _check_nonneg("s0", self.s0)
        _check_nonneg("a", self.a, strictly=True)
        _check_nonneg("b", self.b, strictly=True)
        _check_nonneg("delta", self.delta, strictly=True)

    def accel(self, s, ds, v):
        """Acceleration F(s, ds, v)."""
        return idm_accel(s, ds, v, self.v0, self.T, self.s0, self.a, self.b, self.delta)

    def toml_table(self) -> dict:
        """The ``[hdv]`` table of this model (what :func:`model_from_dict` reads)."""
        out = {"model": self.name}
        out.update({f.name: float(getattr(self, f.name)) for f in fields(self) if f.name != "name"})
        return out

    def equilibrium_spacing(self, v_star):
        """s* = (s0 + v* T) / sqrt(1 - (v*/v0)^delta)."""
        vs = np.asarray(v_star, dtype=float)
        if np.any(~np.isfinite(vs)) or np.any(vs <= 0) or np.any(vs >= np.asarray(self.v0)):
            raise ConfigError(
                "v_star", f"must satisfy 0 < v* < v0 = {self.v0} m/s for the IDM, got {v_star!r}"
            )
        out = (self.s0 + vs * self.T) / np.sqrt(1.0 - (vs / self.v0) ** self.delta)
        return float(out) if np.ndim(out) == 0 else out

    def linear_coefficients(self, v_star: float) -> LinearCoefficients:
        """Coefficients by central differences of F (see :func:`linear_coefficients`)."""
        return numeric_linear_coefficients(self, v_star)


# --------------------------------------------------------------------------------------------
# Linearisation, eq. (8)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LinearCoefficients:
    """alpha1, alpha2, alpha3 of the linearised HDV model, eq. (8)."""

    alpha1: float
    alpha2: float
    alpha3: float

    @property
    def controllability_margin(self) -> float:
        """alpha1 - alpha2 alpha3 + alpha3^2; eq. (13) requires it to be non-zero."""
        return self.alpha1 - self.alpha2 * self.alpha3 + self.alpha3**2

    def problems(self, tol: float = 1e-9) -> list[str]:
        """Violated conditions of Section II-B / eq. (13), as readable strings (empty if none)."""
        out = []
        if not self.alpha1 > 0:
            out.append(f"alpha1 = {self.alpha1:.6g} must be > 0")
        if not self.alpha3 > 0:
            out.append(f"alpha3 = {self.alpha3:.6g} must be > 0")
        if not self.alpha2 > self.alpha3:
            out.append(f"alpha2 = {self.alpha2:.6g} must be > alpha3 = {self.alpha3:.6g}")
        if abs(self.controllability_margin) <= tol * max(1.0, abs(self.alpha1)):
            out.append(
                "alpha1 - alpha2*alpha3 + alpha3^2 = "
                f"{self.controllability_margin:.3g} violates the controllability condition (13)"
            )
        return out

    def check(self) -> LinearCoefficients:
        """Warn (:class:`ControllabilityWarning`) about every violated condition; return self."""
        for p in self.problems():
            warnings.warn(p, ControllabilityWarning, stacklevel=2)
        return self

    def as_tuple(self) -> tuple[float, float, float]:
        return (self.alpha1, self.alpha2, self.alpha3)


def numeric_linear_coefficients(model: CarFollowingModel, v_star: float) -> LinearCoefficients:
    """alpha1..alpha3 of eq. (8) from central differences of ``model.accel`` at (s*, 0, v*).

    The step is 1e-5 of the variable's scale; the truncation error of the central difference
    is O(h^2), about 1e-10 relative for smooth F.
    """
    s_star = float(model.equilibrium_spacing(v_star))
    v = float(v_star)
    hs = 1e-5 * max(1.0, abs(s_star))
    hv = 1e-5 * max(1.0, abs(v))

    def F(s, ds, vv):
        return float(model.accel(s, ds, vv))

    dfds = (F(s_star + hs, 0.0, v) - F(s_star - hs, 0.0, v)) / (2 * hs)
    dfdds = (F(s_star, hv, v) - F(s_star, -hv, v)) / (2 * hv)
    dfdv = (F(s_star, 0.0, v + hv) - F(s_star, 0.0, v - hv)) / (2 * hv)
    return LinearCoefficients(dfds, dfdds - dfdv, dfdds)


def linear_coefficients(model: CarFollowingModel, v_star: float, warn: bool = True):
    """alpha1..alpha3 of eq. (8) for any model; analytic where the model provides it.

    Warns with :class:`ControllabilityWarning` when alpha1 > 0, alpha2 > alpha3 > 0 or eq. (13)
    is violated (``warn=False`` to only return).
    """
    if hasattr(model, "linear_coefficients"):
        coef = model.linear_coefficients(v_star)
    else:
        coef = numeric_linear_coefficients(model, v_star)
    return coef.check() if warn else coef


# --------------------------------------------------------------------------------------------
# Construction from problem files
# --------------------------------------------------------------------------------------------

#: The car-following models by their problem-file name.
MODELS = {"ovm": OVM, "idm": IDM}


def free_speed(model) -> float:
    """The model's free-flow (maximum) speed: ``v_max`` of the OVM, ``v0`` of the IDM (40 m/s
    for a model with neither)."""
    for attr in ("v_max", "v0"):
        if hasattr(model, attr):
            return float(getattr(model, attr))
    return 40.0


def model_from_dict(data: dict, field: str = "hdv") -> OVM | IDM:
    """Build a model from a problem-file table such as ``{model = "ovm", alpha = 0.6, ...}``.

    Unknown keys and wrong types are :class:`ConfigError` naming ``field.key``.
    """
    data = dict(data)
    kind = str(data.pop("model", "ovm")).lower()
    if kind not in MODELS:
        raise ConfigError(f"{field}.model", f"must be one of {sorted(MODELS)}, got {kind!r}")
    cls = MODELS[kind]
    allowed = {f.name for f in fields(cls)} - {"name"}
    kwargs = {}
    for key, value in data.items():
        if key not in allowed:
            close = difflib.get_close_matches(str(key), sorted(allowed | {"model"}), n=1)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise ConfigError(
                f"{field}.{key}",
                f"unknown parameter for model {kind!r}; {hint}allowed: {sorted(allowed)}",
            )
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{field}.{key}", f"must be a number, got {value!r}")
        if not math.isfinite(float(value)):
            raise ConfigError(f"{field}.{key}", f"must be finite, got {value!r}")
        kwargs[key] = float(value)
    try:
        return cls(**kwargs)
    except ConfigError as err:
        raise ConfigError(f"{field}.{err.field}", err.message) from None
