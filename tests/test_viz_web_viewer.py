"""The served web viewer listens on loopback only, runs with analytics disabled, and takes data."""

from __future__ import annotations

import socket
import urllib.request

from monitor.viz.rerun_options import RerunOptions
from monitor.viz.rerun_outputs import analytics_disabled, open_rerun_sink
from tests.viz_helpers import make_steps


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def listening_addresses(port: int) -> set[str]:
    """Local IPv4/IPv6 addresses (hex, as in /proc/net/tcp*) listening on ``port``."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with open(table) as f:
            for line in f.readlines()[1:]:
                local, state = line.split()[1], line.split()[3]
                addr, p = local.split(":")
                if state == "0A" and int(p, 16) == port:  # 0A = LISTEN
                    found.add(addr)
    return found


def test_web_viewer_binds_loopback_only(tmp_path):
    opts = RerunOptions(serve_web=True, web_port=free_port(), grpc_port=free_port(),
                        server_memory_limit="32MiB")
    sink, viewer = open_rerun_sink("B1", opts, config_home=tmp_path / "cfg")
    try:
        assert viewer is not None
        for port in (opts.web_port, opts.grpc_port):
            assert listening_addresses(port) == {"0100007F"}, port  # 127.0.0.1, nothing else
        assert analytics_disabled(tmp_path / "cfg")
        with urllib.request.urlopen(f"http://127.0.0.1:{opts.web_port}/", timeout=30) as resp:
            assert resp.status == 200 and b"<html" in resp.read(4096).lower()
        for step in make_steps(5):
            sink.on_step(step)
        sink.close()
        assert viewer.process.poll() is None  # the viewer took the stream and is still up
    finally:
        viewer.stop()
    assert viewer.process.poll() is not None


def test_web_viewer_serves_a_recording_on_loopback(tmp_path):
    from monitor.viz.rerun_outputs import open_recording, serve_web_viewer
    from monitor.viz.rerun_sink import RerunSink

    rrd = tmp_path / "r.rrd"
    sink = RerunSink(open_recording("B1", RerunOptions(), rrd=rrd))
    for step in make_steps(3):
        sink.on_step(step)
    sink.close()
    opts = RerunOptions(web_port=free_port(), grpc_port=free_port())
    viewer = serve_web_viewer(opts, tmp_path / "cfg", recordings=(rrd,))
    try:
        assert listening_addresses(opts.web_port) == {"0100007F"}
        assert viewer.web_url.startswith(f"http://127.0.0.1:{opts.web_port}/")
        assert viewer.process.poll() is None
    finally:
        viewer.stop()
