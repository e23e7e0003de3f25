"""Benchmark of the sensor bridge (`buoymon bridge`), a real bridge process on loopback.

1. Real time: 5 streams at 1 kHz each for ``--seconds`` (tension and motion over UDP, imu and
   gnss over TCP, waves on a pseudo-terminal as a serial port; delimited lines with the
   instrument's time), sent in 2-ms batches. Prints the lines per second the bridge read, its
   CPU (% of one core, from /proc, after a warm-up) and CPU per 1000 lines, and the latency of
   a block at a subscriber (the stand-in daemon, a Zenoh peer in this process): from the send
   of the line that closes the block (the first sample past ``block_s``: the bridge's own
   delay) and from the send of the block's last sample (that plus the wait for the next one).
2. Flat out: ``--burst`` lines on one TCP connection as fast as the bridge takes them
   (TCP flow control: nothing is lost), timed until the block holding the last one arrives
   (a line 1 s later closes it): lines per second and CPU per 1000 lines at saturation.
Also the bridge's resident memory (after part 1) and the load average (other work on the
machine shares its 2 cores: compare runs interleaved, and CPU per 1000 lines).

Issue 16's targets: 5 x 1 kHz under 5 % of one core, under 5 ms of latency per block.

Measured 2026-11-25 on the 2-core development machine (AMD EPYC), 16:48-16:52 UTC, load
average 2.8-3.9 (other sessions' tests): three 15-s runs of this version interleaved with
three of the version before it (b85378b), the same script, from left to right in time.

=============================  ===========================  ===========================
                               before (b85378b: gathers     shipped
                               20 ms, parses line by line,
                               numba codec)
=============================  ===========================  ===========================
5 x 1 kHz: bridge CPU          4.87, 4.40, 4.33 %           2.87, 2.53, 2.67 %
  per 1000 lines               9.7, 8.8, 8.7 ms             5.7, 5.1, 5.3 ms
  latency, closing line p50    2.27, 1.74, 2.24 ms          2.14, 1.25, 1.85 ms
                        p99    8.3, 4.0, 6.8 ms             19.0, 7.4, 7.1 ms
  latency, last sample p50     4.32, 3.79, 4.28 ms          4.29, 3.25, 4.31 ms
flat out, one TCP source       304k, 319k, 256k lines/s     577k, 652k, 644k lines/s
  CPU per 1000 lines           2.9, 2.9, 3.3 ms             1.6, 1.4, 1.4 ms
bridge resident memory         186 MB                       73 MB
=============================  ===========================  ===========================

An earlier interleaved set (16:41-16:45, load 1.6-3.8, the shipped version but for the
serial burst threshold): before 4.60, 5.87, 5.80 %, after 3.20, 2.80, 3.33 %. Before this
work, on a quiet machine (14:10-14:31, load 0.4-1.1), the version before measured 5.5-6.2 %
and, timed by the status's line count instead of the last block, 154-160k lines/s flat out.

Where the CPU went (thread-CPU cProfile, perf and a/b runs of one knob at a time): at 20 ms
gathers a wake-up with its small reads cost ~50 us, about as much as the lines it brought
(~3 us each line by one); 2,500 immediate reads a second cost 14 % of a core. So: (1) a
read's lines are parsed at once by builtins over all its cells (bulk parser,
monitor.bridge.formats; a read with any faulty line goes line by line), UDP datagrams of one
wake-up are one piece, the line splitter has no Python loop for a clean read, and a block's
values are kept as a list per field (rows of tuples cost as much again at the flush); (2)
reads gather up to 100 ms between blocks, immediate only from 10 ms before the closing line
is due by its sensor time and the source's measured lag (gathering 50 or 100 ms with the old
50-ms window measured 2.7 and 2.4 %); (3) no pause in a flood (read rate), which gives the
flat-out rate back. The status every 0.2 s (this benchmark's; 1 s by default) cost ~0.5 %
(one a/b pair).
Not re-measured: idle (0.4 % before). Latency split (one 15-s run at 16:59, load ~2, the
bridge printing its publish times on the shared monotonic clock): median 1.9 ms = 0.75 ms
from the send of the closing line to the flush + 0.74 ms to encode (numpy: ~0.3 ms a 3-field
block of 1000 samples, where numba took 0.02 ms) and put + 0.04 ms to the subscriber; the
worst block (23.6 ms) was read 22.6 ms after its closing line was sent: a wake-up late on the
loaded machine (the closing line was read in the immediate window in every block traced).

Usage: PYTHONPATH=. python bench/bench_bridge.py [--seconds 20] [--burst 200000]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
import tty
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from monitor import zenoh_io  # noqa: E402
from monitor.daemon_config import ZenohConfig  # noqa: E402

RATE_HZ = 1000
BATCH = 2  # lines per write: one write every 2 ms
BUOY = "bench"
T0_S = 1_750_000_000
BURST_K0 = 10**8  # the burst's sensor times start 10^5 s after the real-time streams
# source name -> (stream, transport, number of fields)
SOURCES = {"tension": ("tension", "udp", 1), "motion": ("motion", "udp", 3),
           "imu": ("imu", "tcp_server", 3), "gnss": ("gnss", "tcp_server", 2),
           "waves": ("waves", "serial", 2)}
FIELDS = {"tension": ["tension_N"], "motion": ["heave_m", "surge_m", "sway_m"],
          "imu": ["accel_x_mps2", "accel_y_mps2", "accel_z_mps2"],
          "gnss": ["lat_deg", "lon_deg"], "waves": ["hs_m", "tp_s"]}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def rss_mb(pid: int) -> float:
    for row in Path(f"/proc/{pid}/status").read_text().splitlines():
        if row.startswith("VmRSS:"):
            return int(row.split()[1]) / 1024
    return float("nan")


def line(k: int, n_fields: int) -> bytes:
    t = f"{T0_S + k // 1000}.{k % 1000:03d}"
    vals = ",".join(f"{0.001 * (k % 997) + i:.3f}" for i in range(n_fields))
    return f"{t},{vals}\n".encode()


def config(path: Path, zport: int, ports: dict[str, int], tty_path: str, burst_port: int) -> None:
    parts = [f'[buoy]\nid = "{BUOY}"\n[bridge]\nconnect = ["tcp/127.0.0.1:{zport}"]\n'
             'status_interval_s = 0.2\n']
    for name, (stream, transport, _) in SOURCES.items():
        where = (f'device = "{tty_path}"\nbaud = 921600\n' if transport == "serial"
                 else f"port = {ports[name]}\n")
        cols = ", ".join(f"{f} = {i + 1}" for i, f in enumerate(FIELDS[stream]))
        parts.append(f'[[source]]\nname = "{name}"\nsensor = "{stream}"\n'
                     f'transport = "{transport}"\nformat = "delimited"\n{where}'
                     f'columns = {{ {cols} }}\ntime_column = 0\n')
    parts.append(f'[[source]]\nname = "burst"\nsensor = "tension"\ntransport = "tcp_server"\n'
                 f'port = {burst_port}\nstall_s = 600\ncolumns = {{ tension_N = 1 }}\ntime_column = 0\n')
    path.write_text("".join(parts))


class Subscriber:
    """The daemon's stand-in: arrival time of each block (by stream and last sample time) and
    the bridge's last status."""

    def __init__(self, port: int) -> None:
        self.session = zenoh_io.open_session(ZenohConfig(listen=(f"tcp/127.0.0.1:{port}",)))
        self.codec = zenoh_io.default_codec()
        self.arrived: list[tuple[str, int, int, float]] = []  # stream, t_first, t_last, mono
        self.status: dict = {}
        self.subs = [
            self.session.declare_subscriber(f"buoy/{BUOY}/sensor/**", self._block),
            self.session.declare_subscriber(f"buoy/{BUOY}/bridge/status", self._status)]

    def _block(self, s) -> None:
        now = time.monotonic()
        b = self.codec.decode(str(s.key_expr), s.payload.to_bytes(), 0)
        self.arrived.append((b.sensor, int(b.t_ns[0]), int(b.t_ns[-1]), now))

    def _status(self, s) -> None:
        self.status = json.loads(s.payload.to_bytes())

    def lines(self, source: str) -> int:
        return int(self.status.get("sources", {}).get(source, {}).get("lines", 0))

    def close(self) -> None:
        for sub in self.subs:
            sub.undeclare()
        self.session.close()


def feed(name: str, write, seconds: float, sent: dict[tuple[str, int], float],
         stop: threading.Event) -> None:
    """1 kHz of lines in BATCH-line writes, paced on the monotonic clock."""
    stream, _, n_fields = SOURCES[name]
    start = time.monotonic()
    k = 0
    while not stop.is_set() and k < seconds * RATE_HZ:
        due = start + k / RATE_HZ
        delay = due - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        data = b"".join(line(k + i, n_fields) for i in range(BATCH))
        write(data)
        now = time.monotonic()
        for i in range(BATCH):
            sent[(stream, (T0_S * 1000 + k + i) * 1_000_000)] = now
        k += BATCH


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--warmup", type=float, default=5.0)
    ap.add_argument("--burst", type=int, default=200_000)
    args = ap.parse_args()
    # the subscriber's callback (arrival times) waits for this process's GIL, which the five
    # feeder threads take in turn: at the default 5-ms switch interval that wait would be
    # most of the latency measured
    sys.setswitchinterval(1e-4)

    zport = free_port()
    ports = {n: free_port() for n in SOURCES}
    burst_port = free_port()
    master, slave = os.openpty()
    tty.setraw(slave)
    load0 = os.getloadavg()
    sub = Subscriber(zport)
    with tempfile.TemporaryDirectory() as tmp:
        cfg = Path(tmp) / "bridge.toml"
        config(cfg, zport, ports, os.ttyname(slave), burst_port)
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        proc = subprocess.Popen([sys.executable, "-m", "monitor.cli", "--log-level", "warning",
                                 "bridge", "--config", str(cfg)], env=env)
        try:
            time.sleep(3.0)  # the bridge starts, binds, listens, opens the port
            udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            tcp = {n: socket.create_connection(("127.0.0.1", ports[n]))
                   for n, (_, tr, _) in SOURCES.items() if tr == "tcp_server"}
            writers = {n: (lambda d, p=ports[n]: udp.sendto(d, ("127.0.0.1", p))) if tr == "udp"
                       else (lambda d: os.write(master, d)) if tr == "serial"
                       else tcp[n].sendall for n, (_, tr, _) in SOURCES.items()}
            sent: dict[tuple[str, int], float] = {}
            stop = threading.Event()
            total_s = args.warmup + args.seconds
            threads = [threading.Thread(target=feed, args=(n, w, total_s, sent, stop),
                                        daemon=True) for n, w in writers.items()]
            for th in threads:
                th.start()
            time.sleep(args.warmup)
            c0, l0, m0 = cpu_s(proc.pid), sum(sub.lines(n) for n in SOURCES), time.monotonic()
            time.sleep(args.seconds)
            c1, l1, m1 = cpu_s(proc.pid), sum(sub.lines(n) for n in SOURCES), time.monotonic()
            for th in threads:
                th.join()
            time.sleep(1.5)  # the last blocks close on the wall-clock timer
            rt_lines, rt_cpu, rt_wall = l1 - l0, c1 - c0, m1 - m0
            lat_close, lat_last = [], []
            worst: dict[str, float] = {}
            for stream, _, t_last, at in sub.arrived:
                closing = sent.get((stream, t_last + 1_000_000))
                if closing is not None and closing > m0:  # blocks closed in the window
                    lat_close.append(at - closing)
                    lat_last.append(at - sent[(stream, t_last)])
                    worst[stream] = max(worst.get(stream, 0.0), at - closing)
            rss = rss_mb(proc.pid)
            # 2. flat out on one TCP connection (its own sensor times, on the tension stream):
            # done when the block of its last line arrives (a line 1 s later closes it)
            data = b"".join(line(BURST_K0 + k, 1) for k in range(args.burst))
            last_ns = (T0_S * 1000 + BURST_K0 + args.burst - 1) * 1_000_000
            with socket.create_connection(("127.0.0.1", burst_port)) as b:
                time.sleep(0.5)
                c0, t0 = cpu_s(proc.pid), time.monotonic()
                b.sendall(data + line(BURST_K0 + args.burst - 1 + 1000, 1))
                done = []
                while not done and time.monotonic() < t0 + 300:
                    time.sleep(0.002)
                    done = [at for s, _, t_last, at in list(sub.arrived)
                            if s == "tension" and t_last == last_ns]
                burst_s, burst_cpu = (done or [math.nan])[0] - t0, cpu_s(proc.pid) - c0
                time.sleep(0.5)  # the status counts the lines
                got = sub.lines("burst") - 1
            for s in tcp.values():
                s.close()
            udp.close()
        finally:
            proc.terminate()
            proc.wait(30)
            sub.close()
            os.close(master)
            os.close(slave)
    ms = np.array(lat_close) * 1e3
    ml = np.array(lat_last) * 1e3
    print(f"real time: {len(SOURCES)} streams x {RATE_HZ} Hz for {rt_wall:.1f} s "
          f"(after {args.warmup:.0f} s of warm-up)")
    print(f"  lines read: {rt_lines / rt_wall:,.0f} /s "
          f"(sent {len(SOURCES) * RATE_HZ:,} /s)")
    print(f"  bridge CPU: {100 * rt_cpu / rt_wall:.2f} % of one core, "
          f"{1e3 * rt_cpu / max(rt_lines, 1) * 1000:.1f} ms per 1000 lines")
    print(f"  block latency from the closing line: p50 {np.percentile(ms, 50):.2f} ms, "
          f"p99 {np.percentile(ms, 99):.2f} ms, max {ms.max():.2f} ms ({len(ms)} blocks)")
    print(f"  from the block's last sample:        p50 {np.percentile(ml, 50):.2f} ms, "
          f"p99 {np.percentile(ml, 99):.2f} ms, max {ml.max():.2f} ms")
    print("  worst per stream: " + ", ".join(f"{k} {1e3 * v:.1f} ms"
                                             for k, v in sorted(worst.items())))
    print(f"  bridge RSS: {rss:.0f} MB")
    print(f"flat out (one TCP source): {got:,} of {args.burst:,} lines in {burst_s:.2f} s: "
          f"{got / burst_s:,.0f} lines/s, CPU {1e3 * burst_cpu / max(got, 1) * 1000:.1f} ms "
          "per 1000 lines")
    print("load average (1 min) at the start and the end: "
          f"{load0[0]:.2f}, {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
