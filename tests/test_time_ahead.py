"""A sample time far ahead of its receive time is ``time_ahead`` and the stream goes on
(monitor.time_ahead). Was: a tension sample dated a year ahead was accepted and every later
good sample was ``time_backwards`` for good. The live daemon is tested in
tests/test_daemon_e2e.py."""

import dataclasses
import json

import numpy as np
import pytest

from monitor.blocks import SampleBlock
from monitor.config import ConfigError, config_with, default_config
from monitor.time_ahead import DEFAULT_MAX_AHEAD_S, drop_ahead
from replay.runner import replay_logs
from replay.writer import LogWriter
from synthetic_buoy import blocks_interleaved, sea

YEAR_NS = 365 * 86400 * 10**9
MAX_NS = int(DEFAULT_MAX_AHEAD_S * 1e9)


def _block(t_ns, recv_ns):
    t = np.asarray(t_ns, np.int64)
    return SampleBlock("vaps", "tension", t, {"tension_N": 3000.0 + np.arange(t.size)}, recv_ns)


def test_drop_ahead_keeps_up_to_the_tolerance_and_blocks_of_unknown_receive_time():
    r = 1_800_000_000 * 10**9
    b = _block([r - 5, r + MAX_NS, r + MAX_NS + 1, r + YEAR_NS, r + 7], r)
    kept, n = drop_ahead(b, MAX_NS)
    assert n == 2 and kept.t_ns.tolist() == [r - 5, r + MAX_NS, r + 7]
    assert kept.fields["tension_N"].tolist() == [3000.0, 3001.0, 3004.0]
    unknown = dataclasses.replace(b, recv_ns=0)  # a file or test without receive times
    assert drop_ahead(unknown, MAX_NS) == (unknown, 0)
    assert drop_ahead(kept, MAX_NS) == (kept, 0)


def _log(path, blocks, corrupt_at=None):
    """``blocks`` as a log, each received 20 ms after its last sample; the ``corrupt_at``-th
    block (a tension one) has its 6th sample's time a year ahead (a flipped year digit)."""
    with LogWriter(path) as w:
        for i, b in enumerate(blocks):
            recv = int(b.t_ns.max()) + 20_000_000
            if i == corrupt_at:
                t = b.t_ns.copy()
                t[5] += YEAR_NS
                b = dataclasses.replace(b, t_ns=t)
            w.write_block(b, recv_ns=recv)
    return path


def _drop_sixth(b):
    keep = np.arange(len(b)) != 5
    return dataclasses.replace(b, t_ns=b.t_ns[keep],
                               fields={f: v[keep] for f, v in b.fields.items()})


@pytest.fixture(scope="module")
def blocks():
    out = blocks_interleaved(sea(300), 1)
    k = [i for i, b in enumerate(out) if b.sensor == "tension"][100]
    return out, k


def test_replay_rejects_a_year_ahead_sample_and_keeps_the_rest(tmp_path, blocks):
    """The log with the corrupt sample replays as the log without that sample, but for one
    ``time_ahead`` count (no ``time_backwards``: the stream went on)."""
    out, k = blocks
    got = replay_logs(default_config(), [_log(tmp_path / "bad.mcap", out, k)]).report
    without = [_drop_sixth(b) if i == k else b for i, b in enumerate(out)]
    want = replay_logs(default_config(), [_log(tmp_path / "good.mcap", without)]).report
    rej = got["samples"]["tension"]["rejected"]
    assert rej["time_ahead"] == 1 and rej["time_backwards"] == 0
    assert want["samples"]["tension"]["rejected"]["time_ahead"] == 0
    want["samples"]["tension"]["rejected"]["time_ahead"] = 1
    skip = ("inputs",)  # the files read differ
    assert ({k_: v for k_, v in got.items() if k_ not in skip}
            == {k_: v for k_, v in want.items() if k_ not in skip})


def test_a_larger_tolerance_takes_the_sample_and_the_stream_is_poisoned(tmp_path, blocks):
    """``[ordering] max_ahead_s`` over a year: the corrupt sample is accepted and the later
    tension samples are ``time_backwards`` (the last minute of five: what the tolerance
    prevents)."""
    out, k = blocks
    base = default_config()
    cfg = config_with(base, ordering={**base.section("ordering"), "max_ahead_s": 2 * YEAR_NS / 1e9})
    got = replay_logs(cfg, [_log(tmp_path / "bad.mcap", out, k)]).report
    rej = got["samples"]["tension"]["rejected"]
    assert rej["time_ahead"] == 0 and rej["time_backwards"] >= 1000


def test_the_tolerance_must_be_positive():
    with pytest.raises(ConfigError, match="max_ahead_s"):
        base = default_config()
        config_with(base, ordering={**base.section("ordering"), "max_ahead_s": 0})


def test_the_sample_count_includes_time_ahead_samples_with_the_stream_stage_on_a_thread(blocks):
    """run_blocks counts the samples read, time_ahead ones included, in each mode (the thread
    mode counted its hand-over's block, from which they are dropped), and gives the same
    report and state in one thread, on two and with the child process."""
    from replay.runner import run_blocks

    out, k = blocks
    fed = []
    for i, b in enumerate(out):
        b = dataclasses.replace(b, recv_ns=int(b.t_ns.max()) + 20_000_000)
        if i == k:
            t = b.t_ns.copy()
            t[5] += YEAR_NS
            b = dataclasses.replace(b, t_ns=t)
        fed.append(b)
    total = sum(len(b) for b in fed)
    outs = []
    for mode in ({}, {"threads": True}, {"child": True}):
        pipeline, result = run_blocks(default_config(), iter(fed), **mode)
        assert pipeline.validators["tension"].rejected["time_ahead"] == 1
        assert (result.blocks, result.samples) == (len(fed), total)
        outs.append(json.dumps([pipeline.report(), pipeline.state()], allow_nan=True))
    assert outs[1] == outs[0] and outs[2] == outs[0]  # the same bits in every mode


def _log_with_a_block_a_year_ahead(path) -> None:
    """Three 1-s tension blocks on the logger's clock; the second's sensor time a year ahead."""
    t0 = 946_684_800 * 10**9
    with LogWriter(path) as w:
        for k in range(3):
            t = t0 + k * 10**9 + 50_000_000 * np.arange(20, dtype=np.int64)
            recv = int(t[-1])
            w.write_block(_block(t + YEAR_NS if k == 1 else t, recv), recv_ns=recv)


def test_a_paced_replay_does_not_sleep_until_a_block_a_year_ahead(tmp_path, monkeypatch):
    """`buoymon replay --speed 100` of a 3-s log with one block a year ahead waited ~3.6 days
    (the pacing followed that block's sensor time); now it follows the receive time there."""
    import replay.runner

    _log_with_a_block_a_year_ahead(tmp_path / "a.mcap")
    slept: list[float] = []
    monkeypatch.setattr(replay.runner.time, "sleep", slept.append)
    report = replay_logs(default_config(), [tmp_path / "a.mcap"], speed=100.0,
                         show_progress=False).report
    assert report["samples"]["tension"]["rejected"]["time_ahead"] == 20
    assert report["samples"]["tension"]["accepted"] == 40
    assert slept and max(slept) < 0.03  # 2 s of data at 100 x: 0.02 s at most


def test_a_paced_publisher_does_not_sleep_until_a_block_a_year_ahead(tmp_path):
    """`python -m replay.publish --speed 100` of the same log: the same wait, the same fix."""
    from monitor import zenoh_io
    from monitor.daemon_config import ZenohConfig
    from monitor.publisher import publish_blocks
    from replay.reader import iter_blocks

    _log_with_a_block_a_year_ahead(tmp_path / "a.mcap")
    slept: list[float] = []
    with zenoh_io.open_session(ZenohConfig(listen=())) as session:
        n = publish_blocks(session, iter_blocks([str(tmp_path / "a.mcap")], coalesce=False),
                           zenoh_io.ProtobufCodec(), speed=100.0, clock=lambda: 0.0,
                           sleep=slept.append)
    assert n == 3
    assert slept and max(slept) <= 0.02  # the last block 2 s after the first, at 100 x
