"""The motion estimator's time step, taken from the motion stream's own sample spacing.

:mod:`models.estimator` works on a fixed step ``dt``: its velocities and accelerations are
differences of consecutive samples divided by ``dt`` and ``dt**2``. Stepped at the wrong
``dt`` a stream gives velocities off by the ratio and accelerations by its square (the 2.5 Hz
Spotter record stepped at 0.1 s: 4 and 16 times too large), so the step must be the stream's.

``[load] motion_rate_hz``:

``"auto"`` (default)  the step is the stream's own spacing: the shorter of its first two
                      intervals (its first three accepted samples, the first two of which
                      only settle the estimator anyway; the shorter, as a missing sample
                      only lengthens one), rounded to the microsecond (so a
                      GPS-stamped 2.5 Hz stream with 0.2 us of time jitter steps at 0.4 s
                      exactly). Until then the samples wait (no estimate).
a number (Hz)         the step is ``1 / motion_rate_hz``.

The spacing is watched all along: the median of the last :data:`WINDOW` intervals (those over
the stream's ``stale_after_s``, where the estimator restarts, left out) more than
:data:`TOLERANCE` from the step is a rate mismatch. Under ``"auto"`` the step is re-derived
from that median and the estimator restarts on it (counted in ``rate_changes``); under a
configured rate the samples are withheld from the estimator (no estimate, counted as
``samples_rate_mismatch``) until the spacing agrees again, when it restarts. A median, not
each interval: a missing sample (one interval of twice the step) or a jittered time stamp is
no rate change; the differences across a missing sample are still taken as one step.

Every decision depends only on the accepted samples in time order, never on how they were
split into blocks, and the tracker's state goes into the checkpoint: live equals replay.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from models._jit import kernel

TOLERANCE = 0.02  # relative difference of the median spacing from the step: a mismatch
WINDOW = 15  # intervals in the running median (odd: the median is one of them)
_FIRST = 2  # intervals that set the step under "auto"

# plan events: (sample index in the block, kind, new step in s or None)
GAP, STEP, WITHHOLD, RESUME = "gap", "step", "withhold", "resume"


def _intervals(t_ns: np.ndarray, prev: np.int64 | int, first: bool) -> np.ndarray:
    """Intervals (ns) before each sample of ``t_ns``, the first from ``prev``, or without it
    (``first``: the stream's first sample has none)."""
    if first:
        return t_ns[1:] - t_ns[:-1]
    d = np.empty_like(t_ns)
    d[0] = t_ns[0] - prev
    np.subtract(t_ns[1:], t_ns[:-1], out=d[1:])
    return d


@kernel(nogil=True)
def _regular(t_ns, prev, first, step_ns, tol, gap_ns):  # pragma: no cover - compiled
    """(every interval of the block a gap (> ``gap_ns``) or within ``tol`` of ``step_ns``,
    any gap): the comparisons of the intervals of :func:`_intervals`, in one pass."""
    n = t_ns.shape[0]
    regular = True
    gaps = False
    if not first:
        d = t_ns[0] - prev
        gaps = d > gap_ns
        regular = gaps or abs(d - step_ns) <= tol
    for i in range(1, n):
        d = t_ns[i] - t_ns[i - 1]
        g = d > gap_ns
        regular &= g | (abs(d - step_ns) <= tol)
        gaps |= g
    return regular, gaps


def _step_s(median_ns: float) -> float:
    """A measured spacing (ns) as the estimator's step (s), rounded to the microsecond."""
    return round(median_ns / 1e3) / 1e6


class MotionRate:
    """Tracks one motion stream's sample spacing against the estimator's step.

    ``configured_hz``: ``[load] motion_rate_hz`` (None for "auto"); ``gap_ns``: intervals
    longer than this are gaps (the estimator restarts there) and are not spacing.
    """

    def __init__(self, configured_hz: float | None, gap_ns: float,
                 state: Mapping[str, Any] | None = None) -> None:
        self.configured_hz = configured_hz
        self.gap_ns = gap_ns
        st = state or {}
        default_dt = None if configured_hz is None else 1.0 / configured_hz
        self.dt: float | None = st.get("dt", default_dt)
        self.ring: list[int] = [int(d) for d in st.get("ring", [])]
        self.last_t_ns: int | None = st.get("last_t_ns")
        self.withholding = bool(st.get("withholding", False))
        self.mismatched = int(st.get("samples_rate_mismatch", 0))
        self.changes = int(st.get("rate_changes", 0))

    def plan(self, t_ns: np.ndarray) -> list[tuple[int, str, float | None]]:
        """The events of the block of accepted sample times ``t_ns`` (in order): ``gap``
        (restart before the sample), ``step`` (the step is now the given one: build the
        estimator on it, fresh), ``withhold`` (from the sample on, no estimate), ``resume``
        (from the sample on, estimates again at the given step, fresh). Advances the
        tracker."""
        n = t_ns.shape[0]
        if n == 0:
            return []
        first = self.last_t_ns is None  # the stream's first sample has no interval
        prev = np.int64(t_ns[0] if first else self.last_t_ns)
        self.last_t_ns = int(t_ns[-1])
        events: list[tuple[int, str, float | None]] = []
        start = 0
        # sample by sample until the step is known and the spacing agrees with it (a
        # stream's first samples, a rate change), then the rest of the block at once
        while start < n:
            rest = t_ns[start:]
            fast = self._fast_plan(rest, prev, first)
            if fast is not None:
                return events + [(i + start, kind, dt) for i, kind, dt in fast]
            stop = self._slow_plan(_intervals(rest, prev, first), rest.shape[0], events, start)
            if stop is None:
                break
            prev, first, start = t_ns[stop - 1], False, stop
        return events

    def _fast_plan(self, t_ns: np.ndarray, prev: np.int64,
                   first: bool) -> list[tuple[int, str, float | None]] | None:
        """The usual block: the step known, every interval of the block and of the window a
        gap or within the tolerance of the step; then so is every running median, and the
        only events are the gaps (one compiled pass over the times). None otherwise."""
        if self.dt is None or self.withholding:
            return None
        step_ns = self.dt * 1e9
        tol = TOLERANCE * step_ns
        regular, gaps = _regular(t_ns, prev, first, step_ns, tol, float(self.gap_ns))
        if not (regular and all(abs(r - step_ns) <= tol for r in self.ring)):
            return None
        n = t_ns.shape[0]
        if not gaps:  # only the window's newest intervals are needed
            tail = _intervals(t_ns[-WINDOW - 1:], prev, first or n > WINDOW)
            self.ring = (self.ring + tail.tolist())[-WINDOW:]
            return []
        d = _intervals(t_ns, prev, first)
        offset = n - d.shape[0]  # 1 for a stream's first block
        is_gap = d > self.gap_ns
        self.ring = (self.ring + d[~is_gap][-WINDOW:].tolist())[-WINDOW:]
        return [(int(i) + offset, GAP, None) for i in np.flatnonzero(is_gap)]

    def _slow_plan(self, d: np.ndarray, n: int, events: list[tuple[int, str, float | None]],
                   base: int) -> int | None:
        """The intervals ``d`` before the last ``d.shape[0]`` of ``n`` samples one by one,
        their events (sample index + ``base``) into ``events``, until a ``step`` or
        ``resume`` event: returns the index (+ ``base``) of the sample after it, None at the
        end."""
        offset = n - d.shape[0]
        for k, interval in enumerate(d.tolist()):
            i = k + offset + base
            if interval > self.gap_ns:
                events.append((i, GAP, None))
                if self.dt is None:  # the spacing so far was of the stretch before the gap
                    self.ring = []
                continue
            self.ring.append(int(interval))
            del self.ring[:-WINDOW]
            median = sorted(self.ring)[(len(self.ring) - 1) // 2]  # (the lower one)
            if self.dt is None:
                if len(self.ring) >= _FIRST and median > 0:
                    self.dt = _step_s(median)
                    events.append((i, STEP, self.dt))
                    return i + 1
                continue
            off = not abs(median - self.dt * 1e9) <= TOLERANCE * self.dt * 1e9
            if self.configured_hz is not None:
                self.mismatched += off
                if off != self.withholding:
                    self.withholding = off
                    events.append((i, WITHHOLD, None) if off else (i, RESUME, self.dt))
                    if not off:
                        return i + 1
            elif off and median > 0:
                self.dt = _step_s(median)
                self.changes += 1
                events.append((i, STEP, self.dt))
                return i + 1
        return None

    def figures(self) -> dict[str, Any]:
        """For the status and the report."""
        return {"setting": "auto" if self.configured_hz is None else self.configured_hz,
                "hz": None if self.dt is None else 1.0 / self.dt,
                "samples_rate_mismatch": self.mismatched, "rate_changes": self.changes}

    def state(self) -> dict[str, Any]:
        return {"dt": self.dt, "ring": list(self.ring), "last_t_ns": self.last_t_ns,
                "withholding": self.withholding, "samples_rate_mismatch": self.mismatched,
                "rate_changes": self.changes}



def rate_problems(figures: Mapping[str, Any]) -> list[str]:
    """The spacing mismatches of :meth:`MotionRate.figures`, in words ([] when none)."""
    out = []
    if figures["samples_rate_mismatch"]:
        out.append(f"{figures['samples_rate_mismatch']:,d} motion samples gave no load estimate: "
                   f"their spacing is not [load] motion_rate_hz = {figures['setting']:g} Hz "
                   "(rate_mismatch; set motion_rate_hz = \"auto\" to take the stream's own)")
    if figures["rate_changes"]:
        out.append(f"the motion stream's sample rate changed {figures['rate_changes']:,d} "
                   f"times: the estimator restarted on each (now {figures['hz']:.4g} Hz)")
    return out
