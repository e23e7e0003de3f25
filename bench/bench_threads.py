"""The second core in a replay of one log: the stream stage on a second thread
(replay.stages), or the reading and the stream stage in a child process
(replay.stage_process), against both stages in turn in one process.

Replays one log (``replay.runner.run_blocks`` with the default configuration, after a
warm-up replay of every mode), the modes interleaved round by round, and prints the best and
median wall and CPU seconds of each (a child's CPU apart), the load average before and after,
and whether every run gave the same report and state bytes.

usage: PYTHONPATH=. python bench/bench_threads.py LOG [--rounds N] [--modes M,..] [--warm-log L]

Modes: ``turn`` (one process, the reader's read-ahead thread: ``buoymon replay --one-process``),
``turn-no-ra`` (one thread), ``threads``, ``child`` (the child reads on its one thread: what
``buoymon replay`` runs by default on 2 idle CPUs), ``child-ra`` (the child with a read-ahead
thread). glibc's malloc keeps freed memory, as in ``buoymon replay``.

The child process with the shared-memory hand-over (replay.stage_process: the slabs' arrays in
six reused 4 MB slots shared with the child, the header alone through the pipe; the tension
statistics, stresses and the sea-state learner's feeding in the parent; glibc's malloc keeping
freed memory, replay.runner.keep_freed_memory), measured 2026-11-26 00:00-00:40 UTC on the
same machine, never quiet (other sessions' test suites: load 2.2-5.5 on 2 CPUs, so wall times
measure them too), the 30-day benchmark log, report and state identical to the golden in
both modes (golden30.sh, and with the child forced):

* Where the old hand-over's cost went (its 30-day run at load ~4: parent 6.9 + 1.4 sys, child
  6.6 + 1.2 sys CPU-s, 457k + 77k page faults): the parent's fresh receive buffers (every
  page faulted in, then unmapped: most of the system time), the learner's spectra (every
  slab re-sent its open window's segments so far: about two thirds of the bytes, and their
  pickling, copying and unpickling), the children's malloc returning freed chunks to the
  kernel. Now: parent 29k page faults, 0.2 s sys; child 15-16k, 0.1-0.2 s sys; the
  hand-over 46 MB a day (382 kB a slab), all through the slots (3571 of 3575 slabs; the
  rest empty), no slot ever held by the tick stage.
* Each side's CPU alone, the first 1,000-1,500 slabs (~10 days) replayed serially in one
  process, child's work then parent's (load 3.2-4.0), against one
  process on the same slabs: pickled hand-over through memory 1.45-2.47 + 1.36-2.57 CPU-s,
  the sum equal to one process (+-2 %); through the real slots and pipes, slab by slab:
  child 2.26-2.38, parent 2.27-2.37, sum +9 to +24 % over one process (pickling the intake
  ~45-90 us a slab, unpickling ~25, the stresses computed twice, the copy into the slot):
  the two halves are even, so on two idle CPUs the wall is about half of one process's
  streaming plus the start-up (~0.8 s: numba and the kernels, before the fork).
* Whole `buoymon replay` of the 30-day log (the child forced past the idle check), CPU
  user+sys: one process 10.8-13.1, two processes 11.8-16.4 (+6 to +30 % in these loaded
  runs: the two processes share the CPUs with the other jobs and wait for each other);
  walls 10.6-22.8 s against 14.1-22.0 s: on this loaded machine one process is as fast or
  faster, which is why ``child_pays`` requires 1.5 idle CPUs. Peak RSS 30 days against 1
  day, two processes: 215 + 150 against 209 + 147 MB (+2.9 %, +2.0 %); one process 242
  against 232 MB (+4.3 %).
* Later, at load 1.7-2.5 (one other job on about one CPU), whole `buoymon replay` of the
  30-day log (imports and report included), wall / user+sys CPU, 6 interleaved rounds
  (00:53-00:56 UTC): main 38adbf4 (one process) 9.24-14.19 s / 11.1-13.4; this build,
  ``--one-process`` 8.71-12.27 s / 10.5-11.6; two processes (forced past the idle check)
  6.55-10.01 s / 11.0-14.2, best 6.55 against 8.71 and 9.24. The 2-core measurement of
  bench_replay (from the reader's creation, the child forced), 3 interleaved pairs at load
  1.7-2.1: one process 9.88-11.07 s wall (11.6-12.5 CPU-s), two 7.79-10.08 s (parent
  6.1-7.4, its ~0.8 s of kernel loading before the fork included, + child 5.3-6.4 CPU-s),
  best 6.65 M tension samples/s against 5.25; peak RSS 215 + 150 MB against 243 MB.
* This script, 30-day log, 2 rounds at load 1.7-2.3 (00:58 UTC, in-process after a warm-up:
  no kernel loading): ``child`` best 6.64 s wall (5.21 CPU-s here + 5.14 in the child),
  ``child-ra`` 8.49 s (5.96 + 5.64): a read-ahead thread in the child still costs more than
  it overlaps. The garbage collector is no factor: 2 young-generation collections per day
  of log, none older (one process, 1-day log).
* The quiet-machine figure (the target: 5.18 s wall) is for the lead's final run:
  ``bench/bench_replay.py`` measures the default path (two processes when 1.5 CPUs are
  idle as it starts).

Earlier, the child process with the pickled hand-over through the pipe, measured 2026-11-25
on the 2-core development machine (Xeon, shared with
other sessions), the 1-day bench log (/work/wt/_gold/day1.mcap, 1.73 M tension samples) and
the 30-day benchmark log (/tmp/perf_bench/log_30d.mcap, 51.84 M), report and state identical
in every run and to the golden of main 7e8ba84 (golden.sh, golden30.sh):

* Final build, fairly quiet machine (22:05-22:09 UTC, load 1.2-2.1 with this benchmark's own
  two processes; nothing else in ``top``):
  - 30-day log, one round each, in-process after a warm-up: ``turn`` 10.99 s wall (12.33
    CPU-s), ``child`` 7.73 s wall (5.67 CPU-s here + 7.64 in the child): -30 % wall, 6.7 M
    tension samples/s against 4.7; an earlier round at load 1.4-2.1: ``turn`` 11.83 s.
    ``child-ra`` 8.27 s against ``child`` 8.25 s in the same round: the read-ahead thread
    buys nothing in the child (it waits for the GIL), so the child reads on its own thread.
    Two later pairs (22:10-22:13 UTC, final build but the idle-CPU rule): ``turn`` 11.62 s
    against ``child`` 15.21 s while another job took most of a CPU (``top``), and ``turn``
    11.63 s (14.16 CPU-s: contended) against ``child`` 9.35 s (7.58 + 9.11) at load 1.2-1.3.
    Hence the rule of :func:`replay.stage_process.child_pays`: the child only when at least
    1.5 of the machine's CPUs are idle as the replay starts.
  - 30-day log as ``buoymon replay`` runs it (``replay_logs`` in a fresh process): 8.37 s
    wall, 6.13 + 7.66 CPU-s, 6.2 M tension samples/s; the CLI (imports, report) 10.05 s.
    Peak RSS 188 MB here + 137 MB in the child, against 177 + 133-135 MB for the 1-day log
    (+6.4 % / +2-3 %, +4.6 % together; the two share the libraries and kernels, so together
    they hold less than the sum); one process: ~220 MB.
  - 1-day log, 7 rounds, wall best / median: ``turn`` 0.291 / 0.329, ``turn-no-ra`` 0.344 /
    0.386, ``threads`` 0.342 / 0.429, ``child`` 0.302 / 0.321 s (CPU 0.180 + 0.290 in the
    child against 0.361): even at one day (the fork and a fresh child's first slabs); in a
    fresh process (``replay_logs``, 3 pairs) 0.89-0.95 s with the child, 0.90-0.97 s
    without: :data:`replay.stage_process.CHILD_MIN_BYTES` (20 MB, about a day of the
    default streams) is where it starts to pay.
* The critical path is the child (reading and stream stage, ~0.25 CPU-s a day) against the
  tick stage's ~0.19: 10 M tension samples/s (5.2 s for the 30-day log) would need the
  child's work itself to shrink by a third, or part of the stream stage (the sea-state
  learner's spectra, ~1.5 s of the 30-day log) to move to the tick stage's process.
* Where one process's time goes, 1-day log, one core, per stage (load 2.6): reading 0.085,
  stream stage (``ingest``) 0.135, tick stage (``advance``) 0.135 CPU-s.
* The hand-over, a day of the default streams: pickled as they are 162 MB (the block 55 MB,
  the stream slabs' accepted values 35 MB that the tick stage never reads, the components'
  stresses 28 MB); sent without those (a block only when a sink has a block hook, the
  stresses computed again by the tick stage's process: 3 ms a day) 46 MB. A pipe moves 72 MB
  in 0.008 CPU-s (writer) / 0.012 (reader); the costs are pickling (~0.01-0.02 CPU-s a day
  in the child) and receiving into fresh buffers and unpickling (0.055 -> 0.040 CPU-s a day
  without the stresses).
* What did not work: a writer thread in the child (up to 4 slabs queued) and the child's
  read-ahead thread: each write waited for the GIL and the parent for the write; the 30-day
  log took 11.3 s (``child``) and 13.9 s (``child-ra``) wall at load 1.4-2.1 against
  ``turn``'s 11.8; writing each hand-over in one ``writev`` from the child's one thread gave
  the 7.7 s above. Loading the kernels in both processes after the fork cost the child
  ~0.5 CPU-s in a fresh process: the pipeline is built (its kernels loaded) before the fork.
* On a saturated machine (load 6-7, 21:45-21:51 UTC, the writer-thread build) the child buys
  nothing: ``turn`` 33.86 s, ``child-ra`` 33.74 s wall (14.80 against 7.73 + 9.90 CPU-s): the
  wall is then this job's share of the CPUs, and the split costs ~10-20 % more CPU (the
  hand-over, each process's copy of the pages it touches).

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
from replay.runner import keep_freed_memory, run_blocks

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
    keep_freed_memory()  # as buoymon replay
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
