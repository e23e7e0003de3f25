"""Write buoymon MCAP logs: sensor blocks (protobuf) and monitor outputs (JSON).

The file layer is :class:`monitor.mcap_file.McapFile` (the one MCAP writer, the daemon's
recordings use it too); this adds the log's contents. Sensor payloads are the compact
protobuf blocks of :mod:`monitor.codec`, each field stored to its quantum.

Times: ``log_time`` = receive time, ``publish_time`` = sensor time of the block's first sample;
both must be > 0.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from models._jit import kernel
from monitor.blocks import SENSOR_FIELDS, SampleBlock, sensor_topic, validate_buoy_id
from monitor import codec
from monitor.mcap_file import OP_MESSAGE, McapFile
from monitor.strict_json import to_json_bytes
from monitor.quanta import quanta as sensor_quanta

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


class LogWriter(McapFile):
    """Append-only writer of one buoymon MCAP log.

    Args:
        path: output file (created or truncated).
        chunk_size: target uncompressed chunk size in bytes.
        zstd_level: zstd compression level of the chunks (3: the quantized samples compress
            by a third more than at level 1, at a cost the writer does not notice).
        quanta: quantum per field name (see :func:`monitor.codec.quanta`), overriding
            :data:`monitor.quanta.DEFAULT_QUANTA`; every sample is stored to within half of it.
        message_index: also write MCAP Message Index records after each chunk (see
            :class:`monitor.mcap_file.McapFile`).

    Use as a context manager or call :meth:`close`; a writer that is never closed leaves a
    file without footer, which :mod:`replay.reader` still reads up to the last closed chunk.
    """

    def __init__(self, path: str | os.PathLike, *, chunk_size: int = 1 << 20, zstd_level: int = 3,
                 quanta: Mapping[str, float] | None = None, message_index: bool = False):
        self._quanta = {s: sensor_quanta(s, quanta) for s in SENSOR_FIELDS}
        super().__init__(path, chunk_size=chunk_size, zstd_level=zstd_level,
                         message_index=message_index)

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
        self.add_message(ch, log_ns, pub_ns, payload)

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
        ch = self.channel(topic, str(schema.get("title", "buoymon.v1.Json")), "jsonschema",
                           json.dumps(schema, sort_keys=True).encode(), "json")
        payload = to_json_bytes(obj)
        self.add_message(ch, int(log_ns), int(publish_ns), payload)

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
            nb = starts.shape[0] - 1
            seq0 = self.reserve(ch, nb)
            buf, rec_off = _encode_records(t, vals, self._quanta[s.sensor], starts, ch, seq0,
                                           log_ns)
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
        self.append_records(buf, rec_off, chan, log)
        return int(order.shape[0])

    # ------------------------------------------------------------------ internals

    @staticmethod
    def _check_times(topic: str, log_ns: int, pub_ns: int) -> None:
        if log_ns <= 0 or pub_ns <= 0:
            raise ValueError(
                f"{topic}: log_time {log_ns} and publish_time {pub_ns} must be > 0 (ns since epoch)"
            )

    def _sensor_channel(self, buoy_id: str, sensor: str) -> int:
        topic = sensor_topic(buoy_id, sensor)
        known = self.channel_id(topic)
        if known is not None:
            return known
        return self.channel(topic, codec.schema_name(sensor), "protobuf",
                            codec.file_descriptor_set(sensor), "protobuf")
