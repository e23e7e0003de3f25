"""commit_ticks: the alert-tick pass in one compiled call gives the same bits as
StreamingRainflow.feed + MinerAccumulator.add_cycles per tick."""

from __future__ import annotations

import contextlib
import json

import numpy as np
import pytest

from models._jit import uncompiled
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


def _per_tick(stress, stops, times, sn, edges=None):
    """The oracle: feed + add_cycles + the accumulator's properties, tick by tick."""
    rf, mi = StreamingRainflow(), MinerAccumulator(sn, edges, rate_window_s=86400.0,
                                                   rate_buckets=24)
    rows, start = [], 0
    for stop, t in zip(stops, times):
        mi.add_cycles(*rf.feed(stress[start:stop]), time_s=t)
        mi.set_provisional_from(rf)
        rows.append((mi.damage_committed, mi.damage_rate_per_day, mi.damage,
                     mi.remaining_life_days))
        start = stop
    return rows, mi


@pytest.mark.parametrize("plain", [False, True])
def test_tick_dating_over_days_equals_add_cycles(plain):
    """Rate, damage and remaining life of every tick over three days of hourly rate buckets
    (the window fills, old buckets are dropped, a quiet spell empties it, a storm drives the damage past 1): the compiled dating equals add_cycles' to the last
    bit, compiled and as plain Python."""
    rng = np.random.default_rng(7)
    n_ticks = 3 * 24 * 6  # 10-min ticks
    per = 40
    amp = np.full(n_ticks, 30e6)
    amp[150:310] = 0.0  # a quiet spell longer than the window
    amp[-30:] = 250e6  # the storm: failure
    stress = (60e6 + np.repeat(amp, per) * np.sin(np.arange(n_ticks * per) / 3.0)
              + rng.normal(0, 2e5, n_ticks * per))
    stops = (per * np.arange(1, n_ticks + 1)).tolist()
    stops[100:104] = [stops[99]] * 4  # ticks without samples
    times = (1.7e9 + 600.0 * np.arange(1, n_ticks + 1)).tolist()
    sn = SNCurve.vaps_copper()
    rows, oracle = _per_tick(stress, stops, times, sn)
    rf, mi = StreamingRainflow(), MinerAccumulator(sn, rate_window_s=86400.0, rate_buckets=24)
    with uncompiled() if plain else contextlib.nullcontext():
        # in slabs, with a state round trip in between: the buckets carried across
        runs = [commit_ticks(rf, mi, stress[:stops[200]], stops[:201], times[:201])]
        st = json.loads(json.dumps([rf.state(), mi.state()]))
        rf, mi = StreamingRainflow.from_state(st[0]), MinerAccumulator.from_state(st[1])
        rest = [s - stops[200] for s in stops[201:]]
        runs.append(commit_ticks(rf, mi, stress[stops[200]:], rest, times[201:]))
    got = [row for run in runs for row in zip(run.committed.tolist(), run.rate_per_day.tolist(),
                                               run.damage.tolist(), run.life_days.tolist())]
    assert got == rows
    assert len({r[1] for r in rows}) > 300 and rows[140][1] > 1e-6  # rates really vary
    assert rows[305][1] == 0.0 < rows[330][1]  # the quiet spell emptied the window
    assert rows[-1][2] > 1.0 and rows[-1][3] == 0.0  # life used up
    assert mi.damage_rate_per_day == oracle.damage_rate_per_day
    mi.set_provisional_from(rf)
    assert json.dumps(mi.state()) == json.dumps(oracle.state())


@pytest.mark.parametrize("edges", [None, [0.0, 5e6, 10e6, 20e6, 40e6, 80e6, 300e6]])
def test_tick_groups_stack_growth_and_long_residues_equal_the_per_tick_calls(edges):
    """More ticks than one group of the compiled pass (models.fatigue._loops.TICK_GROUP), a
    stack outgrowing its storage mid-slab and residues too long to buffer a whole group
    (RESIDUE_ROOM): committed damage, rates, residue damage, histogram (uniform edges and
    not) and closed cycles equal the per-tick feed + add_cycles + residue_damage's bits."""
    rng = np.random.default_rng(5)
    n = 20_000
    # a diverging run (every sample a turning point, no cycle closes: the stack grows to
    # n / 2 points, past the counter's first storage), then a noisy sine closing cycles
    grow = 60e6 + np.linspace(1e5, 50e6, n // 2) * (-1.0) ** np.arange(n // 2)
    wave = 60e6 + 5e6 * np.sin(np.arange(n // 2) / 4.0) + rng.normal(0, 2e6, n // 2)
    stress = np.concatenate([grow, wave])
    stops = np.minimum(np.cumsum(rng.integers(0, 100, 400)), n).tolist()
    stops[-1] = n
    times = (1.7e9 + 10.0 * np.arange(1, len(stops) + 1)).tolist()
    sn = SNCurve.vaps_copper()
    rows, oracle = _per_tick(stress, stops, times, sn, edges)
    rf, mi = StreamingRainflow(), MinerAccumulator(sn, edges, rate_window_s=86400.0,
                                                   rate_buckets=24)
    storage = rf._st.shape[0]
    run = commit_ticks(rf, mi, stress, stops, times)
    got = list(zip(run.committed.tolist(), run.rate_per_day.tolist(), run.damage.tolist(),
                   run.life_days.tolist()))
    assert got == rows
    assert rf._st.shape[0] > storage and run.ranges.shape[0] > 1000  # grown; cycles closed
    assert len(set(run.residue.tolist())) > 100 and run.residue[-1] > 1.0  # the long residue
    mi.set_provisional_from(rf)
    assert json.dumps(mi.state()) == json.dumps(oracle.state())
