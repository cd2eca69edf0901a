"""lcc_synth: design and test Leading Cruise Control (LCC) controllers.

The package follows the paper "Leading Cruise Control in Mixed Traffic Flow" (Wang, Zheng,
Chen, Xu, Li). Data flows one way: problem file -> model -> controller -> simulator ->
metrics -> recording / figures.

The flat API (:mod:`lcc_synth.api`) reads like the paper::

    import lcc_synth as lcc
    string = lcc.system("fd_lcc", n=10, v_star=15.0)
    lcc.controllability(string).verdict
    result = lcc.simulate(lcc.scenario(string, [lcc.Brake(vehicle=1)]), lcc.hdv_controller())
    lcc.metrics(result, window=lcc.TABLE2_WINDOW)["aave"]

Its names are loaded on first use (module ``__getattr__``): ``import lcc_synth`` imports only
:mod:`lcc_synth.errors`; the API imports numpy and scipy, and cvxpy, CasADi or Rerun only in
the functions that need them. Every name is the function or class of :mod:`lcc_synth.api`
itself (``lcc.metrics is lcc_synth.api.metrics``: its help and signature), also ``metrics``
and ``mpc``, which the module :mod:`lcc_synth.metrics` and the package :mod:`lcc_synth.mpc`
share: Python binds a submodule on its package when it is imported, and this package does not
let those two bindings replace the API's functions (``from lcc_synth.metrics import ...`` and
``from lcc_synth.mpc import ...`` import the modules as always; ``import lcc_synth.metrics as
m`` would give the function).
"""

import sys
import types

from lcc_synth.errors import ConfigError

__version__ = "0.1.0"

_API = (
    "OVM", "IDM", "System", "Scenario", "V2V", "Gains", "MetricsConfig",
    "Brake", "Sine", "BrakeProfile", "Profile",
    "system", "ring", "model", "controllability", "observability", "control_energy", "gains",
    "string_stability", "region_map", "h2_problem", "synthesize_h2", "hdv_controller",
    "static_controller", "mpc", "deep_lcc",
    "scenario", "simulate", "sweep", "metrics", "aave", "fuel", "calibrate", "record",
    "ProblemObjects", "Regions", "build_problem", "load_problem", "TABLE2_WINDOW",
)  # fmt: skip

#: API names that are also the names of a submodule (the module stays importable by its path).
_SUBMODULE_NAMES = ("metrics", "mpc")

__all__ = ["ConfigError", *_API]


class _Package(types.ModuleType):
    """``lcc_synth``: the import system's binding of the submodules named in
    :data:`_SUBMODULE_NAMES` is not kept, so those names stay the API's functions."""

    def __setattr__(self, name: str, value: object) -> None:
        if name in _SUBMODULE_NAMES and value is sys.modules.get(f"{__name__}.{name}"):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package


def __getattr__(name: str):
    if name == "api":
        import lcc_synth.api

        return lcc_synth.api
    if name in _API:
        from lcc_synth import api

        value = getattr(api, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'lcc_synth' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
