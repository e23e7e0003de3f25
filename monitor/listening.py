"""Listening time: the daemon's monotonic clock without the stretches its process stood still.

A daemon that is stopped whole (SIGSTOP, a long GC pause holding the GIL, a paused VM, heavy
swapping) cannot take in data meanwhile: its sensors' messages wait in the socket and arrive
in a burst after it resumes. Measured on the monotonic clock, every stream then looks silent
for the length of the stall and ``data_age`` fires for sensors that never stopped. Ages
measured in listening time leave the stall out: a stream is judged silent only for time the
process could have heard it. A stream that really stopped is still alerted, later by at most
the stall's length.

A thread wakes every ``beat_s``; a gap between its wake-ups longer than ``slack_s`` means the
process (not one busy thread: the beat needs only the GIL for a moment) stood still, and the
gap beyond ``slack_s`` is left out. A stall still going on when the time is read (the reader
resumed before the beat) is left out the same way, so the clock is continuous and never goes
back.

The daemon's intake queue (:class:`IntakeQueue`) remembers when each waiting item was put:
while the daemon works off a backlog, ages are judged as of the oldest item still waiting
(what it has not looked at yet cannot count as silence), so a backlog after a slow checkpoint
does not read as old data either.
"""

from __future__ import annotations

import bisect
import queue
import threading
import time
from collections import deque
from typing import Any

BEAT_S = 0.25  # ~50 us a wake-up: 0.026 % of a core (a busy 2-core machine, 2026-11-26)
SLACK_S = 0.5  # a beat late by more is a stall (a loaded machine's delays stay below: < 0.2 s)
_KEEP = 4096  # stalls remembered for converting past times (older ones: the oldest kept)


class ListeningClock:
    """Monotonic seconds minus the stalls of this process (see the module docstring)."""

    def __init__(self, beat_s: float = BEAT_S, slack_s: float = SLACK_S) -> None:
        self.beat_s, self.slack_s = beat_s, slack_s
        self._lock = threading.Lock()
        self._last_beat = time.monotonic()
        self._stalled = 0.0  # seconds left out so far
        # per stall: where its left-out part starts and ends (monotonic), and the seconds left
        # out after it; ends are increasing
        self._stalls: deque[tuple[float, float, float]] = deque(maxlen=_KEEP)
        self._stopped = False
        self._thread = threading.Thread(target=self._run, name="listening-clock", daemon=True)

    def start(self) -> None:
        """Start the beat; the time before it (the daemon's start-up) is listened, no stall."""
        with self._lock:
            self._last_beat = time.monotonic()
        self._thread.start()

    def close(self) -> None:
        self._stopped = True
        if self._thread.is_alive():
            self._thread.join()

    def _run(self) -> None:
        while not self._stopped:
            time.sleep(self.beat_s)  # cheaper than an Event's wait (half the CPU)
            self.beat(time.monotonic())

    def beat(self, mono: float) -> None:
        """A wake-up of the beat at monotonic ``mono``; a gap over ``slack_s`` since the
        last one is a stall."""
        with self._lock:
            start = self._last_beat + self.slack_s
            if mono > start:
                self._stalled += mono - start
                self._stalls.append((start, mono, self._stalled))
            self._last_beat = mono

    def now(self) -> float:
        """Listening time now (a stall still going on left out)."""
        mono = time.monotonic()
        with self._lock:
            return mono - self._stalled - max(0.0, mono - self._last_beat - self.slack_s)

    def at(self, mono: float) -> float:
        """Listening time at monotonic ``mono`` in the past (e.g. when a message was
        delivered). A time inside a stall's left-out part, which a running process cannot
        have seen unless the beat woke late, counts as the stall's start."""
        with self._lock:
            stalls = self._stalls
            i = bisect.bisect_left(stalls, mono, key=lambda s: s[1])
            if i == len(stalls):  # after every stall seen (or in one going on)
                return min(mono, self._last_beat + self.slack_s) - self._stalled
            start, end, after = stalls[i]
            return min(mono, start) - (after - (end - start))


class IntakeQueue(queue.SimpleQueue):
    """A :class:`queue.SimpleQueue` that knows when its oldest waiting item was put."""

    def __init__(self) -> None:
        super().__init__()
        # put times (monotonic), appended before each item goes in and taken after each item
        # comes out: never fewer than the items waiting
        self._put_times: deque[float] = deque()

    def put(self, item: Any, block: bool = True, timeout: float | None = None) -> None:
        self._put_times.append(time.monotonic())
        super().put(item, block, timeout)

    def put_nowait(self, item: Any) -> None:  # SimpleQueue's own would not call put()
        self.put(item, False)

    def get(self, block: bool = True, timeout: float | None = None) -> Any:
        item = super().get(block, timeout)
        self._put_times.popleft()
        return item

    def get_nowait(self) -> Any:
        return self.get(False)

    def oldest_put(self) -> float | None:
        """When the oldest item still waiting was put (monotonic; None: none waits)."""
        try:
            return self._put_times[0]
        except IndexError:
            return None
