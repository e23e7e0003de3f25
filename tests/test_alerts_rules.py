"""Timed sequences per rule kind: fire, hold, clear, re-send, ack and latch at exact ticks.

Ticks are 10 s of sensor time; tick k ends at T(k) = T0 + 10 k s. Each test lists the value
the rule sees per tick and the exact (tick, event) pairs expected.
"""

from __future__ import annotations

import json
import math

import numpy as np

from monitor.alerts.engine import AlertEngine
from monitor.alerts.records import ALERT_JSON_SCHEMA
from monitor.events import ComponentObs, Observation, StreamObs

NS = 1_000_000_000
T0 = 1_700_000_000 * NS
TICK = 10 * NS
NAN = math.nan


def T(k: int) -> int:
    return T0 + k * TICK


def comp(damage=0.0, committed=None, rate=0.0, life=math.inf, stress=NAN) -> ComponentObs:
    return ComponentObs(damage, damage if committed is None else committed, rate, life, stress)


def stream(stale=False, last=0, rejected=0, received=0) -> StreamObs:
    return StreamObs(last, stale, received - rejected, {"range": rejected}, rejected, received)


def obs(k, components=None, tension=(), tension_t=None, measured=NAN, estimated=NAN,
        streams=None, buoy="b1") -> Observation:
    x = np.asarray(tension, dtype=float)
    if tension_t is None:  # samples evenly inside the tick (t_{k-1}, t_k]
        tension_t = T(k - 1) + (np.arange(1, len(x) + 1) * TICK) // max(len(x), 1)
    return Observation(
        buoy_id=buoy, t_ns=T(k), tick_s=10.0, load_source="measured",
        load_t_ns=np.asarray(tension_t, dtype=np.int64), tension_N=x,
        measured_tension_N=measured, estimated_tension_N=estimated,
        components=components or {}, streams=streams or {},
    )


def engine(rule: dict, resend_s: float = 3600.0, components=None) -> AlertEngine:
    cfg = {"resend_interval_s": resend_s, "rule": [rule]}
    return AlertEngine.from_config(cfg, "b1", components or {"left": 15.8e6})


def run(eng: AlertEngine, observations, before=None):
    """Evaluate; return [(tick, event, component, value)]. ``before[k]`` runs prior to tick k."""
    out = []
    for k, o in observations:
        if before and k in before:
            before[k](eng)
        for r in eng.evaluate(o):
            assert r.at_ns == T(k)
            out.append((k, r.event, r.component, r.value))
    return out


def events(seq):
    return [(k, e) for k, e, *_ in seq]


def test_damage_fraction_fires_latches_resends_and_clears_only_on_reset_or_replacement():
    eng = engine({"kind": "damage_fraction", "component": "left", "threshold": 0.1,
                  "severity": "warning"}, resend_s=30)
    damage = {1: 0.05, 2: 0.09, 3: 0.1, 4: 0.11, 5: 0.115, 6: 0.118, 7: 0.099, 8: 0.12,
              9: 0.15, 10: 0.221, 11: 0.0, 12: 0.01}
    # committed damage is monotone until the cable replacement at tick 11
    committed = {k: min(v, 0.098) if k < 11 else v for k, v in damage.items()}
    seq = run(eng, [(k, obs(k, {"left": comp(damage[k], committed[k])})) for k in damage],
              before={8: lambda e: e.reset("damage_fraction", "left", "ops", "inspected", 123)})
    assert events(seq) == [
        (3, "fire"),     # 0.1 >= 0.1
        (6, "resend"),   # 30 s after the fire, still latched
        # tick 7: damage dips to 0.099 (provisional residue) but the alert stays latched
        (8, "reset"),    # operator reset: released at the next tick, re-baselined at 0.12
        (10, "fire"),    # 0.221 - 0.12 = 0.101 >= 0.1 (0.15 at tick 9 is only +0.03)
        (11, "reset"),   # committed damage went down: cable replaced, counts from zero
    ]
    assert seq[0][3] == 0.1 and seq[3][3] == 0.221
    hist = eng.history()
    assert [h["type"] for h in hist] == ["alert", "reset", "alert", "alert", "alert"]
    assert hist[1] == {"type": "reset", "fingerprint": hist[0]["fingerprint"],
                       "rule": "damage_fraction", "component": "left", "who": "ops",
                       "why": "inspected", "at_ns": 123}
    released = hist[2]
    assert released["state"] == "resolved" and released["starts_at_ns"] == T(3)
    assert released["ends_at_ns"] == T(8)
    assert eng.active() == []


def test_damage_rate_on_and_off_delays():
    eng = engine({"kind": "damage_rate", "threshold": 0.01, "on_delay_s": 20,
                  "off_delay_s": 20})
    rate = [0.02, 0.005, 0.02, 0.02, 0.02, 0.0, 0.02, 0.0, 0.0, 0.0]
    seq = run(eng, [(k, obs(k, {"left": comp(rate=r)})) for k, r in enumerate(rate, 1)])
    # pending from tick 1 cancelled at tick 2; pending again from tick 3, fires 20 s later at 5;
    # clearing from tick 6 cancelled at 7; clearing from tick 8 completes 20 s later at 10
    assert events(seq) == [(5, "fire"), (10, "clear")]
    assert seq[1][3] == 0.0


def test_remaining_life_below_days_and_nan_changes_nothing():
    eng = engine({"kind": "remaining_life", "threshold": 30, "severity": "critical"})
    life = [100.0, 20.0, math.inf, NAN, 10.0, NAN, 40.0]
    seq = run(eng, [(k, obs(k, {"left": comp(life=v)})) for k, v in enumerate(life, 1)])
    assert events(seq) == [(2, "fire"), (3, "clear"), (5, "fire"), (7, "clear")]
    assert seq[2][3] == 10.0 and seq[2][1] == "fire"


def test_tension_high_deadband_and_on_delay():
    eng = engine({"kind": "tension_high", "threshold": 0.5, "breaking_strength_N": 45e3,
                  "deadband": 0.1, "on_delay_s": 10})
    peaks = {1: 20e3, 2: 23e3, 3: 24e3, 4: 20e3, 5: 17e3, 6: 23e3, 7: None, 8: 23e3}
    ticks = [(k, obs(k, tension=[] if p is None else [5e3, p, 8e3])) for k, p in peaks.items()]
    seq = run(eng, ticks)
    # on at > 22.5 kN after 10 s (ticks 2 -> 3); held at 20 kN (above the 18 kN deadband
    # edge); off at 17 kN; a tick without samples (7) keeps the pending start of tick 6
    assert events(seq) == [(3, "fire"), (5, "clear"), (8, "fire")]
    assert [v for *_, v in seq] == [24e3, 17e3, 23e3]
    rec = eng.active()[0]
    assert rec.threshold == 22.5e3 and rec.unit == "N" and rec.component == "cable"
    assert rec.annotations["value"] == "23 kN" and rec.annotations["threshold"] == "22.5 kN"


def test_conductor_stress_only_for_components_with_an_endurance_stress():
    comps = {"left": {"endurance_stress_Pa": 15.8e6}, "right": 15.8e6, "core": None}
    eng = engine({"kind": "conductor_stress"}, components=comps)
    assert eng.rule_keys() == [("conductor_stress", "left"), ("conductor_stress", "right")]
    left = [10e6, 16e6, 12e6]
    seq = run(eng, [(k, obs(k, {"left": comp(stress=s), "right": comp(stress=10e6),
                                "core": comp(stress=99e6)})) for k, s in enumerate(left, 1)])
    assert [(k, e, c) for k, e, c, _ in seq] == [(2, "fire", "left"), (3, "clear", "left")]


def test_slack_then_snap_within_window():
    eng = engine({"kind": "slack_snap", "floor_N": 1000, "threshold": 5000, "window_s": 2,
                  "off_delay_s": 20})
    S = NS

    def tick(k, values_at):  # 1 Hz samples at t_{k-1} + 1..10 s, 3 kN unless given
        x = [values_at.get(i, 3000.0) for i in range(1, 11)]
        return (k, obs(k, tension=x, tension_t=[T(k - 1) + i * S for i in range(1, 11)]))

    seq = run(eng, [
        tick(1, {}),
        tick(2, {9: 500.0}),           # slack at t1 + 9 s
        tick(3, {1: 7000.0}),          # 2 s after the slack (t2 + 1 s): snap across ticks
        tick(4, {}), tick(5, {}),
        tick(6, {}),                   # 20 s without a snap after tick 4: clear
        tick(7, {5: 500.0, 8: 7000.0}),  # jump 3 s after slack: outside the 2 s window
        tick(8, {2: 500.0, 3: 6500.0}),  # jump 1 s after slack within one tick: snap
    ])
    assert [(k, e, v) for k, e, _, v in seq] == [(3, "fire", 7000.0), (6, "clear", 0.0),
                                                 (8, "fire", 6500.0)]


def test_stale_resend_and_ack_suppresses_resend():
    eng = engine({"kind": "stale", "component": "tension", "on_delay_s": 10}, resend_s=30)
    last = T(1)
    flags = [False, True, True, True, True, True, True, True, True, False]
    seq = run(eng, [(k, obs(k, streams={"tension": stream(f, last)}))
                    for k, f in enumerate(flags, 1)],
              before={7: lambda e: e.ack(e.active()[0].fingerprint, "ana", "known outage",
                                         T(6) + 5)})
    # pending at 2, fires at 3, re-sent at 6 (30 s); acked before 7 so no re-send at 9
    assert events(seq) == [(3, "fire"), (6, "resend"), (10, "clear")]
    assert seq[0][3] == 20.0  # data age at tick 3: T(3) - T(1)
    assert [h["type"] for h in eng.history()] == ["alert", "ack", "alert"]
    assert eng.history()[2]["acked_by"] == "ana"  # the clear carries the acknowledgement


def test_rejected_rate_over_sliding_window():
    eng = engine({"kind": "rejected_rate", "component": "tension", "threshold": 0.1,
                  "window_s": 30})
    rejected = [0, 30, 30, 40, 0, 0]
    seq = run(eng, [(k, obs(k, streams={"tension": stream(rejected=r, received=200)}))
                    for k, r in enumerate(rejected, 1)])
    # window of the last 30 s = 3 ticks: 0.075, 0.1 (not above), 100/600, 70/600, 40/600
    assert [(k, e, round(v, 6)) for k, e, _, v in seq] == [(4, "fire", round(100 / 600, 6)),
                                                           (6, "clear", round(40 / 600, 6))]


def test_model_residual_needs_both_and_a_duration():
    eng = engine({"kind": "model_residual", "threshold": 2000, "on_delay_s": 20})
    pairs = [(10e3, 9e3), (13e3, 10e3), (13e3, 10e3), (13e3, NAN), (13e3, 10e3), (10e3, 9.5e3)]
    seq = run(eng, [(k, obs(k, measured=m, estimated=e)) for k, (m, e) in enumerate(pairs, 1)])
    assert [(k, e, v) for k, e, _, v in seq] == [(5, "fire", 3000.0), (6, "clear", 500.0)]


def test_record_json_and_alertmanager_shape():
    eng = engine({"kind": "damage_rate", "threshold": 0.01, "severity": "critical"})
    rec = eng.evaluate(obs(1, {"left": comp(rate=0.5)}))[0]
    d = json.loads(json.dumps(rec.to_dict(), allow_nan=False))
    assert type(rec).from_dict(d) == rec
    assert sorted(d) == sorted(ALERT_JSON_SCHEMA["required"]) == sorted(
        ALERT_JSON_SCHEMA["properties"])
    am = rec.to_alertmanager()
    assert am["status"] == "firing" and am["endsAt"] == "0001-01-01T00:00:00Z"
    assert am["startsAt"] == "2023-11-14T22:13:30.000000Z"  # T0 = 1.7e9 s, + 10 s
    assert am["labels"] == {"alertname": "damage_rate", "severity": "critical", "buoy": "b1",
                            "component": "left", "rule": "damage_rate"}
    assert rec.key == "buoy/b1/monitor/alert/damage_rate/left"
    assert rec.fingerprint == AlertEngine.from_config(
        {"rule": [{"kind": "damage_rate", "threshold": 1}]}, "b1", {"left": None}
    ).evaluate(obs(1, {"left": comp(rate=2.0)}))[0].fingerprint
