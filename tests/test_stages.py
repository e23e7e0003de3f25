"""The replay's stream stage on a second thread (replay.stages) gives what the pipeline gives
block by block, to the last bit: report, state, and every step, tick observation and block
the sinks see, on a faulty feed (NaNs, spikes, a load-cell gap the motion estimate fills,
re-sent and swapped blocks, a clock jumping a day ahead, a stream's clock stepping back),
with the stream stage running as far ahead as it may (a slow sink) and as it happens to;
and an exception on either thread reaches the caller with no thread left behind."""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest

from monitor.blocks import SampleBlock
from monitor.config import config_with, default_config
from replay.runner import replay_pipeline, run_blocks
from replay.stages import ingest_ahead
from synthetic_buoy import S, blocks_interleaved, sea

# 5-minute sea-state windows: the learner closes windows (and hands spectra over) in a short
# feed; the live ordering horizon: the ticks pass a silent load stream after 10 s
CONFIG = config_with(default_config(), forecast={"window_s": 300.0},
                     ordering={"replay_horizon_s": 10.0})


def _shifted(b: SampleBlock, dt_ns: int) -> SampleBlock:
    return SampleBlock(b.buoy_id, b.sensor, b.t_ns + dt_ns, b.fields)


def faulty_blocks() -> tuple[list[SampleBlock], dict[str, int]]:
    """20 minutes of tension, IMU and GNSS in 5-s blocks and a sea state a minute, with
    faults; also the copies sent per stream."""
    blocks = blocks_interleaved(sea(1200, seed=3, gap=(300, 420)), 5)
    t0 = blocks[0].t_first_ns
    waves = [SampleBlock("vaps", "waves", np.array([t0 + k * 60 * S]),
                         {"hs_m": np.array([1.0 + 0.1 * k]), "tp_s": np.array([7.0])})
             for k in range(1, 20)]  # a wave buoy's sea state every minute
    blocks = sorted(blocks + waves, key=lambda b: b.t_first_ns)
    # tension and IMU silent for 4 minutes from the end of a sea-state window (no load at all)
    blocks = [b for b in blocks
              if b.sensor == "gnss" or not t0 + 600 * S <= b.t_first_ns < t0 + 840 * S]
    glitch = next(i for i in range(400, len(blocks)) if blocks[i].sensor == "gnss")
    out, copies = [], {}
    for i, b in enumerate(blocks):
        if b.t_first_ns >= t0 + 1080 * S:  # the clock jumps a day ahead
            b = _shifted(b, 86400 * S)
        out.append(b)
        if i % 11 == 5:  # re-sent
            out.append(b)
            copies[b.sensor] = copies.get(b.sensor, 0) + len(b)
        if i == glitch:  # a stream's clock steps an hour back
            out.append(_shifted(b, -3600 * S))
    for i in range(7, len(out) - 1, 17):
        out[i], out[i + 1] = out[i + 1], out[i]
    return out, copies


class Recorder:
    """Everything a sink sees, as text (a slow one lets the stream stage run ahead)."""

    wants_qc = True

    def __init__(self, slow: bool = False) -> None:
        self.slow, self.seen = slow, []

    def on_block(self, block) -> None:
        self.seen.append(repr(("block", block.sensor, block.t_ns.tolist())))

    def on_observation(self, obs) -> None:
        streams = {s: obs.streams[s] for s in obs.streams}  # each stream's health, idle or not
        self.seen.append(repr((obs.t_ns, obs.load_source, obs.measured_tension_N,
                               obs.estimated_tension_N, obs.components, streams,
                               obs.tension_range_N, obs.tension_N.tolist())))

    def on_step(self, step) -> None:
        if self.slow:
            time.sleep(0.0005)
        comps = {n: (c.damage, c.damage_committed, c.max_stress_Pa, c.ranges_Pa.tolist())
                 for n, c in step.components.items()}
        self.seen.append(repr((step.sensor, step.now_ns, step.t_ns.tolist(),
                               step.tension_N.tolist(), step.load_source,
                               step.measured_tension_N, step.estimated_tension_N, step.accepted,
                               step.rejected, [a.to_dict() for a in step.alerts], step.windows,
                               step.forecasts, step.qc, comps)))

    def close(self) -> None:
        pass


def _replay(blocks, threads: bool, ahead: int | None = None) -> tuple[bytes, list[str]]:
    """Report and state bytes and what the sink saw: ``run_blocks`` (``threads``), or with
    ``ahead`` the stream stage up to that many slabs ahead of a slow tick stage."""
    sink = Recorder(slow=ahead is not None)
    if ahead is None:
        pipeline, result = run_blocks(CONFIG, iter(blocks), sinks=[sink], threads=threads)
        assert result.blocks == len(blocks)
    else:
        pipeline = replay_pipeline(CONFIG, [sink])
        for intake in ingest_ahead(pipeline, iter(blocks), ahead):
            pipeline.advance(intake)
    out = json.dumps([pipeline.report(), pipeline.state()], allow_nan=True).encode()
    return out, sink.seen


@pytest.fixture(scope="module")
def sequential():
    blocks, copies = faulty_blocks()
    out, seen = _replay(blocks, threads=False)
    return blocks, copies, out, seen


def test_the_faulty_feed_exercises_what_the_stages_hand_over(sequential):
    _, copies, out, seen = sequential
    report, state = json.loads(out)
    samples = report["samples"]
    for s, n in copies.items():
        assert samples[s]["rejected"]["duplicate"] == n
    assert samples["tension"]["rejected"]["nan"] > 0 and samples["tension"]["rejected"]["spike"] > 0
    assert samples["gnss"]["rejected"]["time_backwards"] == 5  # the block an hour back
    assert report["tension_N"]["samples_estimated"] > 0  # the gap's load is the estimate
    table = report["sea_state_table"]
    assert table["windows"] >= 3 and table["learned"] >= 2
    assert {w["sea_state_from"] for w in report["spectral_windows"]} >= {"waves", None}
    rules = {a["rule"] for a in report["alerts"]}
    assert "stale" in rules
    assert len(seen) > 1000


@pytest.mark.parametrize("ahead", [None, 1, 64], ids=["run_blocks", "one-ahead", "far-ahead"])
def test_threaded_replay_gives_the_same_bits_as_block_by_block(sequential, ahead):
    blocks, _, out, seen = sequential
    threaded, threaded_seen = _replay(blocks, threads=True, ahead=ahead)
    assert threaded == out
    assert threaded_seen == seen


def test_an_error_in_the_stream_stage_reaches_the_caller(sequential):
    blocks = sequential[0][:200]

    def failing():
        yield from blocks
        raise RuntimeError("disk went away")

    before = threading.active_count()
    with pytest.raises(RuntimeError, match="disk went away"):
        run_blocks(CONFIG, failing(), threads=True)
    assert threading.active_count() == before


def test_an_error_in_the_tick_stage_stops_the_stream_stage(sequential):
    blocks = sequential[0]
    taken = []

    class Failing(Recorder):
        steps = 0

        def on_step(self, step) -> None:
            self.steps += 1
            if self.steps == 50:
                raise OSError("sink full")

    def counted():
        for b in blocks:
            taken.append(b)
            yield b

    before = threading.active_count()
    with pytest.raises(OSError, match="sink full"):
        run_blocks(CONFIG, counted(), sinks=[Failing()], threads=True)
    assert threading.active_count() == before
    # the stream stage stopped at most two slabs ahead, and the one it was working on
    assert 50 <= len(taken) <= 53


class StepsOnly:
    """What a sink without a per-tick hook sees: slabs of many ticks then go through the
    alert batch."""

    wants_qc = True

    def __init__(self) -> None:
        self._recorder = Recorder()
        self.seen = self._recorder.seen

    def on_block(self, block) -> None:
        self._recorder.on_block(block)

    def on_step(self, step) -> None:
        self._recorder.on_step(step)

    def close(self) -> None:
        pass


def test_the_alert_batch_reads_an_idle_stream_as_handed_over_not_as_the_validator_is_now():
    """GNSS silent from 400 s to 800 s of a 20-minute feed in 200-s blocks (slabs of ~20
    ticks: the alert batch), stale after 250 s: its last fix at 399 s makes it stale at the
    650-s tick, in a slab without GNSS. With every slab's stream stage run before any tick
    stage (as far ahead as ``ingest`` may run) the validator already holds the 800-s fixes;
    the batch must still see the totals handed over with the slab."""
    validate = CONFIG.section("validate")
    alerts = CONFIG.section("alerts")
    cfg = config_with(CONFIG, validate={**validate, "gnss": {**validate.get("gnss", {}),
                                                             "stale_after_s": 250.0}},
                      alerts={**alerts, "rule": [*alerts["rule"],
                                                 {"kind": "stale", "name": "any_stale"}]})
    blocks = blocks_interleaved(sea(1200, seed=3), 200)
    t0 = blocks[0].t_first_ns
    blocks = [b for b in blocks
              if not (b.sensor == "gnss" and t0 + 300 * S <= b.t_first_ns < t0 + 800 * S)]

    def replay(ahead: bool) -> tuple[dict, list[str]]:
        sink = StepsOnly()
        pipeline = replay_pipeline(cfg, [sink])
        assert not pipeline._tick_hooks
        if ahead:
            for intake in [pipeline.ingest(b) for b in blocks] + [pipeline.ingest_end()]:
                pipeline.advance(intake)
        else:
            for b in blocks:
                pipeline.process(b)
            pipeline.flush()
        return json.loads(json.dumps([pipeline.report(), pipeline.state()])), sink.seen

    (report, state), seen = replay(ahead=False)
    gnss = [(a["event"], (a["at_ns"] - t0) // S) for a in report["alerts"]
            if a["rule"] == "any_stale" and a["labels"]["component"] == "gnss"]
    assert ("fire", 650) in gnss  # 399 s + 250 s, the first tick end after
    assert replay(ahead=True) == ([report, state], seen)


def test_the_alert_batch_gives_the_per_tick_results_on_the_faulty_feed(sequential, monkeypatch):
    """The same feed (a clock a day ahead, a stream stepping back, gaps, copies) without a
    per-tick hook: every slab's ticks through the alert batch, which must give the report
    and state of the per-tick path (the sequential fixture has a hook), and the stream stage
    run ahead must give the same again."""
    import monitor.pipeline

    blocks, _, out, _ = sequential
    monkeypatch.setattr(monitor.pipeline, "BATCH_MIN_TICKS", 1)
    batches = []
    evaluate_batch = monitor.pipeline.Pipeline._evaluate_batch
    monkeypatch.setattr(monitor.pipeline.Pipeline, "_evaluate_batch",
                        lambda self, *a: batches.append(1) or evaluate_batch(self, *a))
    sink = StepsOnly()
    pipeline, _ = run_blocks(CONFIG, iter(blocks), sinks=[sink])
    assert len(batches) > 50
    assert json.dumps([pipeline.report(), pipeline.state()], allow_nan=True).encode() == out
    ahead = replay_pipeline(CONFIG, [StepsOnly()])
    for intake in [ahead.ingest(b) for b in blocks] + [ahead.ingest_end()]:
        ahead.advance(intake)
    assert json.dumps([ahead.report(), ahead.state()], allow_nan=True).encode() == out
