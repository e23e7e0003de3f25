"""One compiled pass for a stream's health at a slab's alert tick ends (the pipeline's
``_StreamSlab.tick_arrays``), in place of a dozen numpy calls on arrays of a few hundred
ticks: per slab, their Python overhead was the cost, not the work.

Each count is ``np.searchsorted(x, ends, side="right")`` by numpy's own binary search
(``npy_binsearch``: the lower bound carried over while the keys rise, reset when they do
not), so the result is numpy's for any input, sorted or not.
"""

from __future__ import annotations

import numpy as np

from models._jit import kernel


@kernel(inline="always")
def _search_right(x, key, last_key, lo, hi):
    """numpy's ``binsearch`` (side right) of ``key`` in ``x``, from the previous key's
    bounds ``lo, hi`` (``last_key``: the previous key; the first key's own for the first);
    returns the index and the new bounds."""
    n = x.shape[0]
    if last_key <= key:
        hi = n
    else:
        lo = 0
        hi = hi + 1 if hi < n else n
    while lo < hi:
        mid = lo + ((hi - lo) >> 1)
        if x[mid] <= key:
            lo = mid + 1
        else:
            hi = mid
    return lo, hi


@kernel()
def tick_health(rx_t, rej_t, acc_t, ends):
    """Per tick end ``ends[q]``: the samples of ``rx_t`` (received) and of ``rej_t``
    (rejected) in the tick (after the previous end; from the start for the first), how many
    of ``acc_t`` (accepted) are at or before the end, and the newest of those (0 if none).
    As numpy: ``_counts(searchsorted(rx_t, ends, "right"))``, the same of ``rej_t``,
    ``k = searchsorted(acc_t, ends, "right")`` and ``where(k > 0, acc_t[k - 1], 0)``."""
    n = ends.shape[0]
    received = np.empty(n, np.int64)
    rejected = np.empty(n, np.int64)
    upto = np.empty(n, np.int64)
    last = np.empty(n, np.int64)
    i_lo, i_hi, r_lo, r_hi, a_lo, a_hi = 0, rx_t.shape[0], 0, rej_t.shape[0], 0, acc_t.shape[0]
    prev_i, prev_r = 0, 0
    last_key = ends[0] if n else 0
    for q in range(n):
        key = ends[q]
        i_lo, i_hi = _search_right(rx_t, key, last_key, i_lo, i_hi)
        r_lo, r_hi = _search_right(rej_t, key, last_key, r_lo, r_hi)
        a_lo, a_hi = _search_right(acc_t, key, last_key, a_lo, a_hi)
        last_key = key
        received[q] = i_lo - prev_i
        rejected[q] = r_lo - prev_r
        prev_i, prev_r = i_lo, r_lo
        upto[q] = a_lo
        last[q] = acc_t[a_lo - 1] if a_lo > 0 else 0
    return received, rejected, upto, last
