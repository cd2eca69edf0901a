"""CAV controllers: the interface the simulator calls (:mod:`.base`), the HDV-law and
static-gain controllers (:mod:`.static`), the field's baselines and ``build_controller`` from
their problem tables (:mod:`.registry`); the MPC is :mod:`lcc_synth.mpc`, DeeP-LCC
:mod:`lcc_synth.deeplcc`, and the controller of a table of any type
:func:`lcc_synth.experiments.controller_tables.controller_from_table`."""
