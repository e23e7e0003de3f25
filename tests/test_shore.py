"""Shore-side multi-buoy monitor: three buoys publishing at once over loopback Zenoh, per-buoy
pipelines equal to replay, liveliness appear/disappear, bounded intake per buoy, status states."""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from monitor.blocks import SampleBlock
from monitor.config import config_with, default_config
from monitor.daemon_config import ZenohConfig
from monitor.pipeline import Pipeline
from monitor.shore import BuoyTracker, ShoreConfig, ShoreMonitor, buoy_of_key, config_for_buoy
from replay.reader import iter_blocks
from replay.runner import run_blocks
from replay.writer import LogWriter
from waiting import wait_until

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`

ROOT = Path(__file__).resolve().parents[1]
T0_NS = 1_750_000_000 * 10**9
SECONDS = 120
AMPLITUDES = {"north1": 800.0, "north2": 1600.0, "south1": 2400.0}


def measured_config():
    c = default_config()
    return config_with(c, load={**c.section("load"), "source": "measured"})


def buoy_blocks(buoy: str, amp: float, seconds: int, seed: int) -> list[SampleBlock]:
    """1-s blocks of 20 Hz tension and 10 Hz IMU of a two-component swell."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(seconds):
        tt = T0_NS + (k * 20 + np.arange(20, dtype=np.int64)) * 50_000_000
        ti = T0_NS + (k * 10 + np.arange(10, dtype=np.int64)) * 100_000_000
        x = (tt - T0_NS) / 1e9
        v = (5000 + amp * np.sin(2 * np.pi * x / 5.25) + 0.3 * amp * np.sin(2 * np.pi * x / 7.1)
             + rng.normal(0, 30, 20))
        out.append(SampleBlock(buoy, "tension", tt, {"tension_N": v}, int(tt[-1]) + 10**6))
        az = rng.normal(0, 0.5, 10)
        out.append(SampleBlock(buoy, "imu", ti, {"accel_x_mps2": 0 * az, "accel_y_mps2": 0 * az,
                                                 "accel_z_mps2": az}, int(ti[-1]) + 10**6))
    return out


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def committed(report: dict) -> dict:
    return {n: c["damage_committed"] for n, c in report["components"].items()}


def hub_session(port: int):
    """A loopback peer the buoys and the shore connect to: stands in for a Zenoh router
    (zenohd is not on the package index); a peer routes for the clients connected to it."""
    from monitor import zenoh_io

    return zenoh_io.open_session(ZenohConfig(mode="peer", listen=(f"tcp/127.0.0.1:{port}",)))


def test_three_buoys_publishing_at_once_over_loopback(tmp_path):
    """Three publisher processes (peers) and the shore monitor (a client) meet at a hub."""
    config = measured_config()
    logs = {}
    for k, (buoy, amp) in enumerate(AMPLITUDES.items()):
        logs[buoy] = tmp_path / f"{buoy}.mcap"
        with LogWriter(logs[buoy]) as w:
            for b in buoy_blocks(buoy, amp, SECONDS, seed=k):
                w.write_block(b)
    port = free_port()
    hub = hub_session(port)
    shore = ShoreMonitor(config, ShoreConfig(
        zenoh=ZenohConfig(mode="client", listen=(), connect=(f"tcp/127.0.0.1:{port}",)),
        status_interval_s=0.2, data_age_timeout_s=3.0))
    server = threading.Thread(target=shore.run)
    server.start()
    try:
        assert shore.wait_ready(30)
        env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
        pubs = [subprocess.Popen([sys.executable, "-m", "replay.publish", str(log),
                                  "--connect", f"tcp/127.0.0.1:{port}", "--speed", "15"],
                                 env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                for log in logs.values()]
        # all three are followed at the same time while they publish
        wait_until(lambda: {b for b, s in shore.snapshot()["buoys"].items()
                            if s["state"] == "online"} == set(AMPLITUDES), 60, "3 buoys online")
        for p in pubs:
            out, err = p.communicate(timeout=120)
            assert p.returncode == 0 and out.strip() == str(2 * SECONDS), err
        wait_until(lambda: all(s["counters"]["messages"] == 2 * SECONDS
                               for s in shore.snapshot()["buoys"].values()), 30, "all messages")
        # publishers gone: tokens withdrawn and data old -> offline, history kept
        wait_until(lambda: all(s["state"] == "offline" and not s["alive_sensors"]
                               for s in shore.snapshot()["buoys"].values()), 30, "3 buoys offline")
    finally:
        shore.stop()
        server.join(timeout=30)
        hub.close()
    assert not server.is_alive()
    status = shore.status()
    assert set(status["buoys"]) == set(AMPLITUDES)
    damages = {}
    for buoy, log in logs.items():
        s = status["buoys"][buoy]
        assert s["counters"] == {"messages": 2 * SECONDS, "undecodable": 0, "dropped": 0,
                                 "pending": 0}
        # the live status lags by what the ordering still holds (at most the last block)
        assert 20 * SECONDS - 20 <= s["streams"]["tension"]["accepted"] <= 20 * SECONDS
        # live per-buoy pipeline, finished like a replay, equals the replay of the buoy's log
        live = Pipeline(config_for_buoy(config, buoy), state=shore.pipeline_state(buoy))
        live.flush()
        replayed, _ = run_blocks(config_for_buoy(config, buoy), iter_blocks([str(log)]))
        assert committed(live.report()) == committed(replayed.report())
        assert live.report()["samples"] == replayed.report()["samples"]
        assert live.report()["samples"]["tension"]["accepted"] == 20 * SECONDS
        damages[buoy] = committed(live.report())["conductor"]
    assert 0 < damages["north1"] < damages["north2"] < damages["south1"]


class FakeCodec:
    def decode(self, topic, payload, recv_ns):
        if payload == b"bad":
            raise ValueError("bad payload")
        buoy = buoy_of_key(topic)
        t = np.array([int(payload)], np.int64)
        return SampleBlock(buoy, "tension", t, {"tension_N": np.array([1000.0])}, recv_ns)


class FakePipeline:
    def __init__(self, config):
        self.buoy_id = config.buoy.id
        self.samples = 0

    def process(self, block):
        assert block.buoy_id == self.buoy_id
        self.samples += len(block)

    def status(self):
        return {"now_ns": 0, "load_source": "measured", "measured_tension_N": None,
                "estimated_tension_N": None, "components": {}, "streams": {}}

    def state(self):
        return {"samples": self.samples}


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def fake_shore(**kw) -> tuple[ShoreMonitor, Clock]:
    clock = Clock()
    return ShoreMonitor(measured_config(), ShoreConfig(**kw), codec=FakeCodec(),
                        make_pipeline=FakePipeline, clock=clock), clock


def test_intake_is_bounded_per_buoy_and_counts_drops():
    shore, _ = fake_shore(max_pending_blocks=5)
    accepted = [shore.offer_data("buoy/a/sensor/tension", b"%d" % i, 0) for i in range(8)]
    assert accepted == [True] * 5 + [False] * 3
    # another buoy has its own budget
    assert shore.offer_data("buoy/b/sensor/tension", b"1", 0)
    assert not shore.offer_data("not/a/sensor/key", b"1", 0)
    assert shore.drain() == 6
    st = shore.status()["buoys"]
    assert st["a"]["counters"] == {"messages": 5, "undecodable": 0, "dropped": 3, "pending": 0}
    assert shore.pipeline_state("a") == {"samples": 5}
    # once drained, the buoy may queue again
    assert shore.offer_data("buoy/a/sensor/tension", b"9", 0)


def test_max_buoys_refuses_further_buoys_and_bad_ids_are_ignored():
    shore, _ = fake_shore(max_buoys=2)
    for b in ("a", "b", "c"):
        shore.offer_data(f"buoy/{b}/sensor/tension", b"1", 0)
    shore.offer_data("buoy/bad id!/sensor/tension", b"1", 0)
    shore.drain()
    st = shore.status()
    assert sorted(st["buoys"]) == ["a", "b"] and st["refused_buoys"] == ["c"]


def test_status_states_follow_data_age_and_liveliness():
    shore, clock = fake_shore(data_age_timeout_s=5.0)
    shore.offer_alive("buoy/a/sensor/tension", True)
    shore.offer_alive("buoy/a/sensor/imu", True)
    shore.drain()
    assert shore.status()["buoys"]["a"]["state"] == "stale"  # alive, but no data yet
    shore.offer_data("buoy/a/sensor/tension", b"1", 0)
    shore.offer_data("buoy/a/sensor/tension", b"bad", 0)
    shore.drain()
    a = shore.status()["buoys"]["a"]
    assert (a["state"], a["alive_sensors"], a["counters"]["undecodable"]) == (
        "online", ["imu", "tension"], 1)
    clock.t += 5.5
    assert shore.status()["buoys"]["a"]["state"] == "stale"  # hung sensor on a live link
    shore.offer_alive("buoy/a/sensor/tension", False)
    shore.offer_alive("buoy/a/sensor/imu", False)
    shore.drain()
    assert shore.status()["buoys"]["a"]["state"] == "offline"
    assert shore.pipeline_state("a") == {"samples": 1}  # history kept while offline
    shore.offer_data("buoy/a/sensor/tension", b"2", 0)  # reappears
    shore.drain()
    assert shore.status()["buoys"]["a"]["state"] == "online"


def test_tracker_states_without_data_or_tokens():
    t = BuoyTracker("x", 0.0)
    assert t.state(1.0, 5.0) == "offline"
    t.last_arrival_mono = 0.0
    assert t.state(5.0, 5.0) == "online" and t.state(5.1, 5.0) == "offline"


def test_shore_config_rejects_bad_values():
    with pytest.raises(ValueError, match="max_pending_blocks = 0"):
        ShoreConfig(max_pending_blocks=0)
    with pytest.raises(ValueError, match="data_age_timeout_s = nan"):
        ShoreConfig(data_age_timeout_s=float("nan"))
    with pytest.raises(ValueError, match="buoy id 'a/b'"):
        ShoreConfig(name="a/b")


def test_buoy_of_key():
    assert buoy_of_key("buoy/b1/sensor/tension") == "b1"
    assert buoy_of_key("buoy/b1/monitor/status") is None
    assert buoy_of_key("buoy/b1/sensor") is None


def test_shore_command_rejects_a_bad_configuration(tmp_path):
    from monitor.cli import main

    bad = tmp_path / "bad.toml"
    bad.write_text('[buoy]\nid = "x"\n[[component]]\nname = "c"\nlay = "up"\n')
    assert main(["shore", "--config", str(bad)]) == 2
    assert main(["shore", "--max-buoys", "0"]) == 2


def test_shore_command_with_nothing_to_connect_to_is_a_clear_error(tmp_path):
    """No router or daemon on the configured endpoint: exit status 1 and a message naming
    it (was a zenoh.ZError traceback)."""
    port = free_port()
    cfg = tmp_path / "fleet.toml"
    cfg.write_text((ROOT / "monitor" / "vaps_seed004.toml").read_text()
                   + f'\n[zenoh]\nmode = "client"\nconnect = ["tcp/127.0.0.1:{port}"]\n')
    p = subprocess.run([sys.executable, "-m", "monitor.cli", "shore", "--config", str(cfg)],
                       env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 1 and "Traceback" not in p.stderr, p.stderr
    assert (f"cannot join the Zenoh network as a client of ['tcp/127.0.0.1:{port}']: is a "
            "router or `buoymon run` listening there?") in p.stderr
