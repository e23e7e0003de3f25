"""QARTOD flags: equal to ioos_qc's batch results on whole records; streaming = batch."""

import math

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

from monitor.config import FieldLimits
from monitor.qartod import FLAT_MEMORY, SPIKE, TESTS, StreamQC

qartod = pytest.importorskip("ioos_qc.qartod")

S = 1_000_000_000
FIELD = FieldLimits(min=-8.0, max=8.0, max_rate_per_s=3.0, suspect_min=-5.0, suspect_max=5.0,
                    spike_suspect=1.5, spike_fail=4.0, rate_suspect_per_s=0.8,
                    flat_tolerance=0.01, flat_suspect_s=5.0, flat_fail_s=9.0)


def record(n: int, seed: int, step_s: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """A noisy sea with NaNs, out-of-range values, spikes, steps and flat runs; whole-second
    steps (ioos_qc truncates time steps to whole seconds)."""
    rng = np.random.default_rng(seed)
    t = (1_700_000_000 + step_s * np.arange(n)).astype(np.int64) * S
    x = 2.0 * np.sin(np.arange(n) * 0.3) + rng.normal(0, 0.3, n)
    for kind, k in zip(rng.integers(0, 5, n // 15), rng.integers(2, n - 12, n // 15)):
        if kind == 0:
            x[k] = np.nan
        elif kind == 1:
            x[k] += rng.choice([-1, 1]) * rng.uniform(1, 12)
        elif kind == 2:
            x[k:k + 4] += rng.uniform(-6, 6)
        elif kind == 3:
            x[k:k + 12] = x[k] + rng.uniform(0, 0.005, 12)
        else:
            x[k] = rng.choice([np.inf, 9.0, -9.0, 6.0])
    return t, x


def oracle(t: np.ndarray, x: np.ndarray, f: FieldLimits = FIELD) -> dict[str, np.ndarray]:
    times = t.astype("datetime64[ns]")
    return {
        "gross_range": qartod.gross_range_test(x, (f.min, f.max),
                                               (f.suspect_min, f.suspect_max)),
        "spike": qartod.spike_test(x, f.spike_suspect, f.spike_fail),
        "rate_of_change": qartod.rate_of_change_test(x, times, f.rate_suspect_per_s,
                                                     f.max_rate_per_s),
        "flat_line": qartod.flat_line_test(x, times, f.flat_suspect_s, f.flat_fail_s,
                                           f.flat_tolerance),
    }


def streamed(t: np.ndarray, values: np.ndarray, cuts, qc_args=((FIELD,),), restore=False):
    """Flags per test over the whole record, fed in blocks cut at ``cuts``; the spike flag of
    each sample taken when the next arrives (the last one's stays 2, 9 if missing)."""
    qc = StreamQC(*qc_args)
    out, spike = [], []
    for a, b in zip([0, *cuts], [*cuts, t.shape[0]]):
        if restore:
            qc = StreamQC(*qc_args, state=qc.state())
        flags, prev = qc.check(t[a:b], values[:, a:b])
        out.append(flags)
        spike.append(prev)
    flags = np.concatenate(out, axis=1)
    prev = np.concatenate(spike)
    last = 9 if not np.all(np.isfinite(values[:, -1])) else 2
    flags[SPIKE] = np.append(prev[1:], last)
    return flags, qc


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_flags_equal_ioos_qc_batch_on_whole_records(seed):
    t, x = record(3000, seed)
    flags, qc = streamed(t, x[None, :], [])
    want = oracle(t, x)
    for k, name in enumerate(TESTS[:4]):
        np.testing.assert_array_equal(flags[k], np.asarray(want[name]), err_msg=name)
        assert set(np.unique(flags[k])) >= {1}
    # the record exercises every flag of every test (a test that cannot fail is a defect)
    for name in TESTS[:4]:
        assert qc.counts[name]["suspect"] > 0 and qc.counts[name]["fail"] > 0, name
        assert qc.counts[name]["suspect"] == int(np.count_nonzero(np.asarray(want[name]) == 3)) \
            or name == "spike"
    spike = np.asarray(want["spike"])
    # the last sample's spike flag is never counted (it waits for a next sample)
    assert qc.counts["spike"]["fail"] == int(np.count_nonzero(spike[:-1] == 4))


def test_flat_line_window_in_seconds_equals_ioos_qc_at_another_step():
    t, x = record(2000, 7, step_s=2)
    flags, _ = streamed(t, x[None, :], [])
    want = oracle(t, x)
    np.testing.assert_array_equal(flags[3], np.asarray(want["flat_line"]))
    np.testing.assert_array_equal(flags[2], np.asarray(want["rate_of_change"]))


def test_location_equals_ioos_qc():
    rng = np.random.default_rng(4)
    n = 500
    lat = 41.85 + np.cumsum(rng.normal(0, 2e-4, n))
    lon = -82.4 + np.cumsum(rng.normal(0, 2e-4, n))
    lat[rng.integers(0, n, 10)] += rng.choice([-1, 1], 10) * 0.01  # ~1 km jumps
    lat[5], lon[9], lat[20], lon[20] = np.nan, np.nan, np.nan, np.nan
    lat[30] = 95.0
    t = (1_700_000_000 + 60 * np.arange(n)).astype(np.int64) * S
    off = FieldLimits(-math.inf, math.inf, math.inf)
    qc_args = ((off, off), 300.0)
    flags, qc = streamed(t, np.stack([lat, lon]), [], qc_args)
    want = np.asarray(qartod.location_test(lon, lat, range_max=300.0, range_method="wgs84"))
    np.testing.assert_array_equal(flags[4], want)
    assert qc.counts["location"]["suspect"] >= 10 and qc.counts["location"]["fail"] == 3


@settings(max_examples=40, deadline=None)
@example(seed=191, cuts=[178], restore=True)  # an infinite value saved in the state
@given(seed=st.integers(0, 10_000), cuts=st.lists(st.integers(1, 799), max_size=12),
       restore=st.booleans())
def test_streaming_equals_batch_for_any_block_split(seed, cuts, restore):
    t, x = record(800, seed)
    values = np.stack([x, -0.5 * x])  # two fields: the worst flag of both
    args = ((FIELD, FIELD),)
    whole, qc1 = streamed(t, values, [], args)
    split, qc2 = streamed(t, values, sorted(set(cuts)), args, restore)
    np.testing.assert_array_equal(whole, split)
    assert qc1.counts == qc2.counts


def test_flat_line_memory_is_bounded_and_saved():
    n = FLAT_MEMORY + 500
    t = (np.arange(n) * S // 10).astype(np.int64)
    x = np.zeros((1, n))
    f = FieldLimits(-1, 1, math.inf, flat_tolerance=0.01, flat_suspect_s=1.0, flat_fail_s=1e6)
    qc = StreamQC((f,))
    flags, _ = qc.check(t, x)
    # suspect once 1 s of flat data is there; fail never (the window is cut to the memory)
    assert (flags[3][:10] == 1).all() and (flags[3][11:] == 3).all()
    assert len(qc.state()["ring_t"]) == FLAT_MEMORY


def test_fast_blocks_longer_than_the_flat_memory_equal_the_general_kernel(monkeypatch):
    """Blocks of finite values (the fast kernel) from one sample to past the flat-line
    memory, so its ring wraps anywhere, over a sea with stuck stretches (the flat-line scan
    reads back through the ring): the flags, counts and saved memory of the sample-by-sample
    general kernel."""
    rng = np.random.default_rng(9)
    n = 3 * FLAT_MEMORY + 700
    t, x = record(n, 9)
    x = np.where(np.isfinite(x), x, 0.5)
    for k in rng.integers(0, n - 400, 12):
        x[k:k + 300] = x[k] + rng.uniform(0, 0.005, 300)  # stuck: flat-line scans
    f = FieldLimits(-10, 10, 3.0, flat_tolerance=0.01, flat_suspect_s=30.0, flat_fail_s=200.0)
    values = np.stack([x, -0.5 * x])
    cuts = np.cumsum(rng.choice([1, 2, 57, 900, FLAT_MEMORY + 300], 40))
    cuts = sorted(set(cuts[cuts < n].tolist()))
    fast, qc_fast = streamed(t, values, cuts, ((f, f),))
    assert qc_fast.ring_n == FLAT_MEMORY and (fast[3] == 4).any() and (fast[3] == 3).any()
    import monitor.qartod

    monkeypatch.setattr(monitor.qartod, "_qc_fast", lambda *a: (False,) + (None,) * 5)
    general, qc_general = streamed(t, values, cuts, ((f, f),))
    np.testing.assert_array_equal(fast, general)
    assert qc_fast.counts == qc_general.counts and qc_fast.state() == qc_general.state()
