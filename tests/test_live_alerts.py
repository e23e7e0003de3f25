"""Live (wall-clock) alert rules on status documents, and clock-fault detection per block.

The wall clock is passed in, so these checks are exact; tests/test_daemon_live.py drives the
same rules in a real daemon process.
"""

from monitor.alerts.live import LiveAlerts, LiveConfig
from monitor.clock_faults import ClockFaults

NS = 10**9
YEAR_S = 365 * 86400
T0 = 1_750_000_000 * NS


def doc(age=None, accepted=0, missed=None, feed=1.0, ckpt_failing=False, channels=None,
        uptime=100.0, **stream):
    s = {"data_age_s": age, "data_age_timeout_s": 5.0, "accepted": accepted, "rejected": {},
         **stream}
    if missed is not None:
        s["samples_missed"] = missed
    d = {"uptime_s": uptime, "streams": {"tension": s}, "fatigue_feed_age_s": feed,
         "checkpoint": {"failing": ckpt_failing, "failures": int(ckpt_failing),
                        "last_error": "disk I/O error" if ckpt_failing else None}}
    if channels is not None:
        d["delivery"] = {"channels": channels}
    return d


def fired(records):
    return {(r.rule, r.component, r.event) for r in records}


def test_data_age_fires_after_the_timeout_and_clears_when_data_flows():
    live = LiveAlerts("b1", LiveConfig())
    assert live.evaluate(doc(age=4.9, accepted=10), 1 * NS) == []
    recs = live.evaluate(doc(age=5.1, accepted=10), 2 * NS)
    assert fired(recs) == {("data_age", "tension", "fire")}
    assert recs[0].value == 5.1 and recs[0].threshold == 5.0 and recs[0].starts_at_ns == 2 * NS
    assert live.health() == {"ok": False, "reasons": [
        "data_age tension: no data on stream tension for 5 s (timeout 5 s, logger clock)"]}
    assert live.evaluate(doc(age=9.0, accepted=10), 3 * NS) == []  # no repeat
    recs = live.evaluate(doc(age=0.1, accepted=20), 4 * NS)
    assert fired(recs) == {("data_age", "tension", "clear")}
    assert recs[0].starts_at_ns == 2 * NS and recs[0].ends_at_ns == 4 * NS
    assert live.health()["ok"]


def test_a_stream_never_seen_alerts_only_when_required_counting_from_the_start():
    live = LiveAlerts("b1", LiveConfig())
    assert live.evaluate(doc(age=None, uptime=1000.0), NS) == []  # unknown stream: no alert
    req = LiveAlerts("b1", LiveConfig(required_streams=("tension",)))
    assert req.evaluate(doc(age=None, uptime=4.0), NS) == []
    recs = req.evaluate(doc(age=None, uptime=6.0), 2 * NS)
    assert fired(recs) == {("data_age", "tension", "fire")} and recs[0].value == 6.0
    # a stream known from the checkpoint (accepted before) counts from the daemon's start too
    known = LiveAlerts("b1", LiveConfig())
    assert fired(known.evaluate(doc(age=None, accepted=5, uptime=6.0), NS)) == {
        ("data_age", "tension", "fire")}


def test_data_that_arrives_but_is_all_rejected_is_alerted():
    live = LiveAlerts("b1", LiveConfig())
    flowing = dict(age=0.5, accepted=100, rejected={"time_backwards": 40},
                   rejected_since_accepted=40)
    assert live.evaluate(doc(**flowing, accepted_age_s=4.0), NS) == []
    # samples held back by the ordering layer (none rejected meanwhile) are not this rule's
    held = dict(flowing, rejected_since_accepted=0)
    assert live.evaluate(doc(**held, accepted_age_s=8.0), NS) == []
    recs = live.evaluate(doc(**flowing, accepted_age_s=6.0), 2 * NS)
    assert fired(recs) == {("data_rejected", "tension", "fire")}
    assert recs[0].summary == ("stream tension: data arrives but none was accepted for 6 s: "
                               "since then 0 duplicate(s) (data already received, sent again) "
                               "and 40 rejected (so far: 0 duplicate(s); rejected "
                               "time_backwards=40)")
    # copies of old data (a publisher re-sending) are told apart from rejections
    mixed = dict(age=0.5, accepted=100, rejected={"duplicate": 700, "time_backwards": 40},
                 rejected_since_accepted=540, duplicates_since_accepted=500)
    again = LiveAlerts("b1", LiveConfig()).evaluate(doc(**mixed, accepted_age_s=6.0), 2 * NS)
    assert again[0].summary.endswith(": since then 500 duplicate(s) (data already received, "
                                     "sent again) and 40 rejected (so far: 700 duplicate(s); "
                                     "rejected time_backwards=40)")
    assert not live.health()["ok"]
    # data that stopped altogether is data_age's, not this rule's
    recs = live.evaluate(doc(age=9.0, accepted=100, accepted_age_s=9.0), 3 * NS)
    assert fired(recs) == {("data_rejected", "tension", "clear"), ("data_age", "tension", "fire")}


def test_fatigue_blind_and_checkpoint_failed_make_health_fail():
    live = LiveAlerts("b1", LiveConfig(fatigue_blind_timeout_s=60.0))
    recs = live.evaluate(doc(age=1.0, accepted=1, feed=61.0, ckpt_failing=True), NS)
    assert fired(recs) == {("fatigue_blind", "fatigue", "fire"),
                           ("checkpoint_failed", "checkpoint", "fire")}
    assert [r.severity for r in recs] == ["critical", "critical"]
    assert len(live.health()["reasons"]) == 2
    recs = live.evaluate(doc(age=1.0, accepted=1, feed=1.0), 2 * NS)
    assert fired(recs) == {("fatigue_blind", "fatigue", "clear"),
                           ("checkpoint_failed", "checkpoint", "clear")}


def test_counter_increases_fire_for_hold_s_and_old_counts_do_not_alert():
    live = LiveAlerts("b1", LiveConfig(hold_s=600.0))
    ch = {"webhook": {"pending": 3, "dead_letters": 0, "dropped_total": 2}}
    # first sight of the counters (e.g. after a restart): the base, no alert
    assert live.evaluate(doc(age=1.0, accepted=1, missed=7, channels=ch), NS) == []
    ch2 = {"webhook": {"pending": 3, "dead_letters": 1, "dropped_total": 3}}
    recs = live.evaluate(doc(age=1.0, accepted=1, missed=9, channels=ch2), 2 * NS)
    assert fired(recs) == {("samples_missed", "tension", "fire"),
                           ("alert_delivery_refused", "webhook", "fire"),
                           ("alert_outbox_dropped", "webhook", "fire")}
    assert next(r for r in recs if r.rule == "samples_missed").value == 9
    assert live.evaluate(doc(age=1.0, accepted=1, missed=9, channels=ch2), 601 * NS) == []
    recs = live.evaluate(doc(age=1.0, accepted=1, missed=9, channels=ch2), 603 * NS)
    assert fired(recs) == {("samples_missed", "tension", "clear"),
                           ("alert_outbox_dropped", "webhook", "clear")}


def test_an_alert_undelivered_longer_than_delivery_stall_s_is_alerted_and_fails_health():
    live = LiveAlerts("b1", LiveConfig(delivery_stall_s=30.0))
    waiting = {"alertmanager": {"pending": 2, "dead_letters": 0, "oldest_pending_age_s": 29.5},
               "webhook": {"pending": 0, "dead_letters": 0, "oldest_pending_age_s": None}}
    assert live.evaluate(doc(age=1.0, accepted=1, channels=waiting), NS) == []
    waiting["alertmanager"]["oldest_pending_age_s"] = 30.5
    recs = live.evaluate(doc(age=1.0, accepted=1, channels=waiting), 2 * NS)
    assert fired(recs) == {("alert_delivery_stalled", "alertmanager", "fire")}
    assert (recs[0].severity, recs[0].value, recs[0].threshold) == ("critical", 30.5, 30.0)
    assert recs[0].summary == ("alert channel alertmanager: 2 notifications undelivered, the "
                               "oldest for 30 s (receiver unreachable or failing; retried)")
    assert live.health()["ok"] is False
    delivered = {"alertmanager": {"pending": 0, "dead_letters": 0, "oldest_pending_age_s": None}}
    recs = live.evaluate(doc(age=1.0, accepted=1, channels=delivered), 3 * NS)
    assert fired(recs) == {("alert_delivery_stalled", "alertmanager", "clear")}
    assert live.health()["ok"] is True


def test_state_survives_a_restart_and_clears_what_no_longer_holds_after_hold_s():
    live = LiveAlerts("b1", LiveConfig())
    live.evaluate(doc(age=9.0, accepted=1, missed=1), NS)
    live.evaluate(doc(age=9.0, accepted=1, missed=2), 2 * NS)
    saved = live.state()
    again = LiveAlerts("b1", LiveConfig(), saved)
    assert {(r.rule, r.component) for r in again.active()} == {
        ("data_age", "tension"), ("samples_missed", "tension")}
    # just restarted, the tension stream has not reported yet: no evidence either way, so
    # both stay firing (no clear now and fire again later) ...
    assert again.evaluate({"uptime_s": 1.0, "streams": {}}, 3 * NS) == []
    assert len(again.active()) == 2
    # ... until hold_s (600 s) of this life without the stream: then its subject is gone
    recs = again.evaluate({"uptime_s": 600.0, "streams": {}}, 600 * NS)
    assert fired(recs) == {("data_age", "tension", "clear"),
                           ("samples_missed", "tension", "clear")}
    assert again.active() == []


def test_a_restart_that_caught_up_between_evaluations_still_fires_for_hold_s():
    live = LiveAlerts("b1", LiveConfig(hold_s=600.0))
    base = doc(age=1.0, accepted=1, time_restarts=0, time_behind_s=0.0, time_restart_jump_s=0.0)
    assert live.evaluate(base, NS) == []
    again = doc(age=1.0, accepted=1, time_restarts=1, time_behind_s=0.0, time_restart_jump_s=9.5)
    recs = live.evaluate(again, 2 * NS)
    assert fired(recs) == {("time_restart", "tension", "fire")} and recs[0].value == 9.5
    assert fired(live.evaluate(again, 603 * NS)) == {("time_restart", "tension", "clear")}
    # restart counts start at 0 in every daemon life: not saved as a base
    assert live.state()["counters"] == []


def test_a_damaged_saved_state_starts_fresh():
    live = LiveAlerts("b1", LiveConfig(), {"firing": [{"rule": "x"}], "counters": [["a"]]})
    assert live.active() == [] and live.state() == {"firing": [], "counters": []}


def test_live_rules_off_raise_nothing_but_health_still_fails():
    live = LiveAlerts("b1", LiveConfig(enabled=False))
    assert live.evaluate(doc(age=99.0, accepted=1, feed=999.0), NS) == []
    assert live.active() == []
    assert [r.split(":")[0] for r in live.health()["reasons"]] == [
        "data_age tension", "fatigue_blind fatigue"]


def test_clock_skew_of_a_year_either_way_is_counted_with_its_size():
    cf = ClockFaults(skew_max_s=600.0, restart_min_s=1.0)
    recv = T0
    assert cf.observe("tension", T0 - NS, recv) == []
    msgs = cf.observe("tension", T0 + YEAR_S * NS, recv + NS)
    assert msgs == [f"stream tension: sensor time is {YEAR_S - 1:.6g} s ahead of the logger "
                    "clock (allowed 600 s)"]
    assert cf.fields("tension")["clock_skew_s"] == YEAR_S - 1
    assert cf.fields("tension")["clock_skewed_blocks"] == 1
    cf2 = ClockFaults(600.0, 1.0)
    cf2.observe("imu", T0 - YEAR_S * NS, recv)
    assert cf2.fields("imu")["clock_skew_s"] == -YEAR_S
    assert cf.fields("gnss") == {"clock_skew_s": None, "clock_skewed_blocks": 0,
                                 "time_restarts": 0, "time_behind_s": 0.0,
                                 "time_restart_jump_s": 0.0}


def test_a_block_time_ahead_of_its_arrival_is_skewed_but_the_next_right_one_no_restart():
    """A block 601 s ahead of its arrival (time_ahead: the pipeline rejects it) is a clock
    skew; the stream's next block at the right time is no restart. 600 s ahead is taken."""
    cf = ClockFaults(skew_max_s=300.0, restart_min_s=1.0, max_ahead_s=600.0)
    cf.observe("tension", T0, T0)
    assert len(cf.observe("tension", T0 + 601 * NS, T0)) == 1
    assert cf.observe("tension", T0 + NS, T0 + NS) == []
    assert cf.fields("tension")["time_restarts"] == 0
    cf.observe("tension", T0 + 602 * NS, T0 + 2 * NS)
    assert len(cf.observe("tension", T0 + 3 * NS, T0 + 3 * NS)) == 1  # 599 s back: a restart
    assert cf.fields("tension")["time_restarts"] == 1


def test_a_late_block_is_ahead_by_its_receive_time_and_behind_by_its_publication():
    """A block fetched from a publisher's cache 100 s after it was published: a sample 50 s
    after the publication is ahead of nothing (the pipeline judges time_ahead against the
    receive time: it takes the sample, so it is the stream's newest time: going back 40 s
    from it is a restart); one 20 s before the publication is behind it within the allowed
    30 s (arriving late is no skew), one 40 s before is skewed by 40 s."""
    sent, recv = T0, T0 + 100 * NS
    cf = ClockFaults(skew_max_s=30.0, restart_min_s=1.0, max_ahead_s=30.0)
    assert cf.observe("tension", T0 + 50 * NS, recv, sent) == []
    assert cf.fields("tension")["clock_skew_s"] == 0.0
    assert len(cf.observe("tension", T0 + 10 * NS, recv, sent)) == 1  # back 40 s: a restart
    assert cf.fields("tension")["time_restarts"] == 1
    assert cf.observe("tension", T0 + 60 * NS, recv, sent) == []
    assert cf.fields("tension")["clock_skew_s"] == 0.0
    assert cf.observe("tension", T0 - 20 * NS, T0 + 100 * NS, sent)[0].startswith(
        "stream tension: time restarted")  # not skewed: the restart's message alone
    assert cf.fields("tension")["clock_skew_s"] == -20.0
    assert cf.fields("tension")["clock_skewed_blocks"] == 0
    msgs = cf.observe("tension", T0 - 40 * NS, recv, sent)
    assert msgs[0] == ("stream tension: sensor time is 40 s behind the logger clock "
                       "(allowed 30 s)")
    # a sample 31 s ahead of its arrival: skewed, and not the newest (the pipeline rejects it)
    assert len(cf.observe("imu", recv + 31 * NS, recv, sent)) == 1
    assert cf.fields("imu")["clock_skew_s"] == 31.0
    assert cf.streams["imu"].newest_ns is None


def test_time_restart_is_counted_once_and_holds_until_the_stream_catches_up():
    cf = ClockFaults(skew_max_s=1e12, restart_min_s=1.0)
    for k in range(10):
        assert cf.observe("tension", T0 + k * NS, T0) == []
    msgs = cf.observe("tension", T0 + 2 * NS, T0)  # the publisher restarted 7 s back
    assert msgs == ["stream tension: time restarted 7 s in the past (its samples are rejected "
                    "as time_backwards until it catches up)"]
    assert cf.fields("tension")["time_restarts"] == 1
    cf.observe("tension", T0 + 3 * NS, T0)
    assert cf.fields("tension") == {"clock_skew_s": 3.0, "clock_skewed_blocks": 0,
                                    "time_restarts": 1, "time_behind_s": 6.0,
                                    "time_restart_jump_s": 7.0}
    assert cf.observe("tension", T0 + 9 * NS, T0) == []  # caught up
    assert cf.fields("tension")["time_behind_s"] == 0.0
    cf.observe("tension", T0 - YEAR_S * NS, T0)  # a second restart, a year back
    assert cf.fields("tension")["time_restarts"] == 2
    assert cf.fields("tension")["time_behind_s"] == YEAR_S + 9
    assert cf.fields("tension")["time_restart_jump_s"] == YEAR_S + 9
    # within the tolerance (re-delivery overlap of under 1 s) is no restart
    cf3 = ClockFaults(1e12, 1.0)
    cf3.observe("gnss", T0 + 10 * NS, T0)
    assert cf3.observe("gnss", T0 + 9_500_000_000, T0) == []
