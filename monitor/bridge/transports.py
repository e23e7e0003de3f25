"""Byte sources -> complete lines, reconnecting: serial ports, TCP (client or server), UDP,
a file another logger appends to (followed through rotation and truncation), stdin.

Each transport runs in a thread of its own and calls ``emit(lines, recv_ns)`` with the
complete lines of each read (one call per read, not per line: a thread hand-over per line
would cost more than the line's parsing) and ``event(reason)`` for what the bridge counts: ``disconnected`` (a device
unplugged, a socket reset, an open that failed), ``partial_line`` (the bytes before the
first newline after a (re)connect unless the link was idle first, and a line cut by a
disconnect: never published),
``overlong`` (no newline within ``MAX_LINE`` bytes: baud-rate garbage), ``rotated``,
``truncated``. Receive times are the logger's clock corrected by the monotonic clock
(:class:`ReceiveClock`), so a wall-clock step never reorders them.
"""

from __future__ import annotations

import os
import socket
import sys
import threading
import time
from typing import Callable

from monitor.bridge.config import SourceConfig

MAX_LINE = 4096
Emit = Callable[[list[bytes], int], None]
Event = Callable[[str], None]


class ReceiveClock:
    """Wall-clock ns since the epoch, advancing with the monotonic clock from its start."""

    def __init__(self) -> None:
        self._wall0 = time.time_ns()
        self._mono0 = time.monotonic_ns()

    def now_ns(self) -> int:
        return self._wall0 + (time.monotonic_ns() - self._mono0)


class LineSplitter:
    """Cuts a byte stream into lines (LF or CRLF); the first fragment after :meth:`reset`
    (a (re)connect mid-line) and lines over ``MAX_LINE`` bytes are dropped and reported."""

    def __init__(self, emit: Emit, event: Event, clock: ReceiveClock) -> None:
        self.emit, self.event, self.clock = emit, event, clock
        self.buf = b""
        self.synced = False
        self.rotated = False  # a followed file was rotated at least once

    def reset(self, synced: bool = False) -> None:
        if self.buf:
            self.event("partial_line")
        self.buf = b""
        self.synced = synced

    def idle(self) -> None:
        """Nothing arrived for a read timeout: with nothing buffered, the instrument is
        between lines, so the next byte starts one."""
        if not self.buf:
            self.synced = True

    def feed(self, data: bytes) -> None:
        now = self.clock.now_ns()
        self.buf += data
        *lines, self.buf = self.buf.split(b"\n")
        out = []
        for line in lines:
            if not self.synced:
                self.synced = True
                if line.strip():
                    self.event("partial_line")
                continue
            if len(line) > MAX_LINE:
                self.event("overlong")
            elif line.strip(b"\r \t\x00"):
                out.append(line.rstrip(b"\r"))
        if out:
            self.emit(out, now)
        if len(self.buf) > MAX_LINE:
            self.event("overlong")
            self.buf = b""
            self.synced = False


def run_transport(cfg: SourceConfig, emit: Emit, event: Event, stop: threading.Event,
                  clock: ReceiveClock, connected: Callable[[bool], None]) -> None:
    """Read ``cfg``'s transport until ``stop`` is set (runs in its own thread)."""
    lines = LineSplitter(emit, event, clock)
    reader = {"serial": _serial, "tcp_client": _tcp_client, "tcp_server": _tcp_server,
              "udp": _udp, "file": _file, "stdin": _stdin}[cfg.transport]
    while not stop.is_set():
        try:
            reader(cfg, lines, stop, connected)
        except OSError as exc:  # serial.SerialException is an OSError too
            event("disconnected")
            connected(False)
            lines.reset()
            stop.wait(cfg.reconnect_s)
            del exc
        else:
            if cfg.transport == "stdin":
                return


def _serial(cfg: SourceConfig, lines: LineSplitter, stop: threading.Event, connected) -> None:
    import serial  # noqa: PLC0415 (pyserial only where a serial source is configured)

    with serial.Serial(cfg.device, cfg.baud, parity=cfg.parity, timeout=0.2) as port:
        connected(True)
        port.reset_input_buffer()  # what queued before we opened: stale, maybe mid-line
        lines.reset(synced=False)
        while not stop.is_set():
            data = port.read(port.in_waiting or 1)  # blocks for the first byte (or timeout)
            if data:
                lines.feed(data + port.read(port.in_waiting))
            else:
                lines.idle()


def _stream(sock: socket.socket, lines: LineSplitter, stop: threading.Event) -> None:
    sock.settimeout(0.2)
    while not stop.is_set():
        try:
            data = sock.recv(65536)
        except socket.timeout:
            lines.idle()
            continue
        if not data:
            raise ConnectionResetError("peer closed the connection")
        lines.feed(data)


def _tcp_client(cfg: SourceConfig, lines: LineSplitter, stop: threading.Event, connected) -> None:
    with socket.create_connection((cfg.host, cfg.port), timeout=5) as sock:
        connected(True)
        lines.reset(synced=False)
        _stream(sock, lines, stop)


def _tcp_server(cfg: SourceConfig, lines: LineSplitter, stop: threading.Event, connected) -> None:
    with socket.create_server((cfg.host, cfg.port)) as srv:
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except socket.timeout:
                continue
            with conn:
                connected(True)
                lines.reset(synced=True)  # a new connection starts at a line's start
                try:
                    _stream(conn, lines, stop)
                except OSError:
                    lines.event("disconnected")
                    connected(False)
                    lines.reset()


def _udp(cfg: SourceConfig, lines: LineSplitter, stop: threading.Event, connected) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind((cfg.host, cfg.port))
        sock.settimeout(0.2)
        connected(True)
        while not stop.is_set():
            try:
                data = sock.recv(65536)
            except socket.timeout:
                continue
            lines.reset(synced=True)  # each datagram holds whole lines
            lines.feed(data if data.endswith(b"\n") else data + b"\n")


def _file(cfg: SourceConfig, lines: LineSplitter, stop: threading.Event, connected) -> None:
    with open(cfg.path, "rb") as f:
        ino = os.fstat(f.fileno()).st_ino
        if not cfg.from_start and not lines.rotated:  # a rotated-in file is read whole
            f.seek(0, os.SEEK_END)
        connected(True)
        lines.reset(synced=cfg.from_start)
        while not stop.is_set():
            data = f.read(65536)
            if data:
                lines.feed(data)
                continue
            try:
                st = os.stat(cfg.path)
            except FileNotFoundError:  # rotated away, the new one not there yet
                stop.wait(0.1)
                continue
            if st.st_ino != ino:
                lines.reset()
                lines.event("rotated")
                lines.rotated = True
                return  # reopen the new file from its start
            if st.st_size < f.tell():
                lines.reset(synced=True)
                lines.event("truncated")
                f.seek(0)
                continue
            stop.wait(0.05)


def _stdin(cfg: SourceConfig, lines: LineSplitter, stop: threading.Event, connected) -> None:
    connected(True)
    lines.reset(synced=True)
    stream = sys.stdin.buffer
    while not stop.is_set():
        data = stream.read1(65536) if hasattr(stream, "read1") else stream.read(65536)
        if not data:
            lines.feed(b"\n")  # a last line without newline still counts
            return
        lines.feed(data)
