"""A wall-clock step while messages wait does not age them: delivery is timed on the
monotonic clock taken in the Zenoh callback (a buoy logger's clock steps at boot, when its
RTC time is corrected from GNSS or NTP, often while sensor messages are already flowing)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from monitor import cmd_run, zenoh_io
from monitor.blocks import SampleBlock

ROOT = Path(__file__).resolve().parents[1]


def test_a_wall_clock_step_forward_after_receipt_does_not_make_data_stale(tmp_path):
    cfg = tmp_path / "daemon.toml"
    cfg.write_text((ROOT / "monitor" / "vaps_seed004.toml").read_text()
                   + f'\n[state]\npath = "{tmp_path / "state.sqlite"}"\n[metrics]\nport = 0\n')
    daemon = cmd_run.build_daemon(str(cfg))
    codec = zenoh_io.default_codec()
    # received a moment ago (monotonic clock), stamped by the wall clock before it stepped
    # forward by an hour; the sensor's clock agreed with the logger's then
    recv_ns = time.time_ns() - 3600 * 10**9
    t = recv_ns - 10**9 + np.arange(20) * 50_000_000
    block = SampleBlock("vaps", "tension", t, {"tension_N": np.full(20, 3000.0)})
    daemon._on_data("buoy/vaps/sensor/tension", codec.encode(block), recv_ns, None,
                    time.monotonic())
    status = daemon.status()
    tension = status["streams"]["tension"]
    assert tension["data_age_s"] < 5.0  # was 3600 s: derived from the wall clock
    assert tension["data_stale"] is False
    assert status["counters"]["messages"] == 1
