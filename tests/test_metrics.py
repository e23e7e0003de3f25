"""/healthz verdicts and the metric families of a status document (no server: the daemon
process tests in tests/test_daemon_live.py scrape a real one)."""

import math

from prometheus_client import generate_latest
from prometheus_client.parser import text_string_to_metric_families

from monitor.metrics import STALL_S, healthz, make_registry

NOW = 1_800_000_000 * 10**9


def test_healthz_reasons_and_a_stalled_daemon():
    assert healthz(None) == (503, "starting: no status yet\n")
    ok = {"wall_time_ns": NOW, "health": {"ok": True, "reasons": []}}
    assert healthz(ok, NOW + 10**9) == (200, "ok\n")
    late = NOW + int((STALL_S + 1) * 1e9)
    assert healthz(ok, late) == (503, f"daemon loop stalled: the last status is "
                                      f"{STALL_S + 1:.0f} s old\n")
    bad = {"wall_time_ns": NOW, "health": {"ok": False, "reasons": ["data_age tension: x"]}}
    assert healthz(bad, NOW) == (503, "data_age tension: x\n")


def test_units_and_counters_follow_prometheus_conventions():
    doc = {"buoy_id": "b1", "now_ns": NOW, "load_source": "estimated",
           "streams": {"imu": {"accepted": 7, "rejected": {"nan": 2}, "data_age_s": None,
                               "data_age_timeout_s": 5.0, "samples_missed": 3}},
           "components": {"lay": {"damage": 0.25, "damage_committed": 0.2,
                                  "damage_rate_per_day": 0.864, "remaining_life_days": 2.0}},
           "counters": {"messages": 4}, "checkpoint": {
               "age_s": 1.5, "failures": 0, "late_copies_lost_minutes": {"imu": 2, "tension": 1}},
           "delivery": {"channels": {"webhook": {"pending": 2, "dropped_total": 1}}}}
    text = generate_latest(make_registry(lambda: doc)).decode()
    got = {(s.name, tuple(sorted(s.labels.items()))): s.value
           for f in text_string_to_metric_families(text) for s in f.samples}
    imu = (("buoy", "b1"), ("stream", "imu"))
    lay = (("buoy", "b1"), ("component", "lay"))
    assert got[("buoymon_samples_accepted_total", imu)] == 7
    assert got[("buoymon_samples_rejected_total", (("buoy", "b1"), ("reason", "nan"),
                                                   ("stream", "imu")))] == 2
    assert got[("buoymon_samples_missed_total", imu)] == 3
    assert math.isnan(got[("buoymon_data_age_seconds", imu)])  # never arrived
    assert got[("buoymon_damage_ratio", lay)] == 0.25
    assert got[("buoymon_damage_rate_per_second", lay)] == 0.864 / 86400
    assert got[("buoymon_remaining_life_seconds", lay)] == 2.0 * 86400
    assert got[("buoymon_load_source", (("buoy", "b1"), ("source", "estimated")))] == 1.0
    assert got[("buoymon_outbox_pending_messages", (("buoy", "b1"), ("channel", "webhook")))] == 2
    assert got[("buoymon_outbox_dropped_total", (("buoy", "b1"), ("channel", "webhook")))] == 1
    assert got[("buoymon_checkpoint_age_seconds", (("buoy", "b1"),))] == 1.5
    assert got[("buoymon_checkpoint_late_copies_lost_minutes", (("buoy", "b1"),))] == 3
    assert any(name.startswith("process_") for name, _ in got)


def test_bridge_source_families():
    """Each bridge source of the status (monitor.bridge.watch) becomes counters, a one-hot
    state and ages; a source that has read nothing yet has a NaN line age."""
    doc = {"buoy_id": "b1", "bridge": {"sources": {
        "cell": {"sensor": "tension", "state": "stalled", "lines": 12, "samples": 10,
                 "blocks": 3, "rejected": {"columns": 2}, "events": {"disconnected": 1},
                 "last_line_age_s": 7.5, "status_age_s": 0.4},
        "gps": {"sensor": "gnss", "state": "connecting", "lines": 0, "samples": 0,
                "blocks": 0, "rejected": {}, "events": {}, "last_line_age_s": None,
                "status_age_s": 0.4}}}}
    text = generate_latest(make_registry(lambda: doc)).decode()
    got = {(s.name, tuple(sorted(s.labels.items()))): s.value
           for f in text_string_to_metric_families(text) for s in f.samples}
    cell = (("buoy", "b1"), ("sensor", "tension"), ("source", "cell"))
    gps = (("buoy", "b1"), ("sensor", "gnss"), ("source", "gps"))
    assert got[("buoymon_bridge_lines_total", cell)] == 12
    assert got[("buoymon_bridge_samples_total", cell)] == 10
    assert got[("buoymon_bridge_blocks_total", cell)] == 3
    assert got[("buoymon_bridge_rejected_lines_total", (*cell[:1], ("reason", "columns"),
                                                         *cell[1:]))] == 2
    assert got[("buoymon_bridge_link_events_total", (*cell[:1], ("event", "disconnected"),
                                                      *cell[1:]))] == 1
    states = {dict(k[1])["state"]: v for k, v in got.items()
              if k[0] == "buoymon_bridge_source_state" and dict(k[1])["source"] == "cell"}
    assert states == {"reading": 0, "rejecting": 0, "connecting": 0, "stalled": 1,
                      "disconnected": 0, "stopped": 0, "silent": 0}
    assert got[("buoymon_bridge_line_age_seconds", cell)] == 7.5
    assert math.isnan(got[("buoymon_bridge_line_age_seconds", gps)])
    assert got[("buoymon_bridge_status_age_seconds", gps)] == 0.4
