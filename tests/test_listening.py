"""monitor.listening: a stall of the whole process is left out of the daemon's data ages, a
busy or sleeping thread is not (tests/test_daemon_stall.py: the daemon under SIGSTOP)."""

from __future__ import annotations

import sys
import time

import pytest

from monitor.listening import IntakeQueue, ListeningClock


def test_stalls_are_left_out_beyond_the_slack_and_past_times_convert_by_them():
    c = ListeningClock(beat_s=0.1, slack_s=0.5)
    t = time.monotonic() - 100.0  # a synthetic past: beats at t, t+0.1, t+6.1 (a 6-s gap)
    c.beat(t)
    c.beat(t + 0.1)
    c.beat(t + 0.55)  # late by less than the slack: no stall
    c.beat(t + 6.1)  # 5.55 s gap: left out beyond the 0.5-s slack
    c.beat(t + 6.2)
    c.beat(t + 9.0)  # a second stall: 2.8 - 0.5
    assert c.at(t + 0.05) == t + 0.05
    assert c.at(t + 1.05) == t + 1.05  # where its left-out part starts
    assert c.at(t + 3.0) == t + 1.05  # inside a stall: its start (a running process saw it)
    assert c.at(t + 6.15) == pytest.approx(t + 6.15 - 5.05, abs=1e-9)
    assert c.at(t + 9.5) == pytest.approx(t + 9.5 - 5.05 - 2.3, abs=1e-9)
    # a stream delivered at t+0.05 and judged at t+6.15 has listened 1.05 s, not 6.1 s
    assert c.at(t + 6.15) - c.at(t + 0.05) == pytest.approx(1.05, abs=1e-9)


def test_a_gil_holding_pause_is_left_out_and_a_sleep_is_not():
    c = ListeningClock(beat_s=0.05, slack_s=0.3)
    c.start()
    old = sys.getswitchinterval()
    try:
        l0, m0 = c.now(), time.monotonic()
        time.sleep(1.0)  # the process runs: listening time goes on
        assert c.now() - l0 == pytest.approx(time.monotonic() - m0, abs=0.05)
        sys.setswitchinterval(5.0)  # the beat cannot take the GIL: as a long GC pause
        l1, m1 = c.now(), time.monotonic()
        while time.monotonic() - m1 < 1.5:
            pass
        sys.setswitchinterval(old)
        during = c.now() - l1  # read before the beat woke: the stall going on is left out
        time.sleep(0.2)
        after = c.now() - l1
    finally:
        sys.setswitchinterval(old)
        c.close()
    assert 0.0 < during <= 0.3 + 0.05 + 0.01
    assert 0.2 <= after <= 0.3 + 0.05 + 0.2 + 0.05


def test_the_intake_queue_knows_when_its_oldest_waiting_item_was_put():
    q = IntakeQueue()
    assert q.oldest_put() is None
    before = time.monotonic()
    q.put("a")
    time.sleep(0.05)
    mid = time.monotonic()
    q.put("b")
    first = q.oldest_put()
    assert before <= first <= mid
    assert q.get_nowait() == "a"
    assert mid <= q.oldest_put() <= time.monotonic()
    assert q.get(timeout=1) == "b" and q.oldest_put() is None and q.qsize() == 0
    # every way in and out keeps the times (SimpleQueue's C put_nowait skipped put(): a get
    # then popped an empty deque, IndexError in the daemon's loop)
    q.put_nowait("c")
    assert q.oldest_put() is not None and q.get() == "c" and q.oldest_put() is None


def test_the_time_before_the_beat_starts_is_listened():
    """The daemon makes its clock, then restores its pipeline (seconds, from a large state)
    and opens its session before the beat starts: that start-up is no stall (was: left out,
    so a stream silent since before a restart was called younger by the start-up's length)."""
    c = ListeningClock(beat_s=0.05, slack_s=0.3)
    l0, m0 = c.now(), time.monotonic()
    time.sleep(0.8)  # the start-up, before start()
    c.start()
    try:
        time.sleep(0.2)
        assert c.now() - l0 == pytest.approx(time.monotonic() - m0, abs=0.05)
    finally:
        c.close()
