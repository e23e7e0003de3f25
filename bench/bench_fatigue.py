"""Throughput of the hot path tension -> conductor stress -> streaming rainflow -> Miner.

Signal: 1e7 samples at 20 Hz of a wave-like tension (6 s waves, a slow group envelope and
sensor noise). Prints samples per second for large blocks and for 20-sample blocks (one
second of data per call, as the service feeds it), per backend. Targets (issue 3): >= 50 M
samples/s in large blocks, >= 1 M samples/s in 20-sample blocks, on one core.

Run: PYTHONPATH=. python bench/bench_fatigue.py [n_samples]
"""

from __future__ import annotations

import sys
import time

import numpy as np

from models.fatigue import MinerAccumulator, SNCurve, StreamingRainflow
from models.helix import HelixCable, conductor_stress


def wave_tension(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 20.0
    return (6e3 + 2.5e3 * np.sin(2 * np.pi * t / 6.0) * (1 + 0.3 * np.sin(2 * np.pi * t / 300.0))
            + 150.0 * rng.normal(size=n))


def run(tension: np.ndarray, block: int, backend: str) -> tuple[float, float]:
    """Seconds for the whole path over ``tension`` in blocks of ``block``; final damage."""
    cable = HelixCable.vaps_biw()
    rf = StreamingRainflow(backend=backend)
    miner = MinerAccumulator(SNCurve.vaps_copper(), backend=backend)
    blocks = [tension[i:i + block] for i in range(0, tension.size, block)]
    t0 = time.perf_counter()
    for k, b in enumerate(blocks):
        stress = conductor_stress(b, cable, "left")
        r, m, c = rf.feed(stress)
        miner.add_cycles(r, c, m, time_s=k * block / 20.0)
    elapsed = time.perf_counter() - t0
    return elapsed, miner.damage_committed


def main() -> None:
    n = int(float(sys.argv[1])) if len(sys.argv) > 1 else 10_000_000
    tension = wave_tension(n)
    run(tension[:1000], 20, "numba")  # compile / load the numba cache outside the timing
    print(f"samples: {n:.3g} (20 Hz, 6 s waves + noise)")
    results = {}
    for backend, block in (("numba", n), ("numba", 1_000_000), ("numba", 20), ("numpy", 1_000_000), ("numpy", 20)):
        if backend == "numpy" and block == 20:
            sub = tension[: min(n, 1_000_000)]  # the fallback is slow per call: a shorter run
        else:
            sub = tension
        best = min((run(sub, block, backend) for _ in range(2)), key=lambda r: r[0])
        results[(backend, block)] = best[1]
        print(f"{backend:6s} block {block:>9d}: {sub.size / best[0] / 1e6:8.2f} M samples/s "
              f"({best[0] / (sub.size / block) * 1e6:9.2f} us/call), damage {best[1]:.6e}")
    same = results[("numba", n)] == results[("numba", 1_000_000)] == results[("numba", 20)]
    print(f"numba damage identical across block sizes: {same}")


if __name__ == "__main__":
    main()
