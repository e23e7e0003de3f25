"""Miner accumulator: split-invariant committed damage, the numpy oracle and the uncompiled
loops, rate, histogram, state."""

import json

import numpy as np
import pytest
import rainflow

from fatigue_oracles import damage_oracle, miner_oracle, sequential_sum
from models.fatigue import MinerAccumulator, SNCurve, StreamingRainflow, damage
from models.helix import HelixCable, conductor_stress

DAY = 86400.0


def _wave_tension(n: int, seed: int) -> np.ndarray:
    """20 Hz tension [N]: 6 s waves, a slow swell group and sensor noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 20.0
    return 6e3 + 2.5e3 * np.sin(2 * np.pi * t / 6.0) * (1 + 0.3 * np.sin(2 * np.pi * t / 300)) \
        + 150.0 * rng.normal(size=n)


def _replay(stress, cuts, curve, roundtrips=()):
    """Feed blocks with state saved to JSON and restored before the blocks in ``roundtrips``."""
    rf = StreamingRainflow()
    miner = MinerAccumulator(curve)
    for i, block in enumerate(np.split(stress, cuts)):
        if i in roundtrips:
            rf = StreamingRainflow.from_state(json.loads(json.dumps(rf.state())))
            miner = MinerAccumulator.from_state(json.loads(json.dumps(miner.state())))
        r, m, c = rf.feed(block)
        miner.add_cycles(r, m, c, time_s=float(i))
    miner.set_provisional_from(rf)
    return miner


@pytest.fixture(scope="module")
def stress() -> np.ndarray:
    return conductor_stress(_wave_tension(120_000, 1), HelixCable.vaps_biw(), "left")


def test_committed_damage_is_bit_identical_for_any_split(stress):
    curve = SNCurve.vaps_copper()
    whole = _replay(stress, [], curve)
    assert whole.damage_committed > 0
    rng = np.random.default_rng(4)
    for trial in range(4):
        cuts = np.sort(rng.integers(0, stress.size, rng.integers(1, 3000)))
        trips = set(rng.integers(0, cuts.size + 1, 5).tolist())
        split = _replay(stress, cuts, curve, roundtrips=trips)
        assert split.damage_committed == whole.damage_committed  # to the last bit
        assert split.damage == whole.damage
        np.testing.assert_array_equal(split.histogram[1], whole.histogram[1])
    # 20-sample blocks, as the service feeds them
    blocks = _replay(stress, np.arange(20, stress.size, 20), curve)
    assert blocks.damage_committed == whole.damage_committed


@pytest.mark.parametrize("mean_correction", ["none", "goodman"])
def test_committed_sum_and_histogram_equal_the_numpy_oracle(stress, mean_correction, monkeypatch):
    curve = SNCurve.dnv_rp_c203("C", "seawater_cp", scf=3.0, mean_correction=mean_correction,
                                ultimate_Pa=400e6)
    ranges, means, counts = StreamingRainflow().feed(stress)
    assert ranges.size > 10_000
    want, hist = miner_oracle(curve, ranges, means, counts, np.linspace(0.0, 100e6, 101))
    for compiled in (True, False):  # without numba the same loops run as plain Python
        if not compiled:
            ranges, means, counts = ranges[:3000], means[:3000], counts[:3000]
            want, hist = miner_oracle(curve, ranges, means, counts, np.linspace(0.0, 100e6, 101))
            monkeypatch.setattr("models.fatigue._loops.commit_compiled", None)
            monkeypatch.setattr("models.fatigue._loops.commit_damage_compiled", None)
        miner = MinerAccumulator(curve)
        miner.add_cycles(ranges[:5000], means[:5000], counts[:5000])
        miner.add_cycles(ranges[5000:], means[5000:], counts[5000:])
        # both evaluate log_det/exp_det (models.fatigue._loops) and sum in order: the same bits
        assert miner.damage_committed == want
        np.testing.assert_array_equal(miner.histogram[1], hist[:-1])
        assert miner.histogram[2] == hist[-1] and miner.total_cycles == counts.sum()


def test_total_equals_astm_batch_damage(stress):
    curve = SNCurve.vaps_copper()
    cycles = np.array([c[:3] for c in rainflow.extract_cycles(stress)])
    expected = curve.damage_per_cycle(cycles[:, 0], counts=cycles[:, 2]).sum()
    miner = _replay(stress, np.arange(997, stress.size, 997), curve)
    assert miner.damage == pytest.approx(expected, rel=1e-12)
    assert damage(stress, curve) == pytest.approx(expected, rel=1e-12)
    assert damage(stress, curve, include_residue=False) == miner.damage_committed


def test_sequential_sum_matches_python_loop():
    rng = np.random.default_rng(2)
    ranges = rng.uniform(1e6, 80e6, 5000)
    curve = SNCurve.dnv_rp_c203("D")
    miner = MinerAccumulator(curve)
    miner.add_cycles(ranges[:10], None, np.ones(10))
    miner.add_cycles(ranges[10:], None, np.ones(4990))
    total = 0.0
    for d in curve.damage_per_cycle(ranges):
        total += float(d)
    assert miner.damage_committed == total


def test_mean_correction_path():
    curve = SNCurve.vaps_copper(mean_correction="goodman", ultimate_Pa=220.6e6)
    miner = MinerAccumulator(curve)
    added = miner.add_cycles(np.array([40e6]), np.array([110.3e6]), np.array([1.0]))
    assert added == pytest.approx(1.0 / SNCurve.vaps_copper().cycles_to_failure(80e6), rel=1e-12)
    with pytest.raises(ValueError, match="means_Pa"):
        miner.add_cycles(np.array([40e6]), None, np.array([1.0]))


def test_rate_and_remaining_life():
    curve = SNCurve.dnv_chain_studless()
    per_cycle = float(curve.damage_per_cycle(np.array([50e6]))[0])  # 1 / 4.8e5
    miner = MinerAccumulator(curve, rate_window_s=DAY, rate_buckets=24)
    # 100 cycles every hour for two days: 2400 cycles per day
    for hour in range(49):
        miner.add_cycles(np.full(100, 50e6), None, np.ones(100), time_s=hour * 3600.0)
    assert miner.damage_committed == pytest.approx(4900 * per_cycle, rel=1e-12)
    assert miner.damage_rate_per_day == pytest.approx(2400 * per_cycle, rel=0.05)
    assert miner.remaining_life_days == pytest.approx((1 - miner.damage) / miner.damage_rate_per_day)
    # a quiet day afterwards: the rate decays to zero, life becomes unbounded
    miner.add_cycles(np.array([]), None, np.array([]), time_s=49 * 3600.0 + 1.5 * DAY)
    assert miner.damage_rate_per_day == 0.0
    assert miner.remaining_life_days == np.inf
    with pytest.raises(ValueError, match="non-decreasing"):
        miner.add_cycles(np.array([1e6]), None, np.array([1.0]), time_s=0.0)
    # the life used up (damage past 1) stays used up when the rate falls back to zero
    n = int(np.ceil((1.0 - miner.damage) / per_cycle)) + 10
    miner.add_cycles(np.full(n, 50e6), None, np.ones(n), time_s=50 * 3600.0 + 1.5 * DAY)
    assert miner.damage > 1.0 and miner.remaining_life_days == 0.0
    miner.add_cycles(np.array([]), None, np.array([]), time_s=50 * 3600.0 + 3 * DAY)
    assert miner.damage_rate_per_day == 0.0 and miner.remaining_life_days == 0.0


def test_histogram_fixed_edges_and_equivalent_range():
    curve = SNCurve.basquin(3.0, 12.0)
    edges = np.array([10e6, 20e6, 40e6])
    miner = MinerAccumulator(curve, histogram_edges_Pa=edges, reference_cycles=1e6)
    ranges = np.array([5e6, 10e6, 15e6, 20e6, 39e6, 40e6, 90e6])
    counts = np.array([1.0, 1.0, 0.5, 2.0, 1.0, 1.0, 3.0])
    miner.add_cycles(ranges, None, counts)
    e, h, overflow = miner.histogram
    np.testing.assert_array_equal(e, edges)
    np.testing.assert_array_equal(h, [1.5, 3.0])
    assert overflow == 4.0
    # uniform edges take a direct-index path: values exactly on (inexact) edges
    edges = np.linspace(0.0, 0.7e6, 8)  # 0.1e6 steps are not exact in binary
    for sn in (curve, curve.with_factors(mean_correction="swt")):  # two commit loops
        uniform = MinerAccumulator(sn, histogram_edges_Pa=edges)
        uniform.add_cycles(np.concatenate((edges, np.nextafter(edges[1:], 0))), np.zeros(15), np.ones(15))
        np.testing.assert_array_equal(uniform.histogram[1], [2.0] * 7)
        assert uniform.histogram[2] == 1.0
    # hand value: S_eq = (sum n S^3 / N_ref)^(1/3) for a single slope
    expected = (np.sum(counts * (ranges / 1e6) ** 3) / 1e6) ** (1 / 3) * 1e6
    assert miner.equivalent_stress_range() == pytest.approx(expected, rel=1e-12)
    assert miner.equivalent_stress_range(1e7) == pytest.approx(expected * 10 ** (-1 / 3), rel=1e-12)


def test_provisional_is_replaced_not_added():
    miner = MinerAccumulator(SNCurve.dnv_chain_studless())
    rf = StreamingRainflow()
    rf.feed(np.array([0.0, 50e6, 0.0, 10e6]))  # residue 0, 50, 0, 10 MPa: half cycles
    first = miner.set_provisional_from(rf)
    assert first == pytest.approx((0.5 + 0.5) / 4.8e5 + 0.5 / (6e10 / 10 ** 3), rel=1e-12)
    p = miner.set_provisional(np.array([50e6]), None, np.array([0.5]))
    assert miner.damage_provisional == p == pytest.approx(0.5 / 4.8e5, rel=1e-12)
    assert miner.damage == miner.damage_committed + p


def test_state_round_trip_exact():
    curve = SNCurve.vaps_copper(scf=1.3)
    miner = MinerAccumulator(curve)
    rng = np.random.default_rng(8)
    miner.add_cycles(rng.uniform(0, 90e6, 300), None, np.ones(300), time_s=10.0)
    miner.set_provisional(np.array([33e6]), None, np.array([0.5]))
    state = json.loads(json.dumps(miner.state()))
    again = MinerAccumulator.from_state(state)
    assert again.state() == miner.state()
    assert again.damage == miner.damage and again.sn_curve == curve
    assert len(json.dumps(state)) < 10_000


def test_bad_input():
    for curve in (SNCurve.dnv_rp_c203("D"), SNCurve.dnv_rp_c203("D", mean_correction="swt")):
        miner = MinerAccumulator(curve)
        with pytest.raises(ValueError, match="cycle 1"):
            miner.add_cycles(np.array([1e6, np.nan]), np.zeros(2), np.ones(2))
        with pytest.raises(ValueError, match="cycle 0"):
            miner.add_cycles(np.array([-1e6]), np.zeros(1), np.ones(1))
        with pytest.raises(ValueError, match="cycle 1"):
            miner.add_cycles(np.array([1e6, 2e6]), np.zeros(2), np.array([1.0, -0.5]))
        assert miner.damage_committed == 0.0 and miner.histogram[1].sum() == 0.0
    with pytest.raises(ValueError, match="histogram_edges"):
        MinerAccumulator(SNCurve.dnv_rp_c203("D"), histogram_edges_Pa=[3.0, 1.0])
    with pytest.raises(ValueError, match="SNCurve"):
        MinerAccumulator("D")
    with pytest.raises(ValueError, match="time_s"):
        miner.add_cycles(np.array([1e6]), None, np.ones(1), time_s=float("nan"))


def test_committed_sum_matches_qats_and_fatpack():
    # the accumulator's own log/exp (models.fatigue._loops) against the peers' numpy power
    qats_sn = pytest.importorskip("qats.fatigue.sn")
    fatpack = pytest.importorskip("fatpack")
    rng = np.random.default_rng(7)
    ranges = rng.uniform(5.0, 300.0, 5000)  # MPa, both sides of the knee
    counts = rng.integers(1, 1000, 5000).astype(float)
    m1, m2, log_a1, knee = 3.0, 5.0, 12.115, 1e6  # DNV-RP-C203 D in seawater with CP
    log_a2 = m2 / m1 * log_a1 + (1 - m2 / m1) * np.log10(knee)  # continuous at the knee
    miner = MinerAccumulator(SNCurve.multi_slope((m1, m2), (log_a1, log_a2)))
    miner.add_cycles(ranges[:1234] * 1e6, None, counts[:1234])
    miner.add_cycles(ranges[1234:] * 1e6, None, counts[1234:])
    q = qats_sn.minersum(ranges, counts, {"m1": m1, "m2": m2, "loga1": log_a1, "nswitch": knee})
    fp = fatpack.BiLinearEnduranceCurve(1.0)
    fp.Nc, fp.m1, fp.m2, fp.Nd = 10 ** log_a1, m1, m2, knee
    f = fp.find_miner_sum(np.column_stack((ranges, counts)))
    assert miner.damage_committed == pytest.approx(q, rel=1e-12)
    assert miner.damage_committed == pytest.approx(f, rel=1e-12)
    assert miner.total_cycles == np.sum(counts)


@pytest.mark.parametrize("hysteresis", [0.0, 2e6])
def test_residue_damage_is_the_astm_residue_at_every_block(hysteresis, monkeypatch):
    # the damage of the open residue, read at every alert tick, equals the ASTM half cycles
    # of the residue through the S-N curve (in order: the oracle's bits), compiled or not
    rng = np.random.default_rng(11)
    sn = SNCurve.vaps_copper()
    goodman = sn.with_factors(mean_correction="goodman", ultimate_Pa=250e6)
    for _ in range(3):
        x = np.cumsum(rng.normal(0, 4e6, 3000)) + 5e6 * np.sin(np.arange(3000) / 7)
        rf = StreamingRainflow(hysteresis=hysteresis)
        fast = MinerAccumulator(sn)
        mean_corrected = MinerAccumulator(goodman)
        cuts = np.sort(rng.choice(np.arange(1, 3000), 200, replace=False))
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, 3000]):
            rf.feed(x[a:b])
            r, m, c = rf.residue_half_cycles()
            expected = sequential_sum(0.0, damage_oracle(sn, r, m, c))
            assert fast.residue_damage(rf) == expected
            with monkeypatch.context() as patch:
                patch.setattr("models.fatigue._loops.residue_compiled", None)
                assert fast.residue_damage(rf) == expected
            assert mean_corrected.residue_damage(rf) == sequential_sum(
                0.0, damage_oracle(goodman, r, m, c))
        assert expected > 0
    assert MinerAccumulator(sn).residue_damage(StreamingRainflow()) == 0.0
