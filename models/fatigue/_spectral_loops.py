"""Compiled loops of the spectral path (``models.fatigue.spectral``), each giving the bits of
the numpy expressions it replaces, so a stream of spectra costs one call where it cost ten.

Bit-identity rests on three things:

* elementwise steps are the same IEEE-754 operations in the same order (no fast-math: no
  contraction into fused multiply-adds, no reassociation; ``models._jit``);
* every sum numpy computed with ``np.sum`` / ``mean`` / ``trapezoid`` along a contiguous
  axis is :func:`pairwise_sum`, numpy's own pairwise summation (``DOUBLE_pairwise_sum`` in
  ``numpy/_core/src/umath/loops_utils.h.src``: 8 running sums in blocks of up to 128, halves
  cut at multiples of 8) added to the reduction's initial 0.0;
* what numpy computes with its own SIMD code (``exp``, complex ``abs``, the FFT, ``power``)
  stays numpy's: the callers run those between the loops here.

tests/test_spectral_loops.py checks each loop against the numpy expression, compiled and as
plain Python, on random and edge-case inputs.
"""

from __future__ import annotations

import math

import numpy as np

from models._jit import compile_loop, jitable

_BLOCK = 128  # numpy's PW_BLOCKSIZE


@jitable
def _block_sum(a, lo, n):
    """numpy's pairwise sum of ``a[lo:lo + n]`` for ``n <= 128``: sequential below 8
    values, else 8 running sums combined pairwise, then the remainder. (Indexed in a slice
    of the block from non-negative loop counters: compiled, the index needs no wraparound
    check and the 8 sums vectorise: 2.5x faster, the same additions in the same order.)"""
    s = a[lo:lo + n]
    if n < 8:
        res = 0.0
        for i in range(n):
            res += s[i]
        return res
    r0, r1, r2, r3, r4, r5, r6, r7 = s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7]
    for j in range(1, n // 8):
        i = 8 * j
        r0 += s[i]
        r1 += s[i + 1]
        r2 += s[i + 2]
        r3 += s[i + 3]
        r4 += s[i + 4]
        r5 += s[i + 5]
        r6 += s[i + 6]
        r7 += s[i + 7]
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for i in range(n - n % 8, n):
        res += s[i]
    return res


@jitable
def _pairwise(a, lo, n):
    """numpy's pairwise sum of ``a[lo:lo + n]``: above 128 values the sum of the two halves
    (the first cut at a multiple of 8), left first. numpy recurses; this walks the same tree
    with a stack (numba compiles no recursion through these helpers): each node is visited
    to push its left half, then its right half, then to add the two sums."""
    if n <= _BLOCK:
        return _block_sum(a, lo, n)
    node_lo = np.empty(64, np.int64)  # depth <= log2(n / 128) + 1: 64 is any array
    node_n = np.empty(64, np.int64)
    node_visits = np.zeros(64, np.int64)
    sums = np.empty(64)
    depth, held = 1, 0
    node_lo[0], node_n[0] = lo, n
    while depth:
        top = depth - 1
        m = node_n[top]
        if m <= _BLOCK:
            sums[held] = _block_sum(a, node_lo[top], m)
            held += 1
            depth -= 1
            continue
        half = m // 2
        half -= half % 8
        visits = node_visits[top]
        node_visits[top] = visits + 1
        if visits == 2:  # both halves summed: replace them by their sum
            held -= 1
            sums[held - 1] = sums[held - 1] + sums[held]
            depth -= 1
        else:
            node_lo[depth] = node_lo[top] + (0 if visits == 0 else half)
            node_n[depth] = half if visits == 0 else m - half
            node_visits[depth] = 0
            depth += 1
    return sums[0]


@jitable
def pairwise_sum(a):
    """``np.sum(a)`` of a contiguous 1-D float64 array, to the bit (0.0 + numpy's pairwise
    sum: the reduction starts from add's identity)."""
    return 0.0 + _pairwise(a, 0, a.shape[0])


@jitable
def _detrend_row(src, window, out):
    """``out = (src - src.mean()) * window`` for one segment (``out`` may be ``src``: the mean
    is taken first), numpy's ``np.subtract(x, x.mean()); np.multiply(x, window)``."""
    n = window.shape[0]
    mean = pairwise_sum(src) / n
    for i in range(n):
        out[i] = (src[i] - mean) * window[i]


@compile_loop
def detrend_window(src, first, last, window, out):
    """``out`` rows = ``(x - x.mean()) * window`` of the rows ``src[c, first:last]`` of each
    signal ``c`` in turn (signal by signal, segment by segment): numpy's
    ``np.subtract(x, x.mean(axis=1, keepdims=True)); np.multiply(x, window)``."""
    k = 0
    for c in range(src.shape[0]):
        for j in range(first, last):
            _detrend_row(src[c, j], window, out[k])
            k += 1


@compile_loop
def window_segments(out, js, open_x, x, window):
    """Segments ``js`` (increasing) of a stream, each detrended and windowed
    (:func:`_detrend_row`) into a row of ``out``: segment ``j`` is samples ``[j n, (j + 1) n)``
    (``n = window.shape[0]``) of the open samples ``open_x`` followed by ``x``; only the first
    can start among the open ones (then it is joined in its row and transformed there: the
    same bits)."""
    n = window.shape[0]
    nc = open_x.shape[0]
    for k in range(js.shape[0]):
        row = out[k]
        start = js[k] * n - nc  # in x; < 0 for a segment starting among the open samples
        if start >= 0:
            _detrend_row(x[start:start + n], window, row)
        else:  # joined in its row first
            row[:-start] = open_x[nc + start:]
            row[-start:] = x[:start + n]
            _detrend_row(row, window, row)


@compile_loop
def add_power(acc, mags, scale, rows_per_signal, top):
    """Add each row's one-sided PSD ``|X|^2 / scale``, doubled at bins ``1 .. top - 1`` (all
    but DC and, for an even segment, Nyquist: ``top`` is ``mags.shape[1] - 1`` for an even
    segment length, ``mags.shape[1]`` for an odd one), into ``acc`` of its signal, row after
    row in order: signal ``c`` has rows ``[c m, (c + 1) m)`` of ``mags`` (``m =
    rows_per_signal``), numpy's ``np.square(psd); psd /= scale; psd[:, 1:top] *= 2.0`` then
    ``acc += row`` per row."""
    nb = mags.shape[1]
    for c in range(acc.shape[0]):
        for j in range(c * rows_per_signal, (c + 1) * rows_per_signal):
            for i in range(nb):
                p = mags[j, i] * mags[j, i]
                p = p / scale
                if 0 < i < top:
                    p = p * 2.0
                acc[c, i] += p


@compile_loop
def psd_moments(wpow, g, d, out):
    """``np.trapezoid(y, f)`` of the rows ``y[i] = wpow[i] * g`` (``d = np.diff(f)``) into
    ``out``: per row ``(d * (y[1:] + y[:-1]) / 2.0).sum()``. Returns 0, or 1 if ``g`` has a
    non-finite value, 2 if a negative one (checked first: nothing is computed then)."""
    n = g.shape[0]
    for k in range(n):
        if not math.isfinite(g[k]):
            return 1
    for k in range(n):
        if g[k] < 0.0:
            return 2
    terms = np.empty(n - 1)
    for r in range(wpow.shape[0]):
        prev = wpow[r, 0] * g[0]
        for k in range(n - 1):
            y = wpow[r, k + 1] * g[k + 1]
            terms[k] = d[k] * (y + prev) / 2.0
            prev = y
        out[r] = pairwise_sum(terms)
    return 0


@compile_loop
def dirlik_exponents(z, neg_z2, q, two_r2, e1, e2):
    """The exponents of Dirlik's density: ``e1 = -z / q``, ``e2 = neg_z2 / two_r2`` (numpy's
    ``np.exp`` is applied by the caller)."""
    for k in range(z.shape[0]):
        e1[k] = -z[k] / q
        e2[k] = neg_z2[k] / two_r2


@jitable
def _dirlik_at(z, rayleigh, d1_q, d2, r2, d3, e1, e2):
    """Dirlik's density at one node from its exponentials: ``d1 / q * e1 + d2 * z / r**2 *
    e2 + d3 * z * rayleigh``, left to right as numpy evaluates it (``d1_q = d1 / q``,
    ``r2 = r**2`` are the caller's scalars)."""
    return (d1_q * e1 + d2 * z / r2 * e2) + d3 * z * rayleigh


@compile_loop
def dirlik_combine(z, rayleigh, d1_q, d2, r2, d3, e1, e2, out):
    """Dirlik's density (:func:`_dirlik_at`) at every node."""
    for k in range(z.shape[0]):
        out[k] = _dirlik_at(z[k], rayleigh[k], d1_q, d2, r2, d3, e1[k], e2[k])


@compile_loop
def dirlik_damage_sum(w, z, rayleigh, d1_q, d2, r2, d3, e1, e2, dpc):
    """``np.sum(w * density * dpc)`` with Dirlik's density of :func:`dirlik_combine` computed
    in the same pass (each node's density the same double: the same bits)."""
    n = w.shape[0]
    terms = np.empty(n)
    for k in range(n):
        terms[k] = w[k] * _dirlik_at(z[k], rayleigh[k], d1_q, d2, r2, d3, e1[k], e2[k]) * dpc[k]
    return pairwise_sum(terms)


@compile_loop
def weighted_sum(w, density, dpc):
    """``np.sum(w * density * dpc)``."""
    n = w.shape[0]
    terms = np.empty(n)
    for k in range(n):
        terms[k] = w[k] * density[k] * dpc[k]
    return pairwise_sum(terms)


@compile_loop
def band_moments(f, s, f_min, f_max, out):
    """``models.waves.sea_state_from_psd``'s numbers over the band ``f_min <= f <= f_max``
    (its bins in order: ``fb = f[band]``, ``sb = s[band]``): ``out = [m0, m2, fp]`` with
    ``m0 = np.trapezoid(fb**0 * sb, fb)``, ``m2 = np.trapezoid(fb**2 * sb, fb)`` (the rows of
    :func:`psd_moments`; ``fb**0`` is 1.0, ``fb**2`` numpy's square ``fb * fb``) and ``fp``
    the peak's frequency refined by a parabola through the peak (``np.argmax``: the first
    maximum) and its neighbours when it opens downwards. Returns 0, or 1 if the band holds
    fewer than 3 bins, 2 if a value of ``sb`` is not finite, 3 if ``m0`` is not > 0 (checked
    in that order; ``out`` is then incomplete)."""
    band = np.empty(f.shape[0], np.int64)
    nb = 0
    for k in range(f.shape[0]):
        if f[k] >= f_min and f[k] <= f_max:
            band[nb] = k
            nb += 1
    if nb < 3:
        return 1
    for j in range(nb):
        if not math.isfinite(s[band[j]]):
            return 2
    t0 = np.empty(nb - 1)
    t2 = np.empty(nb - 1)
    a = band[0]
    for j in range(nb - 1):
        b = band[j + 1]
        d = f[b] - f[a]
        t0[j] = d * (s[b] + s[a]) / 2.0
        t2[j] = d * (f[b] * f[b] * s[b] + f[a] * f[a] * s[a]) / 2.0
        a = b
    m0 = pairwise_sum(t0)
    out[0] = m0
    out[1] = pairwise_sum(t2)
    if not m0 > 0.0:
        return 3
    i = 0
    for j in range(1, nb):
        if s[band[j]] > s[band[i]]:
            i = j
    fp = f[band[i]]
    if 0 < i < nb - 1:
        lo, mid, hi = s[band[i - 1]], s[band[i]], s[band[i + 1]]
        den = lo - 2.0 * mid + hi
        if den < 0.0:
            fp = fp + 0.5 * (lo - hi) / den * (f[band[1]] - f[band[0]])
    out[2] = fp
    return 0


@compile_loop
def steady_segments(t, n_open, t_open, n_seg, size, fs_ref, tolerance, taken):
    """Which of the ``n_seg`` segments of ``size`` samples of a stream are at its rate:
    segment ``j`` is samples ``[j size, (j + 1) size)`` of ``n_open`` earlier samples (the
    first at time ``t_open``) followed by ``t`` (int64 ns). A segment's rate is
    ``(size - 1) / span`` (NaN for a span <= 0); the reference rate is ``fs_ref``, or if that
    is NaN the first finite one; a segment is taken if its rate is within ``tolerance``
    (relative) of the reference. Writes the indices taken to ``taken``; returns (their
    count, the reference rate). numpy's expressions, element by element:
    ``spans = (t_end - t_start) / 1e9``, ``fs = (size - 1) / spans``,
    ``abs(fs / fs_ref - 1.0) <= tolerance``."""
    fs = np.empty(n_seg)
    for j in range(n_seg):
        end = size - 1 - n_open + j * size
        start = t_open if (j == 0 and n_open > 0) else t[max(end - (size - 1), 0)]
        span = (t[end] - start) / 1e9
        fs[j] = (size - 1) / span if span > 0 else np.nan
        if math.isnan(fs_ref) and math.isfinite(fs[j]):
            fs_ref = fs[j]
    n = 0
    for j in range(n_seg):
        if math.isfinite(fs[j]) and abs(fs[j] / fs_ref - 1.0) <= tolerance:
            taken[n] = j
            n += 1
    return n, fs_ref
