"""Alert-engine cost per tick on quiet data (nothing changes), the replay's common case.

Prints microseconds per tick, per rule instance per tick, and the time for the ~260 k ticks
of a 30-day log at a 10 s evaluation interval.

    PYTHONPATH=. python bench/alerts_engine.py
"""

from __future__ import annotations

import time

import numpy as np

from monitor.alerts.engine import AlertEngine
from monitor.events import ComponentObs, Observation, StreamObs

NS = 1_000_000_000
T0 = 1_700_000_000 * NS
RULES = {"resend_interval_s": 3600, "rule": [
    {"kind": "damage_fraction", "threshold": 0.1, "name": "damage_warning"},
    {"kind": "damage_fraction", "threshold": 0.5, "name": "damage_critical",
     "severity": "critical"},
    {"kind": "damage_rate", "threshold": 0.01, "on_delay_s": 60, "off_delay_s": 600},
    {"kind": "remaining_life", "threshold": 30},
    {"kind": "tension_high", "threshold": 0.5, "breaking_strength_N": 45e3, "deadband": 0.05},
    {"kind": "conductor_stress"},
    {"kind": "slack_snap", "floor_N": 500, "threshold": 10e3},
    {"kind": "stale", "on_delay_s": 30},
    {"kind": "rejected_rate", "threshold": 0.05},
    {"kind": "model_residual", "threshold": 5e3},
]}


def main(n_ticks: int = 50_000, samples_per_tick: int = 200) -> None:
    rng = np.random.default_rng(1)
    eng = AlertEngine.from_config(RULES, "b1", {"left": 15.8e6, "right": 15.8e6, "core": None})
    n_rules = len(eng.rule_keys())
    base = np.arange(1, samples_per_tick + 1, dtype=np.int64) * (10 * NS // samples_per_tick)
    x = 12e3 + rng.normal(0, 2e3, samples_per_tick)
    comps = {n: ComponentObs(1e-4, 1e-4, 1e-4, 1e4, 8e6) for n in ("left", "right", "core")}
    obs = []
    for k in range(1, n_ticks + 1):
        t = T0 + k * 10 * NS
        streams = {s: StreamObs(t - NS, False, 200 * k, {}, 0, 200)
                   for s in ("tension", "motion", "imu")}
        obs.append(Observation("b1", t, 10.0, "measured", t - 10 * NS + base, x, 12e3, 11e3,
                               comps, streams))
    t0 = time.perf_counter()
    emitted = sum(len(eng.evaluate(o)) for o in obs)
    dt = time.perf_counter() - t0
    per_tick = dt / n_ticks * 1e6
    print(f"rule instances: {n_rules}; ticks: {n_ticks}; records emitted: {emitted}")
    print(f"evaluate: {per_tick:.1f} us/tick, {per_tick / n_rules:.2f} us per rule instance "
          f"per tick; 30 days at 10 s (259200 ticks): {per_tick * 259200 / 1e6:.1f} s")


if __name__ == "__main__":
    main()
