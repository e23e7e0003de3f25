"""End-to-end replay benchmark (issue 2): a simulated N-day log through the pipeline core.

Writes a synthetic log (20 Hz tension, 10 Hz IMU, 1 s blocks, the seed 004 buoy in a 1.5 m,
5.25 s sea with noise) with replay.writer, then measures:

* replay: ``replay.reader.LogReader`` -> ``Pipeline`` with the default configuration, in a
  child process so its peak RSS is its own, the way ``buoymon replay`` runs it (glibc's
  malloc keeping freed memory; ``replay.runner.use_child`` choosing the processes):
  pinned to one CPU (the issue's "on one core": one process, the reader reading in line,
  without its read-ahead thread, by the rule of replay.chunks.read_ahead_pays) and, for
  the wall-clock figure a user sees, on every core (on 2 idle CPUs the reading and stream
  stage in a second process, replay.stage_process; one process on a busy machine: the line
  says which); tension samples per second and times real time;
* peak memory of a 1-day replay against the N-day one (must stay within 10 %), on one core
  and, with two processes, of each;
* the naive baseline: decode message by message with mcap's reader, then
  ``rainflow.extract_cycles`` over the whole tension series (on ``--baseline-days``, since
  it holds everything in memory), in tension samples per second on one core.

Latest, quiet: 2026-11-26 09:21 UTC, the 2-core development machine (load average 1.0),
main 828b5b6 (this stop's cuts: runs of stretches up to 3 h where exact, the reader's reused
zstd buffer and pending table, the learner's segments windowed as kept; kernels warmed up
and bytecode compiled first), one full run on the 30-day log: one core 4.59 CPU-s = 11.25 M
tension samples/s, **19.4 x** the naive baseline of the same run (0.580 M/s; 20.2 x without
alert rules; target 10 x); 2 cores **3.24 s wall = 15.99 M tension samples/s** (target 10
M/s), 2.54 + 2.67 CPU-s; peak RSS one process 1 / 30 days 226 / 241 MB (+6.6 %; runs of 3 h
hold ~20 MB more than runs of an hour), two processes 213 + 163 / 222 + 167 MB (+4.2 %,
+2.6 %). A run right after kernels changed, before ``buoymon warmup``, compiles inside the
replay: 17.8 s on one core and +50 % peak RSS (the LLVM compiler's), as a user's first
replay after an upgrade would without the install's warm-up.

Before, quiet: 2026-11-26 07:18-07:30 UTC, the 2-core development machine (load average
0.5-0.9 before each run), main 7373d50 (this stop's cuts: an hour of log per slab, the decoder
writing in place, the validation screen, the estimator's side-by-side ODE, the learner's and
the alert batch's; bytecode compiled first), three full runs on the 30-day log: one core
5.60 / 8.05 / 5.47 CPU-s = 9.17 / 6.30 / 9.43 M tension samples/s, **15.6 / 11.6 / 15.7 x**
the naive baseline of the same run (0.587 / 0.544 / 0.603 M/s; target 10 x; the middle run
was disturbed: its rule-free replay took 5.48 CPU-s as in the others); 2 cores **3.67 / 4.13
/ 3.58 s wall = 14.13 / 12.55 / 14.49 M tension samples/s** (target 10 M/s), 3.02 + 3.19 /
3.60 + 3.34 / 3.09 + 2.94 CPU-s; peak RSS one process 1 / 30 days 205 / 219, 206 / 219, 205 /
218 MB (+6.4-6.6 %), two processes 199 + 134-135 / 205 + 136 MB (+2.7-2.9 %, +1.3-1.9 %).

Before, quiet: 2026-11-26 04:32-04:33 UTC, the 2-core development machine with no other job
(load average 0.8-1.1), main 8077ae8 (this round's slab joining, strict_json and decoder
cuts; bytecode compiled first), two full runs of this script on the 30-day log: one core
8.04 / 7.69 CPU-s = 6.45 / 6.74 M tension samples/s, **11.6 / 11.7 x** the naive baseline
of the same run (0.554 / 0.576 M/s; target 10 x); 2 cores (``buoymon replay``'s default
two processes) **4.96 / 5.15 s wall = 10.45 / 10.07 M tension samples/s** (target 10 M/s),
4.50 + 4.34 / 4.63 + 4.42 CPU-s; peak RSS one process 1 / 30 days 207 / 220 and 206 / 221 MB
(+6.1 / +7.2 %), two processes 196 + 132 / 203 + 135 MB (+3.4 %, +2.3 %). Both targets met
in both runs (the 2-core one by 0.7-4.5 %; the machine drifts ~10 % between runs).

Earlier, 2026-11-26 03:13-03:35 UTC on the 2-core development machine, NOT quiet (other
sessions' test suites: load average 4-8 through every run, so walls measure them and CPU
times are inflated; the quiet-machine figures are the lead's to take), branch twocore
(one slab per stretch of the log, replay.spans: half the slabs; this script now replays
through ``replay_logs`` after the CLI's numba set-up, as ``buoymon replay`` does) against
main 0762eca (an exported copy with its own kernel and bytecode caches), this script for
both, interleaved, the same 30-day log:

* this script, one full run each (03:21-03:23, load 7.3-8.0): one core 8.75 -> 8.30 CPU-s
  (no alert rules 8.24 -> 7.81); the "2 cores" line ran in one process both times (fewer
  than 1.5 CPUs idle); naive baseline 0.576 / 0.559 M/s; peak RSS 1 / 30 days 208 / 224 MB
  (+7.5 %) -> 208 / 221 MB (+6.4 %);
* ``buoymon replay``'s path with two processes forced (the idle check off), three
  interleaved rounds (03:13-03:17, load 4.7-7.9): the two processes' CPU, best round, main
  5.09 + 4.98 s -> 4.71 + 4.56 s (the other rounds 5.59 + 5.42 -> 4.73 + 4.60 and
  4.98 + 4.71); again with this branch's last commit (03:31-03:35, load 4.4-6.2): main
  5.30-5.68 + 5.14-5.35 s -> 4.55-5.07 + 4.63-4.94 s; one core (pinned) 8.56 / 9.50 /
  9.82 -> 8.47 / 8.15 / 8.46 CPU-s;
* the slab joining alone, in one process alternating (the same code otherwise): one core
  8.66 / 8.97 -> 7.87 / 7.96 CPU-s (load 4.3-4.9); two processes (load 8.3-8.7), parent +
  child CPU 5.66 + 5.99, 5.11 + 5.60, 5.41 + 5.83 -> 4.65 + 5.24, 4.80 + 5.30, 4.32 + 4.89.

Timing notes: the figures below this section were taken while this script imported all of
scipy.linalg with numba's target (~0.23 s before the fork; ``buoymon replay`` hides scipy
then, monitor.numba_setup) and slept its idle check's 0.05 s. With PYTHONDONTWRITEBYTECODE
set (as in these sessions' shells), a checkout whose ``__pycache__`` lacks a module's
bytecode compiles it from source at every run (measured: the stage process's first slab
0.27 s after the fork without, 0.09 s with): run ``python -m compileall monitor models
replay`` on a fresh or edited checkout before timing it.

Before, 2026-11-26 01:39-01:43 UTC on the 2-core development machine, quiet (no other job;
load 0.9-1.0 from these runs), main 22397eb+ (this round's tick-stage and reading cuts, the
shared-memory two-process replay by default, the late-copies and learner-state fixes), the
same 30-day log, reports identical to the previous main's (state: + ``late_copies``). The
machine's speed drifts by ~10 % between identical runs, so every figure below is a range:

* one core (one process, pinned): 8.12-10.03 CPU-s in seven runs; the two complete runs of
  this script: 9.36 s wall with a 0.557 M/s baseline = 9.7 x, and 8.55 s wall with a
  0.592 M/s baseline = **10.2 x** (target 10 x: met in the second run, not the first);
* 2 cores (``buoymon replay``'s default: two processes): 5.28, 5.53, 5.92 and 7.14 s wall =
  **9.8**, 9.4, 8.8 and 7.3 M tension samples/s (target 10 M/s, 5.18 s: NOT reached; the
  best run 2 % short); the two processes' CPU 4.68 + 4.49 s in the best run, plus ~0.6 s
  of kernel loading before the fork;
* peak RSS 1 / 30 days: one process 219 / 230-231 MB (+5.1-5.6 %), two processes
  210 + 141 / 216 + 145 MB (+2.9 %, +2.5-2.8 %).

Earlier, 2026-11-26 00:38-00:40 UTC, the same machine and 30-day log, loaded (other sessions' test
suites, load 2.2-3.1: walls measure them too), this round's hand-over (shared-memory slots,
bench/bench_threads.py): one core 12.94 s wall, 9.18 CPU-s, 4.01 M/s (no alert rules 9.05
CPU-s); the "2 cores" line ran in one process (fewer than 1.5 CPUs idle as it started:
14.68 s wall, 10.44 CPU-s); peak RSS 1 / 30 days 216 / 229 MB (+5.9 %); naive baseline
0.592 M/s. Two processes forced past the idle check, `buoymon replay` of the 30-day log at
load ~3: 14.08 s wall, 11.78 CPU-s against one process's 13.65 s, 11.12 CPU-s (golden30
identical both ways); peak RSS of the two 215 + 150 MB against 209 + 147 for 1 day. At load
1.7-2.1 (00:57 UTC, this script's 2-core measurement with the child forced, 3 interleaved
pairs): one process 9.88-11.07 s wall, two 7.79-10.08 s, best 6.65 M tension samples/s
against 5.25 (bench/bench_threads.py). The two halves' CPU are even, so on two idle CPUs the
wall should be about half of one process's streaming plus ~0.8 s of start-up: the
quiet-machine figure against the 10 M/s target (5.18 s) is the lead's final run.

Earlier, 2026-11-25 22:22-22:23 UTC on the 2-core development machine, quiet (load 0.9-1.1),
the same 30-day log, report and state identical to the last bit to the previous main's (and,
with the time_ahead and rejected_rate changes of the same round, to the new golden): this
round's reading (a count per value instead of np.unique, ISA-L's CRC-32, no read-ahead thread
on one CPU), learner (compiled loops with numpy's bits, one periodogram batch per window),
alert batch (re-sends in the compiled scan) and stream stage (estimator in registers, ticks
pass in groups, fused validation and QC) cuts:

* one core: 9.79 s wall, 9.77 CPU-s, 5.29 M tension samples/s (13.78 CPU-s before: 1.41 x);
  without alert rules 9.71 s;
* 2 cores: 9.33 s wall (11.46 CPU-s), **5.55 M/s** (4.27 before); the reading and stream
  stage in a child process (replay.stage_process, ``--two-processes``) was slower here than
  one process (fresh in-process runs at load ~1: 11.4 s, 9.1 s with glibc's mmap threshold
  raised, against 7.7-8.1 s in one process): its
  hand-over costs ~40 % more CPU in all (bench/bench_threads.py);
* peak RSS 1 day / 30 days 217 / 224 MB (+3.0 %);
* naive baseline 0.549 M/s: **9.6 x** on one core (9.7 x without alert rules), 10.1 x on 2.

Targets (issue 22): 10 M/s wall on 2 cores: NOT reached (5.55); 10 x on one core: NOT reached
(9.6 x).

Earlier, measured 2026-11-25 on the 2-core development machine, same 30-day log (51.84 M tension
samples), default configuration, report and state identical to the last bit (a golden of this
log written from main 7e8ba84). This build: the batched alert ticks, the per-tick commits in
one compiled pass, the learner's reused periodogram buffers, the fused validation, QC,
estimator and selector passes, fewer copies in ordering and merge. Quiet machine (20:08-20:11
UTC, load 0.3-1.2), main 7e8ba84 (warm compile cache) / this build, one run each:

* one core: 20.40 / 13.78 s wall, 20.39 / 13.78 CPU-s, 2.54 / 3.76 M tension samples/s
  (1.48 x); without alert rules 18.91 / 12.82 s;
* 2 cores: 18.57 / 12.14 s wall (21.36 / 14.59 CPU-s), 2.79 / 4.27 M/s (1.53 x; 213,490 x
  real time). The stream stage can run ahead on a second thread (replay.stages,
  bench/bench_threads.py) but the stages' Python holds the GIL most of the time, so it is
  off: the 2-core figure is the read-ahead thread's overlap alone;
* peak RSS 1 day / 30 days: 216 / 224 MB (+3.6 %) / 222 / 230 MB (+3.7 %);
* naive baseline 0.484 / 0.543 M/s in the two runs: 5.2 / 6.9 x on one core, 5.8 / 7.9 x on 2.

An earlier pair (19:45-19:50 UTC, main at load 2.0-2.4, this build at 0.6-1.7) gave main
27.39 CPU-s on one core and 21.10 s wall on 2 cores against 13.18 CPU-s and 11.24 s (4.61
M/s, 6.7 x the baseline on one core): the load inflated main's figures, the quiet pair is the
fair one.

Reading (measured 2026-11-25 21:34-21:46 UTC on the 2-core machine shared with other jobs,
load 3.7-6.2: CPU times only): in-process ``LogReader(..., read_ahead=False)``, pinned to one
CPU, no pipeline, best of 3 (30-day) / 7 (1-day), main c8bad01 and this build interleaved in 3
rounds: 30-day log 2.53-2.94 -> 1.93-2.21 CPU-s, 1-day log 0.080-0.093 -> 0.058-0.068 (a count
per value instead of np.unique per run of records, unsigned positions in the one-pass decoder,
ISA-L's CRC-32, fewer copies in the merge). The whole 30-day replay on one core, in-process,
one run each at load 5.5: 13.02 CPU-s (main: read-ahead thread on one core) -> 11.82 (the
reader starts no thread when the process has one CPU).

Targets (issue 22): 10 M/s wall on 2 cores and 10 x on one core: NOT reached. Where the time
goes now (cProfile of the 1-day log, ~0.45 s): no single part above ~8 %: the rainflow/Miner
tick kernel, the motion estimator's filter and jerk ODE (every IMU sample, though 60 of
864,000 are estimated), QARTOD QC, the learner's FFTs, the reader's inflate/decode/merge, and
~3,000 kernel dispatches and ~4,000 numpy reductions of per-slab glue.

Earlier: Measured 2026-11-25 16:49 UTC on the 2-core development machine (shared with other jobs,
load average 3.6-3.7 through the run, so the wall times measure them too: the CPU times are
the comparable figures), this build (compact log format; payloads of buoymon's own regular
layout decoded in one pass, monitor/codec_regular.py), 30-day log of 322 MB, 51.84 M tension
samples: default configuration (12 alert rule instances, 10 s ticks, QC, the sea-state
learner) on one core 30.34 s wall, 21.47 CPU-s = 1.71 M tension samples/s wall (2.41 M per
CPU-s); without alert rules 23.53 s wall, 17.10 CPU-s, 2.20 M/s; on 2 cores 21.83 s wall,
19.11 CPU-s = 2.37 M/s (118,700 x real time). Peak RSS 214 MB (1 day) vs 222 MB (30 days),
+4.0 %. Naive baseline (mcap + protobuf per message, the compact values rebuilt as
docs/LOG_FORMAT.md says, then ``rainflow``) 0.538 M/s: 3.2 x on one core by wall time
(4.5 x by CPU time), 4.4 x on 2 cores. Targets (issue 22): 10 M/s wall on 2 cores and 10 x on
one core: NOT reached. At load 2.5-4 (16:34 UTC, before rebasing on main) the figures were
1.31 / 2.38 / 2.51 M/s wall, at load 7 (16:28) 1.05 / 1.07 / 0.93 M/s: only CPU times compare
on this machine. Before / after this build's changes, the same 30-day log replayed in-process
on 2 cores, builds alternating: main of the same hour 24.29 / 23.88 CPU-s (20.5 / 21.5 s
wall), this build 21.19 / 21.63 CPU-s (19.5 / 20.4 s wall) at load 1.4-1.9 (-11 % CPU); four
pairs before the rebase at load 4-5: -9 %. The report and state identical to the last bit
before and after (a golden of the benchmark log written before the change). Reading the log
alone on one thread: 4.72 -> 2.80 CPU-s (the decode was 0.65 us per 1-s tension message and
1.25 us per IMU message, now 0.12-0.27 and 0.16-0.30 us). The float64 format's figures
(2026-11-21: 4.52 M/s on 2 cores, 11.48 s wall, on a quiet machine, before QC) are not
comparable with these.

Where the main thread's time goes now (py-spy, 30-day log, 2 cores): alert ticks ~25 % (each
tick's observation, the rule steps, stream health, the sea-state learner's window close);
the sea-state learner's Welch spectra of the load and the IMU ~13 %; rainflow and Miner tick
commits ~11 %; the reader's ordering and coalescing ~11 %; the motion estimator ~9 %;
validation and QC ~8 %; the read-ahead thread is idle 73 % of the run. Alert ticks every 60 s
instead of 10 s cut the CPU from 18.4-19.7 to 14.0-15.3 s: a third of the CPU is per-tick
Python, the rest per-sample numpy and compiled passes spread over a dozen stages.

Alert ticks batched (measured 2026-11-25 18:40-19:05 UTC on the same machine, load average
4-9 from other jobs: CPU times only, best of N): a replay slab's ticks go through
monitor/alerts/batch.py (per-tick value arrays and one compiled scan of the firing state
machine; an Observation and ``AlertEngine.evaluate`` only at the ticks where something
happens; slabs of under 16 ticks go tick by tick: 33 of the 1-day log's 8,640 ticks). Cost of the alert ticks in the 1-day log of
this script (in-process ``run_blocks``, CPU in ``Pipeline._evaluate_ticks`` less the damage
split, the sea-state learner's tick stubbed out, best of 7, two interleaved rounds): main
(7e8ba84) 14.0 / 14.2 us per tick, this build 5.0 / 4.7 us. The whole 1-day replay
in-process (``prof.py time 7``, three interleaved rounds): main 0.650 / 0.715 / 0.631 CPU-s,
this build 0.553 / 0.590 / 0.573 (-9 to -17 %). The 30-day log, ``buoymon replay`` (report,
state and output identical to main's): main 22.86 / 22.38 CPU-s, this build 22.06 / 19.71
(two interleaved pairs at load 7-9). What is left of the ~5 us a tick: setting the batch up
(~0.3 ms a slab of ~145 ticks), the first tick's load figures rebuilt with the samples an
earlier slab left, the committed damages handed to the sea-state learner (which still sees
every tick), the 33 ordinary evaluations.

Measured 2026-11-24 on the same machine (shared with other jobs), `--days 2 --baseline-days
0.1`, warm compile cache, before / after QARTOD QC by default (issue 17: monitor.qartod on every
stream, the over-break rule, the damage split): default config on one core 1.04 s / 1.18 s
(+13 %), without alert rules 0.97 s / 0.96 s, 2 cores 0.96 s / 1.22 s wall; peak RSS 191 /
194 MB. In-process best of 3 on one core (default config): 0.72-0.79 s / 0.82-0.86 s. The QC
kernels take ~0.06 s of the 2-day replay (3.5 M tension + 1.7 M three-field IMU samples).

Measured 2026-11-25 on the same machine (load average 4-5 from other jobs), the cost of QC in
today's tree (which also monitors the termination, so twice the rules per tick of the 11-24
figures): 1-day log of this script, in-process ``run_blocks`` on one core, CPU time best of 16
in 4 interleaved rounds: the tree with QC stubbed out (``StreamQC.check`` returning passes,
no damage split, no over-break rule) 0.479 s (median of rounds 0.497 s), the shipped QC
0.516 s (0.527 s): +7.8 % (+6 %), after the damage split's per-tick Python sums became one
cumulative sum each (same bits: additions in the same order) and the QC kernel's tallies
moved into locals; report and state of the replay identical to the last bit before and after.

Measured 2026-11-25 15:48 UTC on the same machine (load average 3.6-3.8), ``--days 1 --no-qc
6`` (child processes on one core, QC on and stubbed out interleaved, CPU from the reader's
start, numba cache loads included): with QC best 1.135 s, median 1.174 s; stubbed out best
1.108 s, median 1.195 s: QC +2.4 % (best), -1.8 % (median, within the noise). This log has no
``motion`` stream; the check-factor test of one costs 21 ns a sample (the Spotter's 218,556
samples: 4.6 ms, in-process best of 7, against ~5 s for the record's replay).

Usage: python bench/bench_replay.py [--days 30] [--baseline-days 1] [--dir DIR [--reuse]] [--keep]
       python bench/bench_replay.py --days 1 --no-qc 6   (the QC's cost alone, interleaved)
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

S = 1_000_000_000
T0 = 1_600_000_000 * S
BUOY = "vaps"


def write_log(path: Path, days: float, seed: int = 4) -> int:
    """Write the synthetic log hour by hour (flat memory); return the tension sample count."""
    from replay.writer import LogWriter, Series

    rng = np.random.default_rng(seed)
    # a 1.5 m, 5.25 s sea as a sum of a few wave components, plus slow drift and noise
    periods = np.array([4.4, 5.0, 5.25, 5.6, 6.3, 8.0])
    amps = np.array([400.0, 900.0, 1400.0, 900.0, 500.0, 250.0])
    phases = rng.uniform(0, 2 * np.pi, periods.size)
    n_tension = 0
    with LogWriter(path) as w:
        for hour in range(int(np.ceil(days * 24))):
            t0 = T0 + hour * 3600 * S
            series = []
            for sensor, hz in (("tension", 20), ("imu", 10)):
                n = 3600 * hz
                t = t0 + (np.arange(n, dtype=np.int64) * S) // hz
                x = (t - T0) / S
                wave = np.sin(2 * np.pi * x[None, :] / periods[:, None] + phases[:, None])
                if sensor == "tension":
                    v = 5000.0 + amps @ wave + 300 * np.sin(2 * np.pi * x / 600) + rng.normal(0, 50, n)
                    values = v[None, :]
                    n_tension += n
                else:
                    az = (amps / 1400.0) @ wave
                    values = np.stack([rng.normal(0, 0.05, n), rng.normal(0, 0.05, n), az])
                series.append(Series(BUOY, sensor, t, values))
            w.write_series(series, block_ns=S, recv_delay_ns=50_000_000)
    return n_tension


def _stub_qc() -> None:
    """QC off, for its cost: every QARTOD test of every stream returns "not evaluated" (2)
    without running; the validator's own rules (nan, range, rate) still run."""
    from monitor import qartod

    def check(self, t_ns, values):
        n = t_ns.shape[0]
        return np.full((len(qartod.TESTS), n), qartod.NOT_EVALUATED, np.uint8), np.zeros(n, np.uint8)

    qartod.StreamQC.check = check


def child_replay(path: str, rules: bool, one_core: bool, qc: bool = True) -> None:
    """Run in a child process: replay, print figures as JSON (with this process's peak RSS,
    and a stage process's CPU and peak RSS). As ``buoymon replay`` runs: the CLI's numba
    set-up (its CPU target loaded without scipy, monitor.numba_setup), then
    ``replay.runner.replay_logs`` (its malloc setting, its choice of processes and reader,
    the stream stage's kernels loaded while the idle CPUs are measured, the report): on 2
    CPUs the reading and stream stage in a child process when it pays
    (replay.stage_process); ``one_core`` pins the process to one CPU (one process, the
    reader then starts no read-ahead thread)."""
    if one_core:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    if not qc:
        _stub_qc()
    from monitor.config import config_with, default_config
    from monitor.numba_setup import prepare_numba
    from replay.runner import replay_logs

    prepare_numba()  # as monitor.cli.main, before anything imports numba
    config = default_config()
    if not rules:
        config = config_with(config, alerts={k: v for k, v in config.raw["alerts"].items()
                                             if k != "rule"})
    start, cpu = time.perf_counter(), time.process_time()
    result = replay_logs(config, [path], show_progress=False)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    rep = result.report
    print(json.dumps({
        "wall_s": wall,
        "cpu_s": cpu,
        "tension_samples": rep["samples"]["tension"]["accepted"],
        "all_samples": result.samples,
        "damage_committed": rep["components"]["conductor"]["damage_committed"],
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "child_cpu_s": kids.ru_utime + kids.ru_stime,
        # the stage process is the only child a replay starts
        "two_processes": kids.ru_utime + kids.ru_stime > 0,
        "child_peak_rss_mb": kids.ru_maxrss / 1024,
    }))


def replay_in_child(path: Path, rules: bool = True, one_core: bool = True,
                    qc: bool = True) -> dict:
    cmd = ([sys.executable, __file__, "--child-replay", str(path)] + ([] if rules else ["--no-rules"])
           + (["--one-core"] if one_core else []) + ([] if qc else ["--qc-off"]))
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def qc_cost(path: Path, rounds: int) -> None:
    """Print the CPU cost of the QARTOD QC: replays of ``path`` on one core with QC on and
    stubbed out, interleaved (on, off, on, off...) so that the machine's load drifts alike."""
    cpu: dict[bool, list[float]] = {True: [], False: []}
    for _ in range(rounds):
        for qc in (True, False):
            cpu[qc].append(replay_in_child(path, qc=qc)["cpu_s"])
    on, off = (np.array(cpu[q]) for q in (True, False))
    print(f"QC cost ({rounds} interleaved rounds, one core, CPU s): with QC best {on.min():.3f} "
          f"median {np.median(on):.3f}; QC stubbed out best {off.min():.3f} median "
          f"{np.median(off):.3f}; QC {on.min() / off.min() - 1:+.1%} (best), "
          f"{np.median(on) / np.median(off) - 1:+.1%} (median); target within 10 %")


def naive_baseline(path: Path) -> tuple[float, int, float]:
    """Decode every message with mcap's reader and protobuf (the compact values as
    docs/LOG_FORMAT.md says: cumulative sum of the deltas times the quantum, raw samples put
    back), then ASTM rainflow on it all.
    Returns (CPU seconds, tension samples, damage)."""
    import rainflow
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
    from mcap.reader import make_reader

    from models import fatigue, helix

    start = time.process_time()
    parts = []
    with open(path, "rb") as f:
        classes = {}
        for schema, channel, msg in make_reader(f).iter_messages(log_time_order=False):
            if not channel.topic.endswith("/tension"):
                continue
            cls = classes.get(schema.id)
            if cls is None:
                fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
                pool = descriptor_pool.DescriptorPool()
                for fd in fds.file:
                    pool.Add(fd)
                cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
                classes[schema.id] = cls
            q = cls.FromString(msg.data).tension_N  # docs/LOG_FORMAT.md's recipe
            v = np.cumsum(np.array(q.delta, np.int64)).astype(np.float64) * q.quantum
            v[np.array(q.raw_index, np.int64)] = np.array(q.raw_value)
            parts.append(v)
    tension = np.concatenate(parts)
    stress = helix.conductor_stress(tension, helix.HelixCable.vaps_biw(), lay="left")
    cycles = np.array([(r, c) for r, _, c, _, _ in rainflow.extract_cycles(stress)])
    sn = fatigue.SNCurve.vaps_copper()
    damage = float(np.sum(sn.damage_per_cycle(cycles[:, 0], counts=cycles[:, 1])))
    return time.process_time() - start, tension.shape[0], damage


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=float, default=30.0)
    ap.add_argument("--baseline-days", type=float, default=1.0)
    ap.add_argument("--dir", help="where to write the logs (default: a temporary directory)")
    ap.add_argument("--keep", action="store_true", help="keep the generated logs")
    ap.add_argument("--reuse", action="store_true", help="reuse logs already in --dir")
    ap.add_argument("--no-qc", type=int, metavar="ROUNDS", default=0,
                    help="only measure the QC's cost: ROUNDS interleaved replays of the log "
                         "with QC on and stubbed out")
    ap.add_argument("--child-replay", help=argparse.SUPPRESS)
    ap.add_argument("--qc-off", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--no-rules", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--one-core", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child_replay:
        child_replay(args.child_replay, rules=not args.no_rules, one_core=args.one_core,
                     qc=not args.qc_off)
        return
    work = Path(args.dir or tempfile.mkdtemp(prefix="bench_replay_"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        t = time.perf_counter()
        big, small = work / f"log_{args.days:g}d.mcap", work / "log_1d.mcap"
        if not (args.reuse and big.exists() and small.exists()):
            write_log(big, args.days)
            write_log(small, 1.0)
        print(f"{args.days:g}-day log: {big.stat().st_size / 1e6:.0f} MB "
              f"(written or found in {time.perf_counter() - t:.1f} s)")
        if args.no_qc:
            qc_cost(big, args.no_qc)
            return
        r_big = replay_in_child(big)
        r_small = replay_in_child(small)
        r_plain = replay_in_child(big, rules=False)
        r_cores = replay_in_child(big, one_core=False)
        r_small_cores = replay_in_child(small, one_core=False)
        cores = len(os.sched_getaffinity(0))
        for label, r in (("default config, one core", r_big), ("no alert rules, one core", r_plain),
                         (f"default config, {cores} cores", r_cores)):
            rr = r["tension_samples"] / r["wall_s"]
            child = (f" + {r['child_cpu_s']:.2f} s in the child (peak RSS "
                     f"{r['peak_rss_mb']:.0f} + {r['child_peak_rss_mb']:.0f} MB)"
                     if r["two_processes"] else " (one process)")
            print(f"replay {args.days:g} d ({label}): {r['wall_s']:.2f} s wall, "
                  f"{r['cpu_s']:.2f} s CPU{child}; {rr / 1e6:.2f} M tension samples/s "
                  f"({r['all_samples'] / r['wall_s'] / 1e6:.2f} M samples/s all streams), "
                  f"{rr / 20:,.0f} x real time; target >= 10 M/s wall on 2 cores")
        growth = r_big["peak_rss_mb"] / r_small["peak_rss_mb"] - 1
        print(f"peak RSS: 1 d {r_small['peak_rss_mb']:.0f} MB, {args.days:g} d "
              f"{r_big['peak_rss_mb']:.0f} MB ({growth:+.1%}); target within 10 %")
        if r_cores["two_processes"] and r_small_cores["two_processes"]:
            print("peak RSS on {} cores, this process + the child: 1 d {:.0f} + {:.0f} MB, "
                  "{:g} d {:.0f} + {:.0f} MB ({:+.1%}, {:+.1%})".format(
                      cores, r_small_cores["peak_rss_mb"], r_small_cores["child_peak_rss_mb"],
                      args.days, r_cores["peak_rss_mb"], r_cores["child_peak_rss_mb"],
                      r_cores["peak_rss_mb"] / r_small_cores["peak_rss_mb"] - 1,
                      r_cores["child_peak_rss_mb"] / r_small_cores["child_peak_rss_mb"] - 1))
        base_log = small if args.baseline_days == 1.0 else work / "log_baseline.mcap"
        if base_log != small:
            write_log(base_log, args.baseline_days)
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # the baseline is serial anyway
        cpu, n, damage = naive_baseline(base_log)
        base_rate = n / cpu
        ours = replay_in_child(base_log)

        def ratio(r: dict) -> float:
            return r["tension_samples"] / r["wall_s"] / base_rate

        print(f"naive baseline ({args.baseline_days:g} d, mcap per message + rainflow, one core): "
              f"{base_rate / 1e6:.3f} M tension samples/s; the {args.days:g}-day replay is "
              f"{ratio(r_big):.1f} x faster on one core ({ratio(r_plain):.1f} x without alert "
              f"rules), {ratio(r_cores):.1f} x on {cores} cores; target >= 10 x on one core")
        print(f"damage check on the baseline log: naive {damage:.6e} (ASTM incl. residue), "
              f"pipeline committed {ours['damage_committed']:.6e}")
    finally:
        if not args.keep and not args.dir:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
