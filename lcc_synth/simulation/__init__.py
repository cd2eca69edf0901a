"""The nonlinear simulator: ``simulate`` (:mod:`.engine`), its compiled loops (:mod:`.kernels`),
perturbations (:mod:`.perturbations`), the scenario and its problem-file table
(:mod:`.scenario`) and the recorded result (:mod:`.results`); co-simulation in SUMO
(:mod:`.sumo`, :mod:`.sumo_net`) and the dispatch between the two (:mod:`.backends`)."""
