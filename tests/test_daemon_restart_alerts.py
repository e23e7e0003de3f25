"""A daemon killed (SIGKILL) and restarted beside a sensor publisher that kept sending: the
publisher's cache holds all it missed, so the restarted daemon raises no data_age. `buoymon
run` twice and a separate `python -m replay.publish` process on loopback. Before, the live
rules ran on the first status, before the catch-up from the caches: every stream was as old
as the downtime, and data_age fired and cleared 1-2 s later (both sent to Alertmanager)."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

pytest.importorskip("monitor.pipeline")

from daemon_harness import ENV, DaemonProcess, free_port, query_state  # noqa: E402
from test_daemon_stall import BUOY, _config, _log  # noqa: E402
from waiting import wait_until  # noqa: E402

pytestmark = pytest.mark.integration


def _accepted(port: int) -> int:
    state = query_state(port, timeout=2.0, buoy=BUOY)
    return state["status"]["streams"].get("tension", {}).get("accepted", 0) if state else 0


def test_a_restart_beside_a_publisher_that_kept_sending_raises_no_data_age(tmp_path):
    port = free_port()
    cfg = _config(tmp_path, port)  # data_age_timeout_s 2.5 s for tension and the IMU
    cmd = [sys.executable, "-m", "monitor.cli", "--log-level", "warning", "run",
           "--config", str(cfg)]
    d = DaemonProcess(cmd, tmp_path)
    d.wait_for("READY=1", timeout=120)
    log = _log(tmp_path / "sensors.mcap", time.time_ns() // 10**9 * 10**9 + 2 * 10**9,
               tension_s=40, imu_s=40)
    pub = subprocess.Popen([sys.executable, "-m", "replay.publish", str(log), "--connect",
                            f"tcp/127.0.0.1:{port}", "--speed", "1"], env=ENV,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    d2 = None
    try:
        wait_until(lambda: _accepted(port) > 0, 60, "tension accepted")
        time.sleep(1.5)  # a checkpoint (every 1 s) knows the stream
        d.kill9()
        time.sleep(4.0)  # down longer than the 2.5-s timeout; the publisher goes on
        d2 = DaemonProcess(cmd, tmp_path)
        d2.wait_for("READY=1", timeout=120)
        before = _accepted(port)
        wait_until(lambda: _accepted(port) > before + 40, 30, "tension flowing again")
        time.sleep(1.0)  # a few status intervals (0.5 s) after the catch-up
        restarted = d2.stderr_path.read_text()
        recovered = query_state(port, buoy=BUOY)["status"]["streams"]["tension"]["recovered"]
    finally:
        pub.terminate()
        pub.wait(30)
        if d2 is not None:
            d2.terminate()
    assert recovered > 0  # what it missed came from the publisher's cache
    assert '"rule": "data_age"' not in restarted, restarted[-2000:]
