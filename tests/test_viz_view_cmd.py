"""``buoymon view`` as a real process: stop signals end its viewer, taken ports are refused
with the holder named, so a browser never shows a stale recording (issue 19)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from monitor.viz.port_owner import port_listeners
from monitor.viz.rerun_options import RerunOptions
from monitor.viz.rerun_outputs import open_recording
from monitor.viz.rerun_sink import RerunSink
from tests.test_viz_web_viewer import free_port
from tests.viz_helpers import make_steps

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def rrd(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rrd") / "r.rrd"
    sink = RerunSink(open_recording("B1", RerunOptions(), rrd=path))
    for step in make_steps(3):
        sink.on_step(step)
    sink.close()
    return path


def _start_view(rrd: Path, web: int, grpc: int) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "monitor.cli", "view", str(rrd), "--web-port", str(web),
         "--grpc-port", str(grpc)],
        cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)), stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True)


def _wait_url(proc: subprocess.Popen) -> str:
    line = proc.stdout.readline()  # printed once the viewer listens
    assert line.startswith("Rerun web viewer (127.0.0.1 only): http://127.0.0.1:"), (
        line + proc.stderr.read() if proc.poll() is not None else line)
    return line


def _gone(ports: tuple[int, int], timeout_s: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if not any(port_listeners(p) for p in ports):
            return True
        time.sleep(0.1)
    return False


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_stop_signals_end_the_viewer(rrd, sig):
    ports = (free_port(), free_port())
    proc = _start_view(rrd, *ports)
    try:
        _wait_url(proc)
        holders = port_listeners(ports[0])
        assert holders and all(h.pid != proc.pid for h in holders)  # the rerun server
        proc.send_signal(sig)
        assert proc.wait(30) == 0
        assert f"{sig.name}: viewer stopped" in proc.stderr.read()
        assert _gone(ports), f"viewer still listening after {sig.name}"
        for h in holders:  # the server and its fork are gone, not orphaned
            assert not Path(f"/proc/{h.pid}").exists() or \
                Path(f"/proc/{h.pid}/stat").read_text().split()[2] == "Z"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_taken_ports_are_refused_naming_the_holder(rrd, tmp_path):
    ports = (free_port(), free_port())
    first = _start_view(rrd, *ports)
    try:
        _wait_url(first)
        holder = port_listeners(ports[0])[0]
        second = subprocess.run(
            [sys.executable, "-m", "monitor.cli", "view", str(rrd), "--web-port",
             str(ports[0]), "--grpc-port", str(free_port())],
            cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)), capture_output=True,
            text=True, timeout=60)
        assert second.returncode == 2 and "Rerun web viewer" not in second.stdout
        assert (f"web port {ports[0]} is already in use by pid {holder.pid} "
                in second.stderr), second.stderr
        assert "rerun_cli" in second.stderr  # the holder's command line
    finally:
        first.send_signal(signal.SIGTERM)
        first.wait(30)
    assert _gone(ports)


def test_port_listeners_names_this_process():
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        (me,) = port_listeners(port)
        assert me.pid == os.getpid() and "pytest" in me.command
    assert port_listeners(port) == []


def test_native_viewer_refuses_a_taken_grpc_port(rrd, capsys):
    import socket

    from monitor.cli import main

    with socket.socket() as s:  # this test process holds the port
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert main(["view", str(rrd), "--native", "--grpc-port", str(port)]) == 2
    err = capsys.readouterr().err
    assert f"gRPC port {port} is already in use by pid {os.getpid()} (" in err
