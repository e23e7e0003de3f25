"""Reading one MCAP log file front to back with salvage (see :mod:`replay.reader`).

The footer and summary are not needed, so a file cut short (crash, power loss) or with
damaged chunks is read as far as it is intact; what could not be recovered is reported in the
file's :class:`FileStats` as :class:`LostRange` records. The messages found are handed, a run
of records at a time, to a :class:`RecordSink` (the cross-file merge, :mod:`replay.merge`).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Iterator, Protocol

from monitor import codec
from monitor.mcap_file import (
    MAGIC, OP_CHANNEL, OP_CHUNK, OP_DATA_END, OP_FOOTER, OP_MESSAGE, OP_MESSAGE_INDEX,
    OP_SCHEMA,
)
from replay.chunks import Inflated, Inflater, ReadAhead
from replay.mcap_scan import (
    MAX_CUT_CHUNK, Digest, digest, end_of_log, find_chunk, str_at, summary_records,
)


@dataclass(frozen=True)
class LostRange:
    """Data that could not be recovered.

    ``start_ns``/``end_ns`` are receive times (MCAP log times) bounding the loss when known;
    ``messages`` is the number of messages lost, ``None`` when it cannot be known.
    """

    reason: str
    offset: int
    start_ns: int | None = None
    end_ns: int | None = None
    messages: int | None = None


@dataclass
class FileStats:
    """What reading one file found. ``messages``/``samples`` count decoded sensor messages."""

    path: str
    size_bytes: int = 0
    messages: int = 0
    samples: int = 0
    messages_by_topic: dict[str, int] = field(default_factory=dict)
    chunks: int = 0
    bad_chunks: int = 0
    complete: bool = False  # data section ended properly (DataEnd record reached)
    late: int = 0
    bad_payloads: int = 0
    skipped: dict[str, int] = field(default_factory=dict)  # non-sensor / undecodable channels
    first_ns: int | None = None  # earliest / latest publish time of the sensor messages read
    last_ns: int | None = None
    lost: list[LostRange] = field(default_factory=list)
    error: str | None = None
    # bytes after the log's end (its closing magic): no part of it, not read; no data lost
    trailing_bytes: int = 0

    @property
    def readable(self) -> bool:
        return self.messages > 0

    def as_dict(self) -> dict:
        # trailing_bytes only when there are some: the report of a sound file is unchanged
        d = {k: v for k, v in self.__dict__.items()
             if k != "lost" and (k != "trailing_bytes" or v)}
        d["lost"] = [r.__dict__ for r in self.lost]
        return d


class FileContext:
    """Schemas and channels of one file: channel id -> (stream, field numbers) or a skip reason."""

    def __init__(self) -> None:
        self.schemas: dict[int, tuple[str, str, bytes]] = {}
        self.channels: dict[int, tuple[int, tuple] | str] = {}
        self.last_log = 0

    def definition(self, op: int, b: bytes, sink: RecordSink, st: FileStats) -> None:
        try:
            if op == OP_SCHEMA:
                (sid,) = struct.unpack_from("<H", b, 0)
                name, p = str_at(b, 2)
                enc, p = str_at(b, p)
                (n,) = struct.unpack_from("<I", b, p)
                self.schemas[sid] = (name, enc, bytes(b[p + 4:p + 4 + n]))
                return
            cid, sid = struct.unpack_from("<HH", b, 0)
            topic, p = str_at(b, 4)
            enc, _ = str_at(b, p)
        except (struct.error, UnicodeDecodeError):
            st.lost.append(LostRange("malformed schema or channel record", -1))
            return
        if cid in self.channels:
            return
        schema = self.schemas.get(sid)
        sidx = sink.stream_index(topic)
        if sidx is None or schema is None or schema[1] != "protobuf" or enc != "protobuf":
            self.channels[cid] = topic  # not a sensor block channel: skipped, counted
            return
        try:
            numbers = codec.field_numbers_from_schema(schema[2], schema[0],
                                                      sink.sensor(sidx))
        except Exception as e:  # a foreign or broken schema: skip its messages, say why
            self.channels[cid] = f"{topic} (undecodable schema: {e})"
            return
        self.channels[cid] = (sidx, numbers)


class RecordSink(Protocol):
    """Where the messages of a file go (:class:`replay.merge.StreamMerge`)."""

    def stream_index(self, topic: str) -> int | None:
        """Index of a sensor topic's stream, creating it (None if not a sensor topic)."""

    def sensor(self, idx: int) -> str:
        """The sensor of stream ``idx``."""

    def records(self, d: Digest, ctx: FileContext, st: FileStats) -> int:
        """Take a run of records; return the number of messages found in it."""

    def fronts(self, ahead: bool = False) -> dict[int, int]:
        """Room to leave before each stream's samples when decoding (see
        :func:`replay.mcap_scan.digest`); ``ahead``: for a run decoded ahead."""


class FileSalvage:
    """Reads files record by record with salvage, handing their messages to ``sink``; with
    ``read_ahead`` a worker thread inflates and digests the next chunk meanwhile."""

    def __init__(self, sink: RecordSink, read_ahead: bool = True) -> None:
        self.sink = sink
        self.read_ahead = read_ahead
        self._inflater = Inflater()

    def read_file(self, path: Path, st: FileStats) -> Iterator[None]:
        """Read one file record by record; yield after each batch of messages."""
        try:
            f = open(path, "rb")
        except OSError as e:
            st.error = f"cannot open: {e.strerror or e}"
            return
        with f:
            f.seek(0, 2)
            size = st.size_bytes = f.tell()
            f.seek(0)
            if f.read(8) != MAGIC:
                st.error = "not an MCAP file (bad or missing magic bytes)"
                return
            ctx = FileContext()
            self._summary_definitions(f, size, ctx)
            f.seek(8)
            ahead = ReadAhead(f.fileno(), size, _digest_ahead) if self.read_ahead else None
            try:
                yield from self._read_records(f, size, ctx, st, ahead)
            finally:
                if ahead is not None:
                    ahead.close()

    def _summary_definitions(self, f: BinaryIO, size: int, ctx: FileContext) -> None:
        """Take the schemas and channels repeated in the summary section, when the file ends
        in an intact footer. Other writers (mcap's own, which made buoymon's recordings before
        monitor.mcap_file did) may define a channel inside the first chunk that uses it: should
        that chunk be damaged, the channel's messages in the other chunks are then still decoded. The definitions are the same as in the data
        section (the first one read wins), so an intact file reads exactly as before."""
        scratch = FileStats(path="")  # a damaged summary loses no data: not reported as loss
        for op, content in summary_records(f, size):
            if op in (OP_SCHEMA, OP_CHANNEL):
                ctx.definition(op, content, self.sink, scratch)

    def _read_records(self, f: BinaryIO, size: int, ctx: FileContext, st: FileStats,
                      ahead: ReadAhead | None) -> Iterator[None]:
        """The records after the magic, in file order, with salvage (see the module doc)."""
        pos = 8
        loose: list[bytes] = []  # top-level (unchunked) message records, batched
        awaiting: list | None = None  # lost chunk whose message count comes from its index
        while True:
            head = f.read(9)
            if len(head) < 9:
                if head:
                    st.lost.append(LostRange("file cut inside a record header", pos))
                break
            op, ln = struct.unpack("<BQ", head)
            cut = ln > size - pos - 9
            if op == 0 or 0x10 <= op < 0x80 or (cut and op != OP_CHUNK):
                # an impossible record header: skip to the next chunk if there is one
                why = ("file cut inside a record" if cut and op
                       else f"corrupt record (opcode {op})")
                nxt = find_chunk(f, pos + 1, size)
                tail = "" if nxt is None else f"; skipped {nxt - pos} bytes to the next chunk"
                # a cut index/summary record holds no messages; a corrupt header may hide some
                known_empty = cut and 0 < op < 0x10 and op != OP_MESSAGE
                st.lost.append(LostRange(f"{why} at byte {pos}{tail}", pos,
                                         messages=0 if known_empty else None))
                if nxt is None:
                    break
                f.seek(nxt)
                pos = nxt
                continue
            if op == OP_MESSAGE and not cut:
                loose.append(head + f.read(ln))
                if len(loose) >= 4096:
                    self._deliver(digest(b"".join(loose), ctx.channels), ctx, st)
                    loose.clear()
                    yield
                pos += 9 + ln
                continue
            if loose:
                self._deliver(digest(b"".join(loose), ctx.channels), ctx, st)
                loose.clear()
                yield
            if awaiting is not None and op != OP_MESSAGE_INDEX:
                awaiting = None
            if op == OP_CHUNK:
                got = ahead.take(pos) if ahead is not None else None
                if got is None:
                    # (whole: into the inflater's reused buffer; the file position moves on)
                    content = (f.read(min(ln, MAX_CUT_CHUNK)) if cut
                               else self._inflater.read(f.fileno(), ln, pos + 9))
                    got = self._inflater.inflate(content, cut), None
                if not cut:
                    f.seek(pos + 9 + ln)
                awaiting = self._chunk(got[0], got[1], pos, ctx, st)
                if ahead is not None and not cut:
                    # the next chunk is inflated and digested while the caller works
                    ahead.schedule(pos + 9 + ln, (dict(ctx.channels), self.sink.fronts(True)))
                yield
                if cut:  # a truncated file, or a corrupt length: look for a next chunk
                    nxt = find_chunk(f, pos + 1, size)
                    if nxt is None:
                        break
                    f.seek(nxt)
                    pos = nxt
                    continue
            elif op in (OP_SCHEMA, OP_CHANNEL):
                ctx.definition(op, f.read(ln), self.sink, st)
            elif op == OP_MESSAGE_INDEX and awaiting is not None:
                content = f.read(ln)
                (nbytes,) = struct.unpack_from("<I", content, 2)
                lost = awaiting[0]
                awaiting[0] = LostRange(lost.reason, lost.offset, lost.start_ns, lost.end_ns,
                                        (lost.messages or 0) + nbytes // 16)
                st.lost[awaiting[1]] = awaiting[0]
            elif op in (OP_DATA_END, OP_FOOTER):
                st.complete = True
                self._trailing(f, end_of_log(f, pos + 9 + ln if op == OP_DATA_END else pos,
                                             size), size, st)
                break
            else:
                f.seek(ln, 1)
            pos += 9 + ln
        if loose:
            self._deliver(digest(b"".join(loose), ctx.channels), ctx, st)
            yield
        if st.messages == 0 and st.error is None:
            st.error = "no sensor messages could be read"

    @staticmethod
    def _trailing(f: BinaryIO, end: int, size: int, st: FileStats) -> None:
        """Count the bytes after the log's ``end``; when they start as an MCAP file does (two
        logs joined by ``cat``), that log's messages are not read: a loss of unknown size."""
        st.trailing_bytes = size - end
        f.seek(end)
        if st.trailing_bytes >= len(MAGIC) and f.read(len(MAGIC)) == MAGIC:
            st.lost.append(LostRange(
                f"another MCAP log ({st.trailing_bytes:,d} bytes) after the end of this one "
                f"at byte {end}: not read (split it off to replay it)", end))

    def _deliver(self, d: Digest, ctx: FileContext, st: FileStats) -> int:
        """Apply a run of records' channel definitions, then hand its messages to the sink;
        return the number of messages found in it."""
        oop, ooff, olen = d.scan[5:8]
        raw = None
        for op, a, ln in zip(oop.tolist(), ooff.tolist(), olen.tolist()):
            if op in (OP_SCHEMA, OP_CHANNEL):
                raw = d.buf.tobytes() if raw is None else raw
                ctx.definition(op, raw[a:a + ln], self.sink, st)
        return self.sink.records(d, ctx, st)

    def _chunk(self, c: Inflated, scanned: Digest | None, pos: int, ctx: FileContext,
               st: FileStats) -> list | None:
        """Take one inflated chunk (``scanned``: its records, when the read-ahead scanned them);
        return ``[LostRange, index in st.lost]`` if it was lost whole and its Message Index
        records may still give the count of its messages."""
        st.chunks += 1
        if c.raw is None:
            st.bad_chunks += 1
            st.lost.append(LostRange(c.error or "chunk lost", pos, c.t_lo, c.t_hi))
            return [st.lost[-1], len(st.lost) - 1] if c.indexed else None
        n = self._deliver(scanned if scanned is not None
                          else digest(c.raw, ctx.channels, self.sink.fronts()), ctx, st)
        if c.cut:
            st.bad_chunks += 1
            st.lost.append(LostRange(
                f"file cut inside a chunk: {n} messages of it recovered", pos,
                ctx.last_log if n else c.t_lo, c.t_hi))
        return None


def _digest_ahead(raw: bytes | memoryview, arg: tuple) -> Digest:
    """:func:`replay.mcap_scan.digest` in the read-ahead thread: ``arg`` is the channels and
    fronts taken when the chunk was scheduled."""
    return digest(raw, *arg)
