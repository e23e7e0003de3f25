"""QARTOD quality-control flags for every stream, computed while streaming.

The tests and flags of the IOOS QARTOD manuals (general, in-situ currents, waves), with the
semantics of ``ioos_qc.qartod`` (the test oracle, tests/test_qartod.py)::

    1 pass   2 not evaluated   3 suspect   4 fail   9 missing (the value is NaN / infinite)

``gross_range``     outside the sensor span (or infinite) -> fail; outside the operator span
                    -> suspect
``spike``           ``|x[n-1] - (x[n-2] + x[n]) / 2|`` above a threshold (ioos_qc "average"
                    method): a centred test, so the flag of a sample is known when the NEXT
                    sample arrives; the first sample and the last one so far stay 2
``rate_of_change``  ``|x[n] - x[n-1]| / dt`` above ``rate_suspect_per_s`` -> suspect, above
                    ``max_rate_per_s`` -> fail
``flat_line``       every value in the last ``flat_suspect_s`` (``flat_fail_s``) seconds within
                    ``flat_tolerance`` of each other -> suspect (fail); the first window's
                    samples pass
``location``        (GNSS) distance from the previous fix above ``location_range_max_m`` ->
                    suspect; only one of lat/lon missing, or |lat| > 90, |lon| > 180 -> fail
``check_factor``    (motion) horizontal motion in a window no linear wave makes -> fail
                    (:mod:`monitor.check_factor`; not an ioos_qc test)

A stream with several fields gets one flag per test and sample: the worst over its fields
(missing > fail > suspect > pass > not evaluated). A test switched off for a field (threshold
inf, tolerance 0) gives 2 for it.

Differences from ``ioos_qc`` batch results, on purpose: time steps are exact (ioos_qc truncates
them to whole seconds, so its rate is infinite for sub-second data), and the flat-line window is
the samples within the last N seconds (ioos_qc counts ``N / median step`` samples, which needs
the whole record; both agree for evenly sampled data). The flat-line memory holds at most
:data:`FLAT_MEMORY` samples per stream, so a window longer than that many samples is cut to it.

Speed: a block of finite values after a stream's first two samples (the usual block) goes
through ``_qc_fast``, test by test in loops the compiler vectorises; any other block through
the general ``_qc``; both give the same flags (the split test compares them).

Streaming: :class:`StreamQC` carries every test's memory across blocks (and in its state), so
any split of a stream into blocks gives the same flags as one pass. Only samples later than the
last one seen enter the tests (re-delivered and out-of-order samples are the validator's
``duplicate`` / ``time_backwards`` rejections and get no flags).
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from models._jit import kernel
from monitor.check_factor import CheckFactor
from monitor.config import FieldLimits

PASS, NOT_EVALUATED, SUSPECT, FAIL, MISSING = 1, 2, 3, 4, 9
TESTS: tuple[str, ...] = ("gross_range", "spike", "rate_of_change", "flat_line", "location",
                          "check_factor")
GROSS, SPIKE, RATE, FLAT, LOCATION, CHECK = range(len(TESTS))
FLAT_MEMORY = 4096
_EARTH_RADIUS_M = 6_371_008.8  # mean radius (IUGG): haversine distance between fixes


def _params(fields: tuple[FieldLimits, ...]) -> np.ndarray:
    """The kernels' thresholds per field: the sensor span and the fastest physical change of
    a field's limits are its gross-range and rate-of-change fail thresholds."""
    return np.array([[f.min, f.max, f.suspect_min, f.suspect_max, f.spike_suspect,
                      f.spike_fail, f.rate_suspect_per_s, f.max_rate_per_s, f.flat_tolerance,
                      f.flat_suspect_s, f.flat_fail_s] for f in fields], dtype=np.float64)


_N_TESTS = 6  # the kernels leave the check factor's row at 2 (not evaluated): CheckFactor fills it
# counts column of a flag: suspect 0, fail 1, missing 2
_SLOT = np.array([0, 0, 0, 0, 1, 0, 0, 0, 0, 2], np.int64)


# worst-of order: missing > fail > suspect > pass > not evaluated (index: flag)
_RANK = np.array([0, 1, 0, 3, 4, 0, 0, 0, 0, 5], np.int64)


@kernel(nogil=True, inline="always")
def _worst(a, b):  # pragma: no cover - compiled
    return a if _RANK[a] >= _RANK[b] else b


@kernel(nogil=True, inline="always")
def _flat_widen(w, age, lo, hi, tol, sw, fw, flat_s, flat_f):  # pragma: no cover - compiled
    """One older value ``w`` (NaN skipped) of the flat-line scan widens [lo, hi]; once that
    spans ``tol`` the line is not flat in the windows (suspect ``sw``, fail ``fw``) reaching
    back ``age``, and the scan is done. Returns (lo, hi, flat_s, flat_f, done)."""
    if np.isfinite(w):
        lo = min(lo, w)
        hi = max(hi, w)
        if hi - lo >= tol:
            return lo, hi, flat_s and age > sw, flat_f and age > fw, True
    return lo, hi, flat_s, flat_f, False


@kernel(nogil=True, error_model="numpy")
def _qc(t, x, p, location_max_m, prev_t, prev, prev2, n_seen, ring_t, ring_x, ring_head, ring_n, first_t):  # pragma: no cover - compiled
    """Flags ``(len(TESTS), n)`` of the samples ``t, x`` (``x``: fields x samples) and the
    spike flag of each sample's PREDECESSOR (0 = none). State arrays are updated in place;
    returns (flags, spike_prev, counts, prev_t, n_seen, ring_head, ring_n, first_t)."""
    nf, n = x.shape
    cap = ring_t.shape[0]
    # which tests run on which field, decided once
    do_spike = np.zeros(nf, np.bool_)
    do_rate = np.zeros(nf, np.bool_)
    do_flat = np.zeros(nf, np.bool_)
    s_ns = np.zeros(nf)
    f_ns = np.zeros(nf)
    for f in range(nf):
        do_spike[f] = np.isfinite(p[f, 4]) or np.isfinite(p[f, 5])
        do_rate[f] = np.isfinite(p[f, 6]) or np.isfinite(p[f, 7])
        do_flat[f] = p[f, 8] > 0 and (np.isfinite(p[f, 9]) or np.isfinite(p[f, 10]))
        s_ns[f] = p[f, 9] * 1e9
        f_ns[f] = p[f, 10] * 1e9
    flags = np.full((_N_TESTS, n), 2, np.uint8)
    spike_prev = np.zeros(n, np.uint8)
    # per test: suspect, fail, missing (the spike test's of the predecessors)
    counts = np.zeros((_N_TESTS, 3), np.int64)
    for i in range(n):
        ti = t[i]
        if n_seen == 0:
            first_t = ti
        dt = (ti - prev_t) * 1e-9
        sp = 0
        gr = 2
        rt = 2
        ft = 2
        for f in range(nf):
            v = x[f, i]
            ok = np.isfinite(v)
            # gross range (an infinite value is out of range, as in ioos_qc)
            if np.isnan(v):
                g = 9
            elif v < p[f, 0] or v > p[f, 1]:
                g = 4
            elif v < p[f, 2] or v > p[f, 3]:
                g = 3
            else:
                g = 1
            gr = _worst(gr, g)
            # spike of the previous sample (x[n-1]) now that x[n] is here
            if n_seen >= 1 and do_spike[f]:
                if not np.isfinite(prev[f]):
                    s = 9
                elif n_seen < 2 or not np.isfinite(prev2[f]) or not ok:
                    s = 2
                else:
                    d = abs(prev[f] - (prev2[f] + v) / 2.0)
                    s = 1
                    if d > p[f, 4]:
                        s = 3
                    if d > p[f, 5]:
                        s = 4
                sp = s if sp == 0 else _worst(sp, s)
            # rate of change
            if do_rate[f]:
                if not ok:
                    r = 9
                elif n_seen == 0 or np.isnan(prev[f]):
                    r = 1  # (after an infinite value the rate is infinite, as in ioos_qc)
                else:
                    roc = abs(v - prev[f]) / dt
                    r = 1
                    if roc > p[f, 6]:
                        r = 3
                    if roc > p[f, 7]:
                        r = 4
                rt = _worst(rt, r)
            # flat line over the samples within the longer window (newest first)
            tol = p[f, 8]
            if do_flat[f]:
                if not ok:
                    fl = 9
                else:
                    lo = v
                    hi = v
                    sw = s_ns[f]
                    fw = f_ns[f]
                    flat_s = True
                    flat_f = True
                    k = 0
                    while k < ring_n:
                        j = ring_head - 1 - k
                        if j < 0:
                            j += cap
                        age = ti - ring_t[j]
                        if age > sw and age > fw:
                            break
                        lo, hi, flat_s, flat_f, done = _flat_widen(ring_x[f, j], age, lo, hi, tol, sw,
                                                                   fw, flat_s, flat_f)
                        if done:
                            break
                        k += 1
                    span = (ti - first_t) + (ti - prev_t if n_seen else 0)
                    fl = 1
                    if flat_s and span > sw:
                        fl = 3
                    if flat_f and span > fw:
                        fl = 4
                ft = _worst(ft, fl)
        if location_max_m > 0 and nf == 2:
            lat = x[0, i]
            lon = x[1, i]
            a, b = np.isfinite(lat), np.isfinite(lon)
            if a != b:
                loc = 4
            elif not a:
                loc = 9
            else:
                loc = 1
                # no distance from an impossible fix (undefined, as in ioos_qc)
                if n_seen >= 1 and abs(prev[0]) <= 90 and abs(prev[1]) <= 180:
                    p1, p2 = np.radians(prev[0]), np.radians(lat)
                    h = (np.sin((p2 - p1) / 2) ** 2 + np.cos(p1) * np.cos(p2)
                         * np.sin(np.radians(lon - prev[1]) / 2) ** 2)
                    # math.asin: libm's, compiled or not (numpy's own arcsin differs in the
                    # last bit from it, so a kernel run as plain Python would too)
                    if 2 * _EARTH_RADIUS_M * math.asin(np.sqrt(min(h, 1.0))) > location_max_m:
                        loc = 3
                if abs(lat) > 90 or abs(lon) > 180:
                    loc = 4
            flags[4, i] = loc
        flags[0, i] = gr
        flags[2, i] = rt
        flags[3, i] = ft
        if n_seen >= 1:
            spike_prev[i] = sp if sp != 0 else 2
        # tally only what is flagged (the usual pass / not-evaluated costs one compare each)
        if gr > 2:
            counts[0, _SLOT[gr]] += 1
        if spike_prev[i] > 2:
            counts[1, _SLOT[spike_prev[i]]] += 1
        if rt > 2:
            counts[2, _SLOT[rt]] += 1
        if ft > 2:
            counts[3, _SLOT[ft]] += 1
        if flags[4, i] > 2:
            counts[4, _SLOT[flags[4, i]]] += 1
        for f in range(nf):
            prev2[f] = prev[f]
            prev[f] = x[f, i]
        ring_t[ring_head] = ti
        for f in range(nf):
            ring_x[f, ring_head] = x[f, i]
        ring_head += 1  # (no modulo: an integer division per sample is most of the cost)
        if ring_head == cap:
            ring_head = 0
        if ring_n < cap:
            ring_n += 1
        prev_t = ti
        n_seen += 1
    return flags, spike_prev, counts, prev_t, n_seen, ring_head, ring_n, first_t



@kernel(nogil=True, error_model="numpy")
def _qc_fast(t, x, p, prev_t, prev, prev2, ring_t, ring_x, ring_head, ring_n, first_t):
    # pragma: no cover - compiled
    """The usual block, test by test in branch-free loops the compiler vectorises, writing
    the flag rows in place: every value finite, two finite samples before it, no location
    test. Returns ``(ok, flags, spike_prev, counts, ring_head, ring_n)``; ``ok`` False
    (nothing changed) means: use :func:`_qc`. Same flags as :func:`_qc` for such a block."""
    n = x.shape[1]
    flags = np.full((_N_TESTS, n), 2, np.uint8)
    spike_prev = np.full(n, 2, np.uint8)
    counts = np.zeros((_N_TESTS, 3), np.int64)
    if not fast_finite(x, prev, prev2):
        return False, flags, spike_prev, counts, ring_head, ring_n
    dt = np.empty(n)
    steps(t, prev_t, 0, dt)
    qc_span(t, x, p, prev_t, prev, prev2, ring_t, ring_x, ring_head, ring_n, first_t, 0, dt,
            np.empty(n + 2), np.empty(n, np.bool_), flags[0], spike_prev, flags[2], flags[3])
    tally(flags[0], spike_prev, flags[2], flags[3], counts)
    ring_head, ring_n = remember(t, x, ring_t, ring_x, ring_head, ring_n)
    return True, flags, spike_prev, counts, ring_head, ring_n


# The pieces of _qc_fast, public for monitor.validate's one pass over a block (which runs
# them span by span: its scratch then stays in the cache, and no flag rows are kept).

@kernel(nogil=True, inline="always")
def fast_finite(x, prev, prev2):  # pragma: no cover - compiled
    """Every value of ``x`` and the two samples before it finite (:func:`_qc_fast`'s
    block)."""
    bad = False  # x - x is 0 for finite x, NaN otherwise: the OR vectorises
    for f in range(x.shape[0]):
        bad |= not (np.isfinite(prev[f]) and np.isfinite(prev2[f]))
        for i in range(x.shape[1]):
            bad |= (x[f, i] - x[f, i]) != 0.0
    return not bad


@kernel(nogil=True, inline="always")
def steps(t, prev_t, a, dt):  # pragma: no cover - compiled
    """``dt[k]``: the time step in seconds before sample ``a + k`` (from ``prev_t`` to the
    first sample)."""
    tt = t[a:a + dt.shape[0]]  # (indices from 0: the loop vectorises)
    dt[0] = (tt[0] - (t[a - 1] if a else prev_t)) * 1e-9
    for k in range(1, dt.shape[0]):
        dt[k] = (tt[k] - tt[k - 1]) * 1e-9


@kernel(nogil=True, error_model="numpy", inline="always")
def qc_span(t, x, p, prev_t, prev, prev2, ring_t, ring_x, ring_head, ring_n, first_t, a, dt,
            z, quick, gr, sp, rt, ft):  # pragma: no cover - compiled
    """:func:`_qc_fast`'s flags of the samples ``a .. a + m - 1`` of its block (``dt``: their
    :func:`steps`, length m) into ``gr, sp, rt, ft`` (length m: gross range, the spike flag
    of each sample's predecessor, rate of change, flat line). ``z`` (m + 2) and ``quick``
    (m) are scratch. The memory (``prev*``, ``ring_*``) is the stream's before the block."""
    nf = x.shape[0]
    m = dt.shape[0]
    cap = ring_t.shape[0]
    gr[:] = 1
    sp[:] = 2
    rt[:] = 2
    ft[:] = 2
    for f in range(nf):
        xf = x[f]
        # the field's values from two before the span
        z[0] = xf[a - 2] if a >= 2 else (prev[f] if a else prev2[f])
        z[1] = xf[a - 1] if a else prev[f]
        z[2:] = xf[a:a + m]
        # thresholds in locals: the loops below then vectorise
        fmin, fmax, smin, smax = p[f, 0], p[f, 1], p[f, 2], p[f, 3]
        for i in range(m):
            v = z[i + 2]
            g = np.uint8(4) if (v < fmin or v > fmax) else (
                np.uint8(3) if (v < smin or v > smax) else np.uint8(1))
            gr[i] = max(gr[i], g)
        if np.isfinite(p[f, 6]) or np.isfinite(p[f, 7]):
            rs, rf = p[f, 6], p[f, 7]
            for i in range(m):
                roc = abs(z[i + 2] - z[i + 1]) / dt[i]
                r = np.uint8(4) if roc > rf else (np.uint8(3) if roc > rs else np.uint8(1))
                rt[i] = r if rt[i] == 2 else max(rt[i], r)
        if np.isfinite(p[f, 4]) or np.isfinite(p[f, 5]):
            ss, sf = p[f, 4], p[f, 5]
            for i in range(m):
                d = abs(z[i + 1] - (z[i] + z[i + 2]) / 2.0)
                s = np.uint8(4) if d > sf else (np.uint8(3) if d > ss else np.uint8(1))
                sp[i] = s if sp[i] == 2 else max(sp[i], s)
        tol = p[f, 8]
        if tol > 0 and (np.isfinite(p[f, 9]) or np.isfinite(p[f, 10])):
            sw = p[f, 9] * 1e9
            fw = p[f, 10] * 1e9
            near = min(sw, fw) * 1e-9
            # a sample whose predecessor lies within both windows and differs by tol or more
            # is not flat: decided here in a loop the compiler vectorises; the few others
            # take the scan below
            slow = 0
            for i in range(m):
                q = (abs(z[i + 2] - z[i + 1]) >= tol) & (dt[i] <= near)
                quick[i] = q
                ft[i] = np.uint8(1) if q & (ft[i] == 2) else ft[i]
                slow += not q
            i = -1
            while slow:
                i += 1
                if quick[i]:
                    continue
                slow -= 1
                # the flat-line scan of _qc (newest first, stop at the first value out of
                # tolerance), over this block's earlier samples, then the memory
                ti = t[a + i]
                v = z[i + 2]
                lo = v
                hi = v
                flat_s = True
                flat_f = True
                k = a + i - 1
                back = 0
                while True:
                    if k >= 0:
                        tj = t[k]
                        w = xf[k]
                    elif back < ring_n:
                        j = ring_head - 1 - back
                        if j < 0:
                            j += cap
                        tj = ring_t[j]
                        w = ring_x[f, j]
                        back += 1
                    else:
                        break
                    k -= 1
                    age = ti - tj
                    if age > sw and age > fw:
                        break
                    lo, hi, flat_s, flat_f, done = _flat_widen(w, age, lo, hi, tol, sw, fw, flat_s, flat_f)
                    if done:
                        break
                span = (ti - first_t) + (ti - (t[a + i - 1] if a + i else prev_t))
                fl = np.uint8(1)
                if flat_s and span > sw:
                    fl = np.uint8(3)
                if flat_f and span > fw:
                    fl = np.uint8(4)
                ft[i] = fl if ft[i] == 2 else max(ft[i], fl)


@kernel(nogil=True, inline="always")
def tally(gr, sp, rt, ft, counts):  # pragma: no cover - compiled
    """Add the suspect and fail flags of :func:`qc_span`'s rows to ``counts`` (tests x
    suspect, fail, missing)."""
    worst = np.uint8(0)  # nearly always a pass: then nothing to count
    for i in range(gr.shape[0]):
        worst = max(worst, max(max(gr[i], sp[i]), max(rt[i], ft[i])))
    if worst < 3:
        return
    # tallies in locals (stores into ``counts`` each sample would not vectorise)
    g3 = g4 = s3 = s4 = r3 = r4 = f3 = f4 = 0
    for i in range(gr.shape[0]):
        g3 += gr[i] == 3
        g4 += gr[i] == 4
        s3 += sp[i] == 3
        s4 += sp[i] == 4
        r3 += rt[i] == 3
        r4 += rt[i] == 4
        f3 += ft[i] == 3
        f4 += ft[i] == 4
    counts[0, 0] += g3
    counts[0, 1] += g4
    counts[1, 0] += s3
    counts[1, 1] += s4
    counts[2, 0] += r3
    counts[2, 1] += r4
    counts[3, 0] += f3
    counts[3, 1] += f4


@kernel(nogil=True, inline="always")
def remember(t, x, ring_t, ring_x, ring_head, ring_n):  # pragma: no cover - compiled
    """The block's newest samples into the flat-line memory; returns (ring_head, ring_n)."""
    n = t.shape[0]
    cap = ring_t.shape[0]
    # up to the memory's end, then on from its start (copies)
    a = max(0, n - cap)
    first = min(n - a, cap - ring_head)
    ring_t[ring_head:ring_head + first] = t[a:a + first]
    ring_x[:, ring_head:ring_head + first] = x[:, a:a + first]
    ring_t[:n - a - first] = t[a + first:]
    ring_x[:, :n - a - first] = x[:, a + first:]
    return (ring_head + n - a) % cap, min(ring_n + n - a, cap)


class StreamQC:
    """The QARTOD tests of one stream, with counts per test and the memory across blocks."""

    def __init__(self, fields: tuple[FieldLimits, ...], location_range_max_m: float = 0.0,
                 state: Mapping[str, Any] | None = None,
                 check_factor: tuple[float, float, float] | None = None) -> None:
        """``check_factor``: (depth m, longest wave period s, gap s) of a motion stream's
        (heave, surge, sway) check-factor test (:class:`CheckFactor`), None = off."""
        self.fields = fields
        self._p = _params(fields)
        self._cf = None if check_factor is None else CheckFactor(
            *check_factor, max_rate_per_s=tuple(self._p[:, 7]),
            state=None if state is None else state.get("check_factor"))
        self._loc = float(location_range_max_m)
        # the flat-line test needs the samples of its longest window; others two samples
        windows = [max(f.flat_suspect_s if np.isfinite(f.flat_suspect_s) else 0.0,
                       f.flat_fail_s if np.isfinite(f.flat_fail_s) else 0.0)
                   for f in fields if f.flat_tolerance > 0]
        self._cap = FLAT_MEMORY if any(w > 0 for w in windows) else 1
        nf = len(fields)
        self.counts = {name: {"suspect": 0, "fail": 0, "missing": 0} for name in self.tests()}
        self.prev_t, self.n_seen, self.first_t = 0, 0, 0
        self.prev, self.prev2 = np.full(nf, np.nan), np.full(nf, np.nan)
        self.ring_t = np.zeros(self._cap, np.int64)
        self.ring_x = np.full((nf, self._cap), np.nan)
        self.ring_head, self.ring_n = 0, 0
        if state is not None:
            self.prev_t, self.n_seen = int(state["prev_t"]), int(state["n_seen"])
            self.first_t = int(state["first_t"])
            self.prev = _floats(state["prev"])
            self.prev2 = _floats(state["prev2"])
            rt, rx = state["ring_t"], state["ring_x"]
            m = min(len(rt), self._cap)
            self.ring_t[:m] = np.array(rt[len(rt) - m:], np.int64)
            self.ring_x[:, :m] = _floats(rx).reshape(nf, -1)[:, len(rt) - m:]
            self.ring_head, self.ring_n = m % self._cap, m
            for name, c in state["counts"].items():
                self.counts.setdefault(name, {"suspect": 0, "fail": 0, "missing": 0}).update(c)

    def tests(self) -> tuple[str, ...]:
        """The tests this stream runs (location only for a stream given a range, the check
        factor only for a motion stream given one)."""
        return TESTS[:LOCATION] + ("location",) * (self._loc > 0) + (
            ("check_factor",) if self._cf is not None else ())

    def check(self, t_ns: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(flags, spike_prev)`` of samples in time order, each later than every earlier one:
        ``flags[test, i]`` per :data:`TESTS`; ``spike_prev[i]`` the spike flag of the sample
        before ``i`` (0 for the stream's first). Counts suspect / fail / missing per test."""
        values = np.ascontiguousarray(values, dtype=np.float64)
        ok = False
        if self.fast_ready and t_ns.shape[0]:
            ok, flags, spike_prev, counts, head, ring_n = _qc_fast(
                t_ns, values, self._p, np.int64(self.prev_t), self.prev, self.prev2,
                self.ring_t, self.ring_x, np.int64(self.ring_head), np.int64(self.ring_n),
                np.int64(self.first_t))
            if ok:
                self.took_fast(t_ns, values, head, ring_n)
        if not ok:
            flags, spike_prev, counts, prev_t, n_seen, head, ring_n, first_t = _qc(
                t_ns, values, self._p, self._loc, np.int64(self.prev_t), self.prev,
                self.prev2, np.int64(self.n_seen), self.ring_t, self.ring_x,
                np.int64(self.ring_head), np.int64(self.ring_n), np.int64(self.first_t))
            self.prev_t, self.n_seen, self.first_t = int(prev_t), int(n_seen), int(first_t)
            self.ring_head, self.ring_n = int(head), int(ring_n)
        if self._cf is not None:
            flags[CHECK] = self._cf.check(t_ns, values[0], values[1], values[2])
            counts[CHECK] = [0, np.count_nonzero(flags[CHECK] == FAIL),
                             np.count_nonzero(flags[CHECK] == MISSING)]
        if t_ns.shape[0]:
            flags[SPIKE] = NOT_EVALUATED  # a sample's own spike flag is not known yet
            self.add_counts(counts)
        return flags, spike_prev

    @property
    def params(self) -> np.ndarray:
        """The kernels' thresholds per field (see :func:`_params`)."""
        return self._p

    @property
    def has_check_factor(self) -> bool:
        return self._cf is not None

    @property
    def fast_ready(self) -> bool:
        """Blocks of finite values go through :func:`_qc_fast` (two samples seen, no
        location test)."""
        return self.n_seen >= 2 and self._loc == 0

    def took_fast(self, t_ns: np.ndarray, values: np.ndarray, head: int, ring_n: int) -> None:
        """The memory after :func:`_qc_fast` took the samples ``t_ns, values`` (its ring
        position ``head, ring_n``)."""
        n = t_ns.shape[0]
        self.prev2 = values[:, -2].copy() if n >= 2 else self.prev.copy()
        self.prev = values[:, -1].copy()
        self.prev_t, self.n_seen = int(t_ns[-1]), self.n_seen + n
        self.ring_head, self.ring_n = int(head), int(ring_n)

    def add_counts(self, counts: np.ndarray) -> None:
        """Add a kernel's flag counts (tests x suspect, fail, missing) of this stream's tests."""
        rows = counts.tolist()
        if not any(map(any, rows)):  # (nearly always: nothing flagged)
            return
        for name in self.tests():
            suspect, fail, missing = rows[TESTS.index(name)]
            if suspect or fail or missing:
                c = self.counts[name]
                c["suspect"] += suspect
                c["fail"] += fail
                c["missing"] += missing

    def count(self, test: str, suspect: int, fail: int) -> None:
        """Add flags of a test computed outside the kernel (the motion watch circle)."""
        c = self.counts.setdefault(test, {"suspect": 0, "fail": 0, "missing": 0})
        c["suspect"] += suspect
        c["fail"] += fail

    def state(self) -> dict[str, Any]:
        order = (self.ring_head - self.ring_n + np.arange(self.ring_n)) % self._cap
        return {"prev_t": self.prev_t, "n_seen": self.n_seen, "first_t": self.first_t,
                "prev": _json_floats(self.prev), "prev2": _json_floats(self.prev2),
                "ring_t": self.ring_t[order].tolist(),
                "ring_x": _json_floats(self.ring_x[:, order].ravel()),
                "counts": {k: dict(v) for k, v in self.counts.items()},
                **({} if self._cf is None else {"check_factor": self._cf.state()})}


def _json_floats(a: np.ndarray) -> list[float | str | None]:
    """Floats for a strict-JSON state: NaN (a missing value) as null, infinities as "inf" /
    "-inf" (the rate after an infinite value is infinite, after a NaN it is not)."""
    return [v if math.isfinite(v) else (None if math.isnan(v) else str(v)) for v in a.tolist()]


def _floats(values: list[float | str | None]) -> np.ndarray:
    return np.array([np.nan if v is None else float(v) for v in values], np.float64)
