"""Clock faults of sensor streams, seen by the live daemon on the logger's wall clock.

Two faults, per stream, checked on every received block (before the pipeline sees it; the
pipeline still decides what is accepted, so rejected data stays rejected):

* **clock skew**: the block's newest sample time lies more than ``[health] clock_skew_max_s``
  outside the span in which the block is known to have existed, from its publication (the
  publisher's clock) to its arrival (the logger clock): ahead of its arrival, the reference
  of the pipeline's ``time_ahead`` (:mod:`monitor.time_ahead`; a replay's MCAP log_time),
  or behind its publication (a message fetched from a publisher's cache arrives late by
  design: not behind for that) (a sensor clock a year ahead or behind, an unset RTC);
* **time restart**: the block's newest sample is older, by more than ``[health]
  time_restart_min_s``, than the newest sample time this stream already sent in this daemon
  life (a sensor or publisher restarted with an older clock). Only this life is compared: a
  re-delivery after a daemon restart (samples at or before the checkpoint) is not a restart.
  The fault holds until the stream catches up with its previous newest time. A block time
  ``time_ahead`` of its arrival (:func:`monitor.time_ahead.is_ahead` of the block's receive
  time, as the pipeline rejects it) is not taken as the newest: the stream going on at the
  right time after it is no restart.

Both are counted, give a log line (the caller rate-limits it) and show as status fields,
from which :mod:`monitor.alerts.live` raises the ``clock_skew`` and ``time_restart`` alerts.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from monitor.time_ahead import DEFAULT_MAX_AHEAD_S, is_ahead

NS = 1_000_000_000


@dataclass
class StreamClock:
    """Clock figures of one stream in this daemon life."""

    newest_ns: int | None = None  # newest sample time received (this life)
    skew_s: float | None = None  # newest sample time of the last block minus arrival time
    skewed_blocks: int = 0
    time_restarts: int = 0
    behind_s: float = 0.0  # > 0 while the stream is behind its previous newest time
    last_jump_s: float = 0.0  # how far back the last restart went

    def to_dict(self) -> dict[str, Any]:
        return {"clock_skew_s": self.skew_s, "clock_skewed_blocks": self.skewed_blocks,
                "time_restarts": self.time_restarts, "time_behind_s": self.behind_s,
                "time_restart_jump_s": self.last_jump_s}


class ClockFaults:
    """Per-stream clock-skew and time-restart detection."""

    def __init__(self, skew_max_s: float, restart_min_s: float,
                 max_ahead_s: float = DEFAULT_MAX_AHEAD_S) -> None:
        self.skew_max_s = skew_max_s
        self.restart_min_ns = int(restart_min_s * NS)
        self.max_ahead_ns = int(round(max_ahead_s * NS))
        self.streams: dict[str, StreamClock] = {}

    def observe(self, sensor: str, t_last_ns: int, recv_ns: int,
                sent_ns: int | None = None) -> list[str]:
        """Check one block of newest sample time ``t_last_ns``, received at ``recv_ns`` (the
        block's ``recv_ns``: what the pipeline judges ``time_ahead`` against) and published
        at ``sent_ns`` (None: unknown); returns a message per fault found (for the caller to
        log)."""
        s = self.streams.setdefault(sensor, StreamClock())
        out = []
        # the distance of the sample time from [publication, arrival] (module docstring)
        first_ns = recv_ns if sent_ns is None else min(sent_ns, recv_ns)
        s.skew_s = (t_last_ns - min(max(t_last_ns, first_ns), recv_ns)) / NS
        if abs(s.skew_s) > self.skew_max_s:
            s.skewed_blocks += 1
            out.append(f"stream {sensor}: sensor time is {abs(s.skew_s):.6g} s "
                       f"{'ahead of' if s.skew_s > 0 else 'behind'} the logger clock "
                       f"(allowed {self.skew_max_s:g} s)")
        if s.newest_ns is not None and t_last_ns < s.newest_ns - self.restart_min_ns:
            behind = (s.newest_ns - t_last_ns) / NS
            if s.behind_s == 0.0:  # a new restart, not the continuation of one
                s.time_restarts += 1
                s.last_jump_s = behind
            s.behind_s = behind
            out.append(f"stream {sensor}: time restarted {s.behind_s:.6g} s in the past "
                       "(its samples are rejected as time_backwards until it catches up)")
        else:
            s.behind_s = 0.0
        if not is_ahead(t_last_ns, recv_ns, self.max_ahead_ns):
            s.newest_ns = t_last_ns if s.newest_ns is None else max(s.newest_ns, t_last_ns)
        return out

    def fields(self, sensor: str) -> dict[str, Any]:
        """Status fields of ``sensor`` (defaults for a stream not seen in this life)."""
        return self.streams.get(sensor, StreamClock()).to_dict()
