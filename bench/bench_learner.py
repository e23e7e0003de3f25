"""The sea-state learner's own cost (monitor.sea_state_learner, issue 22 parts 3 and 5).

Writes the 1-day log of ``bench_replay.py`` (20 Hz tension, 10 Hz IMU), replays it once
through the pipeline with the learner's calls recorded as the pipeline makes them (the
slabs' load stresses and IMU accelerations, the hand-over of each slab's inputs and their
taking, the ticks with the committed damages the learner asks for), checks that feeding
those calls to a fresh learner gives the pipeline's learner state to the bit, then feeds
them again and again: CPU time best of N, split per method (the Welch feed of the load and
IMU slabs; ``ticks``, which closes the windows: periodograms, Dirlik damage of each
component, the sea state, the table). Prints those, and checks the learned table and
windows are the same each time.

Measured 2026-11-25 21:20-21:50 UTC on the 2-core development machine (shared with other
jobs, load average 3.5-6.8: only best-of-N CPU times compare), main c8bad01 and this build
(87ebf8d; later commits add only a comparison per slab) interleaved, on the lead's 1-day
golden log (48 windows, 123 load and 60 IMU slabs):

- learner alone, best of 7, six pairs: main 0.059 / 0.065 / 0.068 / 0.069 / 0.084 / 0.063
  CPU-s, this build 0.033 / 0.034 / 0.035 / 0.050 / 0.035 / 0.035 (about -45 %, 1.8x);
  per method (with timers): load feed 24-28 -> 6-7.6 ms, IMU feed 12-14.5 -> 2.9-4.1 ms,
  hand-over 1.8-2.7 -> 0.9-1.4 ms, ticks 24-30 -> 23-35 ms (the periodograms moved there:
  computed when a window is taken);
- the whole replay in process (``/work/wt/_notes/prof.py time 7``), four pairs: main best
  0.412 / 0.413 / 0.415 / 0.449 CPU-s, this build 0.390 / 0.370 / 0.362 / 0.426; on one
  core without the read-ahead thread (``taskset -c 0``, best of 5), five pairs: main 0.403 /
  0.391 / 0.439 / 0.443 / 0.437, this build 0.388 / 0.366 / 0.397 / 0.439 / 0.389 (-1 to
  -13 %, about 0.03 CPU-s a day);
- the 30-day benchmark log (``/work/wt/_notes/golden30.sh``, load 4.6-6.5): report and state
  identical to main's to the last bit; 14.5-15.7 CPU-s for the whole command under that
  load, 227-232 MB peak RSS.

The 3x asked of the learner is not reached: about 1.8x. What it costs now (1 day,
best of 5, timers around the parts): numpy's FFT of the 2,530 kept segments and their
complex ``abs`` (~8 ms, numpy's own SIMD code: anything else gives other bits), the
detrend/window loop (numpy's pairwise mean replicated, ~1.8 ms), the copy of each
segment into the window's rows (~2.6 ms), the S-N curve's damage per quadrature node
(``SNCurve.damage_per_cycle``, ~2.7 ms: log and exp per node), the IMU sea state
(``models.waves.sea_state_from_psd``, ~2.7 ms) and the table's update
(``models.sea_state_table``, ~2 ms), then Python glue (~8 ms). Earlier builds of this
script recorded ``tick`` but not ``ticks``, ``hand_over`` or ``receive``, so their closes
saw no spectra: their "ticks" figures left the Dirlik integration out.

What changed: a window's segments are kept as they complete and transformed when the
window is taken, one batch per window instead of one per slab
(``models.fatigue.spectral.Periodograms.add``); the detrend/window, power sums, segment
rate checks, spectral moments, Dirlik density and damage sum are compiled loops with
numpy's bits (``models.fatigue._spectral_loops``: numpy's pairwise summation replicated;
numpy's exp, FFT and complex abs kept); the frequency terms of the moments are cached per
grid; components whose stresses are equal to the bit (the default conductor and its
termination) are transformed and integrated once.

Part 5 (2026-11-26 06:26-06:27 UTC, load average 6.5-7.0: best-of-N CPU only), on a day of
the fleet archive (``--log /tmp/perf_fleet/buoy002/day_0001.mcap``: 48 windows), main
452691c and this build interleaved, best of 9, three pairs: learner alone main 0.0431 /
0.0403 / 0.0408 CPU-s, this build 0.0303 / 0.0324 / 0.0329 (-20 to -30 %); ticks 30.0-30.8
-> 23.0-23.3 ms, hand-over 0.9-1.0 -> 0.3 ms, the feeds unchanged (load 5.5-5.8 -> 5.0-5.2,
IMU 3.7-3.8 -> 3.2-3.5 ms). What changed: the IMU/heave sea state in one compiled pass
(``models.waves.sea_state_from_psd`` over ``_spectral_loops.band_moments``: 38 -> 9 us a
window, hot), Dirlik's damage rate with its coefficients once, one ``np.exp`` call and the
density fused into the weighted sum (68 -> 61 us), the table's update with scalar bins
(23 -> 10 us), the heave/IMU periodograms only when the sea state needs them, the
hand-over's snapshot a direct shallow copy. What is left is mostly numpy's FFT and complex
``abs`` (about half of ``ticks``: with them moved to the feed, ``ticks`` halved and the
feeds grew by as much), the S-N curve's log and exp per quadrature node (~20 us a window)
and numpy's exp (~8 us), all with bits that must stay numpy's or the curve's; the 50 % cut
asked of this slice is not reached.

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
