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
