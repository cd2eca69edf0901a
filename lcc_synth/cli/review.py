"""``lcc-synth review PATH.rrd``: open a recording in the Rerun viewer, or summarise it.

* With a display (``DISPLAY`` / ``WAYLAND_DISPLAY`` on Linux, always on macOS and Windows) the
  native viewer opens the file; if it cannot start (e.g. no usable X server) review falls back
  to the web viewer.
* Without a display (or with ``--web``) the web viewer is served on 127.0.0.1 only (Rerun binds
  0.0.0.0 by default) and the address to open is printed.
* In both modes the viewer's gRPC server is bound to 127.0.0.1 too.
* ``--summary`` prints what the recording holds without a viewer, on one screen (at most 60
  lines: entity groups, time range, the comparison metrics, one line per report); ``--full``
  lists every entity and document; ``--json`` gives everything as one JSON object.

The viewer is the ``rerun`` executable of the ``rerun-sdk`` wheel, started directly (not via the
Python wrapper script, which would leave the real viewer running when stopped) in its own
process group, with Rerun's usage analytics off (:func:`lcc_synth.recording.viewer_environment`);
Ctrl-C, SIGTERM or SIGHUP stop it.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from lcc_synth.errors import ConfigError

HELP = "open a Rerun recording (.rrd) in the viewer, or print a summary of it"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "path", metavar="PATH.rrd", nargs="+",
        help="the recording to open; two recordings (A.rrd B.rrd) open side by side: every run "
        "they have in common, A left and B right",
    )  # fmt: skip
    parser.add_argument(
        "--summary", action="store_true", help="print what the recording holds; no viewer"
    )
    parser.add_argument(
        "--full", action="store_true",
        help="with --summary: every entity and every metrics, status and report document "
        "(default: one screen, at most 60 lines)",
    )  # fmt: skip
    parser.add_argument("--json", action="store_true", help="with --summary: one JSON object")
    parser.add_argument(
        "--web",
        action="store_true",
        help="serve the web viewer on 127.0.0.1 even when a display is available",
    )
    parser.add_argument(
        "--web-port", type=int, default=0, metavar="PORT",
        help="HTTP port of the web viewer (default: a free port)",
    )  # fmt: skip
    parser.add_argument(
        "--port", type=int, default=0, metavar="PORT",
        help="gRPC port the viewer streams the recording from (default: a free port)",
    )  # fmt: skip


def has_display(env: dict[str, str] | None = None, platform: str | None = None) -> bool:
    """Whether a native viewer window can open here."""
    env = os.environ if env is None else env
    platform = sys.platform if platform is None else platform
    if platform.startswith(("darwin", "win")):
        return True
    return bool(env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"))


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _check_port(value: int, field: str) -> int:
    if not 0 <= value <= 65535:
        raise ConfigError(field, f"must be a port in [1, 65535] (0 = pick a free one), got {value}")
    if value and _listening(value):
        raise ConfigError(field, f"port {value} on 127.0.0.1 is in use; choose another (0 = free)")
    return value or _free_port()


def _listening(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


def web_url(web_port: int, grpc_port: int) -> str:
    """Address of the web viewer showing the served recording."""
    return f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc_port}%2Fproxy"


def _stop(proc: subprocess.Popen, timeout: float = 3.0) -> None:
    """Stop the viewer and its process group: SIGTERM, then SIGKILL (it only reads a file)."""
    if proc.poll() is not None:
        return
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            if os.name == "posix":
                os.killpg(proc.pid, sig)
            else:  # pragma: no cover - Windows
                proc.terminate() if sig != signal.SIGKILL else proc.kill()
        except ProcessLookupError:
            return
        try:
            proc.wait(timeout=timeout)
            return
        except subprocess.TimeoutExpired:
            continue


def _print_summary(summary, as_json: bool, full: bool = False) -> None:
    if as_json:
        print(json.dumps(summary.to_json()))
        return
    from lcc_synth.recording.summary import full_lines, summary_lines

    print("\n".join(full_lines(summary) if full else summary_lines(summary)))


def _interrupt(signum, frame):  # SIGTERM / SIGHUP: stop like Ctrl-C
    raise KeyboardInterrupt


def _serve(binary: Path, path: Path, args: argparse.Namespace, env: dict[str, str]) -> int:
    previous = {}
    for sig in (getattr(signal, "SIGTERM", None), getattr(signal, "SIGHUP", None)):
        if sig is not None:
            try:
                previous[sig] = signal.signal(sig, _interrupt)
            except ValueError:  # not the main thread: leave signals alone
                pass
    try:
        return _serve_until_stopped(binary, path, args, env)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def _tail(log) -> str:
    """The viewer's last log lines, without terminal colour codes."""
    log.seek(0)
    text = _ANSI.sub("", log.read().decode(errors="replace")).strip()
    return "\n  ".join(text.splitlines()[-5:])


def _viewer(cmd: list[str], env: dict[str, str], log) -> subprocess.Popen:
    return subprocess.Popen(
        cmd,
        stdin=subprocess.DEVNULL,
        stdout=log,
        stderr=log,
        env=env,
        start_new_session=True,  # our Ctrl-C stops it through _stop, never half of it
    )


def _wait(proc: subprocess.Popen, log) -> int:
    """Wait for the viewer until it exits or we are interrupted (then stop it)."""
    try:
        rc = proc.wait()
    except KeyboardInterrupt:
        _stop(proc)
        print("stopped", file=sys.stderr)
        return 0
    finally:
        _stop(proc)
    if rc not in (0, -signal.SIGINT, -signal.SIGTERM, 130):
        print(f"lcc-synth review: the viewer failed:\n  {_tail(log)}", file=sys.stderr)
        return 1
    return 0


def _serve_until_stopped(
    binary: Path, path: Path, args: argparse.Namespace, env: dict[str, str]
) -> int:
    grpc_port = _check_port(args.port, "--port")
    # Every mode binds the viewer's own gRPC server to 127.0.0.1 (Rerun's default: 0.0.0.0).
    base = [str(binary), str(path), "--bind", "127.0.0.1", "--port", str(grpc_port)]
    with tempfile.TemporaryFile(mode="w+b") as log:
        if not args.web and has_display():
            proc = _viewer(base, env, log)
            try:
                proc.wait(timeout=3.0)
            except subprocess.TimeoutExpired:
                print(f"Opened {path} in the Rerun viewer (Ctrl-C here closes it).", flush=True)
                return _wait(proc, log)
            except KeyboardInterrupt:
                _stop(proc)
                return 0
            if proc.returncode == 0:
                return 0
            print(
                f"lcc-synth review: the native viewer could not start ({_tail(log)}); "
                "serving the web viewer instead",
                file=sys.stderr,
            )
            log.seek(0)
            log.truncate()
            grpc_port = _check_port(args.port, "--port")
            base = [str(binary), str(path), "--bind", "127.0.0.1", "--port", str(grpc_port)]
        web_port = _check_port(args.web_port, "--web-port")
        if web_port == grpc_port:
            raise ConfigError("--port", f"must differ from --web-port ({web_port})")
        proc = _viewer([*base, "--serve-web", "--web-viewer-port", str(web_port)], env, log)
        try:
            deadline = time.monotonic() + 30.0
            while not _listening(web_port):
                if proc.poll() is not None or time.monotonic() > deadline:
                    _stop(proc)
                    print(
                        f"lcc-synth review: the web viewer did not start:\n  {_tail(log)}",
                        file=sys.stderr,
                    )
                    return 1
                time.sleep(0.1)
        except KeyboardInterrupt:
            _stop(proc)
            return 0
        print(f"Serving {path} on 127.0.0.1 only; open {web_url(web_port, grpc_port)}")
        print("Press Ctrl-C to stop.", flush=True)
        return _wait(proc, log)


def run(args: argparse.Namespace) -> int:
    from lcc_synth.recording import rerun_binary, summarize_recording, viewer_environment

    paths = [Path(p) for p in args.path]
    if len(paths) > 2:
        raise ConfigError("PATH.rrd", f"one recording, or two side by side; got {len(paths)}")
    if len(paths) == 2 and args.summary:
        raise ConfigError("--summary", "applies to one recording (run it once per file)")
    path = paths[0]
    if args.json and not args.summary:
        raise ConfigError("--json", "only applies with --summary")
    if args.full and not args.summary:
        raise ConfigError("--full", "only applies with --summary")
    if args.summary:
        for flag, given in (("--web", args.web), ("--web-port", args.web_port),
                            ("--port", args.port)):
            if given:
                raise ConfigError(flag, "opens the viewer; it does not apply with --summary")
    if len(paths) == 2:  # one file holding both, removed when the viewer ends
        import tempfile

        from lcc_synth.recording.compare import side_by_side

        with tempfile.TemporaryDirectory(prefix="lcc-review-") as tmp:
            both = side_by_side(paths[0], paths[1], Path(tmp) / "side_by_side.rrd",
                                rerun_binary())  # fmt: skip
            return _serve(rerun_binary(), both, args, viewer_environment())
    summary = summarize_recording(path)  # validates: ConfigError for a missing/invalid file
    if args.summary:
        _print_summary(summary, args.json, args.full)
        return 0
    return _serve(rerun_binary(), path, args, viewer_environment())
