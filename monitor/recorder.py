"""MCAP recording of every message the daemon (or ``buoymon record``) receives or publishes.

Files are ``<dir>/<prefix>-<YYYYmmddTHHMMSSZ>.mcap``, one per ``rotate_s`` window of log time
(aligned to multiples of ``rotate_s`` since the epoch: hourly by default). The recorder flushes
the open chunk and fsyncs the file every ``flush_interval_s`` of log time, so a file left by
``kill -9`` or a power cut has no footer but every message up to the last flush is intact and
readable by a streaming MCAP reader (``replay.reader`` salvages such files).

Payloads are recorded byte for byte as they travelled over Zenoh; ``log_time`` is the receive
(or publish) wall-clock time and ``publish_time`` the sensor time, as in the log format. The
files are written by :class:`monitor.mcap_file.McapFile`, the writer of the logs too (one
layout: channels at top level, no Message Index records).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

from monitor.mcap_file import McapFile


@dataclass(frozen=True)
class ChannelSpec:
    """How one topic's payloads are described in MCAP."""

    schema_name: str
    schema_encoding: str  # "protobuf" (FileDescriptorSet) or "jsonschema"
    schema_data: bytes
    message_encoding: str  # "protobuf" or "json"


JSON_OBJECT = ChannelSpec("buoymon.v1.Json", "jsonschema",
                          b'{"title":"buoymon.v1.Json","type":"object"}', "json")


class McapRecorder:
    """Append messages to hourly-rotated MCAP files with periodic flush + fsync."""

    def __init__(self, directory: str | os.PathLike[str], rotate_s: float = 3600.0,
                 flush_interval_s: float = 5.0, prefix: str = "buoymon") -> None:
        if rotate_s <= 0 or flush_interval_s <= 0:
            raise ValueError(f"recorder: rotate_s={rotate_s} and flush_interval_s="
                             f"{flush_interval_s} must be > 0")
        self.directory = os.fspath(directory)
        os.makedirs(self.directory, exist_ok=True)
        self._rotate_ns = int(rotate_s * 1e9)
        self._flush_ns = int(flush_interval_s * 1e9)
        self._prefix = prefix
        self._file: McapFile | None = None
        self._window = -1
        self._last_flush_ns = 0
        self._dirty = False
        self.files: list[str] = []
        self.messages = 0
        self.flushes = 0  # flushes and closes: everything written before one is on disk

    def write(self, topic: str, payload: bytes, spec: ChannelSpec, log_time_ns: int,
              publish_time_ns: int) -> None:
        """Record one message; rotates and flushes as due by ``log_time_ns``."""
        window = log_time_ns // self._rotate_ns
        if window != self._window:
            self._open(window)
        assert self._file is not None
        channel = self._file.channel(topic, spec.schema_name, spec.schema_encoding,
                                     spec.schema_data, spec.message_encoding)
        # MCAP readers treat 0 as "unset": never write it (a block may lack a sensor time)
        self._file.add_message(channel, log_time_ns, publish_time_ns or log_time_ns, payload)
        self.messages += 1
        self._dirty = True
        self.maybe_flush(log_time_ns)

    def maybe_flush(self, now_ns: int | None = None) -> bool:
        """Flush + fsync if ``flush_interval_s`` passed since the last flush."""
        now_ns = time.time_ns() if now_ns is None else now_ns
        if not self._dirty or now_ns - self._last_flush_ns < self._flush_ns:
            return False
        self.flush(now_ns)
        return True

    def flush(self, now_ns: int | None = None) -> None:
        """Close the open chunk, write it out and fsync: survives a power cut from here."""
        if self._file is not None:
            self._file.flush(fsync=True)
        self._last_flush_ns = time.time_ns() if now_ns is None else now_ns
        self._dirty = False
        self.flushes += 1

    def close(self) -> None:
        """Finish the current file (footer + index) and fsync it."""
        if self._file is not None:
            self._file.close()
            self.flushes += 1
        self._file = None
        self._window = -1

    def _open(self, window: int) -> None:
        self.close()
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(window * self._rotate_ns / 1e9))
        path = os.path.join(self.directory, f"{self._prefix}-{stamp}.mcap")
        n = 0
        while os.path.exists(path):  # a restart within the same window: never overwrite
            n += 1
            path = os.path.join(self.directory, f"{self._prefix}-{stamp}-{n}.mcap")
        self._file = McapFile(path)
        self._window = window
        self.files.append(path)
