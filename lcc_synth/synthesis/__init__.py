"""H2 structured and sparse gain synthesis for LCC.

Modules: :mod:`.h2` (design plant, true H2 norm, Riccati, full-state LMI), :mod:`.structured`
(sparsity-invariance convex restriction + polishing on the true H2 cost), :mod:`.sparsity`
(group-sparsity ADMM Pareto sweep), :mod:`.string_lmi` (bounded-real lemma, string-stable
designs), :mod:`.config` (``[synthesis]`` problem table), :mod:`.design` (run a problem),
:mod:`.report` (checks and report), :mod:`.gains_file` (the gains JSON file).

cvxpy is imported only inside the functions that solve LMIs.
"""

from lcc_synth.synthesis.h2 import SynthesisError, Weights, h2_norm, make_plant, riccati_gain

__all__ = ["SynthesisError", "Weights", "h2_norm", "make_plant", "riccati_gain"]
