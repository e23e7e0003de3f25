"""Log writer and fast reader: standard MCAP, generic decoding, ordering, dedup, coalescing."""

from __future__ import annotations

import json

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader

from monitor.blocks import SENSOR_FIELDS, SampleBlock
from mcap_oracle import reference_blocks
from monitor.quanta import DEFAULT_QUANTA
from replay.log_files import time_span
from replay.reader import LogReader, iter_blocks
from replay.writer import LogWriter, Series, alert_topic, status_topic

T0 = 1_750_000_000 * 10**9
S = 10**9


def _blk(sensor, t, seed=0, buoy="b1"):
    """Random samples on each field's quantum grid (as the decoder computes them), so they
    come back from a log bit for bit."""
    rng = np.random.default_rng(seed)
    t = np.asarray(t, np.int64)
    fields = {f: rng.integers(-20_000, 20_000, t.shape[0]).astype(np.float64) * DEFAULT_QUANTA[f]
              for f in SENSOR_FIELDS[sensor]}
    return SampleBlock(buoy, sensor, t, fields)


def _seconds(sensor, k, rate):
    return T0 + k * S + np.arange(rate) * (S // rate)


def _same(a, b):
    return (a.topic == b.topic and np.array_equal(a.t_ns, b.t_ns)
            and all(np.array_equal(a.fields[f], b.fields[f]) for f in a.fields))


@pytest.fixture()
def mixed_log(tmp_path):
    """40 s of tension (20 Hz) and imu (10 Hz) blocks, a JSON status, a series; small chunks."""
    path = tmp_path / "mixed.mcap"
    blocks = []
    with LogWriter(path, chunk_size=4096) as w:
        for k in range(40):
            for sensor, rate in (("tension", 20), ("imu", 10)):
                b = _blk(sensor, _seconds(sensor, k, rate), seed=k)
                w.write_block(b, recv_ns=T0 + (k + 1) * S + 5)
                blocks.append(b)
            if k % 10 == 0:
                w.write_json(status_topic("b1"), {"k": k, "nan": float("nan")},
                             T0 + k * S + 7, T0 + k * S)
        ti = T0 + 40 * S + np.cumsum(np.random.default_rng(9).integers(1, S // 5, 60))
        w.write_series([Series("b1", "motion", ti, np.random.default_rng(2).normal(size=(3, 60)))])
        w.write_json(alert_topic("b1", "damage_rate", "conductor_left"), {"state": "raised"},
                     T0 + 50 * S, T0 + 49 * S)
    return path, blocks


def test_file_is_standard_indexed_mcap_with_crcs(mixed_log):
    path, blocks = mixed_log
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        msgs = list(reader.iter_messages(log_time_order=True))
    n_motion = sum(1 for _, c, _ in msgs if c.topic.endswith("motion"))
    assert summary.statistics.message_count == len(msgs) == 80 + 4 + n_motion + 1
    assert len(summary.chunk_indexes) > 5
    by_topic = {c.topic: (s.encoding, c.message_encoding, s.name) for s, c, _ in msgs}
    assert by_topic["buoy/b1/sensor/tension"] == ("protobuf", "protobuf", "buoymon.v2.TensionBlock")
    assert by_topic["buoy/b1/monitor/status"] == ("jsonschema", "json", "buoymon.v1.Status")
    assert "buoy/b1/monitor/alert/damage_rate/conductor_left" in by_topic
    for s, c, m in msgs:
        assert m.log_time > 0 and m.publish_time > 0
        if c.topic.endswith("status"):
            assert json.loads(m.data)["nan"] is None
            assert json.loads(s.data)["type"] == "object"
    # the streaming reader validates chunk CRCs too
    with open(path, "rb") as f:
        assert sum(1 for _ in StreamReader(f, validate_crcs=True).records) > len(msgs)


def test_generic_protobuf_decoding_from_the_stored_descriptor_set(mixed_log):
    """Foxglove/Rerun-style decoding: only the FileDescriptorSet in the file, no buoymon codec."""
    path, blocks = mixed_log
    got = []
    with open(path, "rb") as f:
        for schema, channel, msg in make_reader(f).iter_messages(log_time_order=False):
            if schema.encoding != "protobuf":
                continue
            pool = descriptor_pool.DescriptorPool()
            for fd in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
                pool.Add(fd)
            cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
            m = cls.FromString(msg.data)
            if channel.topic.endswith("tension"):
                q = m.tension_N  # docs/LOG_FORMAT.md: value = quantum * running sum of delta
                t = m.t0_ns + m.period_ns * np.arange(len(q.delta))
                v = np.cumsum(np.array(q.delta, np.int64)).astype(np.float64) * q.quantum
                assert q.quantum == 0.1 and not q.raw_index
                got.append((msg.publish_time, msg.log_time, t, v))
    tension = [b for b in blocks if b.sensor == "tension"]
    assert len(got) == len(tension) == 40
    for k, ((pub, log, t, v), b) in enumerate(zip(got, tension)):
        assert pub == b.t_first_ns == T0 + k * S  # publish_time = first sample's sensor time
        assert log == T0 + (k + 1) * S + 5  # log_time = receive time
        assert np.array_equal(t, b.t_ns) and np.array_equal(v, b.fields["tension_N"])


def test_fast_reader_equals_reference_reader(mixed_log):
    path, _ = mixed_log
    ref = reference_blocks(path)
    reader = LogReader(path, coalesce=False)
    fast = list(reader)
    assert len(fast) == len(ref) == reader.stats[0].messages
    for a, b in zip(fast, ref):
        assert _same(a, b) and a.recv_ns == b.recv_ns
    st = reader.stats[0]
    assert st.complete and not st.lost and st.error is None
    assert st.skipped == {"buoy/b1/monitor/status": 4,
                          "buoy/b1/monitor/alert/damage_rate/conductor_left": 1}
    # coalesced: same samples per topic, far fewer blocks
    co = list(iter_blocks(path))
    assert len(co) < len(fast) / 5
    for topic in {b.topic for b in fast}:
        a = [b for b in fast if b.topic == topic]
        c = [b for b in co if b.topic == topic]
        assert np.array_equal(np.concatenate([b.t_ns for b in a]),
                              np.concatenate([b.t_ns for b in c]))
        for f in a[0].fields:
            assert np.array_equal(np.concatenate([b.fields[f] for b in a]),
                                  np.concatenate([b.fields[f] for b in c]))


def test_series_are_cut_on_the_block_grid_and_keep_irregular_times(tmp_path):
    path = tmp_path / "s.mcap"
    t = T0 + np.array([0, 3, 900_000_000, S, S + 7, 3 * S + 1], np.int64)  # 3 blocks, none at 2 s
    v = np.arange(6.0)[None]
    with LogWriter(path) as w:
        assert w.write_series([Series("b1", "tension", t, v)], recv_delay_ns=11) == 3
    blocks = list(LogReader(path, coalesce=False))
    assert [b.t_ns.tolist() for b in blocks] == [t[:3].tolist(), t[3:5].tolist(), t[5:].tolist()]
    assert [b.recv_ns for b in blocks] == [t[2] + 11, t[4] + 11, t[5] + 11]


def test_out_of_order_within_the_window_and_every_copy_delivered(tmp_path):
    path = tmp_path / "ooo.mcap"
    order = [0, 2, 1, 3, 3, 5, 4, 6]  # 1 and 4 arrive late, 3 twice
    with LogWriter(path) as w:
        for k in order:
            w.write_block(_blk("tension", _seconds("tension", k, 20), seed=k), T0 + 10 * S)
        # same time as a message already written, different samples
        w.write_block(_blk("tension", _seconds("tension", 6, 20), seed=99), T0 + 10 * S)
    reader = LogReader(path, coalesce=False, reorder_window_s=5)
    blocks = list(reader)
    firsts = [(b.t_first_ns - T0) // S for b in blocks]
    assert firsts == [0, 1, 2, 3, 3, 4, 5, 6, 6] and reader.stats[0].late == 0
    # the copy right behind the first (the pipeline rejects it as duplicate, tests/test_duplicates.py)
    assert np.array_equal(blocks[4].fields["tension_N"], blocks[3].fields["tension_N"])
    # the same-time message with different samples is kept, after the first one (read order)
    expected = _blk("tension", [0] * 20, seed=99).fields["tension_N"]
    assert np.array_equal(blocks[-1].fields["tension_N"], expected)


def test_coalesced_blocks_of_messages_read_out_of_order_are_theirs_in_time_order(tmp_path):
    """Messages released together but not back to back in read order (late ones, copies,
    one held back between them) are gathered into the coalesced block in the order of one
    block per message; its receive time is their latest."""
    path = tmp_path / "ooo.mcap"
    with LogWriter(path) as w:
        # 0 and 1 are released after the first chunk, 20 read between them is held back
        for k, recv in ((0, 40), (20, 21), (1, 22)):
            w.write_block(_blk("tension", _seconds("tension", k, 20), seed=k), T0 + recv * S)
        w.flush(fsync=False)
        for k in [21, 23, 22, 23]:  # 22 late, 23 twice
            w.write_block(_blk("tension", _seconds("tension", k, 20), seed=k), T0 + 30 * S)
    per_message = list(LogReader(path, coalesce=False, reorder_window_s=5))
    blocks = list(LogReader(path, coalesce=True, reorder_window_s=5))
    assert [((b.t_ns[::20] - T0) // S).tolist() for b in blocks] == [[0, 1], [20, 21, 22, 23, 23]]
    assert [b.recv_ns for b in blocks] == [T0 + 40 * S, T0 + 30 * S]
    for f in ("t_ns", "tension_N"):
        get = (lambda b: b.t_ns) if f == "t_ns" else (lambda b: b.fields[f])
        assert np.array_equal(np.concatenate([get(b) for b in blocks]),
                              np.concatenate([get(b) for b in per_message]))


def test_messages_later_than_the_window_are_counted_late_and_delivered(tmp_path):
    path = tmp_path / "late.mcap"
    with LogWriter(path) as w:
        for k in [*range(10, 200), 3]:
            w.write_block(_blk("tension", _seconds("tension", k, 20)), T0 + 300 * S)
            w.flush(fsync=False)  # one message per chunk: the reader releases after each
    reader = LogReader(path, coalesce=False, reorder_window_s=2)
    firsts = [(b.t_first_ns - T0) // S for b in reader]
    # 198 and 199 are still held in the window when 3 arrives: 3 joins (and leads) that release
    assert firsts == [*range(10, 198), 3, 198, 199] and reader.stats[0].late == 1
    # a window covering the whole file sorts it
    reader = LogReader(path, coalesce=False, reorder_window_s=1e6)
    firsts = [(b.t_first_ns - T0) // S for b in reader]
    assert firsts == [3, *range(10, 200)]


def test_a_message_far_ahead_of_its_receive_time_is_read_where_it_was_received(tmp_path):
    """A block dated a year ahead of its log time (time_ahead: a wrong clock) was ordered by
    its publish time: read last, and while it was pending every message after it was
    released as soon as read (no reordering: 41 before 40 counted late). Ordered by its log
    time it is read in its place and the window sorts the rest; a block ahead by no more
    than ``max_ahead_s`` keeps its publish time (and a log time 0 is unknown: publish time)."""
    path = tmp_path / "ahead.mcap"
    year = 365 * 86400 * S
    with LogWriter(path) as w:
        for k in [*range(40), 41, 40, *range(42, 60)]:
            t = _seconds("tension", k, 20) + (year if k == 20 else 0)
            w.write_block(_blk("tension", t, seed=k), T0 + (k + 1) * S)
            w.flush(fsync=False)  # one message per chunk: the reader releases after each
    reader = LogReader(path, coalesce=False, reorder_window_s=5)
    firsts = [(b.t_first_ns - T0) // S for b in reader]
    assert firsts == [*range(20), 20 + year // S, *range(21, 60)]
    assert reader.stats[0].late == 0
    # the pipeline's limit: a year is within it, the block keeps its publish time
    reader = LogReader(path, coalesce=False, reorder_window_s=5, max_ahead_s=2 * year / S)
    firsts = [(b.t_first_ns - T0) // S for b in reader]
    assert firsts[-1] == 20 + year // S and reader.stats[0].late == 1
    from replay.merge import order_times

    pub, log = np.array([5 * S, 700 * S, 900 * S]), np.array([4 * S, 99 * S, 0])
    assert order_times(pub, log, 600 * S).tolist() == [5 * S, 99 * S, 900 * S]


def test_overlapping_files_are_merged_in_order_with_every_copy(tmp_path):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    for path, ks in ((a, range(0, 30)), (b, range(25, 50))):
        with LogWriter(path) as w:
            for k in ks:
                w.write_block(_blk("tension", _seconds("tension", k, 20), seed=k), T0 + (k + 1) * S)
    reader = LogReader([tmp_path], coalesce=True)
    blocks = list(reader)
    t = np.concatenate([blk.t_ns for blk in blocks])
    seconds = sorted([*range(0, 30), *range(25, 50)])  # 25..29 twice, each copy behind the first
    assert np.array_equal(t, np.concatenate([_seconds("tension", k, 20) for k in seconds]))
    assert [s.messages for s in reader.stats] == [30, 25]
    assert [s.path for s in reader.stats] == [str(a), str(b)]


def test_flush_makes_data_durable_without_close(tmp_path):
    path = tmp_path / "live.mcap"
    w = LogWriter(path)
    for k in range(5):
        w.write_block(_blk("imu", _seconds("imu", k, 10)), T0 + (k + 1) * S)
    w.flush(fsync=True)
    w.write_block(_blk("imu", _seconds("imu", 9, 10)), T0 + 10 * S)  # still in the open chunk
    reader = LogReader(path)
    blocks = list(reader)
    assert sum(len(b) for b in blocks) == 50
    assert not reader.stats[0].complete and not reader.stats[0].lost
    w.close()
    assert sum(len(b) for b in iter_blocks(path)) == 60


def test_writer_rejects_bad_input_with_named_errors(tmp_path):
    with LogWriter(tmp_path / "x.mcap") as w:
        with pytest.raises(ValueError, match="empty block"):
            w.write_block(_blk("tension", []), T0)
        with pytest.raises(ValueError, match="must be > 0"):
            w.write_block(_blk("tension", [0, 5]), T0)
        with pytest.raises(ValueError, match="must be an object"):
            w.write_json(status_topic("b1"), [1, 2], T0, T0)
        with pytest.raises(ValueError, match=r"values must be \(1, 3\)"):
            w.write_series([Series("b1", "tension", np.array([1, 2, 3]) + T0, np.zeros((2, 3)))])
        with pytest.raises(ValueError, match="non-decreasing"):
            w.write_series([Series("b1", "tension", np.array([3, 2]) + T0, np.zeros((1, 2)))])
    with pytest.raises(ValueError, match="component"):
        alert_topic("b1", "rule", "a/b")


def test_foreign_mcap_unchunked_and_lz4_files_are_read(tmp_path):
    """Files from mcap's own writer (top-level messages; lz4 chunks) decode the same."""
    from mcap.writer import CompressionType, Writer

    from monitor import codec

    blocks = [_blk("tension", _seconds("tension", k, 20), seed=k) for k in range(12)]
    variants = (("flat", {"use_chunking": False}), ("lz4", {"compression": CompressionType.LZ4}))
    for name, kw in variants:
        path = tmp_path / f"{name}.mcap"
        with open(path, "wb") as f:
            w = Writer(f, **kw)
            w.start()
            sid = w.register_schema(codec.schema_name("tension"), "protobuf",
                                    codec.file_descriptor_set("tension"))
            cid = w.register_channel("buoy/b1/sensor/tension", "protobuf", sid)
            for b in blocks:
                w.add_message(cid, log_time=b.t_last_ns, publish_time=b.t_first_ns,
                              data=codec.encode_block(b))
            w.finish()
        got = list(LogReader(path, coalesce=False))
        assert len(got) == 12 and all(_same(a, b) for a, b in zip(got, blocks))


def test_time_span_from_the_summary_and_first_last_in_stats(mixed_log, tmp_path):
    path, _ = mixed_log
    with open(path, "rb") as f:
        stats = make_reader(f).get_summary().statistics
    assert time_span(path) == (stats.message_start_time, stats.message_end_time)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[:-100])
    assert time_span(cut) is None and time_span([cut, path]) == time_span(path)
    with open(path, "rb") as f:
        pubs = [m.publish_time for _, c, m in make_reader(f).iter_messages()
                if "/sensor/" in c.topic]
    reader = LogReader(path)
    list(reader)
    assert min(pubs) == T0
    assert (reader.stats[0].first_ns, reader.stats[0].last_ns) == (min(pubs), max(pubs))


def test_coalesced_blocks_span_at_most_coalesce_s_so_replay_keeps_every_sample(tmp_path):
    """80 min of tension and IMU in ONE chunk (compact samples make chunks long): the reader
    cuts the release into <= 1800 s blocks, so the replay's ordering (1 h horizon) never
    passes a stream by; every sample is accepted, as with one block per message."""
    from monitor.config import default_config
    from replay.merge import COALESCE_NS
    from replay.runner import run_blocks

    path = tmp_path / "long.mcap"
    n = 80 * 60
    t20 = T0 + np.arange(n * 20, dtype=np.int64) * (S // 20)
    rng = np.random.default_rng(4)
    series = [Series("vaps", "tension", t20, 5000 + 300 * rng.normal(size=(1, t20.shape[0]))),
              Series("vaps", "imu", t20[::2], 0.5 * rng.normal(size=(3, n * 10)))]
    with LogWriter(path, chunk_size=64 << 20) as w:
        w.write_series(series)
    reader = LogReader(path)
    blocks = list(reader)
    assert reader.stats[0].chunks == 1
    assert max(int(b.t_ns[-1] - b.t_ns[0]) for b in blocks) < COALESCE_NS + S
    per_message = list(LogReader(path, coalesce=False))
    for sensor in ("tension", "imu"):
        a = np.concatenate([b.t_ns for b in blocks if b.sensor == sensor])
        b = np.concatenate([b.t_ns for b in per_message if b.sensor == sensor])
        assert np.array_equal(a, b)
    samples = run_blocks(default_config(), iter(blocks))[0].report()["samples"]
    for sensor, count in (("tension", n * 20), ("imu", n * 10)):
        assert samples[sensor]["accepted"] == count  # not so with 80 min blocks: time_backwards
        assert not any(samples[sensor]["rejected"].values())
