"""A load cell timed on receipt (no time column) whose lines reach the bridge several per
read, as a USB serial adapter delivers them (an FTDI chip sends what it holds every 16 ms):
a real bridge process on a pseudo-terminal, its blocks taken by a Zenoh subscriber."""

from __future__ import annotations

import os
import subprocess
import sys
import time
import tty

import numpy as np
import pytest

from daemon_harness import ENV, free_port
from test_bridge import Collector

pytestmark = pytest.mark.integration


def test_lines_arriving_together_each_give_a_sample_in_order(tmp_path):
    """20 writes of 3 loads each, 50 ms apart: 60 samples in their order, times strictly
    increasing within the feed's span, none rejected (each write's lines had one receive
    time: the 2nd and 3rd of each were dropped as ``time_backwards``, 40 of 60)."""
    port = free_port()
    col = Collector(port)
    master, slave = os.openpty()
    tty.setraw(slave)
    cfg = tmp_path / "b.toml"
    cfg.write_text(f'[buoy]\nid = "t1"\n[bridge]\nconnect = ["tcp/127.0.0.1:{port}"]\n'
                   'status_interval_s = 0.2\n[[source]]\nname = "lc"\nsensor = "tension"\n'
                   f'transport = "serial"\ndevice = "{os.ttyname(slave)}"\n'
                   'columns = { tension_N = 0 }\n')
    p = subprocess.Popen([sys.executable, "-m", "monitor.cli", "--log-level", "warning",
                          "bridge", "--config", str(cfg)], env=ENV, stderr=subprocess.PIPE)
    loads = np.arange(60, dtype=float) + 1000.0
    try:
        time.sleep(1.5)  # connected to the collector
        os.write(master, b"\n")  # ends whatever partial line the open saw
        time.sleep(0.2)
        t0 = time.time_ns()
        for k in range(0, 60, 3):
            os.write(master, "".join(f"  {v:.1f}\r\n" for v in loads[k:k + 3]).encode())
            time.sleep(0.05)
        t1 = time.time_ns()
        time.sleep(2.0)  # the last block closes on the wall clock
        status = col.status[-1]["sources"]["lc"]
        blocks = col.blocks()
    finally:
        p.terminate()
        p.wait(30)
        col.close()
        os.close(master)
        os.close(slave)
    t = np.concatenate([b.t_ns for b in blocks])
    v = np.concatenate([b.fields["tension_N"] for b in blocks])
    assert status["rejected"] == {} and status["samples"] == 60, status
    np.testing.assert_array_equal(v, loads)
    assert np.all(np.diff(t) > 0)
    assert t0 - 1_000_000_000 < t[0] and t[-1] <= t1
