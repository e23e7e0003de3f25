"""Bytes the live daemon writes to its disk for checkpoints, per checkpoint and per day.

A real daemon (`buoymon run`, shipped configuration, measured load, checkpoint every 10 s, no
recording) is fed over Zenoh on loopback by a real publisher (bench/bench_daemon.py's): first
``--history-s`` of 20 Hz tension, 10 Hz IMU and 1 Hz GNSS in 1-s blocks as fast as it takes
them (so its late copies hold a whole ``copy_span_s`` hour), then ``--seconds`` of the same in
real time. Over the real-time part it prints the daemon process's ``write_bytes`` (what reached
the block layer) and ``wchar`` (what it passed to write()) from /proc/<pid>/io, divided by the
checkpoints made meanwhile (the status's ``checkpoint.seq``), and that times a day of
checkpoints; then the sizes in the state file: the checkpoint row and the write-once parts
(monitor/state_part.py). The daemon writes nothing else meanwhile but a rate-limited
warning line or two on stderr (its sensor time, 2025-06, is behind the clock).

Measured 2026-11-26 on the 2-core development machine (shared with other workers: bytes do
not depend on the load, CPU does), ext4 on a virtio disk (/tmp), SQLite 3.40.1 (its
secure_delete on by default), history 3,720 s, 120 s real time (12-13 checkpoints):

    before (0762eca): state row 1.384 MB, late copies inline, rewritten every checkpoint
        02:55  write_bytes 4.198 MB per checkpoint = 36.3 GB per day (wchar 4.179 MB)
        03:34  write_bytes 4.220 MB per checkpoint = 36.5 GB per day (wchar 4.204 MB)
               CPU of a save 37.5 ms
    closed minutes as write-once parts only: state row 0.585 MB, parts 0.817 MB
        03:00  write_bytes 1.590 MB per checkpoint = 13.7 GB per day (wchar 1.575 MB)
    now (+ row deflated, secure_delete=FAST): state row 0.112 MB, 360 parts 0.817 MB
        03:05  write_bytes 0.160 MB per checkpoint =  1.39 GB per day (wchar 0.148 MB)
        03:32  write_bytes 0.144 MB per checkpoint =  1.24 GB per day (wchar 0.134 MB)
               CPU of a save 51.4 ms (deflating the row: +14 ms every 10 s, 0.14 % of a core)

Writes were ~3 x the row: the new row, the replaced one's pages zeroed (secure_delete) and
the WAL's copy into the database file. The late copies held (1 h of the default streams,
values quantised by the sensor codec): tension 0.257 MB, IMU 0.532 MB, GNSS 0.039 MB.

Usage: PYTHONPATH=. python bench/bench_checkpoint.py [--history-s 3720] [--seconds 120]
Run it from a checkout of another commit (copy this file there) for its figures.
"""

from __future__ import annotations

import argparse
import sqlite3
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from bench_daemon import Client, accelerated, blocks_at, free_port, start_daemon  # noqa: E402

import numpy as np  # noqa: E402

INTERVAL_S = 10.0  # bench_daemon's start_daemon: checkpoint_interval_s = 10.0


def io_bytes(pid: int) -> dict[str, int]:
    """/proc/<pid>/io as numbers (write_bytes, wchar, ...)."""
    return {k: int(v) for k, v in (ln.split(": ") for ln in
                                   Path(f"/proc/{pid}/io").read_text().splitlines())}


def last_status(client: Client, wait_s: float = 3.0) -> dict:
    """The newest status the daemon published within ``wait_s``."""
    deadline, doc = time.monotonic() + wait_s, None
    while doc is None or time.monotonic() < deadline:
        for _, d in client.statuses():
            doc = d
        time.sleep(0.1)
    return doc


def state_sizes(path: Path) -> tuple[int, int, int]:
    """(checkpoint row bytes, parts, parts' bytes) in the state file (no parts table: 0, 0)."""
    db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        row = db.execute("SELECT length(state) FROM checkpoint WHERE id = 1").fetchone()[0]
        try:
            n, size = db.execute("SELECT count(*), coalesce(sum(length(data)), 0) FROM parts"
                                 ).fetchone()
        except sqlite3.OperationalError:
            n, size = 0, 0
    finally:
        db.close()
    return row, n, size


def late_copies_held(path: Path) -> str:
    """Minutes and MB of late copies per stream in the saved state (inline or as parts)."""
    from monitor.checkpoint import CheckpointStore  # noqa: PLC0415

    store = CheckpointStore(path)
    try:
        late = store.load().state["pipeline"].get("late_copies", {})
    finally:
        store.close()
    return ", ".join(f"{s} {len(d['t'])} min {sum(map(len, d['t'] + d['v'])) / 1e6:.3f} MB"
                     for s, d in late.items())


def save_cpu_ms(path: Path, tmp: Path, n: int = 10) -> float:
    """Median CPU ms of one save of the daemon's last state (loaded from ``path``) into a
    store of this process, after a first save (steady state: no part new)."""
    from monitor.checkpoint import CheckpointStore  # noqa: PLC0415

    src = CheckpointStore(path)
    state = src.load().state
    src.close()
    store = CheckpointStore(tmp / "again.sqlite")
    store.save(state)
    cpu = []
    for _ in range(n):
        t = time.process_time()
        store.save(state)
        cpu.append(time.process_time() - t)
    store.close()
    return 1e3 * sorted(cpu)[n // 2]


def realtime(client: Client, buoy: str, first: int, seconds: int) -> None:
    rng = np.random.default_rng(5)
    start = time.time()
    for k in range(seconds):
        time.sleep(max(0.0, start + k + 1 - time.time()))
        for b in blocks_at(buoy, first + k, 1, rng):
            client.put(b)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--history-s", type=int, default=3720)
    ap.add_argument("--seconds", type=int, default=120)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmpd:  # /tmp: on the disk here (not a tmpfs)
        tmp = Path(tmpd)
        port, metrics_port = free_port(), free_port()
        proc, buoy = start_daemon(tmp, port, "measured", metrics_port)
        client = Client(port, buoy)
        try:
            accelerated(client, buoy, proc.pid, args.history_s / 86400, 1, 0)
            while last_status(client)["queue_depth"]:
                pass
            seq0, io0 = last_status(client)["checkpoint"]["seq"], io_bytes(proc.pid)
            realtime(client, buoy, args.history_s, args.seconds)
            seq1, io1 = last_status(client)["checkpoint"]["seq"], io_bytes(proc.pid)
        finally:
            client.close()
            proc.terminate()
            proc.wait(60)
        row, n_parts, parts = state_sizes(tmp / "state.sqlite")
        held = late_copies_held(tmp / "state.sqlite")
        cpu_ms = save_cpu_ms(tmp / "state.sqlite", tmp)
    saves = seq1 - seq0
    per_day = 86400 / INTERVAL_S
    print(f"real time {args.seconds} s after {args.history_s} s of history: {saves} checkpoints")
    for key, what in (("write_bytes", "to the disk"), ("wchar", "through write()")):
        each = (io1[key] - io0[key]) / max(saves, 1)
        print(f"  {key:12s} {each / 1e6:8.3f} MB per checkpoint, {each * per_day / 1e9:7.2f} GB "
              f"per day at one per {INTERVAL_S:g} s ({what})")
    print(f"  state file at exit: checkpoint row {row / 1e6:.3f} MB, {n_parts} write-once parts "
          f"{parts / 1e6:.3f} MB")
    print(f"  late copies held: {held}")
    print(f"  CPU of a save of that state (this process, median of 10): {cpu_ms:.1f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
