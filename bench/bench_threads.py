"""The replay's stream stage on a second thread (replay.stages) against both stages in turn.

Replays one log in-process (``replay.runner.run_blocks`` with the default configuration,
after a warm-up replay), alternating sequential and threaded runs, and prints the best and
median wall and CPU seconds of each, the load average before and after, and whether every
run gave the same report and state bytes.

usage: PYTHONPATH=. python bench/bench_threads.py LOG [--rounds N]

Measured 2026-11-25 on the 2-core development machine, never quiet (other sessions' test
suites: load average 2 to 9 on 2 cores, so the wall times measure them too), the 1-day bench
log (/work/wt/_gold/day1.mcap: 1.73 M tension samples, 123 slabs), best / median wall and CPU
seconds, sequential vs threaded, every run the same report and state bytes:

* 18:25 UTC, load 2.0-2.3, 5 rounds: wall 0.686 / 0.767 vs 0.715 / 0.829; CPU 0.672 / 0.703
  vs 0.690 / 0.726 (threaded no faster: no free core at that load);
* 18:40 UTC, load 5.0-5.3, 7 rounds: wall 1.431 / 1.732 vs 1.317 / 1.539; CPU 0.682 / 0.729
  vs 0.649 / 0.747;
* 19:03 UTC, load 8.6-8.8, 7 rounds: wall 1.601 / 2.376 vs 1.471 / 2.175; CPU 0.679 / 0.704
  vs 0.681 / 0.709.

The CPU is the same either way. Under load the threaded wall is 8-11 % lower, partly because
two runnable threads get a larger share of a busy machine; the gain on a quiet machine is
bounded by the GIL: of the ~0.26 CPU-s of the stream stage ~0.09 s are compiled ``nogil``
kernels (validation, QC, the estimator's filter and dynamics), of the ~0.29 s of the tick
stage ~0.04 s, the rest Python glue and numpy that hold the GIL most of the time.
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
