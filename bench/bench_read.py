"""Benchmark the log writer and the fast reader on a long synthetic log.

Writes a synthetic log (20 Hz tension, 10 Hz IMU, 1 s blocks; sine waves plus noise), then
reads it back with :class:`replay.reader.LogReader` and, for comparison, reads the first part
with ``mcap``'s own per-message reader. Prints messages/s and samples/s, both per wall-clock
second and per CPU second of this process (the two differ when other jobs share the cores).

    python bench/bench_read.py --days 30        # the issue's 30-day case (~5.2 M messages)
    python bench/bench_read.py --days 1 --keep out/bench.mcap
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from replay.reader import LogReader
from replay.writer import LogWriter, Series

T0_NS = 1_700_000_000 * 10**9
HOUR_NS = 3600 * 10**9


def synthetic_hour(hour: int, rng: np.random.Generator, buoy: str) -> list[Series]:
    """One hour of 20 Hz tension and 10 Hz IMU: wave-period sines plus noise."""
    out = []
    for sensor, rate, nf, scale in (("tension", 20, 1, 4000.0), ("imu", 10, 3, 1.5)):
        n = 3600 * rate
        t = T0_NS + hour * HOUR_NS + np.arange(n, dtype=np.int64) * (10**9 // rate)
        ts = (t - T0_NS) * 1e-9
        vals = np.empty((nf, n))
        for f in range(nf):
            wave = 1.0 + 0.3 * np.sin(2 * np.pi * ts / (5.25 + f))
            vals[f] = scale * wave + rng.normal(0, 0.02 * scale, n)
        out.append(Series(buoy, sensor, t, vals))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--days", type=float, default=30.0, help="log length in days (default 30)")
    ap.add_argument("--keep", type=Path, help="write the log here and keep it")
    ap.add_argument("--baseline-messages", type=int, default=200_000,
                    help="messages read with mcap's reader for comparison (0: skip)")
    args = ap.parse_args()
    hours = max(1, int(round(args.days * 24)))
    tmp = tempfile.TemporaryDirectory() if args.keep is None else None
    path = args.keep or Path(tmp.name) / "bench.mcap"
    rng = np.random.default_rng(1)

    gen = write = write_cpu = 0.0
    messages = 0
    with LogWriter(path) as w:
        for h in range(hours):
            t0 = time.perf_counter()
            series = synthetic_hour(h, rng, "bench")
            t1, c1 = time.perf_counter(), time.process_time()
            messages += w.write_series(series)
            write += time.perf_counter() - t1
            write_cpu += time.process_time() - c1
            gen += t1 - t0
    size = path.stat().st_size
    print(f"log: {hours} h, {messages:,} messages, {size / 1e6:,.1f} MB; "
          f"peak RSS so far {_peak_mb():,.0f} MB")
    print(f"write: {write:.2f} s wall = {messages / write:,.0f} msg/s; "
          f"{write_cpu:.2f} s CPU = {messages / write_cpu:,.0f} msg/s "
          f"(synthetic data generation {gen:.2f} s not included)")

    t0, c0 = time.perf_counter(), time.process_time()
    reader = LogReader(path)
    samples = {"tension": 0, "imu": 0}
    blocks = 0
    for b in reader:
        samples[b.sensor] += len(b)
        blocks += 1
    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    st = reader.stats[0]
    for what, sec in (("wall", dt), ("CPU", cpu)):
        print(f"fast read (coalesced), {what}: {sec:.2f} s = {st.messages / sec:,.0f} msg/s, "
              f"{samples['tension'] / sec:,.0f} tension samples/s, "
              f"{(samples['tension'] + samples['imu']) / sec:,.0f} samples/s all")
    print(f"  {blocks:,} coalesced blocks; peak RSS so far {_peak_mb():,.0f} MB")
    assert st.messages == messages and not st.lost, st

    if args.baseline_messages:
        from mcap.reader import NonSeekingReader

        t0, c0 = time.perf_counter(), time.process_time()
        n = 0
        with open(path, "rb") as f:
            # streaming, file order: the indexed reader and log-time ordering load whole-file
            # indexes or messages first
            for _ in NonSeekingReader(f).iter_messages(log_time_order=False):
                n += 1
                if n >= args.baseline_messages:
                    break
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
        print(f"mcap streaming reader, undecoded payloads, first {n:,} messages: "
              f"{n / dt:,.0f} msg/s wall, "
              f"{n / cpu:,.0f} msg/s CPU")
    print(f"peak RSS: {_peak_mb():,.0f} MB")


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


if __name__ == "__main__":
    main()
