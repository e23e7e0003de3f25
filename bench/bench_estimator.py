"""Benchmark: motion -> tension estimator throughput (issue 5 targets).

Targets: >= 1000x real time on 20 Hz data fed in 1 s (20-sample) blocks, and >= 1 M samples/s
in large blocks. Two quasi-static models: the seed 004 catenary (TensionTable, the real
configuration) and a linearised one (to show the estimator's own cost). The jerk and
finite-line axial increments are on. Prints measured figures.

Run: PYTHONPATH=. python bench/bench_estimator.py
"""

from __future__ import annotations

import time

import numpy as np

from models import waves
from models.estimator import LinearisedQuasiStatic, MotionTensionEstimator, seed004_estimator

DT = 0.05


def run(name, cfg, qs, m) -> None:
    est = MotionTensionEstimator(cfg, qs)
    est.update(m.heave[:40], m.surge[:40], m.sway[:40])  # warm-up (numba cache load)
    n_blocks = m.t.size // 20
    t0 = time.perf_counter()
    for i in range(n_blocks):
        s = slice(i * 20, i * 20 + 20)
        est.update(m.heave[s], m.surge[s], m.sway[s])
    el = time.perf_counter() - t0
    print(f"[{name}] 1 s blocks (displacement): {el / n_blocks * 1e6:8.1f} us/block"
          f" -> {n_blocks / el:8.0f}x real time")

    est = MotionTensionEstimator(cfg, qs)
    est.update_accel(m.accel_x[:20], m.accel_y[:20], m.accel_z[:20])
    t0 = time.perf_counter()
    for i in range(n_blocks):
        s = slice(i * 20, i * 20 + 20)
        est.update_accel(m.accel_x[s], m.accel_y[s], m.accel_z[s])
    el = time.perf_counter() - t0
    print(f"[{name}] 1 s blocks (IMU accel):    {el / n_blocks * 1e6:8.1f} us/block"
          f" -> {n_blocks / el:8.0f}x real time")

    big = [np.tile(a, 28)[:2_000_000] for a in (m.heave, m.surge, m.sway)]
    est = MotionTensionEstimator(cfg, qs)
    rates = []
    for _ in range(3):
        t0 = time.perf_counter()
        est.update(*big)
        rates.append(2e6 / (time.perf_counter() - t0) / 1e6)
    # The first call also pays first-touch page faults for its ~200 MB of outputs.
    print(f"[{name}] large block (2 M samples):", ", ".join(f"{r:.2f}" for r in rates),
          "M samples/s (3 calls)")


def main() -> None:
    m = waves.buoy_motion(1.5, 5.25, 3600.0, DT, seed=1, depth=23.0, direction_deg=20.0)
    t0 = time.perf_counter()
    cfg, qs = seed004_estimator(dt=DT)
    print(f"seed 004 estimator build (catenary table): {time.perf_counter() - t0:.2f} s")
    run("seed004 catenary", cfg, qs, m)
    lin = LinearisedQuasiStatic(220.0, 150.0, 60.0, 40.0, 40.0, 60.0)
    run("linearised", cfg, lin, m)


if __name__ == "__main__":
    main()
