"""Linearised LCC state-space models, Section II-B/C (eqs. 9, 11, 12, 14).

One dataclass, :class:`LCCModel`, holds every variant:

``"lcc"``
    general LCC, m HDVs ahead, CAV, n HDVs behind (eq. 9); the CAV row is
    ``ds0 = v_{-1} - v_0, dv0 = u``.
``"cf_lcc"``
    car-following LCC (eq. 11): m = 0, the CAV follows the head vehicle with the HDV law and
    ``u`` is the *additional* input ``u_hat``.
``"fd_lcc"``
    free-driving LCC (eq. 12): m = 0, no head vehicle, first state ``-p_0``.
``"ccc"``
    connected cruise control (eq. 14): the general model with n = 0.

States are ordered from the front of the string to the tail, two per vehicle
(spacing error, velocity error): ``s_-m, v_-m, ..., s_0, v_0, ..., s_n, v_n`` (FD-LCC: ``-p_0``
instead of ``s_0``). Every HDV may have its own coefficients (heterogeneous string).
``B`` is the input of the CAV's acceleration command, ``H`` the head-vehicle velocity error
(a zero column for FD-LCC, which has no head vehicle).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import CarFollowingModel, LinearCoefficients, linear_coefficients
from lcc_synth.models.platoon import (
    HEAD,
    chain_matrices,
    discretize,
    selection_matrix,
    state_index,
)
from lcc_synth.models.records import Record

__all__ = [
    "KINDS",
    "LCCModel",
    "build_model",
    "general_lcc",
    "cf_lcc",
    "fd_lcc",
    "ccc",
    "model_from_hdv",
    "discretize",
]

KINDS = ("lcc", "cf_lcc", "fd_lcc", "ccc")

CoefArg = LinearCoefficients | Sequence[LinearCoefficients]


@dataclass(frozen=True, eq=False, repr=False)
class LCCModel(Record):
    """A linearised LCC system ``dx = A x + B u + H v_h``.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    m, n : int
        Number of HDVs ahead of / behind the CAV.
    A, B, H : numpy.ndarray
        ``(2(m+n+1), 2(m+n+1))``, ``(2(m+n+1), 1)``, ``(2(m+n+1), 1)``.
    vehicles : tuple of int
        Vehicle index of each two-state block, ``-m, ..., 0, ..., n``.
    coefficients : dict
        Linear coefficients of every vehicle index; for the CAV (index 0) these are the HDV-law
        coefficients it uses when it follows with the HDV law (CF-LCC, eq. 23 "added" gains).
    """

    kind: str
    m: int
    n: int
    A: np.ndarray
    B: np.ndarray
    H: np.ndarray
    vehicles: tuple[int, ...]
    coefficients: dict[int, LinearCoefficients] = field(repr=False)

    @property
    def nx(self) -> int:
        """Number of states."""
        return self.A.shape[0]

    # The layout, with the same attributes as :class:`~lcc_synth.models.platoon.PlatoonModel`:
    # one CAV, vehicle 0, on an open string.

    @property
    def cavs(self) -> tuple[int, ...]:
        """CAV vehicle indices, ``(0,)``; input column ``k`` is CAV ``cavs[k]``."""
        return (0,)

    @property
    def ring(self) -> bool:
        """``False``: the string is open (a head vehicle ahead, or none for FD-LCC)."""
        return False

    @property
    def conserved(self) -> None:
        """No conserved direction (a ring's total spacing): ``None``."""
        return None

    @property
    def conserved_mode(self) -> None:
        """No conserved mode: ``None``."""
        return None

    def invariant_basis(self) -> np.ndarray:
        """The identity ``(nx, nx)``: the dynamics of an open string keep every direction (a
        ring's keep the hyperplane of :meth:`PlatoonModel.invariant_basis
        <lcc_synth.models.platoon.PlatoonModel.invariant_basis>`)."""
        return np.eye(self.nx)

    @property
    def vehicle_coefficients(self) -> tuple[LinearCoefficients, ...]:
        """The ``coefficients`` in the order of :attr:`vehicles`."""
        return tuple(self.coefficients[i] for i in self.vehicles)

    @cached_property
    def state_names(self) -> tuple[str, ...]:
        """``s_-2, v_-2, ..., s_0, v_0, ...`` (FD-LCC: ``-p_0, v_0, ...``)."""
        names = []
        for i in self.vehicles:
            names.append("-p_0" if (self.kind == "fd_lcc" and i == 0) else f"s_{i}")
            names.append(f"v_{i}")
        return tuple(names)

    def index(self, name: str) -> int:
        """Position of state ``name`` (e.g. ``"v_2"``)."""
        return state_index(self.state_names, name)

    def block(self, vehicle: int) -> slice:
        """Slice of the two states of ``vehicle`` (index -m..n)."""
        if vehicle not in self.vehicles:
            raise ConfigError(
                "vehicle", f"must be in [{-self.m}, {self.n}] for this model, got {vehicle}"
            )
        j = self.vehicles.index(vehicle)
        return slice(2 * j, 2 * j + 2)

    @property
    def tail_velocity_index(self) -> int:
        """Index of the velocity error of the last vehicle of the string."""
        return self.nx - 1

    def output_matrix(self, names: Sequence[str]) -> np.ndarray:
        """Selection matrix ``C`` whose rows pick the named states."""
        return selection_matrix(self.state_names, names)

    def to_statespace(self, outputs: Sequence[str] | None = None):
        """``control.StateSpace`` with inputs ``(u, v_h)`` and the chosen state outputs.

        Parameters
        ----------
        outputs : sequence of str, optional
            State names to output; default all states.
        """
        import control as ct

        names = list(self.state_names if outputs is None else outputs)
        C = self.output_matrix(names)
        D = np.zeros((len(names), 2))
        return ct.ss(
            self.A,
            np.hstack([self.B, self.H]),
            C,
            D,
            inputs=["u", "v_h"],
            outputs=names,
            states=list(self.state_names),
            name=self.kind,
        )


def _coef_list(coef: CoefArg, count: int, what: str) -> list[LinearCoefficients]:
    if isinstance(coef, LinearCoefficients):
        return [coef] * count
    coef = list(coef)
    if len(coef) != count:
        raise ConfigError(what, f"needs {count} sets of coefficients, got {len(coef)}")
    for c in coef:
        if not isinstance(c, LinearCoefficients):
            raise ConfigError(what, f"entries must be LinearCoefficients, got {type(c).__name__}")
    return coef


def _check_size(name: str, value: int, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
        raise ConfigError(name, f"must be an integer >= {low}, got {value!r}")
    return int(value)


def build_model(kind: str, m: int, n: int, hdv: CoefArg, cav: LinearCoefficients | None = None):
    """Build any of the four models.

    Parameters
    ----------
    kind : {"lcc", "cf_lcc", "fd_lcc", "ccc"}
    m, n : int
        HDVs ahead and behind (``m`` must be 0 for CF/FD-LCC, ``n`` 0 for CCC).
    hdv : LinearCoefficients or sequence
        One set for a homogeneous string, or one per HDV ordered front to tail
        (vehicles ``-m..-1`` then ``1..n``).
    cav : LinearCoefficients, optional
        HDV-law coefficients of the CAV (CF-LCC dynamics, "added" gains); default: the
        coefficients of the first HDV behind, else the last ahead.
    """
    if kind not in KINDS:
        raise ConfigError("kind", f"must be one of {list(KINDS)}, got {kind!r}")
    m = _check_size("m", m, 0)
    n = _check_size("n", n, 0)
    if kind in ("cf_lcc", "fd_lcc") and m != 0:
        raise ConfigError("m", f"must be 0 for {kind} (no HDV ahead of the CAV), got {m}")
    if kind == "ccc" and n != 0:
        raise ConfigError("n", f"must be 0 for ccc (no HDV behind the CAV), got {n}")
    if kind != "ccc" and n < 1 and kind != "lcc":
        raise ConfigError("n", f"must be >= 1 for {kind}, got {n}")
    coefs = _coef_list(hdv, m + n, "hdv")
    if cav is None:
        cav = coefs[m] if n > 0 else (coefs[m - 1] if m > 0 else None)
    if cav is None:
        raise ConfigError("cav", "coefficients are required when there is no HDV")

    vehicles = tuple(range(-m, n + 1))
    per_vehicle = {i: c for i, c in zip([*range(-m, 0), *range(1, n + 1)], coefs, strict=True)}
    per_vehicle[0] = cav
    cav_role = {"fd_lcc": "free", "cf_lcc": "cav_hdv"}.get(kind, "cav")
    roles = [cav_role if i == 0 else "hdv" for i in vehicles]
    follows = [None if (kind == "fd_lcc" and i == 0) else (HEAD if j == 0 else j - 1)
               for j, i in enumerate(vehicles)]  # fmt: skip
    A, B, H = chain_matrices(roles, [per_vehicle[i] for i in vehicles], follows)
    return LCCModel(kind, m, n, A, B, H, vehicles, per_vehicle)


def general_lcc(m: int, n: int, hdv: CoefArg, cav: LinearCoefficients | None = None):
    """General LCC, eq. (9): m HDVs ahead, n behind."""
    return build_model("lcc", m, n, hdv, cav)


def cf_lcc(n: int, hdv: CoefArg, cav: LinearCoefficients | None = None):
    """CF-LCC, eq. (11): the CAV follows the head vehicle with the HDV law plus ``u_hat``."""
    return build_model("cf_lcc", 0, n, hdv, cav)


def fd_lcc(n: int, hdv: CoefArg):
    """FD-LCC, eq. (12): no vehicle ahead, first state ``-p_0``."""
    return build_model("fd_lcc", 0, n, hdv)


def ccc(m: int, hdv: CoefArg, cav: LinearCoefficients | None = None):
    """CCC, eq. (14): m HDVs ahead, none behind."""
    return build_model("ccc", m, 0, hdv, cav)


def model_from_hdv(
    kind: str,
    m: int,
    n: int,
    hdv: CarFollowingModel | Sequence[CarFollowingModel],
    v_star: float,
    warn: bool = True,
) -> LCCModel:
    """Linearise nonlinear HDV model(s) at ``v_star`` and build the LCC model.

    ``hdv`` is one model (homogeneous) or one per HDV ordered front to tail.
    """
    if isinstance(hdv, Sequence):
        coefs = [linear_coefficients(h, v_star, warn=warn) for h in hdv]
        cav = coefs[m] if n > 0 else coefs[-1]
    else:
        coefs = linear_coefficients(hdv, v_star, warn=warn)
        cav = coefs
    return build_model(kind, m, n, coefs, cav)
