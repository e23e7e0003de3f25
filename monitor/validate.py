"""Sample validation: every sample of a stream is accepted or rejected for one counted reason.

Rules, applied to each sample in time order, first match wins:

``duplicate``       its time equals the stream's last ACCEPTED sample time;
``time_backwards``  its time is earlier than the last accepted sample, or not later than the
                    point the pipeline has already processed this stream to (a sample that
                    arrived after the reorder horizon, see :mod:`monitor.ordering`);
``duplicate``       its time equals that of the newest sample seen before it (accepted or
                    not): one verdict per sample time, so a second copy of a rejected sample
                    is not judged again;
``nan``             any field is NaN or infinite;
``out_of_range``    any field is outside ``[min, max]`` of ``[validate.<sensor>.<field>]``;
``spike``           any field changed faster than ``max_rate_per_s`` since the last accepted
                    sample: ``|v - v_last| > max_rate_per_s * (t - t_last)``;
``flat_line``       the QARTOD flat-line test fails (monitor.qartod): a stuck sensor;
``check_factor``    (motion) the check-factor test fails (monitor.check_factor): horizontal
                    motion no wave makes, e.g. a GNSS multipath excursion. The whole sample
                    goes, heave too (the estimator needs all three displacements), and the
                    fail lasts a window (50 s), so the estimator sees a gap and restarts.

Before all these, the pipeline drops a sample whose time is further ahead of its receive time
than ``[ordering] max_ahead_s`` and counts it here as ``time_ahead`` (:mod:`monitor.time_ahead`):
accepted, it would make every later sample ``time_backwards``.

A displacement (``motion``) sample whose position the line cannot reach is ``out_of_range``
and a QARTOD ``location`` fail: its horizontal distance from the anchor,
``hypot(span + surge, sway)``, beyond ``sqrt(L^2 - (depth + heave)^2)`` with the line
stretched 2 % (``[validate.motion] watch_circle = false`` turns this off).

Every sample later than the stream's last one also gets the QARTOD flags of
:mod:`monitor.qartod` (counted per test as ``qc``): a gross-range fail is ``out_of_range``
(the same sensor span), a rate-of-change fail is (nearly always) ``spike``, a flat-line fail is
``flat_line``; suspect flags are counted and the sample is used.

Comparing with the last accepted sample (not the previous sample) makes the checks
split-invariant: the validator's whole memory is ``(t_last, v_last)``, carried across blocks and
saved in the state, so any split of a stream into blocks gives the same verdicts. It also makes a
re-delivered sample after a restart a ``duplicate``/``time_backwards`` and never counted twice.
A genuine step in the signal is accepted once ``max_rate_per_s * elapsed`` covers it.

Duplicates are removed and counted in the pipeline only, live and in replay alike (the log
reader delivers every copy it reads): the ordering (:mod:`monitor.ordering`, stable) drops an
exact copy it finds right behind its original, this rule rejects any other sample at a time
already seen, and :mod:`monitor.late_copies` turns a ``time_backwards`` sample that is an exact
copy of a recent accepted one into a ``duplicate`` (a re-sent cache arriving behind the
processed time); all land in the one ``duplicate`` count. A copy is no measurement: it is not
among the samples a tick received or rejected (the ``rejected_rate`` alert rule), so
re-deliveries never read as a glitching sensor. (A different value at a time already seen is
a ``duplicate`` too, and likewise outside the rate.)

Rejected samples are simply absent downstream: the fatigue series is the accepted samples in
time order. A run of rejections therefore joins the accepted samples either side; if the run is
longer than the stream's ``stale_after_s`` the load cell counts as stale and the load source
switches to the motion estimate for that interval (monitor.load_source), so distant samples are
never spliced silently.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from models._jit import kernel
from monitor.blocks import SENSOR_FIELDS
from monitor.config import SensorLimits
from monitor.qartod import (CHECK, FAIL, FLAT, NOT_EVALUATED, StreamQC, _N_TESTS, fast_finite,
                            qc_span, remember, steps, tally)

ACCEPTED = 0
# time_ahead last: the pipeline counts it at intake (monitor.time_ahead), no code of _validate
REASONS: tuple[str, ...] = ("nan", "out_of_range", "spike", "duplicate", "time_backwards",
                            "flat_line", "check_factor", "time_ahead")
_NAN, _RANGE, _SPIKE, _DUP, _BACK, _FLAT, _CHECK = 1, 2, 3, 4, 5, 6, 7


@kernel(nogil=True)
def _validate(t, values, lo, hi, rate, last_t, last_v, has_last, floor_t,
              qc_code, repeat):  # pragma: no cover
    """The verdicts (codes, counts per code, last_t, has_last) of a block: its QC fail codes
    ``qc_code`` and repeated times ``repeat`` given; ``last_v`` is updated in place."""
    n = t.shape[0]
    codes = np.zeros(n, dtype=np.int8)
    counts = np.zeros(len(REASONS) + 1, np.int64)
    if n == 0:
        return codes, counts, last_t, has_last
    dt = np.empty(n)
    steps(t, t[0], 0, dt)
    run = np.empty(n, np.bool_)
    _runs(t, values, lo, hi, rate, floor_t, qc_code, repeat, 0, dt, run)
    last_t, has_last, _ = _verdicts(t, values, lo, hi, rate, last_t, last_v, has_last, floor_t,
                                    qc_code, repeat, 0, run, False, codes, counts)
    return codes, counts, last_t, has_last


@kernel(nogil=True, inline="always")
def _verdicts(t, values, lo, hi, rate, last_t, last_v, has_last, floor_t, qc_code, repeat, a,
              run, prev_accepted, codes, counts):  # pragma: no cover
    """The verdicts of samples ``a .. a + m - 1`` (m = ``run.shape[0]``; ``qc_code``,
    ``repeat`` and ``run`` (:func:`_runs`) of them) into ``codes`` (the block's) and
    ``counts``; ``prev_accepted``: the sample before was. Returns (last_t, has_last,
    prev_accepted)."""
    # Sequential by nature: each verdict depends on the last ACCEPTED sample before it. But
    # nearly every sample is accepted, and a sample after an accepted one is judged against
    # its predecessor: ``run[k]`` (computed in loops the compiler vectorises) says it passes
    # every rule if the sample before was accepted. A run of such samples after an
    # accepted one is accepted at once; the others take the rules one by one below.
    m = run.shape[0]
    nf = values.shape[0]
    k = 0
    while k < m:
        if prev_accepted and run[k]:
            j = _run_end(run, k + 1)
            counts[ACCEPTED] += j - k
            last_t = t[a + j - 1]
            for f in range(nf):
                last_v[f] = values[f, a + j - 1]
            k = j
            continue
        i = a + k
        ti = t[i]
        code = ACCEPTED
        if has_last and ti == last_t:
            code = _DUP
        elif (has_last and ti < last_t) or ti <= floor_t:
            code = _BACK
        elif repeat[k]:
            code = _DUP
        else:
            for f in range(nf):
                v = values[f, i]
                if not np.isfinite(v):
                    code = _NAN
                    break
            if code == ACCEPTED:
                for f in range(nf):
                    v = values[f, i]
                    if v < lo[f] or v > hi[f]:
                        code = _RANGE
                        break
            if code == ACCEPTED and has_last:
                dt = (ti - last_t) * 1e-9
                for f in range(nf):
                    if abs(values[f, i] - last_v[f]) > rate[f] * dt:
                        code = _SPIKE
                        break
            if code == ACCEPTED and qc_code[k]:
                code = qc_code[k]
        codes[i] = code
        counts[code] += 1
        prev_accepted = code == ACCEPTED
        if prev_accepted:
            last_t = ti
            has_last = True
            for f in range(nf):
                last_v[f] = values[f, i]
        k += 1
    return last_t, has_last, prev_accepted


@kernel(nogil=True, inline="always")
def _run_end(run, k):  # pragma: no cover
    """The first index from ``k`` on where ``run`` is False, or its length."""
    m = run.shape[0]
    while k + 64 <= m:  # 64 at a time: a sum the compiler vectorises
        w = run[k:k + 64]
        s = 0
        for q in range(64):
            s += w[q]
        if s < 64:
            break
        k += 64
    while k < m and run[k]:
        k += 1
    return k


@kernel(nogil=True, inline="always")
def _runs(t, values, lo, hi, rate, floor_t, qc_code, repeat, a, dt, run):  # pragma: no cover
    """``run[k]``: sample ``a + k`` passes every rule of :func:`_verdicts` when the sample
    before it was its last accepted one (the same comparisons, branch-free; False for the
    block's first sample). ``qc_code``, ``repeat``, ``dt`` (:func:`monitor.qartod.steps`)
    and ``run`` are the samples' from ``a`` on."""
    m = run.shape[0]
    if a == 0:
        run[0] = False
        _run_pairs(t[:m], values, 0, lo, hi, rate, floor_t, qc_code[1:], repeat[1:], dt[1:],
                   run[1:])
    else:
        _run_pairs(t[a - 1:a + m], values, a - 1, lo, hi, rate, floor_t, qc_code, repeat, dt,
                   run)


@kernel(nogil=True, inline="always")
def _run_pairs(tp, values, s, lo, hi, rate, floor_t, qc_code, repeat, dt, run):
    # pragma: no cover
    """:func:`_runs` of the samples ``s + 1 .. s + m`` (m = ``run.shape[0]``) after sample
    ``s``; ``tp`` the times from ``s`` on. (Indices from 0 in views: the compiler then
    vectorises the loops, which a possibly negative index would stop.)"""
    m = run.shape[0]
    for k in range(m):
        run[k] = (tp[k + 1] > tp[k]) & (tp[k + 1] > floor_t) & (qc_code[k] == 0) & (not repeat[k])
    for f in range(values.shape[0]):
        x = values[f, s:s + m + 1]
        lo_f, hi_f, rate_f = lo[f], hi[f], rate[f]
        for k in range(m):
            v = x[k + 1]
            run[k] &= (((v - v) == 0.0) & (not ((v < lo_f) | (v > hi_f)))
                       & (not (abs(v - x[k]) > rate_f * dt[k])))


@kernel(nogil=True)
def _scan(t, values):  # pragma: no cover - compiled
    """(every value finite, the times strictly increasing), in one pass."""
    bad = False
    for f in range(values.shape[0]):
        for i in range(t.shape[0]):  # v - v is 0 for finite v, NaN otherwise
            bad |= (values[f, i] - values[f, i]) != 0.0
    increasing = True
    for i in range(1, t.shape[0]):
        increasing &= t[i] > t[i - 1]
    return not bad, increasing


@kernel(nogil=True, inline="always")
def _fail_code(flat, check):  # pragma: no cover - compiled
    """The QC fails that reject a sample: flat line (_FLAT) over check factor (_CHECK)."""
    return _FLAT if flat == FAIL else (_CHECK if check == FAIL else 0)


@kernel(nogil=True)
def _fail_codes(flags):  # pragma: no cover - compiled
    """:func:`_fail_code` of every sample's flags."""
    n = flags.shape[1]
    code = np.empty(n, np.int8)
    for i in range(n):
        code[i] = _fail_code(flags[FLAT, i], flags[CHECK, i])
    return code


# samples per pass of _check_usual: its scratch (about 30 bytes a sample) stays in the L1
# cache, and no array as long as the block is made but the verdicts
_SPAN = 1024
# (1 - 2^-49): a rate bound shrunk by it is surely not exceeded (see _screen_limits)
_SHRINK = 1.0 - 2.0 ** -49
_NORMAL = 1e-280  # a product this large is a normal number with 2^-53 relative rounding


@kernel(nogil=True, inline="always")
def _screen_limits(p, lo, hi, rate):  # pragma: no cover
    """Per field, the bounds of :func:`_clear`: the range within both the QC's gross range
    spans and the validator's, the validator's rate, the QC rate bound shrunk by
    :data:`_SHRINK` (inf: no rate test), the spike bound (inf: no spike test), the
    flat-line tolerance, its step bound in seconds and window in ns (0, inf, inf: no
    flat-line test), as :func:`monitor.qartod.qc_span` reads ``p``.

    The rate-of-change test divides: ``|d| / dt > r``. With ``rp = fl(fl(r * (1 - 2^-49))
    * dt)`` a normal number, ``rp <= r * dt * (1 - 2^-49) * (1 + 2^-53)^2 < r * dt * (1 -
    2^-50)``, so ``|d| <= rp`` gives ``|d| / dt < r`` exactly and, rounding being monotonic
    and ``r`` a float, ``fl(|d| / dt) <= r``: no flag, without the division."""
    nf = p.shape[0]
    lim = np.empty((nf, 8))
    for f in range(nf):
        lim[f, 0] = max(max(p[f, 0], p[f, 2]), lo[f])
        lim[f, 1] = min(min(p[f, 1], p[f, 3]), hi[f])
        lim[f, 2] = rate[f]
        lim[f, 3] = (min(p[f, 6], p[f, 7]) * _SHRINK
                     if np.isfinite(p[f, 6]) or np.isfinite(p[f, 7]) else np.inf)
        lim[f, 4] = min(p[f, 4], p[f, 5]) if np.isfinite(p[f, 4]) or np.isfinite(p[f, 5]) else np.inf
        if p[f, 8] > 0 and (np.isfinite(p[f, 9]) or np.isfinite(p[f, 10])):
            sw = p[f, 9] * 1e9
            fw = p[f, 10] * 1e9
            lim[f, 5] = p[f, 8]
            lim[f, 6] = min(sw, fw) * 1e-9
            lim[f, 7] = min(sw, fw)
        else:
            lim[f, 5] = 0.0
            lim[f, 6] = np.inf
            lim[f, 7] = np.inf
    return lim


@kernel(nogil=True, inline="always")
def _clear(t, values, a, dt, lim):  # pragma: no cover
    """Every sample ``a .. a + m - 1`` (``a >= 2``; ``dt``: their steps, length m) of a usual
    block surely gets QC flags pass or not evaluated and passes every rule of :func:`_runs`
    (``lim``: :func:`_screen_limits`), judged in one loop per field the compiler vectorises:
    within the ranges, the step under both rate bounds, the spike under its bound, and not
    flat: the step at least the tolerance within both windows (the flat-line pass of
    :func:`monitor.qartod.qc_span`), or the last three values spanning it within both
    windows (where its scan would stop, at the second sample back). False: some sample may
    be flagged or rejected (the general pass decides)."""
    m = dt.shape[0]
    tp = t[a - 2:a + m]  # (views indexed from 0: the loops vectorise)
    bad = False
    for f in range(values.shape[0]):
        w = values[f, a - 2:a + m]
        lo_f, hi_f, rate_f, r_lo = lim[f, 0], lim[f, 1], lim[f, 2], lim[f, 3]
        s_max, tol, near, win = lim[f, 4], lim[f, 5], lim[f, 6], lim[f, 7]
        for i in range(m):
            v0 = w[i]
            v1 = w[i + 1]
            v = w[i + 2]
            d = abs(v - v1)
            rp = r_lo * dt[i]
            flat = ((d >= tol) & (dt[i] <= near)) | (
                (max(max(v, v1), v0) - min(min(v, v1), v0) >= tol) & (tp[i + 2] - tp[i] <= win))
            bad |= not ((v >= lo_f) & (v <= hi_f) & (d <= rate_f * dt[i]) & (d <= rp)
                        & (rp >= _NORMAL) & (abs(v1 - (v0 + v) / 2.0) <= s_max) & flat)
    return not bad


@kernel(nogil=True, error_model="numpy")
def _check_usual(t, values, floor_t, p, prev_t, prev, prev2, ring_t, ring_x, ring_head, ring_n,
                 first_t, lo, hi, rate, last_t, last_v, has_last):  # pragma: no cover
    """:meth:`StreamValidator.check` of the usual block in one call: every value finite, the
    times increasing and later than both the stream's last QC'd sample ``prev_t`` and
    ``floor_t``, the QC memory ready for :func:`monitor.qartod._qc_fast` (its arguments
    ``p`` .. ``first_t``; no location or check-factor test). Then the QC flags
    (:func:`monitor.qartod._qc_fast`'s pieces), the QC fails that reject (:func:`_fail_code`)
    and the verdicts (:func:`_validate`'s pieces, no repeated times): the general path's
    results, in one pass over spans of the block; a span :func:`_clear` finds clear (nearly
    all) needs no flags. Returns (ok, QC counts, ring head, ring count, codes, counts,
    last_t, has_last); ok False: not such a block, nothing changed."""
    n = t.shape[0]
    usual = n > 0 and t[0] > prev_t and t[0] > floor_t
    for i in range(1, n):
        usual &= t[i] > t[i - 1]
    qc_counts = np.zeros((_N_TESTS, 3), np.int64)
    counts = np.zeros(len(REASONS) + 1, np.int64)
    if not (usual and fast_finite(values, prev, prev2)):  # (nothing changed)
        return False, qc_counts, ring_head, ring_n, np.zeros(0, np.int8), counts, last_t, has_last
    codes = np.zeros(n, np.int8)
    lim = _screen_limits(p, lo, hi, rate)
    span = min(n, _SPAN)
    dt = np.empty(span)
    z = np.empty(span + 2)
    quick = np.empty(span, np.bool_)
    flags = np.empty((4, span), np.uint8)
    qc_code = np.empty(span, np.int8)
    repeat = np.zeros(span, np.bool_)
    run = np.empty(span, np.bool_)
    accepted = False
    a = 0
    while a < n:
        # the first two samples alone (the screen reads two samples back), then spans
        m = min(span, n - a) if a else min(2, n)
        steps(t, prev_t, a, dt[:m])
        if a and _clear(t, values, a, dt[:m], lim):
            run[:m] = True  # no flag to count, no fail to reject, every rule passes
            qc_code[:m] = 0
        else:
            gr, sp, rt, ft = flags[0, :m], flags[1, :m], flags[2, :m], flags[3, :m]
            qc_span(t, values, p, prev_t, prev, prev2, ring_t, ring_x, ring_head, ring_n,
                    first_t, a, dt[:m], z[:m + 2], quick[:m], gr, sp, rt, ft)
            tally(gr, sp, rt, ft, qc_counts)
            for k in range(m):
                qc_code[k] = _fail_code(ft[k], NOT_EVALUATED)
            _runs(t, values, lo, hi, rate, floor_t, qc_code[:m], repeat[:m], a, dt[:m],
                  run[:m])
        last_t, has_last, accepted = _verdicts(t, values, lo, hi, rate, last_t, last_v,
                                               has_last, floor_t, qc_code[:m], repeat[:m], a,
                                               run[:m], accepted, codes, counts)
        a += m
    ring_head, ring_n = remember(t, values, ring_t, ring_x, ring_head, ring_n)
    return True, qc_counts, ring_head, ring_n, codes, counts, last_t, has_last


class StreamValidator:
    """Validates one sensor stream; keeps its counters and last accepted sample."""

    def __init__(self, sensor: str, limits: SensorLimits, state: Mapping[str, Any] | None = None):
        self.sensor = sensor
        self.fields = tuple(SENSOR_FIELDS[sensor])
        self._lo = np.array([limits.fields[f].min for f in self.fields])
        self._hi = np.array([limits.fields[f].max for f in self.fields])
        self._rate = np.array([limits.fields[f].max_rate_per_s for f in self.fields])
        self._watch = limits.watch_circle if sensor == "motion" else None
        self.last_t_ns = 0
        self.has_last = False
        self.last_values = np.zeros(len(self.fields))
        self.accepted = 0
        self.rejected = {r: 0 for r in REASONS}
        check = limits.check_factor if sensor == "motion" else None
        self.qc = StreamQC(
            tuple(limits.fields[f] for f in self.fields),
            limits.location_range_max_m, None if state is None else state.get("qc"),
            None if check is None else (*check, limits.stale_after_s))
        if state is not None:
            self.has_last = bool(state["has_last"])
            self.last_t_ns = int(state["last_t_ns"])
            self.last_values = np.array(state["last_values"], dtype=np.float64)
            self.accepted = int(state["accepted"])
            self.rejected.update({r: int(state["rejected"].get(r, 0)) for r in REASONS})

    def check(self, t_ns: np.ndarray, values: np.ndarray, floor_ns: int) -> np.ndarray:
        """Verdict per sample: 0 = accepted, else ``REASONS[code - 1]``.

        ``values`` has shape ``(n_fields, n)`` in the order of :data:`SENSOR_FIELDS`. Samples at
        or before ``floor_ns`` (already processed) are ``time_backwards``.
        """
        n = t_ns.shape[0]
        if values.shape != (len(self.fields), n):
            raise ValueError(f"{self.sensor}: values of shape {values.shape} for {n} times "
                             f"and {len(self.fields)} fields")
        qc = self.qc
        if qc.fast_ready and not qc.has_check_factor and self._watch is None and n:
            values = np.ascontiguousarray(values, dtype=np.float64)
            ok, qc_counts, head, ring_n, codes, counts, last_t, has_last = _check_usual(
                t_ns, values, np.int64(floor_ns), qc.params, np.int64(qc.prev_t), qc.prev,
                qc.prev2, qc.ring_t, qc.ring_x, np.int64(qc.ring_head), np.int64(qc.ring_n),
                np.int64(qc.first_t), self._lo, self._hi, self._rate,
                np.int64(self.last_t_ns), self.last_values, self.has_last)
            if ok:  # the usual block: QC and verdicts in one call
                qc.took_fast(t_ns, values, head, ring_n)
                qc.add_counts(qc_counts)
                return self._took(codes, counts, last_t, has_last)
        # the QARTOD tests see each sample later than the stream's last one, once
        seen = self.qc.prev_t if self.qc.n_seen else np.iinfo(np.int64).min
        repeat = np.zeros(n, np.bool_)  # the time of the newest sample seen before it
        qc_values = values
        finite, increasing = _scan(t_ns, values) if n else (True, True)
        if not finite:
            # an infinite value is missing here, as it is once saved (strict JSON state) and
            # as the nan rule rejects it: flags must not change with a restart
            qc_values = np.where(np.isfinite(values), values, np.nan)
        if n and int(t_ns[0]) > max(seen, floor_ns) and increasing:
            new = None  # the usual case: every sample is new
            flags, _ = self.qc.check(t_ns, qc_values)
            qc_code = _fail_codes(flags)
        elif n:
            qc_code = np.zeros(n, np.int8)
            newest = np.maximum.accumulate(np.concatenate(([seen], t_ns[:-1])))
            repeat = t_ns == newest
            new = t_ns > np.maximum(newest, floor_ns)
            if new.any():
                flags, _ = self.qc.check(t_ns[new], qc_values[:, new])
                idx = np.flatnonzero(new)
                qc_code[idx[flags[CHECK] == FAIL]] = _CHECK
                qc_code[idx[flags[FLAT] == FAIL]] = _FLAT
        else:
            qc_code = np.zeros(0, np.int8)
        if self._watch is not None and n:
            outside = self._outside_watch_circle(qc_values)
            qc_code[outside] = _RANGE
            self.qc.count("location", 0, int(np.count_nonzero(
                outside if new is None else outside & new)))
        codes, counts, last_t, has_last = _validate(
            t_ns, values, self._lo, self._hi, self._rate,
            np.int64(self.last_t_ns), self.last_values, self.has_last, np.int64(floor_ns),
            qc_code, repeat,
        )
        return self._took(codes, counts, last_t, has_last)

    def _took(self, codes: np.ndarray, counts: np.ndarray, last_t: int,
              has_last: bool) -> np.ndarray:
        """Adopt :func:`_validate`'s verdict counts and last accepted sample; returns the
        verdicts."""
        self.last_t_ns, self.has_last = int(last_t), bool(has_last)
        accepted, *rejected = counts.tolist()
        self.accepted += accepted
        if any(rejected):  # (rarely: a slab is nearly always all accepted)
            for reason, n in zip(REASONS, rejected):
                self.rejected[reason] += n
        return codes

    def _outside_watch_circle(self, values: np.ndarray) -> np.ndarray:
        """Displacement samples (heave, surge, sway rows) the line cannot reach (see above)."""
        span, line, depth = self._watch
        heave, surge, sway = values
        with np.errstate(invalid="ignore"):
            reach = np.sqrt(np.maximum(line ** 2 - np.maximum(depth + heave, 0.0) ** 2, 0.0))
            return np.hypot(span + surge, sway) > reach

    def state(self) -> dict[str, Any]:
        return {
            "has_last": self.has_last,
            "last_t_ns": self.last_t_ns,
            "last_values": [float(v) for v in self.last_values],
            "accepted": self.accepted,
            "rejected": dict(self.rejected),
            "qc": self.qc.state(),
        }

    def qc_counts(self) -> dict[str, dict[str, int]]:
        """QARTOD flags so far per test: ``{test: {"suspect": n, "fail": n}}``."""
        return {k: {"suspect": c["suspect"], "fail": c["fail"]} for k, c in self.qc.counts.items()}
