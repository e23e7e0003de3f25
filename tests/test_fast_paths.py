"""The per-tick fast paths give the same bits as the general code they shortcut.

``SNCurve.damage_of_valid`` (compiled segment lookup, numpy power) against
``damage_per_cycle``; the cached damage rate of ``MinerAccumulator`` against a fresh
accumulator restored from the same state (which recomputes it from scratch).
"""

from __future__ import annotations

import numpy as np
import pytest

from models.miner import MinerAccumulator
from models.sn_curve import SNCurve

CURVES = [
    SNCurve.vaps_copper(),
    SNCurve.vaps_copper(low_stress="cutoff", derating=2.0, scf=1.3),
    SNCurve.vaps_copper(low_stress="miner", dff=3.0),
    SNCurve.dnv_chain_studless(scf=1.3, derating=2.0, dff=3.0),
    SNCurve.dnv_rp_c203("D", "seawater_cp", scf=1.1),
    # exponents numpy special-cases when given as a scalar (square, square root)
    SNCurve.basquin(2.0, 12.0),
    SNCurve.basquin(0.5, 3.0, low_stress="cutoff", endurance_MPa=20.0),
    SNCurve.multi_slope((2.0, 0.5), (10.0, 6.0)),
]


@pytest.mark.parametrize("curve", CURVES, ids=lambda c: c.name)
def test_damage_of_valid_is_damage_per_cycle_bit_for_bit(curve):
    rng = np.random.default_rng(11)
    for n in (1, 2, 3, 8, 17, 5000):
        ranges = rng.uniform(0.0, 80e6, n) * rng.choice([0.01, 0.1, 1.0, 3.0], n)
        ranges[0] = 0.0
        counts = rng.choice([0.5, 1.0], n)
        expected = curve.damage_per_cycle(ranges, counts)
        assert curve.damage_of_valid(ranges, counts, ranges).tobytes() == expected.tobytes()
    # a hand value: DNV chain, 100 MPa nominal x scf 1.3 x derating 2 -> 260 MPa,
    # N = 6e10 / 260**3, damage = dff / N
    chain = CURVES[3]
    d = chain.damage_of_valid(np.array([100e6]), np.array([1.0]), np.array([0.0]))
    assert d[0] == pytest.approx(3.0 * 260.0 ** 3 / 6.0e10, rel=1e-12)


def test_cached_damage_rate_equals_a_fresh_computation():
    rng = np.random.default_rng(5)
    acc = MinerAccumulator(SNCurve.vaps_copper(), rate_window_s=3600.0, rate_buckets=6)
    t = 0.0
    for _ in range(2000):
        t += float(rng.choice([0.0, 10.0, 700.0]))
        acc.add_cycles(rng.uniform(0.0, 60e6, int(rng.integers(0, 4))), 1.0, time_s=t)
        rate = acc.damage_rate_per_day
        assert rate == acc.damage_rate_per_day  # a second read is the cached value
        assert rate == MinerAccumulator.from_state(acc.state()).damage_rate_per_day
