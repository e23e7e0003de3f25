"""Cost of the Rerun sink in a replay-like bulk run, with and without an .rrd recording.

A replay drives the pipeline core with steps of buffered blocks; the sink's cost per day of
20 Hz tension is measured for several step sizes and both option presets, next to a stand-in
replay (stress per component + rainflow counting with the ``rainflow`` package per step) run
without the sink. Also reported: the ratio against the replay throughput target of 3 M
samples/s (issue 2), the budget that ``--rrd`` may at most double.

Run: PYTHONPATH=. python bench/bench_viz.py [--days D]
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time

import numpy as np
import rainflow

from monitor.events import ComponentStep, StepResult
from monitor.viz.rerun_options import RerunOptions
from monitor.viz.rerun_outputs import open_recording
from monitor.viz.rerun_sink import RerunSink

RATE_HZ = 20
T0_NS = 1_700_000_000_000_000_000
TARGET_SAMPLES_PER_S = 3e6
COMPONENTS = {"left_lay": 2000.0, "right_lay": 1000.0}  # Pa per N


def series(days: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    n = int(days * 86400 * RATE_HZ)
    i = np.arange(n)
    rng = np.random.default_rng(seed)
    tension = 5000 + 1500 * np.sin(2 * np.pi * i / (RATE_HZ * 5.25)) + rng.normal(0, 100, n)
    return T0_NS + i * (1_000_000_000 // RATE_HZ), tension


def steps(t: np.ndarray, tension: np.ndarray, step_s: float, count_cycles: bool):
    """Replay-like steps; with count_cycles the rainflow work is part of the timed loop."""
    n = int(step_s * RATE_HZ)
    damage = 0.0
    for k in range(0, len(t), n):
        tt, tn = t[k:k + n], tension[k:k + n]
        comps = {}
        for name, kpa in COMPONENTS.items():
            stress = tn * kpa
            if count_cycles:
                cyc = np.array([c[:3] for c in rainflow.extract_cycles(stress)]).reshape(-1, 3)
            else:
                cyc = np.zeros((0, 3))
            damage += 1e-9 * len(cyc)
            comps[name] = ComponentStep(name, stress, cyc[:, 0], cyc[:, 1], cyc[:, 2], damage * 1.1,
                                        damage, 1e-3, 1e4, float(stress.max()))
        yield StepResult("B1", "tension", int(tt[-1]), tt, tn, "measured", float(tn[-1]),
                         float("nan"), comps, len(tt), {}, [])


def run(t, tension, step_s: float, options: RerunOptions, path: str, repeats: int = 1
        ) -> tuple[float, float]:
    """Best (wall, CPU) seconds of the sink over ``repeats`` runs (CPU includes rerun's
    encoder/writer threads; on a shared machine wall time is inflated by other load)."""
    # the steps (with their rainflow cycles) are built outside the timed sink loop
    all_steps = list(steps(t, tension, step_s, count_cycles=True))
    best = (math.inf, math.inf)
    for _ in range(repeats):
        sink = RerunSink(open_recording("B1", options, rrd=path), options)
        w0, c0 = time.perf_counter(), time.process_time()
        for s in all_steps:
            sink.on_step(s)
        sink.close()
        best = min(best, (time.perf_counter() - w0, time.process_time() - c0))
    return best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--days", type=float, default=1.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    t, tension = series(args.days)
    n = len(t)
    t0 = time.perf_counter()
    for _ in steps(t, tension, 600.0, count_cycles=True):
        pass
    standin = time.perf_counter() - t0
    target = n / TARGET_SAMPLES_PER_S
    print(f"{args.days:g} day(s), {n:,} tension samples at 20 Hz, 2 components; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"stand-in replay without sink (rainflow pkg, 600 s steps): {standin:.2f} s "
          f"({n / standin / 1e6:.2f} M samples/s); replay target time at 3 M/s: {target:.2f} s")
    with tempfile.TemporaryDirectory() as tmp:
        warm, _ = run(t[:72000], tension[:72000], 60.0, RerunOptions(), os.path.join(tmp, "w.rrd"))
        print(f"first use of rerun in the process (one-off start-up, 1 h of data): {warm:.2f} s")
        opts = RerunOptions().for_replay()
        for step_s in (60.0, 600.0, 3600.0):
            path = os.path.join(tmp, f"b_{step_s:g}.rrd")
            wall, cpu = run(t, tension, step_s, opts, path, args.repeats)
            size = os.path.getsize(path) / 1e6
            print(f"  --rrd (replay preset), steps {step_s:5g} s: sink wall {wall:5.2f} s "
                  f"({n / wall / 1e6:4.1f} M samples/s), CPU {cpu:5.2f} s, .rrd {size:5.1f} MB; "
                  f"replay with/without: vs stand-in {(standin + wall) / standin:4.2f}x, "
                  f"vs 3 M/s target {(target + wall) / target:4.2f}x (CPU-based "
                  f"{(target + cpu) / target:4.2f}x)")
        hour = 72000
        wall, cpu = run(t[:hour], tension[:hour], 1.0, RerunOptions(),
                        os.path.join(tmp, "live.rrd"), args.repeats)
        print(f"  live preset, 1-s steps (1 h): {wall / 3600 * 1e3:.2f} ms wall, "
              f"{cpu / 3600 * 1e3:.2f} ms CPU per step (= per second of live data)")


if __name__ == "__main__":
    main()
