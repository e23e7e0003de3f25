"""Runs the configured sources: lines -> samples -> blocks -> publisher, and the status.

Reader threads only queue what they read; one thread parses, cuts blocks, publishes and
reports, so every Zenoh call happens on it. A block closes when a sample lies ``block_s``
after its first one, or when ``block_s`` of wall-clock time has passed since its first
sample arrived (a quiet instrument still gets its samples out). Times must increase
strictly within a source: a sample at or before the last one is counted
(``time_backwards``) and dropped, so no garbage time reaches the monitor.

Status: every ``status_interval_s`` a JSON document on ``buoy/<id>/bridge/status``: per
source its transport, stream, whether connected, counters (lines, samples, blocks) and
rejections by reason, the time source (``instrument`` or ``receive``) and the age of the
last sample. Each reason is logged at most once a minute per source.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from monitor.blocks import SENSOR_FIELDS, SampleBlock
from monitor.bridge.config import BridgeConfig, SourceConfig
from monitor.bridge.formats import Rejected, parser
from monitor.bridge.transports import ReceiveClock, run_transport
from monitor.sensors import PublisherOptions, SensorPublisher
from monitor import zenoh_io

log = logging.getLogger("buoymon.bridge")
_LOG_EVERY_S = 60.0
# reasons that are not faults of the data (header lines of a CSV file)
_QUIET = {"header_read"}


@dataclass
class SourceState:
    cfg: SourceConfig
    parse: Callable[[str, int], Any]
    connected: bool = False
    lines: int = 0
    samples: int = 0
    blocks: int = 0
    rejected: Counter = field(default_factory=Counter)
    events: Counter = field(default_factory=Counter)
    time_source: str | None = None
    last_t_ns: int | None = None
    last_sample_mono: float | None = None
    t: list[int] = field(default_factory=list)
    values: list[list[float]] = field(default_factory=list)
    block_opened_mono: float = 0.0
    logged: dict[str, float] = field(default_factory=dict)

    def status(self, now_mono: float) -> dict[str, Any]:
        return {"sensor": self.cfg.sensor, "transport": self.cfg.transport,
                "format": self.cfg.format, "connected": self.connected, "lines": self.lines,
                "samples": self.samples, "blocks": self.blocks,
                "rejected": dict(self.rejected), "events": dict(self.events),
                "time_source": self.time_source,
                "last_sample_age_s": None if self.last_sample_mono is None
                else now_mono - self.last_sample_mono}


class Bridge:
    """The bridge of ``cfg``, publishing through ``publisher`` (see :meth:`run`)."""

    def __init__(self, cfg: BridgeConfig, publisher: SensorPublisher) -> None:
        self.cfg = cfg
        self.publisher = publisher
        self.clock = ReceiveClock()
        self.sources = [SourceState(s, parser(s)) for s in cfg.sources]
        self._q: "queue.SimpleQueue[tuple[int, str, Any, int]]" = queue.SimpleQueue()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._status_pub: Any = None

    def stop(self) -> None:
        self._stop.set()

    def start_readers(self) -> None:
        for i, src in enumerate(self.sources):
            def emit(line: bytes, recv_ns: int, i: int = i) -> None:
                self._q.put((i, "line", line, recv_ns))

            def event(reason: str, i: int = i) -> None:
                self._q.put((i, "event", reason, 0))

            def connected(up: bool, i: int = i) -> None:
                self._q.put((i, "connected", up, 0))

            th = threading.Thread(target=run_transport, name=f"bridge-{src.cfg.name}",
                                  args=(src.cfg, emit, event, self._stop, self.clock, connected),
                                  daemon=True)
            th.start()
            self._threads.append(th)

    def run(self, until: Callable[[], bool] = lambda: False) -> None:
        """Serve until :meth:`stop` (or ``until()``); flushes what is buffered at the end."""
        self._status_pub = zenoh_io.declare_json_publisher(
            self.publisher.session, f"buoy/{self.cfg.buoy_id}/bridge/status")
        self.start_readers()
        next_status = time.monotonic()
        try:
            while not self._stop.is_set() and not until():
                try:
                    item = self._q.get(timeout=0.05)
                except queue.Empty:
                    item = None
                if item is not None:
                    self.handle(*item)
                now = time.monotonic()
                for src in self.sources:
                    if src.t and now - src.block_opened_mono >= src.cfg.block_s:
                        self._flush(src)
                if now >= next_status:
                    self.publish_status()
                    next_status = now + self.cfg.status_interval_s
        finally:
            self._stop.set()
            for th in self._threads:
                th.join(2.0)
            while True:  # what the readers queued before they stopped
                try:
                    self.handle(*self._q.get_nowait())
                except queue.Empty:
                    break
            for src in self.sources:
                self._flush(src)
            self.publish_status()
            self._status_pub.undeclare()

    def handle(self, i: int, kind: str, data: Any, recv_ns: int) -> None:
        src = self.sources[i]
        if kind == "connected":
            src.connected = bool(data)
            return
        if kind == "event":
            src.events[data] += 1
            self._log(src, data)
            return
        src.lines += 1
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
        if src.t and t_ns - src.t[0] >= int(src.cfg.block_s * 1e9):
            self._flush(src)
        if not src.t:
            src.block_opened_mono = time.monotonic()
        src.t.append(t_ns)
        src.values.append([vals[f] for f in SENSOR_FIELDS[src.cfg.sensor]])
        src.last_t_ns = t_ns
        src.time_source = time_source
        src.samples += 1
        src.last_sample_mono = time.monotonic()

    def _reject(self, src: SourceState, reason: str) -> None:
        if reason in _QUIET:
            return
        src.rejected[reason] += 1
        self._log(src, reason)

    def _log(self, src: SourceState, reason: str) -> None:
        now = time.monotonic()
        if now - src.logged.get(reason, -_LOG_EVERY_S) >= _LOG_EVERY_S:
            src.logged[reason] = now
            log.warning("bridge source: %s", reason, extra={"fields": {
                "source": src.cfg.name, "reason": reason,
                "count": src.rejected.get(reason, 0) or src.events.get(reason, 0)}})

    def _flush(self, src: SourceState) -> None:
        if not src.t:
            return
        v = np.array(src.values, dtype=np.float64)
        fields = {f: v[:, k].copy() for k, f in enumerate(SENSOR_FIELDS[src.cfg.sensor])}
        block = SampleBlock(self.cfg.buoy_id, src.cfg.sensor, np.array(src.t, dtype=np.int64),
                            fields)
        src.t, src.values = [], []
        self.publisher.publish_block(block)
        src.blocks += 1

    def status(self) -> dict[str, Any]:
        now = time.monotonic()
        return {"buoy_id": self.cfg.buoy_id, "wall_time_ns": time.time_ns(),
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
