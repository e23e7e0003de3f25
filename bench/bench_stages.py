"""Benchmark: CPU per sample of the replay's per-sample stages (issue 22, part 3).

Replays a log (default: the 1-day bench log of the golden check, /work/wt/_gold/day1.mcap,
or the log given as the first argument) in process with the default configuration, timing
each stage with a wrapper (``time.process_time_ns``) around its entry point; prints the
stage's CPU per sample it takes, best of N replays (second argument, default 5; the first
replay warms the caches and is not counted). Stages:

``validate``        StreamValidator.check (all streams; includes qc and check_factor)
``  qc``            StreamQC.check (QARTOD tests and the check factor)
``  check_factor``  CheckFactor.check (motion streams only)
``estimator``       the pipeline's estimator feed (_ModelsEstimator.feed, the rate tracker, the
                    IMU integrator, the quasi-static lookup and the dynamic core)
``  imu``           DisplacementIntegrator.update (not called once the estimator integrates
                    the IMU in its own loop: then inside ``estimator``)
``  quasi_static``  the quasi-static model's lookup of the wanted samples (per call: in the
                    default configuration one sample per slab is wanted)
``selector``        LoadSelector.needed + select (per estimated sample)
``stress``          Component.stress (every component)
``ticks``           models.fatigue.commit_ticks: rainflow, Miner and residue damage of the
                    slab's whole alert ticks (every component; per stress sample)
``tick_load``       the slab's per-tick load figures (pipeline._TickLoad; per load sample)
``damage_split``    DamageSplit.ticks (per evaluated tick)

The replays read without the read-ahead thread (``read_ahead=False``): a stage's CPU clock
would otherwise count the reader thread's work done meanwhile.

Measured 2026-11-25 19:10 UTC on the 2-core Xeon shared with 7 other jobs (load 7: figures
are best of 5 and move by 10-20 % between runs), 1-day bench log, main at 7e8ba84 against
the branch estval at d96e0e6, two rounds run one after the other (the range of the two):

    stage          main 7e8ba84                  estval
    validate       69.5-70.9 ms  26.8-27.4 ns    39.4-44.5 ms  15.2-17.2 ns per sample
      qc           27.9-29.2     10.8-11.3       18.8-19.7      7.3-7.6
    estimator      68.7-75.4     79.5-87.2       44.1-45.1     51.1-52.2
      imu          17.1-18.2     19.8-21.0       (in the estimator's loop)
      quasi_static  6.9 ms, 62 calls              7.7-8.7 ms, 62 calls
    selector       10.6-11.4     12.3-13.2       5.6-6.1        6.4-7.0 (per estimate)
    stress          6.6-6.7       1.9             6.7-8.0        1.9-2.3
    replay CPU     0.636-0.637 s                 0.585-0.601 s

Measured 2026-11-25 21:52 UTC on the 2-core AMD EPYC (lscpu) shared with other jobs (load
5.7-6.3: figures move by 10-20 % between runs), ``taskset -c 0``, 1-day bench log, best of
5, main c8bad01 against the branch stream at f8f680c (this script on both), three rounds
interleaved (the range of the three):

    stage          main c8bad01                  stream f8f680c
    validate       25.8-30.6 ms  10.0-11.8 ns    23.9-25.9 ms   9.2-10.0 ns per sample
      qc           16.6-19.4      6.4-7.5        (the usual block's QC runs inside
                                                  validate's one compiled call)
    estimator      35.9-41.8     41.6-48.4       34.0-36.3     39.4-42.0
    ticks          31.8-36.1      9.2-10.5       27.8-29.7      8.1-8.6 (per stress sample)
    tick_load       9.8-13.4      5.6-7.7         8.3-9.9       4.8-5.7
    damage_split    7.6-8.8       878-1014        3.4-3.7       398-432 (per tick)
    replay CPU     0.375-0.442 s                 0.389-0.422 s

The 30-day bench log in process on one core (``read_ahead=False``, after a warm-up replay),
main c8bad01 then this branch, then the other way round, 22:04 UTC (load 2.4-3.5): main
11.13 and 11.83 CPU-s, this branch 10.69 and 10.93 CPU-s.

The compiled loops alone, on their calls captured from the same replay (same bits checked):
the ticks pass 7.6 -> 6.1 ns per stress sample, the estimator's ``_advance`` 24.5 -> 19.3 ns
per IMU sample, the QC fast kernel 5.5 -> 5.1 ns per sample.

Run: PYTHONPATH=. python bench/bench_stages.py [LOG] [N]
"""

from __future__ import annotations

import sys
import time
from collections import defaultdict

from models import estimator, imu
from models import fatigue
from monitor import (check_factor, components, damage_split, load_source, pipeline, qartod,
                     validate)
from monitor.config import default_config
from replay.reader import LogReader
from replay.runner import run_blocks

LOG = "/work/wt/_gold/day1.mcap"

cpu: dict[str, int] = defaultdict(int)
samples: dict[str, int] = defaultdict(int)


def _timed(owner, name: str, stage: str, count) -> None:
    """Wrap ``owner.name`` to add its CPU time to ``stage`` and ``count(args)`` samples."""
    func = getattr(owner, name)

    def wrapper(*args, **kw):
        t0 = time.process_time_ns()
        out = func(*args, **kw)
        cpu[stage] += time.process_time_ns() - t0
        samples[stage] += count(args, out)
        return out

    setattr(owner, name, wrapper)


def main() -> None:
    log = sys.argv[1] if len(sys.argv) > 1 else LOG
    reps = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    _timed(validate.StreamValidator, "check", "validate", lambda a, o: a[1].shape[0])
    _timed(qartod.StreamQC, "check", "  qc", lambda a, o: a[1].shape[0])
    _timed(check_factor.CheckFactor, "check", "  check_factor", lambda a, o: a[1].shape[0])
    _timed(load_source._ModelsEstimator, "feed", "estimator", lambda a, o: a[1].shape[0])
    _timed(imu.DisplacementIntegrator, "update", "  imu", lambda a, o: o.shape[-1])
    _timed(estimator.CatenaryQuasiStatic, "__call__", "  quasi_static",
           lambda a, o: a[1].shape[0])
    _timed(load_source.LoadSelector, "needed", "selector", lambda a, o: 0)
    _timed(load_source.LoadSelector, "select", "selector", lambda a, o: a[3].shape[0])
    _timed(components.Component, "stress", "stress", lambda a, o: a[1].shape[0])
    _timed(fatigue, "commit_ticks", "ticks", lambda a, o: a[3][-1] if len(a[3]) else 0)
    _timed(pipeline._TickLoad, "__init__", "tick_load", lambda a, o: a[1].shape[0])
    _timed(damage_split.DamageSplit, "ticks", "damage_split", lambda a, o: len(a[2]))
    cfg = default_config()
    best: dict[str, tuple[int, int]] = {}
    total = []
    for rep in range(reps + 1):
        cpu.clear()
        samples.clear()
        t0 = time.process_time()
        run_blocks(cfg, LogReader([log], read_ahead=False))
        if rep:
            total.append(time.process_time() - t0)
            for k, v in cpu.items():
                if k not in best or v < best[k][0]:
                    best[k] = (v, samples[k])
    print(f"{log}: replay CPU best {min(total):.3f} s, median {sorted(total)[len(total) // 2]:.3f} s")
    for k, (ns, n) in best.items():
        per = f"{ns / n:7.1f} ns/sample" if n else ""
        print(f"{k:16s} {ns / 1e6:8.1f} ms  {n:>10,d} samples  {per}")


if __name__ == "__main__":
    main()
