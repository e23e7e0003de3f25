"""The check-factor test of a displacement (``motion``) stream: horizontal motion no wave makes.

Physics (linear waves, models.waves): a surface-following buoy moves on the water-particle
orbit, whose horizontal amplitude is the vertical one times ``coth(k d)`` (1 in deep water,
larger in shallow water). Per frequency, the horizontal displacement variance is the vertical
one times ``coth^2(k d)``: NDBC checks exactly this ratio of the spectra, the directional
"check factor" (NDBC Technical Document 96-01, Earle 1996), on every wave record. The ratio
grows as ``k`` falls, so over the waves up to the longest period ``T_max``
(:data:`monitor.config.LONGEST_WAVE_S`, the waves' ``tp_s`` operator limit, 25 s) it is at most
``C^2 = coth^2(k(T_max) d)`` at the configured depth ``d`` (7.10 in the VAPS mooring's 23 m).

The test, in the time domain and streaming: the velocities of consecutive samples,
``v = (p[n] - p[n-1]) / dt``. Differencing is one linear filter applied alike to every
channel, so it keeps each frequency's horizontal/vertical ratio while it removes the mean
position and the slow drift the mooring permits. Over the window of the last ``W = 2 T_max``
seconds of sampled time (two of the longest waves; pairs further apart than the stream's
``stale_after_s`` are gaps and skipped, so a window spans a gap, and the samples after one are
judged against the sea before it)::

    sum(vx^2 + vy^2) > C^2 sum(vz^2)   -> the window is not waves: a violation

Sums of windows that each obey the bound obey it too, so a change of sea state cannot make a
violation; a GNSS multipath excursion of metres at metres per second while the heave stays
steady (the Spotter record's glitches) makes one at once. Flags, per sample: 4 fail within
``W`` of a violation (a violating window cannot say which of its samples are wrong, and a
displacement filter disturbed by a glitch takes tens of seconds to recover); 2 not evaluated
until the stream's pairs span one longest period ``T_max`` (a shorter window gives a ratio
that is not a property of the sea: over 4,000 random starts in the Spotter's clean window,
the first pair alone exceeds ``C^2`` at about 30 % of them, a 4-s window at 0.9 %, a 12.5-s
one never but reaches 6.57, a 25-s one at most 4.13); 9 missing (a NaN or infinite field;
velocities join the finite samples either side); 1 pass. No suspect flag: the bound already
holds for every linear sea.

Lone spikes: a sample that moved from the last one taken faster than a field's fastest
physical change (the fields' ``max_rate_per_s``; ``sqrt(g d)`` for displacements, the phase
speed of the longest wave the depth allows: no water particle of an unbroken wave outruns its
wave, ``u <= c``) is held. If the next finite sample is back within reach of the last one
taken (``|p[n+1] - p[n-1]| <= rate (t[n+1] - t[n-1])`` in every field) the held sample was a
lone spike: it makes no pair, and the window never sees it. Otherwise (or after a gap) it was a
real move (a step, a multipath excursion, a filter reset: the Spotter's glitches all are) and
is taken as it would have been when it came, so those fail exactly as without holding. This
is the order of the wave-data standards: the time-series tests first, spikes edited out
(IOOS QARTOD waves, time-series test of order 2: points ``>= M`` standard deviations,
``M = 4``, interpolated), and the check factor a test of the spectra of the edited record
(there "check factors, ratio: should be approximately 1"; NDBC's QC handbook, Technical
Document 09-02, "range test of directional wave check factors" after its time-series range
check). A lone spike is the validator's to reject (``spike``, the same rate); before holding,
one 5-10 sigma surge sample of ``buoymon simulate --spikes`` failed every sample 50-100 s
around it: 42 % of the motion of a 1-h Hs 1.5 m, Tp 5.25 s log with ``--spikes 0.001``,
52 % of an Hs 4 m, Tp 8 s one (the golden logs' "storm" fails), while the sea itself
stays far inside the bound (windowed ratio median 1.20 / 1.33 / 1.49 at Hs 1.5 / 4 / 6 m,
Tp 5.25 / 10 / 12 s, at most 2.05, against 7.10; NDBC's spectral check factor of those
simulated seas 1.00, tests/test_check_factor.py). A held sample gets its flag when it comes,
as if taken (a fail when the window with it violates), so no flag is late.

Streaming: the memory (last finite sample taken, the sample held, the window's pairs, their
sums, the time of the last violation) is carried across blocks and saved in the state, so any
split of a stream into blocks gives the same flags. The window holds at most :data:`MEMORY`
pairs (80 Hz over 50 s); a denser stream's window is cut to that many. Its sums are kept by adding and removing
pairs, and recomputed from the pairs each time the ring wraps (no drift, same for any split).
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from models._jit import kernel
from models.waves import wavenumber

MEMORY = 4096
_S = 1_000_000_000


def bound(depth_m: float, longest_period_s: float) -> float:
    """``coth^2(k d)`` of the wave of period ``longest_period_s`` in ``depth_m``: the largest
    horizontal/vertical displacement variance ratio of linear waves up to that period."""
    k = float(wavenumber(2.0 * math.pi / longest_period_s, depth_m)[()])
    return 1.0 / math.tanh(k * depth_m) ** 2


@kernel(nogil=True, inline="always")
def _push(ring_dt, ring_v, head, count, cover, ez, eh, step, vz2, vh2, window_ns):
    # pragma: no cover - compiled
    """The pair (``step`` ns, ``vz2``, ``vh2``) into the window: the oldest pairs leave while
    the rest still span it (or the memory is full). Returns (head, count, cover, ez, eh)."""
    cap = ring_dt.shape[0]
    if count == cap:  # the memory is full: the oldest pair leaves
        j = (head - count) % cap
        cover -= ring_dt[j]
        ez -= ring_v[0, j]
        eh -= ring_v[1, j]
        count -= 1
    ring_dt[head] = step
    ring_v[0, head] = vz2
    ring_v[1, head] = vh2
    head += 1
    count += 1
    cover += step
    ez += vz2
    eh += vh2
    while True:
        j = (head - count) % cap
        if cover - ring_dt[j] < window_ns:
            break
        cover -= ring_dt[j]
        ez -= ring_v[0, j]
        eh -= ring_v[1, j]
        count -= 1
    if head == cap:
        head = 0
        ez = 0.0
        eh = 0.0
        for k in range(count):
            j = (cap - count + k) % cap
            ez += ring_v[0, j]
            eh += ring_v[1, j]
    return head, count, cover, ez, eh


@kernel(nogil=True, inline="always")
def _too_fast(z, x, y, prev, rate, dt):  # pragma: no cover - compiled
    """A field of (z, x, y) moved from ``prev`` faster than its ``rate`` over ``dt`` s."""
    return (abs(z - prev[0]) > rate[0] * dt or abs(x - prev[1]) > rate[1] * dt
            or abs(y - prev[2]) > rate[2] * dt)


@kernel(nogil=True)
def _check(t, z, x, y, c2, rate, window_ns, cover_min_ns, gap_ns, ints, prev, held,
           ring_dt, ring_v, sums):  # pragma: no cover - compiled
    """Flags of the samples ``t, z, x, y``; ``rate`` the fastest physical change of (z, x, y)
    per second. State in place: ``ints`` = [has_prev, prev_t, head, count, cover_ns, has_bad,
    last_bad, has_held, held_t]; ``prev`` = the last finite (z, x, y) taken, ``held`` the
    sample held (see :class:`CheckFactor`); ``ring_dt`` the pairs' steps (ns), ``ring_v``
    their (vz^2, vh^2); ``sums`` = (sum vz^2, sum vh^2)."""
    n = t.shape[0]
    has_prev, prev_t, head, count, cover, has_bad, last_bad, has_held, held_t = (
        ints[0], ints[1], ints[2], ints[3], ints[4], ints[5], ints[6], ints[7], ints[8])
    ez, eh = sums[0], sums[1]
    flags = np.empty(n, np.uint8)
    for i in range(n):
        ti = t[i]
        zi, xi, yi = z[i], x[i], y[i]
        if not (np.isfinite(zi) and np.isfinite(xi) and np.isfinite(yi)):
            flags[i] = 9
            continue
        flag = 2
        if has_prev:
            step = ti - prev_t
            if has_held:
                if step > gap_ns or _too_fast(zi, xi, yi, prev, rate, step * 1e-9):
                    # not back within reach: the held sample was a real move; it is taken
                    # as it would have been when it came
                    hstep = held_t - prev_t
                    hdt = hstep * 1e-9
                    head, count, cover, ez, eh = _push(
                        ring_dt, ring_v, head, count, cover, ez, eh, hstep,
                        ((held[0] - prev[0]) / hdt) ** 2,
                        ((held[1] - prev[1]) ** 2 + (held[2] - prev[2]) ** 2) / (hdt * hdt),
                        window_ns)
                    if cover >= cover_min_ns and eh > c2 * ez:
                        has_bad = 1
                        last_bad = held_t
                    prev_t = held_t
                    prev[0], prev[1], prev[2] = held[0], held[1], held[2]
                    step = ti - prev_t
                has_held = 0  # (else a lone spike: left out)
            if step <= gap_ns:
                dt = step * 1e-9
                vz2 = ((zi - prev[0]) / dt) ** 2
                vh2 = ((xi - prev[1]) ** 2 + (yi - prev[2]) ** 2) / (dt * dt)
                if _too_fast(zi, xi, yi, prev, rate, dt):
                    # held until the next sample says whether it is a lone spike; flagged
                    # now as it would be if taken, the window then put back as it was
                    h0, c0, cov0, ez0, eh0 = head, count, cover, ez, eh
                    dt0, vz0, vh0 = ring_dt[h0], ring_v[0, h0], ring_v[1, h0]
                    head, count, cover, ez, eh = _push(ring_dt, ring_v, head, count, cover,
                                                       ez, eh, step, vz2, vh2, window_ns)
                    if cover >= cover_min_ns:
                        flag = 4 if eh > c2 * ez else 1
                    if has_bad and ti - last_bad < window_ns:
                        flag = 4
                    flags[i] = flag
                    head, count, cover, ez, eh = h0, c0, cov0, ez0, eh0
                    ring_dt[h0], ring_v[0, h0], ring_v[1, h0] = dt0, vz0, vh0
                    has_held = 1
                    held_t = ti
                    held[0], held[1], held[2] = zi, xi, yi
                    continue
                head, count, cover, ez, eh = _push(ring_dt, ring_v, head, count, cover, ez,
                                                   eh, step, vz2, vh2, window_ns)
            if cover >= cover_min_ns:
                flag = 1
                if eh > c2 * ez:
                    has_bad = 1
                    last_bad = ti
            if has_bad and ti - last_bad < window_ns:
                flag = 4
        flags[i] = flag
        has_prev = 1
        prev_t = ti
        prev[0], prev[1], prev[2] = zi, xi, yi
    ints[0], ints[1], ints[2], ints[3], ints[4], ints[5], ints[6], ints[7], ints[8] = (
        has_prev, prev_t, head, count, cover, has_bad, last_bad, has_held, held_t)
    sums[0], sums[1] = ez, eh
    return flags


class CheckFactor:
    """The check-factor test of one motion stream (heave, surge, sway), with its memory."""

    def __init__(self, depth_m: float, longest_period_s: float, gap_s: float,
                 max_rate_per_s: tuple[float, float, float],
                 state: Mapping[str, Any] | None = None) -> None:
        """``max_rate_per_s``: the fastest physical change of (heave, surge, sway), the
        fields' ``max_rate_per_s`` (a faster move is a spike candidate, see the module)."""
        self.c2 = bound(depth_m, longest_period_s)
        self._rate = np.array(max_rate_per_s, np.float64)
        self._window_ns = int(round(2 * longest_period_s * _S))
        self._cover_ns = int(round(longest_period_s * _S))
        self._gap_ns = int(round(gap_s * _S))
        self._ints = np.zeros(9, np.int64)
        self._prev = np.zeros(3)
        self._held = np.zeros(3)
        self._ring_dt = np.zeros(MEMORY, np.int64)
        self._ring_v = np.zeros((2, MEMORY))
        self._sums = np.zeros(2)
        if state is not None:
            self._ints[:7] = [int(v) for v in state["ints"]]
            self._prev[:] = state["prev"]
            if "held" in state:  # (t, heave, surge, sway) of the sample held
                t, *values = state["held"]
                self._ints[7:] = 1, int(t)
                self._held[:] = values
            # the pairs back in their slots: the sums are recomputed when the ring wraps, so
            # a restored stream must wrap where an uninterrupted one does
            slots = self._slots()
            self._ring_dt[slots] = state["ring_dt"]
            self._ring_v[:, slots] = np.array(state["ring_v"], np.float64).reshape(2, -1)
            self._sums[:] = state["sums"]

    def _slots(self) -> np.ndarray:
        """Ring slots of the window's pairs, oldest first."""
        head, count = int(self._ints[2]), int(self._ints[3])
        return (head - count + np.arange(count)) % MEMORY

    def check(self, t_ns: np.ndarray, heave: np.ndarray, surge: np.ndarray,
              sway: np.ndarray) -> np.ndarray:
        """Flags (1 pass, 2 not evaluated, 4 fail, 9 missing) of samples in time order, each
        later than every earlier one."""
        return _check(t_ns, heave, surge, sway, self.c2, self._rate, np.int64(self._window_ns),
                      np.int64(self._cover_ns), np.int64(self._gap_ns), self._ints, self._prev,
                      self._held, self._ring_dt, self._ring_v, self._sums)

    def state(self) -> dict[str, Any]:
        slots = self._slots()
        held = {"held": [int(self._ints[8]), *self._held.tolist()]} if self._ints[7] else {}
        return {"ints": self._ints[:7].tolist(), "prev": self._prev.tolist(),
                "ring_dt": self._ring_dt[slots].tolist(),
                "ring_v": self._ring_v[:, slots].ravel().tolist(), "sums": self._sums.tolist(),
                **held}
