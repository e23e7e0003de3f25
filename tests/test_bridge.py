"""The sensor bridge with real parts: a pseudo-terminal standing in for a serial port, loopback
TCP and UDP sockets and a growing file, fed from measured data (the Maine load cell, the
Spotter buoy's GPS fixes as NMEA sentences) with faults injected; end to end through a
bridge process and a daemon process to the damage that `buoymon import` + `replay` give."""

from __future__ import annotations

import functools
import json
import math
import os
import queue
import re
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
from monitor.blocks import SampleBlock
from monitor.bridge.config import parse_bridge_config
from monitor.bridge.runner import Bridge
from monitor.config import load_config
from monitor.daemon_config import ZenohConfig
from monitor.schema import ConfigError
from monitor.sensors import SensorPublisher
from test_daemon_e2e import committed, flushed_figures, replayed_figures

REPO = Path(__file__).resolve().parents[1]
# ../shared/realdata beside the repository (or beside a parent: a worktree)
SHARED = next((p / "shared" / "realdata" for p in REPO.parents
               if (p / "shared" / "realdata").is_dir()), REPO.parent / "shared" / "realdata")
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
    fault_at = {10: 0, 20: 1, 30: 2, 35: 3, 50: 4}  # sentence index -> fault after it

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
                if k in fault_at:
                    junk = (bad[fault_at[k]] + "\r\n").encode("latin-1")
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
        return all(s.samples + sum(s.rejected.values()) >= 65 for s in b.sources)

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
        # a sentence cut short or garbled loses its checksum: "checksum" (required)
        assert rej == {"no_fix": 1, "checksum": 3, "garbled": 1}
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
    # a bad endpoint was accepted; the bridge then failed when its session opened
    for endpoint, message in (("tcp/127.0.0.1:99999", "port 99999 is not in 0..65535"),
                              ("127.0.0.1:7447", "is not of the form '<proto>/<address>'")):
        with pytest.raises(ConfigError, match=rf"bridge\.connect = .*{re.escape(message)}"):
            parse_bridge_config({"buoy": {"id": "b"}, "bridge": {"connect": [endpoint]},
                                 "source": [{"name": "x", "sensor": "tension",
                                             "transport": "stdin", "columns": {"tension_N": 1}}]})
    with pytest.raises(ConfigError, match="gnss stream only"):
        parse_bridge_config({"buoy": {"id": "b"}, "source": [
            {"name": "x", "sensor": "tension", "transport": "stdin", "format": "nmea"}]})
    # these were accepted, then every line was NaN, constant or rejected as bad_time
    for key, value, message in (("scale", {"tension_N": math.nan}, "scale"),
                                ("scale", {"tension_N": 0.0}, "scale"),
                                ("offset", {"tension_N": math.inf}, "offset"),
                                ("time_format", "%Y-%m-%d %Q", "time_format")):
        with pytest.raises(ConfigError, match=rf"source\[0\]\.{message} = "):
            parse_bridge_config({"buoy": {"id": "b"}, "source": [
                {"name": "x", "sensor": "tension", "transport": "stdin",
                 "columns": {"tension_N": 1}, key: value}]})
    # the README's load cell format is fine
    parse_bridge_config({"buoy": {"id": "b"}, "source": [
        {"name": "x", "sensor": "tension", "transport": "stdin", "columns": {"tension_N": 1},
         "time_column": 0, "time_format": "%Y-%m-%d-%H:%M:%S.%f"}]})


def test_bridge_quanta_set_the_resolution_on_the_wire():
    """[bridge] quanta: the bridge's codec stores a field to that quantum (within half of
    it), the others to the defaults; a bad quantum is refused naming the key."""
    src = [{"name": "x", "sensor": "tension", "transport": "stdin",
            "columns": {"tension_N": 1}}]
    cfg = parse_bridge_config({"buoy": {"id": "b"}, "bridge": {"quanta": {"tension_N": 2.5}},
                               "source": src})
    assert cfg.quanta == {"tension_N": 2.5}
    zc = zenoh_io.ProtobufCodec(cfg.quanta)
    v = np.array([1000.0, 1001.2, 1003.8, 998.7])
    block = SampleBlock("b", "tension", 10**18 + np.arange(4, dtype=np.int64) * 10**8,
                        {"tension_N": v})
    back = zc.decode("buoy/b/sensor/tension", zc.encode(block), 0).fields["tension_N"]
    assert back.tolist() == [1000.0, 1000.0, 1005.0, 997.5]  # nearest multiples of 2.5 N
    for bad in ({"tension_N": 0}, {"tension": 1.0}, {"tension_N": "x"}, [1]):
        with pytest.raises(ConfigError, match="bridge.quanta"):
            parse_bridge_config({"buoy": {"id": "b"}, "bridge": {"quanta": bad}, "source": src})


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
    stopping = False
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
        # the bridge's counters reach the daemon's status: every line read, each fault by
        # reason, the unplug. The line cut by it is no line; the tail written 1 s after the
        # replug is a line (a bad time) if the bridge had reopened the port and seen it idle
        # by then, else the fragment before the first newline (partial): timing under load
        src = wait_until_state(port, lambda s: s["status"].get("bridge", {}).get(
            "sources", {}).get("loadcell", {}).get("samples") == n,
            buoy="maine", timeout=30)["status"]["bridge"]["sources"]["loadcell"]
        tail_read = src["lines"] - n - len(faults)
        assert tail_read in (0, 1)
        assert src["rejected"] == {"garbled": 1, "columns": 1, "non_numeric": 1,
                                   **({"bad_time": 1} if tail_read else {})}
        assert src["events"]["partial_line"] == 2 - tail_read
        assert src["events"]["disconnected"] >= 1
        # a bridge that stops says so in its last status, at once
        b.terminate()
        stopping = True
        t0 = time.monotonic()
        wait_until_state(port, lambda s: s["status"]["bridge"]["sources"]["loadcell"]["state"]
                         == "stopped", buoy="maine", timeout=30)
        assert time.monotonic() - t0 < 5.0
    finally:
        if b.poll() is None and not stopping:  # one SIGTERM, as systemd sends
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
    config = load_config(daemon_cfg)
    live = checkpointed_figures(config, tmp_path / "st.sqlite")
    replayed = import_and_replay(tmp_path, expected_lines, config)
    assert st["status"]["streams"]["tension"]["accepted"] > 0.95 * n
    assert live["samples"]["tension"] == replayed["samples"]["tension"]
    assert committed(live) == committed(replayed)


def checkpointed_figures(config, state_path: Path) -> dict:
    """The figures of a stopped daemon's last checkpoint, its ordering buffer flushed."""
    from monitor.checkpoint import CheckpointStore

    store = CheckpointStore(state_path)
    final = store.load().state["pipeline"]
    store.close()
    return flushed_figures(config, final)


def import_and_replay(tmp_path: Path, lines: list[str], config) -> dict:
    """The figures of Maine load-cell ``lines`` through `buoymon import` + `buoymon replay`."""
    csv = tmp_path / "maine.csv"
    rows = ["time,tension_N"]
    for ln in lines:
        c = ln.split(",")
        ts = c[0].strip()
        iso = f"{ts[:10]}T{ts[11:]}Z"
        rows.append(f"{iso},{float(c[2]) * LBF + 0.0!r}")
    csv.write_text("\n".join(rows) + "\n")
    log = tmp_path / "maine.mcap"
    out = subprocess.run([sys.executable, "-m", "monitor.cli", "import", str(csv), "-o", str(log),
                          "--buoy-id", "maine"], env=ENV, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return replayed_figures(config, [log])


def test_nmea_gga_and_rmc_of_one_fix_give_one_sample():
    """A receiver sends GGA and RMC for each fix (and GSA, VTG...): one sample per fix, at
    the RMC's date; the repeats and other sentences are counted, not published."""
    from monitor.bridge.formats import Rejected, parser

    cfg = parse_bridge_config({"buoy": {"id": "b"}, "source": [
        {"name": "gps", "sensor": "gnss", "transport": "stdin"}]}).sources[0]
    parse = parser(cfg)
    rmc, fixes = spotter_sentences(3)
    out, reasons = [], []
    for s, (ts, lat, lon) in zip(rmc, fixes):
        f = s.split(",")  # the same fix as GGA: hhmmss, lat, N, lon, W, quality 1
        for line in (s, nmea(f"GPGGA,{f[1]},{f[3]},N,{f[5]},W,1,08,0.9,1.0,M,-20.0,M,,"),
                     nmea("GPVTG,0.0,T,,M,0.1,N,0.2,K,A")):
            try:
                out.append(parse(line, 0))
            except Rejected as exc:
                reasons.append(str(exc))
    assert [t for t, _, _ in out] == [ts for ts, _, _ in fixes]
    for (_, (la, lo), src), (_, lat, lon) in zip(out, fixes):  # lat_deg, lon_deg
        assert la == pytest.approx(lat, abs=1e-7) and src == "instrument"
        assert lo == pytest.approx(lon, abs=1e-7)
    assert sorted(reasons) == ["other_sentence"] * 3 + ["repeat_fix"] * 3


def test_tcp_client_reconnects_and_a_dead_address_does_not_hold_the_others(tmp_path):
    """A TCP client source connects to the instrument (a server here), which drops the
    connection mid-line and comes back: disconnected, the cut line dropped, reconnected
    within reconnect_s; a new connection may start mid-line (a serial-to-Ethernet converter
    streams on), so its first line is dropped too. A second source pointing at a closed port keeps failing (counted)
    without holding the first."""
    lines = maine_lines(300)
    srv = socket.create_server(("127.0.0.1", 0))
    iport, port = srv.getsockname()[1], free_port()
    raw = {"buoy": {"id": "t1"}, "bridge": {"connect": [f"tcp/127.0.0.1:{port}"]},
           "source": [
               {"name": "cell", "sensor": "tension", "transport": "tcp_client",
                "port": iport, "reconnect_s": 0.2, "columns": {"tension_N": 2},
                "time_column": 0, "time_format": "%Y-%m-%d-%H:%M:%S.%f"},
               {"name": "nobody", "sensor": "gnss", "transport": "tcp_client",
                "port": free_port(), "reconnect_s": 0.2}]}

    def feed() -> None:
        with srv:
            conn, _ = srv.accept()
            conn.sendall("".join(ln + "\n" for ln in lines[:150]).encode())
            conn.sendall(lines[150].encode()[:12])  # cut by the drop
            time.sleep(0.2)
            conn.close()
            conn, _ = srv.accept()  # the bridge connects again
            with conn:
                conn.sendall("".join(ln + "\n" for ln in lines[151:]).encode())
                time.sleep(0.5)

    bridge, col = run_bridge(raw, feed, port, lambda b: b.sources[0].samples >= 298)
    try:
        cell, nobody = bridge.sources
        assert cell.samples == 298 and not cell.rejected
        # the drop, and the instrument's close at the end
        assert cell.events["disconnected"] == 2 and cell.events["partial_line"] == 2
        assert nobody.events["disconnected"] >= 3 and nobody.lines == 0
        got = np.concatenate([b.fields["tension_N"] for b in col.blocks()])
        exp = [float(ln.split(",")[2]) for k, ln in enumerate(lines) if k not in (150, 151)]
        assert got.tolist() == [v for v in exp]  # scale 1: the lbf as sent
    finally:
        col.close()


def test_stdin_csv_through_a_bridge_process(tmp_path):
    """`producer | buoymon bridge`: buoymon import's CSV columns on stdin; the last line
    without a newline counts; the bridge exits at the end of its input."""
    port = free_port()
    col = Collector(port)
    cfg = tmp_path / "b.toml"
    cfg.write_text(f'[buoy]\nid = "t1"\n[bridge]\nconnect = ["tcp/127.0.0.1:{port}"]\n'
                   '[[source]]\nname = "csv"\nsensor = "tension"\ntransport = "stdin"\n'
                   'format = "csv"\n')
    rows = ["time_s,tension_N"] + [f"{1_750_000_000 + k * 0.05:.2f},{1000.0 + k}"
                                   for k in range(100)]
    rows.insert(40, "1750000001.00,not a number")
    try:
        p = subprocess.Popen([sys.executable, "-m", "monitor.cli", "--log-level", "warning",
                              "bridge", "--config", str(cfg)], env=ENV, stdin=subprocess.PIPE,
                             stderr=subprocess.PIPE)
        time.sleep(1.5)  # connected to the collector
        p.stdin.write("\n".join(rows).encode())  # no newline at the end
        p.stdin.close()
        deadline = time.monotonic() + 30
        got = []
        while time.monotonic() < deadline and sum(len(b) for b in got) < 100:
            time.sleep(0.2)
            got.extend(col.blocks())
        p.terminate()
        p.wait(30)
    finally:
        col.close()
    t = np.concatenate([b.t_ns for b in got])
    v = np.concatenate([b.fields["tension_N"] for b in got])
    assert v.tolist() == [1000.0 + k for k in range(100)]
    assert t[0] == 1_750_000_000 * 10**9 and t[-1] == 1_750_000_004_950_000_000
    assert col.status[-1]["sources"]["csv"]["rejected"] == {"non_numeric": 1}


@pytest.mark.parametrize("cell, ns", [
    ("1750000012.345", 1_750_000_012_345_000_000), (" 1750000012 ", 1_750_000_012 * 10**9),
    ("1750000012.123456789123", 1_750_000_012_123_456_789),  # beyond ns: cut, not rounded
    ("-1.5", None), ("1_000", None), ("+5", None), ("1e9", None), ("1750000012.", None),
    ("", None)])
def test_unix_time_cells_are_exact_or_rejected(cell, ns):
    from monitor.bridge.formats import Rejected, instrument_time

    if ns is None:
        with pytest.raises(Rejected, match="bad_time"):
            instrument_time(cell, "unix")
    else:
        assert instrument_time(cell, "unix") == ns


def _listening(pid: int) -> list[tuple[str, str, int]]:
    """(protocol, local address, port) of every socket the process listens or binds on (TCP
    in LISTEN, UDP bound), from /proc: its socket inodes matched in /proc/net/*."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    out = []
    for proto in ("tcp", "udp", "tcp6", "udp6"):
        for row in Path(f"/proc/net/{proto}").read_text().splitlines()[1:]:
            cells = row.split()
            local, state, inode = cells[1], cells[3], cells[9]
            if inode in inodes and (proto.startswith("udp") or state == "0A"):
                addr, port = local.split(":")
                ip = (socket.inet_ntop(socket.AF_INET, bytes.fromhex(addr)[::-1])
                      if len(addr) == 8 else "v6:" + addr)
                out.append((proto, ip, int(port, 16)))
    return out


def test_the_bridge_listens_on_loopback_only_and_only_where_configured(tmp_path):
    """The bridge process's Zenoh session listens on nothing (it connects out); its TCP
    server and UDP sources bind 127.0.0.1 by default, on their configured ports."""
    port, tport, uport = free_port(), free_port(), free_port()
    col = Collector(port)
    cfg = tmp_path / "b.toml"
    cfg.write_text(f'[buoy]\nid = "t1"\n[bridge]\nconnect = ["tcp/127.0.0.1:{port}"]\n'
                   f'[[source]]\nname = "a"\nsensor = "gnss"\ntransport = "tcp_server"\n'
                   f'port = {tport}\n[[source]]\nname = "b"\nsensor = "gnss"\n'
                   f'transport = "udp"\nport = {uport}\n')
    p = subprocess.Popen([sys.executable, "-m", "monitor.cli", "--log-level", "warning",
                          "bridge", "--config", str(cfg)], env=ENV, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 30
        while not col.status and time.monotonic() < deadline:  # running and connected
            time.sleep(0.1)
        got = sorted(_listening(p.pid))
    finally:
        p.terminate()
        p.wait(30)
        col.close()
    assert got == sorted([("tcp", "127.0.0.1", tport), ("udp", "127.0.0.1", uport)])


def test_followed_files_truncated_in_place_and_started_at_their_end(tmp_path):
    """A logger that truncates its file in place (logrotate's copytruncate): read again from
    the start, counted as truncated; a source with from_start = false skips what the file
    held before the bridge started; 5000 bytes without a newline are overlong, dropped."""
    lines = maine_lines(200)
    a, b = tmp_path / "a.log", tmp_path / "b.log"
    a.write_text("")
    b.write_text("".join(ln + "\n" for ln in lines[:50]))  # before the bridge: skipped
    port = free_port()
    src = {"sensor": "tension", "transport": "file", "columns": {"tension_N": 2},
           "time_column": 0, "time_format": "%Y-%m-%d-%H:%M:%S.%f"}
    raw = {"buoy": {"id": "t1"}, "bridge": {"connect": [f"tcp/127.0.0.1:{port}"]},
           "source": [{**src, "name": "a", "path": str(a)},
                      {**src, "name": "b", "path": str(b), "from_start": False}]}

    def feed() -> None:
        with open(a, "ab") as fa, open(b, "ab") as fb:
            for k, ln in enumerate(lines[50:]):
                if k == 75:  # once the bridge has read it all (copytruncate loses the rest)
                    time.sleep(1.0)
                    fa.truncate(0)  # copytruncate: the same file, emptied
                    fa.seek(0)
                    time.sleep(0.3)
                if k == 100:
                    fb.write(b"x" * 5000)  # no newline: a runaway line
                    fb.write(b"\n")
                fa.write((ln + "\n").encode())
                fb.write((ln + "\n").encode())
                fa.flush()
                fb.flush()
                if k % 25 == 0:
                    time.sleep(0.1)

    bridge, col = run_bridge(raw, feed, port,
                             lambda br: all(s.samples >= 149 for s in br.sources))
    try:
        sa, sb = bridge.sources
        assert sa.samples == 150 and sa.events == {"truncated": 1} and not sa.rejected
        assert sb.samples == 150 and not sb.rejected and sb.events == {"overlong": 1}
        by = {}
        for blk in col.blocks():
            by.setdefault(blk.sensor, []).append(blk)
        got = np.concatenate([blk.fields["tension_N"] for blk in by["tension"]])
        exp = [float(ln.split(",")[2]) for ln in lines[50:]]
        assert sorted(got.tolist()) == sorted(exp * 2)
    finally:
        col.close()


def test_a_source_whose_every_line_is_rejected_is_rejecting_and_alerted(tmp_path):
    """A load cell on a pty sending lines that give no sample (here non-numeric loads, as a
    wrong column map or baud rate does): once ``stall_s`` passes the bridge process reports
    ``rejecting`` (was "reading" for ever: lines kept coming) and the daemon's live rule fires
    on it, naming the reasons; the Maine load cell's own lines then bring it back to reading."""
    from monitor.alerts.live import LiveAlerts, LiveConfig  # noqa: PLC0415
    from monitor.metrics import BRIDGE_STATES  # noqa: PLC0415

    port = free_port()
    col = Collector(port)
    master, slave = os.openpty()
    tty.setraw(slave)
    cfg = tmp_path / "b.toml"
    cfg.write_text(f'[buoy]\nid = "t1"\n[bridge]\nconnect = ["tcp/127.0.0.1:{port}"]\n'
                   'status_interval_s = 0.2\n[[source]]\nname = "lc"\nsensor = "tension"\n'
                   f'transport = "serial"\ndevice = "{os.ttyname(slave)}"\nstall_s = 1.0\n'
                   f'columns = {{ tension_N = 2 }}\nscale = {{ tension_N = {LBF} }}\n')
    p = subprocess.Popen([sys.executable, "-m", "monitor.cli", "--log-level", "warning",
                          "bridge", "--config", str(cfg)], env=ENV, stderr=subprocess.PIPE)

    def state_after(lines: list[str], pause: float) -> dict:
        for line in lines:
            os.write(master, line.encode() + b"\n")
            time.sleep(pause)
        return col.status[-1]["sources"]["lc"]

    try:
        time.sleep(1.5)  # connected to the collector
        bad = state_after(["2018-11-30-09:58:27.538, 0.35,4O, 0.02"] * 40, 0.05)
        good = state_after(maine_lines(20), 0.05)
        time.sleep(0.5)
        good = col.status[-1]["sources"]["lc"]
    finally:
        p.terminate()
        p.wait(30)
        col.close()
        os.close(master)
        os.close(slave)
    assert bad["state"] == "rejecting" and bad["samples"] == 0
    assert bad["rejected"] == {"non_numeric": bad["lines"]} and bad["lines"] >= 30
    assert good["state"] == "reading" and good["samples"] == 20
    assert "rejecting" in BRIDGE_STATES
    live = LiveAlerts("t1", LiveConfig())
    (rec,) = live.evaluate({"bridge": {"sources": {"lc": bad}}}, time.time_ns())
    assert (rec.rule, rec.component, rec.event) == ("bridge_source", "lc", "fire")
    assert rec.summary.startswith("bridge source lc (serial -> tension): rejecting every line "
                                  "(non_numeric), last line 0 s ago"), rec.summary
    (rec,) = live.evaluate({"bridge": {"sources": {"lc": good}}}, time.time_ns())
    assert rec.event == "clear"
