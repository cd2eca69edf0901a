"""Experiments over many runs: the ``lcc-synth run`` comparison suite and its tables
(:mod:`.comparison`) and Dask robustness sweeps (:mod:`.sweep`)."""
