"""Engine-level behaviour: state round trip (bit-exact continuation), operator commands,
input checks, and config validation messages."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from monitor.alerts.config import AlertsConfig
from monitor.alerts.engine import AlertEngine
from monitor.events import ComponentObs, Observation, StreamObs
from monitor.schema import ConfigError

NS = 1_000_000_000
T0 = 1_700_000_000 * NS

ALL_RULES = {
    "resend_interval_s": 60,
    "rule": [
        {"kind": "damage_fraction", "threshold": 0.02, "name": "damage_warning"},
        {"kind": "damage_fraction", "threshold": 0.05, "name": "damage_critical",
         "severity": "critical"},
        {"kind": "damage_rate", "threshold": 0.5, "on_delay_s": 20, "off_delay_s": 30},
        {"kind": "remaining_life", "threshold": 5, "on_delay_s": 10},
        {"kind": "tension_high", "threshold": 0.5, "breaking_strength_N": 45e3,
         "deadband": 0.05, "on_delay_s": 10},
        {"kind": "conductor_stress", "threshold": 1.0, "off_delay_s": 20},
        {"kind": "slack_snap", "floor_N": 2000, "threshold": 15000, "window_s": 2},
        {"kind": "stale", "on_delay_s": 10},
        {"kind": "rejected_rate", "threshold": 0.05, "window_s": 60},
        {"kind": "model_residual", "threshold": 3000, "on_delay_s": 30},
    ],
}
COMPONENTS = {"left": 15.8e6, "right": 15.8e6, "core": None}


def random_ticks(n: int, seed: int = 7) -> list[Observation]:
    rng = np.random.default_rng(seed)
    out, damage = [], {"left": 0.0, "right": 0.0, "core": 0.0}
    for k in range(1, n + 1):
        t = T0 + k * 10 * NS
        lt = t - 10 * NS + np.arange(1, 201, dtype=np.int64) * (10 * NS // 200)
        x = 12e3 + rng.normal(0, 4e3 if k % 9 else 9e3, 200)
        comps = {}
        for name in damage:
            rate = float(rng.choice([0.01, 0.8, 2.0]))
            damage[name] += rate * 10 / 86400 * 5
            comps[name] = ComponentObs(damage[name], damage[name], rate,
                                       (1 - damage[name]) / rate,
                                       float(rng.uniform(5e6, 20e6)))
        streams = {"tension": StreamObs(int(t - 5 * NS), bool(rng.random() < 0.3), 100,
                                        {"range": 3}, int(rng.integers(0, 30)), 200)}
        out.append(Observation("b1", t, 10.0, "measured", lt, x, float(x.mean()),
                               float(x.mean() + rng.choice([0, 5e3])), comps, streams))
    return out


def test_state_round_trip_continues_bit_exactly():
    ticks = random_ticks(120)
    ref = AlertEngine.from_config(ALL_RULES, "b1", COMPONENTS)
    ref_out = []
    for i, o in enumerate(ticks):
        if i == 70:
            ref.reset("damage_warning", "left", "ops", "inspection", 5)
        ref_out += [r.to_dict() for r in ref.evaluate(o)]
    kinds = {r["kind"] for r in ref_out}
    assert {"damage_fraction", "damage_rate", "tension_high", "conductor_stress",
            "slack_snap", "stale", "rejected_rate", "model_residual"} <= kinds

    eng = AlertEngine.from_config(ALL_RULES, "b1", COMPONENTS)
    out = []
    for i, o in enumerate(ticks):
        if i in (33, 70, 101):  # save and restore through strict JSON text
            text = json.dumps(eng.state(), allow_nan=False)
            eng = AlertEngine.from_state(json.loads(text))
            assert json.dumps(eng.state(), allow_nan=False) == text
        if i == 70:
            eng.reset("damage_warning", "left", "ops", "inspection", 5)
        out += [r.to_dict() for r in eng.evaluate(o)]
    assert out == ref_out
    assert eng.state() == ref.state()


def test_from_state_with_an_edited_config_keeps_matching_instances():
    eng = AlertEngine.from_config(ALL_RULES, "b1", COMPONENTS)
    for o in random_ticks(40):
        eng.evaluate(o)
    firing = {r.fingerprint for r in eng.active()}
    assert firing
    edited = {**ALL_RULES, "rule": ALL_RULES["rule"][:1]}
    eng2 = AlertEngine.from_state(eng.state(), alerts_cfg=edited)
    assert {r.fingerprint for r in eng2.active()} == {
        r.fingerprint for r in eng.active() if r.rule == "damage_warning"}


def test_evaluate_rejects_time_going_back_and_foreign_buoy():
    eng = AlertEngine.from_config(ALL_RULES, "b1", COMPONENTS)
    ticks = random_ticks(2)
    eng.evaluate(ticks[1])
    with pytest.raises(ValueError, match="not after the previous evaluation"):
        eng.evaluate(ticks[0])
    with pytest.raises(ValueError, match="buoy 'b2'"):
        eng.evaluate(Observation("b2", ticks[1].t_ns + NS, 10.0, "none",
                                 np.zeros(0, np.int64), np.zeros(0), math.nan, math.nan, {}, {}))


def test_operator_commands_validate():
    eng = AlertEngine.from_config(ALL_RULES, "b1", COMPONENTS)
    with pytest.raises(ValueError, match="no such alert"):
        eng.apply_command({"op": "ack", "fingerprint": "0" * 16, "who": "a", "why": "b",
                           "at_ns": 1})
    with pytest.raises(ValueError, match="who = '': must be a non-empty string"):
        eng.reset("damage_warning", "left", "", "b", 1)
    with pytest.raises(ValueError, match="no such rule instance"):
        eng.apply_command({"op": "reset", "rule": "nope", "component": "left", "who": "a",
                           "why": "b", "at_ns": 1})
    with pytest.raises(ValueError, match="missing field 'why'"):
        eng.apply_command({"op": "reset", "rule": "damage_warning", "component": "left",
                           "who": "a", "at_ns": 1})
    with pytest.raises(ValueError, match='op = \'drop\': must be "ack" or "reset"'):
        eng.apply_command({"op": "drop"})
    res = eng.apply_command({"op": "reset", "rule": "damage_warning", "component": "left",
                             "who": "a", "why": "b", "at_ns": 1})
    assert res == {"ok": True, "op": "reset", "rule": "damage_warning", "component": "left"}


@pytest.mark.parametrize("section, message", [
    ({"rule": [{"kind": "damage_rate", "threshold": 1}, {"kind": "stale"},
               {"kind": "damage_fraction", "threshold": -1}]},
     "alerts.rule[2].threshold = -1: must be a finite number > 0"),
    ({"rule": [{"kind": "damage_fraction"}]},
     "alerts.rule[0].threshold: missing; rule kind 'damage_fraction' requires it"),
    ({"rule": [{"kind": "fatigue"}]}, "alerts.rule[0].kind = 'fatigue': unknown rule kind"),
    ({"rule": [{"kind": "stale", "severity": "page"}]},
     "alerts.rule[0].severity = 'page': must be one of"),
    ({"rule": [{"kind": "stale", "threshold": 3}]},
     "alerts.rule[0].threshold = 3: unknown key"),
    ({"rule": [{"kind": "rejected_rate", "threshold": 1.5}]},
     "alerts.rule[0].threshold = 1.5: must be a finite number > 0 and <= 1"),
    ({"rule": [{"kind": "damage_rate", "threshold": True}]},
     "alerts.rule[0].threshold = True: must be a finite number > 0"),
    ({"rule": [{"kind": "damage_rate", "threshold": float("nan")}]},
     "alerts.rule[0].threshold = nan: must be a finite number > 0"),
    ({"rule": [{"kind": "damage_rate", "threshold": 1, "on_delay_s": -5}]},
     "alerts.rule[0].on_delay_s = -5: must be a finite number >= 0 and <= 1e+09"),
    ({"rule": [{"kind": "tension_high", "threshold": 0.5, "breaking_strength_N": 45e3,
                "deadband": 0.6}]},
     "alerts.rule[0].deadband = 0.6: must be < threshold (0.5)"),
    ({"rule": [{"kind": "stale", "component": "a/b"}]},
     "alerts.rule[0].component = 'a/b': must be 1-64 letters"),
    ({"rule": [{"kind": "damage_fraction", "threshold": 0.1},
               {"kind": "damage_fraction", "threshold": 0.5}]},
     "alerts.rule[1].name = 'damage_fraction': duplicate of alerts.rule[0]"),
    ({"eval_interval_s": 0}, "alerts.eval_interval_s = 0: must be a finite number > 0 and <= 1e+09"),
    ({"resend_interval_s": "1h"}, "alerts.resend_interval_s = '1h': must be a finite number >= 0"),
    ({"rule": {"kind": "stale"}}, "alerts.rule = {'kind': 'stale'}: must be an array"),
    ({"webhook": {"url": "ftp://x"}}, "alerts.webhook.url = 'ftp://x': must be an http"),
    ({"email": {"host": "h", "from": "a@b", "to": []}}, "alerts.email.to = []: must be"),
    ({"outbox": {"retry_base_s": 10, "retry_max_s": 5}},
     "alerts.outbox.retry_max_s = 5: must be >= retry_base_s (10)"),
    ({"evaluate_s": 3}, "alerts.evaluate_s = 3: unknown key"),
])
def test_config_errors_name_key_and_value(section, message):
    with pytest.raises(ConfigError) as exc:
        AlertsConfig.from_dict(section)
    assert str(exc.value).startswith("config error: " + message), str(exc.value)


def test_engine_errors_for_unknown_components():
    with pytest.raises(ValueError, match="alerts.rule\\[0\\].component = 'mid': unknown "
                                         "component; expected one of \\['core', 'left'"):
        AlertEngine.from_config({"rule": [{"kind": "damage_rate", "threshold": 1,
                                           "component": "mid"}]}, "b1", COMPONENTS)
    with pytest.raises(ValueError, match="alerts.rule\\[0\\].component = 'core': component has "
                                         "no endurance stress"):
        AlertEngine.from_config({"rule": [{"kind": "conductor_stress", "component": "core"}]},
                                "b1", COMPONENTS)
    with pytest.raises(ValueError, match="endurance_stress_Pa = -1"):
        AlertEngine.from_config({}, "b1", {"left": -1})


def test_config_defaults_and_round_trip():
    cfg = AlertsConfig.from_dict(ALL_RULES)
    assert cfg.eval_interval_s == 10.0 and cfg.resend_interval_s == 60.0
    assert cfg.rules[6].params == {"threshold": 15000.0, "floor_N": 2000.0, "window_s": 2.0,
                                   "off_delay_s": 60.0}
    assert AlertsConfig.from_dict(cfg.to_dict()).to_dict() == cfg.to_dict()
    assert AlertsConfig.from_dict(None).rules == ()
