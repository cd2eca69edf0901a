"""Screenshot of a recording as ``lcc-synth review --web`` shows it, in headless Chromium.

Serves ``PATH.rrd`` with the web viewer bound to 127.0.0.1 (``lcc-synth review --web``),
starts Chromium headless with its DevTools endpoint on 127.0.0.1, navigates to the viewer,
waits for the WebAssembly viewer to load the recording and its blueprint, and saves a PNG
(``Page.captureScreenshot`` over the DevTools protocol). Both processes are stopped at the end.

Needs the Debian package ``chromium`` (``apt-get install -y chromium``) and the optional extra
``screenshot`` (``pip install -e .[screenshot]``: websocket-client)::

    python benchmarks/screenshot_review.py logs/showcase-*.rrd -o review.png [--timeout 300]

``chromium --headless --screenshot`` alone returns before the viewer has started (the PNG
shows "Loading Application Bundle"): this script waits for the data instead, not for a fixed
time: it captures every 5 s until three captures in a row are identical and far larger than
the loading page (with the software rasterizer here: 60-120 s).
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(proc: subprocess.Popen | None) -> None:
    """Stop ``proc`` and its process group (the viewer's own children too)."""
    if proc is None or proc.poll() is not None:
        return
    for sig, wait in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(wait)
            return
        except subprocess.TimeoutExpired:
            continue


def _serve(rrd: Path, log) -> tuple[subprocess.Popen, str]:
    """Start ``lcc-synth review --web`` on 127.0.0.1; return the process and the viewer URL."""
    web, grpc = _free_port(), _free_port()
    env = {**os.environ, "RERUN_ANALYTICS": "0"}
    cmd = [sys.executable, "-m", "lcc_synth.cli.main", "review", str(rrd), "--web",
           "--web-port", str(web), "--port", str(grpc)]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=log, text=True, env=env,
                            start_new_session=True)  # fmt: skip
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            if proc.poll() is not None:
                raise RuntimeError(f"lcc-synth review exited with {proc.returncode}")
            continue
        if "open http" in line:
            return proc, line.split("open ", 1)[1].strip()
    raise RuntimeError("lcc-synth review did not print the viewer address within 60 s")


def _chromium(port: int, profile: str, size: tuple[int, int], log) -> subprocess.Popen:
    binary = shutil.which("chromium") or shutil.which("chromium-browser")
    if binary is None:
        raise RuntimeError("chromium not found: apt-get install -y chromium")
    cmd = [binary, "--headless=new", "--no-sandbox", "--use-angle=swiftshader",
           "--enable-unsafe-swiftshader", f"--remote-debugging-port={port}",
           "--remote-debugging-address=127.0.0.1", f"--user-data-dir={profile}",
           f"--window-size={size[0]},{size[1]}", "--no-first-run", "about:blank"]  # fmt: skip
    return subprocess.Popen(cmd, stdout=log, stderr=log, start_new_session=True)


def _page_socket(port: int, timeout: float = 30.0) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json", timeout=2) as r:
                for target in json.load(r):
                    if target.get("type") == "page":
                        return target["webSocketDebuggerUrl"]
        except OSError:
            pass
        time.sleep(0.5)
    raise RuntimeError("Chromium's DevTools endpoint did not answer")


class _DevTools:
    def __init__(self, url: str):
        import websocket  # optional extra "screenshot"

        self.ws = websocket.create_connection(url, timeout=120, suppress_origin=True)
        self.next_id = 0

    def call(self, method: str, **params):
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == self.next_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})


def _settled(shots: list[bytes], settle: int) -> bool:
    """The view has its data: the last ``settle`` captures are identical (nothing loads or
    moves any more: the recording opens paused) and far larger than the first capture, taken
    while the viewer was still loading (a blank page or "Loading Application Bundle")."""
    if len(shots) < settle + 1:
        return False
    last = shots[-settle:]
    return all(x == last[0] for x in last) and len(last[0]) >= 3 * len(shots[0])


def screenshot(rrd: Path, out: Path, timeout: float = 300.0, size=(1920, 1080),
               poll: float = 5.0, settle: int = 3) -> tuple[Path, float]:  # fmt: skip
    """Serve ``rrd`` and screenshot the web viewer once it shows the data: captures every
    ``poll`` seconds until ``settle`` of them in a row are identical (:func:`_settled`), at
    most ``timeout`` seconds (then the last capture, and a warning). Returns the PNG written
    and the seconds it took to settle."""
    viewer = browser = None
    shots: list[bytes] = []
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory() as profile, open(Path(profile) / "log", "w") as log:
        try:
            viewer, url = _serve(rrd, log)
            port = _free_port()
            browser = _chromium(port, os.path.join(profile, "chrome"), size, log)
            tools = _DevTools(_page_socket(port))
            tools.call("Emulation.setDeviceMetricsOverride", width=size[0], height=size[1],
                       deviceScaleFactor=1, mobile=False)  # fmt: skip
            tools.call("Page.enable")
            tools.call("Page.navigate", url=url)
            t0 = time.monotonic()
            while True:
                try:
                    data = tools.call("Page.captureScreenshot", format="png")["data"]
                except RuntimeError:  # the page is still navigating: not attached yet
                    data = None
                if data is not None:
                    shots.append(base64.b64decode(data))
                if shots and _settled(shots, settle):
                    break
                if time.monotonic() - t0 > timeout and shots:
                    print(f"warning: the view did not settle within {timeout:g} s",
                          file=sys.stderr)  # fmt: skip
                    break
                time.sleep(poll)
            tools.ws.close()
        finally:
            _stop(browser)
            _stop(viewer)
    took = time.monotonic() - t0
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(shots[-1])
    return out, took


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("rrd", type=Path, help="the recording (.rrd)")
    p.add_argument("-o", "--out", type=Path, default=Path("review.png"), help="PNG to write")
    p.add_argument("--timeout", type=float, default=300.0,
                   help="seconds to wait at most for the view to settle (default 300)")  # fmt: skip
    p.add_argument("--size", default="1920x1080", help="window size WIDTHxHEIGHT")
    a = p.parse_args(argv)
    w, h = (int(x) for x in a.size.lower().split("x"))
    path, took = screenshot(a.rrd, a.out, a.timeout, (w, h))
    print(f"{path} (the view settled after {took:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
