"""Calibration of car-following models on recorded platoons (NGSIM-style trajectory files):
replays of recorded leaders (:mod:`lcc_synth.calibration.replay`), bounded least-squares fits
with identifiability (:mod:`lcc_synth.calibration.fit`), the report and the problem file of a
calibrated platoon (:mod:`lcc_synth.calibration.report`). Guide: docs/guide/calibration.md."""
