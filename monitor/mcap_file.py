"""A small MCAP writer of our own (records per https://mcap.dev/spec), for every MCAP file
buoymon writes: the logs of :mod:`replay.writer` (simulator, importer, benchmarks) and the
daemon's recordings (:mod:`monitor.recorder`).

Not ``mcap.writer.Writer``: that manages ~175 k messages/s in pure Python, too slow for the
30-day logs of the benchmark and the simulator, and costs the recorder more CPU per message
(bench/bench_record.py). The file layout is a standard indexed MCAP:

    magic, Header, [Schema, Channel]*, Chunk*, DataEnd,
    summary (Schema*, Channel*, Statistics, ChunkIndex*), SummaryOffset*, Footer, magic

(MessageIndex records after each chunk only with ``message_index=True``.) Schemas and channels
are written at top level (never inside a chunk) so a damaged chunk can never take a channel
definition with it; chunks are zstd-compressed with the CRC32 of their uncompressed bytes.
:meth:`McapFile.flush` closes the open chunk and fsyncs, so after a crash everything up to
the last flush is recoverable by ``replay.reader`` even without a footer.
"""

from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path

import numpy as np
import zstandard

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE = 0x01, 0x02, 0x03, 0x04, 0x05
OP_CHUNK, OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_ATTACHMENT = 0x06, 0x07, 0x08, 0x09
OP_ATTACHMENT_INDEX, OP_STATISTICS, OP_METADATA, OP_METADATA_INDEX = 0x0A, 0x0B, 0x0C, 0x0D
OP_SUMMARY_OFFSET, OP_DATA_END = 0x0E, 0x0F

_MSG_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
MSG_HEAD_SIZE = _MSG_HEAD.size  # 31
LIBRARY = "buoymon"


def _string(s: str) -> bytes:
    b = s.encode()
    return struct.pack("<I", len(b)) + b


def _record(op: int, content: bytes) -> bytes:
    return struct.pack("<BQ", op, len(content)) + content


class McapFile:
    """Append-only writer of one MCAP file: channels, messages, chunks, index and summary.

    Args:
        path: output file (created or truncated).
        chunk_size: target uncompressed chunk size in bytes.
        zstd_level: zstd compression level of the chunks.
        message_index: also write MCAP Message Index records after each chunk. Off by default:
            they cost 16 bytes per message (as much as a second of GNSS samples) and serve only
            readers that seek by time inside a chunk, which buoymon's reader and ``mcap``'s
            do not need; their one use here is the message count of a chunk lost to damage
            (unknown without them).

    Use as a context manager or call :meth:`close`; a file that is never closed has no footer,
    and ``replay.reader`` still reads it up to the last closed chunk.
    """

    def __init__(self, path: str | os.PathLike, *, chunk_size: int = 1 << 20, zstd_level: int = 3,
                 message_index: bool = False):
        if chunk_size < 1024:
            raise ValueError(f"chunk_size = {chunk_size}: must be at least 1024 bytes")
        self._message_index = message_index
        self.path = Path(path)
        self._f = open(self.path, "wb")
        self._chunk_size = chunk_size
        self._zstd = zstandard.ZstdCompressor(level=zstd_level)
        self._schemas: dict[str, tuple[int, bytes]] = {}  # name -> (id, record)
        self._channels: dict[str, tuple[int, bytes]] = {}  # topic -> (id, record)
        self._seq: dict[int, int] = {}
        self._msg_count: dict[int, int] = {}
        self._t_min: int | None = None
        self._t_max: int | None = None
        self._chunk_indexes: list[bytes] = []
        self._closed = False
        self._pos = 0
        self._reset_chunk()
        self._write(MAGIC + _record(OP_HEADER, _string("") + _string(LIBRARY)))

    def channel_id(self, topic: str) -> int | None:
        """The id of ``topic``'s channel, None before it is defined."""
        known = self._channels.get(topic)
        return None if known is None else known[0]

    def reserve(self, ch: int, n: int) -> int:
        """Count ``n`` messages of channel ``ch`` written as records by the caller
        (:meth:`append_records`); return the sequence number of the first."""
        seq0 = self._seq.get(ch, 0)
        self._seq[ch] = seq0 + n
        self._msg_count[ch] = self._msg_count.get(ch, 0) + n
        return seq0

    def flush(self, fsync: bool = True) -> None:
        """Close the open chunk and write it out; fsync the file if ``fsync``."""
        self._close_chunk()
        self._f.flush()
        if fsync:
            os.fsync(self._f.fileno())

    def close(self) -> None:
        """Write the index, summary and footer and close the file (idempotent)."""
        if self._closed:
            return
        self._close_chunk()
        self._write(_record(OP_DATA_END, struct.pack("<I", 0)))  # 0: data CRC not computed
        summary_start = self._pos
        groups: list[tuple[int, list[bytes]]] = [
            (OP_SCHEMA, [r for _, r in self._schemas.values()]),
            (OP_CHANNEL, [r for _, r in self._channels.values()]),
            (OP_STATISTICS, [self._statistics()]),
            (OP_CHUNK_INDEX, self._chunk_indexes),
        ]
        summary = bytearray()
        offsets = bytearray()
        for op, records in groups:
            if records:
                start = summary_start + len(summary)
                summary += b"".join(records)
                offsets += _record(OP_SUMMARY_OFFSET, struct.pack(
                    "<BQQ", op, start, summary_start + len(summary) - start))
        offset_start = summary_start + len(summary)
        summary += offsets
        footer_head = struct.pack("<BQQQ", OP_FOOTER, 20, summary_start, offset_start)
        crc = zlib.crc32(footer_head, zlib.crc32(summary))
        self._write(bytes(summary) + footer_head + struct.pack("<I", crc) + MAGIC)
        self._f.flush()
        os.fsync(self._f.fileno())
        self._f.close()
        self._closed = True

    def __enter__(self) -> "McapFile":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def channel(self, topic: str, schema: str, schema_enc: str, schema_data: bytes,
                msg_enc: str) -> int:
        """The id of ``topic``'s channel, defining it (and its schema) at its first use."""
        known = self._channels.get(topic)
        if known is not None:
            return known[0]
        if self._chunk_parts:
            self._close_chunk()  # definitions go at top level, between chunks
        if schema not in self._schemas:
            sid = len(self._schemas) + 1
            rec = _record(OP_SCHEMA, struct.pack("<H", sid) + _string(schema) + _string(schema_enc)
                          + struct.pack("<I", len(schema_data)) + schema_data)
            self._schemas[schema] = (sid, rec)
            self._write(rec)
        cid = len(self._channels)
        if cid > 0xFFFF:
            raise ValueError("too many channels in one log (max 65536)")
        rec = _record(OP_CHANNEL, struct.pack("<HH", cid, self._schemas[schema][0])
                      + _string(topic) + _string(msg_enc) + struct.pack("<I", 0))
        self._channels[topic] = (cid, rec)
        self._write(rec)
        return cid

    # ------------------------------------------------------------------ internals

    def _write(self, data: bytes) -> None:
        self._f.write(data)
        self._pos = self._f.tell()

    def _reset_chunk(self) -> None:
        self._chunk_parts: list[bytes] = []
        self._chunk_len = 0
        # per-message index entries: Python lists (one message at a time) ...
        self._one_ch: list[int] = []
        self._one_log: list[int] = []
        self._one_off: list[int] = []
        # ... and arrays (bulk appends)
        self._bulk: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._chunk_t: list[int | None] = [None, None]  # log-time range of its messages

    def _note_times(self, lo: int, hi: int) -> None:
        ct = self._chunk_t
        ct[0] = lo if ct[0] is None else min(ct[0], lo)
        ct[1] = hi if ct[1] is None else max(ct[1], hi)

    def add_message(self, ch: int, log_ns: int, pub_ns: int, payload: bytes) -> None:
        """Append one message of channel ``ch`` (times in ns since the epoch, both > 0)."""
        seq = self._seq.get(ch, 0)
        self._seq[ch] = seq + 1
        self._msg_count[ch] = self._msg_count.get(ch, 0) + 1
        head = _MSG_HEAD.pack(OP_MESSAGE, 22 + len(payload), ch, seq, log_ns, pub_ns)
        self._one_ch.append(ch)
        self._one_log.append(log_ns)
        self._one_off.append(self._chunk_len)
        self._chunk_parts += (head, payload)
        self._chunk_len += MSG_HEAD_SIZE + len(payload)
        self._note_times(log_ns, log_ns)
        if self._chunk_len >= self._chunk_size:
            self._close_chunk()

    def append_records(self, buf: np.ndarray, rec_off: np.ndarray, chan: np.ndarray,
                        log: np.ndarray) -> None:
        """Append whole message records, cutting chunks at record boundaries near the target."""
        n = chan.shape[0]
        i = 0
        while i < n:
            room = self._chunk_size - self._chunk_len
            j = int(np.searchsorted(rec_off, rec_off[i] + room, side="left"))
            j = min(max(j, i + 1), n)
            a, b = int(rec_off[i]), int(rec_off[j])
            self._bulk.append((chan[i:j], log[i:j], rec_off[i:j] - a + self._chunk_len))
            self._chunk_parts.append(buf[a:b].tobytes())
            self._chunk_len += b - a
            self._note_times(int(log[i:j].min()), int(log[i:j].max()))
            if self._chunk_len >= self._chunk_size:
                self._close_chunk()
            i = j

    def _close_chunk(self) -> None:
        if not self._chunk_parts:
            return
        data = b"".join(self._chunk_parts)
        ch = np.array(self._one_ch, np.int64)
        log = np.array(self._one_log, np.uint64)
        off = np.array(self._one_off, np.uint64)
        if self._bulk:
            ch = np.concatenate([ch, *(c for c, _, _ in self._bulk)])
            log = np.concatenate([log, *(lg.astype(np.uint64) for _, lg, _ in self._bulk)])
            off = np.concatenate([off, *(o.astype(np.uint64) for _, _, o in self._bulk)])
        comp = self._zstd.compress(data)
        t_lo, t_hi = self._chunk_t
        assert t_lo is not None and t_hi is not None  # the chunk holds messages
        content = (struct.pack("<QQQI", t_lo, t_hi, len(data), zlib.crc32(data))
                   + _string("zstd") + struct.pack("<Q", len(comp)))
        chunk_start = self._pos
        self._write(struct.pack("<BQ", OP_CHUNK, len(content) + len(comp)) + content)
        self._write(comp)
        chunk_len = self._pos - chunk_start
        index_offsets, mi = (self._message_indexes(ch, log, off) if self._message_index
                             else ([], b""))
        self._write(mi)
        self._chunk_indexes.append(_record(OP_CHUNK_INDEX, struct.pack(
            "<QQQQI", t_lo, t_hi, chunk_start, chunk_len, 10 * len(index_offsets))
            + b"".join(index_offsets) + struct.pack("<Q", len(mi)) + _string("zstd")
            + struct.pack("<QQ", len(comp), len(data))))
        self._t_min = t_lo if self._t_min is None else min(self._t_min, t_lo)
        self._t_max = t_hi if self._t_max is None else max(self._t_max, t_hi)
        self._reset_chunk()

    def _message_indexes(self, ch: np.ndarray, log: np.ndarray, off: np.ndarray
                         ) -> tuple[list[bytes], bytes]:
        """One MessageIndex record per channel of the chunk just written (entries sorted by log
        time, then offset) and the ChunkIndex's offsets of them."""
        index_offsets = []
        order = np.lexsort((off, log, ch))
        ch, log, off = ch[order], log[order], off[order]
        bounds = np.flatnonzero(np.r_[True, ch[1:] != ch[:-1], True])
        mi = bytearray()
        for a, b in zip(bounds[:-1], bounds[1:]):
            entries = np.empty((b - a, 2), "<u8")
            entries[:, 0] = log[a:b]
            entries[:, 1] = off[a:b]
            index_offsets.append(struct.pack("<HQ", int(ch[a]), self._pos + len(mi)))
            mi += _record(OP_MESSAGE_INDEX, struct.pack("<HI", int(ch[a]), entries.nbytes)
                          + entries.tobytes())
        return index_offsets, bytes(mi)

    def _statistics(self) -> bytes:
        counts = b"".join(struct.pack("<HQ", c, n) for c, n in sorted(self._msg_count.items()))
        return _record(OP_STATISTICS, struct.pack(
            "<QHIIIIQQI", sum(self._msg_count.values()), len(self._schemas), len(self._channels),
            0, 0, len(self._chunk_indexes), self._t_min or 0, self._t_max or 0, len(counts))
            + counts)
