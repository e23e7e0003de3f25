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
