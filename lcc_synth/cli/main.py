"""Entry point of ``lcc-synth``.

Each command lives in its own module ``lcc_synth.cli.<command>`` exposing
``HELP: str``, ``add_arguments(parser)`` and ``run(args) -> int``. Modules import their heavy
dependencies inside ``run`` so that ``lcc-synth --help`` stays fast.

Exit codes: 0 success; 1 a run that found a failure (a solver failure, a controller that
could not be designed, a file that could not be written after the work: every result that
succeeded is still written and printed); 2 bad input (problem file, option, an output path
that cannot be written, a run too large for the disk, memory or the recording limit) with a
one-line message naming the file and the field, before any work; 130 / 143 stopped by SIGINT /
SIGTERM (:mod:`lcc_synth.interrupts`: the recording is finalised as "interrupted", finished
work is kept). A bad option of a command prints that command's usage, not the top-level one.

Every command has ``--quiet`` (``-q``; ``--no-progress`` is the same flag,
:func:`lcc_synth.cli.arguments.add_quiet`): no progress bar, stage line or estimate on stderr
for that run (:func:`lcc_synth.resources.set_quiet`); results and errors stay.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from lcc_synth.cli.arguments import add_quiet, check_options
from lcc_synth.errors import ConfigError, FileError, Interrupted
from lcc_synth.interrupts import interruption_behind

COMMANDS = ("run", "analyze", "regions", "simulate", "synthesize", "sweep", "review", "calibrate")


def _available() -> dict[str, object]:
    mods = {}
    for name in COMMANDS:
        try:
            mods[name] = importlib.import_module(f"lcc_synth.cli.{name}")
        except ModuleNotFoundError as err:
            if err.name != f"lcc_synth.cli.{name}":
                raise
    return mods


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # argparse already exits 2; keep its one-line style
        self.print_usage(sys.stderr)
        self.exit(2, f"{self.prog}: error: {message}\n")


class _CommandParser(_Parser):
    """A command's parser: an option it does not know is its error (with its usage), not one
    of the top-level parser (which would print the top-level usage)."""

    def parse_known_args(self, args=None, namespace=None):
        namespace, extra = super().parse_known_args(args, namespace)
        if extra:
            self.error(f"unrecognized arguments: {' '.join(extra)}")
        return namespace, extra


def build_parser() -> argparse.ArgumentParser:
    """The ``lcc-synth`` argument parser: one subcommand per module of ``COMMANDS``."""
    from lcc_synth import __version__

    parser = _Parser(prog="lcc-synth", description="Design and test LCC controllers for a CAV.")
    parser.add_argument("--version", action="version", version=f"lcc-synth {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_CommandParser)
    for name, mod in _available().items():
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        add_quiet(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from lcc_synth.resources import set_quiet

    set_quiet(args.quiet)  # process-wide for the command's run, cleared after it
    try:
        check_options(args)
        return int(args._run(args) or 0)
    except ConfigError as err:
        problem = getattr(args, "problem", None)
        if err.source is None and problem and not err.field.startswith("-"):
            err = err.with_source(problem)  # a field of the problem file: name the file
        print(f"lcc-synth {args.command}: error: {err}", file=sys.stderr)
        return 2
    except FileError as err:
        print(f"lcc-synth {args.command}: error: {err}", file=sys.stderr)
        return 1
    except Interrupted as err:
        print(f"lcc-synth {args.command}: interrupted by {err.signame}", file=sys.stderr)
        return 128 + err.signum
    except KeyboardInterrupt:
        print(f"lcc-synth {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # a signal's exception wrapped by native code: still a stop
        stop = interruption_behind(err)
        if stop is None:
            raise
        print(f"lcc-synth {args.command}: interrupted by {stop.signame}", file=sys.stderr)
        return 128 + stop.signum
    finally:
        set_quiet(False)


def entry() -> None:
    """The ``lcc-synth`` console script: :func:`main` with SIGINT and SIGTERM handled
    (:func:`lcc_synth.interrupts.handling`) and Rerun's own log lines off (every recording
    error is reported by the package as one line; a ``RUST_LOG`` you set is kept). Output
    piped into a reader that stops early (``lcc-synth review X.rrd --summary | head``) ends
    quietly with the shell's code for SIGPIPE, 141.

    After a signal the process exits at once when :func:`main` returns (``os._exit``):
    threads still inside native code (a simulation kernel on the thread pool) would otherwise
    hold the interpreter's exit until they finish.
    """
    from lcc_synth.interrupts import handling, interrupted

    os.environ.setdefault("RUST_LOG", "off")
    try:
        with handling():
            code = main()
    except Interrupted as err:  # a signal between main's return and the end of the block
        code = 128 + err.signum
    except BrokenPipeError:  # the reader of stdout went away (``| head``): as a shell tool
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no flush error
        sys.exit(141)  # 128 + SIGPIPE, what the shell reports for a command killed by it
    signum = interrupted()
    if signum is not None:  # the command's own code: 128 + signum, or 0 when a signal is its
        sys.stdout.flush()  # normal end (Ctrl-C closes the viewer of ``review``)
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":  # pragma: no cover
    entry()
