"""Calibration of car-following models on recorded platoons (NGSIM-style trajectory files,
read by :mod:`lcc_synth.schema.trajectories`): replays of recorded leaders
(:mod:`lcc_synth.calibration.replay`), bounded least-squares fits with identifiability
(:mod:`lcc_synth.calibration.fit`), the text report (:mod:`lcc_synth.calibration.report`) and
the problem file of a calibrated platoon (:mod:`lcc_synth.calibration.problem`). Guide:
docs/guide/calibration.md; command: ``lcc-synth calibrate``."""
