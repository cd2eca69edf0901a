"""H2 structured and sparse gain synthesis for LCC, one CAV or several (platoons, rings).

Modules, each for every layout: :mod:`.h2` (design plant, true H2 norm, Riccati, full-state
LMI; a gain row per CAV, the ring on its invariant hyperplane), :mod:`.structured`
(sparsity-invariance convex restriction + polishing on the true H2 cost; per-CAV row patterns,
robust multi-model descent), :mod:`.sparsity` (group-sparsity ADMM Pareto sweep; per-CAV range
front), :mod:`.string_lmi` (bounded-real lemma, string-stable designs, one CAV),
:mod:`.as_run` (the loop as it runs, one CAV), :mod:`.as_run_dynamics` (the gain with the
estimator, filter and sample time as design variables, on the loop as it runs),
:mod:`.robust_string` (the robust multi-model design of one CAV, on its one-CAV platoon),
:mod:`.config` (``[synthesis]`` problem table, both vocabularies), :mod:`.design`
(:func:`~.design.synthesize`, the one entry point),
:mod:`.report` (checks and report), :mod:`.gains_file` (the gains JSON file).

cvxpy is imported only inside the functions that solve LMIs.
"""

from lcc_synth.synthesis.h2 import SynthesisError, Weights, h2_norm, make_plant, riccati_gain

__all__ = ["SynthesisError", "Weights", "h2_norm", "make_plant", "riccati_gain"]
