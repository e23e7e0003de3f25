"""The alert engine's batch path (monitor.alerts.batch: many ticks at once, the replay path)
against its per-tick path (AlertEngine.evaluate on one Observation per tick), on the same
inputs: records, history, every rule's saved state (values, times, windows) identical to the
last bit, through re-sends, acks, operator resets, a latching damage rule released by a cable
replacement, stale and rejected-rate streams, slack snaps, on/off delays and ticks without
data; and a pipeline replaying a log both ways."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math

import numpy as np
import pytest

from models._jit import uncompiled
from monitor.alerts.batch import StreamTicks, TickInputs
from monitor.alerts.engine import AlertEngine
from monitor.events import ComponentObs, Observation, StreamObs

NS = 1_000_000_000
T0 = 1_700_000_000 * NS
TICK = 10 * NS

RULES = {
    "resend_interval_s": 60,
    "rule": [
        {"kind": "damage_fraction", "threshold": 0.02, "name": "damage_warning"},
        {"kind": "damage_fraction", "threshold": 0.05, "name": "damage_critical"},
        {"kind": "damage_rate", "threshold": 0.5, "on_delay_s": 20, "off_delay_s": 30},
        {"kind": "remaining_life", "threshold": 5, "on_delay_s": 10},
        {"kind": "tension_high", "threshold": 0.5, "breaking_strength_N": 45e3,
         "deadband": 0.05, "on_delay_s": 10, "off_delay_s": 20},
        {"kind": "conductor_stress", "threshold": 1.0, "off_delay_s": 20},
        {"kind": "conductor_yield", "threshold": 1.2, "on_delay_s": 10},
        {"kind": "slack_snap", "floor_N": 2000, "threshold": 15000, "window_s": 2,
         "off_delay_s": 30},
        {"kind": "stale", "component": "tension", "on_delay_s": 10},
        {"kind": "stale", "component": "imu"},
        {"kind": "rejected_rate", "component": "tension", "threshold": 0.05, "window_s": 60},
        {"kind": "model_residual", "threshold": 3000, "on_delay_s": 30},
    ],
}
COMPONENTS = {"left": {"endurance_stress_Pa": 15.8e6, "yield_stress_Pa": 18e6},
              "right": {"endurance_stress_Pa": 15.8e6, "yield_stress_Pa": 18e6},
              "core": None}


class Ticks:
    """Random per-tick inputs, as arrays (TickInputs) and as Observations."""

    def __init__(self, n: int, seed: int) -> None:
        rng = np.random.default_rng(seed)
        self.ends = T0 + TICK * np.arange(1, n + 1, dtype=np.int64)
        self.t, self.x, self.cut = [], [], [0]
        for k in range(n):
            m = 0 if rng.random() < 0.05 else int(rng.integers(5, 40))  # some without samples
            tt = np.sort(self.ends[k] - TICK + 1 + rng.choice(TICK - 1, m, replace=False))
            x = 12e3 + rng.normal(0, 4e3 if k % 9 else 9e3, m)
            if rng.random() < 0.1:  # slack, then a snatch load within the window (or not)
                x[: m // 2] = 500.0
                x[m // 2:] = rng.choice([9e3, 30e3])
            self.t.append(tt.astype(np.int64))
            self.x.append(x)
            self.cut.append(self.cut[-1] + m)
        self.tmax = np.array([x.max() if x.size else math.nan for x in self.x])
        self.meas = np.array([x.mean() if x.size else math.nan for x in self.x])
        self.est = self.meas + rng.choice([0.0, 5e3, math.nan], n, p=[0.6, 0.3, 0.1])
        self.comps = {}
        for name in COMPONENTS:
            rate = rng.choice([0.01, 0.8, 2.0, math.nan], n, p=[0.4, 0.3, 0.25, 0.05])
            step = np.where(np.isnan(rate), 0.0, rate) * 10 / 86400 * 8
            committed = np.cumsum(step)
            if name == "left":  # the cable replaced: the accumulator restarts
                committed[n // 2:] -= committed[n // 2 - 1] - 1e-6
            damage = committed + rng.uniform(0, 1e-4, n)
            damage[rng.random(n) < 0.03] = math.nan
            life = (1 - damage) / rate
            smax = np.where(np.isnan(self.tmax), math.nan, rng.uniform(5e6, 25e6, n))
            self.comps[name] = np.column_stack([damage, committed, rate, life, smax])
        self.streams = {}
        for name, p_acc in (("tension", 0.7), ("imu", 0.2)):
            got = rng.random(n) < p_acc
            last = np.where(got, self.ends - rng.integers(0, TICK, n), 0)
            last = np.maximum.accumulate(last)  # the newest accepted sample so far
            received = np.where(rng.random(n) < 0.2, 0, rng.integers(1, 200, n))
            rejected = np.minimum(received, rng.integers(0, 25, n))
            stale = (last == 0) | (self.ends - last > 25 * NS)
            self.streams[name] = StreamTicks(last, stale, received, rejected)

    def inputs(self, a: int, b: int) -> TickInputs:
        def load():
            lo = self.cut[a]
            return (np.concatenate(self.t[a:b]), np.concatenate(self.x[a:b]),
                    np.array(self.cut[a:b], np.int64) - lo, np.array(self.cut[a + 1:b + 1]) - lo)
        return TickInputs(
            buoy_id="b1", ends=self.ends[a:b], tension_max=self.tmax[a:b],
            measured=self.meas[a:b], estimated=self.est[a:b],
            component=lambda name, i: self.comps[name][a:b, i],
            stream=lambda s: StreamTicks(*(x[a:b] for x in (
                self.streams[s].last_t_ns, self.streams[s].stale, self.streams[s].received,
                self.streams[s].rejected))),
            load=load)

    def obs(self, k: int) -> Observation:
        streams = {s: StreamObs(int(h.last_t_ns[k]), bool(h.stale[k]), 0, {},
                                int(h.rejected[k]), int(h.received[k]))
                   for s, h in self.streams.items()}
        return Observation(
            "b1", int(self.ends[k]), 10.0, "measured", self.t[k], self.x[k],
            float(self.meas[k]), float(self.est[k]),
            {n: ComponentObs(*(float(v) for v in c[k])) for n, c in self.comps.items()},
            streams)


def operator(eng: AlertEngine, slab: int) -> None:
    """The same operator actions between slabs: ack one firing alert, reset rules."""
    active = eng.active()
    if slab % 3 == 1 and active:
        rec = active[slab % len(active)]
        eng.ack(rec.fingerprint, "ops", "seen", slab)
    if slab % 4 == 2:
        eng.reset("damage_warning", "right", "ops", "inspected", slab)
        eng.reset("damage_rate", "core", "ops", "quiet or not", slab)


def dump(records: list) -> list[str]:
    return [repr(r.to_dict()) for r in records]


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("plain", [False, True])
def test_batch_equals_per_tick_evaluation(seed: int, plain: bool) -> None:
    n = 400
    ticks = Ticks(n, seed)
    cuts = np.unique(np.concatenate([[0, n], np.random.default_rng(seed).integers(1, n, 12)]))
    ref = AlertEngine.from_config(RULES, "b1", COMPONENTS)
    eng = AlertEngine.from_config(RULES, "b1", COMPONENTS)
    ref_out, out, called = [], [], []
    for slab, (a, b) in enumerate(zip(cuts[:-1].tolist(), cuts[1:].tolist())):
        operator(ref, slab)
        operator(eng, slab)
        for k in range(a, b):
            ref_out += ref.evaluate(ticks.obs(k))
        batch = eng.tick_batch(ticks.inputs(a, b))
        assert batch is not None

        def tick(j: int) -> None:
            called.append(a + j)
            out.extend(eng.evaluate(ticks.obs(a + j)))
        with uncompiled() if plain else contextlib.nullcontext():
            batch.run(tick, out.extend)
        assert dump(out) == dump(ref_out)
        assert json.dumps(eng.state()) == json.dumps(ref.state())
    events = {(r.kind, r.event) for r in ref_out}
    # the paths this covers, and the batch evaluated only some ticks the ordinary way
    assert {("damage_fraction", "fire"), ("damage_fraction", "reset"), ("damage_rate", "fire"),
            ("damage_rate", "clear"), ("tension_high", "fire"), ("tension_high", "clear"),
            ("slack_snap", "fire"), ("slack_snap", "clear"), ("stale", "fire"),
            ("stale", "clear"), ("rejected_rate", "fire"), ("model_residual", "fire"),
            ("conductor_yield", "fire")} <= events, events
    assert sum(r.event == "resend" for r in ref_out) > 5
    assert any(r.acked_by for r in ref_out)
    # the ordinary evaluation ran where transitions came, and otherwise only for the re-arms
    # of quiet rules by the resets (two per reset slab at most); re-sends came without it too
    with_transitions = {int((r.at_ns - T0) // TICK) - 1 for r in ref_out if r.event != "resend"}
    assert with_transitions <= set(called)
    assert len(set(called) - with_transitions) <= 2 * sum(slab % 4 == 2 for slab in range(len(cuts)))
    resent = {int((r.at_ns - T0) // TICK) - 1 for r in ref_out if r.event == "resend"}
    assert len(resent - set(called)) > 10


def test_replacement_on_a_tick_without_damage_releases_at_the_next_with_data() -> None:
    n = 60
    ticks = Ticks(n, 5)
    c = ticks.comps["right"]
    c[:, 1] = np.linspace(0.0, 0.2, n)
    c[:, 0] = c[:, 1]
    c[30:, 1] -= 0.19
    c[30:, 0] -= 0.19
    c[30:33, 0] = math.nan  # the drop seen on ticks whose damage is NaN
    ref = AlertEngine.from_config(RULES, "b1", COMPONENTS)
    eng = AlertEngine.from_config(RULES, "b1", COMPONENTS)
    ref_out = [r for k in range(n) for r in ref.evaluate(ticks.obs(k))]
    out: list = []
    for a, b in ((0, 31), (31, n)):
        eng.tick_batch(ticks.inputs(a, b)).run(
            lambda j, a=a: out.extend(eng.evaluate(ticks.obs(a + j))), out.extend)
    assert dump(out) == dump(ref_out)
    assert json.dumps(eng.state()) == json.dumps(ref.state())
    released = [r for r in ref_out if r.component == "right" and r.event == "reset"]
    assert [r.at_ns for r in released] == [int(ticks.ends[33])] * 2  # both damage rules


def test_an_idle_stream_with_an_empty_window_is_not_asked_for_and_a_full_one_expires() -> None:
    """``TickInputs.receives``: a rejected-rate rule whose window is empty, on a stream
    that receives nothing in the slab's ticks, gets no value without asking ``stream``;
    while its window still holds ticks from the slab before, it is asked and the window
    expires tick by tick (rates until the last entry leaves). Records and state equal the
    per-tick path's."""
    n = 200
    ticks = Ticks(n, 8)
    imu = ticks.streams["imu"]
    imu.received[50:120] = 0  # idle from tick 50 (the window, 60 s, empties by tick 56)
    imu.rejected[50:120] = 0
    imu.received[40:50] = 100
    imu.rejected[40:50] = 30  # a 30 % rate: fires, then the window empties
    rules = {"rule": [{"kind": "rejected_rate", "component": "imu", "threshold": 0.05,
                       "window_s": 60}]}
    ref = AlertEngine.from_config(rules, "b1", COMPONENTS)
    eng = AlertEngine.from_config(rules, "b1", COMPONENTS)
    ref_out = [r for k in range(n) for r in ref.evaluate(ticks.obs(k))]
    out: list = []
    asked: list[tuple[int, str]] = []
    for a, b in ((0, 50), (50, 60), (60, 80), (80, 130), (130, n)):
        x = ticks.inputs(a, b)

        def stream(s: str, a: int = a, x: TickInputs = x) -> StreamTicks:
            asked.append((a, s))
            return x.stream(s)
        x = dataclasses.replace(x, stream=stream,
                                receives=lambda s, a=a, b=b: bool(
                                    ticks.streams[s].received[a:b].any()))
        eng.tick_batch(x).run(lambda j, a=a: out.extend(eng.evaluate(ticks.obs(a + j))),
                              out.extend)
    assert dump(out) == dump(ref_out)
    assert json.dumps(eng.state()) == json.dumps(ref.state())
    assert (50, "imu") in asked and (60, "imu") not in asked  # expiring, then idle and empty
    assert [r.event for r in ref_out if r.event != "resend"][:2] == ["fire", "clear"]
    assert ref._rules[0].received > 0  # active again at the end


def test_forecast_due_ticks_are_evaluated_the_ordinary_way() -> None:
    ticks = Ticks(50, 6)
    eng = AlertEngine.from_config({"rule": []}, "b1", COMPONENTS)
    seen: list[int] = []
    due = [int(ticks.ends[17]) - 3, int(ticks.ends[40])]
    batch = eng.tick_batch(ticks.inputs(0, 50))
    quiet: list[tuple[int, int]] = []

    def tick(j: int) -> None:
        seen.append(j)
        eng.evaluate(ticks.obs(j))
        due.pop(0)
    batch.run(tick, pytest.fail, lambda a, b: quiet.append((a, b)), lambda: due[0] if due else None)
    assert seen == [17, 40]
    assert quiet == [(0, 17), (18, 40), (41, 50)]
    assert eng.last_t_ns == int(ticks.ends[-1])


class _TickHook:
    """A sink with a per-tick hook: the pipeline then evaluates tick by tick."""

    def on_step(self, step) -> None:
        pass

    def on_observation(self, obs) -> None:
        pass

    def close(self) -> None:
        pass


def _pipeline_run(block_s: int, hooked: bool, monkeypatch) -> tuple[str, str, list, int]:
    """Report, state, alert history and the number of ticks evaluated the ordinary way."""
    from monitor import pipeline as pipeline_mod
    from monitor.config import config_with, default_config
    from monitor.pipeline import Pipeline
    from synthetic_buoy import blocks_interleaved, sea
    from test_pipeline import FakeEstimator

    # every slab through the batch when not hooked, even of one tick
    monkeypatch.setattr(pipeline_mod, "BATCH_MIN_TICKS", 1)
    monkeypatch.setattr(pipeline_mod, "build_estimator",
                        lambda config, state=None, sensor=None: FakeEstimator())
    config = config_with(default_config(), alerts={"resend_interval_s": 60, "rule": [
        {"kind": "damage_fraction", "threshold": 1e-12},
        {"kind": "tension_high", "threshold": 0.15, "breaking_strength_N": 45e3,
         "deadband": 0.01, "on_delay_s": 10, "off_delay_s": 20},
        {"kind": "conductor_stress", "threshold": 0.1, "off_delay_s": 30},
        {"kind": "slack_snap", "floor_N": 2700, "threshold": 4000, "window_s": 3},
        {"kind": "stale", "component": "tension"},
        {"kind": "stale", "component": "waves", "name": "waves_stale"},  # never seen
        {"kind": "rejected_rate", "component": "tension", "threshold": 0.002, "window_s": 60},
        {"kind": "model_residual", "threshold": 300, "on_delay_s": 20},
    ]})
    blocks = blocks_interleaved(sea(900, gap=(300, 360)), block_s)
    # live ordering: slabs of a tick or two with 1-s blocks, many ticks with 97-s blocks
    p = Pipeline(config, [_TickHook()] if hooked else [], horizon_s=2.0)
    ordinary = []
    evaluate = p._evaluate
    monkeypatch.setattr(p, "_evaluate", lambda *a: ordinary.append(1) or evaluate(*a))
    mid = len(blocks) // 2 if block_s == 1 else 4
    for i, b in enumerate(blocks):
        if i == mid:  # operator actions mid-stream
            for rec in p.alerts.active()[:1]:
                p.alerts.ack(rec.fingerprint, "ops", "seen", 1)
            p.alerts.reset("damage_fraction", "conductor", "ops", "inspected", 2)
        p.process(b)
    p.flush()
    return (json.dumps(p.report(), sort_keys=True), json.dumps(p.state(), sort_keys=True),
            p.alert_history, len(ordinary))


@pytest.mark.parametrize("block_s", [1, 97])
def test_pipeline_replays_the_same_with_and_without_a_tick_hook(block_s, monkeypatch) -> None:
    report, state, history, ordinary = _pipeline_run(block_s, False, monkeypatch)
    assert (report, state) == _pipeline_run(block_s, True, monkeypatch)[:2]
    # the batch evaluated the ordinary way only ticks with a transition (or a re-arm)
    assert ordinary <= sum(a["event"] != "resend" for a in history)
    events = {(a["kind"], a["event"]) for a in history}
    assert {("damage_fraction", "fire"), ("damage_fraction", "reset"), ("tension_high", "fire"),
            ("slack_snap", "fire"), ("stale", "fire"),
            ("stale", "clear"), ("rejected_rate", "fire"), ("conductor_stress", "resend"),
            } <= events, events
    assert any(a["acked_by"] == "ops" for a in history)
    assert any(a["rule"] == "waves_stale" and a["event"] == "fire" for a in history)


@pytest.mark.parametrize("plain", [False, True])
def test_batch_equals_per_tick_at_the_levels_and_when_a_latched_condition_lapses(plain) -> None:
    """The scan's quiet ticks alone (the random feed's events stop it at nearly every tick,
    where the ordinary path corrects it): a peak tension exactly at the on level (not above:
    no alert), above it or, while firing, below the off level for one tick (a pending or
    clearing period that lapses), exactly at the off level (the deadband holds it), a damage
    rate and a remaining life exactly at their thresholds, and a latched damage alert whose
    condition stops holding (nothing moves, not even a clearing time: a latching rule only
    clears by reset or replacement). Slabs end just after such ticks, so a pending or
    clearing time the scan set wrongly would be in the state; each of those mutations of
    scan_ticks fails this test."""
    n = 120
    ticks = Ticks(n, 7)
    on, off = 0.5 * 45e3, 0.45 * 45e3
    peaks = np.full(n, 15e3)
    peaks[5] = on + 1.0  # above for one tick, shorter than the on-delay: pending, then not
    peaks[10:14] = on  # at the on level: not above it
    peaks[20:26] = on + 1.0  # fires after the 10-s on-delay
    peaks[26:40] = off  # at the off level while firing: still holds
    peaks[33] = off - 1.0  # below for one tick, shorter than the off-delay: clearing, then not
    peaks[40:45] = off - 1.0  # clears after the 20-s off-delay
    for k in range(3, 50):  # samples in every tick around the peaks
        if not ticks.t[k].size:
            ticks.t[k] = ticks.ends[k:k + 1] - 1
    ticks.cut = [0, *np.cumsum([t.size for t in ticks.t]).tolist()]
    for k in range(n):
        if ticks.t[k].size:
            ticks.x[k] = np.full(ticks.t[k].size, peaks[k])
            ticks.tmax[k], ticks.meas[k] = peaks[k], peaks[k]
    ticks.est = ticks.meas.copy()
    c = ticks.comps["left"]
    c[:, 1] = np.linspace(0.0, 0.03, n)  # committed: no replacement
    c[:, 0] = c[:, 1]
    c[95:110, 0] = 0.019  # below damage_warning's 0.02 after it fired at tick 80 (latched)
    c[:, 2] = np.where(np.arange(n) % 3 == 0, 0.5, 0.1)  # damage rate exactly 0.5: not above
    c[:, 3] = np.where(np.arange(n) % 4 == 1, 5.0, 50.0)  # remaining life exactly 5: not below
    # only these rules, without re-sends: no other rule's events stop the scan, so its quiet
    # ticks alone decide the pending and clearing times between the ticks of records
    rules = {"rule": [{**r, "component": "left"} for r in RULES["rule"][:1] + [
        r for r in RULES["rule"] if r["kind"] in ("remaining_life", "damage_rate")]]
        + [r for r in RULES["rule"] if r["kind"] == "tension_high"]}
    ref = AlertEngine.from_config(rules, "b1", COMPONENTS)
    eng = AlertEngine.from_config(rules, "b1", COMPONENTS)
    ref_out: list = []
    out: list = []
    for a, b in ((0, 11), (11, 28), (28, 81), (81, 98), (98, n)):
        ref_out += [r for k in range(a, b) for r in ref.evaluate(ticks.obs(k))]
        batch = eng.tick_batch(ticks.inputs(a, b))
        assert batch is not None
        with uncompiled() if plain else contextlib.nullcontext():
            batch.run(lambda j, a=a: out.extend(eng.evaluate(ticks.obs(a + j))), out.extend)
        assert json.dumps(eng.state()) == json.dumps(ref.state()), (a, b)
    assert dump(out) == dump(ref_out)
    high = [(r.event, int((r.at_ns - T0) // TICK) - 1) for r in ref_out
            if r.kind == "tension_high" and r.event != "resend"]
    assert high == [("fire", 21), ("clear", 42)]
    assert not [r for r in ref_out if r.kind in ("damage_rate", "remaining_life")
                and r.component == "left"]
    warning = [(r.event, int((r.at_ns - T0) // TICK) - 1) for r in ref_out
               if r.rule == "damage_warning" and r.component == "left"]
    assert warning == [("fire", 80)]


@pytest.mark.parametrize("plain", [False, True])
def test_rejected_rate_through_silences_longer_than_its_window(plain) -> None:
    """A stream whose samples stop for longer than the 60-s window: the window empties and
    the rule has no value (not a zero rate), so nothing moves. Quiet (1 % rejected), then
    silent (its value stays 1 %); 20 % rejected for two ticks (a pending period starts: the
    on-delay is 120 s), silent for 80 s (still pending once the window is empty), 20 % again
    (fires 120 s after the period began), silent (still firing, re-sent every 30 s), clean
    (clears at once: the window holds no rejections). Slabs end inside the silences, so the window, value and pending time
    the batch leaves in the rule are in the compared state; one lies in a silence with the
    window already empty."""
    n = 60
    ticks = Ticks(n, 8)
    s = ticks.streams["tension"]
    s.received[:] = 100
    s.rejected[:] = 20
    s.rejected[:10] = 1
    s.rejected[45:] = 0
    for a, b in ((10, 20), (22, 30), (31, 45)):
        s.received[a:b] = 0
        s.rejected[a:b] = 0
    rules = {"resend_interval_s": 30, "rule": [
        {"kind": "rejected_rate", "component": "tension", "threshold": 0.05, "window_s": 60,
         "on_delay_s": 120}]}
    ref = AlertEngine.from_config(rules, "b1", COMPONENTS)
    eng = AlertEngine.from_config(rules, "b1", COMPONENTS)
    ref_out: list = []
    out: list = []
    for a, b in ((0, 17), (17, 19), (19, 29), (29, n)):  # 17..18: idle, the window empty
        ref_out += [r for k in range(a, b) for r in ref.evaluate(ticks.obs(k))]
        batch = eng.tick_batch(ticks.inputs(a, b))
        with uncompiled() if plain else contextlib.nullcontext():
            batch.run(lambda j, a=a: out.extend(eng.evaluate(ticks.obs(a + j))), out.extend)
        assert json.dumps(eng.state()) == json.dumps(ref.state()), (a, b)
    assert dump(out) == dump(ref_out)
    assert [(r.event, int((r.at_ns - T0) // TICK) - 1) for r in ref_out] == [
        ("fire", 32), ("resend", 35), ("resend", 38), ("resend", 41), ("resend", 44),
        ("clear", 45)]
