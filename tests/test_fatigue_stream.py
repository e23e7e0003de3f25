"""commit_ticks: the alert-tick pass in one compiled call gives the same bits as
StreamingRainflow.feed + MinerAccumulator.add_cycles per tick."""

from __future__ import annotations

import json

import numpy as np

from models.fatigue import MinerAccumulator, SNCurve, StreamingRainflow, commit_ticks


def test_commit_ticks_equals_feed_and_add_cycles_per_tick():
    rng = np.random.default_rng(21)
    stress = 20e6 + 8e6 * np.sin(np.arange(6000) / 6.0) + rng.normal(0, 1e6, 6000)
    stops = [0, 700, 700, 2500, 4100, 6000]  # an empty first tick and an empty middle one
    times = [10.0 * (i + 1) for i in range(len(stops))]
    sn = SNCurve.vaps_copper()
    # two cycles pending from an earlier block, committed first in the first tick
    pending = (np.array([3e6, 5e6]), np.array([10e6, 12e6]), np.array([1.0, 1.0]))
    rf_a, mi_a = StreamingRainflow(), MinerAccumulator(sn)
    rf_b, mi_b = StreamingRainflow(), MinerAccumulator(sn)
    run = commit_ticks(rf_a, mi_a, stress, stops, times, pending)
    start, committed, rates, residue, closed = 0, [], [], [], []
    for k, (stop, t) in enumerate(zip(stops, times)):
        r, m, c = rf_b.feed(stress[start:stop])
        closed.append(r)
        if k == 0:
            r, c = np.concatenate([pending[0], r]), np.concatenate([pending[2], c])
        mi_b.add_cycles(r, None, c, time_s=t)
        committed.append(mi_b.damage_committed)
        rates.append(mi_b.damage_rate_per_day)
        residue.append(mi_b.residue_damage(rf_b))
        start = stop
    assert run.committed.tolist() == committed and run.rate_per_day.tolist() == rates
    assert run.residue.tolist() == residue
    np.testing.assert_array_equal(run.ranges, np.concatenate(closed))
    assert json.dumps([rf_a.state(), mi_a.state()]) == json.dumps([rf_b.state(), mi_b.state()])
    # no pass for a mean-corrected curve (it commits nominal ranges): the caller runs the
    # per-tick calls
    goodman = sn.with_factors(mean_correction="goodman", ultimate_Pa=250e6)
    assert commit_ticks(StreamingRainflow(), MinerAccumulator(goodman), stress, stops, times) is None
