"""The per-tick fast paths give the same bits as the general code they shortcut: the
cached damage rate of ``MinerAccumulator`` against a fresh accumulator restored from the same
state (which recomputes it from scratch).
"""

from __future__ import annotations

import numpy as np

from models.fatigue.miner import MinerAccumulator
from models.fatigue.sn_curve import SNCurve

def test_cached_damage_rate_equals_a_fresh_computation():
    rng = np.random.default_rng(5)
    acc = MinerAccumulator(SNCurve.vaps_copper(), rate_window_s=3600.0, rate_buckets=6)
    t = 0.0
    for _ in range(2000):
        t += float(rng.choice([0.0, 10.0, 700.0]))
        acc.add_cycles(rng.uniform(0.0, 60e6, int(rng.integers(0, 4))), None, 1.0, time_s=t)
        rate = acc.damage_rate_per_day
        assert rate == acc.damage_rate_per_day  # a second read is the cached value
        assert rate == MinerAccumulator.from_state(acc.state()).damage_rate_per_day
