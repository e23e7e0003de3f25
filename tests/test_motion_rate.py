"""The motion estimator's step from the stream's own spacing (monitor.motion_rate, issue 17).

Oracles: ``models.estimator`` run directly at the stream's true step; the replay reports of
the code before the step was measured (fixed ``motion_rate_hz = 10``) for a 10 Hz simulated
log, which must not change by a bit.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import msgspec
import numpy as np
import pytest

from models.estimator import MotionTensionEstimator, seed004_estimator
from monitor.config import ConfigError, config_with, default_config, load_config
from monitor.load_source import build_estimator
from monitor.motion_rate import GAP, STEP, WITHHOLD, MotionRate, rate_problems

S = 1_000_000_000
GAP_NS = 5 * S
REPO = Path(__file__).resolve().parents[1]


def _config(rate: float | str = "auto"):
    c = default_config()
    return dataclasses.replace(c, load=msgspec.structs.replace(c.load, motion_rate_hz=rate))


def _times(steps_s: list[tuple[float, int]], t0_s: float = 100.0) -> np.ndarray:
    """Sample times (ns) of runs of ``n`` intervals of ``step`` s each."""
    d = np.concatenate([np.full(n, round(step * 1e9), np.int64) for step, n in steps_s])
    return np.int64(round(t0_s * 1e9)) + np.concatenate([[0], np.cumsum(d)])


def _plan_all(rate: MotionRate, t: np.ndarray, cuts) -> list[tuple[int, str, float | None]]:
    out = []
    for a, b in zip([0, *cuts], [*cuts, t.shape[0]]):
        out += [(a + i, kind, dt) for i, kind, dt in rate.plan(t[a:b])]
        rate = MotionRate(rate.configured_hz, rate.gap_ns, rate.state())  # checkpointed
    return out


def test_auto_step_is_the_first_two_intervals_rounded_to_the_microsecond():
    # the Spotter's GPS times: 0.4 s with 0.1 us of jitter
    t = np.int64(10**18) + np.cumsum([0, 399_999_857, 400_000_095, 400_000_096, 399_999_857])
    rate = MotionRate(None, GAP_NS)
    assert rate.plan(t[:2]) == []  # one interval: not yet
    assert rate.plan(t[2:]) == [(0, STEP, 0.4)]
    assert rate.figures() == {"setting": "auto", "hz": 2.5, "samples_rate_mismatch": 0,
                              "rate_changes": 0}


def test_decisions_do_not_depend_on_the_block_split():
    """A jittered 10 Hz start, single missing samples (no change), a gap, a change to 2.5 Hz
    then back: the same events for any split, the state saved between blocks."""
    rng = np.random.default_rng(7)
    t = _times([(0.1, 40), (0.2, 1), (0.1, 30), (20.0, 1), (0.1, 30), (0.4, 40), (0.1, 40)])
    t[1:40] += rng.integers(-500_000, 500_000, 39)  # +-0.5 % jitter
    whole = _plan_all(MotionRate(None, GAP_NS), t, [])
    kinds = [(t_i, k) for t_i, k, _ in whole]
    assert whole[0][:2] == (2, STEP) and abs(whole[0][2] - 0.1) <= 0.001  # jittered
    assert (72, GAP) in kinds  # the 20 s silence
    changes = [e for e in whole if e[1] == STEP][1:]
    # the change to 0.4 s (from sample 103) is taken when it holds the median of the last 15
    # intervals (at the 8th 0.4 s interval), and back to 0.1 s (from 143) likewise
    assert [(i, dt) for i, _, dt in changes] == [(110, 0.4), (150, 0.1)]
    for seed in range(20):
        r = np.random.default_rng(seed)
        cuts = sorted(set(r.integers(1, t.shape[0], int(r.integers(1, 30))).tolist()))
        assert _plan_all(MotionRate(None, GAP_NS), t, cuts) == whole


def test_a_configured_rate_the_stream_does_not_keep_is_withheld_and_counted():
    t = _times([(0.1, 50), (0.4, 30), (0.1, 40)])
    rate = MotionRate(10.0, GAP_NS)
    events = rate.plan(t)
    # 0.4 s from sample 51, 0.1 s again from 81: each taken at its 8th interval
    assert [(i, k) for i, k, _ in events] == [(58, WITHHOLD), (88, "resume")]
    assert rate.figures()["samples_rate_mismatch"] == 30
    assert rate_problems(rate.figures()) == [
        "30 motion samples gave no load estimate: their spacing is not [load] motion_rate_hz "
        "= 10 Hz (rate_mismatch; set motion_rate_hz = \"auto\" to take the stream's own)"]


def _accel(n: int, dt: float) -> dict[str, np.ndarray]:
    k = np.arange(n) * dt
    return {"accel_x_mps2": 0.3 * np.sin(2 * np.pi * k / 6.0),
            "accel_y_mps2": 0.1 * np.cos(2 * np.pi * k / 7.0),
            "accel_z_mps2": 0.8 * np.sin(2 * np.pi * k / 5.0)}


@pytest.mark.parametrize("hz", [5.0, 2.5])
def test_an_imu_stream_is_integrated_at_its_own_step(hz):
    """IMU accelerations at 5 or 2.5 Hz: the estimate equals the models' estimator at 1 / hz
    fed directly, to the bit, for a split into blocks with the state saved; the shipped
    10 Hz before "auto" would have integrated them at 0.1 s (4x slower motion at 2.5 Hz)."""
    n = 2000
    dt = 1.0 / hz
    t = _times([(dt, n - 1)])
    f = _accel(n, dt)
    direct = MotionTensionEstimator(*seed004_estimator(dt=dt, span=29.0)).update_accel(
        f["accel_x_mps2"], f["accel_y_mps2"], f["accel_z_mps2"])
    settled = (direct.flags & 16) != 0
    for cuts in ([700], [1, 2, 3], [2, 1500]):  # the state saved, JSON, while samples wait too
        est = build_estimator(_config(), sensor="imu")
        out = []
        for a, b in zip([0, *cuts], [*cuts, n]):
            out.append(est.feed(t[a:b], {k: v[a:b] for k, v in f.items()}))
            est = build_estimator(_config(), json.loads(json.dumps(est.state())), sensor="imu")
        e_t = np.concatenate([o[0] for o in out])
        e_v = np.concatenate([o[1] for o in out])
        assert np.array_equal(e_t, t[~settled]) and np.array_equal(e_v, direct.tension[~settled])
    assert e_t.shape[0] > n // 2
    old = MotionTensionEstimator(*seed004_estimator(dt=0.1, span=29.0)).update_accel(
        f["accel_x_mps2"], f["accel_y_mps2"], f["accel_z_mps2"])
    assert not np.allclose(old.tension[~settled], e_v, rtol=0.01)
    wrong = build_estimator(_config(10.0), sensor="imu")
    assert wrong.feed(t, f)[0].shape[0] == 0
    assert wrong.rate_figures()["samples_rate_mismatch"] == n - 1


def test_a_rate_change_restarts_the_estimator_at_the_new_step():
    """Displacements at 10 Hz then 2.5 Hz ("auto"): from the sample where the change is
    taken on, the estimate is that of a fresh estimator at 0.4 s fed from there."""
    t = _times([(0.1, 99), (0.4, 100)])
    k = np.arange(t.shape[0])
    heave = 0.4 * np.sin(2 * np.pi * (t - t[0]) / 8e9)
    f = {"heave_m": heave, "surge_m": 0.3 * heave, "sway_m": 0.05 * heave}
    est = build_estimator(_config(), sensor="motion")
    e_t, e_v, _ = est.feed(t, f)
    at = 99 + 8  # the 8th 0.4 s interval holds the median of the last 15
    assert est.rate_figures() == {"setting": "auto", "hz": 2.5, "samples_rate_mismatch": 0,
                                  "rate_changes": 1}
    fresh = MotionTensionEstimator(*seed004_estimator(dt=0.4, span=29.0)).update(
        heave[at:], f["surge_m"][at:], f["sway_m"][at:])
    after = e_t >= t[at]
    assert np.array_equal(e_t[after], t[at + 2:]) and np.array_equal(e_v[after], fresh.tension[2:])
    assert k.shape[0] - e_t.shape[0] == 4  # two settle at the start, two at the change
    assert rate_problems(est.rate_figures()) == [
        "the motion stream's sample rate changed 1 times: the estimator restarted on each "
        "(now 2.5 Hz)"]


def test_config_takes_auto_or_a_rate(tmp_path, capsys):
    assert default_config().load.motion_rate_hz == "auto"
    assert config_with(default_config(), load={"motion_rate_hz": 2.5}).load.motion_rate_hz == 2.5
    for bad in ("fast", 0, -1.0, True):
        with pytest.raises(ConfigError, match="motion_rate_hz"):
            config_with(default_config(), load={"motion_rate_hz": bad})
    cfg = tmp_path / "c.toml"
    text = (REPO / "monitor/vaps_seed004.toml").read_text()
    cfg.write_text(text)
    assert load_config(cfg).load.motion_rate_hz == "auto"
    from monitor.cli import main

    assert main(["check-config", str(cfg)]) == 0
    assert ("  motion estimator step: auto (the motion stream's own sample spacing)\n"
            in capsys.readouterr().out)
    cfg.write_text(text.replace('motion_rate_hz = "auto"', "motion_rate_hz = 2.5"))
    assert main(["check-config", str(cfg)]) == 0
    assert ("  motion estimator step: 2.5 Hz (a motion stream spaced otherwise gives no "
            "estimate: rate_mismatch)\n" in capsys.readouterr().out)
    cfg.write_text(text.replace('motion_rate_hz = "auto"', 'motion_rate_hz = "10 Hz"'))
    assert main(["check-config", str(cfg)]) == 2
    assert "load.motion_rate_hz" in capsys.readouterr().err


def _golden(tmp_path: Path, sensor: str) -> dict:
    from monitor.cli import main

    log = tmp_path / "sim.mcap"
    if not log.exists():
        assert main(["simulate", "--hours", "0.25", "--hs", "2", "--tp", "7", "--seed", "3",
                     "--dropouts", "0.002", "-o", str(log)]) == 0
    text = (REPO / "monitor/vaps_seed004.toml").read_text()
    for old, new in (('source = "auto"', 'source = "estimated"'),
                     ('motion_sensor = "auto"', f'motion_sensor = "{sensor}"')):
        assert old in text
        text = text.replace(old, new)
    (tmp_path / f"{sensor}.toml").write_text(text)
    report = tmp_path / f"{sensor}.json"
    assert main(["replay", str(log), "--report", str(report), "--no-progress",
                 "--config", str(tmp_path / f"{sensor}.toml")]) == 0
    return json.loads(report.read_text())


def test_a_10_hz_simulated_log_is_estimated_exactly_as_before(tmp_path, capsys):
    """The 10 Hz IMU and displacement streams of a simulated log (with dropouts), the load
    estimated from each: the figures of the code before "auto" (fixed 10 Hz), to the bit."""
    before = {  # tension max, mean, samples estimated, conductor damage (fixed 0.1 s step)
        "motion": (2357.872629992792, 249.3389384307624, 8998, 1.608166842256141e-47),
        "imu": (2920.7857882468247, 260.3041301953586, 7627, 6.712827592138687e-36)}
    for sensor, figures in before.items():
        r = _golden(tmp_path, sensor)
        capsys.readouterr()
        assert r["motion_rate"] == {"setting": "auto", "hz": 10.0, "samples_rate_mismatch": 0,
                                    "rate_changes": 0}
        t = r["tension_N"]
        assert (t["max"], t["mean"], t["samples_estimated"],
                r["components"]["conductor"]["damage"]) == figures


def test_status_and_metrics_say_the_stream_is_not_at_the_configured_rate():
    """A live pipeline told 10 Hz, fed a 2.5 Hz displacement stream: its status and the
    metrics made from it carry the mismatch, and the status says it in words."""
    from prometheus_client import generate_latest
    from prometheus_client.parser import text_string_to_metric_families

    from monitor.blocks import SampleBlock
    from monitor.metrics import make_registry
    from monitor.pipeline import Pipeline

    config = config_with(default_config(), load={"source": "estimated", "motion_sensor": "motion",
                                                 "motion_rate_hz": 10.0})
    p = Pipeline(config)
    t = _times([(0.4, 299)], t0_s=1.7e9)
    heave = 0.3 * np.sin(np.arange(300) / 3.0)
    for a in range(0, 300, 25):
        p.process(SampleBlock("vaps", "motion", t[a:a + 25], {
            "heave_m": heave[a:a + 25], "surge_m": 0.2 * heave[a:a + 25],
            "sway_m": 0.1 * heave[a:a + 25]}))
    p.flush()
    status = p.status()
    assert status["motion_rate"] == {"setting": 10.0, "hz": 10.0, "samples_rate_mismatch": 299,
                                     "rate_changes": 0}
    assert status["estimated_tension_N"] is None
    assert status["load_problems"][0].startswith("299 motion samples gave no load estimate")
    text = generate_latest(make_registry(lambda: status)).decode()
    got = {(s.name, tuple(sorted(s.labels.items()))): s.value
           for f in text_string_to_metric_families(text) for s in f.samples}
    assert got[("buoymon_motion_rate_hz", (("buoy", "vaps"), ("setting", "10.0")))] == 10.0
    assert got[("buoymon_motion_rate_mismatch_samples_total", (("buoy", "vaps"),))] == 299
    assert got[("buoymon_motion_rate_changes_total", (("buoy", "vaps"),))] == 0


class _SampleBySample(MotionRate):
    """The tracker without its one-pass path for regular blocks: every interval through the
    running median (the oracle of that path)."""

    def _fast_plan(self, t_ns, prev, first):
        return None


@pytest.mark.parametrize("configured", [None, 10.0])
def test_regular_stretches_at_once_give_the_sample_by_sample_events(configured):
    # a jittered start, missing samples, gaps, rate changes and returns, in blocks of any size
    rng = np.random.default_rng(3)
    t = _times([(0.1, 400), (0.2, 1), (0.1, 300), (20.0, 1), (0.1, 30), (0.4, 200), (0.104, 50), (0.1, 500),
                (30.0, 1), (0.4, 100), (0.1, 100)])
    t[1:300] += rng.integers(-500_000, 500_000, 299)
    for seed in range(10):
        r = np.random.default_rng(seed)
        cuts = sorted(set(r.integers(1, t.shape[0], int(r.integers(1, 12))).tolist()))
        fast, slow = MotionRate(configured, GAP_NS), _SampleBySample(configured, GAP_NS)
        for a, b in zip([0, *cuts], [*cuts, t.shape[0]]):
            assert fast.plan(t[a:b]) == slow.plan(t[a:b])
            assert fast.state() == slow.state()
