"""Catenary performance figures (issue 4): run `PYTHONPATH=. python bench/bench_catenary.py`.
All figures are process CPU time (best of a few runs).

Targets: >= 100,000 vectorised line solves per second, a scalar solve < 50 us, and (for the
motion -> tension estimator) >= 1 M TensionTable lookups per second.
"""

from __future__ import annotations

import time

import numpy as np

from models.catenary import TensionTable, solve, solve_line, vaps_mooring


def best_of(fn, repeat: int = 5) -> float:
    """Best process CPU time of `repeat` runs (s): the machine is shared, so CPU time is the
    figure that says what the code costs; wall time only adds other people's load."""
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        times.append(time.process_time() - t0)
    return min(times)


def main() -> None:
    rng = np.random.default_rng(0)
    solve_line(30.0, 20.0, 47.0, 50.0, ea=1e6)  # compile / load the numba cache

    n_scalar = 20000
    x_s = rng.uniform(10.0, 40.0, n_scalar).tolist()

    def scalar_loop():
        for x in x_s:
            solve_line(x, 20.0, 47.0, 50.0, 1e6, True, 0.3)

    t = best_of(scalar_loop, 3)
    print(f"scalar solve_line (seabed, friction, elastic): {t / n_scalar * 1e6:7.2f} us/solve")

    n = 100_000
    # every regime: suspended, grounded (with/without anchor tension), slack piled, near taut
    x = rng.uniform(0.0, 46.0, n)
    z = rng.uniform(0.0, 46.0, n)
    keep = np.hypot(x, z) < 47.0 * 1.005
    x, z = x[keep], z[keep]
    t = best_of(lambda: solve_line(x, z, 47.0, 50.0, ea=1e6, seabed_friction=0.5), 3)
    sol = solve_line(x, z, 47.0, 50.0, ea=1e6, seabed_friction=0.5)
    counts = np.bincount(sol.regime, minlength=5)
    print(f"vectorised solve_line, {x.size} positions (regime counts {counts.tolist()}): "
          f"{x.size / t:,.0f} solves/s")
    xf = rng.uniform(0.0, 60.0, n)
    zf = rng.uniform(-30.0, 30.0, n)
    keep = np.hypot(xf, zf) < 70.0
    t = best_of(lambda: solve_line(xf[keep], zf[keep], 70.0, 50.0, seabed=False), 3)
    print(f"vectorised solve_line, free line (seed 003 type), inextensible: "
          f"{keep.sum() / t:,.0f} solves/s")

    line = vaps_mooring()
    xv = rng.uniform(0.0, 32.0, n)
    zv = rng.uniform(21.0, 25.0, n)
    t = best_of(lambda: solve(line, xv, zv), 3)
    print(f"vectorised solve, seed 004 multi-segment line: {n / t:,.0f} solves/s")
    t = best_of(lambda: [solve(line, xx * 0.8, 23.0) for xx in x_s[:5000]], 3)
    print(f"scalar solve, seed 004 multi-segment line: {t / 5000 * 1e6:7.2f} us/solve")
    # a motion record: 20 s of 10 Hz-sampled surge/heave, consecutive samples close together
    tt = np.arange(n) * 0.01
    xr = 25.0 + 3.0 * np.sin(2 * np.pi * tt / 7.0)
    zr = 23.0 + 0.75 * np.sin(2 * np.pi * tt / 5.0)
    t = best_of(lambda: solve(line, xr, zr), 3)
    print(f"vectorised solve, seed 004 line along a motion record: {n / t:,.0f} solves/s")

    t0 = time.process_time()
    table = TensionTable(line, (0.0, 32.0), (21.0, 25.0))
    build = time.process_time() - t0
    print(f"TensionTable(vaps, x 0..32 m, z 21..25 m): {table.x.size}x{table.z.size} nodes, "
          f"built in {build:.2f} s, max |error| {table.max_error:.3g} N, "
          f"max relative error {table.max_relative_error:.2e}")
    m = 1_000_000
    xm = rng.uniform(0.0, 32.0, m)
    zm = rng.uniform(21.0, 25.0, m)
    table.top_tension(xm[:10], zm[:10])
    t = best_of(lambda: table.top_tension(xm, zm), 3)
    print(f"TensionTable.top_tension, 1e6 samples: {m / t / 1e6:.2f} M samples/s")
    t = best_of(lambda: table.forces(xm, zm, stiffness=True), 3)
    print(f"TensionTable.forces(stiffness=True), 1e6 samples: {m / t / 1e6:.2f} M samples/s")

    try:
        from moorpy.Catenary import catenary
    except ImportError:
        return
    t = best_of(lambda: [catenary(xx, 20.0, 47.0, 1e6, 50.0, CB=0.3) for xx in x_s[:500]], 1)
    print(f"(reference) MoorPy catenary scalar: {t / 500 * 1e6:7.1f} us/solve")


if __name__ == "__main__":
    main()
