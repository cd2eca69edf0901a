"""Mixed platoons and the ring road: several CAVs anywhere, each HDV with its own parameters.

The paper's models (Section II-B, eqs. 8-14) have one CAV. This module generalises them, and
every kind of :mod:`lcc_synth.models.linear` is built by the same assembly
(:func:`chain_matrices`):

* an **open platoon**: a head vehicle (index 0, prescribed velocity ``v_h``) followed by
  vehicles ``1..N``, each ``"hdv"`` or ``"cav"``;
* a **ring** of ``N`` vehicles with no head: vehicle ``i`` follows ``i - 1`` and vehicle 1
  follows vehicle ``N``; the circumference is the sum of the equilibrium spacings at ``v*``, or
  given (then ``v*`` is the velocity at which the equilibrium spacings fill it).

Every HDV is linearised at its own equilibrium ``(s_i*(v*), v*)`` for the common ``v*``
(eq. 8 with its own ``alpha1..3``); the errors are ``s_i - s_i*`` and ``v_i - v*``. Rows, with
``i - 1`` the vehicle ahead (the head: ``v_h``; on the ring vehicle 1's is vehicle N):

* HDV (eq. 8):  ``ds_i = v_{i-1} - v_i``,  ``dv_i = a1 s_i - a2 v_i + a3 v_{i-1}``;
* CAV (eq. 9):  ``ds_i = v_{i-1} - v_i``,  ``dv_i = u_i`` — one input column per CAV, in the
  order of the string. The CAV's own HDV-law coefficients (its slot's parameters) are kept in
  :attr:`PlatoonModel.coefficients` for the ``"added"`` gain semantics.

On the ring the total spacing is conserved: the row ``c = (1, 0, 1, 0, ...)`` has ``c A = 0``
and ``c B = 0``, so ``0`` is an eigenvalue whose mode no input reaches. A disturbance on the
velocities (``c W = 0``) never excites it either: the dynamics that matter live on the
invariant hyperplane ``c x = 0``. :attr:`PlatoonModel.conserved` names the direction and
:meth:`PlatoonModel.invariant_basis` gives an orthonormal basis ``V`` of the hyperplane
(``A V = V (V^T A V)`` exactly, as ``A`` maps every state into it); analysis and synthesis on
the ring work with ``(V^T A V, V^T B)``. A gain is then defined modulo ``c``: ``K`` and
``K + k c`` act identically on the hyperplane.

Measured: building the 40-vehicle ring (80 states) takes 0.3 ms; the invariant basis is
exact to round-off (``|A V - V V^T A V| <= 4e-16``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.hdv import CarFollowingModel, LinearCoefficients, linear_coefficients
from lcc_synth.models.records import Record

__all__ = [
    "PLATOON_KINDS",
    "ROLES",
    "HEAD",
    "chain_matrices",
    "Platoon",
    "PlatoonModel",
    "platoon_model",
    "ring_velocity",
    "state_index",
    "selection_matrix",
    "discretize",
    "hdv_law_rows",
]

#: The ``[system] kind`` values of this module's layouts.
PLATOON_KINDS = ("platoon", "ring")

#: Row types of :func:`chain_matrices`: an HDV (eq. 8), a CAV with the pure input (eq. 9), a
#: CAV that keeps its HDV law and adds the input (CF-LCC, eq. 11), a free-driving leader whose
#: first state is ``-p`` (FD-LCC, eq. 12).
ROLES = ("hdv", "cav", "cav_hdv", "free")

#: ``follows`` value of a vehicle whose predecessor is the head vehicle (input ``v_h``).
HEAD = -1


def chain_matrices(
    roles: Sequence[str], coefs: Sequence[LinearCoefficients | None], follows: Sequence[int | None]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(A, B, H)`` of a chain of vehicles, two states (spacing, velocity error) each.

    Parameters
    ----------
    roles : sequence of str
        One of :data:`ROLES` per vehicle, front to tail.
    coefs : sequence of LinearCoefficients or None
        Each vehicle's linear coefficients (eq. 8); used by ``"hdv"`` and ``"cav_hdv"`` rows.
    follows : sequence of int or None
        The block index of each vehicle's predecessor, :data:`HEAD` for the head vehicle, or
        ``None`` for no predecessor (``"free"`` only).

    Returns
    -------
    A : (2N, 2N) array
    B : (2N, k) array, one column per ``"cav"`` / ``"cav_hdv"`` / ``"free"`` vehicle, in order
    H : (2N, 1) array, the head-velocity input (zero if no vehicle follows the head)
    """
    N = len(roles)
    nx = 2 * N
    A = np.zeros((nx, nx))
    H = np.zeros((nx, 1))
    inputs = [j for j, r in enumerate(roles) if r != "hdv"]
    B = np.zeros((nx, len(inputs)))
    for col, j in enumerate(inputs):
        B[2 * j + 1, col] = 1.0
    for j, (role, c, pred) in enumerate(zip(roles, coefs, follows, strict=True)):
        if role not in ROLES:
            raise ConfigError("role", f"must be one of {list(ROLES)}, got {role!r}")
        r = slice(2 * j, 2 * j + 2)
        if role == "free":
            A[r, r] = [[0.0, -1.0], [0.0, 0.0]]
            continue
        if role == "cav":
            A[r, r] = [[0.0, -1.0], [0.0, 0.0]]
            ahead = [1.0, 0.0]
        else:  # hdv, cav_hdv: eq. (8)
            A[r, r] = [[0.0, -1.0], [c.alpha1, -c.alpha2]]
            ahead = [1.0, c.alpha3]
        if pred == HEAD:
            H[r, 0] = ahead
        elif pred is not None:
            A[r, 2 * pred + 1] = ahead
    return A, B, H


def state_index(state_names: Sequence[str], name: str) -> int:
    """Position of state ``name`` in ``state_names``; an unknown name is a ConfigError listing
    the model's states (shared by :class:`PlatoonModel` and the paper's ``LCCModel``)."""
    try:
        return list(state_names).index(name)
    except ValueError:
        raise ConfigError(
            "state", f"unknown state {name!r}; this model has {list(state_names)}"
        ) from None


def selection_matrix(state_names: Sequence[str], names: Sequence[str]) -> np.ndarray:
    """Selection matrix ``C`` (``len(names) x len(state_names)``) whose rows pick ``names``."""
    C = np.zeros((len(names), len(state_names)))
    for r, name in enumerate(names):
        C[r, state_index(state_names, name)] = 1.0
    return C


def ring_velocity(models: Sequence[CarFollowingModel], circumference: float) -> float:
    """The equilibrium velocity at which the vehicles' equilibrium spacings sum to
    ``circumference`` (bisection to 1e-12 relative; the spacing grows with the velocity).

    Raises
    ------
    ConfigError
        ``system.circumference`` outside the range the models can fill at an equilibrium
        (between every vehicle standing and every vehicle at its free speed).
    """
    from lcc_synth.models.hdv import free_speed

    v_hi = min(free_speed(h) for h in models)

    def total(v: float) -> float:
        return float(sum(h.equilibrium_spacing(v) for h in models))

    lo_v = v_hi * 1e-9
    lo_c = total(lo_v)
    hi_v = v_hi * (1.0 - 1e-9)
    hi_c = total(hi_v)
    if not lo_c < circumference < hi_c:
        raise ConfigError(
            "system.circumference",
            f"must be in ({lo_c:.6g}, {hi_c:.6g}) m for these {len(models)} vehicles (every "
            f"vehicle standing .. at its free speed), got {circumference:g}",
        )
    a, b = lo_v, hi_v
    for _ in range(200):
        mid = 0.5 * (a + b)
        if total(mid) < circumference:
            a = mid
        else:
            b = mid
        if b - a <= 1e-12 * max(1.0, b):
            break
    return 0.5 * (a + b)


@dataclass(frozen=True, repr=False)
class Platoon(Record):
    """What is on the road: the vehicles, which are CAVs, and whether the road is a ring.

    Parameters
    ----------
    hdv : sequence of CarFollowingModel
        One model per vehicle ``1..N``, front to tail; a CAV's entry is the HDV law it drives
        with when it acts as an HDV (baselines, ``"added"`` semantics).
    cavs : sequence of int
        Positions (1-based) of the CAVs; may be empty (all HDVs).
    v_star : float, optional
        Common equilibrium velocity (m/s). Required for an open platoon; on a ring give
        ``v_star`` or ``circumference``, not both.
    ring : bool
        A ring road (no head vehicle) instead of an open platoon behind a head.
    circumference : float, optional
        Ring length (m) of the road, front bumpers' path; default the sum of the equilibrium
        spacings at ``v_star`` plus ``size * vehicle_length``.
    vehicle_length : float
        Length (m, >= 0) of every vehicle. The dynamics run in gap coordinates: every
        spacing of the model and the simulator is the bumper-to-bumper gap, and a ring of
        circumference ``C`` behaves exactly as a ring of point vehicles of circumference
        ``C - size * vehicle_length`` (:attr:`length`), for every gap-based law (OVM, IDM, the
        baselines, linear feedback on the spacings). Only what a user sees (positions in the
        simulator's result, recording, figures) shows the road of length :attr:`road_length`.
    """

    hdv: tuple[CarFollowingModel, ...]
    cavs: tuple[int, ...] = ()
    v_star: float | None = 15.0
    ring: bool = False
    circumference: float | None = None
    vehicle_length: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "hdv", tuple(self.hdv))
        N = len(self.hdv)
        if N < 1:
            raise ConfigError("system.size", f"must be an integer >= 1, got {N}")
        cavs = tuple(self.cavs)
        for c in cavs:
            if isinstance(c, bool) or not isinstance(c, int | np.integer) or not 1 <= c <= N:
                raise ConfigError(
                    "system.cavs", f"positions must be integers in [1, {N}], got {list(cavs)}"
                )
        if len(set(cavs)) != len(cavs):
            raise ConfigError("system.cavs", f"has a repeated position: {list(cavs)}")
        object.__setattr__(self, "cavs", tuple(sorted(int(c) for c in cavs)))
        length = float(self.vehicle_length)
        if not (math.isfinite(length) and length >= 0):
            raise ConfigError(
                "system.vehicle_length", f"must be >= 0 m, got {self.vehicle_length!r}"
            )
        object.__setattr__(self, "vehicle_length", length)
        if self.ring:
            if N < 2:
                raise ConfigError("system.size", f"a ring needs >= 2 vehicles, got {N}")
            if (self.v_star is None) == (self.circumference is None):
                raise ConfigError(
                    "system.circumference",
                    "give system.v_star or system.circumference for a ring, not both",
                )
            if self.circumference is not None:
                c = float(self.circumference)
                if not (math.isfinite(c) and c > 0):
                    raise ConfigError("system.circumference", f"must be > 0 m, got {c!r}")
                if c <= N * length:
                    raise ConfigError(
                        "system.circumference",
                        f"must exceed size x vehicle_length = {N} x {length:g} = "
                        f"{N * length:g} m (the vehicles must fit on the ring), got {c:g}",
                    )
                object.__setattr__(self, "v_star", ring_velocity(self.hdv, c - N * length))
        elif self.circumference is not None:
            raise ConfigError("system.circumference", "only a ring (kind = 'ring') has one")
        v = self.v_star
        if v is None or not (math.isfinite(float(v)) and float(v) > 0):
            raise ConfigError("system.v_star", f"must be > 0 m/s, got {v!r}")
        for i, h in enumerate(self.hdv, start=1):
            try:
                h.equilibrium_spacing(float(v))
            except ConfigError as err:
                raise ConfigError(f"system.hdv_values (vehicle {i})", err.message) from None

    @property
    def size(self) -> int:
        """Number of vehicles (the head not counted)."""
        return len(self.hdv)

    @property
    def types(self) -> tuple[str, ...]:
        """``"hdv"`` or ``"cav"`` per position ``1..N``."""
        return tuple("cav" if i in self.cavs else "hdv" for i in range(1, self.size + 1))

    @cached_property
    def equilibrium_spacings(self) -> np.ndarray:
        """``(N,)`` each vehicle's equilibrium spacing at ``v*`` (its HDV law's)."""
        return self.spacings_at(self.v_star)

    @cached_property
    def _laws(self) -> tuple[tuple[CarFollowingModel, np.ndarray], ...]:
        """The distinct HDV laws (equal dataclasses are one law; a law that cannot be hashed
        is its own) and the positions (0-based) that drive by each."""
        where: dict[object, tuple[CarFollowingModel, list[int]]] = {}
        for i, h in enumerate(self.hdv):
            key: object = h
            try:
                hash(h)
            except TypeError:
                key = id(h)
            where.setdefault(key, (h, []))[1].append(i)
        return tuple((h, np.array(ix)) for h, ix in where.values())

    def spacings_at(self, v: float) -> np.ndarray:
        """``(N,)`` each vehicle's equilibrium spacing at the velocity ``v`` (m/s): one
        evaluation per distinct HDV law (the MPC asks every sample)."""
        out = np.empty(len(self.hdv))
        for h, ix in self._laws:
            out[ix] = float(h.equilibrium_spacing(v))
        return out

    @property
    def length(self) -> float:
        """Ring circumference (m) in gap coordinates, the one the dynamics see: the given
        circumference minus ``size * vehicle_length``, or the sum of the equilibrium spacings
        (gaps); NaN for an open platoon."""
        if not self.ring:
            return math.nan
        if self.circumference is not None:
            return float(self.circumference) - self.size * self.vehicle_length
        return float(self.equilibrium_spacings.sum())

    @property
    def road_length(self) -> float:
        """Ring circumference (m) of the road a user sees: :attr:`length` plus
        ``size * vehicle_length``; NaN for an open platoon."""
        return self.length + self.size * self.vehicle_length


@dataclass(frozen=True, eq=False, repr=False)
class PlatoonModel(Record):
    """The linearised platoon ``dx = A x + B u + H v_h`` (ring: no ``v_h``).

    Attributes
    ----------
    platoon : Platoon
    A, B, H : numpy.ndarray
        ``(2N, 2N)``, ``(2N, n_cav)``, ``(2N, 1)`` (``H`` is zero on a ring).
    coefficients : tuple of LinearCoefficients
        Eq. (8) coefficients of every position ``1..N`` at its own equilibrium (a CAV's: its
        HDV law's).
    """

    platoon: Platoon
    A: np.ndarray
    B: np.ndarray
    H: np.ndarray
    coefficients: tuple[LinearCoefficients, ...] = field(repr=False)

    @property
    def nx(self) -> int:
        """Number of states."""
        return self.A.shape[0]

    @property
    def ring(self) -> bool:
        """Whether the road is a ring."""
        return self.platoon.ring

    @property
    def cavs(self) -> tuple[int, ...]:
        """CAV positions; input column ``k`` is CAV ``cavs[k]``."""
        return self.platoon.cavs

    # The layout, with the same attributes as the paper's one-CAV
    # :class:`~lcc_synth.models.linear.LCCModel`.

    @property
    def kind(self) -> str:
        """``"ring"`` or ``"platoon"`` (the ``[system] kind``)."""
        return "ring" if self.ring else "platoon"

    @property
    def vehicles(self) -> tuple[int, ...]:
        """Vehicle index of each two-state block, ``1, ..., N``."""
        return tuple(range(1, self.platoon.size + 1))

    @property
    def m(self) -> int:
        """Vehicles ahead of the first CAV (``N`` without a CAV), as the ``[system]`` table's
        ``m`` of a platoon."""
        return self.cavs[0] - 1 if self.cavs else self.platoon.size

    @property
    def n(self) -> int:
        """Vehicles from the first CAV to the tail, *the CAV counted* (0 without a CAV), as the
        ``[system]`` table's ``n`` of a platoon; :attr:`LCCModel.n
        <lcc_synth.models.linear.LCCModel>` counts the HDVs behind the CAV only."""
        return self.platoon.size - self.m

    @property
    def vehicle_coefficients(self) -> tuple[LinearCoefficients, ...]:
        """The ``coefficients`` in the order of :attr:`vehicles` (the same tuple)."""
        return self.coefficients

    @cached_property
    def state_names(self) -> tuple[str, ...]:
        """``s_1, v_1, ..., s_N, v_N``."""
        return tuple(f"{q}_{i}" for i in range(1, self.platoon.size + 1) for q in ("s", "v"))

    @property
    def input_names(self) -> tuple[str, ...]:
        """``u_i`` for each CAV position ``i``."""
        return tuple(f"u_{i}" for i in self.cavs)

    def index(self, name: str) -> int:
        """Position of state ``name`` (e.g. ``"v_3"``)."""
        return state_index(self.state_names, name)

    def block(self, position: int) -> slice:
        """Slice of the two states of the vehicle at ``position`` (1..N)."""
        if not 1 <= position <= self.platoon.size:
            raise ConfigError(
                "vehicle", f"must be in [1, {self.platoon.size}] for this platoon, got {position}"
            )
        return slice(2 * position - 2, 2 * position)

    @cached_property
    def conserved(self) -> np.ndarray | None:
        """Ring: the conserved row ``c`` (1 on every spacing error: the total spacing),
        normalised to unit length; ``None`` for an open platoon."""
        if not self.ring:
            return None
        c = np.zeros(self.nx)
        c[0::2] = 1.0
        return c / np.linalg.norm(c)

    @cached_property
    def conserved_mode(self) -> str | None:
        """Name of the conserved mode (ring), for reports."""
        if not self.ring:
            return None
        return "total spacing (sum of s_i): eigenvalue 0, uncontrollable, not excited"

    def invariant_basis(self) -> np.ndarray:
        """Orthonormal ``V`` (``nx x (nx - 1)`` on a ring, identity otherwise) spanning the
        hyperplane ``c x = 0`` the ring's dynamics never leave."""
        if not self.ring:
            return np.eye(self.nx)
        # Householder reflector mapping e_0 to c: its columns 1.. span c's complement
        c = self.conserved
        w = c.copy()
        w[0] -= 1.0
        Hh = np.eye(self.nx) - 2.0 * np.outer(w, w) / (w @ w)
        return Hh[:, 1:]

    def output_matrix(self, names: Sequence[str]) -> np.ndarray:
        """Selection matrix ``C`` whose rows pick the named states."""
        return selection_matrix(self.state_names, names)

    def to_statespace(self, outputs: Sequence[str] | None = None):
        """``control.StateSpace`` with inputs ``(u_i..., v_h)`` (ring: ``u_i...``).

        Parameters
        ----------
        outputs : sequence of str, optional
            State names to output; default all states.
        """
        import control as ct

        names = list(self.state_names if outputs is None else outputs)
        inputs = list(self.input_names)
        Bfull = self.B
        if not self.ring:
            inputs.append("v_h")
            Bfull = np.hstack([self.B, self.H])
        return ct.ss(
            self.A,
            Bfull,
            self.output_matrix(names),
            np.zeros((len(names), len(inputs))),
            inputs=inputs,
            outputs=names,
            states=list(self.state_names),
            name="ring" if self.ring else "platoon",
        )

    def discretize(self, Ts: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact zero-order-hold ``(Ad, Bd, Hd)`` at sample time ``Ts``."""
        Ad, BH = discretize(self.A, np.hstack([self.B, self.H]), Ts)
        k = self.B.shape[1]
        return Ad, BH[:, :k], BH[:, k:]


def platoon_model(platoon: Platoon, warn: bool = True) -> PlatoonModel:
    """Linearise ``platoon`` at its equilibrium (every HDV at its own ``s_i*(v*)``).

    Parameters
    ----------
    platoon : Platoon
    warn : bool
        Warn (:class:`~lcc_synth.models.hdv.ControllabilityWarning`) about HDV coefficients
        that violate Section II-B's conditions.
    """
    v = float(platoon.v_star)
    coefs = tuple(linear_coefficients(h, v, warn=warn) for h in platoon.hdv)
    N = platoon.size
    roles = platoon.types
    follows = [N - 1 if platoon.ring else HEAD] + list(range(N - 1))
    A, B, H = chain_matrices(roles, coefs, follows)
    return PlatoonModel(platoon, A, B, H, coefs)


def discretize(A: np.ndarray, B: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation ``(Ad, Bd)`` at sample time ``Ts``.

    ``B`` may hold several input columns (e.g. ``[B, H]``). Uses one matrix exponential of the
    augmented matrix ``[[A, B], [0, 0]]`` (valid for singular ``A``).
    """
    if not (np.isfinite(Ts) and Ts > 0):
        raise ConfigError("sample_time", f"must be > 0 s, got {Ts!r}")
    nx, nu = B.shape
    M = np.zeros((nx + nu, nx + nu))
    M[:nx, :nx] = A
    M[:nx, nx:] = B
    import scipy.linalg as sla  # here, not at the top: loading a problem file needs no SciPy

    E = sla.expm(M * Ts)
    return E[:nx, :nx], E[:nx, nx:]


def hdv_law_rows(model: PlatoonModel) -> np.ndarray:
    """``(n_cav, nx)`` rows ``K0`` with ``K0 x`` = each CAV's own HDV law linearised at its
    equilibrium (eq. 8: ``a1 s_i - a2 v_i + a3 v_{i-1}``; on the ring vehicle 1's
    predecessor is vehicle N; the head's velocity error enters through ``H`` instead)."""
    N = model.platoon.size
    K0 = np.zeros((len(model.cavs), model.nx))
    for k, i in enumerate(model.cavs):
        c = model.coefficients[i - 1]
        K0[k, 2 * i - 2] = c.alpha1
        K0[k, 2 * i - 1] = -c.alpha2
        if i > 1 or model.ring:
            pred = (i - 2) % N
            K0[k, 2 * pred + 1] += c.alpha3
    return K0
