"""One compiled pass over a slab's fatigue load for the pipeline's load statistics.

``Pipeline``'s ``_TensionStats.add`` needed seven numpy passes over every slab (bins, their
minimum, a bincount, the source count, the millinewton sum, min, max); this kernel does them
in one, with the same arithmetic: bin ``clip(int64((v - lo) / width), 0, bins - 1)``, the sum
of ``int64(rint(v * 1e3))`` (an exact integer sum, so its order does not matter), exact min
and max. Only for finite loads (the caller keeps the numpy path for anything else, whose NaN
handling it defines).
"""

from __future__ import annotations

import numpy as np

from models._jit import kernel


@kernel()
def load_stats_pass(v, src, measured, lo, width, hist):
    """Add ``v``'s samples to ``hist`` (in place); return (finite, samples of source
    ``measured``, millinewton sum, min, max). ``finite`` False: nothing was added."""
    n = v.shape[0]
    top = hist.shape[0] - 1
    for i in range(n):
        if not np.isfinite(v[i]):
            return False, 0, 0, 0.0, 0.0
    n_meas = 0
    total = 0
    vmin = v[0]
    vmax = v[0]
    for i in range(n):
        x = v[i]
        b = np.int64((x - lo) / width)
        hist[min(max(b, 0), top)] += 1
        if src[i] == measured:
            n_meas += 1
        total += np.int64(np.rint(x * 1e3))
        vmin = min(vmin, x)
        vmax = max(vmax, x)
    return True, n_meas, total, vmin, vmax
