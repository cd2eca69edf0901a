"""Rerun recordings (``.rrd``) of simulation, analysis and synthesis runs.

Submodules: :mod:`~lcc_synth.recording.core` (opening a recording, names, colours),
:mod:`~lcc_synth.recording.layout` (blueprints), :mod:`~lcc_synth.recording.simulation`,
:mod:`~lcc_synth.recording.analysis` (what gets recorded), :mod:`~lcc_synth.recording.cli`
(command flags and the recorder), :mod:`~lcc_synth.recording.reader` (reading back, viewer),
:mod:`~lcc_synth.recording.summary` (the text of ``review --summary``),
:mod:`~lcc_synth.recording.decimate` (min/max-preserving decimation, ``decimate="minmax"``,
every command's default), :mod:`~lcc_synth.recording.size` (a recording's size estimated before
the work, ``--max-recording-size``). Everything public is importable from
``lcc_synth.recording`` (each name's submodule is imported on first use).

Every recording command writes one file, by default ``logs/<problem>-<UTC timestamp>.rrd``
(see :func:`recording_path`), with a default blueprint so that opening it in the Rerun viewer
(``lcc-synth review PATH.rrd``) immediately shows what matters.

Every 2-D entity (road views, MPC plans, |Gamma| curves, Pareto fronts) stores its y
multiplied by ``SCREEN_UP`` = -1: Rerun's 2-D views draw y downward (rerun-io/rerun#1387), and
up must mean more (faster, larger) as in a figure of a paper.

Entity layout (stable: tests and users rely on these names)
-----------------------------------------------------------
Timeline ``time``: simulated time in seconds (a Rerun *duration* timeline, stored in ns).
``<scenario>`` is the problem name and ``<controller>`` the controller name, both reduced to the
characters ``[A-Za-z0-9_.-]`` (others become ``_``).

Simulation (:func:`record_simulation`), under ``/<scenario>/<controller>/``:

=====================  =========================================================================
``velocity``           ``Scalars``, one series per vehicle (head, HDVs ahead, CAV, HDVs behind)
``spacing``            ``Scalars``, one series per vehicle except the head vehicle
``acceleration``       ``Scalars``, one series per vehicle (applied acceleration)
``cav/u_cmd``          ``Scalars``, the CAV command before limits and emergency braking
``cav/aeb_active``     ``Scalars``, 1 while the CAV's emergency braking is active, else 0
                       (drawn as steps; every controller's series named ``AEB_SERIES``)
``road``               ``Points2D``, every vehicle over time: x = position relative to the CAV
                       (m), y = ``ROAD_Y_SCALE`` x velocity error (m/s), as in the paper's Fig. 11;
                       CAV blue, HDVs grey, head vehicle yellow; labels = vehicle names
``road/equilibrium``   ``LineStrips2D`` (static), the zero-velocity-error line
``events``             ``TextLog`` on the timeline: CAV emergency braking on/off, collisions
``metrics``            ``TextDocument`` (markdown), the run's metrics table
``controller``         ``TextDocument`` (markdown), ``describe()`` and ``stats()`` of the controller
``mpc/solve_time_ms``  ``Scalars`` (MPC only): whole controller step and QP solver (OSQP or
                       DAQP) time per step (ms)
``mpc/status``         ``Scalars`` (MPC only): status code (0 QP, 1 shifted plan, 2 static gain,
                       3 hold) and 1 when a fallback was used
``mpc/predicted/*``    ``LineStrips2D`` (MPC only): ``u``, ``velocity``, ``spacing`` plans at
                       recorded controller steps (x = seconds ahead, y = value; ``minmax``:
                       one every 0.5 s when it changed)
=====================  =========================================================================

``/<scenario>/recorded/`` (a scenario that replays a recording, ``simulate``:
:func:`record_recorded`): ``velocity`` (``Scalars``, the recorded leader and, with ``[scenario]
initial = "data"``, every recorded follower, named ``recorded <vehicle>`` and coloured as the
simulated vehicle of that column), ``spacing`` (the followers' ``headway - vehicle_length``)
and ``source`` (markdown: the file), every recorded sample on the simulated time; the default
layout shows them after the controllers' velocity and spacing views.

``/<scenario>/metrics`` (markdown) compares every controller recorded so far,
``/<scenario>/context`` (markdown, ``simulate`` and every scenario of ``run``:
:mod:`lcc_synth.recording.context`) says what was run,
``/<scenario>/status`` says whether the run completed, was interrupted (and by what), failed,
or is partial (some controllers failed), and ``/provenance`` (markdown) holds the run's
provenance (:mod:`lcc_synth.provenance`: package version, problem file and SHA-256, backend,
seeds, solvers).

Vehicle names in series and labels: ``head``, ``hdv-2``, ``hdv-1`` (ahead of the CAV), ``cav``,
``hdv1``, ``hdv2``... (behind), i.e. the paper's vehicle index; series colors as above.

Analysis (:func:`record_gamma`, :func:`record_region_map`) under ``/analysis/``:
``gamma/<case>`` (``LineStrips2D``: x = log10 omega, y = |Gamma(j omega)|, with ``gamma/unit``
the line |Gamma| = 1) and ``gamma/<case>/report`` (markdown); ``regions/<name>`` (a
``SegmentationImage`` of classes 0 = plant unstable, 1 = stable, 2 = string stable, with an
annotation context naming them) and ``regions/<name>/report`` (markdown: axes and fractions).
``/analysis/report`` holds the analysis command's whole report (:func:`record_analysis_file`).
Synthesis (:func:`record_synthesis`, :func:`record_gains`) under ``/synthesis/<name>/``:
``gains`` (``BarChart`` of the gain on every state), ``report`` (markdown: state names, gains,
true H2, LMI bound, verdicts, solver), ``pareto/front`` and ``pareto/patterns`` (sparsity
designs: x = vehicles heard, y = true H2); the |Gamma| curve of the gain as above. A platoon or
ring design (the same :func:`record_synthesis`; ``lcc-synth run`` records its designs with
it too, as ``<layout>.<controller>``) records each CAV's gain under
``/synthesis/<name>/<u_col>/`` (``gains``, ``report``), the whole report at
``/synthesis/<name>/report`` and its range front's H2 losses at ``pareto/loss_percent``.

Sweeps (:func:`record_sweep`, ``lcc-synth sweep``) under ``/sweep/<name>/``: one scatter
series per controller and metric over the ``scenario`` timeline, and the summary ``report``.

Interrupted runs: :func:`open_recording` is a context manager that writes a private temporary
file, flushes and finalises it on every exit (exception, ``KeyboardInterrupt``, SIGTERM) and
publishes it under its name atomically (a reader never sees a half file; :func:`written_path`
is the name used), recording the interruption in ``/<scenario>/status``; the commands record
each controller as soon as its result exists (:class:`SimulationRecorder`), so the file holds
everything finished before the interruption. A disk that fills is one error line naming the
file, never a hang.

Rerun's usage analytics live in its viewer/CLI binary, not in the logging SDK (writing a file
sends nothing). Rerun 0.41 documents only ``rerun analytics disable`` (a per-user setting); its
analytics pipeline also switches itself off whenever the ``CI`` environment variable is set, so
every Rerun process started here gets ``CI=1`` in its own environment
(:func:`viewer_environment`), leaving the user's settings and our own process untouched.
"""

from __future__ import annotations

from lcc_synth.resources import lazy_exports

#: The submodule that defines each public name: imported on first use
#: (:func:`~lcc_synth.resources.lazy_exports`), so that importing the package, or one name of
#: it, does not import every submodule (a refused input ends before the recording stack loads).
_SOURCE = {
    "gamma_grid": "analysis",
    "record_analysis_file": "analysis",
    "record_gains": "analysis",
    "record_gamma": "analysis",
    "record_region_map": "analysis",
    "record_synthesis": "analysis",
    "record_synthesis_file": "analysis",
    "synthesis_cavs": "analysis",
    "SimulationRecorder": "cli",
    "add_recording_arguments": "cli",
    "check_recording": "cli",
    "check_recording_limit": "cli",
    "check_recording_space": "cli",
    "parse_record_seeds": "cli",
    "record_seed_count": "cli",
    "recording_decimation": "cli",
    "recording_limit": "cli",
    "recording_path": "cli",
    "APP_ID": "core",
    "COLOR_CAV": "core",
    "COLOR_HDV": "core",
    "COLOR_HEAD": "core",
    "ROAD_Y_SCALE": "core",
    "entity_name": "core",
    "open_recording": "core",
    "record_provenance": "core",
    "record_text": "core",
    "set_status": "core",
    "vehicle_colors": "core",
    "vehicle_names": "core",
    "written_path": "core",
    "analysis_blueprint": "layout",
    "simulation_blueprint": "layout",
    "sweep_blueprint": "layout",
    "synthesis_blueprint": "layout",
    "EntitySummary": "reader",
    "RecordingSummary": "reader",
    "rerun_binary": "reader",
    "summarize_recording": "reader",
    "viewer_environment": "reader",
    "RECORDED_ENTITY": "simulation",
    "RecordedTrajectories": "simulation",
    "record_metrics": "simulation",
    "record_mpc_history": "simulation",
    "record_recorded": "simulation",
    "record_simulation": "simulation",
    "recorded_trajectories": "simulation",
    "RecordingEstimate": "size",
    "estimate_recording_bytes": "size",
    "estimate_simulation_recording": "size",
    "estimate_suite_recording": "size",
    "format_size": "size",
    "parse_size": "size",
    "record_sweep": "sweep",
    "record_sweep_file": "sweep",
}

__all__ = [
    "APP_ID",
    "ROAD_Y_SCALE",
    "COLOR_CAV",
    "COLOR_HDV",
    "COLOR_HEAD",
    "add_recording_arguments",
    "recording_path",
    "recording_decimation",
    "recording_limit",
    "record_seed_count",
    "parse_record_seeds",
    "check_recording",
    "check_recording_limit",
    "check_recording_space",
    "RecordingEstimate",
    "estimate_recording_bytes",
    "estimate_simulation_recording",
    "estimate_suite_recording",
    "format_size",
    "parse_size",
    "entity_name",
    "vehicle_names",
    "vehicle_colors",
    "simulation_blueprint",
    "analysis_blueprint",
    "synthesis_blueprint",
    "sweep_blueprint",
    "record_sweep",
    "record_sweep_file",
    "open_recording",
    "record_provenance",
    "set_status",
    "written_path",
    "record_simulation",
    "RECORDED_ENTITY",
    "RecordedTrajectories",
    "recorded_trajectories",
    "record_recorded",
    "record_metrics",
    "SimulationRecorder",
    "record_mpc_history",
    "record_gamma",
    "record_region_map",
    "record_gains",
    "record_synthesis",
    "record_analysis_file",
    "record_synthesis_file",
    "synthesis_cavs",
    "gamma_grid",
    "record_text",
    "viewer_environment",
    "rerun_binary",
    "RecordingSummary",
    "EntitySummary",
    "summarize_recording",
]


__getattr__, __dir__ = lazy_exports(__name__, _SOURCE)
