"""Damaged logs: cut mid-chunk, no footer, bad chunk CRC, garbage. Never raises; reports loss."""

from __future__ import annotations

import os
import struct

import numpy as np
import pytest
from mcap.reader import make_reader

from monitor.blocks import SampleBlock
from replay.chunks import ReadAhead
from replay.reader import LogReader
from replay.writer import LogWriter

T0 = 1_760_000_000 * 10**9
S = 10**9
N_SECONDS = 120


@pytest.fixture()
def log(tmp_path):
    """120 one-second tension blocks (sample value = sample index, stored exactly to a 1 N
    quantum) in ~10 chunks, with Message Index records (they count a lost chunk's messages)."""
    path, chunks = _write_log(tmp_path / "good.mcap", message_index=True)
    return path, path.read_bytes(), chunks


def _write_log(path, message_index: bool = False):
    """The 120-block log (see ``log``); returns (path, its chunk indexes in file order)."""
    with LogWriter(path, chunk_size=1024, quanta={"tension_N": 1.0},
                   message_index=message_index) as w:
        for k in range(N_SECONDS):
            t = T0 + k * S + np.arange(20, dtype=np.int64) * (S // 20)
            w.write_block(SampleBlock("b1", "tension", t, {"tension_N": k * 20 + np.arange(20.0)}),
                          recv_ns=T0 + (k + 1) * S)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    return path, sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def _read(path):
    reader = LogReader(path, coalesce=True)
    values = np.concatenate([b.fields["tension_N"] for b in reader] or [np.empty(0)])
    return reader, reader.stats[0], values


def _messages_in(path, chunk):
    with open(path, "rb") as f:
        f.seek(chunk.chunk_start_offset + chunk.chunk_length)
        data = f.read(chunk.message_index_length)
    count, p = 0, 0
    while p < len(data):
        _, ln = struct.unpack_from("<BQ", data, p)
        count += struct.unpack_from("<I", data, p + 11)[0] // 16
        p += 9 + ln
    return count


def test_intact_file_reads_everything(log):
    path, _, chunks = log
    _, st, values = _read(path)
    assert np.array_equal(values, np.arange(N_SECONDS * 20.0))
    assert st.complete and not st.lost and st.chunks == len(chunks) >= 10


def test_missing_footer_loses_nothing(log, tmp_path):
    path, data, chunks = log
    last = chunks[-1]
    cut = tmp_path / "nofooter.mcap"
    cut.write_bytes(data[:last.chunk_start_offset + last.chunk_length + last.message_index_length])
    reader, st, values = _read(cut)
    assert np.array_equal(values, np.arange(N_SECONDS * 20.0))
    assert not st.complete and not st.lost and reader.ok
    with pytest.raises(Exception):  # what the stock indexed reader does with such a file
        with open(cut, "rb") as f:
            list(make_reader(f).iter_messages())


def test_cut_inside_the_index_after_the_last_chunk_loses_no_message(log, tmp_path):
    path, data, chunks = log
    last = chunks[-1]
    cut = tmp_path / "cutindex.mcap"
    cut.write_bytes(data[:last.chunk_start_offset + last.chunk_length + 20])
    _, st, values = _read(cut)
    assert np.array_equal(values, np.arange(N_SECONDS * 20.0))
    (lost,) = st.lost
    assert lost.messages == 0 and "file cut inside a record" in lost.reason


def test_cut_mid_chunk_recovers_every_complete_message(tmp_path):
    # noisy values (a fine quantum: ~6 bytes each) in 300 kB chunks of several zstd blocks,
    # so a prefix of a chunk decompresses
    path = tmp_path / "big.mcap"
    rng = np.random.default_rng(0)
    with LogWriter(path, chunk_size=300_000, quanta={"tension_N": 1e-12}, message_index=True) as w:
        for k in range(4000):
            t = T0 + k * S + np.arange(20, dtype=np.int64) * (S // 20)
            w.write_block(SampleBlock("b1", "tension", t, {"tension_N": rng.normal(size=20)}),
                          recv_ns=T0 + (k + 1) * S)
    with open(path, "rb") as f:
        chunks = sorted(make_reader(f).get_summary().chunk_indexes,
                        key=lambda c: c.chunk_start_offset)
    victim = chunks[1]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[:victim.chunk_start_offset + victim.chunk_length * 2 // 3])
    reader = LogReader(cut)
    t = np.concatenate([b.t_ns for b in reader])
    st = reader.stats[0]
    before = _messages_in(path, chunks[0])
    # all of chunk 0 plus a prefix of the cut chunk; whole messages, no gap, nothing invented
    assert before * 20 < t.shape[0] < (before + _messages_in(path, victim)) * 20
    assert t.shape[0] % 20 == 0 and np.array_equal(t, T0 + np.arange(t.shape[0]) * (S // 20))
    (lost,) = st.lost
    assert "cut inside a chunk" in lost.reason and lost.end_ns == victim.message_end_time
    assert lost.offset == victim.chunk_start_offset and lost.messages is None
    assert lost.start_ns == T0 + t.shape[0] // 20 * S  # receive time of the last recovered message
    assert not st.complete and reader.ok


def test_bad_chunk_crc_skips_that_chunk_and_reports_it(log, tmp_path):
    path, data, chunks = log
    victim = chunks[3]
    bad = bytearray(data)
    crc_at = victim.chunk_start_offset + 9 + 24  # opcode+length, then 3 x u64, then the CRC
    bad[crc_at] ^= 0xFF
    p = tmp_path / "badcrc.mcap"
    p.write_bytes(bytes(bad))
    _, st, values = _read(p)
    n_lost = _messages_in(path, victim)
    first_lost = sum(_messages_in(path, c) for c in chunks[:3]) * 20
    expected = np.delete(np.arange(N_SECONDS * 20.0), np.s_[first_lost:first_lost + n_lost * 20])
    assert np.array_equal(values, expected)
    (lost,) = st.lost
    assert lost.reason == "bad chunk CRC" and lost.messages == n_lost
    assert (lost.start_ns, lost.end_ns) == (victim.message_start_time, victim.message_end_time)
    assert st.bad_chunks == 1 and st.complete


def test_corrupt_compressed_bytes_lose_only_that_chunk(log, tmp_path):
    path, data, chunks = log
    victim = chunks[7]
    bad = bytearray(data)
    mid = victim.chunk_start_offset + victim.chunk_length // 2
    bad[mid:mid + 16] = bytes(16)
    p = tmp_path / "corrupt.mcap"
    p.write_bytes(bytes(bad))
    _, st, values = _read(p)
    assert values.shape[0] == (N_SECONDS - _messages_in(path, victim)) * 20
    (lost,) = st.lost
    assert lost.messages == _messages_in(path, victim)
    assert lost.start_ns == victim.message_start_time


@pytest.mark.parametrize("content, error", [
    (b"", "not an MCAP file"),
    (b"hello, this is not a log at all" * 10, "not an MCAP file"),
    (b"\x89MCAP0\r\n\x01\x05\x00", "no sensor messages"),
])
def test_nothing_readable_is_an_error_not_an_exception(tmp_path, content, error):
    p = tmp_path / "junk.mcap"
    p.write_bytes(content)
    reader, st, values = _read(p)
    assert values.shape[0] == 0 and not reader.ok and error in st.error


def test_missing_file_is_reported(tmp_path):
    reader, st, _ = _read(tmp_path / "absent.mcap")
    assert not reader.ok and "cannot open" in st.error


def test_corrupt_record_header_skips_to_the_next_chunk(log, tmp_path):
    path, data, chunks = log
    victim = chunks[4]
    bad = bytearray(data)
    bad[victim.chunk_start_offset] = 0  # opcode 0 is never valid
    p = tmp_path / "opcode.mcap"
    p.write_bytes(bytes(bad))
    reader, st, values = _read(p)
    first_lost = sum(_messages_in(path, c) for c in chunks[:4]) * 20
    n_lost = _messages_in(path, victim) * 20
    expected = np.delete(np.arange(N_SECONDS * 20.0), np.s_[first_lost:first_lost + n_lost])
    assert np.array_equal(values, expected)
    (lost,) = st.lost
    assert lost.reason.startswith("corrupt record (opcode 0)")
    assert lost.offset == victim.chunk_start_offset
    assert "next chunk" in lost.reason and st.complete


def test_corrupt_chunk_length_loses_nothing_when_the_crc_verifies(log, tmp_path):
    path, data, chunks = log
    bad = bytearray(data)
    struct.pack_into("<Q", bad, chunks[2].chunk_start_offset + 1, 10**12)
    p = tmp_path / "length.mcap"
    p.write_bytes(bytes(bad))
    _, st, values = _read(p)
    assert np.array_equal(values, np.arange(N_SECONDS * 20.0))
    assert not st.lost and st.complete


def test_one_damaged_file_among_good_ones(log, tmp_path):
    path, data, _ = log
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"garbage")
    reader = LogReader([junk, path])
    assert sum(len(b) for b in reader) == N_SECONDS * 20
    assert reader.ok and reader.stats[0].error and reader.stats[1].error is None


@pytest.mark.parametrize("seed", range(12))
def test_random_damage_never_raises_and_never_invents_samples(log, tmp_path, seed):
    """Flip random bytes anywhere (headers, chunks, index, footer) and cut at a random length:
    reading never raises, and every sample delivered is a genuine one (CRC-checked chunks)."""
    path, data, _ = log
    rng = np.random.default_rng(seed)
    bad = bytearray(data[:rng.integers(len(data) // 2, len(data) + 1)])
    for pos in rng.integers(0, len(bad), 8):
        bad[pos] ^= int(rng.integers(1, 256))
    p = tmp_path / f"fuzz{seed}.mcap"
    p.write_bytes(bytes(bad))
    reader = LogReader(p, coalesce=False)
    blocks = list(reader)
    for b in blocks:
        k = (b.t_first_ns - T0) // S
        assert b.topic == "buoy/b1/sensor/tension"
        assert np.array_equal(b.t_ns, T0 + k * S + np.arange(20) * (S // 20))
        assert np.array_equal(b.fields["tension_N"], k * 20 + np.arange(20.0))
    st = reader.stats[0]
    assert st.messages == len(blocks)
    if len(blocks) < N_SECONDS:
        assert st.lost or st.error or st.bad_payloads


def _blocks_and_stats(path, read_ahead):
    reader = LogReader(path, coalesce=False, read_ahead=read_ahead)
    blocks = [(b.topic, b.t_ns.tolist(), b.fields["tension_N"].tolist(), b.recv_ns)
              for b in reader]
    return blocks, [st.as_dict() for st in reader.stats]


@pytest.mark.parametrize("seed", range(12))
def test_read_ahead_reads_exactly_what_the_plain_reader_reads(log, tmp_path, seed):
    """The read-ahead thread inflates and decodes the next chunk early; on intact, cut and
    damaged files alike the blocks and every statistic equal those of reading in line."""
    path, data, _ = log
    rng = np.random.default_rng(100 + seed)
    bad = bytearray(data[:rng.integers(len(data) // 2, len(data) + 1)])
    for pos in rng.integers(0, len(bad), seed % 4 * 3):  # seed 0, 4, 8: only cut
        bad[pos] ^= int(rng.integers(1, 256))
    p = tmp_path / f"ra{seed}.mcap"
    p.write_bytes(bytes(bad))
    ahead, plain = _blocks_and_stats(p, True), _blocks_and_stats(p, False)
    assert ahead == plain
    assert len(ahead[0]) > 0 or ahead[1][0]["error"]
    if seed == 0:
        assert _blocks_and_stats(path, True) == _blocks_and_stats(path, False)


def test_read_ahead_inflates_the_chunk_after_the_message_indexes(log):
    path, data, chunks = log
    first, second = chunks[0], chunks[1]
    with open(path, "rb") as f:
        ahead = ReadAhead(f.fileno(), len(data), lambda raw, arg: (len(raw), arg))
        try:
            ahead.schedule(first.chunk_start_offset + first.chunk_length, "ctx")
            inflated, then = ahead.take(second.chunk_start_offset)
            ahead.schedule(first.chunk_start_offset + first.chunk_length)
            assert ahead.take(second.chunk_start_offset + 1) is None  # not the chunk asked for
            assert ahead.take(second.chunk_start_offset) is None  # nothing scheduled
        finally:
            ahead.close()
    assert inflated.error is None and not inflated.cut
    assert then == (second.uncompressed_size, "ctx")
    assert (inflated.t_lo, inflated.t_hi) == (second.message_start_time, second.message_end_time)


def test_read_ahead_falls_back_when_its_worker_fails(log, tmp_path):
    path, data, chunks = log
    first, second = chunks[0], chunks[1]
    with open(path, "rb") as f:
        ahead = ReadAhead(f.fileno(), len(data) + 10_000, lambda raw, arg: 1 / 0)
        try:
            ahead.schedule(first.chunk_start_offset + first.chunk_length)
            assert ahead.take(second.chunk_start_offset) is None
            ahead.schedule(len(data) + 5)  # past the real end: pread returns too little
            assert ahead.take(len(data) + 5) is None
        finally:
            ahead.close()


def _mcap_library_log(path, n=120):
    """A log written as `buoymon record` writes (mcap's Writer: a channel is defined inside the
    first chunk that uses it, and again in the summary)."""
    from mcap.writer import CompressionType, Writer

    from monitor import codec

    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD, chunk_size=2000)
        w.start(profile="", library="test")
        sid = w.register_schema(codec.schema_name("tension"), "protobuf",
                                codec.file_descriptor_set("tension"))
        cid = w.register_channel("buoy/b1/sensor/tension", "protobuf", sid)
        for k in range(n):
            t = T0 + k * S + np.arange(20, dtype=np.int64) * (S // 20)
            block = SampleBlock("b1", "tension", t, {"tension_N": k * 20 + np.arange(20.0)})
            w.add_message(cid, log_time=T0 + (k + 1) * S, publish_time=int(t[0]),
                          data=codec.encode_block(block))
        w.finish()
    with open(path, "rb") as f:
        return sorted(make_reader(f).get_summary().chunk_indexes,
                      key=lambda c: c.chunk_start_offset)


def test_channel_defined_only_in_a_damaged_chunk_comes_from_the_summary(tmp_path):
    path = tmp_path / "recorded.mcap"
    chunks = _mcap_library_log(path)
    first = chunks[0]
    bad = bytearray(path.read_bytes())
    bad[first.chunk_start_offset + first.chunk_length - 5] ^= 0xFF  # in its compressed records
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(bad))
    _, st, values = _read(damaged)
    n_first = _messages_in(damaged, first)
    assert 0 < n_first < N_SECONDS
    assert np.array_equal(values, np.arange(n_first * 20, N_SECONDS * 20.0))
    assert not st.skipped and [lost.messages for lost in st.lost] == [n_first]
    # the summary itself damaged: it is ignored, the data section alone is read as before
    bad[-40] ^= 0xFF
    damaged.write_bytes(bytes(bad))
    _, st, values = _read(damaged)
    assert values.shape[0] == 0 and sum(st.skipped.values()) == N_SECONDS - n_first
    _, st, values = _read(path)
    assert np.array_equal(values, np.arange(N_SECONDS * 20.0)) and not st.lost


def test_without_message_index_a_lost_chunk_has_an_unknown_count(tmp_path):
    """The default writer leaves Message Index records out (bytes): a chunk lost to a bad CRC
    is still reported with its time range, its message count as unknown."""
    path, chunks = _write_log(tmp_path / "plain.mcap")
    assert all(c.message_index_length == 0 for c in chunks) and len(chunks) >= 10
    victim = chunks[3]
    bad = bytearray(path.read_bytes())
    bad[victim.chunk_start_offset + 9 + 24] ^= 0xFF
    p = tmp_path / "badcrc.mcap"
    p.write_bytes(bytes(bad))
    _, st, values = _read(p)
    (lost,) = st.lost
    assert lost.reason == "bad chunk CRC" and lost.messages is None
    assert (lost.start_ns, lost.end_ns) == (victim.message_start_time, victim.message_end_time)
    n_lost = (victim.message_end_time - victim.message_start_time) // S + 1  # 1 message / s
    assert values.shape[0] == (N_SECONDS - n_lost) * 20 and st.complete


def test_recorded_forecasts_before_the_damage_are_kept_and_the_loss_said(tmp_path, caplog):
    """A daemon recording cut by a power loss: the forecasts recorded before the cut are
    handed to the replay, and the log says how many (was "forecasts not read: unknown (opcode
    60) record has length 11604757896567918889 ...", as if none had been)."""
    import json

    from mcap.writer import Writer

    from replay.forecast_log import read_forecasts

    path = tmp_path / "rec.mcap"
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=256)  # one ~400-byte forecast per chunk
        w.start()
        ch = w.register_channel("buoy/b1/forecast/waves", "json", schema_id=0)
        for k in range(6):
            # incompressible padding: each chunk stays ~400 bytes on disk
            doc = {"time_s": [k * 3600.0], "hs_m": [1.0], "tp_s": [5.0],
                   "note": np.random.default_rng(k).bytes(150).hex()}
            w.add_message(ch, log_time=T0 + k * S, data=json.dumps(doc).encode(),
                          publish_time=T0 + k * S)
        w.finish()
    assert [due for _, _, due in read_forecasts([path])] == [T0 + k * S for k in range(6)]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2 + 7])
    got = read_forecasts([cut])
    assert 0 < len(got) < 6
    assert [(b, d["time_s"], due) for b, d, due in got] == [
        ("b1", [k * 3600.0], T0 + k * S) for k in range(len(got))]
    assert (f"{cut}: damaged or not MCAP" in caplog.text
            and f"forecasts past the damage not read, {len(got)} read before it" in caplog.text)
    # the reason is named, not an empty "()" (mcap's EndOfFile, raised for this cut, carries
    # no message)
    caplog.clear()
    for end in range(path.stat().st_size // 2, path.stat().st_size // 2 + 64):
        cut.write_bytes(path.read_bytes()[:end])
        assert 0 < len(read_forecasts([cut])) < 6
    assert f"{cut}: damaged or not MCAP (EndOfFile)" in caplog.text
    assert f"{cut}: damaged or not MCAP ()" not in caplog.text


@pytest.mark.parametrize("cpus, threads", [({0}, 0), ({3}, 0), ({0, 1}, 1), ({0, 2, 5}, 1)])
def test_the_reader_reads_ahead_only_with_a_cpu_to_spare(log, monkeypatch, cpus, threads):
    """Default rule (replay.chunks.read_ahead_pays): a process allowed one CPU reads in line
    (the thread would cost CPU and save no time), one allowed more starts the thread."""
    import replay.salvage

    path, _, _ = log
    started = []

    class Counted(ReadAhead):
        def __init__(self, *a):
            started.append(1)
            super().__init__(*a)

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(cpus))
    monkeypatch.setattr(replay.salvage, "ReadAhead", Counted)
    reader = LogReader(path, coalesce=False)
    assert reader.read_ahead is (threads == 1)
    blocks = list(reader)
    assert len(started) == threads
    assert len(blocks) == N_SECONDS
    for k, b in enumerate(blocks):
        assert np.array_equal(b.t_ns, T0 + k * S + np.arange(20) * (S // 20))
        assert np.array_equal(b.fields["tension_N"], k * 20 + np.arange(20.0))
    # an explicit choice wins over the rule
    assert LogReader(path, read_ahead=True).read_ahead is True


def test_read_ahead_pays_when_the_cpus_outnumber_the_replaying_processes():
    from replay.chunks import read_ahead_pays

    assert not read_ahead_pays(1, cpus=1)
    assert read_ahead_pays(1, cpus=2)
    assert not read_ahead_pays(2, cpus=2)  # a 2-worker pool on 2 cores: every core busy
    assert read_ahead_pays(2, cpus=4)
    assert not read_ahead_pays(8, cpus=4)


@pytest.mark.parametrize("writer", ["buoymon", "mcap"])
def test_bytes_after_the_log_s_end_are_counted_not_silently_ignored(log, tmp_path, writer):
    """A sound log (ours, or mcap's own writer with its summary and offsets) with bytes after
    its closing magic: every sample read as before, the bytes counted; the log alone: none."""
    path = log[0] if writer == "buoymon" else tmp_path / "lib.mcap"
    if writer == "mcap":
        _mcap_library_log(path)
    data = path.read_bytes()
    assert data.endswith(b"\x89MCAP0\r\n")
    assert _read(path)[1].trailing_bytes == 0 and "trailing_bytes" not in _read(path)[1].as_dict()
    for junk in (b"\x00" * 4096, b"x", os.urandom(333), b"\x05" + b"\xff" * 20):
        spoilt = tmp_path / "junk.mcap"
        spoilt.write_bytes(data + junk)
        _, st, values = _read(spoilt)
        assert np.array_equal(values, np.arange(N_SECONDS * 20.0))
        assert st.complete and not st.lost and st.trailing_bytes == len(junk)
        assert st.as_dict()["trailing_bytes"] == len(junk)


def test_a_log_cut_inside_its_closing_magic_has_no_trailing_bytes(log, tmp_path):
    cut = tmp_path / "cutmagic.mcap"
    cut.write_bytes(log[1][:-3])
    _, st, values = _read(cut)
    assert np.array_equal(values, np.arange(N_SECONDS * 20.0))
    assert st.trailing_bytes == 0 and not st.lost


def test_a_second_log_appended_is_reported_as_not_read(log, tmp_path):
    """`cat a.mcap b.mcap > c.mcap`: the first log is read, the second is a loss of unknown
    size at its offset (its messages are not read), not silence."""
    data = log[1]
    joined = tmp_path / "joined.mcap"
    joined.write_bytes(data + data)
    _, st, values = _read(joined)
    assert np.array_equal(values, np.arange(N_SECONDS * 20.0))
    assert st.trailing_bytes == len(data)
    (lost,) = st.lost
    assert lost.offset == len(data) and lost.messages is None
    assert lost.reason.startswith(f"another MCAP log ({len(data):,d} bytes) after the end")


def test_replay_command_reports_the_bytes_after_a_log_s_end(log, tmp_path):
    """The real command line on a real log with 1000 bytes appended: same figures as the
    sound log, and the bytes counted on stdout and in the report."""
    import json
    import subprocess
    import sys

    path, data, _ = log
    spoilt = tmp_path / "spoilt.mcap"
    spoilt.write_bytes(data + os.urandom(1000))
    env = {**os.environ, "PYTHONPATH": str(os.path.dirname(os.path.dirname(__file__)))}
    outs = {}
    for p in (path, spoilt):
        run = subprocess.run([sys.executable, "-m", "monitor.cli", "replay", str(p), "--report",
                              str(tmp_path / f"{p.stem}.json"), "--no-progress"],
                             env=env, capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr
        outs[p.stem] = run.stdout, json.loads((tmp_path / f"{p.stem}.json").read_text())
    good, bad = outs["good"], outs["spoilt"]
    assert "damaged input" not in good[0]
    assert f"  damaged input: 1,000 bytes after the end of the log in {spoilt} (not read)" \
        in bad[0].splitlines()
    (f,) = bad[1]["inputs"]["read"]["files"]
    assert f["trailing_bytes"] == 1000 and f["complete"] and f["lost"] == []
    assert bad[1]["samples"] == good[1]["samples"] and bad[1]["components"] == good[1]["components"]
