"""CAV controllers: the interface the simulator calls (:mod:`.base`), the HDV-law and
static-gain controllers (:mod:`.static`) and ``build_controller`` from problem tables
(:mod:`.registry`); the MPC is :mod:`lcc_synth.mpc`."""
