"""Safety-constrained model predictive control of the CAV in LCC (CasADi formulation, OSQP).

- :mod:`lcc_synth.mpc.settings`: settings and their problem-file table.
- :mod:`lcc_synth.mpc.formulation`: the condensed QP of any number of CAVs, built once with
  CasADi, and the single-CAV prediction model.
- :mod:`lcc_synth.mpc.solver`: OSQP workspace (set up once), exact reference, naive rebuild.
- :mod:`lcc_synth.mpc.scaffold`: what every layout's MPC shares (sample loop, equilibrium,
  head prediction, linearisation cache, warm-started solve, statistics, status codes).
- :mod:`lcc_synth.mpc.controller`: the one MPC of every layout (:class:`MPCController`), its
  fallback chain, and the paper's one-CAV layout.
- :mod:`lcc_synth.mpc.joint_prediction`, :mod:`lcc_synth.mpc.joint`: the string layout, every
  CAV of a platoon or ring road (``[system] kind = "platoon" | "ring"``).
- :mod:`lcc_synth.mpc.build`: the controller of a ``[controllers.NAME]`` table.
- :mod:`lcc_synth.mpc.report`: its step record and statistics, the safety summary of runs.

One class is the MPC of any layout (:class:`MPCController`; ``JointMPCController`` is another
name of the same class, kept for code written against the joint MPC), and one entry point
builds it (:func:`~lcc_synth.mpc.build.build_mpc`, or a ``type = "mpc"`` table): the paper's
one-CAV error state for the paper's kinds, the joint state of every CAV for ``kind =
"platoon" | "ring"``; both run on :mod:`lcc_synth.mpc.scaffold`.

Feature matrix (``tests/test_mpc_layouts.py`` runs every "yes" on each layout through
:func:`~lcc_synth.mpc.build.build_mpc` and checks every refusal)::

    option                         one CAV (cf/fd/lcc/ccc)  platoon              ring
    prediction.delay (HDV delays)  yes                      yes                  yes
    prediction.cav_lag             yes                      yes (each CAV)       yes (each CAV)
    cav_lag with delay             ConfigError (cav_lag)    ConfigError (cav_lag)  (cav_lag)
    constraints.jerk_scale         yes                      yes (each CAV)       yes (each CAV)
    solver.method osqp / daqp      yes                      yes                  yes
    prediction.relinearize         yes                      yes                  yes
    prediction.head = "accel"      yes                      yes                  no head: no effect
    prediction.equilibrium         yes                      yes                  yes (mean speed)
    constraints.spacing            yes                      yes (each CAV)       yes (each CAV)
    n_model                        yes                      ConfigError          ConfigError
    constraints.behind             yes                      ConfigError          ConfigError
    weights.position               used by fd_lcc           ConfigError          ConfigError

``constraints.spacing = "equilibrium"`` replaces the absolute safe spacing of each CAV
(``s >= s_min + t_gap v``) by the DeeP-LCC paper's target, ``spacing_error = [-15, 20]`` m on
``s - s*(v_eq)`` (the spacing error from the equilibrium spacing of the estimated velocity, which
the state already measures; on the ring from the reference spacing that sums to the
circumference). On ``problems/platoon_deeplcc_brake.toml`` it raises the fuel saved against
all-HDV from 20.53 % to 21.70 % (MPC) and from 22.48 % to 25.68 % (DeeP-LCC, same option),
the paper reporting about 25 %: its bound is never active there, the safe one is.

A refusal is one :class:`~lcc_synth.errors.ConfigError` whose field is the key
(``controllers.NAME.n_model``) and whose message names the layout ("... for a platoon or
ring"). Why the three keys stay single-CAV: the joint MPC models every vehicle of
the platoon (``n_model`` has nothing to cut) and constrains every CAV's own spacing ahead
(``behind`` names HDVs of the paper's one-CAV index); ``weights.position`` weighs FD-LCC's
``-p_0``, a state the platoon model has not. The actuator lag and HDV delays in one
prediction are not written for any layout (the lag state and the delay register would have
to share the augmented state).
"""

from lcc_synth.resources import lazy_exports

__all__ = [
    "MPCController",
    "MPCSettings",
    "JointMPCController",
    "build_mpc",
    "STATUS_CODES",
    "mpc_controller_from_table",
    "paper_fallback_gains",
    "settings_from_table",
]

# Each name's submodule, imported on first use (lcc_synth.resources.lazy_exports): reading
# an MPC table (.settings) loads neither the QP nor SciPy. JointMPCController is
# MPCController (the joint MPC of a platoon or ring is the one MPC).
__getattr__, __dir__ = lazy_exports(__name__, {
    "MPCController": "controller", "STATUS_CODES": "controller",
    "JointMPCController": "controller", "MPCSettings": "settings",
    "paper_fallback_gains": "settings", "settings_from_table": "settings",
    "build_mpc": "build", "mpc_controller_from_table": "build",
})  # fmt: skip
