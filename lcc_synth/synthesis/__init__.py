"""H2 structured and sparse gain synthesis for LCC, one CAV or several (platoons, rings).

Modules, each for every layout: :mod:`.h2` (design plant, true H2 norm, Riccati; a gain row
per CAV, the ring on its invariant hyperplane), :mod:`.lmi` (the full-state LMI and the
sparsity-invariance convex restriction, a row pattern per CAV), :mod:`.structured` (the start
and the polishing on the true H2 cost; robust multi-model descent), :mod:`.sparsity`
(group-sparsity ADMM Pareto sweep; per-CAV range front), :mod:`.string_lmi` (bounded-real
lemma, string-stable designs of every layout with a head vehicle), :mod:`.lag_design` (the
CAVs' actuator lag in the plant), :mod:`.robust_string` (the robust multi-model design of one
CAV, on its one-CAV platoon), :mod:`.as_run` (the loop as it runs, one CAV or an open platoon),
:mod:`.as_run_dynamics` (the gain with the estimator, filter and sample time as design
variables, on the loop as it runs), :mod:`.config` (``[synthesis]`` problem table, both
vocabularies), :mod:`.design` (:func:`~.design.synthesize`, the one entry point),
:mod:`.report` (checks and report), :mod:`.gains_file` (the gains JSON file),
:mod:`.lyapunov` (the Lyapunov solves they share).

cvxpy is imported only inside the functions that solve LMIs; the package itself imports no
submodule (its names are :mod:`.h2`'s, loaded on first use).

Feature matrix of ``[synthesis]`` (``tests/test_synthesis_layouts.py`` reads this table and
checks every cell: "yes" parses into a spec, "no: KEY" is one ConfigError naming
``synthesis.KEY``; the designs themselves run on each layout in ``test_synthesis_layouts``,
``test_synthesis_lmi_layouts``, ``test_synthesis_string_platoon``, ``test_robust_one_cav``,
``test_synthesis_platoon``, ``test_lag_platoon``, ``test_actuator_lag``,
``test_baseline_platoon`` and ``test_as_run_design_platoon``)::

    option                           one CAV            platoon            ring
    design = "full_state"            yes                yes                yes
    design = "structured"            yes                yes                yes
    design = "sparsity"              yes                yes                yes
    design = "string_stable"         yes                yes                no: design
    method = "lmi"                   yes                yes                yes
    cross_check = true               yes                yes                yes
    band                             yes                yes                yes
    [synthesis.robust]               yes                yes                yes
    robust, method = "lmi"           yes                yes                yes
    robust, sparsity                 no: design         yes                yes
    robust, string_stable            no: design         no: robust         no: design
    cav_lag                          yes                yes                yes
    cav_lag, full_state              yes                yes                yes
    cav_lag, sparsity                no: cav_lag        no: cav_lag        no: cav_lag
    cav_lag, method = "lmi"          no: method         no: method         no: method
    cav_lag, string_stable           yes                no: cav_lag        no: design
    cav_lag, robust                  yes                yes                yes
    [synthesis.as_run]               yes                yes                no: as_run
    [synthesis.baseline]             yes                yes                yes
    pattern = [...]                  yes                no: pattern        no: pattern
    comm_range                       no: comm_range     yes                yes

"One CAV" is ``kind = "lcc" | "cf_lcc" | "ccc"``; ``fd_lcc`` (no head vehicle) also refuses
``[synthesis.robust]`` and ``design = "string_stable"``, as a ring does. Why the "no" cells
stay: a ring has no head vehicle, so no head-to-tail transfer function to bound; the lag
states are in no pattern, so no LMI holds them and the string-stable polish of several CAVs is
of the lag-free loop; the robust descent does not keep string stability; one CAV's sparsity
design (the ADMM Pareto sweep) has no robust stage, a platoon's (the greedy range front, which
a one-CAV string would need its own vocabulary for) has. The as-run design
of an open platoon (``test_as_run_design_platoon``) has a fixed equilibrium and no trade-off
step: its ``equilibrium = "estimated"`` and ``weight > 0`` are ConfigErrors naming them.
"""

from lcc_synth.resources import lazy_exports

__all__ = ["SynthesisError", "Weights", "h2_norm", "make_plant", "riccati_gain"]

# Every public name is .h2's, imported on first use (lcc_synth.resources.lazy_exports):
# reading a gains file (.gains_file) or a [synthesis] table loads no solver.
__getattr__, __dir__ = lazy_exports(__name__, dict.fromkeys(__all__, "h2"))
