"""The sensor bridge with real parts: a pseudo-terminal standing in for a serial port, loopback
TCP and UDP sockets and a growing file, fed from measured data (the Maine load cell, the
Spotter buoy's GPS fixes as NMEA sentences) with faults injected; end to end through a
bridge process and a daemon process to the damage that `buoymon import` + `replay` give."""

from __future__ import annotations

import functools
import json
import os
import queue
import socket
import subprocess
import sys
import threading
import time
import tty
from pathlib import Path

import numpy as np
import pytest
import zenoh

from daemon_harness import ENV, DaemonProcess, free_port, wait_until_state
from monitor import zenoh_io
from monitor.bridge.config import ConfigError, parse_bridge_config
from monitor.bridge.runner import Bridge
from monitor.config import load_config
from monitor.daemon_config import ZenohConfig
from monitor.sensors import SensorPublisher
from test_daemon_e2e import committed, flushed_figures, replayed_figures

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "realdata"
MAINE = SHARED / "maine_endline_loadcell" / "17348481-2018.11.30-09.58.27-15.csv"
LOC = SHARED / "spotter_clallam_1945" / "0026_LOC.CSV"
LBF = 4.4482216
pytestmark = [pytest.mark.integration, pytest.mark.skipif(not MAINE.exists(), reason="shared/realdata not beside the project")]


def maine_lines(n: int) -> list[str]:
    return MAINE.read_text().splitlines()[:n]


def nmea(body: str) -> str:
    """A sentence with its checksum (XOR of the characters between $ and *)."""
    cs = functools.reduce(lambda a, c: a ^ ord(c), body, 0)
    return f"${body}*{cs:02X}"


def spotter_sentences(n: int) -> tuple[list[str], list[tuple[int, float, float]]]:
    """RMC and GGA pairs from the Spotter's fixes (epoch s, lat deg + min*1e5, lon ...)."""
    from datetime import datetime, timezone

    out, fixes = [], []
    for row in LOC.read_text().splitlines()[1:n + 1]:
        t, lat_d, lat_m, lon_d, lon_m = row.split(",")
        ts = int(float(t))  # NMEA time to the second here
        lat_min = int(lat_m) / 1e5
        lon_min = abs(int(lon_m)) / 1e5
        lat, lon = int(lat_d) + lat_min / 60, -(abs(int(lon_d)) + lon_min / 60)
        dt = datetime.fromtimestamp(ts, timezone.utc)
        hms, dmy = dt.strftime("%H%M%S.00"), dt.strftime("%d%m%y")
        lat_s, lon_s = f"{int(lat_d):02d}{lat_min:08.5f}", f"{abs(int(lon_d)):03d}{lon_min:08.5f}"
        out.append(nmea(f"GPRMC,{hms},A,{lat_s},N,{lon_s},W,0.1,0.0,{dmy},,"))
        fixes.append((ts * 10**9, lat, lon))
    return out, fixes


class Collector:
    """A Zenoh subscriber (another session) keeping every block the bridge publishes."""

    def __init__(self, port: int) -> None:
        self.session = zenoh_io.open_session(ZenohConfig(mode="peer",
                                                         listen=(f"tcp/127.0.0.1:{port}",)))
        self.q: "queue.SimpleQueue[bytes]" = queue.SimpleQueue()
        self.status: list[dict] = []
        self.sub = self.session.declare_subscriber(
            "buoy/t1/sensor/**", lambda s: self.q.put((str(s.key_expr), s.payload.to_bytes())))
        self.st = self.session.declare_subscriber(
            "buoy/t1/bridge/status", lambda s: self.status.append(json.loads(
                s.payload.to_bytes())))

    def blocks(self) -> list:
        codec = zenoh_io.default_codec()
        out = []
        while not self.q.empty():
            key, payload = self.q.get()
            out.append(codec.decode(key, payload, 0))
        return out

    def close(self) -> None:
        self.sub.undeclare()
        self.st.undeclare()
        self.session.close()


def run_bridge(cfg_raw: dict, feed, port: int, settle) -> tuple[Bridge, Collector]:
    """Run a bridge in this process (real transports, real publisher) while ``feed()`` writes
    to its instruments; stop once ``settle(bridge)`` holds."""
    col = Collector(port)
    cfg = parse_bridge_config(cfg_raw)
    pub = SensorPublisher.connect(cfg.buoy_id, [f"tcp/127.0.0.1:{port}"])
    bridge = Bridge(cfg, pub)
    th = threading.Thread(target=feed, daemon=True)
    t0 = time.monotonic()
    deadline = t0 + 60
    started = [False]

    def until() -> bool:  # the readers have had a second to bind, listen and open
        if not started[0] and time.monotonic() > t0 + 1.0:
            started[0] = True
            th.start()
        return (started[0] and not th.is_alive() and settle(bridge)) or time.monotonic() > deadline

    try:
        bridge.run(until)
    finally:
        pub.close()
    time.sleep(0.5)
    return bridge, col


def test_nmea_over_udp_tcp_and_a_growing_file_with_faults(tmp_path):
    sentences, fixes = spotter_sentences(60)
    udp_port, tcp_port = free_port(), free_port()
    path = tmp_path / "gnss.log"
    path.write_bytes(b"")
    bad = [nmea("GPRMC,000000.00,V,,,,,,,010101,,"), sentences[3][:-2] + "00",  # no fix, bad cs
           "$GPRMC,garbled", "\x00\xff\xfe binary", sentences[5][:20]]

    def feed() -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as u, \
                socket.create_connection(("127.0.0.1", tcp_port)) as tc, open(path, "ab") as f:
            for k, s in enumerate(sentences):
                line = (s + "\r\n").encode()
                u.sendto(line, ("127.0.0.1", udp_port))
                tc.sendall(line[:10])  # split across TCP segments
                time.sleep(0.001)
                tc.sendall(line[10:])
                f.write(line)
                f.flush()
                if k in (10, 30):
                    junk = (bad[k % len(bad)] + "\r\n").encode("latin-1")
                    u.sendto(junk, ("127.0.0.1", udp_port))
                    tc.sendall(junk)
                    f.write(junk)
                    f.flush()
                if k == 40:  # the logger rotates its file: a new one, the rest goes there
                    os.rename(path, tmp_path / "gnss.log.1")
                    f.close()
                    f = open(path, "ab")
            f.close()

    # a TCP server source listens; the test's instrument connects to it
    port = free_port()
    raw = {"buoy": {"id": "t1"}, "bridge": {"connect": [f"tcp/127.0.0.1:{port}"],
                                            "status_interval_s": 0.2},
           "source": [
               {"name": "gps_udp", "sensor": "gnss", "transport": "udp", "port": udp_port},
               {"name": "gps_tcp", "sensor": "gnss", "transport": "tcp_server",
                "port": tcp_port},
               {"name": "gps_file", "sensor": "gnss", "transport": "file",
                "path": str(path)}]}

    def settle(b: Bridge) -> bool:
        return all(s.samples + sum(s.rejected.values()) >= 60 for s in b.sources)

    bridge, col = run_bridge(raw, feed, port, settle)
    try:
        by = {s.cfg.name: s for s in bridge.sources}
        for s in by.values():
            assert s.samples == 60, (s.cfg.name, s.rejected)
            assert s.time_source == "instrument"
        assert by["gps_file"].events["rotated"] == 1
        # every published sample is a real fix; faults are counted, never published
        blocks = col.blocks()
        lat = np.concatenate([b.fields["lat_deg"] for b in blocks])
        t = np.concatenate([b.t_ns for b in blocks])
        exp = {ts: (la, lo) for ts, la, lo in fixes}
        assert len(t) == 3 * 60 and set(t.tolist()) == set(exp)
        for tt, la in zip(t.tolist(), lat.tolist()):
            assert la == pytest.approx(exp[tt][0], abs=1e-7)
        rej = by["gps_udp"].rejected
        assert sum(rej.values()) == 2 and set(rej) <= {"no_fix", "checksum", "garbled"}
        assert col.status and set(col.status[-1]["sources"]) == set(by)
    finally:
        col.close()


def test_bad_config_is_refused_naming_key_and_value():
    with pytest.raises(ConfigError, match=r"source\[0\].columns"):
        parse_bridge_config({"buoy": {"id": "b"}, "source": [
            {"name": "x", "sensor": "tension", "transport": "stdin", "columns": {"t": 1}}]})
    with pytest.raises(ConfigError, match=r"source\[0\].device"):
        parse_bridge_config({"buoy": {"id": "b"}, "source": [
            {"name": "x", "sensor": "gnss", "transport": "serial"}]})
    with pytest.raises(ConfigError, match="gnss stream only"):
        parse_bridge_config({"buoy": {"id": "b"}, "source": [
            {"name": "x", "sensor": "tension", "transport": "stdin", "format": "nmea"}]})


def test_load_cell_on_a_pty_through_bridge_and_daemon_equals_import_and_replay(tmp_path):
    """Maine load cell lines on a pseudo-terminal (the serial port), with baud-rate garbage,
    a cut line, wrong column counts, non-numeric cells and an unplug/replug (the device
    link re-pointed to a new pty): bridge process -> daemon process -> the same committed
    damage as `buoymon import` + `buoymon replay` of the same samples."""
    lines = maine_lines(2400)
    port = free_port()
    shipped = (REPO / "monitor" / "vaps_seed004.toml").read_text()
    daemon_cfg = tmp_path / "buoymon.toml"
    daemon_cfg.write_text(shipped.replace('id = "vaps"', 'id = "maine"', 1)
                          + f'\n[zenoh]\nlisten = ["tcp/127.0.0.1:{port}"]\n'
                            f'status_interval_s = 0.5\n[state]\npath = "{tmp_path / "st.sqlite"}"\n'
                            f'checkpoint_interval_s = 1.0\n[metrics]\nport = {free_port()}\n')
    device = tmp_path / "ttyLoadCell"
    masters = []

    def plug() -> int:
        master, slave = os.openpty()
        tty.setraw(slave)
        if device.is_symlink():
            device.unlink()
        device.symlink_to(os.ttyname(slave))
        masters.append((master, slave))
        return master

    master = plug()
    bridge_cfg = tmp_path / "bridge.toml"
    bridge_cfg.write_text(
        f'[buoy]\nid = "maine"\n[bridge]\nconnect = ["tcp/127.0.0.1:{port}"]\n'
        'status_interval_s = 0.5\n[[source]]\nname = "loadcell"\nsensor = "tension"\n'
        f'transport = "serial"\ndevice = "{device}"\nbaud = 115200\nreconnect_s = 0.2\n'
        'columns = { tension_N = 2 }\n'
        f'scale = {{ tension_N = {LBF} }}\ntime_column = 0\n'
        'time_format = "%Y-%m-%d-%H:%M:%S.%f"\n')
    d = DaemonProcess([sys.executable, "-m", "monitor.cli", "--log-level", "warning", "run",
                       "--config", str(daemon_cfg)], tmp_path)
    d.wait_for("READY=1", timeout=120)
    b = subprocess.Popen([sys.executable, "-m", "monitor.cli", "--log-level", "warning",
                          "bridge", "--config", str(bridge_cfg)], env=ENV, cwd=tmp_path,
                         stderr=subprocess.PIPE, text=True)
    faults = {100: b"\xf0\x0f\xaa\x55\xff garbage at the wrong baud rate\n",
              300: b"2018-11-30-10:00:00.000, 1.0\n",  # too few columns
              500: b"2018-11-30-10:01:00.000, 1.0,abc, 0.1\n"}  # non-numeric load
    try:
        time.sleep(2.0)  # the bridge opens the port
        for k, line in enumerate(lines):
            if k in faults:
                os.write(master, faults[k])
            if k == 1200:  # unplugged mid-line, plugged back on a new tty
                os.write(master, line.encode()[:15])
                time.sleep(0.3)
                os.close(master)
                master = plug()
                time.sleep(1.0)  # the bridge reopens the device
                os.write(master, b"9.30-10:5")  # the tail of a line it joined mid-way
            os.write(master, (line + "\n").encode())
            if k % 200 == 0:
                time.sleep(0.05)
        # a cut line before the replug is lost at the instrument, not by the bridge
        expected_lines = [ln for k, ln in enumerate(lines) if k != 1200]
        n = len(expected_lines)
        from monitor.bridge.formats import instrument_time
        t_last = instrument_time(expected_lines[-1].split(",")[0], "%Y-%m-%d-%H:%M:%S.%f")
        horizon = int(11e9)  # the live ordering horizon (10 s) holds the newest samples back

        def arrived(s: dict) -> bool:
            return s["status"]["streams"].get("tension", {}).get("last_t_ns", 0) \
                >= t_last - horizon

        st = wait_until_state(port, arrived, buoy="maine", timeout=120)
    finally:
        b.terminate()
        _, err = b.communicate(timeout=30)
        assert d.terminate() == 0
        for m, s in masters:
            for fd in (m, s):
                try:
                    os.close(fd)
                except OSError:
                    pass
    assert b.returncode == 0, err
    # the same samples through `buoymon import` + `buoymon replay`
    csv = tmp_path / "maine.csv"
    rows = ["time,tension_N"]
    for ln in expected_lines:
        c = ln.split(",")
        ts = c[0].strip()
        iso = f"{ts[:10]}T{ts[11:]}Z"
        rows.append(f"{iso},{float(c[2]) * LBF + 0.0!r}")
    csv.write_text("\n".join(rows) + "\n")
    log = tmp_path / "maine.mcap"
    out = subprocess.run([sys.executable, "-m", "monitor.cli", "import", str(csv), "-o", str(log),
                          "--buoy-id", "maine"], env=ENV, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    config = load_config(daemon_cfg)
    from monitor.checkpoint import CheckpointStore
    store = CheckpointStore(tmp_path / "st.sqlite")
    final = store.load().state["pipeline"]
    store.close()
    live = flushed_figures(config, final)
    replayed = replayed_figures(config, [log])
    assert st["status"]["streams"]["tension"]["accepted"] > 0.95 * n
    assert live["samples"]["tension"] == replayed["samples"]["tension"]
    assert committed(live) == committed(replayed)
