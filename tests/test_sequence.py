"""SequenceTracker: redelivered vs new vs missed, by publisher sequence number, and exact
save/restore (it lives in the daemon's checkpoint)."""

from __future__ import annotations

import json

from monitor.sequence import SequenceTracker, Verdict

A, B = "z1/6", "z2/6"


def test_in_order_messages_are_taken_and_nothing_is_counted():
    t = SequenceTracker()
    assert [t.observe("tension", A, sn) for sn in range(5)] == [Verdict(False, 0)] * 5
    assert t.fields("tension") == {"samples_missed": 0, "redelivered": 0, "recovered": 0}
    assert t.gap("tension", A, 5) is None
    assert t.gap("tension", A, None) == (5, None)


def test_redelivered_numbers_are_skipped_and_a_jump_counts_the_gap():
    t = SequenceTracker()
    for sn in range(10):
        t.observe("tension", A, sn)
    assert t.observe("tension", A, 3) == Verdict(True, 0)
    assert t.observe("tension", A, 9) == Verdict(True, 0)
    assert t.gap("tension", A, 17) == (10, 16)
    assert t.observe("tension", A, 17) == Verdict(False, 7)  # 10..16 never came
    assert t.observe("tension", A, 18) == Verdict(False, 0)
    assert t.fields("tension") == {"samples_missed": 7, "redelivered": 2, "recovered": 0}
    assert t.fields("imu") == {"samples_missed": 0, "redelivered": 0, "recovered": 0}


def test_a_new_publisher_starts_a_fresh_count_and_messages_without_numbers_pass():
    t = SequenceTracker()
    t.observe("tension", A, 100)
    assert t.gap("tension", B, 40) == (0, 39)  # never seen: its whole cache is wanted
    assert t.observe("tension", B, 40) == Verdict(False, 0)  # a restarted sensor: no miss
    assert t.observe("tension", None, None) == Verdict(False, 0)
    assert t.latest_sources() == {("tension", B)}
    assert t.fields("tension")["samples_missed"] == 0


def test_state_round_trips_exactly_through_json():
    t = SequenceTracker()
    for sn in (0, 1, 5):
        t.observe("tension", A, sn)
    t.observe("imu", B, 0)
    t.observe("imu", B, 0)
    t.recovered_from_cache("imu", 3)
    back = SequenceTracker(json.loads(json.dumps(t.state())))
    assert back.state() == t.state()
    assert back.observe("tension", A, 5) == Verdict(True, 0)
    assert back.observe("tension", A, 8) == Verdict(False, 2)
    assert back.fields("imu") == {"samples_missed": 0, "redelivered": 1, "recovered": 3}
