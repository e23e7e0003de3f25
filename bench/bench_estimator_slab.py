"""Benchmark: the load source's motion estimate per 30-minute slab of 10 Hz IMU (issue 22, part 5).

The replay feeds the estimator one slab at a time (monitor.pipeline, COALESCE_S = 1800 s:
18,000 IMU samples) and, with the load cell alive (``[load] source = "auto"``), wants the
estimate of the slab's newest sample only; the stream still advances over every sample (the
IMU integration, the chords, the jerk ODE). This script does exactly that with the default
configuration on a simulated sea (models.waves.buoy_motion, Hs 1.5 m, Tp 5.25 s, 4 h = 8
slabs): ``monitor.load_source`` estimator's ``feed`` per slab (the rate tracker, the
estimator, the quasi-static lookup), and the compiled ``_advance`` alone on the same slabs;
CPU time, best of N rounds (first argument, default 15) after a warm-up round.

Measured 2026-11-26 06:55 UTC on the 2-core AMD EPYC (Zen 4, 2.6 GHz nominal) shared with
other jobs (load 7.5-8: figures move by 10-20 % between runs), main 452691c against the
branch est (this script on both, two rounds interleaved, the range of the two):

    per 18,000-sample slab      main 452691c                 est
    feed                        551-574 us (30.6-31.9 ns)    313-357 us (17.4-19.8 ns)
    _advance                    347-352 us (19.3-19.6 ns)    213-215 us (11.8-11.9 ns)

(of which the jerk ODE: 12.9 -> 4.2 ns per sample, four stretches stepped side by side,
models.estimator._jerk_chain; the rest of ``_advance`` is the IMU integration, about 5 ns,
and the chords, about 1.4 ns).

Run: PYTHONPATH=. python bench/bench_estimator_slab.py [N]
"""

from __future__ import annotations

import sys
import time

import numpy as np

from models import estimator, waves
from monitor.config import default_config
from monitor.load_source import build_estimator

SLAB = 18_000  # 30 minutes of 10 Hz IMU


def main() -> None:
    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 15
    m = waves.buoy_motion(1.5, 5.25, 8 * SLAB * 0.1, 0.1, seed=3, depth=23.0,
                          direction_deg=20.0)
    t_ns = np.arange(m.t.size, dtype=np.int64) * 100_000_000 + 1_700_000_000 * 10**9
    fields = {"accel_x_mps2": m.accel_x, "accel_y_mps2": m.accel_y, "accel_z_mps2": m.accel_z}
    slabs = [(t_ns[a:a + SLAB], {k: v[a:a + SLAB] for k, v in fields.items()})
             for a in range(0, t_ns.size, SLAB)]
    want = np.zeros(SLAB, bool)
    want[-1] = True  # the newest sample, for the status (the cell feeds fatigue)
    config = default_config()
    advance = estimator._advance
    spent = [0]

    def timed(*args):
        t0 = time.process_time_ns()
        out = advance(*args)
        spent[0] += time.process_time_ns() - t0
        return out

    best_feed = best_advance = float("inf")
    for r in range(rounds + 1):
        est = build_estimator(config, None, "imu")
        est.feed(*slabs[0], want)  # (the step measured, the integrator settled)
        spent[0] = 0
        estimator._advance = timed
        t0 = time.process_time_ns()
        for t, f in slabs[1:]:
            est.feed(t, f, want)
        elapsed = time.process_time_ns() - t0
        estimator._advance = advance
        if r:  # (the first round warms up)
            best_feed = min(best_feed, elapsed / (len(slabs) - 1))
            best_advance = min(best_advance, spent[0] / (len(slabs) - 1))
    print(f"per {SLAB:,d}-sample slab: feed {best_feed / 1e3:.0f} us "
          f"({best_feed / SLAB:.1f} ns per sample), _advance {best_advance / 1e3:.0f} us "
          f"({best_advance / SLAB:.1f} ns per sample); CPU, best of {rounds}")


if __name__ == "__main__":
    main()
