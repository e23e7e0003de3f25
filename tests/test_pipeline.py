"""The pipeline core: damage against a hand computation, determinism for any block split and
interleaving, state round trips, duplicates, load-source failover and recovery."""

import json
import math

import numpy as np
import pytest
import rainflow

from models import fatigue, helix
from monitor import pipeline as pipeline_mod
from monitor.blocks import SampleBlock
from monitor.config import config_with, default_config
from monitor.pipeline import Pipeline
from synthetic_buoy import S, T0, blocks_interleaved, sea


class FakeEstimator:
    """Stateless stand-in for models.estimator: tension from vertical acceleration."""

    def feed(self, t_ns, fields, want=None):
        v = 5000.0 + 400.0 * fields["accel_z_mps2"]
        # as the real estimator: unwanted samples are NaN (the pipeline must never use them)
        return (t_ns, v if want is None else np.where(want, v, np.nan),
                np.zeros(t_ns.shape, bool))

    def state(self):
        return {}

    def rate_figures(self):
        return {"setting": "auto", "hz": 10.0, "samples_rate_mismatch": 0, "rate_changes": 0}


class RecordingEngine:
    """Alert engine stand-in that records every Observation it is given."""

    def __init__(self):
        self.seen = []

    def evaluate(self, obs):
        def num(x):
            return None if math.isnan(x) else x

        self.seen.append((
            obs.t_ns, obs.load_source, obs.load_t_ns.tolist(), obs.tension_N.tolist(),
            num(obs.measured_tension_N), num(obs.estimated_tension_N),
            {n: (c.damage, c.damage_committed, num(c.max_stress_Pa))
             for n, c in obs.components.items()},
            {s: (o.last_t_ns, o.stale, o.accepted, dict(o.rejected), o.rejected_in_tick,
                 o.received_in_tick) for s, o in obs.streams.items()},
        ))
        return [{"t_ns": obs.t_ns}] if len(self.seen) % 50 == 0 else []

    def state(self):
        return {"n": len(self.seen)}


@pytest.fixture
def hooks(monkeypatch):
    engines = []

    def engine(config, buoy_id, endurance, state, yield_Pa=None):
        e = RecordingEngine()
        engines.append(e)
        return e

    monkeypatch.setattr(pipeline_mod, "build_alert_engine", engine)
    monkeypatch.setattr(pipeline_mod, "build_estimator", lambda config, state=None, sensor=None: FakeEstimator())
    return engines


def two_components():
    c = default_config()
    return config_with(c, component=[
        c.raw["component"][0],
        {**c.raw["component"][0], "name": "right", "lay": "right"},
        {"name": "core", "kind": "axial", "area_m2": 42.1e-6, "sn_curve": "vaps_copper"},
    ])


def run(config, blocks, state=None, live=False):
    if live:
        p = Pipeline(config, state=state)
    else:
        p = Pipeline(config, state=state, horizon_s=config.ordering.replay_horizon_s, gate_all=True)
    steps = [p.process(b) for b in blocks]
    steps.append(p.flush())
    return p, steps


def test_damage_equals_hand_computation_with_astm_rainflow():
    config = default_config()
    data = sea(600)
    t, v = data["tension"]
    p, _ = run(config, [SampleBlock("vaps", "tension", t, v)])
    # hand computation: drop what validation must reject, helix stress, ASTM rainflow, S-N curve
    x = v["tension_N"]
    good = np.isfinite(x) & (x < 20_000)
    stress = helix.conductor_stress(x[good], helix.HelixCable.vaps_biw(), lay="left")
    cycles = np.array([(r, m, c) for r, m, c, _, _ in rainflow.extract_cycles(stress)])
    sn = fatigue.SNCurve.vaps_copper()
    expected = float(np.sum(sn.damage_per_cycle(cycles[:, 0], cycles[:, 1], cycles[:, 2])))
    rep = p.report()
    assert rep["samples"]["tension"]["accepted"] == int(good.sum())
    assert rep["samples"]["tension"]["rejected"]["nan"] == int(np.isnan(x).sum())
    assert rep["samples"]["tension"]["rejected"]["spike"] == int((~good).sum() - np.isnan(x).sum())
    fig = rep["components"]["conductor"]
    assert fig["damage"] == pytest.approx(expected, rel=1e-12)
    assert 0.5 * expected < fig["damage_committed"] < fig["damage"]
    assert fig["max_stress_Pa"] == pytest.approx(stress.max(), rel=1e-15)
    assert rep["tension_N"]["max"] == x[good].max() and rep["tension_N"]["min"] == x[good].min()
    assert rep["tension_N"]["mean"] == pytest.approx(x[good].mean(), abs=1e-3)
    assert rep["tension_N"]["p99"] == pytest.approx(np.percentile(x[good], 99), abs=5.0)


def test_axial_component_is_tension_over_area(hooks):
    p, _ = run(two_components(), blocks_interleaved(sea(120), 1))
    rep = p.report()
    assert rep["components"]["core"]["max_stress_Pa"] == pytest.approx(
        rep["tension_N"]["max"] / 42.1e-6, rel=1e-15)
    # the seed's conclusion: the same load hurts the left-lay conductors more
    assert rep["components"]["conductor"]["damage"] > 2 * rep["components"]["right"]["damage"]


@pytest.mark.slow
def test_same_samples_same_results_for_any_blocking(hooks):
    config = two_components()
    data = sea(900, gap=(300, 340))
    runs = []
    for blocks, live in ((blocks_interleaved(data, 1), False), (blocks_interleaved(data, 97), False),
                         (blocks_interleaved(data, 1000), False), (blocks_interleaved(data, 1), True)):
        p, _ = run(config, blocks, live=live)
        runs.append((p.report(), hooks[-1].seen))
    (ref_report, ref_obs), *others = runs
    assert len(ref_obs) == 90  # every 10 s tick of the 900 s evaluated exactly once
    assert {o[1] for o in ref_obs} == {"measured", "estimated"}  # the gap is in there
    for report, obs in others[:2]:
        assert obs == ref_obs
        assert report == ref_report
    # live ordering: identical, except that gnss (not a load stream) does not hold back the
    # first tick, so its first sample arrives after that tick and counts as late
    live_report, live_obs = others[2]
    assert live_report["samples"]["gnss"]["rejected"]["time_backwards"] == 1
    del live_report["samples"]["gnss"], ref_report["samples"]["gnss"]
    assert live_report == ref_report
    assert [o[:7] for o in live_obs] == [o[:7] for o in ref_obs]
    strip = [{k: v for k, v in o[7].items() if k != "gnss"} for o in live_obs]
    assert strip == [{k: v for k, v in o[7].items() if k != "gnss"} for o in ref_obs]
    assert [o[7]["gnss"][:2] for o in live_obs[1:]] == [o[7]["gnss"][:2] for o in ref_obs[1:]]


@pytest.mark.slow
def test_state_round_trip_mid_stream_is_bit_identical_and_redelivery_is_skipped(hooks):
    config = two_components()
    blocks = blocks_interleaved(sea(600, gap=(200, 260)), 1)
    full, _ = run(config, blocks)
    ref_obs = hooks[-1].seen
    first = Pipeline(config, horizon_s=3600, gate_all=True)
    cut = len(blocks) // 2
    for b in blocks[:cut]:
        first.process(b)
    state = json.loads(json.dumps(first.state()))
    head_obs = hooks[-1].seen
    # restart: the last 30 blocks before the cut are delivered again
    second, _ = run(config, blocks[cut - 30:], state=state)
    got = head_obs + hooks[-1].seen
    assert [o[:7] for o in got] == [o[:7] for o in ref_obs]
    # stream health matches too, except that the re-delivered samples are counted as rejected
    assert [{s: h[:3] for s, h in o[7].items()} for o in got] == \
           [{s: h[:3] for s, h in o[7].items()} for o in ref_obs]
    a, b = full.report(), second.report()
    for name in a["components"]:
        assert b["components"][name]["damage_committed"] == a["components"][name]["damage_committed"]
        assert b["components"][name]["damage"] == a["components"][name]["damage"]
    redelivered = sum(len(x) for x in blocks[cut - 30:cut])
    dups = sum(b["samples"][s]["rejected"]["duplicate"] - a["samples"][s]["rejected"]["duplicate"]
               + b["samples"][s]["rejected"]["time_backwards"]
               - a["samples"][s]["rejected"]["time_backwards"] for s in a["samples"])
    assert dups == redelivered


def test_failover_to_the_estimate_and_back(hooks):
    config = two_components()
    data = sea(300, gap=(100, 200))
    p = Pipeline(config, horizon_s=10)
    series, sources = [], {}
    for b in blocks_interleaved(data, 1):
        step = p.process(b)
        series.append((step.t_ns, step.tension_N))
        sources[(step.now_ns - T0) // S] = step.load_source
    step = p.flush()
    series.append((step.t_ns, step.tension_N))
    t = np.concatenate([s[0] for s in series])
    assert np.all(np.diff(t) > 0)  # one load series in time order, no time counted twice
    rel = (t - T0) / S
    imu_t, imu = data["imu"]
    est = (rel > 100) & (rel < 200)
    # tension's last sample before the gap is at 99.95 s: the estimate takes over once it is
    # more than stale_after_s = 5 s old, i.e. from 105.0 s, until the cell is back at 200 s
    in_gap = rel[est]
    assert in_gap[0] == pytest.approx(105.0) and in_gap[-1] == pytest.approx(199.9)
    assert in_gap.shape[0] == 950
    tension = np.concatenate([s[1] for s in series])
    expected = 5000.0 + 400.0 * imu["accel_z_mps2"][(imu_t >= T0 + 105 * S) & (imu_t < T0 + 200 * S)]
    np.testing.assert_array_equal(tension[est], expected)
    assert sources[95] == "measured" and sources[103] == "measured"  # not stale yet
    assert sources[150] == "estimated" and sources[250] == "measured"
    rep = p.report()
    assert rep["tension_N"]["samples_estimated"] == 950
    status = p.status()
    assert status["load_source"] == "measured" and not status["streams"]["tension"]["stale"]
    json.dumps(status, allow_nan=False)
    stale = [o for o in hooks[-1].seen if o[0] == T0 + 150 * S][0]
    assert stale[1] == "estimated" and stale[7]["tension"][1] is True


def test_reordered_blocks_within_the_horizon_and_late_blocks(hooks):
    config = default_config()
    blocks = blocks_interleaved(sea(200), 1)
    ref, _ = run(config, blocks)
    swapped = list(blocks)
    for i in range(0, len(swapped) - 1, 7):
        swapped[i], swapped[i + 1] = swapped[i + 1], swapped[i]
    p, _ = run(config, swapped)
    assert p.report() == ref.report()
    # a tension block held back far beyond the 10 s live horizon arrives too late
    late = [b for b in blocks if b.sensor == "tension"][20]
    rest = [b for b in blocks if b is not late]
    p = Pipeline(config, horizon_s=10)
    for b in rest:
        p.process(b)
    p.process(late)
    p.flush()
    assert p.report()["samples"]["tension"]["rejected"]["time_backwards"] == len(late)


def test_state_with_buffered_bad_samples_is_strict_json():
    config = default_config()
    blocks = blocks_interleaved(sea(120), 1)
    live = Pipeline(config)
    cut = next(i for i, b in enumerate(blocks) if i > 200 and b.sensor == "tension")
    for b in blocks[:cut]:
        live.process(b)
    bad = blocks[cut]
    values = bad.fields["tension_N"].copy()
    values[3], values[5] = np.nan, np.inf
    live.process(SampleBlock("vaps", "tension", bad.t_ns, {"tension_N": values}))
    state = live.state()
    assert state["reorder"]["pending"]["tension"][1].count(None) == 2  # still buffered
    restored = Pipeline(config, state=json.loads(json.dumps(state, allow_nan=False)))
    for p in (live, restored):
        for b in blocks[cut + 1:]:
            p.process(b)
        p.flush()
    assert restored.report() == live.report()
    assert live.report()["samples"]["tension"]["rejected"]["nan"] >= 2


def test_state_is_strict_json_and_blocks_of_another_buoy_are_refused():
    config = default_config()
    p, _ = run(config, blocks_interleaved(sea(60), 1))
    restored = Pipeline(config, state=json.loads(json.dumps(p.state(), allow_nan=False)))
    assert restored.report() == p.report()
    t = np.array([T0], dtype=np.int64)
    with pytest.raises(ValueError, match="block of buoy 'other'"):
        p.process(SampleBlock("other", "tension", t, {"tension_N": np.array([1.0])}))
    with pytest.raises(ValueError, match="state version"):
        Pipeline(config, state={"version": 99})


def test_models_estimator_adapter_is_split_invariant_and_restorable():
    from monitor.load_source import build_estimator

    config = default_config()
    t, imu = sea(300)["imu"]
    ref_t, ref_v, clamped = build_estimator(config).feed(t, imu)
    assert clamped.shape == ref_t.shape and not clamped.any()  # a 1.5 m sea stays in range
    # the IMU integrator settles for a while; after that every sample has an estimate
    assert 0.4 * t.shape[0] < ref_t.shape[0] < t.shape[0] and np.all(ref_t == t[-ref_t.shape[0]:])
    assert np.all(np.isfinite(ref_v)) and np.all(ref_v >= 0)
    est, parts = build_estimator(config), []
    for a in range(0, t.shape[0], 7):
        if a == 1995:  # a restart from saved state half-way
            est = build_estimator(config, json.loads(json.dumps(est.state())))
        parts.append(est.feed(t[a:a + 7], {k: v[a:a + 7] for k, v in imu.items()}))
    np.testing.assert_array_equal(np.concatenate([p[0] for p in parts]), ref_t)
    np.testing.assert_allclose(np.concatenate([p[1] for p in parts]), ref_v, rtol=1e-9)
    np.testing.assert_array_equal(np.concatenate([p[2] for p in parts]), clamped)


def test_estimator_for_a_line_given_as_segments():
    from monitor.load_source import build_estimator

    c = default_config()
    chain = {"name": "chain", "length_m": 60.0, "weight_N_per_m": 300.0, "ea_N": 5e8,
             "diameter_m": 0.05}
    config = config_with(c, mooring={"segment": [chain], "depth_m": 23.0, "span_m": 50.0})
    t, imu = sea(300)["imu"]
    est_t, est_v, _ = build_estimator(config).feed(t, imu)
    assert est_t.shape[0] > 0.4 * t.shape[0]
    # a 60 m chain of 300 N/m hanging 23 m: the top tension is at least its suspended weight
    assert np.all(est_v > 300.0 * 23.0)


class HookSink:
    """A sink with the optional hooks: raw blocks and per-tick observations."""

    def __init__(self):
        self.blocks, self.ticks, self.steps = [], [], 0

    def on_step(self, step):
        self.steps += 1

    def on_block(self, block):
        self.blocks.append((block.sensor, len(block)))

    def on_observation(self, obs):
        self.ticks.append(obs.t_ns)

    def close(self):
        pass


@pytest.mark.parametrize("live", [False, True])
def test_core_feeds_block_and_tick_hooks_the_same_live_and_replay(live):
    # no alert rules: the tick hooks alone make the core evaluate the tick grid
    config = config_with(default_config(), alerts={"eval_interval_s": 10.0})
    blocks = blocks_interleaved(sea(60), 1)
    sink = HookSink()
    p = Pipeline(config, [sink]) if live else Pipeline(
        config, [sink], horizon_s=config.ordering.replay_horizon_s, gate_all=True)
    for b in blocks:
        p.process(b)
    p.flush()
    assert sink.blocks == [(b.sensor, len(b)) for b in blocks]
    # samples from T0 to T0 + 60 s: ticks (t - 10 s, t] end at T0 (holding the first sample),
    # T0 + 10 s ... T0 + 50 s; the trailing partial tick is not evaluated, so that a split
    # replay equals one pass
    assert sink.ticks == [T0 + k * 10 * S for k in range(6)]


def test_model_residual_rule_sees_the_estimate_while_the_load_cell_is_healthy(monkeypatch):
    # a load cell reading 2 kN high for 5 minutes: the model-residual rule compares the tick
    # means of the measured tension and of the motion estimate over every motion sample
    # (the estimate does not feed fatigue then), fires after its delay and clears
    monkeypatch.setattr(pipeline_mod, "build_estimator", lambda config, state=None, sensor=None: FakeEstimator())
    config = config_with(default_config(), alerts={"rule": [
        {"kind": "model_residual", "threshold": 1000.0, "on_delay_s": 30.0}]})
    data = sea(900)
    x = (data["tension"][0] - T0) / S
    bias = np.where((x >= 300) & (x < 600), 2000.0, 0.0)
    swell = 5000.0 + 800.0 * np.sin(2 * np.pi * x / 5.25 + 0.3)  # what FakeEstimator sees
    data["tension"] = (data["tension"][0], {"tension_N": swell + bias})
    p, steps = run(config, blocks_interleaved(data, 1), live=True)
    events = [(a["event"], (a["at_ns"] - T0) / S) for a in p.report()["alerts"]]
    assert [e for e, _ in events] == ["fire", "clear"]
    assert 330 <= events[0][1] <= 350 and 600 <= events[1][1] <= 620
    assert p.report()["tension_N"]["samples_estimated"] == 0  # fatigue saw the load cell only
    fired = p.report()["alerts"][0]
    assert fired["value"] == pytest.approx(2000.0, abs=100.0)
    # the same tick means calibrate the band of estimated damage: 30 of the ticks read
    # -2000 / ~7000 N (the estimate 2 kN under the biased cell), the others 0, so the RMS
    # relative residual is 2/7 sqrt(30 / ticks), within the swell's +-130 N on a tick mean
    split = p.report()["components"]["conductor"]["damage_by_source"]
    assert split["estimate_error_from"] == "residual" and 85 <= split["calibration_ticks"] <= 90
    assert split["estimate_relative_error"] == pytest.approx(
        2 / 7 * math.sqrt(30 / split["calibration_ticks"]), rel=0.01)


def test_alert_history_keeps_the_newest_and_counts_the_dropped(hooks, monkeypatch):
    import monitor.pipeline as pipeline_mod

    monkeypatch.setattr(pipeline_mod, "ALERT_HISTORY_LIMIT", 3)
    p, _ = run(default_config(), blocks_interleaved(sea(2600), 10))
    records = len(hooks[-1].seen) // 50  # the stand-in engine raises one every 50 ticks
    rep = p.report()
    assert records == 5 and len(rep["alerts"]) == 3 and rep["alerts_dropped"] == 2
    assert [a["t_ns"] for a in rep["alerts"]] == [hooks[-1].seen[k * 50 - 1][0] for k in (3, 4, 5)]
    again = Pipeline(default_config(), state=json.loads(json.dumps(p.state())))
    assert again.report()["alerts_dropped"] == 2


def _motion_only(data):
    """The sea's IMU blocks re-labelled as a displacement stream (values are small)."""
    t, imu = data["imu"]
    return [SampleBlock("vaps", "motion", t[k:k + 10], {
        "heave_m": imu["accel_z_mps2"][k:k + 10] * 0.1, "surge_m": imu["accel_x_mps2"][k:k + 10] * 0.1,
        "sway_m": imu["accel_y_mps2"][k:k + 10] * 0.1}) for k in range(0, t.shape[0], 10)]


def test_status_and_report_say_in_words_when_no_load_can_be_formed():
    blocks = _motion_only(sea(60))
    imu = config_with(default_config(), load={"source": "auto", "motion_sensor": "imu"})
    p, _ = run(imu, blocks)
    problems = p.status()["load_problems"]
    assert problems == [
        "no tension samples (no load cell)",
        "[load] motion_sensor = 'imu' but no imu samples arrived (the buoy sends motion: set "
        "motion_sensor = \"auto\")",
        "no load could be formed: fatigue damage is not being computed"]
    assert p.report()["load_problems"] == problems and p.report()["motion_sensor"] == "imu"
    # auto takes the displacement stream: a load is formed, only the missing cell is said
    p, _ = run(default_config(), blocks)
    assert p.motion_sensor == "motion" and p.report()["tension_N"]["samples_estimated"] > 0
    assert p.status()["load_problems"] == [
        "no tension samples (no load cell): the load is the motion estimate"]


def test_status_carries_qc_counts_and_the_damage_split_by_source():
    p, _ = run(default_config(), blocks_interleaved(sea(600, gap=(200, 300)), 7))
    st = p.status()
    assert set(st["streams"]["tension"]["qc"]) == {"gross_range", "spike", "rate_of_change",
                                                   "flat_line"}
    assert set(st["streams"]["gnss"]["qc"]["location"]) == {"suspect", "fail"}
    split = st["components"]["conductor"]["damage_by_source"]
    # the 100 s cell gap is fed by the estimate: both sources carry damage, and they add up
    # to the committed damage
    assert split["measured"] > 0 and split["estimated"] > 0
    assert split["measured"] + split["estimated"] + split["unattributed"] == pytest.approx(
        st["components"]["conductor"]["damage_committed"], rel=1e-9)
    assert split["estimate_error_from"] in ("residual", "assumed")
    assert split["estimated_low"] < split["estimated"] < split["estimated_high"]


def test_a_sink_that_wants_qc_gets_the_flag_totals_in_each_step():
    class QcSink:
        wants_qc = True

        def __init__(self):
            self.qc = {}

        def on_step(self, step):
            self.qc.update(step.qc)

        def close(self):
            pass

    sink = QcSink()
    p = Pipeline(default_config(), [sink])
    for b in blocks_interleaved(sea(60), 5):
        p.process(b)
    p.flush()
    assert sink.qc["tension"] == p.status()["streams"]["tension"]["qc"]
    assert set(sink.qc) == {"tension", "imu", "gnss"}


class _TickCounter:
    def __init__(self) -> None:
        self.ticks = 0

    def on_step(self, step) -> None:
        pass

    def on_observation(self, obs) -> None:
        self.ticks += 1


def _run_with_jump(jump_ns: int) -> tuple[Pipeline, _TickCounter]:
    rng = np.random.default_rng(8)
    counter = _TickCounter()
    p = Pipeline(default_config(), sinks=[counter])
    for start in (T0, T0 + 600 * S + jump_ns):
        for k in range(60):  # 10 minutes of 20 Hz tension in 10-s blocks
            t = start + (k * 200 + np.arange(200, dtype=np.int64)) * 50_000_000
            p.process(SampleBlock("vaps", "tension", t,
                                  {"tension_N": 3000.0 + 800.0 * rng.standard_normal(200)}))
    p.flush()
    return p, counter


def test_a_sensor_clock_jumping_years_ahead_costs_what_its_data_costs():
    """A clock jumping 8 years ahead (or logs of one buoy far apart): the gap's ticks are not
    walked one by one (25 million at 10 s), only the first hour after the data stops; the
    committed damage is the same bits as with a 20-minute gap (every tick evaluated)."""
    far, far_ticks = _run_with_jump(8 * 365 * 86400 * S)
    near, near_ticks = _run_with_jump(20 * 60 * S)
    assert committed_of(far) == committed_of(near) and committed_of(far)["conductor"] > 0
    assert near_ticks.ticks == 60 + 120 + 60  # 10 + 20 + 10 minutes of 10 s ticks
    assert far_ticks.ticks == 60 + 361 + 60  # the gap's first hour only
    rules = [(a["rule"], a["event"]) for a in far.report()["alerts"] if a["rule"] == "stale"]
    assert rules[0] == ("stale", "fire") and rules[-1] == ("stale", "clear")


def committed_of(p: Pipeline) -> dict:
    return {n: c["damage_committed"] for n, c in p.report()["components"].items()}


@pytest.mark.parametrize("sources", ["measured", "mixed"])
def test_tick_load_figures_equal_the_tick_by_tick_reductions(sources):
    """_TickLoad's one pass over a slab (the load cell alone, or mixed with estimates; ticks
    without samples between) equals each tick reduced on its own: max, min, peak stresses,
    sample counts and each source's mean as one reduceat segment."""
    from monitor.load_source import ESTIMATED, MEASURED
    from monitor.pipeline import _seq_mean, _TickLoad

    rng = np.random.default_rng(11)
    v = 20_000 + rng.normal(0, 3_000, 4_000)
    src = np.full(v.shape, MEASURED, np.int8)
    if sources == "mixed":
        src[rng.random(v.shape[0]) < 0.3] = ESTIMATED
        src[1_000:1_200] = ESTIMATED  # a tick of estimates alone
    stress = {"a": v * 1e3, "b": -v}
    edges = np.r_[0, np.sort(rng.integers(0, 4_000, 40)), 4_000]
    edges[5:8] = edges[5]  # ticks without samples
    starts, stops = edges[:-1], edges[1:]
    load = _TickLoad(v, src, stress, starts, stops)
    for k, (a, b) in enumerate(zip(starts.tolist(), stops.tolist())):
        x, m = v[a:b], src[a:b] == MEASURED
        assert load.n[k] == b - a and load.n_meas[k] == int(m.sum())
        if a == b:
            assert math.isnan(load.vmax[k]) and math.isnan(load.meas[k])
            continue
        assert (load.vmax[k], load.vmin[k]) == (x.max(), x.min())
        assert load.smax["a"][k] == (x * 1e3).max() and load.smax["b"][k] == (-x).max()
        for got, want in ((load.meas[k], _seq_mean(x[m])), (load.est[k], _seq_mean(x[~m]))):
            assert got == want or (math.isnan(got) and math.isnan(want))


def test_joined_cycles_share_a_lone_array_and_concatenate_several():
    """A step's cycles end to end: the one non-empty part itself, else a concatenation."""
    from monitor.pipeline import _joined

    a, b, empty = np.array([1.0, 2.0]), np.array([3.0]), np.zeros(0)
    assert _joined([empty, a]) is a and _joined([a, empty]) is a
    assert _joined([a, b]).tolist() == [1.0, 2.0, 3.0]
    assert _joined([b, empty, a]).tolist() == [3.0, 1.0, 2.0]
    assert _joined([empty, empty]).shape == (0,)


def test_advance_unread_makes_no_step_and_leaves_the_same_bits():
    """The replay driver's tick stage without a StepResult (no sink): None, and the same
    report and state as the steps made; sea-state windows closed meanwhile are not kept for
    a later step."""
    config = config_with(default_config(), forecast={"window_s": 300.0})
    blocks = blocks_interleaved(sea(1500, seed=5), 30)
    stepped, unread = Pipeline(config), Pipeline(config)
    steps = [stepped.process(b) for b in blocks]
    assert all(unread.advance_unread(unread.ingest(b)) is None for b in blocks)
    assert sum(len(s.windows) for s in steps) >= 3  # (the windows a step hands over)
    assert json.dumps([stepped.report(), stepped.state()]) == json.dumps(
        [unread.report(), unread.state()])
    assert unread.sea_states.take_windows() == []
