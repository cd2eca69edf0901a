"""``lcc-synth calibrate DATA.csv [--model ovm|idm] [--json] [--out FILE.toml] [--length L]
[--starts N] [--seed S]``."""

from __future__ import annotations

import argparse
import time

HELP = "calibrate OVM / IDM drivers on a recorded platoon (an NGSIM-style trajectory CSV)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "data", metavar="DATA.csv",
        help="trajectory file: t, v0, headway0, v1, headway1, ... (headway front to front; "
        "layout in problems/data/ngsim_i80/README.md)",
    )  # fmt: skip
    parser.add_argument("--model", choices=("ovm", "idm"), default="ovm",
                        help="car-following model to fit (default ovm)")  # fmt: skip
    parser.add_argument(
        "--json", action="store_true",
        help="print one JSON object (shape in docs/guide/calibration.md)",
    )  # fmt: skip
    parser.add_argument(
        "--out", metavar="FILE.toml",
        help="write a problem file of this platoon: every HDV with its calibrated values, the "
        "head replaying the recorded leader, initial states from the data",
    )  # fmt: skip
    parser.add_argument(
        "--length", type=float, default=5.0, metavar="L",
        help="vehicle length (m): gap = headway - L (fixed, not fitted; default 5)",
    )  # fmt: skip
    parser.add_argument("--starts", type=int, default=5, metavar="N",
                        help="optimiser starts per fit, 1..100 (default 5)")  # fmt: skip
    parser.add_argument("--seed", type=int, default=0, metavar="S",
                        help="seed of the random starts (default 0)")  # fmt: skip
    parser.add_argument(
        "--substeps", type=int, default=1, metavar="K",
        help="integration steps per sample of the replays, 1..20 (default 1: the recorded "
        "rate; more removes the integration's bias at K times the cost)",
    )  # fmt: skip
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the --out file if it exists")  # fmt: skip


def run(args: argparse.Namespace) -> int:
    from lcc_synth.calibration.fit import calibrate
    from lcc_synth.calibration.report import format_report
    from lcc_synth.cli.output import write_and_report
    from lcc_synth.outputs import check_file
    from lcc_synth.resources import notice
    from lcc_synth.schema.trajectories import read_trajectory

    traj = read_trajectory(args.data, "DATA")
    if args.out:
        check_file(args.out, "--out", overwrite=args.overwrite)
    started = time.monotonic()

    def progress(message: str) -> None:  # only once the work has taken more than 2 s
        if not args.quiet and time.monotonic() - started > 2.0:
            notice("calibrate", f"{message} ({time.monotonic() - started:.0f} s)")

    cal = calibrate(traj, args.model, args.length, args.starts, args.seed, args.substeps,
                    progress)  # fmt: skip

    def write(written: list[str]) -> None:
        if args.out:
            from lcc_synth.calibration.problem import write_problem

            written.append(str(write_problem(args.out, cal, traj, args.overwrite)))

    return write_and_report(
        "calibrate", args.json, write,
        lambda written, ok: {"ok": ok, **cal.as_dict(), "written": written},
        lambda: print(format_report(cal)),
    )  # fmt: skip
