"""The second core in a replay of one log: the stream stage on a second thread
(replay.stages), or the reading and the stream stage in a child process
(replay.stage_process), against both stages in turn in one process.

Replays one log (``replay.runner.run_blocks`` with the default configuration, after a
warm-up replay of every mode), the modes interleaved round by round, and prints the best and
median wall and CPU seconds of each (a child's CPU apart), the load average before and after,
and whether every run gave the same report and state bytes. Modes: ``turn`` (one process,
the reader's read-ahead thread), ``turn-no-ra`` (one thread), ``threads``, ``child`` (the
child reads on its own thread), ``child-ra`` (the child with its read-ahead thread: what
``buoymon replay`` runs on 2 CPUs).

usage: PYTHONPATH=. python bench/bench_threads.py LOG [--rounds N] [--modes M,..] [--warm-log L]

The child process (2026-11-25 21:20-22:45 UTC, same machine, never quiet: load average 3.7
to 6.9 from other sessions' test suites, so every wall time below measures them too; the
quiet-machine figures are still to be taken):

* Where one process's time goes, 1-day log, one core, in-process per slab (load 2.6):
  reading 0.085, stream stage (``ingest``) 0.135, tick stage (``advance``) 0.135 CPU-s. So a
  child that reads and runs the stream stage carries ~60 % of the work, the tick stage ~40 %.
* The hand-over, per day of the default streams: pickled as they are 162 MB (the block
  55 MB, the stream slabs' accepted values 35 MB that the tick stage never reads, the
  components' stresses 28 MB); sent without those (a block only when a sink has a block
  hook; the stresses computed again by the tick stage's process: 3 ms a day) 46 MB. A pipe
  moves 72 MB in 0.008 CPU-s (writer) / 0.012 (reader); what the hand-over costs is pickling
  (~0.02-0.04 CPU-s a day in the child) and receiving into fresh buffers and unpickling
  (0.055 -> 0.040 CPU-s a day with the stresses left out).
* 1-day log, 5 rounds, load 3.7-3.9 (first build, before the sender thread and the stresses
  change): wall best / median ``turn`` 0.345 / 0.467, ``turn-no-ra`` 0.379 / 0.460,
  ``threads`` 0.426 / 0.686, ``child`` 0.600 / 0.716, ``child-ra`` 0.437 / 0.696 s; CPU
  ``turn`` 0.398, the child modes 0.237 here + 0.331 in the child.
* 1-day log, 5 rounds, load 6.6 (final build): ``turn-no-ra`` 0.927 / 1.159, ``child``
  1.144 / 1.319, ``child-ra`` 1.080 / 1.377 s wall; CPU 0.404 against 0.230 + 0.351.
* 30-day benchmark log (/tmp/perf_bench/log_30d.mcap, 51.8 M tension samples), one round,
  load 6.6-6.9 (build e20d987, the stresses still sent): ``turn`` 33.86 s wall, 14.80 CPU-s;
  ``child-ra`` 33.74 s wall, 7.73 CPU-s here + 9.90 in the child. As ``buoymon replay`` runs
  it (``replay_logs`` in a fresh process, load 6.2, final build): 32.03 s
  wall, 7.23 + 9.40 CPU-s; peak RSS 188 MB here + 154 MB in the child, against 177 + 146 MB
  for the 1-day log (+6.2 % / +5.2 %, +5.8 % together; the two share the libraries and
  compiled kernels, so together they hold less than the sum); report and state identical
  to the golden of main 7e8ba84 (golden30.sh).
* A fresh process (``replay_logs`` of the 1-day log, load 4.3-5.0): one process 1.00-1.22
  CPU-s; with the child 0.86-0.94 + 0.95-1.06 while both loaded the compiled kernels, 0.91-
  1.05 + 0.45-0.55 once the pipeline is built (and its kernels loaded) before the fork.

Reading: on a saturated machine the child buys nothing (the wall is the CPU share, and the
split costs ~12-19 % more CPU: the hand-over, and each process's own copy of what it
touches); what it buys on a quiet one follows from the CPU split: the child's ~0.25-0.30
CPU-s a day of the 1-day log's 0.37 (its read-ahead thread can take the inflate and decode
to the other core when the tick stage waits) and the tick stage's ~0.26, so ~0.27-0.30 s of
wall a day against ~0.37-0.40: about 8-9 s for the 30-day log against 12.14 s, short of
the 5.2 s target (which needs ~0.17 s a day: the work itself must shrink). The quiet-machine
pair (``turn`` against ``child-ra`` on the 30-day log) is still to be measured.

The threads, earlier:

Measured 2026-11-25 on the 2-core development machine, never quiet (other sessions' test
suites: load average 1.4 to 9 on 2 cores, so the wall times measure them too), the 1-day
bench log (/work/wt/_gold/day1.mcap: 1.73 M tension samples, 123 slabs), best / median wall
and CPU seconds, sequential vs threaded, every run the same report and state bytes:

* 20:07 UTC, the final merged build on a quiet machine (load 0.04-0.5), 5 rounds: wall
  0.357 / 0.371 vs 0.414 / 0.463; CPU 0.431 / 0.443 vs 0.528 / 0.588: threaded 16 % slower
  by wall, 22 % more CPU (the branches' speed-ups shrank the compiled share of each stage
  further: the threads mostly trade the GIL);
* 19:29-19:31 UTC, load 1.4-1.9 (one other process using most of a core), 3 x 5 rounds:
  wall 0.748 / 0.752 vs 0.757 / 0.843, 0.582 / 0.652 vs 0.643 / 0.793, 0.721 / 0.876 vs
  0.717 / 0.961; CPU 0.680 / 0.715 vs 0.664 / 0.731, 0.634 / 0.643 vs 0.724 / 0.753,
  0.684 / 0.706 vs 0.708 / 0.789;
* 19:25 UTC, load 2.4-3.2, 15 rounds: wall 0.673 / 0.745 vs 0.695 / 0.796; CPU 0.607 /
  0.640 vs 0.612 / 0.669;
* 18:25 UTC, load 2.0-2.3, 5 rounds: wall 0.686 / 0.767 vs 0.715 / 0.829; CPU 0.672 / 0.703
  vs 0.690 / 0.726;
* 18:40 UTC, load 5.0-5.3, 7 rounds: wall 1.431 / 1.732 vs 1.317 / 1.539; CPU 0.682 / 0.729
  vs 0.649 / 0.747;
* 19:03 UTC, load 8.6-8.8, 7 rounds: wall 1.601 / 2.376 vs 1.471 / 2.175; CPU 0.679 / 0.704
  vs 0.681 / 0.709.

At the lowest loads seen the threaded replay is no faster (median wall +7 to +22 %) and
costs up to 17 % more CPU (the threads hand the GIL back and forth); only on a saturated
machine is its wall 8-11 % lower, two runnable threads getting a larger share of it. The GIL
bounds the gain: of the ~0.26 CPU-s of the stream stage ~0.09 s are compiled ``nogil``
kernels (validation, QC, the estimator's filter and dynamics), of the ~0.29 s of the tick
stage ~0.04 s; the rest is Python glue and numpy that hold the GIL most of the time. So
``run_blocks`` runs the stages in turn unless asked (``threads=True``). The same split on
the 30-day benchmark log (``buoymon replay``, 19:00 UTC, load 6-9): threaded 22.1 CPU-s,
64.8 s wall, peak RSS 232 MB; sequential 21.5 CPU-s, 78.1 s wall, 223 MB; report and state
identical to the golden of main 7e8ba84 both ways.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import time

from monitor.config import default_config
from replay.reader import LogReader
from replay.runner import run_blocks

# mode: (the reader's read-ahead thread, the stream stage on a thread, in a child process)
MODES = {"turn": (True, False, False), "turn-no-ra": (False, False, False),
         "threads": (True, True, False), "child": (False, False, True),
         "child-ra": (True, False, True)}


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def replay(log: str, mode: str) -> tuple[float, float, float, bytes]:
    """(wall s, this process's CPU s, the child's CPU s, report and state bytes) of one
    replay."""
    read_ahead, threads, child = MODES[mode]
    cfg = default_config()
    wall, cpu, kids = time.perf_counter(), time.process_time(), _children_cpu()
    pipeline, _ = run_blocks(cfg, LogReader([log], read_ahead=read_ahead), threads=threads,
                             child=child)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    out = json.dumps([pipeline.report(), pipeline.state()], allow_nan=True).encode()
    return wall, cpu, _children_cpu() - kids, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--modes", default="turn,turn-no-ra,threads,child,child-ra",
                    help=f"comma-separated, of {', '.join(MODES)}")
    ap.add_argument("--warm-log", help="warm up on this log (default: LOG itself)")
    args = ap.parse_args()
    modes = args.modes.split(",")
    for mode in modes:  # warm: compile cache, model cache, page cache
        replay(args.warm_log or args.log, mode)
    print(f"load average before: {os.getloadavg()}, CPUs {len(os.sched_getaffinity(0))}")
    runs: dict[str, list[tuple[float, float, float]]] = {m: [] for m in modes}
    outputs = set()
    for _ in range(args.rounds):
        for mode in modes:
            *figures, out = replay(args.log, mode)
            runs[mode].append(tuple(figures))
            outputs.add(out)
    print(f"load average after:  {os.getloadavg()}")
    for mode in modes:
        walls, cpus, kids = zip(*runs[mode])
        print(f"{mode:11s} wall best {min(walls):.3f} median {statistics.median(walls):.3f} s, "
              f"CPU best {min(cpus):.3f} median {statistics.median(cpus):.3f} s"
              + (f", child CPU best {min(kids):.3f} median {statistics.median(kids):.3f} s"
                 if MODES[mode][2] else ""))
    print("report and state identical in every run" if len(outputs) == 1
          else f"DIFFERENT outputs: {len(outputs)}")


if __name__ == "__main__":
    main()
