"""Replay with and without its visual outputs (issue 8: ``--rrd`` at most 2x slower).

Writes the synthetic log of ``bench_replay.py`` (20 Hz tension, 10 Hz IMU, 1 s blocks) for
``--days`` and replays it with ``replay.runner.replay_logs`` as ``buoymon replay`` does: plain,
with the Rerun recording (``--rrd``, bulk preset), with the report's plot fields (``--report`` /
``--html``), and with both. Prints wall and CPU seconds, tension samples per second and the
slow-down against the plain replay (best of ``--repeats``).

Usage: python bench/bench_replay_outputs.py [--days 3] [--repeats 2]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))


def replay(log: Path, rrd: Path | None, plot_fields: bool) -> tuple[float, float, int]:
    from monitor.config import default_config
    from monitor.viz.pipeline_sinks import open_rerun
    from replay.runner import replay_logs

    config = default_config()
    start, cpu = time.perf_counter(), time.process_time()
    sinks = [open_rerun(config, rrd=rrd, replay=True)] if rrd else []
    result = replay_logs(config, [log], sinks=sinks, show_progress=False,
                         plot_fields=plot_fields)
    return (time.perf_counter() - start, time.process_time() - cpu,
            result.report["samples"]["tension"]["accepted"])


def main() -> None:
    from bench_replay import write_log

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=float, default=3.0)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "bench.mcap"
        write_log(log, args.days)
        replay(log, None, False)  # warm-up: imports, numba compilation
        cases = {"plain": (None, False), "--rrd": (Path(tmp) / "r.rrd", False),
                 "plot fields (--html)": (None, True), "--rrd + --html": (Path(tmp) / "r.rrd", True)}
        best: dict[str, tuple[float, float, int]] = {}
        for _ in range(args.repeats):
            for name, (rrd, fields) in cases.items():
                r = replay(log, rrd, fields)
                if name not in best or r[0] < best[name][0]:
                    best[name] = r
        rrd_mb = (Path(tmp) / "r.rrd").stat().st_size / 1e6
    base_wall, base_cpu, _ = best["plain"]
    print(f"replay of a {args.days:g}-day log (best of {args.repeats}):")
    for name, (wall, cpu, n) in best.items():
        print(f"  {name:22s} wall {wall:6.2f} s  cpu {cpu:6.2f} s  {n / wall / 1e6:5.2f} M tension "
              f"samples/s  x{wall / base_wall:4.2f} wall  x{cpu / base_cpu:4.2f} cpu")
    print(f"  .rrd size {rrd_mb:.1f} MB")


if __name__ == "__main__":
    main()
