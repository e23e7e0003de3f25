"""One compiled pass over a slab's fatigue load for the pipeline's load statistics.

``Pipeline``'s ``_TensionStats.add`` needed seven numpy passes over every slab (bins, their
minimum, a bincount, the source count, the millinewton sum, min, max); this kernel does them
in one, with the same arithmetic: bin ``clip(int64((v - lo) / width), 0, bins - 1)``, the sum
of ``int64(rint(v * 1e3))`` (an exact integer sum, so its order does not matter), exact min
and max. Only for finite loads (the caller keeps the numpy path for anything else, whose NaN
handling it defines).

Speed: what vectorises runs in loops the compiler vectorises (the finiteness test, the source
count, the sum, the bins of spans of the slab); only the histogram increments and the min and
max (whose order decides which of -0.0 and 0.0 is kept) run one sample at a time. Float to
integer conversions, which the machine cannot vectorise, go through exact bit tricks:
``rint(y) = bits(y + 1.5 * 2^52) - bits(1.5 * 2^52)`` for ``|y| < 2^51`` (the addition rounds
to an integer, half to even, as ``rint``; else the plain conversion), and a bin is
``bits(floor(q') + 2^52) - bits(2^52)`` of ``q' = min(max(q, 0), bins - 1)``: ``floor`` of the
clipped quotient is the clipped truncation (both are 0 below 0 and ``bins - 1`` from it up),
except from ``q >= 2^63`` (or NaN: a zero width), where the compiled conversion gives int64's
minimum, clipped to 0.
"""

from __future__ import annotations

import numpy as np

from models._jit import float_bits, kernel, select

_SPAN = 1024  # the bins of this many samples at a time (their scratch stays in the cache)
_ROUND = 1.5 * 2.0 ** 52  # y + this is rint(y) + this, exactly, for |y| < 2^51
_ROUND_BITS = 0x4338000000000000  # float_bits(_ROUND)
_INT = 2.0 ** 52  # f + this has f's integer in its low bits, for integers 0 <= f < 2^52
_INT_BITS = 0x4330000000000000  # float_bits(_INT)


@kernel(error_model="numpy")
def load_stats_pass(v, src, measured, lo, width, hist):
    """Add ``v``'s samples to ``hist`` (in place); return (finite, samples of source
    ``measured``, millinewton sum, min, max). ``finite`` False: nothing was added."""
    n = v.shape[0]
    bad = False
    near = True  # every |v * 1e3| < 2^51: the sum by the bit trick
    n_meas = 0
    for i in range(n):
        x = v[i]
        bad |= (x - x) != 0.0  # 0 for finite x, NaN otherwise
        near &= abs(x * 1e3) < 2.0 ** 51
        n_meas += src[i] == measured
    if bad:
        return False, 0, 0, 0.0, 0.0
    total = 0
    if near:
        for i in range(n):
            total += float_bits(v[i] * 1e3 + _ROUND) - _ROUND_BITS
    else:
        for i in range(n):
            total += np.int64(np.rint(v[i] * 1e3))
    top = float(hist.shape[0] - 1)
    bins = np.empty(min(n, _SPAN), np.int64)
    vmin = v[0]
    vmax = v[0]
    for a in range(0, n, _SPAN):
        w = v[a:a + bins.shape[0]]
        m = w.shape[0]
        for i in range(m):
            q = (w[i] - lo) / width
            b = float_bits(np.floor(min(max(q, 0.0), top)) + _INT) - _INT_BITS
            bins[i] = select(q < 2.0 ** 63, b, 0)  # (False for NaN too: bin 0, in bounds)
        for i in range(m):
            hist[bins[i]] += 1
            x = w[i]
            vmin = min(vmin, x)
            vmax = max(vmax, x)
    return True, n_meas, total, vmin, vmax
