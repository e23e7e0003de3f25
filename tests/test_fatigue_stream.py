"""FatigueStream: the fused tension -> stress -> rainflow -> Miner pass gives the same bits
as conductor_stress + StreamingRainflow.feed + MinerAccumulator.add_cycles, for any split."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rainflow

from models.fatigue import FatigueStream, MinerAccumulator, SNCurve, StreamingRainflow, commit_ticks
from models.helix import HelixCable, conductor_stress


def _wave_tension(n: int, seed: int) -> np.ndarray:
    """20 Hz tension [N]: 6 s waves, a slow swell group and sensor noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 20.0
    return 6e3 + 2.5e3 * np.sin(2 * np.pi * t / 6.0) * (1 + 0.3 * np.sin(2 * np.pi * t / 300)) \
        + 150.0 * rng.normal(size=n)


@pytest.fixture(scope="module")
def tension() -> np.ndarray:
    return _wave_tension(60_000, 3)


def _separate(tension, cuts, cable, lay, curve, hysteresis=0.0, backend="auto"):
    rf = StreamingRainflow(hysteresis=hysteresis, backend=backend)
    miner = MinerAccumulator(curve, backend=backend)
    for i, block in enumerate(np.split(tension, cuts)):
        r, m, c = rf.feed(conductor_stress(block, cable, lay))
        miner.add_cycles(r, c, m, time_s=float(i))
    return rf, miner


def _fused(tension, cuts, cable, lay, curve, hysteresis=0.0, backend="auto", roundtrips=()):
    stream = FatigueStream(cable, lay, StreamingRainflow(hysteresis=hysteresis, backend=backend),
                           MinerAccumulator(curve, backend=backend))
    for i, block in enumerate(np.split(tension, cuts)):
        if i in roundtrips:
            rf = StreamingRainflow.from_state(json.loads(json.dumps(stream.rainflow.state())), backend=backend)
            miner = MinerAccumulator.from_state(json.loads(json.dumps(stream.miner.state())), backend=backend)
            stream = FatigueStream(cable, lay, rf, miner)
        stream.feed_tension(block, time_s=float(i))
    return stream.rainflow, stream.miner


def _assert_same(a, b):
    (rf_a, miner_a), (rf_b, miner_b) = a, b
    assert miner_a.damage_committed > 0
    assert miner_b.damage_committed == miner_a.damage_committed  # to the last bit
    assert miner_b.state() == miner_a.state()  # cycles, histogram, rate buckets
    assert rf_b.state() == rf_a.state()


@pytest.mark.parametrize("lay,hysteresis", [("left", 0.0), ("right", 0.0), ("left", 2e5)])
def test_fused_equals_separate_calls_for_any_split(tension, lay, hysteresis):
    cable = HelixCable.vaps_biw()
    curve = SNCurve.vaps_copper()
    whole = _separate(tension, [], cable, lay, curve, hysteresis)
    _assert_same(whole, _fused(tension, [], cable, lay, curve, hysteresis))
    rng = np.random.default_rng(4)
    for _ in range(3):
        cuts = np.sort(rng.integers(0, tension.size, rng.integers(1, 2000)))
        trips = set(rng.integers(0, cuts.size + 1, 5).tolist())
        reference = _separate(tension, cuts, cable, lay, curve, hysteresis)
        assert reference[1].damage_committed == whole[1].damage_committed  # split invariance
        _assert_same(reference, _fused(tension, cuts, cable, lay, curve, hysteresis, roundtrips=trips))
    # 20-sample blocks, one second each as the service feeds them
    cuts = np.arange(20, tension.size, 20)
    fused = _fused(tension, cuts, cable, lay, curve, hysteresis)
    assert fused[1].damage_committed == whole[1].damage_committed
    _assert_same(_separate(tension, cuts, cable, lay, curve, hysteresis), fused)


def test_fused_total_is_the_astm_damage(tension):
    cable = HelixCable.vaps_biw()
    curve = SNCurve.vaps_copper()
    rf, miner = _fused(tension, np.arange(5000, tension.size, 5000), cable, "left", curve)
    miner.set_provisional_from(rf)
    stress = conductor_stress(tension, cable, "left")
    cycles = np.array([c[:3] for c in rainflow.extract_cycles(stress)])
    expected = curve.damage_per_cycle(cycles[:, 0], cycles[:, 2])
    assert miner.damage == pytest.approx(np.sum(expected), rel=1e-12)
    assert miner.total_cycles + np.sum(rf.residue_half_cycles()[2]) == pytest.approx(np.sum(cycles[:, 2]))


def test_numba_and_numpy_backends_give_the_same_bits(tension):
    cable = HelixCable.vaps_biw()
    for curve in (SNCurve.vaps_copper(), SNCurve.dnv_rp_c203("C", "seawater_cp", scf=3.0)):
        cuts = [7, 20_000, 20_001]
        numba_path = _fused(tension, cuts, cable, "left", curve, backend="numba")
        numpy_path = _fused(tension, cuts, cable, "left", curve, backend="numpy")
        _assert_same(numba_path, numpy_path)


def test_fallbacks_equal_separate_calls(tension):
    part = tension[:5000]
    # mean-corrected curve, compressible core: the three calls are run as such
    curve = SNCurve.vaps_copper(mean_correction="goodman", ultimate_Pa=220.6e6)
    cable = HelixCable.vaps_biw()
    _assert_same(_separate(part, [999], cable, "left", curve), _fused(part, [999], cable, "left", curve))
    soft = HelixCable(**{**HelixCable.vaps_biw().__dict__, "core_compressibility": 1e-9})
    curve = SNCurve.vaps_copper()
    _assert_same(_separate(part, [999], soft, "left", curve), _fused(part, [999], soft, "left", curve))


def test_stack_growth_inside_a_block():
    # a slowly decaying oscillation closes no cycles: the stack outgrows its storage;
    # then one big swing closes them all
    n = 40_000
    k = np.arange(n)
    decay = 6e3 + 3e3 * np.where(k % 2 == 0, 1.0, -1.0) * np.exp(-k / n)
    tension = np.concatenate((decay, [2e4, 0.0, 2e4]))
    cable = HelixCable.vaps_biw()
    curve = SNCurve.vaps_copper()
    fused = _fused(tension, [n - 10_000, n], cable, "left", curve)
    _assert_same(_separate(tension, [n - 10_000, n], cable, "left", curve), fused)
    assert fused[1].total_cycles > 19_000 and len(fused[0].state()["stack"]) < 5
    grown = _fused(decay, [], cable, "left", curve)[0]
    assert len(grown.state()["stack"]) == n - 1  # the last sample is the open candidate


def test_bad_blocks_count_nothing(tension):
    stream = FatigueStream(HelixCable.vaps_biw(), "left", StreamingRainflow(), MinerAccumulator(SNCurve.vaps_copper()))
    stream.feed_tension(tension[:3000], time_s=10.0)
    before = (stream.rainflow.state(), stream.miner.state())
    for bad, index in ((np.inf, 2500), (np.nan, 2047), (1e300, 9), (-np.inf, 0)):
        block = tension[3000:6000].copy()
        block[index] = bad
        with pytest.raises(ValueError, match=f"index {index}"):
            stream.feed_tension(block, time_s=20.0)
        assert (stream.rainflow.state(), stream.miner.state()) == before
    # in a late chunk of a long block, after the stack has grown
    long_block = np.concatenate((np.tile([5e3, 7e3], 6000) * np.linspace(1.0, 0.9, 12000), tension[:3000]))
    long_block[-100] = np.nan
    with pytest.raises(ValueError, match=f"index {long_block.size - 100}"):
        stream.feed_tension(long_block, time_s=20.0)
    assert (stream.rainflow.state(), stream.miner.state()) == before
    with pytest.raises(ValueError, match="time_s"):
        stream.feed_tension(tension[3000:6000], time_s=5.0)  # earlier than the last commit
    assert (stream.rainflow.state(), stream.miner.state()) == before
    with pytest.raises(ValueError, match="lay"):
        FatigueStream(HelixCable.vaps_biw(), "up", StreamingRainflow(), MinerAccumulator(SNCurve.vaps_copper()))
    with pytest.raises(ValueError, match="StreamingRainflow"):
        FatigueStream(HelixCable.vaps_biw(), "left", None, MinerAccumulator(SNCurve.vaps_copper()))
    # empty and one-sample blocks
    assert stream.feed_tension(np.array([])) == 0.0
    assert stream.feed_tension(np.array([6e3])) == 0.0
    assert stream.rainflow.samples == 3001


def test_commit_ticks_equals_feed_and_add_cycles_per_tick():
    rng = np.random.default_rng(21)
    stress = 20e6 + 8e6 * np.sin(np.arange(6000) / 6.0) + rng.normal(0, 1e6, 6000)
    stops = [0, 700, 700, 2500, 4100, 6000]  # an empty first tick and an empty middle one
    times = [10.0 * (i + 1) for i in range(len(stops))]
    sn = SNCurve.vaps_copper()
    # two cycles pending from an earlier block, committed first in the first tick
    pending = (np.array([3e6, 5e6]), np.array([1.0, 1.0]))
    rf_a, mi_a = StreamingRainflow(), MinerAccumulator(sn)
    rf_b, mi_b = StreamingRainflow(), MinerAccumulator(sn)
    run = commit_ticks(rf_a, mi_a, stress, stops, times, pending)
    start, committed, rates, residue, closed = 0, [], [], [], []
    for k, (stop, t) in enumerate(zip(stops, times)):
        r, m, c = rf_b.feed(stress[start:stop])
        closed.append(r)
        if k == 0:
            r, c = np.concatenate([pending[0], r]), np.concatenate([pending[1], c])
        mi_b.add_cycles(r, c, time_s=t)
        committed.append(mi_b.damage_committed)
        rates.append(mi_b.damage_rate_per_day)
        residue.append(mi_b.residue_damage(rf_b))
        start = stop
    assert run.committed.tolist() == committed and run.rate_per_day.tolist() == rates
    assert run.residue.tolist() == residue
    np.testing.assert_array_equal(run.ranges, np.concatenate(closed))
    assert json.dumps([rf_a.state(), mi_a.state()]) == json.dumps([rf_b.state(), mi_b.state()])
    # no compiled pass for the numpy backend: the caller runs the per-tick calls
    assert commit_ticks(StreamingRainflow(backend="numpy"), MinerAccumulator(sn), stress,
                        stops, times) is None
