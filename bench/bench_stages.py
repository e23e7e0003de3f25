"""The replay's stream stage on a second thread (replay.stages) against both stages in turn.

Replays one log in-process (``replay.runner.run_blocks`` with the default configuration,
after a warm-up replay), alternating sequential and threaded runs, and prints the best and
median wall and CPU seconds of each, the load average before and after, and whether every
run gave the same report and state bytes.

usage: PYTHONPATH=. python bench/bench_stages.py LOG [--rounds N]

Measured: see the figures quoted in the commit that added this script (2026-11-25, the
2-core development machine shared with other jobs).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

from monitor.config import default_config
from replay.reader import LogReader
from replay.runner import run_blocks


def replay(log: str, threads: bool) -> tuple[float, float, bytes]:
    """(wall s, CPU s, report and state bytes) of one replay."""
    cfg = default_config()
    wall, cpu = time.perf_counter(), time.process_time()
    pipeline, _ = run_blocks(cfg, LogReader([log]), threads=threads)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    out = json.dumps([pipeline.report(), pipeline.state()], allow_nan=True).encode()
    return wall, cpu, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    replay(args.log, True)  # warm: compile cache, model cache, page cache
    print(f"load average before: {os.getloadavg()}")
    runs: dict[bool, list[tuple[float, float]]] = {False: [], True: []}
    outputs = set()
    for _ in range(args.rounds):
        for threads in (False, True):
            wall, cpu, out = replay(args.log, threads)
            runs[threads].append((wall, cpu))
            outputs.add(out)
    print(f"load average after:  {os.getloadavg()}")
    for threads, label in ((False, "sequential"), (True, "threaded  ")):
        walls, cpus = zip(*runs[threads])
        print(f"{label} wall best {min(walls):.3f} median {statistics.median(walls):.3f} s, "
              f"CPU best {min(cpus):.3f} median {statistics.median(cpus):.3f} s")
    print("report and state identical in every run" if len(outputs) == 1
          else f"DIFFERENT outputs: {len(outputs)}")


if __name__ == "__main__":
    main()
