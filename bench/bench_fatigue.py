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


def run(tension: np.ndarray, block: int, backend: str) -> tuple[float, float, float]:
    """(wall s, CPU s, final damage) for the whole path over ``tension`` in ``block``s."""
    cable = HelixCable.vaps_biw()
    rf = StreamingRainflow(backend=backend)
    miner = MinerAccumulator(SNCurve.vaps_copper(), backend=backend)
    blocks = [tension[i:i + block] for i in range(0, tension.size, block)]
    t0, c0 = time.perf_counter(), time.process_time()
    for k, b in enumerate(blocks):
        stress = conductor_stress(b, cable, "left", backend=backend)
        r, m, c = rf.feed(stress)
        miner.add_cycles(r, c, m, time_s=k * block / 20.0)
    return time.perf_counter() - t0, time.process_time() - c0, miner.damage_committed


def main() -> None:
    n = int(float(sys.argv[1])) if len(sys.argv) > 1 else 10_000_000
    tension = wave_tension(n)
    run(tension[:1000], 20, "numba")  # compile / load the numba cache outside the timing
    print(f"samples: {n:.3g} (20 Hz, 6 s waves + noise); best of 3 runs; CPU time excludes")
    print("waiting for a core on a shared machine (load average now "
          f"{' '.join(f'{v:.1f}' for v in __import__('os').getloadavg())})")
    damages = {}
    cases = [("numba", n), ("numba", 1_000_000), ("numba", 100_000), ("numba", 20),
             ("numpy", 100_000), ("numpy", 20)]
    for backend, block in cases:
        # the numpy fallback is slow per call: a shorter run for its 20-sample case
        sub = tension[: min(n, 200_000)] if (backend, block) == ("numpy", 20) else tension
        runs = [run(sub, block, backend) for _ in range(3)]
        wall = min(r[0] for r in runs)
        cpu = min(r[1] for r in runs)
        damages[(backend, block)] = runs[0][2]
        calls = -(-sub.size // block)
        print(f"{backend:6s} block {block:>9d}: {sub.size / wall / 1e6:7.2f} M samples/s wall, "
              f"{sub.size / cpu / 1e6:7.2f} M samples/s CPU ({wall / calls * 1e6:10.2f} us/call)")
    numba_runs = {v for (b, _), v in damages.items() if b == "numba"}
    print(f"committed damage {damages[('numba', n)]:.9e}; identical for all numba block sizes: "
          f"{len(numba_runs) == 1}")
    print(f"numba vs numpy (100k blocks) relative difference: "
          f"{abs(damages[('numba', 100_000)] / damages[('numpy', 100_000)] - 1):.1e}")


if __name__ == "__main__":
    main()
