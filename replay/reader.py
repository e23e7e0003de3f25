"""Fast, damage-tolerant reader of buoymon MCAP logs.

The file is read front to back record by record (https://mcap.dev/spec); the footer and
summary are not needed, so a file that was cut short (crash, power loss) or has damaged
chunks is read as far as it is intact. (An intact summary's copies of the channel definitions
are taken too, so a damaged chunk that held a channel's definition costs only its own
messages.) Each chunk is decompressed once, its records located by a numba scan and all of
its sensor payloads decoded in bulk (:func:`monitor.codec.decode_many`). With ``read_ahead``
(the default) a worker thread does all that for the next chunk
(:class:`replay.chunks.ReadAhead`; none of it holds the GIL) while the caller processes the
blocks of the current one; the results are the same either way.
This delivers millions of messages per second where ``mcap``'s per-message reader manages a
few hundred thousand.

Salvage (what is recovered, what is reported lost, see :class:`FileStats`):

* chunk CRC (when not 0) is checked; a chunk with a bad CRC, a wrong size or that does not
  decompress is skipped whole and reported as a :class:`LostRange` with its receive-time range
  (the chunk's log times) and its message count (from the Message Index records after it,
  ``None`` when those are missing too);
* a file cut inside a chunk: every complete message record of the decompressible prefix of the
  chunk is recovered, the rest is reported lost (count unknown);
* a missing footer/summary is only noted (``complete = False``): nothing is lost by it;
* a corrupt record header (impossible opcode or length) is reported and reading resumes at
  the next chunk found by its signature (a chunk whose length field alone is corrupt is
  still read whole when its CRC verifies);
* a payload that is not a valid block is dropped and counted in ``bad_payloads``.
Nothing raises on a damaged file; a file where nothing could be read has ``error`` set and
``messages == 0``; :attr:`LogReader.ok` is False when no file delivered any message.

Ordering guarantees (deterministic for the same files in the same order):

1. Messages of all files pass through one reorder buffer, keyed by MCAP ``publish_time``
   (= sensor time of the block's first sample). A message is released once a message with a
   publish time more than ``reorder_window_s`` later has been read (at the end, all are).
2. Released messages are delivered sorted by ``(publish_time, topic, read order)``; so
   messages that are out of order by less than the window are delivered in sensor-time order.
3. A message read after messages more than the window newer than it (``publish_time`` at or
   before an already released one) is *late*: it is counted in ``late`` and delivered with the
   next release, i.e. out of order; the pipeline's validation then rejects its samples.
4. Duplicates (same topic, same publish time, identical samples) met within the window are
   delivered once and counted in ``duplicates``.
5. With ``coalesce=True`` the messages of one topic in one release are concatenated, in the
   order of 2, into ONE :class:`SampleBlock` (tens of thousands of samples); the blocks of one
   release are ordered by (first publish time, topic). The samples of each topic are exactly
   those of ``coalesce=False`` in the same order; only the interleaving between topics is
   coarser (per release instead of per message). ``recv_ns`` of a coalesced block is the
   latest receive time of its messages. A release is cut into spans of
   :data:`COALESCE_S` of publish time, each giving its own blocks, so no block covers more.
"""

from __future__ import annotations

import logging
import struct
import zlib
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Iterable, Iterator, Mapping, Sequence

import numba
import numpy as np
import zstandard

from monitor.blocks import SENSOR_FIELDS, SampleBlock, parse_sensor_topic
from monitor import codec
from replay.chunks import Inflated, ReadAhead, inflate

log = logging.getLogger(__name__)
from replay.writer import (
    MAGIC, OP_CHANNEL, OP_CHUNK, OP_DATA_END, OP_FOOTER, OP_MESSAGE, OP_MESSAGE_INDEX,
    OP_SCHEMA, OP_STATISTICS,
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
    duplicates: int = 0
    late: int = 0
    bad_payloads: int = 0
    skipped: dict[str, int] = field(default_factory=dict)  # non-sensor / undecodable channels
    first_ns: int | None = None  # earliest / latest publish time of the sensor messages read
    last_ns: int | None = None
    lost: list[LostRange] = field(default_factory=list)
    error: str | None = None

    @property
    def readable(self) -> bool:
        return self.messages > 0

    def as_dict(self) -> dict:
        d = {k: v for k, v in self.__dict__.items() if k != "lost"}
        d["lost"] = [r.__dict__ for r in self.lost]
        return d


def expand_paths(paths: Iterable[str | PathLike], *, recursive: bool = False,
                 missing: str = "keep") -> list[Path]:
    """Files as given; a directory expands to its ``*.mcap`` files sorted by name (with
    ``recursive``, those of its sub-folders too). A path that does not exist is kept
    (``missing="keep"``: reading it then reports it unreadable), logged and skipped
    (``"skip"``) or a FileNotFoundError (``"raise"``)."""
    if missing not in ("keep", "skip", "raise"):
        raise ValueError(f"missing = {missing!r}: must be 'keep', 'skip' or 'raise'")
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(p.rglob("*.mcap") if recursive else p.glob("*.mcap"))
            if not found:  # a mistyped folder among others would otherwise pass unnoticed
                log.warning("%s: no *.mcap file in this folder%s", p,
                            "" if recursive else " (its sub-folders not searched)")
            out.extend(found)
        elif p.exists() or missing == "keep":
            out.append(p)
        elif missing == "raise":
            raise FileNotFoundError(f"no such log file or folder: {p}")
        else:
            log.error("%s does not exist; skipped", p)
    return out


# ------------------------------------------------------------------------------ record scan


@numba.njit(cache=True, nogil=True)  # runs in the read-ahead thread
def _scan_records(buf):
    """Locate records in a decompressed chunk (or any record sequence).

    Returns message fields (channel, log, publish, payload offset, payload length), the other
    records (opcode, content offset, length), the end position and a status: 0 all records
    complete, 1 the buffer ends inside a record, 2 an impossible record (opcode 0).
    """
    n = buf.shape[0]
    cap = n // 31 + 1
    ch = np.empty(cap, np.int64)
    log = np.empty(cap, np.int64)
    pub = np.empty(cap, np.int64)
    doff = np.empty(cap, np.int64)
    dlen = np.empty(cap, np.int64)
    ocap = n // 9 + 1
    oop = np.empty(ocap, np.int64)
    ooff = np.empty(ocap, np.int64)
    olen = np.empty(ocap, np.int64)
    m = 0
    o = 0
    p = 0
    status = 0
    while p < n:
        if p + 9 > n:
            status = 1
            break
        op = buf[p]
        ln = np.uint64(0)
        for i in range(8):
            ln |= np.uint64(buf[p + 1 + i]) << np.uint64(8 * i)
        if op == 0:
            status = 2
            break
        if ln > np.uint64(n - p - 9):
            status = 1
            break
        c = p + 9
        if op == 5 and ln >= 22:
            ch[m] = np.int64(buf[c]) | (np.int64(buf[c + 1]) << 8)
            lt = np.uint64(0)
            pt = np.uint64(0)
            for i in range(8):
                lt |= np.uint64(buf[c + 6 + i]) << np.uint64(8 * i)
                pt |= np.uint64(buf[c + 14 + i]) << np.uint64(8 * i)
            log[m] = np.int64(lt)
            pub[m] = np.int64(pt)
            doff[m] = c + 22
            dlen[m] = np.int64(ln) - 22
            m += 1
        else:
            oop[o] = op
            ooff[o] = c
            olen[o] = np.int64(ln)
            o += 1
        p = c + np.int64(ln)
    return ch[:m], log[:m], pub[:m], doff[:m], dlen[:m], oop[:o], ooff[:o], olen[:o], p, status


@dataclass(slots=True)
class _Digest:
    """A run of records located by :func:`_scan_records`, its messages grouped by channel
    (indices in record order) and the payloads of the channels already known decoded."""

    buf: np.ndarray
    scan: tuple
    groups: dict[int, np.ndarray]
    decoded: dict[int, tuple]


def _digest(raw: bytes, channels: Mapping[int, tuple[int, tuple] | str]) -> _Digest:
    """Scan ``raw`` and decode the messages of the sensor channels in ``channels``. A pure
    function of its inputs, so the read-ahead thread can run it (channel definitions never
    change once read, so a copy of them taken earlier decodes the same)."""
    buf = np.frombuffer(raw, np.uint8)
    scan = _scan_records(buf)
    ch, doff, dlen = scan[0], scan[3], scan[4]
    groups = {c: np.flatnonzero(ch == c) for c in np.unique(ch).tolist()}
    decoded = {}
    for c, sel in groups.items():
        target = channels.get(c)
        if isinstance(target, tuple):
            decoded[c] = codec.decode_many(buf, doff[sel], dlen[sel], target[1])
    return _Digest(buf, scan, groups, decoded)


_MAX_CUT_CHUNK = 64 << 20  # bytes read for a chunk whose length runs past the end of file
_CHUNK_SIGNATURES = (b"\x04\x00\x00\x00zstd", b"\x03\x00\x00\x00lz4")
_SIG_AT = 37  # opcode, length, start, end, uncompressed size, CRC: then the compression string


def _find_chunk(f, start: int, size: int) -> int | None:
    """Offset of the first plausible compressed Chunk record at or after ``start``, else None."""
    block = 1 << 20
    at = start
    while at < size:
        f.seek(at)
        buf = f.read(block + 64)
        hits = []
        for sig in _CHUNK_SIGNATURES:
            i = buf.find(sig)
            while i >= 0:
                s = at + i - _SIG_AT
                if s >= start and i >= _SIG_AT and buf[i - _SIG_AT] == OP_CHUNK:
                    (ln,) = struct.unpack_from("<Q", buf, i - _SIG_AT + 1)
                    if 0 < ln <= size - s - 9:
                        hits.append(s)
                        break
                i = buf.find(sig, i + 1)
        if hits:
            return min(hits)
        at += block
    return None


def _str_at(b: bytes | memoryview, p: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", b, p)
    return bytes(b[p + 4:p + 4 + n]).decode("utf-8", "replace"), p + 4 + n


# ------------------------------------------------------------------------------ streams


class _Stream:
    """Pending (not yet released) samples of one topic, across files."""

    def __init__(self, topic: str, buoy_id: str, sensor: str):
        self.topic, self.buoy_id, self.sensor = topic, buoy_id, sensor
        self.nf = len(SENSOR_FIELDS[sensor])
        self.t_parts: list[np.ndarray] = []
        self.v_parts: list[np.ndarray] = []
        self.length = 0

    def add(self, t: np.ndarray, v: np.ndarray) -> int:
        """Append samples; return their start index in the stream's pending store."""
        start = self.length
        self.t_parts.append(t)
        self.v_parts.append(v)
        self.length += t.shape[0]
        return start

    def store(self) -> tuple[np.ndarray, np.ndarray]:
        if len(self.t_parts) != 1:
            self.t_parts = [np.concatenate(self.t_parts) if self.t_parts else np.empty(0, np.int64)]
            self.v_parts = [np.concatenate(self.v_parts, axis=1) if self.v_parts
                            else np.empty((self.nf, 0))]
        return self.t_parts[0], self.v_parts[0]


def _gather_index(start: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Indices ``start[i] .. start[i] + n[i]`` of all messages, concatenated."""
    total = int(n.sum())
    if total == 0:
        return np.empty(0, np.int64)
    first = np.cumsum(n) - n
    return np.repeat(start - first, n) + np.arange(total)


def _take(t: np.ndarray, v: np.ndarray, start: np.ndarray, n: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:
    """Samples of messages (start, n) in that order: views when they are contiguous (usual)."""
    if start.shape[0] == 0:
        return t[:0], v[:, :0]
    if np.array_equal(start[1:], start[:-1] + n[:-1]):
        a, b = int(start[0]), int(start[-1] + n[-1])
        return t[a:b], v[:, a:b]
    idx = _gather_index(start, n)
    return t[idx], v[:, idx]


_COLS = ("stream", "pub", "log", "start", "n", "seq", "file")
# Longest stretch of sensor time (by publish time) one coalesced block covers. The replay's
# ordering passes by a stream lagging the newest data by more than [ordering]
# replay_horizon_s (1 h) and rejects what then arrives as late: a chunk of compact samples
# holds more than an hour of the default streams, so a release of a whole chunk must be cut;
# at half the horizon, as long as the chunks of the float64 format, as few blocks as that
# allows (the pipeline's cost per block is the fleet benchmark's: 600 s cost 15 % more CPU).
COALESCE_S = 1800
COALESCE_NS = COALESCE_S * 1_000_000_000


class LogReader:
    """Iterate over the sensor blocks of one or more logs, with per-file statistics.

    Args:
        paths: files or directories (see :func:`expand_paths`), read in the given order.
        coalesce: concatenate messages per topic and release (see module doc) for speed.
        reorder_window_s: sensor-time horizon within which out-of-order messages are sorted.
        read_ahead: inflate the next chunk in a worker thread while the caller processes the
            blocks of the current one (same results; uses a second core).

    Iterate once; afterwards :attr:`stats` holds one :class:`FileStats` per file.
    """

    def __init__(self, paths: Sequence[str | PathLike] | str | PathLike, *, coalesce: bool = True,
                 reorder_window_s: float = 60.0, read_ahead: bool = True):
        if isinstance(paths, (str, PathLike)):
            paths = [paths]
        if not reorder_window_s >= 0:
            raise ValueError(f"reorder_window_s = {reorder_window_s}: must be >= 0")
        self.paths = expand_paths(paths)
        self.coalesce = coalesce
        self.read_ahead = read_ahead
        self.window_ns = int(round(reorder_window_s * 1e9))
        self.stats: list[FileStats] = []
        self._streams: list[_Stream] = []
        self._stream_of: dict[str, int] = {}
        self._pending: list[dict[str, np.ndarray]] = []
        self._max_pub = np.iinfo(np.int64).min
        self._released_to = np.iinfo(np.int64).min
        self._seq = 0
        self._dctx = zstandard.ZstdDecompressor()

    @property
    def ok(self) -> bool:
        """True when at least one sensor message was read."""
        return any(s.messages > 0 for s in self.stats)

    def __iter__(self) -> Iterator[SampleBlock]:
        for i, path in enumerate(self.paths):
            st = FileStats(path=str(path))
            self.stats.append(st)
            for _ in self._read_file(i, path, st):
                yield from self._release(final=False)
        yield from self._release(final=True)

    # -------------------------------------------------------------- file level (salvage)

    def _read_file(self, fidx: int, path: Path, st: FileStats) -> Iterator[None]:
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
            ctx = _FileContext(fidx)
            self._summary_definitions(f, size, ctx)
            f.seek(8)
            ahead = ReadAhead(f.fileno(), size, _digest) if self.read_ahead else None
            try:
                yield from self._read_records(f, size, ctx, st, ahead)
            finally:
                if ahead is not None:
                    ahead.close()

    def _summary_definitions(self, f, size: int, ctx: "_FileContext") -> None:
        """Take the schemas and channels repeated in the summary section, when the file ends
        in an intact footer. mcap's own writer (``buoymon record``) defines a channel inside
        the first chunk that uses it: should that chunk be damaged, the channel's messages in
        the other chunks are then still decoded. The definitions are the same as in the data
        section (the first one read wins), so an intact file reads exactly as before."""
        scratch = FileStats(path="")  # a damaged summary loses no data: not reported as loss
        for op, content in _summary_records(f, size):
            if op in (OP_SCHEMA, OP_CHANNEL):
                ctx.definition(op, content, self, scratch)

    def _read_records(self, f, size: int, ctx: "_FileContext", st: FileStats,
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
                nxt = _find_chunk(f, pos + 1, size)
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
                    self._records(_digest(b"".join(loose), ctx.channels), ctx, st)
                    loose.clear()
                    yield
                pos += 9 + ln
                continue
            if loose:
                self._records(_digest(b"".join(loose), ctx.channels), ctx, st)
                loose.clear()
                yield
            if awaiting is not None and op != OP_MESSAGE_INDEX:
                awaiting = None
            if op == OP_CHUNK:
                got = ahead.take(pos) if ahead is not None else None
                if got is None:
                    content = f.read(min(ln, _MAX_CUT_CHUNK) if cut else ln)
                    got = inflate(content, cut, self._dctx), None
                else:
                    f.seek(ln, 1)
                awaiting = self._chunk(*got, pos, ctx, st)
                if ahead is not None and not cut:
                    # the next chunk is inflated and digested while the caller works
                    ahead.schedule(pos + 9 + ln, dict(ctx.channels))
                yield
                if cut:  # a truncated file, or a corrupt length: look for a next chunk
                    nxt = _find_chunk(f, pos + 1, size)
                    if nxt is None:
                        break
                    f.seek(nxt)
                    pos = nxt
                    continue
            elif op in (OP_SCHEMA, OP_CHANNEL):
                ctx.definition(op, f.read(ln), self, st)
            elif op == OP_MESSAGE_INDEX and awaiting is not None:
                content = f.read(ln)
                (nbytes,) = struct.unpack_from("<I", content, 2)
                lost = awaiting[0]
                awaiting[0] = LostRange(lost.reason, lost.offset, lost.start_ns, lost.end_ns,
                                        (lost.messages or 0) + nbytes // 16)
                st.lost[awaiting[1]] = awaiting[0]
            elif op in (OP_DATA_END, OP_FOOTER):
                st.complete = True
                break
            else:
                f.seek(ln, 1)
            pos += 9 + ln
        if loose:
            self._records(_digest(b"".join(loose), ctx.channels), ctx, st)
            yield
        if st.messages == 0 and st.error is None:
            st.error = "no sensor messages could be read"

    def _chunk(self, c: Inflated, digest: _Digest | None, pos: int, ctx: "_FileContext",
               st: FileStats) -> list | None:
        """Take one inflated chunk (``digest``: its records, when the read-ahead scanned them);
        return ``[LostRange, index in st.lost]`` if it was lost whole and its Message Index
        records may still give the count of its messages."""
        st.chunks += 1
        if c.raw is None:
            st.bad_chunks += 1
            st.lost.append(LostRange(c.error, pos, c.t_lo, c.t_hi))
            return [st.lost[-1], len(st.lost) - 1] if c.indexed else None
        n = self._records(digest if digest is not None else _digest(c.raw, ctx.channels),
                          ctx, st)
        if c.cut:
            st.bad_chunks += 1
            st.lost.append(LostRange(
                f"file cut inside a chunk: {n} messages of it recovered", pos,
                ctx.last_log if n else c.t_lo, c.t_hi))
        return None

    # -------------------------------------------------------------- record level

    def _records(self, d: _Digest, ctx: "_FileContext", st: FileStats) -> int:
        """Handle a run of records; return the number of messages found in it."""
        buf = d.buf
        ch, log, pub, doff, dlen, oop, ooff, olen, _, _ = d.scan
        raw = None
        for op, a, ln in zip(oop.tolist(), ooff.tolist(), olen.tolist()):
            if op in (OP_SCHEMA, OP_CHANNEL):
                raw = buf.tobytes() if raw is None else raw
                ctx.definition(op, raw[a:a + ln], self, st)
        if ch.shape[0] == 0:
            return 0
        ctx.last_log = int(log[-1])
        seq = self._seq + np.arange(ch.shape[0], dtype=np.int64)
        self._seq += ch.shape[0]
        parts = []
        for c, sel in d.groups.items():
            target = ctx.channels.get(c)
            if target is None or isinstance(target, str):
                topic = target if isinstance(target, str) else f"<unknown channel {c}>"
                st.skipped[topic] = st.skipped.get(topic, 0) + sel.shape[0]
                continue
            sidx, numbers = target
            decoded = d.decoded.get(c)  # else defined in this very run of records
            status, n, t, vals = (decoded if decoded is not None
                                  else codec.decode_many(buf, doff[sel], dlen[sel], numbers))
            good = status == codec.OK
            st.bad_payloads += int(sel.shape[0] - good.sum())
            sel, n = sel[good], n[good]
            stream = self._streams[sidx]
            start = stream.add(t, vals) + np.cumsum(n) - n
            topic = stream.topic
            st.messages_by_topic[topic] = st.messages_by_topic.get(topic, 0) + sel.shape[0]
            st.messages += sel.shape[0]
            st.samples += int(n.sum())
            if sel.shape[0]:
                lo, hi = int(pub[sel].min()), int(pub[sel].max())
                st.first_ns = lo if st.first_ns is None else min(st.first_ns, lo)
                st.last_ns = hi if st.last_ns is None else max(st.last_ns, hi)
            parts.append({"stream": np.full(sel.shape[0], sidx, np.int64), "pub": pub[sel],
                          "log": log[sel], "start": start, "n": n, "seq": seq[sel],
                          "file": np.full(sel.shape[0], ctx.fidx, np.int64)})
        for p in parts:
            late = p["pub"] <= self._released_to
            if late.any():
                st.late += int(late.sum())
            if p["pub"].shape[0]:
                self._max_pub = max(self._max_pub, int(p["pub"].max()))
            self._pending.append(p)
        return int(ch.shape[0])

    def stream_index(self, topic: str) -> int | None:
        """Index of a sensor topic's stream, creating it (None if not a sensor topic)."""
        idx = self._stream_of.get(topic)
        if idx is None:
            try:
                buoy, sensor = parse_sensor_topic(topic)
            except ValueError:
                return None
            if sensor not in SENSOR_FIELDS:
                return None
            idx = self._stream_of[topic] = len(self._streams)
            self._streams.append(_Stream(topic, buoy, sensor))
        return idx

    # -------------------------------------------------------------- ordering and release

    def _release(self, final: bool) -> Iterator[SampleBlock]:
        if not self._pending:
            return
        if not final and self._max_pub - self.window_ns <= self._released_to:
            return
        tab = {k: np.concatenate([p[k] for p in self._pending]) for k in _COLS}
        cut = np.iinfo(np.int64).max if final else self._max_pub - self.window_ns
        out = tab["pub"] <= cut
        if not out.any():
            return
        rel = {k: v[out] for k, v in tab.items()}
        keep = {k: v[~out] for k, v in tab.items()}
        self._released_to = max(self._released_to, int(rel["pub"].max()))
        # canonical order: publish time, topic, read order
        rank = np.argsort(np.argsort([s.topic for s in self._streams]))
        order = np.lexsort((rel["seq"], rank[rel["stream"]], rel["pub"]))
        rel = {k: v[order] for k, v in rel.items()}
        stores = {int(s): self._streams[s].store() for s in np.unique(tab["stream"])}
        rel = self._drop_duplicates(rel, stores)
        # a release is as long as a chunk: cut it into spans of at most COALESCE_S of sensor
        # time, so no coalesced block runs ahead of the other streams by more than that
        span = (rel["pub"] - rel["pub"][0]) // COALESCE_NS if rel["pub"].shape[0] else rel["pub"]
        cuts = np.flatnonzero(np.r_[True, span[1:] != span[:-1], True])
        blocks = [b for a, z in zip(cuts[:-1], cuts[1:])
                  for b in self._blocks({k: v[a:z] for k, v in rel.items()}, stores, rank)]
        # compact: keep only the held-back samples in the stores
        for s, (t, v) in stores.items():
            stream = self._streams[s]
            mine = keep["stream"] == s
            kt, kv = _take(t, v, keep["start"][mine], keep["n"][mine])
            stream.t_parts, stream.v_parts = [kt], [kv]
            stream.length = kt.shape[0]
            keep["start"][mine] = np.cumsum(keep["n"][mine]) - keep["n"][mine]
        self._pending = [keep] if keep["pub"].shape[0] else []
        yield from blocks

    def _drop_duplicates(self, rel: dict, stores: dict) -> dict:
        same = ((rel["pub"][1:] == rel["pub"][:-1]) & (rel["stream"][1:] == rel["stream"][:-1]))
        if not same.any():
            return rel
        drop = np.zeros(rel["pub"].shape[0], bool)
        # runs of equal (pub, stream): compare each message with the earlier kept ones
        for j in np.flatnonzero(same) + 1:
            i = j - 1
            while (i >= 0 and rel["pub"][i] == rel["pub"][j]
                   and rel["stream"][i] == rel["stream"][j]):
                if not drop[i] and self._same_samples(rel, stores, i, j):
                    drop[j] = True
                    break
                i -= 1
        for f in rel["file"][drop].tolist():
            self.stats[f].duplicates += 1
        return {k: v[~drop] for k, v in rel.items()}

    @staticmethod
    def _same_samples(rel: dict, stores: dict, i: int, j: int) -> bool:
        if rel["n"][i] != rel["n"][j]:
            return False
        t, v = stores[int(rel["stream"][i])]
        a, b, n = int(rel["start"][i]), int(rel["start"][j]), int(rel["n"][i])
        return bool(np.array_equal(t[a:a + n], t[b:b + n])
                    and np.array_equal(v[:, a:a + n], v[:, b:b + n], equal_nan=True))

    def _blocks(self, rel: dict, stores: dict, rank: np.ndarray) -> list[SampleBlock]:
        out: list[tuple[int, int, int, SampleBlock]] = []
        for s in np.unique(rel["stream"]).tolist():
            mine = np.flatnonzero(rel["stream"] == s)
            stream = self._streams[s]
            t, v = stores[s]
            names = list(SENSOR_FIELDS[stream.sensor])
            if self.coalesce:
                tt, vv = _take(t, v, rel["start"][mine], rel["n"][mine])
                blk = SampleBlock(stream.buoy_id, stream.sensor, tt,
                                  {f: vv[q] for q, f in enumerate(names)},
                                  int(rel["log"][mine].max()))
                out.append((int(rel["pub"][mine[0]]), int(rank[s]), int(mine[0]), blk))
                continue
            for k in mine.tolist():
                a, n = int(rel["start"][k]), int(rel["n"][k])
                blk = SampleBlock(stream.buoy_id, stream.sensor, t[a:a + n].copy(),
                                  {f: v[q, a:a + n].copy() for q, f in enumerate(names)},
                                  int(rel["log"][k]))
                out.append((0, 0, k, blk))
        out.sort(key=lambda x: x[:3])
        return [b for *_, b in out]


class _FileContext:
    """Schemas and channels of one file: channel id -> (stream, field numbers) or a skip reason."""

    def __init__(self, fidx: int):
        self.fidx = fidx
        self.schemas: dict[int, tuple[str, str, bytes]] = {}
        self.channels: dict[int, tuple[int, tuple] | str] = {}
        self.last_log = 0

    def definition(self, op: int, b: bytes, reader: LogReader, st: FileStats) -> None:
        try:
            if op == OP_SCHEMA:
                (sid,) = struct.unpack_from("<H", b, 0)
                name, p = _str_at(b, 2)
                enc, p = _str_at(b, p)
                (n,) = struct.unpack_from("<I", b, p)
                self.schemas[sid] = (name, enc, bytes(b[p + 4:p + 4 + n]))
                return
            cid, sid = struct.unpack_from("<HH", b, 0)
            topic, p = _str_at(b, 4)
            enc, _ = _str_at(b, p)
        except (struct.error, UnicodeDecodeError):
            st.lost.append(LostRange("malformed schema or channel record", -1))
            return
        if cid in self.channels:
            return
        schema = self.schemas.get(sid)
        sidx = reader.stream_index(topic)
        if sidx is None or schema is None or schema[1] != "protobuf" or enc != "protobuf":
            self.channels[cid] = topic  # not a sensor block channel: skipped, counted
            return
        try:
            numbers = codec.field_numbers_from_schema(schema[2], schema[0],
                                                      reader._streams[sidx].sensor)
        except Exception as e:  # a foreign or broken schema: skip its messages, say why
            self.channels[cid] = f"{topic} (undecodable schema: {e})"
            return
        self.channels[cid] = (sidx, numbers)


def _summary_records(f, size: int) -> Iterator[tuple[int, bytes]]:
    """``(opcode, content)`` of the summary section's records, when the file ends in an
    intact footer and its summary passes the footer's CRC; nothing otherwise."""
    if size < 8 + 37:
        return
    f.seek(size - 37)
    tail = f.read(37)  # footer record (opcode, length, 20 bytes), then the magic
    if tail[-8:] != MAGIC or tail[0] != OP_FOOTER:
        return
    start, _, crc = struct.unpack_from("<QQI", tail, 9)
    if not 8 <= start < size - 37:
        return
    f.seek(start)
    buf = f.read(size - 37 - start)
    if crc != 0 and zlib.crc32(tail[:25], zlib.crc32(buf)) != crc:
        return
    pos = 0
    while pos + 9 <= len(buf):
        op, ln = struct.unpack_from("<BQ", buf, pos)
        if ln > len(buf) - pos - 9:
            return
        yield op, buf[pos + 9:pos + 9 + ln]
        pos += 9 + ln


def _file_span(path: Path) -> tuple[int, int] | None:
    """(first, last) message log time of one file from its summary Statistics record."""
    try:
        with open(path, "rb") as f:
            size = f.seek(0, 2)
            for op, content in _summary_records(f, size):
                if op == OP_STATISTICS and len(content) >= 42:
                    t0, t1 = struct.unpack_from("<QQ", content, 26)
                    return (t0, t1) if t1 >= t0 > 0 else None
    except OSError:
        pass
    return None


def time_span(paths: Sequence[str | PathLike] | str | PathLike) -> tuple[int, int] | None:
    """(first, last) message log time over the files, from their summary Statistics records.

    Cheap (reads only the ends of the files), for progress bars; files without a readable
    footer/summary are left out, and None is returned when no file has one.
    """
    if isinstance(paths, (str, PathLike)):
        paths = [paths]
    spans = [sp for sp in map(_file_span, expand_paths(paths)) if sp is not None]
    if not spans:
        return None
    return min(sp[0] for sp in spans), max(sp[1] for sp in spans)


def file_start_ns(path: str | PathLike) -> int | None:
    """The first message log time of a file: from its summary, else from the header of its
    first chunk (a file cut short by a crash); None when neither can be read. Cheap."""
    span = _file_span(Path(path))
    if span is not None:
        return span[0]
    try:
        with open(path, "rb") as f:
            if f.read(8) != MAGIC:
                return None
            while True:
                head = f.read(9)
                if len(head) < 9:
                    return None
                op, ln = struct.unpack("<BQ", head)
                if op in (OP_CHUNK, OP_MESSAGE):  # a chunk's start time; a message's own
                    head = f.read(14)
                    if len(head) < 14:
                        return None
                    return struct.unpack_from("<Q", head, 0 if op == OP_CHUNK else 6)[0]
                if op == 0 or op >= 0x10:
                    return None
                f.seek(ln, 1)
    except OSError:
        return None


def iter_blocks(paths: Sequence[str | PathLike] | str | PathLike, coalesce: bool = True,
                reorder_window_s: float = 60.0) -> Iterator[SampleBlock]:
    """Shorthand for ``iter(LogReader(paths, ...))`` when the statistics are not needed."""
    return iter(LogReader(paths, coalesce=coalesce, reorder_window_s=reorder_window_s))
