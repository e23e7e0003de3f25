"""Write buoymon MCAP logs: sensor blocks (protobuf) and monitor outputs (JSON).

A small MCAP writer of our own (records per https://mcap.dev/spec) rather than
``mcap.writer.Writer``: the latter manages ~175 k messages/s in pure Python, too slow for the
30-day logs of the benchmark and the simulator. The file layout is a standard indexed MCAP:

    magic, Header, [Schema, Channel]*, Chunk*, DataEnd,
    summary (Schema*, Channel*, Statistics, ChunkIndex*), SummaryOffset*, Footer, magic

(MessageIndex records after each chunk only with ``message_index=True``.) Sensor payloads are
the compact protobuf blocks of :mod:`monitor.codec`, each field stored to its quantum.

Schemas and channels are written at top level (never inside a chunk) so a damaged chunk can
never take a channel definition with it; chunks are zstd-compressed with the CRC32 of their
uncompressed bytes. :meth:`LogWriter.flush` closes the open chunk and fsyncs, so after a crash
everything up to the last flush is recoverable by :mod:`replay.reader` even without a footer.

Times: ``log_time`` = receive time, ``publish_time`` = sensor time of the block's first sample;
both must be > 0.
"""

from __future__ import annotations

import json
import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import zstandard

from models._jit import kernel
from monitor.blocks import SENSOR_FIELDS, SampleBlock, sensor_topic, validate_buoy_id
from monitor import codec
from monitor.strict_json import to_json_bytes
from monitor.quanta import quanta as sensor_quanta

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE = 0x01, 0x02, 0x03, 0x04, 0x05
OP_CHUNK, OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_ATTACHMENT = 0x06, 0x07, 0x08, 0x09
OP_ATTACHMENT_INDEX, OP_STATISTICS, OP_METADATA, OP_METADATA_INDEX = 0x0A, 0x0B, 0x0C, 0x0D
OP_SUMMARY_OFFSET, OP_DATA_END = 0x0E, 0x0F

_MSG_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
MSG_HEAD_SIZE = _MSG_HEAD.size  # 31
LIBRARY = "buoymon"


def status_topic(buoy_id: str) -> str:
    """Topic of the monitor's periodic status messages."""
    return f"buoy/{validate_buoy_id(buoy_id)}/monitor/status"


def alert_topic(buoy_id: str, rule: str, component: str) -> str:
    """Topic of one alert rule's transitions for one component."""
    for what, v in (("rule", rule), ("component", component)):
        if not v or "/" in v or any(c in v for c in "*$?#"):
            raise ValueError(f"alert {what} {v!r} must be a non-empty key chunk without / * $ ? #")
    return f"buoy/{validate_buoy_id(buoy_id)}/monitor/alert/{rule}/{component}"


# JSON Schemas of the monitor channels: objects, open to additional properties so the monitor
# can add fields without a format change; Foxglove needs a top-level "type": "object".
STATUS_SCHEMA: Mapping[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "buoymon.v1.Status",
    "description": "Periodic monitor status of one buoy. Non-finite numbers are written as null.",
    "type": "object",
}
ALERT_SCHEMA: Mapping[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "buoymon.v1.Alert",
    "description": "One alert transition (raised, updated, cleared) of one rule and component.",
    "type": "object",
}


def _json_schema_for(topic: str) -> Mapping[str, Any]:
    parts = topic.split("/")
    if len(parts) == 4 and parts[2:] == ["monitor", "status"]:
        return STATUS_SCHEMA
    if len(parts) == 6 and parts[2:4] == ["monitor", "alert"]:
        return ALERT_SCHEMA
    return {"title": "buoymon.v1.Json", "type": "object"}


def _string(s: str) -> bytes:
    b = s.encode()
    return struct.pack("<I", len(b)) + b


def _record(op: int, content: bytes) -> bytes:
    return struct.pack("<BQ", op, len(content)) + content


@dataclass(frozen=True)
class Series:
    """A stretch of one sensor's samples, to be cut into blocks by :meth:`LogWriter.write_series`.

    ``values`` is float64 (n_fields, n) in :data:`SENSOR_FIELDS` order; ``t_ns`` int64 (n,).
    """

    buoy_id: str
    sensor: str
    t_ns: np.ndarray
    values: np.ndarray


@kernel()
def _encode_records(t, vals, quanta, starts, channel, seq0, log_ns):
    """MCAP message records (header + protobuf payload) of blocks ``starts[k]:starts[k+1]``."""
    nb = starts.shape[0] - 1
    nf = vals.shape[0]
    bound = 0
    for k in range(nb):
        bound += 31 + codec.payload_bound(starts[k + 1] - starts[k], nf)
    out = np.empty(bound, np.uint8)
    rec_off = np.empty(nb + 1, np.int64)
    head = np.empty(5, np.uint64)
    widths = (8, 2, 4, 8, 8)
    p = 0
    for k in range(nb):
        rec_off[k] = p
        q = codec.put_payload(out, p + 31, t, vals, quanta, starts[k], starts[k + 1])
        head[0] = np.uint64(q - p - 9)  # record length
        head[1] = np.uint64(channel)
        head[2] = np.uint64(seq0 + k)
        head[3] = np.uint64(log_ns[k])
        head[4] = np.uint64(t[starts[k]])
        out[p] = OP_MESSAGE
        w = p + 1
        for h in range(5):
            for i in range(widths[h]):
                out[w + i] = np.uint8((head[h] >> np.uint64(8 * i)) & np.uint64(0xFF))
            w += widths[h]
        p = q
    rec_off[nb] = p
    return out[:p], rec_off


@kernel()
def _gather(buf, rec_off, order):
    """Concatenate records ``order`` of ``buf`` (bounds ``rec_off``); return bytes and bounds."""
    out = np.empty(buf.shape[0], np.uint8)
    new_off = np.empty(order.shape[0] + 1, np.int64)
    p = 0
    for i in range(order.shape[0]):
        k = order[i]
        a, b = rec_off[k], rec_off[k + 1]
        new_off[i] = p
        out[p:p + b - a] = buf[a:b]
        p += b - a
    new_off[order.shape[0]] = p
    return out[:p], new_off


class LogWriter:
    """Append-only writer of one buoymon MCAP log.

    Args:
        path: output file (created or truncated).
        chunk_size: target uncompressed chunk size in bytes.
        zstd_level: zstd compression level of the chunks (3: the quantized samples compress
            by a third more than at level 1, at a cost the writer does not notice).
        quanta: quantum per field name (see :func:`monitor.codec.quanta`), overriding
            :data:`monitor.codec.DEFAULT_QUANTA`; every sample is stored to within half of it.
        message_index: also write MCAP Message Index records after each chunk. Off by default:
            they cost 16 bytes per message (as much as a second of GNSS samples) and serve only
            readers that seek by time inside a chunk, which buoymon's reader and ``mcap``'s
            do not need; their one use here is the message count of a chunk lost to damage
            (unknown without them).

    Use as a context manager or call :meth:`close`; a writer that is never closed leaves a
    file without footer, which :mod:`replay.reader` still reads up to the last closed chunk.
    """

    def __init__(self, path: str | os.PathLike, *, chunk_size: int = 1 << 20, zstd_level: int = 3,
                 quanta: Mapping[str, float] | None = None, message_index: bool = False):
        if chunk_size < 1024:
            raise ValueError(f"chunk_size = {chunk_size}: must be at least 1024 bytes")
        self._quanta = {s: sensor_quanta(s, quanta) for s in SENSOR_FIELDS}
        self._message_index = message_index
        self.path = Path(path)
        self._f = open(self.path, "wb")
        self._chunk_size = chunk_size
        self._zstd = zstandard.ZstdCompressor(level=zstd_level)
        self._schemas: dict[str, tuple[int, bytes]] = {}  # name -> (id, record)
        self._channels: dict[str, tuple[int, bytes]] = {}  # topic -> (id, record)
        self._seq: dict[int, int] = {}
        self._msg_count: dict[int, int] = {}
        self._t_min = self._t_max = None
        self._chunk_indexes: list[bytes] = []
        self._closed = False
        self._reset_chunk()
        self._write(MAGIC + _record(OP_HEADER, _string("") + _string(LIBRARY)))

    # ------------------------------------------------------------------ public API

    def write_block(self, block: SampleBlock, recv_ns: int | None = None) -> None:
        """Append one block as one message.

        ``recv_ns`` (MCAP log_time) defaults to ``block.recv_ns``, or to the block's last sample
        time when that is 0 (offline data without a receive time). Empty blocks carry no sensor
        time and are rejected with ValueError.
        """
        if len(block) == 0:
            raise ValueError(f"{block.topic}: refusing to write an empty block (no sensor time)")
        log_ns = int(recv_ns or block.recv_ns or block.t_last_ns)
        pub_ns = block.t_first_ns
        self._check_times(block.topic, log_ns, pub_ns)
        ch = self._sensor_channel(block.buoy_id, block.sensor)
        values = np.array([block.fields[f] for f in SENSOR_FIELDS[block.sensor]])
        payload = codec.encode_samples(block.t_ns, values, self._quanta[block.sensor])
        self._add_message(ch, log_ns, pub_ns, payload)

    def write_json(self, topic: str, obj: Mapping[str, Any], log_ns: int, publish_ns: int,
                   schema: Mapping[str, Any] | None = None) -> None:
        """Append one JSON message (schema encoding ``jsonschema``, message encoding ``json``).

        The JSON Schema defaults to :data:`STATUS_SCHEMA` / :data:`ALERT_SCHEMA` by topic (see
        :func:`status_topic`, :func:`alert_topic`). Non-finite floats are written as null.
        """
        if not isinstance(obj, Mapping):
            raise ValueError(f"{topic}: JSON message must be an object, got {type(obj).__name__}")
        self._check_times(topic, int(log_ns), int(publish_ns))
        schema = _json_schema_for(topic) if schema is None else schema
        ch = self._channel(topic, str(schema.get("title", "buoymon.v1.Json")), "jsonschema",
                           json.dumps(schema, sort_keys=True).encode(), "json")
        payload = to_json_bytes(obj)
        self._add_message(ch, int(log_ns), int(publish_ns), payload)

    def write_series(self, series: Sequence[Series], *, block_ns: int = 1_000_000_000,
                     recv_delay_ns: int = 0) -> int:
        """Cut each series into blocks on a fixed grid of ``block_ns`` and write them all.

        Blocks start at the first sample at or after each multiple of ``block_ns`` (since the
        epoch); a block's receive time is its last sample time plus ``recv_delay_ns``. Messages
        of all series are written merged in (publish time, series order), as a live recorder
        would have received them. Returns the number of messages written. Vectorised: use it
        for bulk writers (simulator, importer, benchmark).
        """
        if block_ns <= 0 or recv_delay_ns < 0:
            raise ValueError(f"block_ns = {block_ns} must be > 0 and "
                             f"recv_delay_ns = {recv_delay_ns} >= 0")
        bufs, offs, pubs, logs, chans = [], [], [], [], []
        base = 0
        for s in series:
            t = np.ascontiguousarray(s.t_ns, dtype=np.int64)
            vals = np.ascontiguousarray(s.values, dtype=np.float64)
            nf = len(SENSOR_FIELDS.get(s.sensor, ()))
            if t.ndim != 1 or vals.shape != (nf, t.shape[0]):
                raise ValueError(
                    f"{s.sensor}: values must be ({nf}, {t.shape[0]}), got {vals.shape}")
            if t.shape[0] == 0:
                continue
            if t[0] <= 0 or np.any(np.diff(t) < 0):
                raise ValueError(f"{s.sensor}: series times must be > 0 and non-decreasing")
            ch = self._sensor_channel(s.buoy_id, s.sensor)
            cell = t // block_ns
            starts = np.flatnonzero(np.r_[True, cell[1:] != cell[:-1]])
            starts = np.append(starts, t.shape[0]).astype(np.int64)
            log_ns = t[starts[1:] - 1] + recv_delay_ns
            seq0 = self._seq.get(ch, 0)
            buf, rec_off = _encode_records(t, vals, self._quanta[s.sensor], starts, ch, seq0,
                                           log_ns)
            nb = starts.shape[0] - 1
            self._seq[ch] = seq0 + nb
            self._msg_count[ch] = self._msg_count.get(ch, 0) + nb
            bufs.append(buf)
            offs.append(rec_off[:-1] + base)
            base += buf.shape[0]
            pubs.append(t[starts[:-1]])
            logs.append(log_ns)
            chans.append(np.full(nb, ch, np.int64))
        if not bufs:
            return 0
        buf = np.concatenate(bufs)
        rec_off = np.append(np.concatenate(offs), base)
        pub, log, chan = (np.concatenate(x) for x in (pubs, logs, chans))
        order = np.argsort(pub, kind="stable")
        if not np.all(order[1:] > order[:-1]):
            buf, rec_off = _gather(buf, rec_off, order)
            log, chan = log[order], chan[order]
        self._append_records(buf, rec_off, chan, log)
        return int(order.shape[0])

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

    def __enter__(self) -> "LogWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ internals

    def _write(self, data: bytes) -> None:
        self._f.write(data)
        self._pos = self._f.tell()

    @staticmethod
    def _check_times(topic: str, log_ns: int, pub_ns: int) -> None:
        if log_ns <= 0 or pub_ns <= 0:
            raise ValueError(
                f"{topic}: log_time {log_ns} and publish_time {pub_ns} must be > 0 (ns since epoch)"
            )

    def _sensor_channel(self, buoy_id: str, sensor: str) -> int:
        topic = sensor_topic(buoy_id, sensor)
        known = self._channels.get(topic)
        if known is not None:
            return known[0]
        return self._channel(topic, codec.schema_name(sensor), "protobuf",
                             codec.file_descriptor_set(sensor), "protobuf")

    def _channel(self, topic: str, schema: str, schema_enc: str, schema_data: bytes,
                 msg_enc: str) -> int:
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

    def _reset_chunk(self) -> None:
        self._chunk_parts: list[bytes] = []
        self._chunk_len = 0
        # per-message index entries: Python lists (one message at a time) ...
        self._one_ch: list[int] = []
        self._one_log: list[int] = []
        self._one_off: list[int] = []
        # ... and arrays (bulk appends)
        self._bulk: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._chunk_t = [None, None]

    def _note_times(self, lo: int, hi: int) -> None:
        ct = self._chunk_t
        ct[0] = lo if ct[0] is None else min(ct[0], lo)
        ct[1] = hi if ct[1] is None else max(ct[1], hi)

    def _add_message(self, ch: int, log_ns: int, pub_ns: int, payload: bytes) -> None:
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

    def _append_records(self, buf: np.ndarray, rec_off: np.ndarray, chan: np.ndarray,
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
