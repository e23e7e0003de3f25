"""The daemon's mechanics in a real process over real Zenoh (fake physics, see daemon_harness).

Status at >= 1 Hz with damage, counters and sensor health; the state queryable; liveliness and
wall-clock data age of a sensor; sd_notify READY/WATCHDOG/STOPPING; SIGTERM drains and
checkpoints; the recorder keeps every received and published message; undecodable payloads
and blocks the pipeline refuses are counted without stopping the daemon.
"""

import json
import os
import queue
import subprocess
import sys
import time

import numpy as np
import pytest
from mcap.reader import make_reader

from monitor import zenoh_io
from monitor.blocks import SampleBlock
from monitor.checkpoint import CheckpointStore
from monitor.daemon_config import ZenohConfig

from daemon_harness import (
    BUOY, ENV, T0_NS, DaemonProcess, FakeCodec, expected_total, free_port, tension_blocks,
    wait_until_state, write_config,
)

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`

HARNESS = os.path.join(os.path.dirname(__file__), "daemon_harness.py")


def _statuses(q, until, timeout=60.0):
    """Collect status documents until ``until(doc)`` is true; return them all."""
    out, deadline = [], time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            out.append(json.loads(q.get(timeout=0.2)[2]))
        except queue.Empty:
            continue
        if until(out[-1]):
            return out
    raise AssertionError(f"condition not reached; last status: {out[-1] if out else None}")


def test_daemon_status_query_health_notify_and_clean_shutdown(tmp_path):
    port = free_port()
    state, rec = tmp_path / "state.sqlite", tmp_path / "rec"
    cfg = write_config(tmp_path / "cfg.toml", port, state, record=rec)
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
    d.wait_for("READY=1")
    n_blocks = 30
    total = expected_total(tension_blocks(n_blocks))
    q = queue.SimpleQueue()
    client = ZenohConfig(mode="client", listen=(), connect=(f"tcp/127.0.0.1:{port}",))
    with zenoh_io.open_session(client) as s:
        sub = zenoh_io.declare_enqueuing_subscriber(s, zenoh_io.status_key(BUOY), q)
        idle = _statuses(q, lambda doc: True, timeout=30)
        t_idle = time.monotonic()
        idle += _statuses(q, lambda doc: time.monotonic() - t_idle > 2.0)
        assert len(idle) >= 5  # status_interval_s = 0.5 even without data
        pub = subprocess.run([sys.executable, HARNESS, "publish", f"tcp/127.0.0.1:{port}",
                              str(n_blocks), "20"], env=ENV, capture_output=True, text=True,
                             timeout=60)
        assert pub.stdout.strip() == str(n_blocks), pub.stderr
        done = _statuses(q, lambda doc: doc["streams"].get("tension", {}).get("accepted") == 600)
        live = done[-1]
        assert live["buoy_id"] == BUOY and live["load_source"] == "measured"
        assert live["components"]["conductor"]["damage"] == total
        assert live["streams"]["tension"]["data_stale"] is False
        assert any(doc["streams"].get("tension", {}).get("alive") for doc in done)
        assert live["streams"]["tension"]["last_t_ns"] == tension_blocks(n_blocks)[-1].t_last_ns
        assert live["counters"]["messages"] == n_blocks
        # the publisher has gone: its liveliness token, then (after 1 s) the data age say so
        gone = _statuses(q, lambda doc: doc["streams"]["tension"]["data_stale"]
                         and doc["streams"]["tension"]["alive"] is False)
        assert gone[-1]["streams"]["tension"]["data_age_s"] > 1.0
        waves = SampleBlock(BUOY, "waves", np.array([T0_NS], np.int64),
                            {"hs_m": np.array([1.5]), "tp_s": np.array([5.25])})
        s.put(f"buoy/{BUOY}/sensor/waves", FakeCodec().encode(waves))
        s.put(f"buoy/{BUOY}/sensor/tension", b"garbage")
        refused = _statuses(q, lambda doc: doc["counters"]["refused"] == 1
                            and doc["counters"]["undecodable"] == 1)
        assert refused[-1]["components"]["conductor"]["damage"] == total  # still serving
        replies = [r.ok for r in s.get(zenoh_io.state_key(BUOY), timeout=30) if r.ok]
        full = json.loads(replies[0].payload.to_bytes())
        assert full["state"]["pipeline"]["total"] == total
        assert full["status"]["counters"]["queries"] == 1
        sub.undeclare()
    assert idle[0]["components"]["conductor"]["damage"] == 0.0 and idle[0]["load_source"] == "none"
    assert d.terminate() == 0
    assert "WATCHDOG=1" in d.messages and "STOPPING=1" in d.messages
    store = CheckpointStore(state)
    cp = store.load()
    store.close()
    assert cp.state["pipeline"]["total"] == total
    assert cp.state["pipeline"]["accepted"]["tension"] == 600
    assert cp.state["daemon"]["counters"]["messages"] == n_blocks + 2
    msgs = []
    for name in sorted(os.listdir(rec)):
        with open(rec / name, "rb") as f:
            msgs += [(c.topic, m.data) for _, c, m in make_reader(f).iter_messages()]
    sensor = [m for t, m in msgs if t == f"buoy/{BUOY}/sensor/tension"]
    status = [json.loads(m) for t, m in msgs if t == f"buoy/{BUOY}/monitor/status"]
    assert len(sensor) == n_blocks
    assert status[-1]["components"]["conductor"]["damage"] == total


def test_restart_resumes_from_the_checkpoint(tmp_path):
    """A second life sees the first life's damage and skips re-delivered samples."""
    port = free_port()
    state = tmp_path / "state.sqlite"
    cfg = write_config(tmp_path / "cfg.toml", port, state)
    blocks = tension_blocks(20)
    for life in range(2):
        d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
        d.wait_for("READY=1")
        pub = subprocess.run([sys.executable, HARNESS, "publish", f"tcp/127.0.0.1:{port}",
                              str(10 + 10 * life), "0"], env=ENV, capture_output=True,
                             text=True, timeout=60)
        assert pub.returncode == 0, pub.stderr
        sent = sum(10 + 10 * k for k in range(life + 1))  # counters survive the restart
        wait_until_state(port, lambda s: s["status"]["counters"]["messages"] == sent)
        assert d.terminate() == 0
    store = CheckpointStore(state)
    cp = store.load()
    store.close()
    assert cp.state["pipeline"]["total"] == expected_total(blocks)
    assert cp.state["pipeline"]["accepted"]["tension"] == 400
    assert cp.state["pipeline"]["rejected"]["tension"]["duplicate"] == 200


def test_a_backlog_does_not_starve_status_and_checkpoints(tmp_path):
    """200 blocks arrive at once and take 20 ms each: status keeps coming during the 4 s."""
    port = free_port()
    state = tmp_path / "state.sqlite"
    cfg = write_config(tmp_path / "cfg.toml", port, state, checkpoint_s=0.5)
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg), "0.02"], tmp_path)
    d.wait_for("READY=1")
    q = queue.SimpleQueue()
    client = ZenohConfig(mode="client", listen=(), connect=(f"tcp/127.0.0.1:{port}",))
    with zenoh_io.open_session(client) as s:
        sub = zenoh_io.declare_enqueuing_subscriber(s, zenoh_io.status_key(BUOY), q)
        subprocess.run([sys.executable, HARNESS, "publish", f"tcp/127.0.0.1:{port}", "200",
                        "0"], env=ENV, check=True, capture_output=True, timeout=60)
        docs = _statuses(q, lambda doc: doc["counters"]["messages"] == 200)
        sub.undeclare()
    during = {doc["counters"]["messages"] for doc in docs if 0 < doc["counters"]["messages"] < 200}
    assert len(during) >= 8  # about 4 per second of backlog
    assert max(doc["queue_depth"] for doc in docs) > 50  # there was a backlog
    assert d.terminate() == 0
