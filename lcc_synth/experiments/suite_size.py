"""The size of ``lcc-synth run``'s recording, before the work: the suite's scenarios with the
controllers that run in each (:func:`~lcc_synth.experiments.suite_tables.applies`) handed to
:func:`lcc_synth.recording.size.estimate_suite_recording`, and the check ``run`` calls
(:func:`check_suite_recording`: ``--max-recording-size``, the free space)."""

from __future__ import annotations

from typing import Any

from lcc_synth.experiments.comparison import Suite, applies, controller_table

__all__ = ["check_suite_recording", "suite_recording_estimate"]


def suite_recording_estimate(suite: Suite, decimate: int | str = "minmax") -> Any:
    """The estimated size of ``lcc-synth run``'s recording of ``suite``
    (:func:`lcc_synth.recording.size.estimate_suite_recording`): every scenario with the
    controllers that run in it (:func:`~lcc_synth.experiments.suite_tables.applies`, their tables
    for its layout), the |Gamma| curves and gains of every layout; ``decimate`` as
    ``--record-every``. Returns a :class:`~lcc_synth.recording.size.RecordingEstimate`."""
    from lcc_synth.recording.size import estimate_suite_recording

    entries = [
        (ss.scenario, [controller_table(t, ss.layout) for t in suite.controllers.values()
                       if applies(t, ss.layout, sname)])
        for sname, ss in suite.scenarios.items()
    ]  # fmt: skip
    documents = len(suite.layouts) * (len(suite.controllers) + 1)
    return estimate_suite_recording(entries, len(suite.controllers), documents, decimate)


def check_suite_recording(args: Any, suite: Suite) -> Any:
    """What ``lcc-synth run`` calls before the work: :func:`suite_recording_estimate` checked
    against ``--max-recording-size`` and the free space
    (:func:`lcc_synth.recording.cli.check_recording`: a one-line
    :class:`~lcc_synth.errors.ConfigError` naming ``--scenarios`` and what to change, or
    ``--rrd``); returns the estimate (``None`` with ``--no-record``)."""
    if getattr(args, "no_record", False):
        return None
    from lcc_synth.recording.cli import check_recording, recording_decimation

    every = recording_decimation(args)
    estimate = suite_recording_estimate(suite, every)
    check_recording(
        args, estimate, "--scenarios", "run fewer scenarios (--scenarios a,b) or controllers "
        "(--controllers a,b), " + ("--record-every minmax, " if every != "minmax" else "")
        + "--no-record",
    )  # fmt: skip
    return estimate
