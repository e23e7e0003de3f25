"""The one-pass load statistics kernel equals the numpy formulas it replaced, bit for bit."""

from __future__ import annotations

import numpy as np

from monitor.stats_kernel import load_stats_pass


def test_one_pass_equals_the_numpy_passes():
    rng = np.random.default_rng(5)
    lo, hi, bins = -1e4, 2e6, 65536
    width = (hi - lo) / bins
    v = np.concatenate([rng.normal(5000.0, 900.0, 5000), [lo - 5.0, hi + 5.0, lo, 0.0005]])
    src = rng.integers(1, 3, v.shape[0]).astype(np.int8)
    hist = np.zeros(bins, np.int64)
    finite, n_meas, total, vmin, vmax = load_stats_pass(v, src, 1, lo, width, hist)
    want = np.bincount(np.clip(((v - lo) / width).astype(np.int64), 0, bins - 1), minlength=bins)
    assert finite and np.array_equal(hist, want)
    assert n_meas == int(np.count_nonzero(src == 1))
    assert total == int(np.rint(v * 1e3).astype(np.int64).sum())
    assert (vmin, vmax) == (float(v.min()), float(v.max()))


def test_a_non_finite_load_is_left_to_the_caller():
    hist = np.zeros(16, np.int64)
    v = np.array([1.0, np.nan, 2.0])
    assert not load_stats_pass(v, np.ones(3, np.int8), 1, 0.0, 1.0, hist)[0]
    assert not hist.any()


def test_the_bit_tricks_equal_the_conversions_compiled_and_plain():
    # halves (rint rounds them to even), both sides of 0, loads past 2^51 mN (the plain
    # sum) and past 2^63 bins (the compiled conversion gives int64's minimum: bin 0)
    from models import _jit

    lo, hi, bins = -1e4, 2e6, 65536
    width = (hi - lo) / bins
    halves = np.array([0.0005, 0.0015, 0.0025, -0.0005, -0.0025, 1e-3 * (2**51 - 1.5), -0.0,
                       lo, lo + width, hi - width, hi, 123.4565])
    huge = np.array([1.0, 2.5e12, -2.5e12, 1e21, -1e21, 7.0005])
    for v in (halves, huge):
        src = np.arange(v.shape[0], dtype=np.int8) % 2
        with np.errstate(invalid="ignore"):  # (astype of past-int64 values: x86's minimum)
            want = np.bincount(np.clip(((v - lo) / width).astype(np.int64), 0, bins - 1),
                               minlength=bins)
            want_total = int(np.rint(v * 1e3).astype(np.int64).sum())
        outs = []
        for plain in (False, True):
            hist = np.zeros(bins, np.int64)
            with _jit.uncompiled() if plain else np.errstate():
                finite, n_meas, total, vmin, vmax = load_stats_pass(v, src, 1, lo, width, hist)
            assert finite and np.array_equal(hist, want)
            assert int(total) == want_total
            outs.append((int(n_meas), int(total), float(vmin), float(vmax)))
        assert outs[0] == outs[1] and outs[0][0] == v.shape[0] // 2
