"""Byte sources -> complete lines, reconnecting: serial ports, TCP (client or server), UDP,
a file another logger appends to (followed through rotation and truncation), stdin.

One thread serves every source: :class:`Links` waits on all their descriptors at once
(``selectors``) and wakes when one is readable, or when a timed duty is due (a reopen, a file
to look at, an idle link to mark), so its CPU follows the data and a line is read as soon as
it arrives. (A reader thread per source handing each read to a parsing thread cost 9 times
the parsing at 5 x 1 kHz: bench/bench_bridge.py.) Each :class:`Link` calls
``emit(lines, recv_ns)`` with the complete lines of a read, ``event(reason)`` for what the
bridge counts and ``connected(up)``. Events: ``disconnected`` (a device unplugged, a socket
reset, an open or connect that failed), ``partial_line`` (the bytes before the first newline
after a (re)connect unless the link was idle first, and a line cut by a disconnect: never
published), ``overlong`` (no newline within ``MAX_LINE`` bytes: baud-rate garbage),
``rotated``, ``truncated``. A link that fails is reopened every ``reconnect_s``; nothing here
blocks (a TCP connect is non-blocking too), so one dead instrument never holds the others.
Receive times are the logger's clock corrected by the monotonic clock (:class:`ReceiveClock`),
so a wall-clock step never reorders them.
"""

from __future__ import annotations

import errno
import math
import os
import selectors
import socket
import sys
import time
from operator import methodcaller
from typing import Any, Callable

from monitor.bridge.config import SourceConfig

MAX_LINE = 4096
_READ = 65536
FLOOD = 8192  # a read this long: more is waiting (1 kHz lines bring ~1 kB per 20 ms)
_RATE_S = 0.1  # the bytes (datagrams) read per second are counted over windows this long
_GATHER_GRAMS = 64
_TTY_GATHER = 2048
_UDP_BUFFER = 1 << 20
_FILE_READ = 1 << 20  # per turn: a long file is read over several turns, the others served
_IDLE_S = 0.2  # no byte for this long with nothing buffered: the instrument is between lines
# a followed file has no readiness to wait on: looked at this often (appends, rotation,
# truncation)
_FILE_POLL_S = 0.005
# a line with more than blanks, NULs and CRs; a line without its CR (CRLF line ends)
_TEXT = methodcaller("strip", b"\r \t\x00")
_CR = methodcaller("rstrip", b"\r")
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

    def reset(self, synced: bool = False) -> None:
        if self.buf:
            self.event("partial_line")
        self.buf = b""
        self.synced = synced

    def idle(self) -> None:
        """Nothing arrived for a while: with nothing buffered, the instrument is between
        lines, so the next byte starts one."""
        if not self.buf:
            self.synced = True

    def feed(self, data: bytes) -> None:
        now = self.clock.now_ns()
        self.buf += data
        *lines, self.buf = self.buf.split(b"\n")
        if self.synced and lines and max(map(len, lines)) <= MAX_LINE:
            # the usual read: builtins over all its lines (the loop below costs ~0.5 us a line)
            out = list(map(_CR, filter(_TEXT, lines)))
            lines = []
        else:
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


class Link:
    """One source's transport: opened, read when ready, closed and reopened on failure."""

    poll_s: float | None = None  # :meth:`poll` is called this often while open (None: never)
    flood = FLOOD  # a read this long: more is waiting, read again at once

    def __init__(self, cfg: SourceConfig, lines: LineSplitter, event: Event,
                 connected: Callable[[bool], None]) -> None:
        self.cfg, self.lines, self.event, self.connected = cfg, lines, event, connected
        self.retry_mono = 0.0  # when to try opening again (0: now)
        self.last_data_mono = time.monotonic()
        self.opened = False  # open() succeeded: its descriptors exist
        self.is_up = False  # connected (as reported)
        self.finished = False  # stdin at its end: nothing more will come
        self.backlog = False  # more to read at once (a long file)
        self.next_poll_mono = 0.0  # when :meth:`poll` is due (links with ``poll_s``)
        self.full = False  # the last read was a flood's (``FLOOD``): more is waiting
        self.nread = 0  # bytes read
        # set by Links: stop waiting on a file object (before it is closed); what to wait
        # on has changed
        self.forget: Callable[[Any], None] = lambda fileobj: None
        self.changed: Callable[[], None] = lambda: None

    # --- what each transport provides ---------------------------------------------------
    def open(self) -> None:
        """Open (raise OSError to retry after ``reconnect_s``)."""
        raise NotImplementedError

    def selectables(self) -> list[tuple[Any, int]]:
        """(file object, selectors event mask) to wait on while open."""
        return []

    def ready(self, fileobj: Any, mask: int) -> None:
        """Read what is ready on ``fileobj`` (raise OSError on a failure)."""

    def poll(self) -> None:
        """Called every ``poll_s`` while open (files, which are always "ready")."""

    def close(self) -> None:
        """Release the descriptors (never raises)."""

    def pause_limit_s(self, window_s: float) -> float:
        """The longest pause before a read that loses nothing (``inf``: the kernel keeps
        more than a pause brings), from what came in the last ``window_s`` (asked once per
        window)."""
        return math.inf

    # --- shared -------------------------------------------------------------------------
    def up(self, synced: bool) -> None:
        self.changed()
        self.is_up = True
        self.last_data_mono = time.monotonic()
        self.connected(True)
        self.lines.reset(synced=synced)

    def down(self) -> None:
        """Counted as ``disconnected``; a line it cut is a ``partial_line``."""
        self.changed()
        self.event("disconnected")
        if self.is_up:
            self.connected(False)
        self.is_up = False
        self.lines.reset()

    def fail(self) -> None:
        """A failure: counted, the link closed, a reopen in ``reconnect_s``."""
        if self.opened:
            for fileobj, _ in self.selectables():
                self.forget(fileobj)
        self.close()
        self.opened = False
        self.down()
        self.retry_mono = time.monotonic() + self.cfg.reconnect_s

    def got(self, data: bytes) -> None:
        self.full = len(data) >= self.flood
        self.nread += len(data)
        self.last_data_mono = time.monotonic()
        self.lines.feed(data)


def _close(obj: Any) -> None:
    if obj is not None:
        try:
            obj.close()
        except OSError:
            pass


class SerialLink(Link):
    # a tty holds 4 kB for its reader (more waits in the driver, and a pty's writer waits,
    # or the tail of a burst stays there until the next byte comes): pauses gather at most
    # half of it, and a read of three quarters (a burst) is followed by another at once
    flood = 3 * _TTY_GATHER // 2
    _nread_before = 0

    def pause_limit_s(self, window_s: float) -> float:
        rate = (self.nread - self._nread_before) / window_s
        self._nread_before = self.nread
        return _TTY_GATHER / rate if rate > 0 else math.inf

    def open(self) -> None:
        import serial  # noqa: PLC0415 (pyserial only where a serial source is configured)

        self.port = serial.Serial(self.cfg.device, self.cfg.baud, parity=self.cfg.parity,
                                  timeout=0)
        self.port.reset_input_buffer()  # what queued before we opened: stale, maybe mid-line
        self.up(synced=False)

    def selectables(self) -> list[tuple[Any, int]]:
        return [(self.port.fileno(), selectors.EVENT_READ)]

    def ready(self, fileobj: Any, mask: int) -> None:
        # straight from the descriptor: pyserial's read() selects and asks the driver again
        data = os.read(fileobj, _READ)
        if not data:
            raise ConnectionResetError("serial device gone")
        self.got(data)

    def close(self) -> None:
        _close(getattr(self, "port", None))


class TcpClientLink(Link):
    def open(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setblocking(False)
        err = self.sock.connect_ex((self.cfg.host, self.cfg.port))
        if err not in (0, errno.EINPROGRESS):
            raise OSError(err, os.strerror(err))
        self.connecting = True

    def selectables(self) -> list[tuple[Any, int]]:
        return [(self.sock, selectors.EVENT_WRITE if self.connecting else selectors.EVENT_READ)]

    def ready(self, fileobj: Any, mask: int) -> None:
        if self.connecting:
            err = self.sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
            if err:
                raise OSError(err, os.strerror(err))
            self.connecting = False
            self.up(synced=False)
            return
        _stream_read(self, self.sock)

    def close(self) -> None:
        _close(getattr(self, "sock", None))


def _stream_read(link: Link, sock: socket.socket) -> None:
    try:
        data = sock.recv(_READ)
    except BlockingIOError:
        return
    if not data:
        raise ConnectionResetError("peer closed the connection")
    link.got(data)


class TcpServerLink(Link):
    """Listens on ``host:port``; one instrument connection at a time (a new one replaces the
    old: the instrument reconnected after a reset the bridge did not see)."""

    def open(self) -> None:
        self.srv = socket.create_server((self.cfg.host, self.cfg.port))
        self.srv.setblocking(False)
        self.conn: socket.socket | None = None

    def selectables(self) -> list[tuple[Any, int]]:
        out = [(self.srv, selectors.EVENT_READ)]
        if self.conn is not None:
            out.append((self.conn, selectors.EVENT_READ))
        return out

    def ready(self, fileobj: Any, mask: int) -> None:
        if fileobj is self.srv:
            try:
                conn, _ = self.srv.accept()
            except BlockingIOError:
                return
            if self.conn is not None:
                self._drop()
            conn.setblocking(False)
            self.conn = conn
            self.up(synced=True)  # a new connection starts at a line's start
            return
        try:
            _stream_read(self, fileobj)
        except OSError:  # the instrument went away: keep listening
            self._drop()

    def _drop(self) -> None:
        self.forget(self.conn)
        _close(self.conn)
        self.conn = None
        self.down()

    def close(self) -> None:
        _close(getattr(self, "conn", None))
        _close(getattr(self, "srv", None))


class UdpLink(Link):
    grams = 0  # datagrams read
    _grams_before = 0  # ... before the last window (:meth:`pause_limit_s`)

    def pause_limit_s(self, window_s: float) -> float:
        # a socket's buffer counts a small datagram as ~1 kB: pause for _GATHER_GRAMS at most
        rate = (self.grams - self._grams_before) / window_s
        self._grams_before = self.grams
        return _GATHER_GRAMS / rate if rate > 0 else math.inf

    def open(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        # room for the datagrams of a pause at its start, before their rate is known (the
        # kernel caps this at net.core.rmem_max)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, _UDP_BUFFER)
        try:
            self.sock.bind((self.cfg.host, self.cfg.port))
        except OSError:
            self.sock.close()
            raise
        self.sock.setblocking(False)
        self.up(synced=True)

    def selectables(self) -> list[tuple[Any, int]]:
        return [(self.sock, selectors.EVENT_READ)]

    def ready(self, fileobj: Any, mask: int) -> None:
        grams = []
        for _ in range(1000):  # every datagram waiting, within reason
            try:
                data = self.sock.recv(_READ)
            except BlockingIOError:
                break
            grams.append(data if data.endswith(b"\n") else data + b"\n")
        if not grams:
            return
        self.grams += len(grams)
        self.lines.reset(synced=True)  # each datagram holds whole lines
        # all in one piece, parsed at once; a source timed at the read keeps a time for each
        for piece in grams if self.cfg.timed_at_read else [b"".join(grams)]:
            self.got(piece)
        self.full = self.full or len(grams) == 1000

    def close(self) -> None:
        _close(getattr(self, "sock", None))


class FileLink(Link):
    """Follows a file: appended data, rotation (a new file at the path: read from its
    start) and truncation (read again from the start)."""

    rotated = False  # a rotated-in file is read whole, whatever ``from_start`` says
    poll_s = _FILE_POLL_S

    def open(self) -> None:
        self.f = open(self.cfg.path, "rb")
        self.ino = os.fstat(self.f.fileno()).st_ino
        if not self.cfg.from_start and not self.rotated:
            self.f.seek(0, os.SEEK_END)
        self.up(synced=self.cfg.from_start or self.rotated)

    def poll(self) -> None:
        data = self.f.read(_FILE_READ)
        self.backlog = len(data) == _FILE_READ
        if data:
            self.got(data)
            return
        try:
            st = os.stat(self.cfg.path)
        except FileNotFoundError:  # rotated away, the new one not there yet
            return
        if st.st_ino != self.ino:
            self.lines.reset()
            self.event("rotated")
            self.rotated = True
            self.close()
            self.open()  # the new file, from its start
        elif st.st_size < self.f.tell():
            self.lines.reset(synced=True)
            self.event("truncated")
            self.f.seek(0)

    def close(self) -> None:
        _close(getattr(self, "f", None))


class StdinLink(Link):
    def open(self) -> None:
        self.fd = sys.stdin.buffer.fileno()  # left blocking: it may be the terminal's
        self.up(synced=True)

    def selectables(self) -> list[tuple[Any, int]]:
        return [(self.fd, selectors.EVENT_READ)]

    def ready(self, fileobj: Any, mask: int) -> None:
        data = os.read(self.fd, _READ)  # ready: does not block
        if data:
            self.got(data)
            return
        self.got(b"\n")  # a last line without newline still counts
        self.finished = True
        self.changed()


LINKS: dict[str, type[Link]] = {"serial": SerialLink, "tcp_client": TcpClientLink,
                                "tcp_server": TcpServerLink, "udp": UdpLink,
                                "file": FileLink, "stdin": StdinLink}


class Links:
    """Every source's link, served by one thread: :meth:`pump` waits for readiness up to a
    timeout and reads; :meth:`duties` opens what is due, polls the files and marks idle links,
    and :meth:`next_due` says when that is next needed."""

    def __init__(self, links: list[Link]) -> None:
        self.links = links
        self.sel = selectors.DefaultSelector()
        self._registered: dict[Any, tuple[Link, int]] = {}
        self._dirty = True
        self.stale = True
        self.full = False  # a read in the last pump was a flood's: more is waiting
        self.rate_Bps = 0.0  # bytes read per second in the last whole window of ``_RATE_S``
        self._window = (time.monotonic(), 0)  # its start and the bytes read before it
        self.pause_limit_s = math.inf  # the longest pause before a read that loses nothing
        # stop() from another thread or a signal handler: a byte here ends the wait at once
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self.sel.register(self._wake_r, selectors.EVENT_READ, None)
        for link in links:
            link.forget = self._forget
            link.changed = self._changed

    def _changed(self) -> None:
        self._dirty = True
        self.stale = True

    def _forget(self, fileobj: Any) -> None:
        if self._registered.pop(fileobj, None) is not None:
            self.sel.unregister(fileobj)

    def wake(self) -> None:
        """End a :meth:`pump`'s wait (safe from other threads and signal handlers)."""
        try:
            self._wake_w.send(b"\0")
        except OSError:  # full (a wake is pending anyway) or closed (nothing to wake)
            pass

    def duties(self, now: float) -> None:
        """The timed duties due at ``now``: open what is due, poll the files, mark idle
        links."""
        for link in self.links:
            if not link.opened and not link.finished and now >= link.retry_mono:
                self._open(link)
            if link.opened and link.poll_s is not None and (link.backlog
                                                            or now >= link.next_poll_mono):
                link.next_poll_mono = now + link.poll_s
                try:
                    link.poll()
                except OSError:
                    link.fail()
            if not link.lines.synced and now - link.last_data_mono >= _IDLE_S:
                link.lines.idle()

    def next_due(self) -> float:
        """The monotonic time of the next timed duty (``inf`` if none); :attr:`stale` says
        it may have moved since it was last asked (a link opened, failed, reconnected)."""
        self.stale = False
        due = math.inf
        for link in self.links:
            if not link.opened:
                if not link.finished:
                    due = min(due, link.retry_mono)
                continue
            if link.poll_s is not None:
                due = min(due, 0.0 if link.backlog else link.next_poll_mono)
            if not link.lines.synced and not link.lines.buf:
                due = min(due, link.last_data_mono + _IDLE_S)
        return due

    def pump(self, timeout_s: float) -> None:
        """Read what is ready, waiting up to ``timeout_s`` (``inf``: until something is)."""
        if self._dirty:
            self._dirty = False
            self._sync()
        wait = None if timeout_s == math.inf else max(timeout_s, 0.0)
        self.full = False
        for key, mask in self.sel.select(wait):
            link = key.data
            if link is None:
                self._drain_wake()
                continue
            if not link.opened:  # failed earlier in this turn
                continue
            try:
                link.ready(key.fileobj, mask)
            except OSError:
                link.fail()
            if link.full:
                link.full = False
                self.full = True
        now = time.monotonic()
        if now - self._window[0] >= _RATE_S:
            nread = sum(link.nread for link in self.links)
            self.rate_Bps = (nread - self._window[1]) / (now - self._window[0])
            self.pause_limit_s = min(link.pause_limit_s(now - self._window[0])
                                     for link in self.links)
            self._window = (now, nread)

    def _drain_wake(self) -> None:
        try:
            while self._wake_r.recv(4096):
                pass
        except OSError:
            pass

    def _open(self, link: Link) -> None:
        try:
            link.open()
        except OSError:
            link.close()
            link.down()
            link.retry_mono = time.monotonic() + link.cfg.reconnect_s
        else:
            link.opened = True
            link.next_poll_mono = 0.0
        self._changed()

    def _sync(self) -> None:
        """Register exactly what each link waits on now."""
        want: dict[Any, tuple[Link, int]] = {}
        for link in self.links:
            if link.opened and not link.finished:
                for fileobj, mask in link.selectables():
                    want[fileobj] = (link, mask)
        for fileobj in list(self._registered):
            if self._registered[fileobj] != want.get(fileobj):
                self._forget(fileobj)
        for fileobj, (link, mask) in want.items():
            if fileobj not in self._registered:
                self.sel.register(fileobj, mask, link)
                self._registered[fileobj] = (link, mask)

    def close(self) -> None:
        for fileobj in list(self._registered):
            self._forget(fileobj)
        for link in self.links:
            link.close()
        self.sel.close()
        self._wake_r.close()
        self._wake_w.close()
