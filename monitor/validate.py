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
from monitor.qartod import CHECK, FAIL, FLAT, StreamQC, _qc_fast

ACCEPTED = 0
# time_ahead last: the pipeline counts it at intake (monitor.time_ahead), no code of _validate
REASONS: tuple[str, ...] = ("nan", "out_of_range", "spike", "duplicate", "time_backwards",
                            "flat_line", "check_factor", "time_ahead")
_NAN, _RANGE, _SPIKE, _DUP, _BACK, _FLAT, _CHECK = 1, 2, 3, 4, 5, 6, 7


@kernel(nogil=True)
def _validate(t, values, lo, hi, rate, last_t, last_v, has_last, floor_t,
              qc_code, repeat):  # pragma: no cover
    # Sequential by nature: each verdict depends on the last ACCEPTED sample before it. But
    # nearly every sample is accepted, and a sample after an accepted one is judged against
    # its predecessor: ``run[i]`` (computed in loops the compiler vectorises) says sample i
    # passes every rule if sample i - 1 was accepted. A run of such samples after an
    # accepted one is accepted at once; the others take the rules one by one below.
    n = t.shape[0]
    nf = values.shape[0]
    codes = np.zeros(n, dtype=np.int8)
    counts = np.zeros(len(REASONS) + 1, np.int64)
    run = _runs(t, values, lo, hi, rate, floor_t, qc_code, repeat)
    prev_accepted = False
    i = 0
    while i < n:
        if prev_accepted and run[i]:
            j = i + 1
            while j < n and run[j]:
                j += 1
            counts[ACCEPTED] += j - i
            last_t = t[j - 1]
            for f in range(nf):
                last_v[f] = values[f, j - 1]
            i = j
            continue
        ti = t[i]
        code = ACCEPTED
        if has_last and ti == last_t:
            code = _DUP
        elif (has_last and ti < last_t) or ti <= floor_t:
            code = _BACK
        elif repeat[i]:
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
            if code == ACCEPTED and qc_code[i]:
                code = qc_code[i]
        codes[i] = code
        counts[code] += 1
        prev_accepted = code == ACCEPTED
        if prev_accepted:
            last_t = ti
            has_last = True
            for f in range(nf):
                last_v[f] = values[f, i]
        i += 1
    return codes, counts, last_t, has_last


@kernel(nogil=True)
def _runs(t, values, lo, hi, rate, floor_t, qc_code, repeat):  # pragma: no cover
    """``run[i]`` (i >= 1): sample i passes every rule of :func:`_validate` when sample
    i - 1 was its last accepted one (the same comparisons, branch-free; run[0] is False)."""
    n = t.shape[0]
    run = np.zeros(n, np.bool_)
    dt = np.empty(n)
    for i in range(1, n):
        run[i] = (t[i] > t[i - 1]) & (t[i] > floor_t) & (qc_code[i] == 0) & (not repeat[i])
        dt[i] = (t[i] - t[i - 1]) * 1e-9
    for f in range(values.shape[0]):
        x = values[f]
        lo_f, hi_f, rate_f = lo[f], hi[f], rate[f]
        for i in range(1, n):
            v = x[i]
            run[i] &= (((v - v) == 0.0) & (not ((v < lo_f) | (v > hi_f)))
                       & (not (abs(v - x[i - 1]) > rate_f * dt[i])))
    return run


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


@kernel(nogil=True)
def _fail_codes(flags):  # pragma: no cover - compiled
    """The QC fails that reject a sample: flat line (_FLAT) over check factor (_CHECK)."""
    n = flags.shape[1]
    code = np.empty(n, np.int8)
    for i in range(n):
        code[i] = _FLAT if flags[FLAT, i] == FAIL else (_CHECK if flags[CHECK, i] == FAIL else 0)
    return code


@kernel(nogil=True)
def _check_usual(t, values, floor_t, p, prev_t, prev, prev2, ring_t, ring_x, ring_head, ring_n,
                 first_t, lo, hi, rate, last_t, last_v, has_last):  # pragma: no cover
    """:meth:`StreamValidator.check` of the usual block in one call: every value finite, the
    times increasing and later than both the stream's last QC'd sample ``prev_t`` and
    ``floor_t``, the QC memory ready for :func:`monitor.qartod._qc_fast` (its arguments
    ``p`` .. ``first_t``; no location or check-factor test). Then the QC flags
    (``_qc_fast``), the QC fails that reject (``_fail_codes``) and the verdicts
    (``_validate``, no repeated times): the same calls as the general path, without three
    dispatches and a pass over the values. Returns (ok, QC counts, ring head, ring count,
    codes, counts, last_t, has_last); ok False: not such a block, nothing changed."""
    n = t.shape[0]
    usual = n > 0 and t[0] > prev_t and t[0] > floor_t
    for i in range(1, n):
        usual &= t[i] > t[i - 1]
    none = np.zeros(0, np.int8)
    if not usual:
        return (False, np.zeros((1, 3), np.int64), ring_head, ring_n, none,
                np.zeros(0, np.int64), last_t, has_last)
    ok, flags, _, qc_counts, ring_head, ring_n = _qc_fast(t, values, p, prev_t, prev, prev2,
                                                         ring_t, ring_x, ring_head, ring_n,
                                                         first_t)
    if not ok:  # a value is not finite (nothing changed)
        return (False, qc_counts, ring_head, ring_n, none, np.zeros(0, np.int64), last_t,
                has_last)
    codes, counts, last_t, has_last = _validate(t, values, lo, hi, rate, last_t, last_v,
                                                has_last, floor_t, _fail_codes(flags),
                                                np.zeros(n, np.bool_))
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
        counts = counts.tolist()
        self.accepted += counts[0]
        for i, reason in enumerate(REASONS, start=1):
            self.rejected[reason] += counts[i]
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
