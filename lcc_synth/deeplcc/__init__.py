"""DeeP-LCC: data-enabled predictive leading cruise control (Wang, Zheng, Li, Chen et al.,
IEEE T-CST 2023) on Willems' fundamental lemma.

- :mod:`lcc_synth.deeplcc.data`: collection in the nonlinear simulator, persistency of
  excitation, the ``.npz`` cache.
- :mod:`lcc_synth.deeplcc.hankel`: Hankel matrices, the predictor, the exact reduction of the
  QP in ``g``.
- :mod:`lcc_synth.deeplcc.qp`: the online QP formulated once (CasADi).
- :mod:`lcc_synth.deeplcc.settings`: settings and their problem-file table.
- :mod:`lcc_synth.deeplcc.controller`: the controller, its fallback chain.
- :mod:`lcc_synth.deeplcc.build`: the controller of a ``[controllers.NAME]`` table.
"""

from lcc_synth.deeplcc.build import build_deep_lcc, deep_lcc_controller_from_table
from lcc_synth.deeplcc.controller import DeePLCCController

__all__ = ["DeePLCCController", "build_deep_lcc", "deep_lcc_controller_from_table"]
