"""Benchmark: motion -> tension estimator throughput (issue 5 targets).

Targets: >= 1000x real time on 20 Hz data fed in 1 s (20-sample) blocks, and >= 1 M samples/s
in large blocks. The quasi-static model is a QuasiStaticGrid (the estimator's fast path for
any solver); the jerk and finite-line axial increments are on. Prints measured figures.

Run: PYTHONPATH=. python bench/bench_estimator.py
"""

from __future__ import annotations

import time

import numpy as np

from models import waves
from models.dynamics import ElasticDragCord, drag_constant
from models.estimator import EstimatorConfig, LinearisedQuasiStatic, MotionTensionEstimator, QuasiStaticGrid

DT = 0.05


def build():
    linear = LinearisedQuasiStatic(8000.0, 6000.0, 4000.0, 1500.0, 1500.0, 3000.0)
    grid = QuasiStaticGrid.from_function(linear, np.linspace(-1, 5, 61), np.linspace(-2, 2, 41))
    cfg = EstimatorConfig(dt=DT, span=30.0, height=23.0, line_length=40.0, mass_per_length=1.1,
                          ea=3.43e6, drag=ElasticDragCord(drag_constant(1.2, 0.031, 1000.0), 30.0, 0.1, 3.43e6))
    return cfg, grid


def main() -> None:
    cfg, grid = build()
    m = waves.buoy_motion(1.5, 6.0, 3600.0, DT, seed=1, depth=23.0, direction_deg=20.0)
    est = MotionTensionEstimator(cfg, grid)
    est.update(m.heave[:40], m.surge[:40], m.sway[:40])  # warm-up (numba cache load)

    # 1 s blocks of 20 Hz data, displacements.
    n_blocks = m.t.size // 20
    t0 = time.perf_counter()
    for i in range(n_blocks):
        s = slice(i * 20, i * 20 + 20)
        est.update(m.heave[s], m.surge[s], m.sway[s])
    el = time.perf_counter() - t0
    print(f"1 s blocks (displacement): {el / n_blocks * 1e6:8.1f} us/block -> {n_blocks / el:8.0f}x real time")

    # 1 s blocks, IMU accelerations (adds the drift-free double integrator).
    est = MotionTensionEstimator(cfg, grid)
    est.update_accel(m.accel_x[:20], m.accel_y[:20], m.accel_z[:20])
    t0 = time.perf_counter()
    for i in range(n_blocks):
        s = slice(i * 20, i * 20 + 20)
        est.update_accel(m.accel_x[s], m.accel_y[s], m.accel_z[s])
    el = time.perf_counter() - t0
    print(f"1 s blocks (IMU accel):    {el / n_blocks * 1e6:8.1f} us/block -> {n_blocks / el:8.0f}x real time")

    # Large blocks: 2 M samples in one call.
    reps = 28
    big = [np.tile(a, reps)[: 2_000_000] for a in (m.heave, m.surge, m.sway)]
    est = MotionTensionEstimator(cfg, grid)
    rates = []
    for _ in range(3):
        t0 = time.perf_counter()
        est.update(*big)
        rates.append(2e6 / (time.perf_counter() - t0) / 1e6)
    # The first call also pays first-touch page faults for its ~200 MB of outputs.
    print("large block (2 M samples):", ", ".join(f"{r:.2f}" for r in rates), "M samples/s (3 calls)")


if __name__ == "__main__":
    main()
