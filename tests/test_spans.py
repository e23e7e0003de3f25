"""A replay without sinks takes one slab per stretch of the log (replay.spans,
``Pipeline.ingest(*blocks)``): the same report and state to the last bit as block by block,
on the faulty feed of test_stages (copies, swapped blocks, a clock a day ahead, a stream an
hour back, silent streams), in one process and with the stream stage in a child; with a
sink, one slab per block as before."""

from __future__ import annotations

import dataclasses
import functools
import json
import types

import msgspec
import numpy as np
import pytest

from monitor.blocks import SENSOR_FIELDS, SampleBlock
from monitor.config import default_config
from monitor.pipeline import Pipeline
from replay.runner import replay_pipeline, run_blocks
import replay.spans
from replay.spans import spans
from synthetic_buoy import T0, blocks_interleaved, sea
from test_stages import CONFIG, Recorder, faulty_blocks

S = 1_000_000_000


@pytest.fixture(scope="module")
def feed():
    return faulty_blocks()[0]


def _bits(pipeline: Pipeline) -> bytes:
    return json.dumps([pipeline.report(), pipeline.state()], allow_nan=True).encode()


def _block(sensor: str, t0_s: float, t1_s: float) -> SampleBlock:
    t = np.arange(int(t0_s * S), int(t1_s * S) + 1, S, dtype=np.int64)
    return SampleBlock("b", sensor, t, {f: t * 0.0 for f in SENSOR_FIELDS[sensor]})


def test_runs_hold_one_block_per_stream_of_overlapping_spans():
    blocks = [_block("tension", 0, 10), _block("imu", 0, 10),  # one stretch
              _block("tension", 10, 20), _block("imu", 10, 20), _block("gnss", 15, 20),
              _block("gnss", 25, 30),  # starts after the run's end
              _block("imu", 30, 40),  # from the run's end: joins it
              _block("imu", 40, 50)]  # the same stream twice
    runs = [[(b.sensor, b.t_first_ns // S) for b in run] for run in spans(blocks)]
    assert runs == [[("tension", 0), ("imu", 0)],
                    [("tension", 10), ("imu", 10), ("gnss", 15)],
                    [("gnss", 25), ("imu", 30)], [("imu", 40)]]
    assert [len(run) for run in spans(blocks, join=False)] == [1] * len(blocks)


def test_stretches_after_all_before_them_join_once_a_horizon_of_samples_leaves_no_long_gap():
    blocks = [_block("tension", 0, 10), _block("imu", 0, 10),
              _block("tension", 11, 20), _block("imu", 11, 20),  # after all before: joins
              _block("tension", 21, 30), _block("imu", 21, 30),  # the run would span 30 s
              _block("imu", 31, 40), _block("tension", 30, 40),  # not after all before
              _block("gnss", 41, 45), _block("gnss", 46, 50),  # 30 to 50 s: join
              _block("gnss", 51, 59)]
    # a horizon of 20 s: a stretch joins once the samples leave no gap of an hour for 20 s
    # before it (the watermark may lie anywhere there): not the second (the watermark may
    # still be before the first sample), the third
    runs = [[(b.sensor, b.t_first_ns // S) for b in run] for run in spans(blocks, True, 20 * S)]
    assert runs == [[("tension", 0), ("imu", 0)],
                    [("tension", 11), ("imu", 11), ("tension", 21), ("imu", 21)],
                    [("imu", 31), ("tension", 30), ("gnss", 41), ("gnss", 46), ("gnss", 51)]]
    # empty blocks join whatever run is open
    empty = SampleBlock("b", "gnss", np.zeros(0, np.int64),
                        {f: np.zeros(0) for f in SENSOR_FIELDS["gnss"]})
    runs = [[(b.sensor, len(b)) for b in run]
            for run in spans([_block("imu", 0, 9), empty, _block("imu", 10, 19)], True, 19 * S)]
    assert runs == [[("imu", 10), ("gnss", 0)], [("imu", 10)]]
    assert len(list(spans(blocks))) == 7  # (no horizon given: stretches alone)
    hours = [_block("tension", 3600 * h, 3600 * h + 1799) for h in range(4)]
    # (a horizon longer than the log: its watermark may be anywhere)
    assert [len(run) for run in spans(hours, True, 10**6 * S)] == [1, 1, 1, 1]


def _starts(runs: list[list[SampleBlock]]) -> list[list[int]]:
    return [[b.t_first_ns // 1800 // S for b in run if b.sensor == "tension"] for run in runs]


def test_runs_join_beyond_the_horizon_where_no_boundary_can_fall_into_a_long_gap():
    """Half-hour stretches (tension and IMU), a horizon of an hour: within the first hour
    the watermark may lie before the first sample (stretches alone), then runs of up to
    LONGEST_RUN_NS (3 h); after a gap of more than an hour (two), again an hour of
    stretches alone. A block whose samples run ahead of its receive time may lose some
    (time_ahead): its end opens a gap."""
    H = 3600 * S

    def stretch(i: int, recv: int = 0) -> list[SampleBlock]:
        return [dataclasses.replace(_block(s, 1800 * i, 1800 * i + 1799), recv_ns=recv)
                for s in ("tension", "imu")]

    feed = [b for i in [*range(14), *range(18, 30)] for b in stretch(i)]
    assert _starts(list(spans(feed, True, H))) == [
        [0], [1], [2, 3, 4, 5, 6, 7], [8, 9, 10, 11, 12, 13],  # (a gap from 7 h to 9 h)
        [18], [19], [20, 21, 22, 23, 24, 25], [26, 27, 28, 29]]
    # a gap of an hour and a second is one; of an hour, not
    feed = [b for i in [*range(8), *range(10, 14)] for b in stretch(i)]
    assert _starts(list(spans(feed, True, H))) == [
        [0], [1], [2, 3, 4, 5, 6, 7], [10], [11], [12, 13]]
    feed[16:] = [_block(s, 1800 * i - 1, 1800 * i + 1798) for i in range(10, 14)
                 for s in ("tension", "imu")]
    assert _starts(list(spans(feed, True, H))) == [[0], [1], [2, 3, 4, 5, 6, 7], [9, 10, 11, 12]]
    # stretch 5's samples may be ahead of their receive time: its end may open a gap, up to
    # stretch 6's start, and the boundaries of the hour after that stay
    feed = [b for i in range(14) for b in stretch(i, (1800 * i + 1000) * S if i == 5 else 0)]
    assert _starts(list(spans(feed, True, H))) == [
        [0], [1], [2, 3, 4, 5], [6], [7], [8, 9, 10, 11, 12, 13]]
    assert [len(r) for r in spans(feed, True, 10 * H)] == [2] * 14  # (a 10-h horizon)
    # a restored ordering has received up to 4 h 59 min 59 s: its watermark may be there
    feed = [b for i in range(14) for b in stretch(i)]
    assert _starts(list(spans(feed, True, H, after_ns=(5 * 3600 - 1) * S))) == [
        *([i] for i in range(10)), [10, 11, 12, 13]]


@pytest.mark.parametrize("minutes", [25, 30, 12])
def test_runs_around_a_long_gap_give_the_bits_of_a_slab_per_block(monkeypatch, minutes):
    """8 h of tension and IMU (no GNSS: the watermark lags the newest sample by the 1-h
    horizon) in blocks of 25, 30 or 12 min, with all data out from 3 h to 5.5 h: the runs
    give the report and state of one slab per block, in fewer slabs. The gap's ticks are
    walked only an hour from where a slab begins inside it (Pipeline._tick_ends), so a run
    that joined across a boundary a watermark could put in the gap would give other
    alerts: the runs of an hour within the horizon did (main f01117f to this change)."""
    feed = blocks_interleaved(_gapped_sea(), minutes * 60)
    one_by_one = replay_pipeline(default_config())
    for block in feed:
        one_by_one.process(block)
    one_by_one.flush()
    slabs = []
    ingest = Pipeline.ingest
    monkeypatch.setattr(Pipeline, "ingest", lambda self, *b: slabs.append(1) or ingest(self, *b))
    assert _bits(run_blocks(default_config(), iter(feed))[0]) == _bits(one_by_one)
    assert len(slabs) - 1 == {25: 5, 30: 5, 12: 11}[minutes] < len(feed) // 2 - 1  # (the flush)


@functools.lru_cache(maxsize=1)
def _gapped_sea() -> dict:
    data = sea(8 * 3600, seed=5)
    del data["gnss"]
    for sensor, (t, v) in list(data.items()):
        keep = (t < T0 + 3 * 3600 * S) | (t >= T0 + 19800 * S)
        data[sensor] = (t[keep], {k: a[keep] for k, a in v.items()})
    return data


def test_dense_slabs_take_the_usual_tick_path_with_the_same_ticks():
    """Pipeline._tick_ends leaves out all but the first ticks of a long run of ticks
    without samples; its check that no run is long (every 64th sample's tick) takes the
    usual path for a dense slab of hours, and gives the general path's ticks always."""
    pipeline = Pipeline(default_config(), warm=False)
    tick, most = pipeline.tick_ns, pipeline._max_empty_ticks
    assert most * tick == 3610 * S  # (an hour of 10-s ticks, and the last sample's)
    first, k = 10**18, 4 * most  # 4 h of ticks
    rng = np.random.default_rng(3)
    dense = first - tick + np.cumsum(rng.integers(1, 5 * tick, 20_000))
    dense = dense[dense <= first + k * tick]
    gap = dense[(dense < first + most * tick) | (dense > first + (2 * most + 9) * tick)]
    cases = [([dense], True), ([gap], False), ([gap[:10], dense], True),
             ([dense[dense > first + (most + 1) * tick]], False),  # no sample first
             ([dense[dense <= first + (k + 1 - most) * tick]], True)]  # `most` after the last
    for times, usual in cases:
        assert any(pipeline._dense(first, k, x) for x in times) is usual
        general = Pipeline._tick_ends(
            types.SimpleNamespace(tick_ns=tick, _max_empty_ticks=most,
                                  _dense=lambda *a: False), first, k, times)
        assert np.array_equal(pipeline._tick_ends(first, k, times), general)
        assert (general.shape[0] == k + 1) is usual


@pytest.mark.parametrize("child", [False, True], ids=["one-process", "child"])
def test_a_replay_without_sinks_takes_fewer_slabs_and_gives_the_same_bits(feed, child,
                                                                          monkeypatch):
    one_by_one = replay_pipeline(CONFIG)
    for block in feed:
        one_by_one.process(block)
    one_by_one.flush()

    slabs = []
    advance = Pipeline._advance

    def counted(self, intake, result):
        slabs.append(intake.block)
        return advance(self, intake, result)

    monkeypatch.setattr(Pipeline, "_advance", counted)
    pipeline, result = run_blocks(CONFIG, iter(feed), child=child)
    assert _bits(pipeline) == _bits(one_by_one)
    assert (result.blocks, result.samples) == (len(feed), sum(len(b) for b in feed))
    # tension, IMU and GNSS blocks of 5 s: a stretch's three in one slab, less where the
    # feed's faults (copies, swaps, silent streams) cut a run short; stretches after all
    # before them in one slab while within the 10-s horizon (two, where nothing cuts them)
    stretches = len(list(spans(feed)))
    assert len(feed) / 3 < stretches < len(feed) / 2
    assert len(slabs) - 1 == len(list(spans(feed, True, 10 * S))) < 0.6 * stretches


def test_a_replay_with_a_sink_keeps_one_slab_per_block(feed, monkeypatch):
    slabs = []
    advance = Pipeline._advance

    def counted(self, intake, result):
        slabs.append(intake.block)
        return advance(self, intake, result)

    monkeypatch.setattr(Pipeline, "_advance", counted)
    run_blocks(CONFIG, iter(feed), sinks=[Recorder()])
    assert len(slabs) == len(feed) + 1  # and the flush


def test_blocks_given_together_to_a_pipeline_with_block_hooks_are_refused(feed):
    pipeline = replay_pipeline(CONFIG, [Recorder()])
    with pytest.raises(ValueError, match="block hooks"):
        pipeline.ingest(feed[0], feed[1])


@pytest.mark.parametrize("horizon_s, resume_s", [(7200, 14500), (3600, 18000)])
def test_the_ticks_of_a_long_gap_do_not_depend_on_where_the_slabs_are_cut(horizon_s, resume_s):
    """Every stream's last sample before a gap of over an hour on a tick end (3 h of all five
    streams in 30-min stretches): with a 2-h horizon the watermark is that sample, so a slab
    cut there walked the gap's empty ticks from the tick after it, a run across the gap from
    its own tick (one tick fewer, a re-sent alert moved); with a 1-h horizon the first
    block after the gap put the watermark inside it, and the slab after that walked another
    hour of ticks (660 against 482; review of 2026-11-26). A run never joins across such a
    gap, and a gap's empty ticks count from the newest sample before it, in whatever slab
    (Pipeline.sample_tick_ns): the same bits block by block, stretch by stretch and in
    runs."""
    rng = np.random.default_rng(1)
    level = {"tension_N": (2e5, 1e4), "heave_m": (0, 1), "surge_m": (0, 1), "sway_m": (0, 1),
             "accel_x_mps2": (0, .5), "accel_y_mps2": (0, .5), "accel_z_mps2": (9.81, .5),
             "lat_deg": (45, 1e-5), "lon_deg": (-30, 1e-5), "hs_m": (2, .1), "tp_s": (9, .2)}
    step = {"tension": 0.5, "motion": 1, "imu": 0.5, "gnss": 10, "waves": 600}

    def block(sensor: str, a: int, b: int) -> SampleBlock:
        t = T0 + np.arange(a * S, b * S + 1, int(step[sensor] * S), dtype=np.int64)
        return SampleBlock("vaps", sensor, t, {k: level[k][0] + level[k][1] * rng.standard_normal(
            t.shape[0]) for k in SENSOR_FIELDS[sensor]})

    spans_s = [(i * 1800, i * 1800 + (1800 if i == 5 else 1790)) for i in range(6)]
    feed = [block(s, a, b) for a, b in [*spans_s, (resume_s, resume_s + 60)] for s in step]
    config = default_config()
    config = dataclasses.replace(config, ordering=msgspec.structs.replace(
        config.ordering, replay_horizon_s=float(horizon_s)))
    runs = [[(b.t_first_ns - T0) // S for b in run if b.sensor == "tension"]
            for run in spans(feed, True, horizon_s * S)]
    assert runs == {7200: [[0], [1800], [3600], [5400], [7200, 9000], [14500]],
                    3600: [[0], [1800], [3600, 5400, 7200, 9000], [18000]]}[horizon_s]
    one_by_one = replay_pipeline(config)
    for b in feed:
        one_by_one.process(b)
    one_by_one.flush()
    by_stretch = replay_pipeline(config)
    for run in spans(feed):
        by_stretch.advance(by_stretch.ingest(*run))
    by_stretch.flush()
    assert _bits(run_blocks(config, iter(feed))[0]) == _bits(one_by_one) == _bits(by_stretch)
