"""Log size benchmark (issue 22 part 1): bytes per tension sample of a simulated log.

Simulates ``--hours`` of the default streams (20 Hz tension, 10 Hz IMU and motion, 1 Hz GNSS,
30 min waves; ``buoymon simulate``'s defaults) with replay.writer's defaults (quantized samples,
zstd level 3, no Message Index records) and prints the file's bytes per tension sample, then
what each stream costs alone (its decoded samples written again to a log of their own: the
decoded samples are on the quantum grid, so this re-encoding is exact; checked).

Measured on the 2-core machine shared with other jobs, 2026-11-25, 3 h of Hs 2 m, Tp 8 s:
9.78 bytes per tension sample (the float64 format of the first writer: about 38), 6.2 GB per
buoy-year (24 GB before). Alone, per tension sample: tension 2.35 (2.35 bytes per value),
imu 4.30 (2.87 per value), motion 2.86 (1.91 per value), gnss 1.00 (one sample per 1 s message:
the message's framing dominates), waves 0.01.

Usage: python bench/bench_log_size.py [--hours 3] [--hs 2] [--tp 8] [--seed 1]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

YEAR_S = 365.25 * 86400


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=3.0)
    ap.add_argument("--hs", type=float, default=2.0)
    ap.add_argument("--tp", type=float, default=8.0)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    from monitor.quanta import quanta
    from replay.reader import LogReader
    from replay.simulate import SimConfig, simulate
    from replay.writer import LogWriter, Series

    cfg = SimConfig(hours=args.hours, hs_m=args.hs, tp_s=args.tp, seed=args.seed)
    with tempfile.TemporaryDirectory(prefix="bench_log_size_") as tmp:
        path = Path(tmp) / "sim.mcap"
        summary = simulate(cfg, path)
        n_tension = summary.samples["tension"]
        size = path.stat().st_size
        print(f"{args.hours:g} h simulated (Hs {args.hs:g} m, Tp {args.tp:g} s): {size:,d} bytes, "
              f"{n_tension:,d} tension samples")
        print(f"  {size / n_tension:.2f} bytes per tension sample (target <= 12); "
              f"{size / (args.hours * 3600) * YEAR_S / 1e9:.1f} GB per buoy-year")
        streams: dict[str, list] = {}
        for b in LogReader(path):
            streams.setdefault(b.sensor, []).append(b)
        for sensor, blocks in streams.items():
            t = np.concatenate([b.t_ns for b in blocks])
            v = np.vstack([np.concatenate([b.fields[f] for b in blocks]) for f in blocks[0].fields])
            alone = Path(tmp) / f"{sensor}.mcap"
            with LogWriter(alone) as w:
                w.write_series([Series(cfg.buoy_id, sensor, t, v)], recv_delay_ns=200_000_000)
            again = np.vstack([np.concatenate([b.fields[f] for b in LogReader(alone)])
                               for f in blocks[0].fields])
            exact = np.array_equal(again, v, equal_nan=True)
            print(f"  {sensor:8s} alone {alone.stat().st_size / n_tension:6.2f} bytes per tension "
                  f"sample ({alone.stat().st_size / t.shape[0] / v.shape[0]:.2f} per value; "
                  f"re-encoding exact: {exact}); quanta {quanta(sensor).tolist()}")


if __name__ == "__main__":
    main()
