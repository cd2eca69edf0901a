"""The command-line arguments that several ``lcc-synth`` commands (and the scripts under
``examples/``) share, set up one way."""

from __future__ import annotations

import argparse


def add_problem_arguments(
    parser: argparse.ArgumentParser,
    problem_help: str,
    json_help: str = "print one JSON object on stdout",
    optional: bool = False,
) -> None:
    """The problem file (positional, ``None`` when ``optional`` and not given) and ``--json``."""
    if optional:
        parser.add_argument("problem", nargs="?", default=None, help=problem_help)
    else:
        parser.add_argument("problem", help=problem_help)
    parser.add_argument("--json", action="store_true", help=json_help)


def add_recording(parser: argparse.ArgumentParser, steps: bool = True) -> None:
    """``--rrd``, ``--no-record``, ``--overwrite`` and, for the commands that record simulation
    ``steps``, ``--record-every`` (imported only when a command is set up, so that
    ``lcc-synth --help`` stays fast)."""
    from lcc_synth.recording import add_recording_arguments

    add_recording_arguments(parser, steps=steps)
    parser.add_argument(
        "--overwrite", action="store_true",
        help="replace files named by --rrd, --out FILE, --png or --figure if they exist "
        "(default: such a file is refused before any work; default names never collide)",
    )  # fmt: skip


def check_options(args: argparse.Namespace) -> None:
    """Reject options that do not apply together (before any work is done).

    Raises
    ------
    ConfigError
        ``--format`` not one of :data:`FIGURE_FORMATS`; ``--record-every``,
        ``--record-seeds`` or ``--max-recording-size`` with ``--no-record`` (nothing is
        recorded).
    """
    from lcc_synth.errors import ConfigError

    fmt = getattr(args, "format", None)
    if fmt is not None and fmt not in FIGURE_FORMATS:
        raise ConfigError(
            "--format", f"must be one of {', '.join(FIGURE_FORMATS)}, got {fmt!r}"
        )
    if getattr(args, "no_record", False):
        if getattr(args, "record_every", None) is not None:
            raise ConfigError("--record-every", "does not apply with --no-record")
        if getattr(args, "max_recording_size", None) is not None:
            raise ConfigError("--max-recording-size", "does not apply with --no-record")
        if getattr(args, "record_seeds", None) is not None:
            raise ConfigError("--record-seeds", "does not apply with --no-record")


def add_output_arguments(parser: argparse.ArgumentParser, what: str, figures: str) -> None:
    """``--controllers``, ``--out DIR``, ``--no-figures`` and ``--format`` of the commands that
    run many simulations (``what`` writes ``DIR/<problem>-<UTC timestamp>/``)."""
    parser.add_argument(
        "--controllers", metavar="A,B", help="comma-separated controller names (default all)"
    )
    parser.add_argument(
        "--out", metavar="DIR", default="results",
        help=f"results root; {what} writes DIR/<problem>-<UTC timestamp>/ (default results)",
    )  # fmt: skip
    parser.add_argument("--no-figures", action="store_true", help=f"do not write {figures}")
    parser.add_argument(
        "--format", default="png", metavar="FMT",
        help=f"file type of the figures: {', '.join(FIGURE_FORMATS)} (default png)",
    )  # fmt: skip


#: File types the figures can be written as (``--format``).
FIGURE_FORMATS = ("png", "pdf", "svg")


def add_quiet(parser: argparse.ArgumentParser) -> None:
    """``--quiet`` (``-q``; ``--no-progress`` is the same flag) of every command: no progress
    bar, progress line or estimate on stderr (:func:`lcc_synth.resources.set_quiet`); the
    results on stdout and the errors stay."""
    parser.add_argument(
        "-q", "--quiet", "--no-progress", dest="quiet", action="store_true",
        help="no progress bars, stage lines or estimates on stderr (results and errors stay)",
    )  # fmt: skip


def add_example_out(parser: argparse.ArgumentParser) -> None:
    """``--out DIR`` of the scripts under ``examples/``: every file a script writes goes under
    ``DIR`` (default ``results``), and the script prints ``wrote PATH`` for each."""
    parser.add_argument(
        "--out", metavar="DIR", default="results",
        help="directory the outputs are written under (default results)",
    )  # fmt: skip


def add_export_arguments(parser: argparse.ArgumentParser) -> None:
    """``--export DIR`` and ``--export-format`` of the commands that simulate
    (:mod:`lcc_synth.simulation.export`: every run's trajectories, one file per scenario and
    controller)."""
    parser.add_argument(
        "--export", metavar="DIR", default=None,
        help="write every run's trajectories (time, position, velocity, acceleration, spacing "
        "of every vehicle, the CAV commands) to DIR, one file per scenario and controller",
    )  # fmt: skip
    parser.add_argument(
        "--export-format", choices=("csv", "parquet"), default="csv",
        help="file format of --export (default csv, exact floats; parquet needs pyarrow)",
    )  # fmt: skip


def check_export(args: argparse.Namespace, size: float, runs: int) -> None:
    """Before any simulation: ``--export DIR`` can take ``runs`` files of ``size`` bytes in
    all (writable, with room: :func:`lcc_synth.simulation.export.export_bytes` estimates it)
    and ``--export-format parquet`` has pyarrow. Without ``--export``, only that
    ``--export-format`` was not given alone.

    Raises
    ------
    ConfigError
        Naming ``--export`` (the directory) or ``--export-format``.
    """
    from lcc_synth.errors import ConfigError
    from lcc_synth.outputs import check_directory
    from lcc_synth.simulation.export import check_format

    if getattr(args, "export", None) is None:
        if getattr(args, "export_format", "csv") != "csv":
            raise ConfigError("--export-format", "applies with --export DIR only")
        return
    check_format(args.export_format)
    check_directory(args.export, "--export", size, f"trajectories of {runs} run(s)")
