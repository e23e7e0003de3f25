"""Small synthetic buoy data for the core tests: a 5.25 s swell seen by three sensors."""

import numpy as np

from monitor.blocks import SENSOR_FIELDS, SampleBlock

S = 1_000_000_000
T0 = 1_700_000_000 * S  # a whole multiple of the 10 s alert tick


def sea(duration_s, seed=3, gap=None):
    """Tension 20 Hz, IMU 10 Hz and GNSS 1 Hz of a 5.25 s swell, with faults sprinkled in."""
    rng = np.random.default_rng(seed)
    out = {}
    for sensor, hz in (("tension", 20), ("imu", 10), ("gnss", 1)):
        n = int(duration_s * hz)
        t = T0 + (np.arange(n, dtype=np.int64) * S) // hz
        x = np.arange(n) / hz
        if sensor == "tension":
            v = {"tension_N": 5000 + 2500 * np.sin(2 * np.pi * x / 5.25)
                 + 600 * np.sin(2 * np.pi * x / 31) + rng.normal(0, 150, n)}
            v["tension_N"][rng.integers(0, n, 20)] = np.nan
            v["tension_N"][rng.integers(0, n, 20)] += 40_000  # spikes
            if gap is not None:
                keep = (x < gap[0]) | (x >= gap[1])
                t, v = t[keep], {k: a[keep] for k, a in v.items()}
        elif sensor == "imu":
            v = {"accel_x_mps2": rng.normal(0, 0.1, n), "accel_y_mps2": rng.normal(0, 0.1, n),
                 "accel_z_mps2": 2.0 * np.sin(2 * np.pi * x / 5.25 + 0.3)}
        else:
            v = {"lat_deg": 41.85 + rng.normal(0, 1e-5, n), "lon_deg": -82.4 + rng.normal(0, 1e-5, n)}
        out[sensor] = (t, v)
    return out


def blocks_interleaved(data, block_s):
    """Live-like: every stream cut into block_s blocks, interleaved by block start time."""
    items = []
    for sensor, (t, v) in data.items():
        edges = np.searchsorted(t, T0 + np.arange(0, (t[-1] - T0) // S + block_s + 1, block_s) * S)
        for a, b in zip(edges[:-1], edges[1:]):
            if b > a:
                items.append((int(t[a]), sensor, SampleBlock("vaps", sensor, t[a:b],
                                                             {k: x[a:b] for k, x in v.items()})))
    items.sort(key=lambda i: (i[0], list(SENSOR_FIELDS).index(i[1])))
    return [b for _, _, b in items]
