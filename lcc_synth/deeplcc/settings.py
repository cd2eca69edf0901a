"""Settings of DeeP-LCC and their problem-file table (``type = "deep_lcc"``)::

    [controllers.deep_lcc]
    type = "deep_lcc"
    t_ini = 20                 # past samples Tini
    horizon = 50               # prediction steps N
    equilibrium = "moving_average"   # v* from the head's recent speed (fd_lcc: "fixed")
    equilibrium_window = 0.5   # s (see lcc_synth.deeplcc.controller)

    [controllers.deep_lcc.weights]
    velocity = 1.0             # Q on every velocity error behind the head
    spacing = 0.5              # Q on every CAV's spacing error
    input = 0.1                # R on every CAV acceleration
    lambda_g = 100.0
    lambda_y = 1.0e4
    past_outputs = "slack"     # or "exact": Y_p g = y_ini (noise-free data, lambda_g = 0)
    slack = 100.0              # exact l1 penalty of the soft spacing bound (per m and step)
    slack_quadratic = 1.0

    [controllers.deep_lcc.constraints]   # as the MPC's (lcc_synth.mpc.settings.Constraints)
    a_min = -5.0
    a_max = 2.0
    s_min = 5.0                # s >= s_min + t_gap v, absolute metres, every CAV
    t_gap = 0.8
    margin = 0.1
    spacing = "safe"           # or "equilibrium": the DeeP-LCC paper's spacing-error bound
    spacing_error = [-15.0, 20.0]   # lo <= s - s*(v_eq) <= hi (m), both soft

    [controllers.deep_lcc.solver]        # OSQP, as the MPC's, but max_iter = 200 and
    exact = true               # then DAQP (exact active set) before the fallback chain
    [controllers.deep_lcc.data]          # lcc_synth.deeplcc.data.DataSettings
    T = 2000
    dt = 0.05                  # also the controller's period
    seed = 0
    u_amplitude = 1.0
    e_amplitude = 1.0
    cache = true
    cache_dir = "results/deeplcc"

Every bad value is a :class:`~lcc_synth.errors.ConfigError` naming the dotted field.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from lcc_synth.deeplcc.data import DataSettings
from lcc_synth.errors import ConfigError
from lcc_synth.models.records import Record
from lcc_synth.mpc.settings import SolverSettings, check_spacing_target
from lcc_synth.schema import declared
from lcc_synth.schema.controllers import DEEP_MAX_ITER

__all__ = ["DeepWeights", "DeepConstraints", "DeePLCCSettings", "deep_settings_from_table"]


@dataclass(frozen=True, repr=False)
class DeepWeights(Record):
    """Cost weights of DeeP-LCC (Wang et al. 2023, Section V defaults)."""

    velocity: float = 1.0
    spacing: float = 0.5
    input: float = 0.1
    lambda_g: float = 100.0
    lambda_y: float = 1.0e4
    past_outputs: str = "slack"
    slack: float = 100.0
    slack_quadratic: float = 1.0


@dataclass(frozen=True, repr=False)
class DeepConstraints(Record):
    """Hard acceleration bounds and the soft spacing bound of every CAV: the absolute safe
    spacing (``spacing = "safe"``) or the paper's bound on the spacing error from ``s*(v_eq)``
    (``"equilibrium"``), as the MPC's :class:`~lcc_synth.mpc.settings.Constraints`."""

    a_min: float = -5.0
    a_max: float = 2.0
    s_min: float = 5.0
    t_gap: float = 0.8
    margin: float = 0.1
    spacing: str = "safe"
    spacing_error: tuple[float, float] = (-15.0, 20.0)


@dataclass(frozen=True, repr=False)
class DeePLCCSettings(Record):
    """Everything that defines a DeeP-LCC controller (module docstring)."""

    t_ini: int = 20
    horizon: int = 50
    equilibrium: str | None = None
    equilibrium_window: float = 0.5
    weights: DeepWeights = field(default_factory=DeepWeights)
    constraints: DeepConstraints = field(default_factory=DeepConstraints)
    solver: SolverSettings = field(default_factory=lambda: SolverSettings(max_iter=DEEP_MAX_ITER))
    data: DataSettings = field(default_factory=DataSettings)
    exact: bool = True

    def __post_init__(self) -> None:
        c = self.constraints
        if not c.a_min < 0 < c.a_max:
            raise ConfigError("constraints.a_min", f"need a_min < 0 < a_max, got "
                              f"[{c.a_min}, {c.a_max}]")  # fmt: skip
        for name in ("t_ini", "horizon"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(name, f"must be an integer >= 1, got {v!r}")
        check_spacing_target(c.spacing, c.spacing_error, "constraints")

    @property
    def sample_time(self) -> float:
        """The controller's period: the data's sample time."""
        return float(self.data.dt)

    def equilibrium_mode(self, kind: str) -> str:
        """The equilibrium estimator used on a string of ``kind``."""
        if self.equilibrium is not None:
            return self.equilibrium
        return "fixed" if kind == "fd_lcc" else "moving_average"

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable view."""
        out = asdict(self)
        out["data"].pop("field", None)
        out["constraints"]["spacing_error"] = list(self.constraints.spacing_error)
        return out

    def toml_table(self) -> dict[str, Any]:
        """The ``[controllers.NAME]`` table of these settings (``None`` values left out)."""
        d = self.as_dict()
        d["data"] = {k: v for k, v in d["data"].items() if v is not None}
        d["solver"]["exact"] = d.pop("exact")  # a key of the solver table
        return {"type": "deep_lcc", **{k: v for k, v in d.items() if v is not None}}


def deep_settings_from_table(table: Mapping[str, Any], field_name: str) -> DeePLCCSettings:
    """Parse a ``[controllers.NAME]`` table of ``type = "deep_lcc"``.

    Parameters
    ----------
    table : mapping
    field_name : str
        Its dotted path (``"controllers.deep_lcc"``).
    """
    f = field_name
    top = declared("controllers.NAME:deep_lcc")
    top.check(table, f)

    def read(sub: str) -> dict[str, Any]:
        t = declared(f"controllers.NAME.{sub}:deep_lcc")
        raw = top.get(table, sub, f)
        t.check(raw, f"{f}.{sub}")
        return {k: t.get(raw, k, f"{f}.{sub}") for k in t.names}

    c = read("constraints")
    c["spacing_error"] = tuple(c["spacing_error"])
    check_spacing_target(c["spacing"], c["spacing_error"], f"{f}.constraints")
    if not c["a_min"] < 0 < c["a_max"]:
        raise ConfigError(f"{f}.constraints.a_min", "need a_min < 0 < a_max, got "
                          f"[{c['a_min']}, {c['a_max']}]")  # fmt: skip
    solver_keys = read("solver")
    exact = bool(solver_keys.pop("exact"))
    solver = SolverSettings(**solver_keys)
    if solver.eps_abs > 1e-3 or solver.eps_rel > 1e-3:
        raise ConfigError(f"{f}.solver.eps_abs", "must be <= 1e-3 (and eps_rel too), got "
                          f"eps_abs={solver.eps_abs}, eps_rel={solver.eps_rel}")  # fmt: skip
    data = DataSettings(**read("data"), field=f"{f}.data")
    return DeePLCCSettings(
        t_ini=top.get(table, "t_ini", f),
        horizon=top.get(table, "horizon", f),
        equilibrium=top.get(table, "equilibrium", f),
        equilibrium_window=top.get(table, "equilibrium_window", f),
        weights=DeepWeights(**read("weights")),
        constraints=DeepConstraints(**c),
        solver=solver,
        data=data,
        exact=exact,
    )
