"""Compiled loops of the fatigue hot path: conductor stress, streaming rainflow, Miner damage.

They live in one file because numba's on-disk cache only checks the source file of the
compiled function: the building blocks a loop calls must sit in the same file, or editing
one would leave the callers' cached machine code stale. The modules that own the physics
document it (``models.helix``, ``models.fatigue.rainflow``, ``models.fatigue.miner``); this file is
their machinery, and every function here also runs as plain Python (numba is optional).

Determinism. Committed damage must be the same to the last bit for any split of a series
into blocks, so every value is computed from its own inputs by IEEE-754 operations alone,
and sums run sequentially in closure order. ``log_det``/``exp_det`` are table-free,
branch-free log and exp (within 1 ulp; reduction and minimax coefficients of Sun's fdlibm
``e_log.c``/``e_exp.c``), so compiled loops vectorise them; numba compiles without
fast-math, so a vector body and its scalar remainder round alike, and the same functions
on numpy arrays (the tests' oracles) or run as plain Python give the same bits.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from models._jit import bits_float, compile_loop, float_bits, jitable, select

# ----------------------------------------------------------------- log and exp
_LN2_HI = 6.93147180369123816490e-01  # ln 2 split so that k * _LN2_HI is exact for |k| < 2**20
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e+00
_SHIFT = 6755399441055744.0  # 1.5 * 2**52: adding it rounds to an integer held in the low bits
_SHIFT_BITS = 0x4338000000000000
_SQRT_HALF_BITS = 0x3FE6A09E667F3BCD  # mantissas are reduced to [sqrt(1/2), sqrt(2))
_TINY = 2.2250738585072014e-308  # smallest normal float64
_LG = (6.666666666666735130e-01, 3.999999999940941908e-01, 2.857142874366239149e-01,
       2.222219843214978396e-01, 1.818357216161805012e-01, 1.531383769920937332e-01,
       1.479819860511658591e-01)
_LG1, _LG2, _LG3, _LG4, _LG5, _LG6, _LG7 = _LG
_P1, _P2, _P3, _P4, _P5 = (1.66666666666666019037e-01, -2.77777777770155933842e-03,
                           6.61375632143793436117e-05, -1.65339022054652515390e-06,
                           4.13813679705723846039e-08)


@jitable
def log_det(x):
    """Natural log of x >= 0 (0 -> -inf, inf -> inf, negative or NaN -> NaN), < 1 ulp.

    x = 2**e * (1 + f) with 1 + f in [sqrt(1/2), sqrt(2)); with s = f / (2 + f),
    log(1 + f) = f - f**2/2 + s (f**2/2 + R(s**2)), R a minimax polynomial.
    """
    sub = x < _TINY  # subnormals: scale into the normal range first
    xn = x * select(sub, 18014398509481984.0, 1.0)  # 2**54
    bits = float_bits(xn)
    e = (bits - _SQRT_HALF_BITS) >> 52
    f = bits_float(bits - (e << 52)) - 1.0
    dk = (bits_float(e + _SHIFT_BITS) - _SHIFT) - select(sub, 54.0, 0.0)
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    r = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7))) + w * (_LG2 + w * (_LG4 + w * _LG6))
    hfsq = 0.5 * f * f
    y = dk * _LN2_HI - ((hfsq - (s * (hfsq + r) + dk * _LN2_LO)) - f)
    y = select(x < math.inf, y, x)
    return select(x > 0.0, y, select(x == 0.0, -math.inf, math.nan))


@jitable
def exp_det(y):
    """e**y for any float64 y (overflow -> inf, underflow -> 0 or subnormal), < 1 ulp.

    y = k ln 2 + r, |r| <= ln(2)/2; e**r = 1 + r + r c / (2 - c) with
    c = r - r**2 P(r**2); the power 2**k is applied as two factors so that subnormal
    results are rounded once.
    """
    yc = select(y < 1100.0, y, 1100.0)
    yc = select(yc > -1100.0, yc, -1100.0)
    kd = yc * _INV_LN2 + _SHIFT
    k = kd - _SHIFT
    hi = yc - k * _LN2_HI
    lo = k * _LN2_LO
    r = hi - lo
    r2 = r * r
    c = r - r2 * (_P1 + r2 * (_P2 + r2 * (_P3 + r2 * (_P4 + r2 * _P5))))
    p = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi)
    ki = float_bits(kd) - _SHIFT_BITS
    k1 = ki >> 1
    v = p * bits_float((k1 + 1023) << 52) * bits_float((ki - k1 + 1023) << 52)
    return select(np.isnan(y), y, v)


# ------------------------------------------------------------ conductor stress
@jitable
def axial_stress(t, k, tan_a, cos_a, rg_signed, e_mod):
    """Knapp axial stress E |cos a sqrt((1 + k T)^2 + (tan a + R G T)^2) - 1| (models.helix)."""
    a = 1.0 + k * t
    b = tan_a + rg_signed * t
    return abs(cos_a * math.sqrt(a * a + b * b) - 1.0) * e_mod


def axial_loop(t, k, tan_a, cos_a, rg_signed, e_mod, out):
    """``out[i] = axial_stress(t[i])``; returns the first non-finite index or -1.

    The arithmetic loop has no branch so it vectorises; a NaN or inf tension shows up as
    a non-finite stress, flagged by an OR in the same loop (a second pass over the output
    cost 4 ms per 1e7 samples) and then found by a search.
    """
    bad = False
    for i in range(t.shape[0]):
        s = axial_stress(t[i], k, tan_a, cos_a, rg_signed, e_mod)
        out[i] = s
        bad |= (s - s) != 0.0  # s - s is 0 for finite s, NaN otherwise
    if bad:
        for i in range(t.shape[0]):
            if not math.isfinite(out[i]):
                return i
    return -1


# ------------------------------------------------------------------ rainflow
# Layout of the rainflow state vector: a header, then the stack of turning points.
NS, CAND, DIR, HYST, STARTED, HEADER = 0, 1, 2, 3, 4, 5
CHUNK = 2048  # samples per pass: a chunk's stresses, turning points and cycles stay in cache


@jitable
def _all_finite(x):
    bad = False
    for i in range(x.shape[0]):  # x - x is 0 for finite x, NaN otherwise; the OR vectorises
        bad |= (x[i] - x[i]) != 0.0
    return not bad


@jitable
def _begin(st, x, i, n, ns, cand, dirn, hyst):
    """Take the first sample as a turning point, then wait until the signal leaves it by
    more than the hysteresis (that fixes the direction). Returns (i, ns, cand, dirn)."""
    if st[STARTED] == 0.0 and i < n:
        st[HEADER] = x[i]
        ns = 1
        cand = x[i]
        st[STARTED] = 1.0
        i += 1
    while i < n and dirn == 0.0:
        if abs(x[i] - cand) > hyst:
            dirn = 1.0 if x[i] > cand else -1.0
            cand = x[i]
        i += 1
    return i, ns, cand, dirn


@jitable
def _turning_points(x, cand, dirn, hyst, tp):
    """Confirmed turning points of the samples ``x`` into ``tp``, branch-free (noise makes
    branches unpredictable). Returns (count, cand, dirn).

    The candidate is extended when the signal moves on in its direction and confirmed
    when it retreats by more than ``hyst``. The loop is bound by the latency of the values
    it carries, so the direction is a 0/1 integer (and, or, xor take one cycle) and the
    common hyst = 0 has its own, shorter chain (``_turning_points_h0``).
    """
    if hyst == 0.0:
        return _turning_points_h0(x, cand, dirn, tp)
    m = 0
    up = 1 if dirn > 0.0 else 0
    for j in range(x.shape[0]):
        v = x[j]
        d = v - cand  # (v - cand) * dirn, without the multiply (dirn is +-1)
        rev = (up & (1 if d < -hyst else 0)) | ((1 - up) & (1 if d > hyst else 0))
        ext = (up & (1 if d > 0.0 else 0)) | ((1 - up) & (1 if d < 0.0 else 0))
        tp[m] = cand  # kept only when confirmed
        m += rev
        up ^= rev
        cand = v if (rev | ext) != 0 else cand
    return m, cand, 1.0 if up else -1.0


@jitable
def _turning_points_h0(x, cand, dirn, tp):
    """``_turning_points`` for hyst = 0. Then cand always equals the previous sample in
    value (it is the first of a run of equal ones, which keeps the sign of a zero), so the
    comparisons use the previous sample, off the carried chain."""
    m = 0
    up = 1 if dirn > 0.0 else 0
    prev = cand
    for j in range(x.shape[0]):
        v = x[j]
        rev = (up & (1 if v < prev else 0)) | ((1 - up) & (1 if v > prev else 0))
        tp[m] = cand
        m += rev
        up ^= rev
        cand = cand if v == prev else v
        prev = v
    return m, cand, 1.0 if up else -1.0


@jitable
def _close_cycles(st, ns, tp, m, ranges, means, k):
    """Push turning points tp[:m] on the stack in ``st``, closing four-point cycles into
    ranges[k:], means[k:]. Returns (ns, k)."""
    # the two top points live in registers (valid while ns >= 2); the point under test
    # stays in one until it is pushed
    top = st[HEADER + ns - 1]
    below = st[HEADER + ns - 2]
    for j in range(m):
        d = tp[j]
        while ns >= 3:
            r = abs(below - top)
            if (r <= abs(top - d)) & (r <= abs(st[HEADER + ns - 3] - below)):  # one branch, not two
                ranges[k] = r
                means[k] = 0.5 * (below + top)
                k += 1
                ns -= 2
                top = st[HEADER + ns - 1]
                below = st[HEADER + ns - 2]
            else:
                break
        st[HEADER + ns] = d
        below = top
        top = d
        ns += 1
    return ns, k


@jitable
def _count(st, x, i, stop, tp, ranges, means, k):
    """Count samples x[i:stop] into the counter state ``st``, chunk by chunk while the stack
    storage has room for the next chunk, closing cycles into ranges[k:], means[k:]; ``tp``
    holds a chunk's turning points. Returns (where it stopped, k); < stop when the storage
    may overflow."""
    ns = int(st[NS])
    cand = st[CAND]
    dirn = st[DIR]
    hyst = st[HYST]
    limit = st.shape[0] - HEADER
    i, ns, cand, dirn = _begin(st, x, i, stop, ns, cand, dirn, hyst)
    while i < stop and ns + min(CHUNK, stop - i) <= limit:
        end = min(i + CHUNK, stop)
        m, cand, dirn = _turning_points(x[i:end], cand, dirn, hyst, tp)
        ns, k = _close_cycles(st, ns, tp, m, ranges, means, k)
        i = end
    st[NS] = ns
    st[CAND] = cand
    st[DIR] = dirn
    return i, k


def cycle_room(st, n):
    """Columns of a ``feed_loop`` output for ``n`` more samples: each closed cycle removes
    two stack points, so this bounds the cycles one call can close."""
    return (int(st[NS]) + n) // 2 + 2


def feed_loop(st, x, out):
    """Process samples ``x`` into state ``st``, closing cycles into ``out`` (3 rows of at
    least ``cycle_room(st, len(x))``: ranges, means, counts); return (cycles closed,
    samples consumed).

    Returns consumed = -(i + 1) without touching ``st`` if x[i] is not finite, and
    consumed < len(x) when the stack storage in ``st`` may overflow (the caller grows it
    and calls again with the rest). The caller allocates ``out`` with numpy, which advises
    large arrays for transparent huge pages where numba's allocations get 4 kB pages: on a
    block of 1e7 samples the first-touch page faults of the cycles took 22 ms of a 75 ms
    call (measured 2026-11-25, 2-core Xeon). Only the used prefix of each row is touched.
    """
    n = x.shape[0]
    if not _all_finite(x):
        for i in range(n):
            if not math.isfinite(x[i]):
                return 0, -(i + 1)
    i, k = _count(st, x, 0, n, np.empty(min(CHUNK, n)), out[0], out[1], 0)
    out[2, :k] = 1.0
    return k, i


# --------------------------------------------------------------------- Miner
# ``params`` = [range scale to MPa, cut-off MPa, n_seg, m_0.., ln coef_0.., bounds_0..]
# (segment i: damage = count * exp(m_i ln S + ln coef_i); bounds ascending, MPa);
# ``table`` row 0 holds the histogram edges, row 1 the counts (last = overflow);
# ``inv_width`` > 0 marks uniform edges (direct bin index, then an exact check).


@jitable
def _cycle_damage(ranges, counts, params, ln_s, d):
    """d[:n] = damage of each cycle; branch-free passes so that every one vectorises."""
    n = ranges.shape[0]
    scale = params[0]
    cutoff = params[1]
    nseg = int(params[2])
    m_low = params[2 + nseg]
    c_low = params[2 + 2 * nseg]
    for i in range(n):
        ln_s[i] = log_det(ranges[i] * scale)
        d[i] = m_low * ln_s[i] + c_low
    for j in range(nseg - 1):  # ascending knees: each one passed selects a steeper segment
        bound = params[3 + 2 * nseg + j]
        m_j = params[1 + nseg - j]
        c_j = params[1 + 2 * nseg - j]
        for i in range(n):
            d[i] = select(ranges[i] * scale >= bound, m_j * ln_s[i] + c_j, d[i])
    for i in range(n):
        d[i] = select(ranges[i] * scale >= cutoff, counts[i] * exp_det(d[i]), 0.0)


@jitable
def _damage_chunks(ranges, counts, params):
    """Damage of each cycle (``_cycle_damage``, chunk by chunk)."""
    n = ranges.shape[0]
    d = np.empty(n)
    ln_s = np.empty(min(CHUNK, n))
    for i in range(0, n, CHUNK):
        end = min(i + CHUNK, n)
        _cycle_damage(ranges[i:end], counts[i:end], params, ln_s, d[i:end])
    return d


def damage_loop(ranges, counts, params):
    """Damage of each cycle (``_cycle_damage``, chunk by chunk): the one S-N evaluation
    behind ``SNCurve.damage_per_cycle`` as behind the committing loops, hence their bits."""
    return _damage_chunks(ranges, counts, params)


def scaled_damage_loop(ranges, counts, scale, params):
    """``damage_loop`` of ``ranges * scale`` (one product each: ``SNCurve.effective_range_MPa``
    without mean correction) in one call, once every range is checked finite and >= 0;
    returns (ok, damage), ok False (nothing computed) otherwise."""
    n = ranges.shape[0]
    ok = True
    for i in range(n):  # NaN fails both comparisons; the AND vectorises
        ok &= (ranges[i] >= 0.0) & (ranges[i] < np.inf)
    if not ok:
        return False, np.empty(0)
    s = np.empty(n)
    for i in range(n):
        s[i] = ranges[i] * scale
    return True, _damage_chunks(s, counts, params)


@jitable
def _bin(table, r, inv_width, guess):
    """The histogram bin of range ``r``: ``lo`` with edges[lo] <= r < edges[lo + 1], the
    overflow bin from the top edge on, -1 below the first edge. ``guess`` (a bin) is tried
    first: consecutive cycles mostly fall in the same bin."""
    nb = table.shape[1]
    if r >= table[0, nb - 1]:
        return nb - 1
    if not r >= table[0, 0]:
        return -1
    if guess < nb - 1 and r >= table[0, guess] and r < table[0, guess + 1]:
        return guess
    if inv_width > 0.0:  # uniform edges: direct index, then exact against the edges
        lo = min(int((r - table[0, 0]) * inv_width), nb - 2)
        while r < table[0, lo]:
            lo -= 1
        while r >= table[0, lo + 1]:
            lo += 1
        return lo
    lo = 0
    hi = nb - 1
    while hi - lo > 1:  # bisection: edges[lo] <= r < edges[hi]
        mid = (lo + hi) >> 1
        if r >= table[0, mid]:
            lo = mid
        else:
            hi = mid
    return lo


@jitable
def _commit_damage(ranges, counts, d, table, inv_width, committed):
    """Add d[:n] to ``committed`` one by one in order and bin the ranges; returns
    (committed, cycles). The count of the bin last added to is held in a register (one
    bin mostly takes run after run of cycles: a store and reload per cycle would chain
    them); each bin still adds its counts one by one in order."""
    cur = 0
    held = table[1, 0]
    cycles = 0.0
    for i in range(ranges.shape[0]):
        committed += d[i]
        cycles += counts[i]
        b = _bin(table, ranges[i], inv_width, cur)
        if b >= 0:
            if b != cur:
                table[1, cur] = held
                cur = b
                held = table[1, b]
            held += counts[i]
    table[1, cur] = held
    return committed, cycles


def commit_loop(ranges, counts, params, table, inv_width, committed):
    """Add each cycle's damage in order and bin it. Returns (committed, added, cycles, bad).

    ``bad`` is -1, or the index of the first invalid cycle; then nothing has changed.
    """
    n = ranges.shape[0]
    bad = False
    for i in range(n):  # r * 0 is 0 for finite r, NaN otherwise
        bad |= not ((ranges[i] >= 0.0) & (ranges[i] * 0.0 == 0.0) & (counts[i] >= 0.0) & (counts[i] * 0.0 == 0.0))
    if bad:
        for i in range(n):
            if not (ranges[i] >= 0.0 and math.isfinite(ranges[i]) and counts[i] >= 0.0 and math.isfinite(counts[i])):
                return committed, 0.0, 0.0, i
    start = committed
    c = min(CHUNK, n)
    committed, cycles = _commit_chunks(ranges, counts, params, table, inv_width, committed,
                                       np.empty(c), np.empty(c))
    return committed, committed - start, cycles, -1


@jitable
def _commit_chunks(ranges, counts, params, table, inv_width, committed, ln_s, d):
    """``_cycle_damage`` then ``_commit_damage`` per chunk of cycles, so the damages stay in
    cache (``ln_s``, ``d``: scratch of min(CHUNK, n)). Returns (committed, cycles)."""
    n = ranges.shape[0]
    cycles = 0.0
    for i in range(0, n, CHUNK):
        end = min(i + CHUNK, n)
        _cycle_damage(ranges[i:end], counts[i:end], params, ln_s, d)
        committed, more = _commit_damage(ranges[i:end], counts[i:end], d, table, inv_width, committed)
        cycles += more
    return committed, cycles


# ------------------------------------------------------------------ residue
@jitable
def _residue_cycles(st, pts, r, mn, c):
    """The counter's open residue (stack, then the running extreme once the direction is
    known) counted as ASTM E1049 counts the end of a series (three-point rule, the start
    point moving on with each half cycle), in its order: ranges into ``r``, means into
    ``mn``, counts (0.5 or 1.0) into ``c``; ``pts`` is scratch. All four hold at least the
    residue's length. Returns the count."""
    ns = int(st[NS])
    n = ns + (1 if st[DIR] != 0.0 else 0)
    top = 0
    start = 0
    k = 0
    for p in range(n):
        pts[top] = st[HEADER + p] if p < ns else st[CAND]
        top += 1
        while top - start >= 3:
            x = abs(pts[top - 1] - pts[top - 2])
            y = abs(pts[top - 2] - pts[top - 3])
            if x < y:
                break
            r[k] = y
            mn[k] = 0.5 * (pts[top - 3] + pts[top - 2])
            if top - start == 3:  # Y holds the starting point: a half cycle
                c[k] = 0.5
                start += 1
            else:
                c[k] = 1.0
                pts[top - 3] = pts[top - 1]
                top -= 2
            k += 1
    for i in range(start, top - 1):
        r[k] = abs(pts[i] - pts[i + 1])
        mn[k] = 0.5 * (pts[i] + pts[i + 1])
        c[k] = 0.5
        k += 1
    return k


def residue_cycles_loop(st):
    """``_residue_cycles`` of the counter state ``st``: (3, k) ranges, means, counts."""
    n = int(st[NS]) + 1
    out = np.empty((3, n))
    k = _residue_cycles(st, np.empty(n), out[0], out[1], out[2])
    return out[:, :k]


@jitable
def _residue_damage(st, params, pts, r, mn, c, ln_s, d):
    """Miner damage of the residue cycles (``_residue_cycles``), each as ``_cycle_damage``
    computes it, summed in counting order; the arrays are scratch of the residue's length."""
    k = _residue_cycles(st, pts, r, mn, c)
    _cycle_damage(r[:k], c[:k], params, ln_s, d)
    total = 0.0
    for i in range(k):
        total += d[i]
    return total


def residue_loop(st, params):
    """``_residue_damage`` of the counter state ``st`` (one compiled call)."""
    n = int(st[NS]) + 1
    return _residue_damage(st, params, np.empty(n), np.empty(n), np.empty(n), np.empty(n),
                           np.empty(n), np.empty(n))


# -------------------------------------------------------------------- ticks
TICK_GROUP = 64  # ticks counted before their cycles' damage is evaluated in one pass
RESIDUE_ROOM = 1 << 15  # residue cycles buffered per group (a group ends early past it)


@jitable
def _grown(a, n, size):
    """``a`` in a new array of ``size`` with its first ``n`` values."""
    out = np.empty(size)
    out[:n] = a[:n]
    return out


def ticks_loop(x, stops, k, st, params, table, inv_width, committed, pre_r, pre_c,
               out_r, out_m, nc, t_committed, t_cycles, t_residue, residue):
    """Whole alert ticks of stresses ``x``: tick k takes x[stops[k - 1]:stops[k]] (from 0
    for the first); at its end its closed cycles are committed (after ``pre_r``/``pre_c``,
    cycles pending from earlier blocks, in the first tick), and the committed damage, the
    cycles committed and (if ``residue``) the residue damage are recorded in
    ``t_committed[k]``, ``t_cycles[k]``, ``t_residue[k]``.

    The same computations in the same order as ``feed_loop`` per tick, then
    ``commit_loop`` of the pending and closed cycles, then ``residue_loop``: the same bits.
    The ticks go in groups: a group's samples are counted tick by tick, keeping the number
    of cycles closed and each tick end's residue cycles; then the damage of all of them is
    evaluated in long vectorised passes (a tick closes some 40 cycles, too few for the
    vector loops), and committed and summed tick by tick in order (a cycle's damage does
    not depend on the others, so the bits are those of the tick-by-tick calls).
    Starts at tick ``k``, writing closed cycles from ``out_r[nc]``/``out_m[nc]``; returns
    (k, nc, committed), k < len(stops) when tick k may not fit the stack storage (grow it
    and call again from there), or k = -1 if x holds a NaN or inf (nothing changed).
    """
    if not _all_finite(x):
        return -1, nc, committed
    n_ticks = stops.shape[0]
    limit = st.shape[0] - HEADER
    tp = np.empty(CHUNK)
    ln_s = np.empty(CHUNK)
    d = np.empty(CHUNK)
    ones = np.ones(out_r.shape[0])
    dc = np.empty(out_r.shape[0])  # the closed cycles' damage
    tick_nc = np.empty(TICK_GROUP + 1, np.int64)  # cycles closed before each tick of a group
    tick_res = np.zeros(TICK_GROUP + 1, np.int64)  # residue cycles buffered before each tick
    room = 64 * TICK_GROUP
    # the residue cycles' ranges, means, counts and damage (pts: scratch)
    rr, rm, rc, rd = np.empty(room), np.empty(room), np.empty(room), np.empty(room)
    pts = np.empty(64)
    start = stops[k - 1] if k > 0 else 0
    full = False
    while k < n_ticks and not full:
        g0 = k
        first = nc
        tick_nc[0] = nc
        nres = 0
        while k < n_ticks and k - g0 < TICK_GROUP:
            stop = stops[k]
            if int(st[NS]) + (stop - start) > limit:  # the whole tick must fit the storage
                full = True
                break
            need = min(int(st[NS]) + (stop - start), limit) + 1  # the residue's length at most
            if residue and nres + need > room:
                if k > g0 and nres + need > RESIDUE_ROOM:
                    break  # the group ends here
                room = 2 * (nres + need)
                rr, rc = _grown(rr, nres, room), _grown(rc, nres, room)
                rm, rd = np.empty(room), np.empty(room)  # (means are not needed past the count)
            _, nc = _count(st, x, start, stop, tp, out_r, out_m, nc)
            tick_nc[k - g0 + 1] = nc
            if residue:
                ns = int(st[NS])
                if ns + 1 > pts.shape[0]:
                    pts = np.empty(2 * (ns + 1))
                nres += _residue_cycles(st, pts, rr[nres:], rm[nres:], rc[nres:])
                tick_res[k - g0 + 1] = nres
            start = stop
            k += 1
        for i in range(first, nc, CHUNK):
            end = min(i + CHUNK, nc)
            _cycle_damage(out_r[i:end], ones[i:end], params, ln_s, dc[i:end])
        for i in range(0, nres, CHUNK):
            end = min(i + CHUNK, nres)
            _cycle_damage(rr[i:end], rc[i:end], params, ln_s, rd[i:end])
        for j in range(k - g0):
            cycles = 0.0
            if g0 + j == 0 and pre_r.shape[0] > 0:
                committed, cycles = _commit_chunks(pre_r, pre_c, params, table, inv_width,
                                                   committed, ln_s, d)
            a = tick_nc[j]
            b = tick_nc[j + 1]
            committed, more = _commit_damage(out_r[a:b], ones[a:b], dc[a:b], table, inv_width,
                                             committed)
            t_committed[g0 + j] = committed
            t_cycles[g0 + j] = cycles + more
            if residue:  # summed in counting order, as _residue_damage does
                total = 0.0
                for i in range(tick_res[j], tick_res[j + 1]):
                    total += rd[i]
                t_residue[g0 + j] = total
    return k, nc, committed


# -------------------------------------------------------------------- dating
@jitable
def remaining_life_days(damage, rate_per_day):
    """Days until the Miner sum ``damage`` reaches 1 at ``rate_per_day`` (1/day): 0 once it
    has (also when the rate has since dropped to nothing), infinite while nothing accrues."""
    if damage >= 1.0:
        return 0.0
    return (1.0 - damage) / rate_per_day if rate_per_day > 0.0 else math.inf


def date_loop(committed, cycles, times, residue, prev, total, t_first, keys, vals, n, width,
              n_buckets, rates, damage, life):
    """``MinerAccumulator._take_kernel_ticks``'s dating of consecutive ticks: tick i brought
    the committed damage to ``committed[i]`` with ``cycles[i]`` cycles at ``times[i]``
    (non-decreasing) from ``prev`` (``total`` cycles before the first). Each tick's damage
    goes to the rate bucket of its time in ``keys[:n]``/``vals[:n]`` (the accumulator's
    buckets in their order, with room for one more per tick) and buckets past the window
    are dropped, as ``MinerAccumulator._date`` does; ``rates[i]`` is then
    ``_rate_per_day``, ``damage[i] = committed[i] + residue[i]`` and ``life[i]`` its
    ``remaining_life_days``. ``t_first`` is NaN before the first dated commit. The same
    float operations in the same order as those methods: the same bits.
    Returns (prev, total, t_first, n)."""
    keep = n_buckets + 1
    for i in range(committed.shape[0]):
        c = committed[i]
        added = c - prev
        prev = c
        total += cycles[i]
        t = times[i]
        if math.isnan(t_first):
            t_first = t
        b = math.floor(t / width)
        j = n - 1
        while j >= 0 and keys[j] != b:
            j -= 1
        if j >= 0:
            vals[j] = vals[j] + added
        else:
            keys[n] = b
            vals[n] = 0.0 + added
            n += 1
        if n > keep:
            oldest = b - n_buckets
            kept = 0
            for j in range(n):
                if keys[j] > oldest:
                    keys[kept] = keys[j]
                    vals[kept] = vals[j]
                    kept += 1
            n = kept
        rate = 0.0
        if t > t_first:
            # the window's buckets in time order (the newest, b, last), summed one by one
            # from zero as _rate_per_day's sum() adds them
            in_window = 0.0
            for j in range(n):
                if keys[j] > b - n_buckets:
                    in_window += vals[j]
            whole, since = t - t_first, t - (b - n_buckets + 1) * width
            span = since if since < whole else whole  # min(whole, since)
            if span > 0:
                rate = in_window / span * 86400.0
        rates[i] = rate
        damage[i] = c + residue[i]
        life[i] = remaining_life_days(damage[i], rate)
    return prev, total, t_first, n


_LOOPS: dict[str, Callable] = {"axial_compiled": axial_loop, "feed_compiled": feed_loop,
                               "commit_compiled": commit_loop,
                               "commit_damage_compiled": _commit_damage,
                               "damage_compiled": damage_loop, "residue_compiled": residue_loop,
                               "scaled_damage_compiled": scaled_damage_loop,
                               "residue_cycles_compiled": residue_cycles_loop,
                               "ticks_compiled": ticks_loop, "date_compiled": date_loop}


def __getattr__(name: str):
    """``<loop>_compiled``: the loop compiled (None without numba) on first access, then a
    plain module attribute: importing numba is left to the first process that runs a loop
    (models._jit says what that saves)."""
    if name not in _LOOPS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    compiled = globals()[name] = compile_loop(_LOOPS[name])
    return compiled
