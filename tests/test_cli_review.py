"""``lcc-synth review``: summary, bad input, and the web viewer served on 127.0.0.1 only."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import time
import urllib.request

import numpy as np
import pytest

pytest.importorskip("rerun")

from cli_subprocess import start_cli

from lcc_synth import recording as R  # noqa: E402
from lcc_synth.cli import review  # noqa: E402
from lcc_synth.cli.main import main  # noqa: E402
from lcc_synth.controllers.static import HDVController  # noqa: E402
from lcc_synth.simulation.engine import simulate  # noqa: E402
from lcc_synth.simulation.perturbations import Brake  # noqa: E402
from lcc_synth.simulation.scenario import Scenario  # noqa: E402


@pytest.fixture(scope="module")
def rrd(tmp_path_factory):
    sc = Scenario(m=0, n=2, duration=3.0, perturbations=(Brake(vehicle=1, start=1.0),))
    res = simulate(sc, HDVController("all_hdv"))
    path = tmp_path_factory.mktemp("review") / "run.rrd"
    with R.open_recording(path, "demo", R.simulation_blueprint("demo", ["all_hdv"])) as rec:
        R.record_simulation(rec, res, "demo", metrics={"aave": 0.123456, "fuel_ml": 9.5},
                            decimate=1)  # fmt: skip
    return path


def test_summary_prints_entities_time_range_samples_and_metrics(rrd, capsys):
    assert main(["review", "--summary", "--full", str(rrd)]) == 0
    out = capsys.readouterr().out
    assert "time range   0 .. 2.99 s" in out
    assert re.search(r"/demo/all_hdv/velocity\s+Scalars/SeriesLines: 300 samples, 4 series", out)
    assert "/demo/all_hdv/road" in out and "blueprint    yes" in out
    assert "| aave | 0.123456 |" in out  # the metrics document
    assert "complete" in out  # the status document


def test_summary_json_is_one_object(rrd, capsys):
    assert main(["review", "--summary", "--json", str(rrd)]) == 0
    out = capsys.readouterr().out
    data = json.loads(out)
    assert data["time_range"] == [0.0, 2.99]
    assert data["entities"]["/demo/all_hdv/velocity"]["samples"] == 300
    assert data["has_blueprint"] is True
    assert any(v["space_origin"] == "/demo/all_hdv/road" for v in data["views"])


@pytest.mark.parametrize("flags", [["--web"], ["--web-port", "9090"], ["--port", "9876"]])
def test_viewer_options_do_not_apply_with_summary(rrd, capsys, flags):
    assert main(["review", "--summary", *flags, str(rrd)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and flags[0] in err[0] and "does not apply with --summary" in err[0]


@pytest.mark.parametrize("content", [None, b"", b"definitely not an rrd file\n" * 20])
def test_missing_or_invalid_file_exits_2(tmp_path, capsys, content):
    path = tmp_path / "x.rrd"
    if content is not None:
        path.write_bytes(content)
    assert main(["review", "--summary", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lcc-synth review: error:") and "\n" not in err
    assert main(["review", str(path)]) == 2  # also without --summary, before any viewer starts


def test_display_detection():
    assert not review.has_display({}, "linux")
    assert review.has_display({"DISPLAY": ":0"}, "linux")
    assert review.has_display({"WAYLAND_DISPLAY": "wayland-0"}, "linux")
    assert review.has_display({}, "darwin")


def test_viewer_environment_turns_analytics_off():
    env = R.viewer_environment({"PATH": "/bin"})
    assert env["CI"] == "1" and env["PATH"] == "/bin"
    assert R.rerun_binary().is_file() and os.access(R.rerun_binary(), os.X_OK)


def _listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


@pytest.mark.parametrize("display", [None, ":97"])
def test_web_viewer_serves_on_localhost_and_stops_on_ctrl_c(rrd, display, tmp_path):
    """No display -> web viewer; a display that does not work (no X server on :97) -> the
    native viewer fails at once and review falls back to the web viewer. Rerun's analytics
    stay off: nothing is written to the (temporary) home, config or data directories."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    home = tmp_path / "home"
    home.mkdir()
    env.update(HOME=str(home), XDG_CONFIG_HOME=str(home / ".config"),
               XDG_DATA_HOME=str(home / ".local" / "share"))  # fmt: skip
    if display is not None:
        if os.path.exists(f"/tmp/.X11-unix/X{display[1:]}"):
            pytest.skip(f"an X server runs on {display}")
        env["DISPLAY"] = display
    proc = start_cli(["review", rrd], cwd=tmp_path, env=env)
    try:
        line = proc.stdout.readline()  # blocks until the viewer listens (or fails)
        m = re.search(r"open (http://127\.0\.0\.1:(\d+)/\?url=\S+127\.0\.0\.1%3A(\d+)\S+)", line)
        assert m, (line, proc.stderr.read() if proc.poll() is not None else "")
        url, web_port, grpc_port = m.group(1), int(m.group(2)), int(m.group(3))
        with urllib.request.urlopen(url, timeout=10) as resp:
            assert resp.status == 200
        with urllib.request.urlopen(f"http://127.0.0.1:{web_port}/re_viewer.js", timeout=10) as r:
            assert r.status == 200  # the viewer itself is served (offline, no CDN)
        # bound to 127.0.0.1 only: the ports are not open on any other local address
        viewer_pids = _viewer_pids(web_port)
        assert viewer_pids or not os.path.isdir("/proc/net"), "no process listens on the web port"
        for addr in _other_local_addresses():
            for port in (web_port, grpc_port):
                with socket.socket() as s:
                    s.settimeout(0.2)
                    assert s.connect_ex((addr, port)) != 0
        proc.send_signal(signal.SIGINT)  # Ctrl-C
        assert proc.wait(timeout=15) == 0
        if display is not None:
            assert "serving the web viewer instead" in proc.stderr.read()
        deadline = time.monotonic() + 10
        while (_listening(web_port) or _listening(grpc_port)) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _listening(web_port) and not _listening(grpc_port)
        for pid in viewer_pids:  # the viewer process itself is gone (not orphaned)
            assert not _alive(pid)
        assert list(home.rglob("*")) == []  # no analytics config, id or event files
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _viewer_pids(port: int) -> list[int]:
    """PIDs of processes with a listening socket on ``port`` (Linux /proc; empty elsewhere)."""
    if not os.path.isdir("/proc/net"):
        return []
    inodes = set()
    with open("/proc/net/tcp") as fh:
        for row in fh.readlines()[1:]:
            parts = row.split()
            if int(parts[1].split(":")[1], 16) == port and parts[3] == "0A":
                inodes.add(parts[9])
    pids = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            for fd in os.listdir(f"/proc/{pid}/fd"):
                link = os.readlink(f"/proc/{pid}/fd/{fd}")
                if link.startswith("socket:[") and link[8:-1] in inodes:
                    pids.append(int(pid))
                    break
        except OSError:
            continue
    return pids


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split()[2] != "Z"
    except OSError:
        return False


def _other_local_addresses() -> list[str]:
    """Non-loopback IPv4 addresses of this machine (where a 0.0.0.0 bind would answer)."""
    addrs = set()
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("10.255.255.255", 1))
            addrs.add(s.getsockname()[0])
    except OSError:
        pass
    try:
        addrs.update(socket.gethostbyname_ex(socket.gethostname())[2])
    except OSError:
        pass
    return [a for a in addrs if not a.startswith("127.")]


def test_port_validation(rrd, capsys):
    assert main(["review", "--web", "--web-port", "70000", str(rrd)]) == 2
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        assert main(["review", "--web", "--port", str(port), str(rrd)]) == 2
    assert f"port {port} on 127.0.0.1 is in use" in capsys.readouterr().err
    assert np.isfinite(review._free_port())


def test_summary_report_facts_are_rounded_with_units():
    """A report line of the summary: |Gamma|'s peak rounded to 3 decimals, its frequency with
    its unit, words as written, a missing number as written (the report's own text)."""
    from lcc_synth.recording.reader import RecordingSummary
    from lcc_synth.recording.summary import summary_lines

    report = ("# case A\n\n| quantity | value |\n|---|---|\n| verdict | string_unstable |\n"
              "| gamma_peak | 1.12723 |\n| gamma_peak_omega | 0.451821 |\n| h2_true | None |\n")
    s = RecordingSummary(path="x.rrd", size_bytes=0, application_id="a", recording_ids=["r"],
                         has_blueprint=False, entities={},
                         texts={"/analysis/gamma/a/report": report})  # fmt: skip
    (line,) = [ln for ln in summary_lines(s) if "/analysis/gamma/a" in ln]
    assert line.split("/analysis/gamma/a", 1)[1].strip() == (
        "verdict string_unstable, max |Γ| 1.127, at ω 0.452 rad/s, true H2 None")
