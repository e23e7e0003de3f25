"""The sea-state learner's own cost (monitor.sea_state_learner, issue 22 part 3).

Writes the 1-day log of ``bench_replay.py`` (20 Hz tension, 10 Hz IMU), replays it once
through the pipeline with the learner's inputs recorded as the pipeline gives them (the
slabs' load stresses and IMU accelerations, every alert tick), then feeds those inputs to a
fresh learner again and again: CPU time best of N, split into the Welch feed of the load and
IMU slabs, the window closes (Dirlik damage of each component, the sea state, the table),
and the rest of the ticks. Prints those, and checks the learned table and windows are the
same each time.

Measured 2026-11-25 18:40-19:20 UTC on the 2-core development machine (AMD EPYC, shared
with up to 8 other jobs: load average 4-9, so only best-of-N CPU times compare), runs of main
7e8ba84 and of this build interleaved:

- this script on the lead's 1-day golden log (same generator; 48 windows, 123 load and 60
  IMU slabs, 8,640 ticks), learner alone, best of 9: main 0.131 / 0.132 CPU-s, this build
  0.088 / 0.078 (-33 to -41 %); with per-call timers, load feed 53 -> 30 ms, IMU feed
  25 -> 17 ms, ticks with the window closes 47-50 -> 41-42 ms (of which ~17 ms are the timers
  themselves); default run (log written by this script): 0.071 CPU-s;
- inside an in-process replay of that log (best of 5, the methods timed in place; before the
  row-sum kernel): load feed 54 -> 30 ms, IMU feed 33 -> 21 ms, window closes 50 -> 36 ms
  (Dirlik 39 -> 25 ms): the learner ~137 -> ~86 ms of the replay's 0.695 -> 0.601 CPU-s;
- the whole replay (``/work/wt/_notes/prof.py time 7``, three interleaved pairs at load 8):
  main best 0.710 / 0.676 / 0.704 CPU-s (medians 0.76-0.81), this build 0.655 / 0.624 /
  0.644 (medians 0.67-0.69): -8 % best, -13 to -15 % median;
- the 30-day benchmark log, one ``buoymon replay`` each at load 9: main 22.56 CPU-s, this
  build 21.13 and 20.38 (report and state identical to main's to the last bit); peak RSS
  217 MB / 230 and 222 MB (1 day: 206-207 / 208-210 MB: the kept buffers, ~2 MB).

Where the time went: fresh slab-sized temporaries (a few hundred kB: the concatenated slab,
each numpy step's output) were new pages for the allocator each call, and their page faults
cost several times the arithmetic ((x - mean) * w on 35 x 1024 samples: 280 us fresh, 25 us
in place). The periodograms now run in buffers kept between calls
(models.fatigue.spectral.Periodograms), both components in one batch; a batch's rows are
added to the window's sum by one compiled loop (35 rows: 42 us as a numpy call per row,
8.5 us); the Dirlik integration reuses its quadrature grid.

What is left (each the same bits as before, so kept as it is): pocketfft's transforms (~2 us
per 1,024-sample segment, ~4,200 a day; ``scipy.fft.rfft`` gives the same bits but took 273
against 147 us for 70 segments) and numpy's complex ``abs`` (its SIMD hypot: a compiled
kernel would give other bits); a few elementwise passes over a batch (square, scale, double:
~2 ms a day, which a fused kernel would save but then run per row in numpy when small
replays run uncompiled); the per-slab rate checks (~20 small numpy calls); the Dirlik
density and the S-N curve's damage per cycle on 5,600 quadrature nodes per window and
component (~0.1 ms each); the sea state from the IMU spectrum and the table's update at each
close (models.waves, models.sea_state_table); the ticks' own Python (~0.1 us each).

Run: ``python bench/bench_learner.py [--repeat N] [--log PATH]``.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def record(log: Path) -> tuple[list[tuple[str, tuple]], str]:
    """The learner's constructor arguments and every call the pipeline makes to it, and the
    pipeline's learner's final state (JSON)."""
    import monitor.pipeline as pipeline
    from monitor.config import default_config
    from replay.reader import LogReader
    from replay.runner import run_blocks

    calls: list[tuple[str, tuple]] = []
    inside: list[bool] = []  # within a ticks() call
    built: list = []  # the learner the pipeline built
    base = pipeline.SeaStateLearner

    class Recorder(base):  # type: ignore[misc, valid-type]
        def __init__(self, *args):
            calls.append(("__init__", copy.deepcopy(args)))
            super().__init__(*args)
            built.append(self)

    def recorded(name):
        method = getattr(base, name)

        def call(self, *args):
            if not inside:  # not a tick that ticks() makes itself
                calls.append((name, copy.deepcopy(args) if name != "receive" else ()))
            return method(self, *args)
        return call

    def ticks(self, ends, committed, n_samples, a, b):
        asked: dict[int, dict[str, float]] = {}  # the committed damages the learner asks for

        def ask(q):
            asked[q] = dict(committed(q))
            return asked[q]
        calls.append(("ticks", (ends.copy(), asked, n_samples.copy(), a, b)))
        inside.append(True)
        try:
            return base.ticks(self, ends, ask, n_samples, a, b)
        finally:
            inside.pop()

    for name in ("waves", "load", "motion", "imu", "tick", "hand_over", "receive"):
        setattr(Recorder, name, recorded(name))
    setattr(Recorder, "ticks", ticks)
    setattr(pipeline, "SeaStateLearner", Recorder)  # the class the pipeline builds
    try:
        run_blocks(default_config(), LogReader([log]))
    finally:
        setattr(pipeline, "SeaStateLearner", base)
    return calls, json.dumps(built[-1].state(), sort_keys=True)


def replay_learner(calls, timed: dict[str, float] | None = None):
    """A fresh learner fed the recorded calls; ``timed``: CPU per method (load, imu, ticks,
    ...)."""
    from monitor.sea_state_learner import SeaStateLearner

    learner = SeaStateLearner(*calls[0][1])
    windows: list[dict] = []
    handed: list = []  # hand_over results not yet received (the pipeline's slab queue)
    for name, args in calls[1:]:
        start = time.process_time() if timed is not None else 0.0
        if name == "hand_over":
            handed.append(learner.hand_over())
        elif name == "receive":
            learner.receive(handed.pop(0))
        elif name == "ticks":
            ends, asked, n_samples, a, b = args
            learner.ticks(ends, asked.__getitem__, n_samples, a, b)
        else:
            getattr(learner, name)(*args)
        if timed is not None:
            timed[name] = timed.get(name, 0.0) + time.process_time() - start
        if name in ("tick", "ticks"):
            windows += learner.take_windows()
    return learner, windows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=9)
    ap.add_argument("--log", type=Path, help="a log to replay (default: write the 1-day one)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        log = args.log
        if log is None:
            from bench_replay import write_log

            log = Path(tmp) / "day.mcap"
            write_log(log, 1.0)
        calls, pipeline_state = record(log)
    counts = {n: sum(c[0] == n for c in calls) for n in ("load", "imu", "motion", "ticks")}
    print(f"recorded: {counts}")
    learner, windows = replay_learner(calls)  # warm: imports, the quadrature grid
    # the calls replayed give the pipeline's learner to the bit
    assert json.dumps(learner.state(), sort_keys=True) == pipeline_state
    expect = json.dumps([learner.state(), windows], sort_keys=True)
    best, split = float("inf"), dict[str, float]()
    for _ in range(args.repeat):
        start = time.process_time()
        learner, windows = replay_learner(calls)
        best = min(best, time.process_time() - start)
        assert json.dumps([learner.state(), windows], sort_keys=True) == expect
    for _ in range(args.repeat):
        timed: dict[str, float] = {}
        replay_learner(calls, timed)
        split = {k: min(v, split.get(k, v)) for k, v in timed.items()}
    print(f"learner alone: {len(windows)} windows, CPU best of {args.repeat} {best:.4f} s")
    print("  with per-call timers: " + ", ".join(f"{k} {v * 1e3:.1f} ms"
                                                for k, v in sorted(split.items())))


if __name__ == "__main__":
    main()
