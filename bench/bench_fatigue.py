"""Throughput of the hot path tension -> conductor stress -> streaming rainflow -> Miner.

Signal: 1e7 samples at 20 Hz of a wave-like tension (6 s waves, a slow group envelope and
sensor noise; about 2.9 million closed cycles). Prints samples per second for large blocks
and for 20-sample blocks (one second of data per call, as the service feeds it), for

- ``separate``: ``conductor_stress`` + ``StreamingRainflow.feed`` + ``MinerAccumulator.add_cycles``
  (the library path; the monitor's is ``models.fatigue.commit_ticks``);

then the CPU time of each separate stage on the whole series in one block. Targets
(issue 3): >= 50 M samples/s in large blocks (1e6, 1e7), >= 1 M samples/s in 20-sample
blocks, on one core.

Measured 2026-11-21 on the shared 2-core Xeon (Emerald Rapids, 2.3 GHz, load average
1.4-1.8 from other work), CPU time, best of 3, M samples/s; "before" is the code before the
deterministic log/exp, the chunked Miner loop and the short-chain turning-point pass:

    path      backend  block 1e7  block 1e6  block 1e5  block 20
    before    numba        32.8       39.5       42.3      2.92
    separate  numba        69.1       89.4      101.7      3.22
    fused     numba       124.5      120.7      117.6      7.45
    before    numpy           -          -        1.07     0.21
    separate  numpy           -          -        1.38     0.14

    stages on 1e7 samples (separate, one block), before -> after:
    conductor_stress 299 -> 292 M samples/s (mostly first touch of the 80 MB result),
    StreamingRainflow.feed 71 -> 123 M samples/s,
    MinerAccumulator.add_cycles 104 -> 295 M samples/s (33.5 -> 11.8 ns per cycle)

The numba and numpy backends now give the same committed damage to the last bit (before:
2e-16 apart). The numpy fallback is slower on tiny blocks because its log/exp are some
30 numpy operations per call (the price of matching the compiled bits); since issue 18 it is
no longer a production backend but the tests' oracle (tests/fatigue_oracles.py). With hysteresis
> 0 the turning-point pass has a longer dependency chain: fused about 70 M samples/s.
The compiled fused loop showed packed vdivpd/vsqrtpd on ymm registers (LLVM prefers
256-bit vectors on this CPU): the stress and log/exp loops vectorise. The fused path
(``FatigueStream``) ran only here and in tests and was deleted (issue 18, 2026-11-25); the
vector check now inspects the Miner commit loop.

Issue 22 (the library path against pyLife, same run): measured 2026-11-25 on the same
machine, load average 6-8 from other work (wall times wait for a core: CPU is the fair
figure), M samples/s:

    separate numba, one block of 1e7: 91 -> 127.5 CPU (60.3 wall)
    stages: conductor_stress 588 -> 741, StreamingRainflow.feed 144 -> 231,
            MinerAccumulator.add_cycles 430 -> 460 (unchanged code: noise; 7.6 ns per cycle)
    pyLife 2.3.1 FourPointDetector.process (LoopValueRecorder), same tensions: 59-71 CPU
            over the session's runs; in the final run 70.7 CPU, 24.3 wall: ratio 1.80x
            CPU, 1.72x wall (before: 1.54x CPU; target 1.5x); after merging main (load
            average 5): ours 131.4 CPU / 130.6 wall, pyLife 71.8 / 71.3: 1.83x both

What changed: the counter's cycle output is allocated by numpy, which advises large
arrays for transparent huge pages (numba's own allocations fault in 4 kB pages: 22 ms of
a 75 ms feed of 1e7 samples), and conductor_stress flags non-finite stresses in its
arithmetic loop instead of a second pass. The block-20 figure is unchanged within the
noise (3.31 M samples/s CPU). Tried and dropped: the first two four-point
tests of a turning point without a branch (feed 231 -> 87: the pops' store-to-load chain
is longer than the mispredictions it avoids).

Run: PYTHONPATH=. python bench/bench_fatigue.py [n_samples]
"""

from __future__ import annotations

import os
import re
import sys
import time

import numpy as np

from models.fatigue import _loops as _fatigue_loops
from models._jit import numba_module
from models.fatigue import MinerAccumulator, SNCurve, StreamingRainflow
from models.helix import HelixCable, conductor_stress


def wave_tension(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 20.0
    return (6e3 + 2.5e3 * np.sin(2 * np.pi * t / 6.0) * (1 + 0.3 * np.sin(2 * np.pi * t / 300.0))
            + 150.0 * rng.normal(size=n))


def run(tension: np.ndarray, block: int) -> tuple[float, float, float]:
    """(wall s, CPU s, final damage) for the whole path over ``tension`` in ``block``s."""
    cable = HelixCable.vaps_biw()
    rf = StreamingRainflow()
    miner = MinerAccumulator(SNCurve.vaps_copper())
    blocks = [tension[i:i + block] for i in range(0, tension.size, block)]
    t0, c0 = time.perf_counter(), time.process_time()
    for k, b in enumerate(blocks):
        stress = conductor_stress(b, cable, "left")
        miner.add_cycles(*rf.feed(stress), time_s=k * block / 20.0)
    return time.perf_counter() - t0, time.process_time() - c0, miner.damage_committed


def best_cpu(func, repeats: int = 3) -> tuple[float, object]:
    """(best CPU time, last result) of ``func()``."""
    best, result = np.inf, None
    for _ in range(repeats):
        c0 = time.process_time()
        result = func()
        best = min(best, time.process_time() - c0)
    return best, result


def stage_split(tension: np.ndarray) -> None:
    """CPU time of each separate stage over the whole series in one block."""
    cable = HelixCable.vaps_biw()
    t_stress, stress = best_cpu(lambda: conductor_stress(tension, cable, "left"))
    t_feed, (ranges, means, counts) = best_cpu(lambda: StreamingRainflow().feed(stress))
    t_add, _ = best_cpu(lambda: MinerAccumulator(SNCurve.vaps_copper()).add_cycles(ranges, means, counts))
    n = tension.size
    print(f"stages (one block, CPU): conductor_stress {n / t_stress / 1e6:.0f} M samples/s, "
          f"StreamingRainflow.feed {n / t_feed / 1e6:.0f} M samples/s, MinerAccumulator.add_cycles "
          f"{n / t_add / 1e6:.0f} M samples/s ({t_add / ranges.size * 1e9:.1f} ns per cycle, "
          f"{ranges.size} cycles)")


def versus_pylife(tension: np.ndarray, repeats: int = 5) -> None:
    """The library path in one block (``run``: stress, counting and Miner damage) against
    pyLife's compiled ``FourPointDetector`` counting the same tensions into a
    ``LoopValueRecorder`` (detection only), runs interleaved so that both see the same load
    of the shared machine; best of ``repeats`` each, and their ratio (issue 22: >= 1.5x)."""
    try:
        import pylife.stress.rainflow as pylife_rf
    except ImportError:
        print("pyLife is not installed (pip install pylife): no comparison")
        return

    def pylife_run() -> tuple[float, float, int]:
        t0, c0 = time.perf_counter(), time.process_time()
        detector = pylife_rf.FourPointDetector(recorder=pylife_rf.LoopValueRecorder())
        detector.process(tension)
        return (time.perf_counter() - t0, time.process_time() - c0,
                len(detector.recorder.values_from))

    pylife_run()  # first call: pandas and the extension load
    ours, theirs = [], []
    for _ in range(repeats):
        theirs.append(pylife_run())
        ours.append(run(tension, tension.size))
    n = tension.size
    rates = {name: (n / min(r[0] for r in runs) / 1e6, n / min(r[1] for r in runs) / 1e6)
             for name, runs in (("ours", ours), ("pylife", theirs))}
    cycles = len(StreamingRainflow().feed(conductor_stress(tension, HelixCable.vaps_biw(), "left"))[0])
    print(f"library path, one block of {n:.3g}: {rates['ours'][0]:.1f} M samples/s wall, "
          f"{rates['ours'][1]:.1f} CPU ({cycles} cycles); pyLife FourPointDetector.process: "
          f"{rates['pylife'][0]:.1f} wall, {rates['pylife'][1]:.1f} CPU ({theirs[0][2]} cycles)")
    print(f"ratio to pyLife in this run: {rates['ours'][0] / rates['pylife'][0]:.2f}x wall, "
          f"{rates['ours'][1] / rates['pylife'][1]:.2f}x CPU")


def vector_instructions() -> str:
    """Packed divide/sqrt instructions in a fresh (uncached, so inspectable) compilation of
    the Miner commit loop: the damage pass's log/exp vectorise when these show ymm/zmm
    registers."""
    loop = numba_module().njit(error_model="numpy")(_fatigue_loops.commit_loop)
    miner = MinerAccumulator(SNCurve.vaps_copper())
    loop(np.linspace(1e6, 60e6, 100), np.ones(100), miner._params, miner._table, miner._inv_width, 0.0)
    asm = loop.inspect_asm(loop.signatures[0])
    found = sorted(set(re.findall(r"\b(v(?:div|sqrt)p[sd])\s+%([xyz])mm", asm)))
    return ", ".join(f"{op} {reg}mm" for op, reg in found) or "none"


def main() -> None:
    n = int(float(sys.argv[1])) if len(sys.argv) > 1 else 10_000_000
    tension = wave_tension(n)
    run(tension[:1000], 20)  # compile / load the numba cache outside the timing
    print(f"samples: {n:.3g} (20 Hz, 6 s waves + noise); best of 3 runs; CPU time excludes")
    print(f"waiting for a core on a shared machine (load average now "
          f"{' '.join(f'{v:.1f}' for v in os.getloadavg())})")
    damages = {}
    for block in (n, 1_000_000, 100_000, 20):
        runs = [run(tension, block) for _ in range(3)]
        wall = min(r[0] for r in runs)
        cpu = min(r[1] for r in runs)
        damages[block] = runs[0][2]
        calls = -(-tension.size // block)
        print(f"block {block:>9d}: {tension.size / wall / 1e6:7.2f} M samples/s wall, "
              f"{tension.size / cpu / 1e6:7.2f} M samples/s CPU ({wall / calls * 1e6:10.2f} us/call)")
    print(f"committed damage {damages[n]:.9e}; identical for all block sizes: "
          f"{len(set(damages.values())) == 1}")
    stage_split(tension)
    versus_pylife(tension)
    print(f"packed divide/sqrt in the compiled commit loop: {vector_instructions()}")


if __name__ == "__main__":
    main()
