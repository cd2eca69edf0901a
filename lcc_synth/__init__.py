"""lcc_synth: design and test Leading Cruise Control (LCC) controllers.

The package follows the paper "Leading Cruise Control in Mixed Traffic Flow" (Wang, Zheng,
Chen, Xu, Li). Data flows one way: problem file -> model -> controller -> simulator ->
metrics -> recording / figures.

The flat API (:mod:`lcc_synth.api`) reads like the paper::

    import lcc_synth as lcc
    sys = lcc.system("fd_lcc", n=10, v_star=15.0)
    lcc.controllability(sys.linear_model()).verdict
    result = lcc.simulate(lcc.scenario(sys, [lcc.Brake(vehicle=1)]), lcc.hdv_controller())
    lcc.metrics(result, window=lcc.TABLE2_WINDOW)["aave"]

Its names are loaded on first use (module ``__getattr__``): ``import lcc_synth`` imports only
:mod:`lcc_synth.errors`; the API imports numpy and scipy, and cvxpy, CasADi or Rerun only in
the functions that need them.
"""

from lcc_synth.errors import ConfigError

__version__ = "0.1.0"

_API = (
    "OVM", "IDM", "System", "Scenario", "V2V", "StaticGains", "MetricsConfig",
    "Brake", "Sine", "BrakeProfile", "Profile",
    "system", "model", "controllability", "observability", "control_energy", "gains",
    "string_stability", "region_map", "h2_problem", "synthesize_h2", "hdv_controller",
    "static_controller",
    "mpc", "scenario", "simulate", "metrics", "aave", "fuel", "record",
    "ProblemObjects", "build_problem", "load_problem", "TABLE2_WINDOW",
)  # fmt: skip

__all__ = ["ConfigError", *_API]


def __getattr__(name: str):
    if name == "api":
        import lcc_synth.api

        return lcc_synth.api
    if name == "metrics":  # the module, callable as api.metrics (it is bound here once imported)
        import lcc_synth.metrics

        return lcc_synth.metrics
    if name == "mpc":  # the package, callable as api.mpc
        import lcc_synth.mpc

        return lcc_synth.mpc
    if name in _API:
        from lcc_synth import api

        value = getattr(api, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'lcc_synth' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
