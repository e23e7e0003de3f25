"""Runs the configured sources: lines -> samples -> blocks -> publisher, and the status.

One thread reads every source (:class:`monitor.bridge.transports.Links`), parses, cuts
blocks, publishes and reports. It sleeps until a source is readable or the next timed duty
is due (a block to close on the wall clock, a state to change, the status, a transport's
own); near a block's close every read is immediate, so the block goes out as soon as its
closing line arrives (between blocks reads gather: ``_GATHER_S``), and the lines of a read
are parsed at once (:func:`monitor.bridge.formats.bulk_parser`). A block closes when a
sample lies ``block_s`` after its first one, or when ``block_s`` of wall-clock time has
passed since its first sample arrived (a quiet instrument still gets its samples out).
Times must increase strictly within a source: a sample at or before the last one is counted
(``time_backwards``) and dropped, so no garbage time reaches the monitor. A corrupt time stamp
far in the future would make every later sample ``time_backwards``, for good: a sample more
than ``_MAX_AHEAD_NS`` ahead of the logger's clock whose time leapt that much further than
the logger's clock since its source's previous sample is counted (``time_ahead``) and dropped
instead (an instrument whose clock is steadily ahead keeps its pace and is not touched).

Status: every ``status_interval_s`` a JSON document on ``buoy/<id>/bridge/status``: per
source its transport, stream, whether connected, its ``state``, counters (lines, samples,
blocks) and rejections by reason, the time source (``instrument`` or ``receive``) and the
ages of the last line and sample. Each reason is logged at most once a minute per source.

A source's ``state`` makes a dead instrument loud within ``stall_s``: ``reading`` (connected,
a line within ``stall_s``, or connected less than ``stall_s`` ago), ``stalled`` (connected,
no line for ``stall_s``: a cable cut on the far side, an instrument hung), ``rejecting``
(connected, lines coming, but none gave a sample for ``stall_s``: a wrong column map, baud
rate or time format, a GNSS without a fix), ``connecting``
(not connected for less than ``stall_s``: starting, a reconnect) and ``disconnected`` (not
connected for ``stall_s``: a device unplugged, a socket refused); the last status of a
bridge that stops says ``stopped``. Each change is logged (a warning when it leaves
``reading``); the daemon alerts on it (``bridge_source``).

:meth:`Bridge.run` serves in a process of its own (``buoymon bridge``), or in a thread of
the daemon (:mod:`monitor.bridge.embedded`).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from bisect import bisect_left
from collections import Counter
from dataclasses import dataclass, field
from itertools import islice
from operator import lt
from typing import Any, Callable

import numpy as np

from monitor.blocks import SENSOR_FIELDS, SampleBlock
from monitor.bridge.config import BridgeConfig, SourceConfig
from monitor.bridge.formats import Rejected, Samples, bulk_parser, parser
from monitor.bridge.transports import FLOOD, LINKS, LineSplitter, Link, Links, ReceiveClock
from monitor.sensors import PublisherOptions, SensorPublisher
from monitor.time_ahead import DEFAULT_MAX_AHEAD_S, is_ahead
from monitor import zenoh_io

log = logging.getLogger("buoymon.bridge")
_LOG_EVERY_S = 60.0
# run(until=...): how often ``until()`` is asked (the only wait that is not on a due duty)
_UNTIL_S = 0.05
# Between blocks a source's lines only wait for their block, so their bytes may wait in the
# kernel's buffers too: after a read the loop pauses up to _GATHER_S and the next read takes
# every line of every source at once (a wake-up with a small read costs ~50 us, as much as
# 30 lines in bulk: bench/bench_bridge.py). Reads are immediate from _NEAR_S before the
# arrival of a block's closing line, so it is not delayed: expected at its sensor time plus
# the source's lag (the least of read time - sensor time of a read's last sample over this
# block and the last: a gathered read's last line came just before it, so the least is the
# instrument's own lag; the read that opened the block gave one). Receive times are taken at
# the read, so a source timed by the bridge (not the instrument) means no pause at all. A
# pause never outgrows what the kernel keeps for a link (Link.pause_limit_s: a tty's 4 kB, a
# UDP socket's datagrams).
_GATHER_S = 0.1
# a flood: bytes coming so fast that this long a pause would gather ``FLOOD`` of them (a
# pause would only slow the reading down)
_FLOOD_S = 0.02
_NEAR_S = 0.01
# reasons that are not faults of the data: header lines of a CSV file (not counted), NMEA
# sentences without a fix of their own (counted, not logged)
_QUIET = {"header_read"}
# a time stamp this far ahead of the logger's clock, reached by a leap of as much: corrupt
# (the pipeline's time_ahead default, the daemon's clock_skew_max_s default)
_MAX_AHEAD_NS = int(DEFAULT_MAX_AHEAD_S * 10**9)
_UNLOGGED = {"other_sentence", "repeat_fix"}


# a read of fewer lines goes one by one: the bulk parser's set-up costs as much as a line
_BULK_MIN = 2


@dataclass
class SourceState:
    cfg: SourceConfig
    parse: Callable[[str, int], Any]
    parse_many: Callable[[list[bytes], int], Samples | None] | None = None
    connected: bool = False
    lines: int = 0
    samples: int = 0
    blocks: int = 0
    rejected: Counter = field(default_factory=Counter)
    events: Counter = field(default_factory=Counter)
    time_source: str | None = None
    last_t_ns: int | None = None
    last_recv_ns: int = 0  # the receive time of the read that gave ``last_t_ns``
    last_read_ns: int | None = None  # the receive time of the link's previous read
    last_sample_mono: float | None = None
    last_line_mono: float | None = None
    # when ``connected`` last changed (or the bridge started): what a state's age counts from
    link_mono: float = field(default_factory=time.monotonic)
    state: str = "connecting"
    # the open block: its first sample's time (None: no block open), its samples' times and
    # values (a list per field: a flat list becomes an array at a tenth of a row's cost)
    first_t: int | None = None
    t: list[int] = field(default_factory=list)
    columns: list[list[float]] = field(default_factory=list)
    block_opened_mono: float = 0.0
    # read time - sensor time (s) of a read's last sample: the least over the open block and
    # over the block before (``_GATHER_S`` comment)
    lag_s: float = math.inf
    lag_before_s: float = math.inf
    logged: dict[str, float] = field(default_factory=dict)

    block_ns: int = 0  # block_s in ns (set from cfg)

    def __post_init__(self) -> None:
        self.block_ns = int(self.cfg.block_s * 1e9)
        self.columns = [[] for _ in SENSOR_FIELDS[self.cfg.sensor]]

    def near_s(self) -> float:
        """When reads turn immediate for the open block's closing line (monotonic s)."""
        assert self.first_t is not None, "no block open"
        return (self.first_t + self.block_ns) * 1e-9 + min(self.lag_s, self.lag_before_s) \
            - _NEAR_S

    def current_state(self, now_mono: float) -> str:
        """``reading``, ``rejecting``, ``stalled``, ``connecting`` or ``disconnected``
        (module docstring)."""
        quiet_s = now_mono - max(self.link_mono, self.last_line_mono or self.link_mono)
        if self.connected:
            if quiet_s > self.cfg.stall_s:
                return "stalled"
            fruitless_s = now_mono - max(self.link_mono, self.last_sample_mono or self.link_mono)
            return "reading" if fruitless_s <= self.cfg.stall_s else "rejecting"
        return "connecting" if quiet_s <= self.cfg.stall_s else "disconnected"

    def status(self, now_mono: float) -> dict[str, Any]:
        return {"sensor": self.cfg.sensor, "transport": self.cfg.transport,
                "format": self.cfg.format, "connected": self.connected, "state": self.state,
                "stall_s": self.cfg.stall_s, "lines": self.lines,
                "samples": self.samples, "blocks": self.blocks,
                "rejected": dict(self.rejected), "events": dict(self.events),
                "time_source": self.time_source,
                "last_line_age_s": _age(now_mono, self.last_line_mono),
                "last_sample_age_s": _age(now_mono, self.last_sample_mono)}


def _leaps_ahead(src: SourceState, t_ns: int, recv_ns: int) -> bool:
    """A corrupt time stamp (module docstring): ``t_ns`` is over ``_MAX_AHEAD_NS`` ahead of
    the logger's clock, and got there by a leap of as much beyond the clock's own advance."""
    return (is_ahead(t_ns, recv_ns, _MAX_AHEAD_NS) and src.last_t_ns is not None
            and is_ahead(t_ns - src.last_t_ns, recv_ns - src.last_recv_ns, _MAX_AHEAD_NS))


def _read_times(src: SourceState, n: int, recv_ns: int) -> list[int]:
    """Each line's receive time for a read of ``n`` lines. A source timed on receipt gets
    its lines spread evenly over the time since the link's previous read (at most
    ``block_s``), the last at ``recv_ns``: they all arrived in that span (a USB serial
    adapter or an instrument sends several lines at once), and one time for all would
    drop every line but the first as ``time_backwards``. Others: ``recv_ns`` for all."""
    prev = src.last_read_ns
    src.last_read_ns = recv_ns
    if n == 1 or src.cfg.time_column is not None or src.cfg.format != "delimited":
        return [recv_ns] * n
    span = src.block_ns if prev is None else min(recv_ns - prev, src.block_ns)
    return [recv_ns - span * (n - 1 - k) // n for k in range(n)]


def _age(now_mono: float, then: float | None) -> float | None:
    return None if then is None else now_mono - then


class Bridge:
    """The bridge of ``cfg``, publishing through ``publisher`` (see :meth:`run`)."""

    def __init__(self, cfg: BridgeConfig, publisher: SensorPublisher) -> None:
        self.cfg = cfg
        self.publisher = publisher
        self.clock = ReceiveClock()
        self.sources = [SourceState(s, parser(s), bulk_parser(s)) for s in cfg.sources]
        self._stop = threading.Event()
        self._links: Links | None = None
        self._status_pub: Any = None
        self._next_status = 0.0
        self._due = 0.0  # the next timed duty (monotonic)
        self._recheck = True  # something may have changed a state or brought a duty forward

    def stop(self) -> None:
        """Ask :meth:`run` to return (safe from signal handlers and other threads)."""
        self._stop.set()
        if self._links is not None:
            self._links.wake()

    def _link(self, i: int) -> Link:
        src = self.sources[i]

        def emit(lines: list[bytes], recv_ns: int) -> None:
            self.handle(i, "lines", lines, recv_ns)

        def event(reason: str) -> None:
            self.handle(i, "event", reason, 0)

        def connected(up: bool) -> None:
            self.handle(i, "connected", up, 0)

        return LINKS[src.cfg.transport](src.cfg, LineSplitter(emit, event, self.clock), event,
                                        connected)

    def open(self) -> None:
        """Declare the status publisher; the links open at the first :meth:`step`."""
        self._status_pub = zenoh_io.declare_json_publisher(
            self.publisher.session, f"buoy/{self.cfg.buoy_id}/bridge/status")
        self._links = Links([self._link(i) for i in range(len(self.sources))])
        self._next_status = time.monotonic()

    def step(self, wait_s: float) -> None:
        """Do the timed duties that are due (open and poll links, close blocks on the wall
        clock, update the states, publish the status), then read what the instruments send,
        waiting up to ``wait_s`` for something (less if a duty falls due sooner). A wake-up
        for data does only the reads: the duties' time is kept, and moved only by what can
        bring it forward (a block opened, a link event, a line after a stall)."""
        assert self._links is not None, "open() first"
        now = time.monotonic()
        if now >= self._due or self._recheck or self._links.stale:
            self._duties(now)
        self._links.pump(min(wait_s, self._due - time.monotonic()))

    def _duties(self, now: float) -> None:
        assert self._links is not None
        self._recheck = False
        self._links.duties(now)
        for src in self.sources:
            if src.first_t is not None and now - src.block_opened_mono >= src.cfg.block_s:
                self._flush(src)
        self._update_states(now)
        if now >= self._next_status:
            self.publish_status()
            self._next_status = now + self.cfg.status_interval_s
        due = min(self._next_status, self._next_state_change(), self._links.next_due())
        for src in self.sources:
            if src.first_t is not None:
                due = min(due, src.block_opened_mono + src.cfg.block_s)
        self._due = due

    def _next_state_change(self) -> float:
        """When a source's quiet time passes ``stall_s`` next (reading or rejecting ->
        stalled, connecting -> disconnected), or its time without a sample does (reading ->
        rejecting)."""
        due = math.inf
        for src in self.sources:
            if src.state in ("reading", "rejecting", "connecting"):
                due = min(due, max(src.link_mono, src.last_line_mono or src.link_mono)
                          + src.cfg.stall_s)
            if src.state == "reading":
                due = min(due, max(src.link_mono, src.last_sample_mono or src.link_mono)
                          + src.cfg.stall_s)
        return due

    def close(self) -> None:
        """Close the links, flush every block, publish a last status (``stopped``)."""
        if self._links is not None:
            self._links.close()
            self._links = None
        for src in self.sources:
            self._flush(src)
            src.state = "stopped"
        if self._status_pub is not None:
            self.publish_status()
            self._status_pub.undeclare()
            self._status_pub = None

    def run(self, until: Callable[[], bool] | None = None) -> None:
        """Serve until :meth:`stop` (or ``until()``, asked every ``_UNTIL_S``); flushes what
        is buffered at the end."""
        self.open()
        wait_s = math.inf if until is None else _UNTIL_S
        try:
            while not self._stop.is_set() and not (until is not None and until()):
                pause = self._gather_s(time.monotonic())
                if pause > 0:
                    time.sleep(pause)
                self.step(wait_s)  # then ``until()``: it sees what this step read
        finally:
            self.close()

    def _gather_s(self, now: float) -> float:
        """How long the next read may wait (``_GATHER_S`` comment): 0 near a block's close,
        with a source timed by the bridge, with more waiting than a read takes, in a flood
        (data coming so fast that a gathered read would hold ``FLOOD`` bytes: a pause would
        only slow the reading down), or with a duty due."""
        links = self._links
        if links is None or links.full or links.rate_Bps * _FLOOD_S >= FLOOD:
            return 0.0
        pause = min(_GATHER_S, self._due - now, links.pause_limit_s)
        for src in self.sources:
            if src.connected and src.time_source != "instrument":
                return 0.0
            if src.first_t is not None:
                pause = min(pause, src.near_s() - now)
        return pause

    def _update_states(self, now_mono: float) -> None:
        for src in self.sources:
            state = src.current_state(now_mono)
            if state == src.state:
                continue
            fields = {"source": src.cfg.name, "state": state, "was": src.state,
                      "transport": src.cfg.transport, "stall_s": src.cfg.stall_s}
            if state in ("stalled", "rejecting", "disconnected"):
                log.warning("bridge source %s", state, extra={"fields": {
                    **fields, "rejected": dict(src.rejected)}})
            else:
                log.info("bridge source %s", state, extra={"fields": fields})
            src.state = state

    def handle(self, i: int, kind: str, data: Any, recv_ns: int) -> None:
        src = self.sources[i]
        if kind == "connected":
            if src.connected != bool(data):
                src.connected = bool(data)
                src.link_mono = time.monotonic()
                src.last_read_ns = None
                self._recheck = True
            return
        if kind == "event":
            self._recheck = True  # an overlong line unsyncs a link: an idle mark is due
            src.events[data] += 1
            self._log(src, data)
            return
        now = time.monotonic()
        src.lines += len(data)
        src.last_line_mono = now
        if src.state != "reading":
            self._recheck = True
        many = (src.parse_many(data, recv_ns) if src.parse_many is not None
                and len(data) >= _BULK_MIN else None)
        if many is not None and (src.last_t_ns is None or many.t_ns[0] > src.last_t_ns) \
                and all(map(lt, many.t_ns, islice(many.t_ns, 1, None))) \
                and not _leaps_ahead(src, many.t_ns[-1], recv_ns):
            self._samples(src, many, recv_ns, now)
            return
        times = _read_times(src, len(data), recv_ns)
        for line, t_ns in zip(data, times):  # one by one: each rejection counted by its reason
            self._line(src, line, t_ns, now)
        if src.last_t_ns is not None:
            src.lag_s = min(src.lag_s, now - src.last_t_ns * 1e-9)

    def _samples(self, src: SourceState, many: Samples, recv_ns: int, now_mono: float) -> None:
        """Samples of the bulk parser (times increasing, after the last) into blocks, as
        :meth:`_line` puts them one by one."""
        t, n, i = many.t_ns, len(many.t_ns), 0
        while i < n:
            first_t = src.first_t
            if first_t is None:
                first_t = self._open_block(src, t[i], now_mono)
            end = bisect_left(t, first_t + src.block_ns, i)
            src.t.extend(t[i:end])
            for column, values in zip(src.columns, many.columns):
                column.extend(values[i:end])
            if end < n:
                self._flush(src)
            i = end
        src.last_t_ns = t[-1]
        src.last_recv_ns = recv_ns
        src.lag_s = min(src.lag_s, now_mono - t[-1] * 1e-9)
        src.time_source = many.time_source
        src.samples += n
        src.last_sample_mono = now_mono

    def _open_block(self, src: SourceState, t_ns: int, now_mono: float) -> int:
        """Open a block at sample time ``t_ns``; returns it."""
        src.first_t = t_ns
        src.block_opened_mono = now_mono
        self._due = min(self._due, now_mono + src.cfg.block_s)
        return t_ns

    def _line(self, src: SourceState, data: bytes, recv_ns: int, now_mono: float) -> None:
        try:
            line = data.decode("ascii")
            if not line.isprintable():
                raise Rejected("garbled")
            t_ns, vals, time_source = src.parse(line, recv_ns)
        except UnicodeDecodeError:
            self._reject(src, "garbled")
            return
        except Rejected as exc:
            self._reject(src, str(exc))
            return
        if src.last_t_ns is not None and t_ns <= src.last_t_ns:
            self._reject(src, "time_backwards")
            return
        if _leaps_ahead(src, t_ns, recv_ns):
            self._reject(src, "time_ahead")
            return
        if src.first_t is not None and t_ns - src.first_t >= src.block_ns:
            self._flush(src)
        if src.first_t is None:
            self._open_block(src, t_ns, now_mono)
        src.t.append(t_ns)
        for column, v in zip(src.columns, vals):
            column.append(v)
        src.last_t_ns = t_ns
        src.last_recv_ns = recv_ns
        src.time_source = time_source
        src.samples += 1
        src.last_sample_mono = now_mono

    def _reject(self, src: SourceState, reason: str) -> None:
        if reason in _QUIET:
            return
        src.rejected[reason] += 1
        if reason not in _UNLOGGED:
            self._log(src, reason)

    def _log(self, src: SourceState, reason: str) -> None:
        now = time.monotonic()
        if now - src.logged.get(reason, -_LOG_EVERY_S) >= _LOG_EVERY_S:
            src.logged[reason] = now
            log.warning("bridge source: %s", reason, extra={"fields": {
                "source": src.cfg.name, "reason": reason,
                "count": src.rejected.get(reason, 0) or src.events.get(reason, 0)}})

    def _flush(self, src: SourceState) -> None:
        if src.first_t is None:
            return
        fields = {f: np.array(column, np.float64)
                  for f, column in zip(SENSOR_FIELDS[src.cfg.sensor], src.columns)}
        block = SampleBlock(self.cfg.buoy_id, src.cfg.sensor, np.array(src.t, np.int64), fields)
        src.t, src.first_t = [], None
        src.columns = [[] for _ in src.columns]
        src.lag_before_s, src.lag_s = src.lag_s, math.inf
        self.publisher.publish_block(block)
        src.blocks += 1

    def status(self) -> dict[str, Any]:
        now = time.monotonic()
        return {"buoy_id": self.cfg.buoy_id, "wall_time_ns": time.time_ns(),
                "status_interval_s": self.cfg.status_interval_s,
                "sources": {s.cfg.name: s.status(now) for s in self.sources}}

    def publish_status(self) -> None:
        if self._status_pub is not None:
            self._status_pub.put(zenoh_io.to_json_bytes(self.status()))


def open_bridge(cfg: BridgeConfig) -> Bridge:
    """A bridge with a publisher session of its own (the caller closes ``bridge.publisher``)."""
    pub = SensorPublisher.connect(cfg.buoy_id, cfg.connect,
                                  PublisherOptions(cache_blocks=cfg.cache_blocks),
                                  zenoh_io.ProtobufCodec(cfg.quanta))
    return Bridge(cfg, pub)
