"""``monitor.publisher.play`` (``buoymon simulate --publish``, ``python -m replay.publish``)
says when nobody was connected to receive what it published: it does not wait for a
subscriber and its caches close with it, so such blocks are lost (it printed "published N
blocks" and nothing else)."""

from __future__ import annotations

import logging
import time

import numpy as np
import pytest

from daemon_harness import free_port
from monitor import zenoh_io
from monitor.blocks import SampleBlock
from monitor.daemon_config import ZenohConfig
from monitor.publisher import play, publisher_config

pytestmark = pytest.mark.integration  # real Zenoh sessions on loopback

T0 = 946_684_800 * 10**9


def blocks(n: int = 3) -> list[SampleBlock]:
    return [SampleBlock("qa", "tension", T0 + k * 10**9 + np.arange(20, dtype=np.int64) * 50_000_000,
                        {"tension_N": np.full(20, 1000.0 + k)}) for k in range(n)]


def test_play_warns_when_nothing_was_connected(caplog):
    port = free_port()  # nothing listens there
    with caplog.at_level(logging.WARNING, logger="monitor.publisher"):
        assert play(blocks(), publisher_config([f"tcp/127.0.0.1:{port}"])) == 3
    assert "published 3 blocks but no daemon or router was connected" in caplog.text


def test_play_is_quiet_when_a_peer_receives(caplog):
    port = free_port()
    got: list[str] = []
    with zenoh_io.open_session(ZenohConfig(listen=(f"tcp/127.0.0.1:{port}",))) as daemon:
        sub = daemon.declare_subscriber("buoy/qa/sensor/**", lambda s: got.append(str(s.key_expr)))
        zc = publisher_config([f"tcp/127.0.0.1:{port}"])
        with caplog.at_level(logging.WARNING, logger="monitor.publisher"):
            assert play(blocks(), zc, linger_s=0.5) == 3
        deadline = time.monotonic() + 5
        while len(got) < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
        sub.undeclare()
    assert "no daemon or router" not in caplog.text
    assert got == ["buoy/qa/sensor/tension"] * 3
