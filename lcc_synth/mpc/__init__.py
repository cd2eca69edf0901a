"""Safety-constrained model predictive control of the CAV in LCC (CasADi formulation, OSQP).

- :mod:`lcc_synth.mpc.settings`: settings and their problem-file table.
- :mod:`lcc_synth.mpc.formulation`: the condensed QP built once with CasADi.
- :mod:`lcc_synth.mpc.solver`: OSQP workspace (set up once), exact reference, naive rebuild.
- :mod:`lcc_synth.mpc.scaffold`: what every layout's MPC shares (sample loop, equilibrium,
  head prediction, linearisation cache, warm-started solve, statistics, status codes).
- :mod:`lcc_synth.mpc.controller`: the controller of the common interface, fallback chain.
- :mod:`lcc_synth.mpc.qp_joint`, :mod:`lcc_synth.mpc.joint`: the joint MPC of every CAV of
  a platoon or ring road (``[system] kind = "platoon" | "ring"``).
- :mod:`lcc_synth.mpc.build`: the controller of a ``[controllers.NAME]`` table.
- :mod:`lcc_synth.mpc.report`: its step record and statistics, the safety summary of runs.
"""

from lcc_synth.mpc.build import build_mpc, mpc_controller_from_table
from lcc_synth.mpc.controller import STATUS_CODES, MPCController
from lcc_synth.mpc.joint import JointMPCController
from lcc_synth.mpc.settings import MPCSettings, paper_fallback_gains, settings_from_table

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
