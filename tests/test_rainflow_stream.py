"""Streaming four-point rainflow: exactness against ASTM E1049 (``rainflow``) and the
per-sample oracle (``fatigue_oracles.rainflow_oracle``), splits, state, the uncompiled loop."""

import json
from collections import defaultdict

import numpy as np
import pytest
import rainflow
from hypothesis import given, settings
from hypothesis import strategies as st

from fatigue_oracles import rainflow_oracle
from models.fatigue import StreamingRainflow


def _astm_totals(series) -> dict:
    out = defaultdict(float)
    for rng, mean, count, _, _ in rainflow.extract_cycles(series):
        if rng > 0:  # rainflow reports a zero-range half cycle after a trailing plateau
            out[(rng, mean)] += count
    return dict(out)


def astm_residue_oracle(points: list[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ASTM E1049 three-point counting of a (short) turning-point sequence, in plain Python:
    the oracle of the compiled residue count (``models.fatigue._loops._residue_cycles``)."""
    out: list[tuple[float, float, float]] = []
    stack: list[float] = []
    start = 0  # index in stack of the series' current starting point
    for p in points:
        stack.append(p)
        while len(stack) - start >= 3:
            x_rng = abs(stack[-1] - stack[-2])
            y_rng = abs(stack[-2] - stack[-3])
            if x_rng < y_rng:
                break
            if len(stack) - start == 3:  # Y contains the starting point: half cycle
                out.append((y_rng, 0.5 * (stack[start] + stack[start + 1]), 0.5))
                start += 1
            else:
                out.append((y_rng, 0.5 * (stack[-3] + stack[-2]), 1.0))
                del stack[-3:-1]
    for a, b in zip(stack[start:], stack[start + 1:]):
        out.append((abs(a - b), 0.5 * (a + b), 0.5))
    arr = np.array(out, dtype=np.float64).reshape(-1, 3)
    return arr[:, 0].copy(), arr[:, 1].copy(), arr[:, 2].copy()


def _stream(series, cuts, hysteresis=0.0, roundtrip_at=None):
    """Feed ``series`` cut at ``cuts``; return (closed cycles (3, n), residue, counter)."""
    rf = StreamingRainflow(hysteresis=hysteresis)
    closed = [[], [], []]
    for i, block in enumerate(np.split(np.asarray(series, dtype=float), cuts)):
        if roundtrip_at is not None and i == roundtrip_at:
            rf = StreamingRainflow.from_state(json.loads(json.dumps(rf.state())))
        for acc, part in zip(closed, rf.feed(block)):
            acc.extend(part.tolist())
    return np.array(closed).reshape(3, -1), rf.residue, rf


def _totals(closed, rf) -> dict:
    out = defaultdict(float)
    half = rf.residue_half_cycles()
    for rng, mean, count in zip(*np.concatenate([closed, np.array(half)], axis=1)):
        if rng > 0:
            out[(rng, mean)] += count
    return dict(out)


def test_astm_e1049_example():
    series = [-2, 1, -3, 5, -1, 3, -4, 4, -2]
    closed, residue, rf = _stream(series, [])
    # ASTM E1049-85 Fig. 6 / Table: ranges 3, 4, 6, 8, 9 with 0.5, 1.5, 0.5, 1.0, 0.5 cycles
    by_range = defaultdict(float)
    for (rng, _), count in _totals(closed, rf).items():
        by_range[rng] += count
    assert dict(by_range) == {3.0: 0.5, 4.0: 1.5, 6.0: 0.5, 8.0: 1.0, 9.0: 0.5}
    # four-point closes only (-1, 3); the rest is residue, counted as ASTM half cycles
    assert closed[0].tolist() == [4.0]
    np.testing.assert_array_equal(residue, [-2, 1, -3, 5, -4, 4, -2])
    r, m, c = rf.residue_half_cycles()
    assert sorted(zip(r.tolist(), m.tolist(), c.tolist())) == [
        (3.0, -0.5, 0.5), (4.0, -1.0, 0.5), (6.0, 1.0, 0.5), (8.0, 0.0, 0.5), (8.0, 1.0, 0.5), (9.0, 0.5, 0.5)]


@settings(max_examples=150, deadline=None)
@given(series=st.lists(st.integers(-6, 6), min_size=3, max_size=80),
       cut_seeds=st.lists(st.integers(0, 10_000), max_size=6),
       hysteresis=st.sampled_from([0.0, 0.0, 1.5]))
def test_any_split_equals_batch_astm_and_the_oracle(series, cut_seeds, hysteresis):
    x = np.asarray(series, dtype=float)  # small integers: plenty of plateaus and repeats
    cuts = sorted(s % (len(x) + 1) for s in cut_seeds)
    closed, residue, rf = _stream(x, cuts, hysteresis)
    whole, whole_residue, _ = _stream(x, [], hysteresis)
    oracle_r, oracle_m, oracle_residue = rainflow_oracle([x], hysteresis)
    np.testing.assert_array_equal(closed[:2], np.array([oracle_r, oracle_m]).reshape(2, -1))
    np.testing.assert_array_equal(residue, oracle_residue)
    # closure order and values do not depend on the split
    np.testing.assert_array_equal(closed, whole)
    np.testing.assert_array_equal(residue, whole_residue)
    if hysteresis == 0.0:
        assert _totals(closed, rf) == _astm_totals(x)
    oracle = astm_residue_oracle(rf.residue.tolist())
    np.testing.assert_array_equal(np.array(rf.residue_half_cycles()), np.array(oracle))


@pytest.mark.parametrize("seed", range(4))
def test_residue_cycles_equal_the_three_point_oracle_bit_for_bit(seed, monkeypatch):
    rng = np.random.default_rng(seed)
    amp = np.abs(np.cumsum(rng.normal(0.0, 1.0, 400))) + 0.1  # long wandering residues
    x = amp * 1e6 * (-1.0) ** np.arange(amp.size) + rng.normal(0.0, 1e5, amp.size)
    rf, full = StreamingRainflow(), 0
    for block in np.array_split(x, 7):
        rf.feed(block)
        want = np.array(astm_residue_oracle(rf.residue.tolist()))
        assert want.shape[1] >= 7
        np.testing.assert_array_equal(np.array(rf.residue_half_cycles()), want)
        monkeypatch.setattr("models.fatigue._loops.residue_cycles_compiled", None)
        np.testing.assert_array_equal(np.array(rf.residue_half_cycles()), want)  # uncompiled
        monkeypatch.undo()
        full += int(np.count_nonzero(want[2] == 1.0))
    assert full > 0  # the three-point rule paired residue ranges into full cycles


def test_long_random_series_matches_astm():
    rng = np.random.default_rng(3)
    t = np.arange(60_000) / 20.0
    x = 3e7 * np.sin(2 * np.pi * t / 6.0) + 5e6 * rng.normal(size=t.size) + 1e6 * np.cumsum(rng.normal(size=t.size)) / 50
    cuts = np.sort(rng.integers(0, x.size, 300))
    closed, _, rf = _stream(x, cuts)
    got, ref = _totals(closed, rf), _astm_totals(x)
    assert got.keys() == ref.keys()
    np.testing.assert_allclose([got[k] for k in ref], list(ref.values()), rtol=1e-12)
    assert closed.shape[1] > 10_000


@pytest.mark.parametrize("hysteresis", [0.0, 0.35, 2.0])
def test_compiled_and_uncompiled_loops_equal_the_oracle(hysteresis, monkeypatch):
    rng = np.random.default_rng(11)
    x = np.round(np.cumsum(rng.normal(size=20_000)) + 3 * np.sin(np.arange(20_000) / 7), 1)
    cuts = np.sort(rng.integers(0, x.size, 500))
    a, ra, _ = _stream(x, cuts, hysteresis)
    want_r, want_m, want_residue = rainflow_oracle(np.split(x, cuts), hysteresis)
    assert want_r.size > 500
    np.testing.assert_array_equal(a[:2], [want_r, want_m])
    np.testing.assert_array_equal(a[2], np.ones(want_r.size))
    np.testing.assert_array_equal(ra, want_residue)
    # without numba the same loop runs as plain Python (on a part: it is slow)
    monkeypatch.setattr("models.fatigue._loops.feed_compiled", None)
    b, rb, _ = _stream(x[:3000], cuts[cuts < 3000], hysteresis)
    want_r, want_m, want_residue = rainflow_oracle(np.split(x[:3000], cuts[cuts < 3000]), hysteresis)
    np.testing.assert_array_equal(b[:2], [want_r, want_m])
    np.testing.assert_array_equal(rb, want_residue)


def test_hysteresis_gate():
    x = [0.0, 5.0, 4.5, 5.2, 0.0, 0.4, -0.1, 6.0, 1.0]
    closed, residue, _ = _stream(x, [3, 5], hysteresis=1.0)
    np.testing.assert_array_equal(residue, [0.0, 5.2, -0.1, 6.0, 1.0])
    assert closed.shape[1] == 0
    closed0, _, _ = _stream(x, [], hysteresis=0.0)
    assert sorted(closed0[0].tolist()) == [0.4, 0.5]
    rng = np.random.default_rng(5)
    y = np.cumsum(rng.normal(size=5000))
    closed_h, residue_h, rf = _stream(y, [100, 2000], hysteresis=1.5)
    assert closed_h[0].min() > 1.5
    assert np.all(np.abs(np.diff(residue_h[:-1])) > 1.5)
    assert rf.hysteresis == 1.5


def test_state_round_trip_mid_stream_is_bit_identical():
    rng = np.random.default_rng(9)
    x = rng.normal(size=30_000) * 1e7 + 1e6 * np.sin(np.arange(30_000) / 40)
    cuts = list(range(1000, 30_000, 1000))
    a, ra, rf_a = _stream(x, cuts)
    b, rb, rf_b = _stream(x, cuts, roundtrip_at=13)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ra, rb)
    assert rf_a.state() == rf_b.state()
    assert len(json.dumps(rf_b.state())) < 2000  # small: the residue of a stationary signal


def test_stack_growth_inside_a_block():
    # a widening oscillation keeps every turning point open: the stack must grow mid-block
    n = 5000
    x = np.arange(n) * np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    rf = StreamingRainflow(_capacity=4)
    ranges, _, _ = rf.feed(x)
    assert ranges.size == 0 and rf.residue.size == n
    np.testing.assert_array_equal(rf.residue, x)


def test_tiny_and_empty_blocks():
    x = np.array([1.0, 1.0, 3.0, 3.0, 3.0, 2.0, 2.0, 4.0, 0.0, 0.0, 5.0])
    rf = StreamingRainflow()
    out = [rf.feed(x[i:i + 1]) for i in range(x.size)] + [rf.feed(np.array([]))]
    ranges = np.concatenate([o[0] for o in out])
    assert ranges.tolist() == [1.0]
    np.testing.assert_array_equal(rf.residue, [1.0, 4.0, 0.0, 5.0])
    assert rf.samples == x.size
    r, m, c = rf.residue_half_cycles()
    np.testing.assert_array_equal(c, [0.5, 0.5, 0.5])


def test_nan_block_raises_and_counts_nothing():
    rf = StreamingRainflow()
    rf.feed(np.array([0.0, 2.0, -1.0, 3.0]))
    before = rf.state()
    with pytest.raises(ValueError, match="NaN or inf at index 2"):
        rf.feed(np.array([1.0, -5.0, np.nan, 4.0]))
    with pytest.raises(ValueError, match="NaN or inf at index 0"):
        rf.feed(np.array([np.inf]))
    assert rf.state() == before


def test_bad_arguments():
    with pytest.raises(ValueError, match="hysteresis"):
        StreamingRainflow(hysteresis=-1.0)
    with pytest.raises(ValueError, match="1-D"):
        StreamingRainflow().feed(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="version"):
        StreamingRainflow.from_state({"version": 99})
