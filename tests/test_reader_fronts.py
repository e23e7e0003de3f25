"""The reader decodes a run of records behind room for the samples the merge still holds of
each stream and copies them there: the release's first block of a stream is then a view of
the new run's array, not a join, and every block is what it is without that room."""

from __future__ import annotations

import numpy as np
import pytest

from replay.merge import StreamMerge
from replay.reader import LogReader
from replay.writer import LogWriter, Series

T0 = 1_700_000_000 * 10**9


def _log(path) -> None:
    """20 min of 20 Hz tension and 10 Hz IMU in 1-s blocks, in chunks of ~5 min of samples,
    some IMU blocks out of order by a few seconds (within the reorder window)."""
    rng = np.random.default_rng(4)
    with LogWriter(path, chunk_size=64 << 10) as w:
        for minute in range(20):
            series = []
            for sensor, rate, nf in (("tension", 20, 1), ("imu", 10, 3)):
                n = 60 * rate
                t = T0 + minute * 60 * 10**9 + np.arange(n, dtype=np.int64) * (10**9 // rate)
                series.append(Series("b1", sensor, t, rng.normal(100.0, 5.0, (nf, n))))
            w.write_series(series)


def _blocks(path, read_ahead: bool) -> list:
    return [(b.topic, b.t_ns.copy(), {k: v.copy() for k, v in b.fields.items()}, b.recv_ns, b)
            for b in LogReader(path, read_ahead=read_ahead)]


@pytest.mark.parametrize("read_ahead", [False, True])
def test_room_for_held_samples_gives_the_same_blocks_as_views(tmp_path, monkeypatch,
                                                              read_ahead):
    path = tmp_path / "log.mcap"
    _log(path)
    with_room = _blocks(path, read_ahead)
    monkeypatch.setattr(StreamMerge, "fronts", lambda self, ahead=False: {})
    without = _blocks(path, read_ahead)
    assert len(with_room) == len(without) > 8
    for a, b in zip(with_room, without):
        assert a[0] == b[0] and a[3] == b[3] and a[1].tobytes() == b[1].tobytes()
        assert {k: v.tobytes() for k, v in a[2].items()} == {k: v.tobytes()
                                                             for k, v in b[2].items()}
    # without room, a release's first block of a stream joins two runs' arrays (a new
    # array); with it, every block of a stream is a view of a decoded run's samples
    def joined(blocks):
        return sum(b[4].t_ns.base is None for b in blocks)
    assert joined(without) >= 4
    assert joined(with_room) == 0 if not read_ahead else joined(with_room) < joined(without)
