"""Duplicate and out-of-order samples are ordered and removed in one layer, the pipeline's
(monitor.ordering, monitor.validate), live and in replay alike (issue 18): inside one log file,
across overlapping files and live, every copy of a sample met while its original is still in
the ordering is counted once, in ``samples.<stream>.rejected.duplicate``, copies of rejected
samples included (not judged again); everything else, alerts included (a copy is no
measurement, so no rejection in a tick's counts), is the clean data's to the last bit."""

import numpy as np
import pytest

from monitor.blocks import SampleBlock
from monitor.config import default_config
from monitor.pipeline import Pipeline
from replay.reader import LogReader
from replay.runner import replay_logs
from replay.writer import LogWriter
from synthetic_buoy import blocks_interleaved, sea


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """1-s blocks of tension, imu and gnss over 10 minutes as a log holds them (quantised),
    and the replay report of that log."""
    path = _write(tmp_path_factory.mktemp("clean") / "clean.mcap",
                  blocks_interleaved(sea(600), 1))
    blocks = list(LogReader(path, coalesce=False))
    rep = replay_logs(default_config(), [path]).report
    assert all(v["rejected"]["duplicate"] == 0 for v in rep["samples"].values())
    assert rep["samples"]["tension"]["rejected"]["nan"] > 0  # copies of rejected samples too
    return blocks, rep


def _with_copies(blocks, every=7, swap_every=13):
    """Every ``every``-th block twice (the copy right behind it), and every ``swap_every``-th
    pair of neighbours swapped; returns the blocks and the copied samples per stream."""
    out, copied = [], {}
    for i, b in enumerate(blocks):
        out.append(b)
        if i % every in (3, 4):  # every stream
            out.append(b)
            copied[b.sensor] = copied.get(b.sensor, 0) + len(b)
    for i in range(5, len(out) - 1, swap_every):
        out[i], out[i + 1] = out[i + 1], out[i]
    return out, copied


def _write(path, blocks):
    with LogWriter(path) as w:
        for b in blocks:
            w.write_block(b, recv_ns=b.t_last_ns + 1)
    return path


def _check(report, clean, copied):
    """The report is the clean one but for the duplicate counts, which hold every copy."""
    assert copied and all(n > 0 for n in copied.values())
    for s, n in copied.items():
        want = dict(clean["samples"][s]["rejected"], duplicate=n)
        assert report["samples"][s]["rejected"] == want, s
    skip = ("samples", "inputs")  # the files read differ
    assert ({k: v for k, v in report.items() if k not in skip}
            == {k: v for k, v in clean.items() if k not in skip})
    assert list(clean["samples"]) == list(report["samples"])
    assert "duplicates" not in report.get("inputs", {}).get("read", {})  # one count only


def test_copies_and_disorder_inside_one_file(tmp_path, clean):
    blocks, copied = _with_copies(clean[0])
    got = replay_logs(default_config(), [_write(tmp_path / "a.mcap", blocks)]).report
    _check(got, clean[1], copied)


def test_overlapping_files(tmp_path, clean):
    blocks = clean[0]
    cut = len(blocks) // 2
    a = _write(tmp_path / "a.mcap", blocks[:cut + 30])  # the last 30 blocks are also in b
    b = _write(tmp_path / "b.mcap", blocks[cut:])
    copied: dict[str, int] = {}
    for blk in blocks[cut:cut + 30]:
        copied[blk.sensor] = copied.get(blk.sensor, 0) + len(blk)
    got = replay_logs(default_config(), [a, b]).report
    _check(got, clean[1], copied)


def test_live_copies_and_disorder_equal_their_replay(tmp_path, clean):
    """Live: neighbours swapped, and a copy of a tension block right behind it (a publisher's
    cache re-sending what the ordering still holds: the motion stream gates it). A copy
    arriving after the ordering released its original is ``time_backwards`` instead (the
    pipeline keeps no history of times), as any sample at or before the processed time."""
    swapped = list(clean[0])
    for i in range(5, len(swapped) - 1, 13):
        swapped[i], swapped[i + 1] = swapped[i + 1], swapped[i]
    blocks, copied, imu_newest = [], {}, 0
    for i, b in enumerate(swapped):
        blocks.append(b)
        if b.sensor == "imu":
            imu_newest = max(imu_newest, b.t_last_ns)
        held = imu_newest < b.t_first_ns  # the motion stream has not reached this block
        if b.sensor == "tension" and i % 5 == 0 and held:
            blocks.append(b)
            copied["tension"] = copied.get("tension", 0) + len(b)
    ref = Pipeline(default_config())  # the live ordering horizon
    for b in clean[0]:
        ref.process(b)
    ref.flush()
    live = Pipeline(default_config())
    for b in blocks:
        live.process(b)
    live.flush()
    got = live.report()
    _check(got, ref.report(), copied)
    replayed = replay_logs(default_config(), [_write(tmp_path / "rec.mcap", blocks)]).report
    assert replayed["samples"] == got["samples"]
    for name, comp in got["components"].items():
        assert replayed["components"][name]["damage_committed"] == comp["damage_committed"]


def test_the_shipped_rejected_rate_rule_fires_on_glitches_of_any_stream(tmp_path, clean):
    """The shipped rule (5 % over 600 s, every stream) on the IMU: every 5th sample NaN from
    300 s on. The window holds all samples so far (t <= T at the 10-s tick T: 10 T + 1 of them,
    (10 T - 3000) / 5 + 1 NaN), so the fraction first exceeds 5 % at T = 400 s (201 / 4001;
    390 s: 181 / 3901 = 4.6 %), and it is the only rule firing that the clean log does not. The copies of the test above
    fire nothing."""
    from synthetic_buoy import S, T0

    def glitched(b):
        if b.sensor != "imu":
            return b
        bad = ((b.t_ns - T0) >= 300 * S) & (((b.t_ns - T0) // (S // 10)) % 5 == 0)
        return SampleBlock(b.buoy_id, b.sensor, b.t_ns,
                           {f: np.where(bad, np.nan, v) for f, v in b.fields.items()}, b.recv_ns)

    got = replay_logs(default_config(), [_write(tmp_path / "g.mcap", map(glitched, clean[0]))]
                      ).report
    def key(a):
        return a["rule"], a["labels"]["component"]

    clean_fired = {key(a) for a in clean[1]["alerts"]}
    fired = [a for a in got["alerts"] if a["state"] == "firing" and key(a) not in clean_fired]
    assert [key(a) for a in fired] == [("rejected_rate", "imu")]
    assert (fired[0]["at_ns"], fired[0]["value"]) == (T0 + 400 * S, 201 / 4001)
    assert got["samples"]["imu"]["rejected"]["nan"] == 600
    assert not any(a["rule"] == "rejected_rate" for a in clean[1]["alerts"])
