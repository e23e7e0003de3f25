"""Recorder benchmark (issue 18): the daemon's MCAP recording of a 1-day simulated log, written
by the one MCAP writer (monitor.mcap_file, through monitor.recorder.McapRecorder) against
``mcap``'s own Writer as the recorder used it before (zstd chunks, no Message Index records,
chunk index and summary), both with the recorder's pattern: one message at a time, a JSON
status document every second, a flush (chunk closed, fsync) every 5 s of log time, a new
file every hour.

The messages are those of ``buoymon simulate --hours H`` (20 Hz tension, 10 Hz IMU and
motion, 1 Hz GNSS, 30-min waves in 1-s blocks, as a publisher sends them), read once with
mcap's reader; the figures are the writing alone: messages and payload megabytes per CPU
second (process time, best of the interleaved rounds) and the files' size.

Measured 2026-11-25 on the 2-core development machine shared with other jobs (load 4-5),
1 day (432,049 messages: the simulator's 1-s blocks and a status document per second, 36.7 MB
of payloads), 3 interleaved rounds: monitor.mcap_file CPU best 2.70 s (median 3.92 s),
160 k messages/s, 13.6 MB/s per CPU second; mcap's Writer 3.98 s (4.60 s), 109 k messages/s,
9.2 MB/s; wall time is the 17,280 fsyncs' (7-8 s both); files 26.2 MB against 25.6 MB.

Usage: python bench/bench_record.py [--hours 24] [--rounds 3] [--log FILE.mcap]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from monitor.recorder import JSON_OBJECT, ChannelSpec, McapRecorder  # noqa: E402

ROTATE_S, FLUSH_S = 3600.0, 5.0


def messages(log: Path) -> list[tuple[str, ChannelSpec, int, int, bytes]]:
    """The log's messages in log-time order, with a status document after each second."""
    from mcap.reader import make_reader

    out = []
    with open(log, "rb") as f:
        for schema, channel, msg in make_reader(f).iter_messages(log_time_order=True):
            spec = ChannelSpec(schema.name, schema.encoding, schema.data,
                               channel.message_encoding)
            out.append((channel.topic, spec, msg.log_time, msg.publish_time, msg.data))
    buoy = out[0][0].split("/")[1]
    first, last = out[0][2] // 10**9, out[-1][2] // 10**9
    status = [(f"buoy/{buoy}/monitor/status", JSON_OBJECT, s * 10**9 + 1, s * 10**9,
               json.dumps({"now_ns": s * 10**9, "damage": s * 1e-9,
                           "streams": {"tension": {"accepted": s * 20}}}).encode())
              for s in range(first, last + 1)]
    return sorted(out + status, key=lambda m: m[2])


def record_buoymon(msgs, directory: Path) -> None:
    rec = McapRecorder(directory, ROTATE_S, FLUSH_S)
    for topic, spec, log_ns, pub_ns, data in msgs:
        rec.write(topic, data, spec, log_ns, pub_ns)
    rec.close()


def record_mcap(msgs, directory: Path) -> None:
    """The recorder as it was on mcap's Writer (same rotation, flush and fsync)."""
    from mcap.writer import CompressionType, IndexType, Writer

    rotate, flush = int(ROTATE_S * 1e9), int(FLUSH_S * 1e9)
    window, f, w, last_flush = -1, None, None, 0
    channels: dict[str, int] = {}
    schemas: dict[ChannelSpec, int] = {}
    for topic, spec, log_ns, pub_ns, data in msgs:
        if log_ns // rotate != window:
            if w is not None:
                w.finish()
                f.flush()
                os.fsync(f.fileno())
                f.close()
            window = log_ns // rotate
            f = open(directory / f"rec-{window}.mcap", "wb")
            w = Writer(f, compression=CompressionType.ZSTD,
                       index_types=IndexType.ALL & ~IndexType.MESSAGE)
            w.start(profile="", library="buoymon")
            channels.clear()
            schemas.clear()
        ch = channels.get(topic)
        if ch is None:
            sid = schemas.get(spec)
            if sid is None:
                sid = schemas[spec] = w.register_schema(spec.schema_name, spec.schema_encoding,
                                                        spec.schema_data)
            ch = channels[topic] = w.register_channel(topic, spec.message_encoding, sid)
        w.add_message(ch, log_time=log_ns, publish_time=pub_ns or log_ns, data=data)
        if log_ns - last_flush >= flush:
            w.flush()
            os.fsync(f.fileno())
            last_flush = log_ns
    w.finish()
    f.flush()
    os.fsync(f.fileno())
    f.close()


def measure(fn, msgs, tmp: Path) -> tuple[float, float, int]:
    out = Path(tempfile.mkdtemp(dir=tmp))
    cpu, wall = time.process_time(), time.perf_counter()
    fn(msgs, out)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    size = sum(p.stat().st_size for p in out.iterdir())
    for p in out.iterdir():
        p.unlink()
    out.rmdir()
    return cpu, wall, size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--log", help="a simulated log to take the messages from (default: simulate)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        log = Path(args.log) if args.log else tmp / "sim.mcap"
        if not args.log:
            subprocess.run([sys.executable, "-m", "monitor.cli", "simulate", "-o", str(log),
                            "--hours", str(args.hours), "--hs", "2", "--tp", "8", "--seed", "1"],
                           check=True, capture_output=True, cwd=ROOT)
        msgs = messages(log)
        payload_mb = sum(len(m[4]) for m in msgs) / 1e6
        print(f"{len(msgs):,d} messages, {payload_mb:.1f} MB of payloads")
        runs: dict[str, list[tuple[float, float, int]]] = {"buoymon": [], "mcap": []}
        for _ in range(args.rounds):  # interleaved: the machine's load drifts
            runs["buoymon"].append(measure(record_buoymon, msgs, tmp))
            runs["mcap"].append(measure(record_mcap, msgs, tmp))
        for name, r in runs.items():
            cpus = sorted(c for c, _, _ in r)
            print(f"{name:8s} CPU best {cpus[0]:.2f} s (median {cpus[len(cpus) // 2]:.2f}), "
                  f"wall best {min(w for _, w, _ in r):.2f} s: "
                  f"{len(msgs) / cpus[0] / 1e3:.0f} k messages/s, "
                  f"{payload_mb / cpus[0]:.1f} MB/s per CPU second; files {r[0][2] / 1e6:.1f} MB")


if __name__ == "__main__":
    main()
