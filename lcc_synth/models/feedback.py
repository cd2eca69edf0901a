"""Static LCC state feedback (eq. 23) for any number of CAVs: the one gains record.

:class:`Gains` is every static gain of the package: a matrix ``K`` with one row per CAV
(``cavs``) and one column per named state (``states``), and how it enters each CAV's command
(``semantics``). The state names say which vehicle each column is, in the indexing of the
layout's model (its ``vehicles``), and ``cavs`` says which layout that is:

* the paper's single-CAV models (``kind = "lcc" | "cf_lcc" | "fd_lcc" | "ccc"``, Sec. II):
  vehicles are indexed from the CAV, ``cavs = (0,)``: ``s_0``/``v_0`` are the CAV's own errors
  (gains ``k_s_0``/``k_v_0`` on top of its HDV law), ``s_i``/``v_i`` with ``i = 1..n`` the
  HDVs behind it and ``i = -1..-m`` those ahead (gains ``mu_i``/``k_i``, Fig. 6), ``-p_0`` the
  FD-LCC position state. :meth:`Gains.from_paper` builds such a gain from ``mu_i``/``k_i``
  and :meth:`Gains.paper` reads them back;
* a platoon or a ring (``kind = "platoon" | "ring"``): vehicles are positions ``1..N`` from
  the head, ``cavs`` the CAV positions, ``s_i``/``v_i`` vehicle ``i``'s errors
  (:meth:`Gains.from_table` reads the per-CAV table ``{"u_3": {"s_2": ..., ...}}``).

So ``s_1`` is always "the spacing error of vehicle 1 of the model the gain is on", and a gain
only applies to a model with its CAVs (:meth:`Gains.check`): a paper gain (CAV 0) is refused
by a platoon model and the other way round. A TOML table reads
``gains = { s_-2 = 1.0, v_-2 = -1.0 }`` (one CAV) or ``gains = { u_3 = { s_2 = 1.0 } }``.

Two semantics, both used by the paper:

``added``    eq. (23), Sections IV and V-A: the CAV keeps the HDV law towards the vehicle ahead
             and the gains are added, ``u = a1 s0 - a2 v0 + a3 v_-1 + sum(mu_i s_i + k_i v_i)``
             (a gain on ``s_0``/``v_0`` adds to ``a1``/``-a2``).
``replace``  the Section V-B demo gains: ``u = sum(gain * state)`` is the whole command
             (e.g. FD-LCC ``u = -0.5 v0 - 0.2 s1 + 0.05 v1 - 0.1 s2 + 0.05 v2``).

:meth:`Gains.input_feedback` expresses the CAVs' commands as ``u = K x + kh v_h`` on the
model's state ``x`` (one CAV of a paper model: ``K`` of ``nx`` entries and ``kh`` a number;
``kh`` is non-zero only when the HDV law needs the head velocity). Sign convention:
``u = +K x`` (no minus sign). Building a gain and its input feedback is a few array
operations (no factorisation); the entries are checked once, by
:func:`lcc_synth.models.gains.valid_gain`'s range.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from lcc_synth.errors import ConfigError
from lcc_synth.models.gains import GAIN_MAX, SEMANTICS, valid_gain
from lcc_synth.models.linear import KINDS, LCCModel
from lcc_synth.models.platoon import hdv_law_rows
from lcc_synth.models.records import Record, short

__all__ = ["SEMANTICS", "Gains", "hdv_law", "cav_feedback", "input_feedback", "closed_loop"]

_STATE_RE = re.compile(r"^(-p_0|[sv]_-?\d+)$")

#: The CAV of the paper's single-CAV models: vehicle 0 (vehicles indexed from the CAV).
PAPER_CAVS = (0,)


@dataclass(frozen=True, eq=False, repr=False)
class Gains(Record):
    """Static feedback gains of every CAV of a layout (eq. 23).

    Parameters
    ----------
    K : numpy.ndarray
        ``(len(cavs), len(states))``: row ``k`` is CAV ``cavs[k]``'s gain on ``states``; a
        state of the model not in ``states`` has gain 0.
    cavs : tuple of int
        The CAVs, one per row: ``(0,)`` for the paper's single-CAV models, else the CAV
        positions ``1..N`` of a platoon or ring (see the module docstring).
    states : tuple of str
        The state names of ``K``'s columns (``s_i``, ``v_i``, ``-p_0``), distinct.
    semantics : {"added", "replace"}
        See the module docstring.
    kh : numpy.ndarray, optional
        ``(len(cavs),)`` gains on the head velocity error, added to the input feedback;
        default zeros.
    """

    K: np.ndarray
    cavs: tuple[int, ...]
    states: tuple[str, ...]
    semantics: str
    kh: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.semantics not in SEMANTICS:
            raise ConfigError(
                "semantics", f"must be one of {list(SEMANTICS)}, got {self.semantics!r}"
            )
        cavs = tuple(int(c) for c in self.cavs)
        states = tuple(str(s) for s in self.states)
        for name in states:
            if not _STATE_RE.match(name):
                raise ConfigError(
                    f"gains.{name}", "state names look like s_-2, v_-2, s_0, v_1 or -p_0"
                )
        if len(set(states)) != len(states):
            raise ConfigError("gains", f"names a state twice: {list(states)}")
        K = np.asarray(self.K, dtype=float)
        if K.ndim == 1 and len(cavs) == 1:
            K = K.reshape(1, -1)
        if K.shape != (len(cavs), len(states)):
            raise ConfigError("gains", f"needs one row per CAV ({len(cavs)}: {list(cavs)}) with "
                              f"one entry per state ({len(states)}), got shape {K.shape}")
        bad = np.argwhere(~(np.abs(K) <= GAIN_MAX))
        if bad.size:
            k, j = (int(i) for i in bad[0])
            valid_gain(self._entry(cavs, k, states[j]), K[k, j])
        kh = np.zeros(len(cavs)) if self.kh is None else np.asarray(self.kh, float)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "cavs", cavs)
        object.__setattr__(self, "states", states)
        object.__setattr__(self, "kh", kh.reshape(len(cavs)))

    def __eq__(self, other: object) -> bool:
        """Equal gains: the same CAVs, semantics and head gains, and the same column per state
        name (the order of ``states`` does not matter)."""
        if type(other) is not type(self):
            return NotImplemented
        cols = {nm: self.K[:, j].tolist() for j, nm in enumerate(self.states)}
        other_cols = {nm: other.K[:, j].tolist() for j, nm in enumerate(other.states)}
        return (self.cavs, self.semantics, self.kh.tolist(), cols) == (
            other.cavs, other.semantics, other.kh.tolist(), other_cols)

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return (f"Gains(cavs={short(self.cavs)}, gains={short(self.as_table())}, "
                f"semantics={self.semantics!r})")

    @staticmethod
    def _entry(cavs: tuple[int, ...], k: int, name: str) -> str:
        """The field naming entry ``(k, name)``: ``gains.NAME`` (paper) or ``gains.u_i.NAME``."""
        return f"gains.{name}" if cavs == PAPER_CAVS else f"gains.u_{cavs[k]}.{name}"

    # -- constructors -------------------------------------------------------------------------

    @classmethod
    def named(cls, gains: Mapping[str, float], semantics: str = "added") -> Gains:
        """The paper's single-CAV gain by state name, e.g. ``{"s_1": -1.0, "v_1": -1.0}``
        (vehicles indexed from the CAV; missing states have gain 0; entries kept as given,
        zeros included)."""
        items = dict(gains)
        for name, value in items.items():
            if not _STATE_RE.match(str(name)):
                raise ConfigError(
                    f"gains.{name}", "state names look like s_-2, v_-2, s_0, v_1 or -p_0"
                )
            valid_gain(f"gains.{name}", value)
        return cls(np.array([[float(v) for v in items.values()]]).reshape(1, len(items)),
                   PAPER_CAVS, tuple(str(k) for k in items), semantics)  # fmt: skip

    @classmethod
    def from_mapping(
        cls, values: Mapping, model=None, semantics: str = "added", field: str = "gains"
    ) -> Gains:
        """A gain from its mapping on ``model``'s layout, the one reading of both forms: the
        paper's ``{state: gain}`` (:meth:`named`) without a model or on a one-CAV model
        (``cavs = (0,)``), the per-CAV table ``{"u_3": {...}}`` (:meth:`from_table`) on a
        platoon or ring (errors name ``field``). A per-CAV table without a platoon or ring is
        a ConfigError naming ``model``."""
        if model is not None and tuple(model.cavs) != PAPER_CAVS:
            return cls.from_table(values, model, semantics, field)
        if any(isinstance(v, Mapping) for v in values.values()):
            raise ConfigError(
                "model", "per-CAV gain tables ({'u_3': {...}}) are for a platoon or ring: give "
                "model=lcc.system(size=..., cavs=[...]) (or lcc.ring(...))",
            )
        return cls.named(values, semantics)

    @classmethod
    def from_paper(
        cls, mu: Mapping[int, float], k: Mapping[int, float], semantics: str = "added"
    ) -> Gains:
        """The paper's ``mu_i`` (spacing) and ``k_i`` (velocity) gains per vehicle ``i``
        (``i = 0``: the CAV's ``k_s_0``/``k_v_0``; ``1..n`` behind, ``-1..-m`` ahead)."""
        g = {f"s_{i}": v for i, v in mu.items()}
        g.update({f"v_{i}": v for i, v in k.items()})
        return cls.named(g, semantics)

    @classmethod
    def from_table(
        cls, table: Mapping, model, semantics: str = "replace", field: str = "gains"
    ) -> Gains:
        """A platoon or ring gain from its per-CAV table ``{"u_3": {"s_1": ..., ...}}`` (the
        form of :meth:`as_table`) on ``model``'s states; an unknown CAV or state is a
        ConfigError naming it."""
        K = np.zeros((len(model.cavs), model.nx))
        names = list(model.input_names)
        for u, row in table.items():
            if u not in names:
                raise ConfigError(f"{field}.{u}", f"not a CAV input; this platoon has "
                                  f"{sorted(names)}")  # fmt: skip
            if not isinstance(row, Mapping):
                raise ConfigError(f"{field}.{u}", "must be a table of state name -> gain")
            k = names.index(u)
            for nm, g in row.items():
                if nm not in model.state_names:
                    raise ConfigError(f"{field}.{u}.{nm}", f"unknown state; states are "
                                      f"s_1, v_1 .. s_{model.platoon.size}, "
                                      f"v_{model.platoon.size}")  # fmt: skip
                K[k, model.index(nm)] = valid_gain(f"{field}.{u}.{nm}", g)
        return cls(K, model.cavs, model.state_names, semantics)

    @classmethod
    def on(cls, model, K, semantics: str = "replace", kh=None) -> Gains:
        """The gain matrix ``K`` (one row per CAV of ``model``, one column per state of
        ``model``, in its order) as a gain on ``model``."""
        return cls(K, tuple(model.cavs), tuple(model.state_names), semantics, kh)

    @classmethod
    def zero(cls, model, semantics: str = "added") -> Gains:
        """The zero gain on ``model``'s states (``"added"``: each CAV drives with its HDV
        law)."""
        return cls.on(model, np.zeros((len(model.cavs), model.nx)), semantics)

    # -- views --------------------------------------------------------------------------------

    @property
    def gains(self) -> dict[str, float]:
        """The single-CAV gain by state name, ``{"s_1": -1.0, ...}`` (every entry of
        ``states``); a gain of several CAVs is a ConfigError (use :meth:`as_table`)."""
        if len(self.cavs) != 1:
            raise ConfigError("gains", f"hold one row per CAV ({list(self.cavs)}): read them "
                              "with as_table()")  # fmt: skip
        return {nm: float(g) for nm, g in zip(self.states, self.K[0], strict=True)}

    def paper(self) -> tuple[dict[int, float], dict[int, float]]:
        """``(mu, k)``: the paper's spacing and velocity gains by vehicle index (the inverse
        of :meth:`from_paper`; ``-p_0`` is left out)."""
        g = self.gains
        mu = {int(n[2:]): v for n, v in g.items() if n.startswith("s_")}
        return mu, {int(n[2:]): v for n, v in g.items() if n.startswith("v_")}

    def as_table(self) -> dict:
        """The problem-file and gains-file form: one CAV of a paper model: ``{state: gain}``
        (every entry); else ``{"u_3": {"s_1": ..., ...}, ...}`` (each CAV's non-zero gains)."""
        if self.cavs == PAPER_CAVS:
            return self.gains
        return {
            f"u_{i}": {nm: float(g) for nm, g in zip(self.states, row, strict=True) if g}
            for i, row in zip(self.cavs, self.K, strict=True)
        }

    def vehicles(self) -> list[int]:
        """Vehicle indices with a non-zero gain (the information the CAVs need)."""
        out = set()
        for j, name in enumerate(self.states):
            if np.any(self.K[:, j] != 0.0):
                out.add(0 if name == "-p_0" else int(name.split("_", 1)[1]))
        return sorted(out)

    # -- on a model ---------------------------------------------------------------------------

    def check(self, model) -> None:
        """Raise :class:`ConfigError` when the gains are for other CAVs than ``model``'s or
        name a state it does not have."""
        if tuple(model.cavs) != self.cavs:
            raise ConfigError(
                "gains", f"are for CAVs {list(self.cavs)}; the model has CAVs "
                f"{list(model.cavs)} ({model.kind}, {model.nx} states)",
            )
        for name in self.states:
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

    def matrix(self, model) -> np.ndarray:
        """``(len(cavs), model.nx)``: the gains on the model's states (no HDV law)."""
        self.check(model)
        K = np.zeros((len(self.cavs), model.nx))
        for j, name in enumerate(self.states):
            K[:, model.index(name)] = self.K[:, j]
        return K

    def input_feedback(self, model) -> tuple[np.ndarray, np.ndarray | float]:
        """``(K, kh)``: the model's inputs ``u = K x + kh v_h`` (``"added"``: with each CAV's
        HDV law). A paper model (``model.kind`` in :data:`~lcc_synth.models.linear.KINDS`):
        ``K`` of ``nx`` entries and ``kh`` a number (:func:`input_feedback`); else ``K`` one
        row per CAV and ``kh`` one entry each."""
        if model.kind in KINDS:
            return input_feedback(model, self)
        Km = self.matrix(model)
        if self.semantics == "replace":
            return Km, self.kh.copy()
        kh0 = np.array([
            model.coefficients[i - 1].alpha3 if (i == 1 and not model.ring) else 0.0
            for i in self.cavs
        ])  # fmt: skip
        return hdv_law_rows(model) + Km, kh0 + self.kh

    def closed_loop(self, model) -> tuple[np.ndarray, np.ndarray]:
        """``(A_cl, H_cl)`` of ``dx = A_cl x + H_cl v_h`` (:func:`closed_loop`)."""
        return closed_loop(model, *self.input_feedback(model))


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


def cav_feedback(model: LCCModel, gains: Gains) -> tuple[np.ndarray, float]:
    """CAV acceleration command ``u_cav = K x + kh v_h`` for the single-CAV ``gains`` on the
    paper model ``model``."""
    K, kh = gains.matrix(model)[0], float(gains.kh[0])
    if gains.semantics == "replace":
        return K, kh
    K_law, kh_law = hdv_law(model)
    return K + K_law, kh_law + kh


def input_feedback(model: LCCModel, gains: Gains) -> tuple[np.ndarray, float]:
    """Feedback on the paper model's own input (``u``, or ``u_hat`` for CF-LCC, whose ``A``
    already holds the CAV's HDV law): ``input = K x + kh v_h``."""
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
