"""Sample times too far ahead of their receive time: ``time_ahead`` rejections.

A sample's sensor time may not run ahead of the clock that received it (live: the daemon's or
bridge's clock; replay: the MCAP ``log_time``, which the daemon recorded as that clock) by
more than ``max_ahead_s`` (``[ordering] max_ahead_s``, default :data:`DEFAULT_MAX_AHEAD_S`,
the daemon's ``[health] clock_skew_max_s`` default). Such a time is corrupt or from a wrong
clock (a flipped digit of the year, an unset RTC). Accepted, it would become the stream's
newest time and every later good sample would be ``time_backwards``, for good; rejected
(counted as ``time_ahead``) the stream goes on. The pipeline drops these samples before the
ordering sees them (they would also push its watermark into the future).

A clock that is genuinely and steadily ahead loses its samples in the pipeline the same way,
counted, and the daemon's ``clock_skew`` alert (:mod:`monitor.clock_faults`) names it; the
samples stay in the recorded log, so a replay with a larger ``max_ahead_s`` takes them. (The
bridge keeps a steadily-ahead instrument's pace and drops only a leap,
:mod:`monitor.bridge.runner`, with the same test below.)

The test depends only on the sample and its receive time, so it gives the same verdict in any
split of a stream into blocks, after a restart and in replay. In a coalesced replay
(``replay.reader``) a block's receive time is the latest of its messages, so a sample less than
``max_ahead_s`` plus the coalescing span ahead of its own receive time may pass there.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from monitor.blocks import SampleBlock

DEFAULT_MAX_AHEAD_S = 600.0


def is_ahead(t_ns: int, recv_ns: int, max_ahead_ns: int) -> bool:
    """Sensor time ``t_ns`` is more than ``max_ahead_ns`` ahead of receive time ``recv_ns``."""
    return t_ns - recv_ns > max_ahead_ns


def pace_ns(t_ns: int, recv_ns: int) -> int:
    """The time to pace a replayed or re-published block at: its sensor time ``t_ns``, or its
    receive time when that is earlier (a sensor time ahead of it, e.g. a flipped year digit,
    made a paced replay sleep until then: a year at real time). ``recv_ns`` 0: unknown."""
    return min(t_ns, recv_ns) if recv_ns else t_ns


def drop_ahead(block: SampleBlock, max_ahead_ns: int) -> tuple[SampleBlock, int]:
    """``block`` without its samples :func:`is_ahead` of its receive time, and how many went.

    A block of unknown receive time (``recv_ns`` 0: a file or test without one) is kept whole.
    """
    if not block.recv_ns or not len(block) or not is_ahead(
            int(block.t_ns.max()), block.recv_ns, max_ahead_ns):
        return block, 0  # the usual case: one max per block
    keep = block.t_ns - block.recv_ns <= max_ahead_ns
    return (dataclasses.replace(block, t_ns=block.t_ns[keep],
                                fields={f: v[keep] for f, v in block.fields.items()}),
            int(keep.shape[0] - np.count_nonzero(keep)))
