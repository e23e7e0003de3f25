"""Protobuf payloads of the log format: one message per block of samples of one sensor.

The schemas are built at run time with ``descriptor_pb2`` (no protoc, no generated code) and
stored in every log as a serialized ``FileDescriptorSet`` (MCAP schema encoding ``protobuf``),
so Foxglove, Rerun or any protobuf library decode the payloads without buoymon. Each sensor of
:data:`monitor.blocks.SENSOR_FIELDS` gets one message type ``buoymon.v1.<Sensor>Block``::

    message TensionBlock {                 // ImuBlock, MotionBlock, GnssBlock, WavesBlock alike
      sfixed64 t0_ns = 1;                  // sensor time of the first sample, ns since epoch
      uint64   period_ns = 2;              // sample i is at t0_ns + i * period_ns (regular)
      repeated sint64 t_offset_ns = 3;     // irregular: sample i is at t0_ns + t_offset_ns[i]
      repeated double tension_N = 4;       // the sensor's fields, in SENSOR_FIELDS order, SI
    }

Exactly one time base is used: ``t_offset_ns`` (one entry per sample) when present, otherwise
``period_ns``; a one-sample block needs neither. Every value field has one entry per sample.

Encoding is hand-written (it is a handful of bytes around ``ndarray.tobytes``) because the
generic protobuf runtime costs more per block than the rest of the log writer together.
Decoding of many messages at once is a numba kernel over the raw bytes (:func:`decode_many`);
it accepts anything a conforming encoder may produce (packed or unpacked repeated fields, any
field order, unknown fields skipped) and flags malformed payloads instead of raising.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Mapping, Sequence

import numba
import numpy as np
from google.protobuf import descriptor_pb2

from monitor.blocks import SENSOR_FIELDS, SampleBlock

PACKAGE = "buoymon.v1"
FIELD_T0 = 1
FIELD_PERIOD = 2
FIELD_OFFSETS = 3
FIRST_VALUE_FIELD = 4

# decode status codes (one per message)
OK = 0
BAD_WIRE = 1  # truncated varint/field or an impossible wire type
BAD_COUNTS = 2  # value fields (or time offsets) disagree on the number of samples
NO_TIME_BASE = 3  # several samples but neither period_ns > 0 nor t_offset_ns
NO_T0 = 4  # t0_ns missing
STATUS_TEXT = {
    BAD_WIRE: "malformed protobuf",
    BAD_COUNTS: "fields disagree on the number of samples",
    NO_TIME_BASE: "several samples but no period_ns or t_offset_ns",
    NO_T0: "t0_ns missing",
}


def message_name(sensor: str) -> str:
    """Unqualified message name of a sensor's block, e.g. ``ImuBlock``."""
    _check_sensor(sensor)
    return ("Imu" if sensor == "imu" else sensor.capitalize()) + "Block"


def schema_name(sensor: str) -> str:
    """Fully qualified protobuf name stored as the MCAP schema name."""
    return f"{PACKAGE}.{message_name(sensor)}"


def _check_sensor(sensor: str) -> None:
    if sensor not in SENSOR_FIELDS:
        raise ValueError(f"unknown sensor {sensor!r}; expected one of {sorted(SENSOR_FIELDS)}")


@lru_cache(maxsize=None)
def file_descriptor_set(sensor: str) -> bytes:
    """Serialized ``FileDescriptorSet`` describing the sensor's block message."""
    _check_sensor(sensor)
    fdp = descriptor_pb2.FieldDescriptorProto
    proto = descriptor_pb2.FileDescriptorProto(
        name=f"buoymon/v1/{sensor}.proto", package=PACKAGE, syntax="proto3"
    )
    msg = proto.message_type.add(name=message_name(sensor))
    msg.field.add(name="t0_ns", number=FIELD_T0, type=fdp.TYPE_SFIXED64, label=fdp.LABEL_OPTIONAL)
    msg.field.add(name="period_ns", number=FIELD_PERIOD, type=fdp.TYPE_UINT64,
                  label=fdp.LABEL_OPTIONAL)
    msg.field.add(name="t_offset_ns", number=FIELD_OFFSETS, type=fdp.TYPE_SINT64,
                  label=fdp.LABEL_REPEATED)
    for i, name in enumerate(SENSOR_FIELDS[sensor]):
        msg.field.add(name=name, number=FIRST_VALUE_FIELD + i, type=fdp.TYPE_DOUBLE,
                      label=fdp.LABEL_REPEATED)
    return descriptor_pb2.FileDescriptorSet(file=[proto]).SerializeToString(deterministic=True)


def proto_text() -> str:
    """The schemas as ``.proto`` source, rendered from the descriptors (``monitor/buoymon.proto``
    is this text, kept for readers and for protoc users; a test checks they agree)."""
    names = {descriptor_pb2.FieldDescriptorProto.TYPE_SFIXED64: "sfixed64",
             descriptor_pb2.FieldDescriptorProto.TYPE_UINT64: "uint64",
             descriptor_pb2.FieldDescriptorProto.TYPE_SINT64: "sint64",
             descriptor_pb2.FieldDescriptorProto.TYPE_DOUBLE: "double"}
    lines = ["// buoymon log format: one message per block of samples of one sensor.",
             "// Generated from monitor/codec.py (proto_text); see docs/LOG_FORMAT.md.",
             'syntax = "proto3";', "", f"package {PACKAGE};"]
    for sensor, fields in SENSOR_FIELDS.items():
        fds = descriptor_pb2.FileDescriptorSet.FromString(file_descriptor_set(sensor))
        msg = fds.file[0].message_type[0]
        lines += ["", f"message {msg.name} {{"]
        for fld in msg.field:
            rep = "repeated " if fld.label == fld.LABEL_REPEATED else ""
            unit = fields.get(fld.name) or "ns"
            lines.append(f"  {rep}{names[fld.type]} {fld.name} = {fld.number};  // {unit}")
        lines.append("}")
    return "\n".join(lines) + "\n"


FieldNumbers = tuple[int, int, int, tuple[int, ...]]  # t0, period, offsets, value fields


@lru_cache(maxsize=None)
def field_numbers_from_schema(schema_data: bytes, name: str, sensor: str) -> FieldNumbers:
    """Field numbers ``(t0, period, offsets, values...)`` of message ``name`` in a stored schema.

    Read from the schema in the file (not assumed) so a log written by another tool with a
    different numbering still decodes. Raises ValueError naming what is missing.
    """
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema_data)
    for f in fds.file:
        for m in f.message_type:
            full = f"{f.package}.{m.name}" if f.package else m.name
            if full != name:
                continue
            numbers = {fld.name: fld.number for fld in m.field}
            wanted = ["t0_ns", *SENSOR_FIELDS[sensor]]
            missing = [w for w in wanted if w not in numbers]
            if missing:
                raise ValueError(f"schema {name}: missing fields {missing}")
            values = tuple(numbers[w] for w in SENSOR_FIELDS[sensor])
            return (numbers["t0_ns"], numbers.get("period_ns", -1),
                    numbers.get("t_offset_ns", -1), values)
    raise ValueError(f"schema data does not define message {name!r}")


DEFAULT_FIELD_NUMBERS = {
    s: (FIELD_T0, FIELD_PERIOD, FIELD_OFFSETS,
        tuple(range(FIRST_VALUE_FIELD, FIRST_VALUE_FIELD + len(f))))
    for s, f in SENSOR_FIELDS.items()
}


# ----------------------------------------------------------------------------------- encode


@numba.njit(cache=True)
def _regular_period(t: np.ndarray) -> int:
    """Constant positive step of ``t``, 0 for fewer than two samples, -1 if irregular."""
    n = t.shape[0]
    if n < 2:
        return 0
    p = t[1] - t[0]
    if p <= 0:
        return -1
    for i in range(2, n):
        if t[i] - t[i - 1] != p:
            return -1
    return p


@numba.njit(cache=True)
def _zigzag_varints(t: np.ndarray) -> np.ndarray:
    """Packed sint64 encoding of ``t - t[0]``."""
    out = np.empty(t.shape[0] * 10, np.uint8)
    k = 0
    t0 = t[0]
    for i in range(t.shape[0]):
        d = t[i] - t0
        z = np.uint64((d << 1) ^ (d >> 63))
        while z >= 0x80:
            out[k] = np.uint8((z & np.uint64(0x7F)) | np.uint64(0x80))
            z >>= np.uint64(7)
            k += 1
        out[k] = np.uint8(z)
        k += 1
    return out[:k]


@numba.njit(cache=True, inline="always")
def _put_varint(out, k, z):
    """Write unsigned ``z`` as a varint at ``out[k]``; return the position after it."""
    z = np.uint64(z)
    while z >= 0x80:
        out[k] = np.uint8((z & np.uint64(0x7F)) | np.uint64(0x80))
        z >>= np.uint64(7)
        k += 1
    out[k] = np.uint8(z)
    return k + 1


@numba.njit(cache=True)
def payload_bound(n: int, nf: int) -> int:
    """Upper bound of the payload size of an ``n``-sample block with ``nf`` value fields."""
    return 9 + 11 + 11 + 10 * n + nf * (11 + 8 * n)


@numba.njit(cache=True)
def put_payload(out, k, t, vals, a, b):
    """Encode samples ``a:b`` of ``t``/``vals`` (n_fields, N) at ``out[k]``; return end position.

    The numba twin of :func:`encode_samples` for bulk writers (same bytes).
    """
    n = b - a
    out[k] = 0x09
    k += 1
    t0 = t[a]
    u = np.uint64(t0)
    for i in range(8):
        out[k + i] = np.uint8((u >> np.uint64(8 * i)) & np.uint64(0xFF))
    k += 8
    period = _regular_period(t[a:b])
    if period > 0:
        out[k] = 0x10
        k = _put_varint(out, k + 1, period)
    elif period < 0:
        # the length prefix needs the packed size, so encode the offsets first
        body = _zigzag_varints(t[a:b])
        out[k] = 0x1A
        k = _put_varint(out, k + 1, body.shape[0])
        out[k:k + body.shape[0]] = body
        k += body.shape[0]
    for f in range(vals.shape[0]):
        out[k] = np.uint8(((FIRST_VALUE_FIELD + f) << 3) | 2)
        k = _put_varint(out, k + 1, 8 * n)
        raw = vals[f, a:b].copy().view(np.uint8)
        out[k:k + 8 * n] = raw
        k += 8 * n
    return k


@lru_cache(maxsize=4096)
def _varint(x: int) -> bytes:
    if x < 0x80:
        return bytes((x,))
    out = bytearray()
    while x >= 0x80:
        out.append((x & 0x7F) | 0x80)
        x >>= 7
    out.append(x)
    return bytes(out)


_VALUE_TAGS = tuple(bytes(((FIRST_VALUE_FIELD + i) << 3 | 2,)) for i in range(8))


def encode_samples(t_ns: np.ndarray, values: Sequence[np.ndarray]) -> bytes:
    """Payload bytes of one block: ``t_ns`` int64 (n,), ``values`` float64 arrays in field order.

    The caller guarantees the shapes (``SampleBlock`` does); ``n`` must be at least 1.
    """
    n = t_ns.shape[0]
    parts = [b"\x09", t_ns[:1].astype("<i8", copy=False).tobytes()]
    period = _regular_period(t_ns)
    if period > 0:
        parts += (b"\x10", _varint(period))
    elif period < 0:
        packed = _zigzag_varints(t_ns).tobytes()
        parts += (b"\x1a", _varint(len(packed)), packed)
    size = _varint(8 * n)
    for tag, v in zip(_VALUE_TAGS, values):
        parts += (tag, size, v.astype("<f8", copy=False).tobytes())
    return b"".join(parts)


def encode_block(block: SampleBlock) -> bytes:
    """Payload bytes of a :class:`SampleBlock` (ValueError if it is empty)."""
    if len(block) == 0:
        raise ValueError(f"{block.topic}: an empty block has no sensor time and cannot be encoded")
    return encode_samples(block.t_ns, [block.fields[f] for f in SENSOR_FIELDS[block.sensor]])


# ----------------------------------------------------------------------------------- decode


@numba.njit(cache=True, inline="always")
def _read_varint(buf, p, end):
    """(value as int64 bit pattern, next position); next position -1 past ``end`` or overlong.

    Plain int64 arithmetic on purpose: mixing uint64 and int64 makes numba go through floats.
    """
    result = 0
    shift = 0
    while p < end:
        b = np.int64(buf[p])
        p += 1
        result |= (b & 0x7F) << shift
        if b < 0x80:
            return result, p
        shift += 7
        if shift >= 70:
            return result, -1
    return result, -1


@numba.njit(cache=True, inline="always")
def _read_i64(buf, p):
    v = 0
    for i in range(8):
        v |= np.int64(buf[p + i]) << (8 * i)
    return v


@numba.njit(cache=True, inline="always")
def _value_slot(fn_vals, fnum):
    """Index of field number ``fnum`` among the value fields, or -1."""
    j = -1
    for q in range(fn_vals.shape[0]):
        if fn_vals[q] == fnum:
            j = q
    return j


@numba.njit(cache=True)
def _skip(buf, p, end, wt):
    """Position after a field of wire type ``wt`` starting at ``p``; -1 if malformed."""
    if wt == 0:
        _, p = _read_varint(buf, p, end)
        return p
    if wt == 1:
        return p + 8 if p + 8 <= end else -1
    if wt == 5:
        return p + 4 if p + 4 <= end else -1
    if wt == 2:
        ln, p = _read_varint(buf, p, end)
        if p < 0 or p + ln > end:
            return -1
        return p + ln
    return -1


@numba.njit(cache=True, nogil=True)  # runs in the read-ahead thread
def _decode_kernel(buf, offs, lens, fn_t0, fn_period, fn_off, fn_vals):
    m = offs.shape[0]
    nf = fn_vals.shape[0]
    status = np.zeros(m, np.int8)
    nsamp = np.zeros(m, np.int64)
    t0s = np.zeros(m, np.int64)
    periods = np.zeros(m, np.int64)
    cnt = np.zeros(nf, np.int64)
    # pass 1: validate and count samples per message
    for k in range(m):
        p = offs[k]
        end = p + lens[k]
        cnt[:] = 0
        noff = 0
        have_t0 = False
        st = 0
        while p < end:
            tag, p = _read_varint(buf, p, end)
            if p < 0:
                st = 1
                break
            fnum = tag >> 3
            wt = tag & 7
            j = _value_slot(fn_vals, fnum)
            if fnum == fn_t0 and wt == 1:
                if p + 8 > end:
                    st = 1
                    break
                t0s[k] = _read_i64(buf, p)
                have_t0 = True
                p += 8
            elif fnum == fn_period and wt == 0:
                v, p = _read_varint(buf, p, end)
                periods[k] = v
            elif fnum == fn_off and wt == 2:
                ln, p = _read_varint(buf, p, end)
                if p < 0 or p + ln > end:
                    st = 1
                    break
                e2 = p + ln
                while p < e2:
                    _, p = _read_varint(buf, p, e2)
                    if p < 0:
                        break
                    noff += 1
                if p < 0:
                    st = 1
                    break
            elif fnum == fn_off and wt == 0:
                _, p = _read_varint(buf, p, end)
                noff += 1
            elif j >= 0 and wt == 2:
                ln, p = _read_varint(buf, p, end)
                if p < 0 or p + ln > end or ln % 8 != 0:
                    st = 1
                    break
                cnt[j] += ln // 8
                p += ln
            elif j >= 0 and wt == 1:
                if p + 8 > end:
                    st = 1
                    break
                cnt[j] += 1
                p += 8
            else:
                p = _skip(buf, p, end, wt)
            if p < 0:
                st = 1
                break
        if st == 0:
            n = cnt[0]
            for q in range(1, nf):
                if cnt[q] != n:
                    st = 2
            if noff != 0 and noff != n:
                st = 2
            if st == 0 and not have_t0:
                st = 4
            if st == 0 and n > 1 and noff == 0 and periods[k] <= 0:
                st = 3
            if st == 0:
                nsamp[k] = n
                if noff != 0:
                    periods[k] = -1  # marks "offsets present" for pass 2
        status[k] = st
    total = 0
    for k in range(m):
        total += nsamp[k]
    t = np.empty(total, np.int64)
    vb = np.empty((nf, total * 8), np.uint8)
    fill = np.zeros(nf, np.int64)
    # pass 2: fill times and value bytes (messages already validated)
    pos = 0
    for k in range(m):
        n = nsamp[k]
        if status[k] != 0 or n == 0:
            continue
        p = offs[k]
        end = p + lens[k]
        fill[:] = 0
        noff = 0
        while p < end:
            tag, p = _read_varint(buf, p, end)
            fnum = tag >> 3
            wt = tag & 7
            j = _value_slot(fn_vals, fnum)
            if fnum == fn_off and (wt == 2 or wt == 0):
                e2 = p + 1  # one varint for the unpacked form
                if wt == 2:
                    ln, p = _read_varint(buf, p, end)
                    e2 = p + ln
                while p < e2:
                    z, p = _read_varint(buf, p, end)
                    t[pos + noff] = ((z >> 1) & 0x7FFFFFFFFFFFFFFF) ^ -(z & 1)
                    noff += 1
            elif j >= 0 and (wt == 2 or wt == 1):
                ln = 8
                if wt == 2:
                    ln, p = _read_varint(buf, p, end)
                base = (pos + fill[j]) * 8
                vb[j, base:base + ln] = buf[p:p + ln]
                fill[j] += ln // 8
                p += ln
            else:
                p = _skip(buf, p, end, wt)
        t0 = t0s[k]
        if periods[k] < 0:
            for i in range(n):
                t[pos + i] += t0
        else:
            per = periods[k]
            for i in range(n):
                t[pos + i] = t0 + i * per
        pos += n
    return status, nsamp, t0s, t, vb


def decode_many(
    buf: np.ndarray, offs: np.ndarray, lens: np.ndarray,
    numbers: FieldNumbers,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Decode many block payloads lying in one byte buffer.

    Args:
        buf: uint8 buffer holding the payloads.
        offs, lens: int64 start and length of each payload in ``buf``.
        numbers: field numbers ``(t0, period, offsets, values)`` (see
            :func:`field_numbers_from_schema`).

    Returns:
        ``(status, n_samples, t_ns, values)``: per-message status (:data:`OK` or an error code
        of :data:`STATUS_TEXT`) and sample count (0 for bad messages), then the samples of all
        good messages concatenated in message order: ``t_ns`` int64 (N,) and ``values``
        float64 (n_fields, N).
    """
    fn_t0, fn_period, fn_off, fn_vals = numbers
    status, nsamp, _, t, vb = _decode_kernel(
        buf, offs, lens, fn_t0, fn_period, fn_off, np.asarray(fn_vals, np.int64)
    )
    return status, nsamp, t, vb.view("<f8")


def decode_block(buoy_id: str, sensor: str, payload: bytes, recv_ns: int = 0,
                 numbers: FieldNumbers | None = None) -> SampleBlock:
    """Decode one payload into a :class:`SampleBlock` (ValueError if malformed)."""
    _check_sensor(sensor)
    buf = np.frombuffer(payload, np.uint8)
    status, _, t, vals = decode_many(
        buf, np.zeros(1, np.int64), np.array([buf.shape[0]], np.int64),
        numbers or DEFAULT_FIELD_NUMBERS[sensor],
    )
    if status[0] != OK:
        raise ValueError(f"{sensor} payload of {len(payload)} bytes: {STATUS_TEXT[int(status[0])]}")
    fields: Mapping[str, np.ndarray] = {
        name: vals[i] for i, name in enumerate(SENSOR_FIELDS[sensor])
    }
    return SampleBlock(buoy_id, sensor, t, fields, recv_ns)
