"""``buoymon status --config bridge.toml``: a separate bridge's file names its daemon in
``[bridge] connect`` (docs/SENSORS.md); status asked the default tcp/127.0.0.1:7447 instead
(operator test). A real daemon process (daemon_harness) on a port of its own, the real CLI."""

import json
import os
import subprocess
import sys

import pytest

from daemon_harness import BUOY, ENV, DaemonProcess, free_port, write_config

pytestmark = pytest.mark.integration  # a daemon process

HARNESS = os.path.join(os.path.dirname(__file__), "daemon_harness.py")


def _bridge_file(path, port: int):
    path.write_text(f'[buoy]\nid = "{BUOY}"\n[bridge]\nconnect = ["tcp/127.0.0.1:{port}"]\n'
                    '[[source]]\nname = "loadcell"\nsensor = "tension"\ntransport = "file"\n'
                    'path = "loadcell.log"\ncolumns = { tension_N = 0 }\n')
    return path


def _status(cfg, *extra):
    return subprocess.run([sys.executable, "-m", "monitor.cli", "status", "--config", str(cfg),
                           *extra], env=ENV, capture_output=True, text=True, timeout=60)


def test_status_asks_the_daemon_a_bridge_file_connects_to(tmp_path):
    port = free_port()
    bridge = _bridge_file(tmp_path / "bridge.toml", port)
    # nothing there yet: the message names the endpoint asked, and why that one
    out = _status(bridge, "--timeout", "0.5")
    assert out.returncode == 1
    assert out.stderr == (
        f"buoymon status: no daemon answered at tcp/127.0.0.1:{port} ([bridge] connect of the "
        f"bridge configuration {bridge}) within 0.5 s; a bridge configuration names no state "
        "file: pass the daemon's configuration for its last checkpoint\n")
    cfg = write_config(tmp_path / "cfg.toml", port, tmp_path / "state.sqlite")
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
    try:
        d.wait_for("READY=1")
        out = _status(bridge, "--json", "--timeout", "10")
        assert out.returncode == 0, out.stderr
        doc = json.loads(out.stdout)
        assert doc["source"] == "daemon" and doc["running"] is True
        assert doc["status"]["buoy_id"] == BUOY
    finally:
        assert d.terminate() == 0
