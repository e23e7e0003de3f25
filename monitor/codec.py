"""Protobuf payloads of the log format: one message per block of samples of one sensor.

The schemas are built at run time with ``descriptor_pb2`` (no protoc, no generated code) and
stored in every log as a serialized ``FileDescriptorSet`` (MCAP schema encoding ``protobuf``),
so Foxglove, Rerun or any protobuf library decode the payloads without buoymon. Each sensor of
:data:`monitor.blocks.SENSOR_FIELDS` gets one message type ``buoymon.v2.<Sensor>Block``::

    message Quantized {                    // one field's samples, exact to half a quantum
      double quantum = 1;                  // the sensor's resolution, field units
      repeated sint64 delta = 2;           // value[i] = quantum * (delta[0] + ... + delta[i])
      repeated uint32 raw_index = 3;       // samples stored as they are (NaN, inf, huge) ...
      repeated double raw_value = 4;       // ... at these indices, with these values
    }
    message TensionBlock {                 // ImuBlock, MotionBlock, GnssBlock, WavesBlock alike
      sfixed64 t0_ns = 1;                  // sensor time of the first sample, ns since epoch
      uint64   period_ns = 2;              // sample i is at t0_ns + i * period_ns (regular)
      repeated sint64 t_offset_ns = 3;     // irregular: sample i is at t0_ns + t_offset_ns[i]
      Quantized tension_N = 4;             // the sensor's fields, in SENSOR_FIELDS order, SI
    }

A value is stored as the integer ``k = rint(value / quantum)`` when ``float(k) * quantum`` lies
within half a quantum of it (checked when encoding, so the bound holds exactly as the decoder
computes it); the packed zigzag varints of the differences of ``k`` are a few bytes that zstd
shrinks further, where a float64 sample cost 8 incompressible bytes. Anything else (NaN, inf,
a value beyond 2**52 quanta) is kept bit for bit in ``raw_value`` (its ``delta`` is 0).

Exactly one time base is used: ``t_offset_ns`` (one entry per sample) when present, otherwise
``period_ns``; a one-sample block needs neither. Every value field has one entry per sample.

Logs of the first format (``buoymon.v1``: ``repeated double`` value fields) still decode: the
format of a channel is read from the schema stored with it (:func:`field_numbers_from_schema`).
Encoding is a numba kernel (:func:`put_payload`) shared by the replay tools and the bulk
writer; processes that only publish (the bridge, :mod:`monitor.sensors`) encode the same bytes
with numpy alone (:mod:`monitor.codec_np`), without loading numba.
Decoding of many messages at once is a numba kernel over the raw bytes (:func:`decode_many`);
it accepts anything a conforming encoder may produce (packed or unpacked repeated fields, any
field order, unknown fields skipped) and flags malformed payloads instead of raising.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Mapping

import numpy as np
from google.protobuf import descriptor_pb2

from models._jit import kernel
from monitor.blocks import SENSOR_FIELDS, SampleBlock
from monitor.codec_np import (EXACT as _EXACT, FIELD_OFFSETS, FIELD_PERIOD, FIELD_T0,
                              FIRST_VALUE_FIELD, Q_DELTA, Q_QUANTUM, Q_RAW_INDEX, Q_RAW_VALUE)
from monitor.codec_regular import decode_regular
from monitor.quanta import quanta
from monitor.varint import read_varint, unzigzag

PACKAGE = "buoymon.v2"
QUANTIZED = "Quantized"
QUANTIZED_FILE = "buoymon/v2/quantized.proto"
QUANTIZED_FIELDS = ("quantum", "delta", "raw_index", "raw_value")

# decode status codes (one per message)
OK = 0
BAD_WIRE = 1  # truncated varint/field or an impossible wire type
BAD_COUNTS = 2  # value fields (or time offsets, raw samples) disagree on the number of samples
NO_TIME_BASE = 3  # several samples but neither period_ns > 0 nor t_offset_ns
NO_T0 = 4  # t0_ns missing
BAD_QUANTUM = 5  # a quantized field without a finite quantum > 0
REPEATED_FIELD = 6  # a quantized field given twice in one message
STATUS_TEXT = {
    BAD_WIRE: "malformed protobuf",
    BAD_COUNTS: "fields disagree on the number of samples",
    NO_TIME_BASE: "several samples but no period_ns or t_offset_ns",
    NO_T0: "t0_ns missing",
    BAD_QUANTUM: "quantum missing, not finite or not > 0",
    REPEATED_FIELD: "a quantized value field appears twice",
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


def _quantized_file() -> descriptor_pb2.FileDescriptorProto:
    fdp = descriptor_pb2.FieldDescriptorProto
    proto = descriptor_pb2.FileDescriptorProto(name=QUANTIZED_FILE, package=PACKAGE,
                                               syntax="proto3")
    msg = proto.message_type.add(name=QUANTIZED)
    for name, number, typ, label in (
            ("quantum", Q_QUANTUM, fdp.TYPE_DOUBLE, fdp.LABEL_OPTIONAL),
            ("delta", Q_DELTA, fdp.TYPE_SINT64, fdp.LABEL_REPEATED),
            ("raw_index", Q_RAW_INDEX, fdp.TYPE_UINT32, fdp.LABEL_REPEATED),
            ("raw_value", Q_RAW_VALUE, fdp.TYPE_DOUBLE, fdp.LABEL_REPEATED)):
        msg.field.add(name=name, number=number, type=typ, label=label)
    return proto


@lru_cache(maxsize=None)
def file_descriptor_set(sensor: str) -> bytes:
    """Serialized ``FileDescriptorSet`` describing the sensor's block message (two files:
    ``Quantized``, then the block that imports it)."""
    _check_sensor(sensor)
    fdp = descriptor_pb2.FieldDescriptorProto
    proto = descriptor_pb2.FileDescriptorProto(
        name=f"buoymon/v2/{sensor}.proto", package=PACKAGE, syntax="proto3",
        dependency=[QUANTIZED_FILE])
    msg = proto.message_type.add(name=message_name(sensor))
    msg.field.add(name="t0_ns", number=FIELD_T0, type=fdp.TYPE_SFIXED64, label=fdp.LABEL_OPTIONAL)
    msg.field.add(name="period_ns", number=FIELD_PERIOD, type=fdp.TYPE_UINT64,
                  label=fdp.LABEL_OPTIONAL)
    msg.field.add(name="t_offset_ns", number=FIELD_OFFSETS, type=fdp.TYPE_SINT64,
                  label=fdp.LABEL_REPEATED)
    for i, name in enumerate(SENSOR_FIELDS[sensor]):
        msg.field.add(name=name, number=FIRST_VALUE_FIELD + i, type=fdp.TYPE_MESSAGE,
                      type_name=f".{PACKAGE}.{QUANTIZED}", label=fdp.LABEL_OPTIONAL)
    return descriptor_pb2.FileDescriptorSet(
        file=[_quantized_file(), proto]).SerializeToString(deterministic=True)


def proto_text() -> str:
    """The schemas as ``.proto`` source, rendered from the descriptors (``monitor/buoymon.proto``
    is this text, kept for readers and for protoc users; a test checks they agree)."""
    fdp = descriptor_pb2.FieldDescriptorProto
    names = {fdp.TYPE_SFIXED64: "sfixed64", fdp.TYPE_UINT64: "uint64", fdp.TYPE_SINT64: "sint64",
             fdp.TYPE_DOUBLE: "double", fdp.TYPE_UINT32: "uint32", fdp.TYPE_MESSAGE: QUANTIZED}
    units = {"quantum": "field units", "delta": "quanta", "raw_index": "sample index",
             "raw_value": "field units"}
    lines = ["// buoymon log format: one message per block of samples of one sensor.",
             "// Generated from monitor/codec.py (proto_text); see docs/LOG_FORMAT.md.",
             'syntax = "proto3";', "", f"package {PACKAGE};"]
    messages = [(_quantized_file().message_type[0], units)]
    for sensor, fields in SENSOR_FIELDS.items():
        fds = descriptor_pb2.FileDescriptorSet.FromString(file_descriptor_set(sensor))
        messages.append((fds.file[-1].message_type[0], fields))
    for msg, unit_of in messages:
        lines += ["", f"message {msg.name} {{"]
        for fld in msg.field:
            rep = "repeated " if fld.label == fld.LABEL_REPEATED else ""
            unit = unit_of.get(fld.name) or "ns"
            lines.append(f"  {rep}{names[fld.type]} {fld.name} = {fld.number};  // {unit}")
        lines.append("}")
    return "\n".join(lines) + "\n"


# t0, period, offsets, value fields, Quantized's (quantum, delta, raw_index, raw_value) or
# (-1, -1, -1, -1) for value fields of packed doubles (the v1 format)
FieldNumbers = tuple[int, int, int, tuple[int, ...], tuple[int, int, int, int]]
DOUBLES = (-1, -1, -1, -1)


@lru_cache(maxsize=None)
def field_numbers_from_schema(schema_data: bytes, name: str, sensor: str) -> FieldNumbers:
    """Field numbers of message ``name`` in a stored schema, and its value encoding.

    Read from the schema in the file (not assumed) so a log written by another tool with a
    different numbering, or by an older buoymon (``repeated double`` values), still decodes.
    Raises ValueError naming what is missing or not understood.
    """
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema_data)
    messages = {(f"{f.package}.{m.name}" if f.package else m.name): m
                for f in fds.file for m in f.message_type}
    m = messages.get(name)
    if m is None:
        raise ValueError(f"schema data does not define message {name!r}")
    fields = {fld.name: fld for fld in m.field}
    wanted = ["t0_ns", *SENSOR_FIELDS[sensor]]
    missing = [w for w in wanted if w not in fields]
    if missing:
        raise ValueError(f"schema {name}: missing fields {missing}")
    fdp = descriptor_pb2.FieldDescriptorProto
    value_fields = [fields[w] for w in SENSOR_FIELDS[sensor]]
    types = {(f.type, f.type_name) for f in value_fields}
    if types == {(fdp.TYPE_DOUBLE, "")}:
        sub = DOUBLES
    elif len(types) == 1 and value_fields[0].type == fdp.TYPE_MESSAGE:
        inner = messages.get(value_fields[0].type_name.lstrip("."))
        numbers = {fld.name: fld.number for fld in inner.field} if inner is not None else {}
        if "quantum" not in numbers or "delta" not in numbers:
            raise ValueError(f"schema {name}: value type {value_fields[0].type_name} "
                             "lacks quantum/delta fields")
        sub = tuple(numbers.get(k, -1) for k in QUANTIZED_FIELDS)
    else:
        raise ValueError(f"schema {name}: value fields must all be double or all "
                         f"{QUANTIZED}")
    return (fields["t0_ns"].number, fields["period_ns"].number if "period_ns" in fields else -1,
            fields["t_offset_ns"].number if "t_offset_ns" in fields else -1,
            tuple(f.number for f in value_fields), sub)


DEFAULT_FIELD_NUMBERS = {
    s: (FIELD_T0, FIELD_PERIOD, FIELD_OFFSETS,
        tuple(range(FIRST_VALUE_FIELD, FIRST_VALUE_FIELD + len(f))),
        (Q_QUANTUM, Q_DELTA, Q_RAW_INDEX, Q_RAW_VALUE))
    for s, f in SENSOR_FIELDS.items()
}


# ----------------------------------------------------------------------------------- encode


@kernel()
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


@kernel(inline="always")
def _zigzag(d):
    return np.uint64((d << 1) ^ (d >> 63))


@kernel(inline="always")
def _varint_size(z):
    z = np.uint64(z)
    n = 1
    while z >= 0x80:
        z >>= np.uint64(7)
        n += 1
    return n


@kernel(inline="always")
def _put_varint(out, k, z):
    """Write unsigned ``z`` as a varint at ``out[k]``; return the position after it."""
    z = np.uint64(z)
    while z >= 0x80:
        out[k] = np.uint8((z & np.uint64(0x7F)) | np.uint64(0x80))
        z >>= np.uint64(7)
        k += 1
    out[k] = np.uint8(z)
    return k + 1


@kernel(inline="always")
def _quantize(v, q):
    """``(k, True)`` when ``float(k) * q`` is within ``q / 2`` of ``v`` (the decoder's exact
    arithmetic), ``(0, False)`` for a sample to keep raw (NaN, inf, too many quanta)."""
    x = v / q
    if not abs(x) < _EXACT:  # NaN fails too
        return 0, False
    k = np.rint(x)
    # at a tie, k * q may round to just over q / 2 away while a neighbour is just within
    for c in (k, k - 1.0, k + 1.0):
        if abs(c * q - v) <= 0.5 * q:
            return np.int64(c), True
    return 0, False


@kernel()
def payload_bound(n: int, nf: int) -> int:
    """Upper bound of the payload size of an ``n``-sample block with ``nf`` value fields."""
    return 9 + 11 + 11 + 10 * n + nf * (60 + 29 * n)


@kernel()
def _put_quantized(out, k, v, q, qb):
    """Encode the samples ``v`` of one field as a ``Quantized`` message body at ``out[k]``
    (``qb``: the 8 bytes of ``q``); return the end position. Sizes are counted first so the
    length prefixes can be written in place."""
    n = v.shape[0]
    dsize = 0
    isize = 0
    nraw = 0
    prev = 0
    for i in range(n):
        kk, ok = _quantize(v[i], q)
        if ok:
            dsize += _varint_size(_zigzag(kk - prev))
            prev = kk
        else:
            dsize += 1
            isize += _varint_size(i)
            nraw += 1
    size = 9 + 1 + _varint_size(dsize) + dsize
    if nraw:
        size += 1 + _varint_size(isize) + isize + 1 + _varint_size(8 * nraw) + 8 * nraw
    k = _put_varint(out, k, size)
    out[k] = (Q_QUANTUM << 3) | 1
    out[k + 1:k + 9] = qb
    out[k + 9] = (Q_DELTA << 3) | 2
    k = _put_varint(out, k + 10, dsize)
    prev = 0
    for i in range(n):
        kk, ok = _quantize(v[i], q)
        if ok:
            k = _put_varint(out, k, _zigzag(kk - prev))
            prev = kk
        else:
            out[k] = 0
            k += 1
    if nraw:
        out[k] = (Q_RAW_INDEX << 3) | 2
        k = _put_varint(out, k + 1, isize)
        for i in range(n):
            if not _quantize(v[i], q)[1]:
                k = _put_varint(out, k, i)
        out[k] = (Q_RAW_VALUE << 3) | 2
        k = _put_varint(out, k + 1, 8 * nraw)
        for i in range(n):
            if not _quantize(v[i], q)[1]:
                out[k:k + 8] = v[i:i + 1].copy().view(np.uint8)
                k += 8
    return k


@kernel()
def put_payload(out, k, t, vals, quanta, a, b):
    """Encode samples ``a:b`` of ``t``/``vals`` (n_fields, N) at ``out[k]`` with the field
    quanta ``quanta`` (n_fields,); return the end position. ``out`` must have
    :func:`payload_bound` bytes free."""
    out[k] = (FIELD_T0 << 3) | 1
    k += 1
    u = np.uint64(t[a])
    for i in range(8):
        out[k + i] = np.uint8((u >> np.uint64(8 * i)) & np.uint64(0xFF))
    k += 8
    period = _regular_period(t[a:b])
    if period > 0:
        out[k] = FIELD_PERIOD << 3
        k = _put_varint(out, k + 1, period)
    elif period < 0:
        size = 0
        for i in range(a, b):
            size += _varint_size(_zigzag(t[i] - t[a]))
        out[k] = (FIELD_OFFSETS << 3) | 2
        k = _put_varint(out, k + 1, size)
        for i in range(a, b):
            k = _put_varint(out, k, _zigzag(t[i] - t[a]))
    qb = quanta.view(np.uint8)
    for f in range(vals.shape[0]):
        out[k] = np.uint8(((FIRST_VALUE_FIELD + f) << 3) | 2)
        k = _put_quantized(out, k + 1, vals[f, a:b], quanta[f], qb[8 * f:8 * f + 8])
    return k


def encode_samples(t_ns: np.ndarray, values: np.ndarray, quanta: np.ndarray) -> bytes:
    """Payload bytes of one block: ``t_ns`` int64 (n,), ``values`` float64 (n_fields, n) in
    field order, ``quanta`` float64 (n_fields,) (see :func:`quanta`); ``n`` at least 1."""
    t = np.ascontiguousarray(t_ns, np.int64)
    vals = np.ascontiguousarray(values, np.float64)
    out = np.empty(payload_bound(t.shape[0], vals.shape[0]), np.uint8)
    end = put_payload(out, 0, t, vals, np.ascontiguousarray(quanta, np.float64), 0, t.shape[0])
    return out[:end].tobytes()


def encode_block(block: SampleBlock, overrides: Mapping[str, float] | None = None) -> bytes:
    """Payload bytes of a :class:`SampleBlock` (ValueError if it is empty), with the default
    quanta or ``overrides`` by field name."""
    if len(block) == 0:
        raise ValueError(f"{block.topic}: an empty block has no sensor time and cannot be encoded")
    names = SENSOR_FIELDS[block.sensor]
    return encode_samples(block.t_ns, np.array([block.fields[f] for f in names]),
                          quanta(block.sensor, overrides))


# ----------------------------------------------------------------------------------- decode


@kernel(inline="always")
def _read_i64(buf, p):
    v = 0
    for i in range(8):
        v |= np.int64(buf[p + i]) << (8 * i)
    return v


@kernel(inline="always")
def _value_slot(fn_vals, fnum):
    """Index of field number ``fnum`` among the value fields, or -1."""
    j = -1
    for q in range(fn_vals.shape[0]):
        if fn_vals[q] == fnum:
            j = q
    return j


@kernel()
def _skip(buf, p, end, wt):
    """Position after a field of wire type ``wt`` starting at ``p``; -1 if malformed."""
    if wt == 0:
        _, p = read_varint(buf, p, end)
        return p
    if wt == 1:
        return p + 8 if p + 8 <= end else -1
    if wt == 5:
        return p + 4 if p + 4 <= end else -1
    if wt == 2:
        ln, p = read_varint(buf, p, end)
        if p < 0 or p + ln > end:
            return -1
        return p + ln
    return -1


@kernel(inline="always")
def _varint_run(buf, p, end, wt):
    """Bounds ``(a, b)`` of the varints of a repeated varint field starting at ``p`` (after
    its tag): packed (``wt`` 2) or one unpacked value (``wt`` 0); ``b`` -1 if malformed."""
    if wt == 2:
        ln, p = read_varint(buf, p, end)
        if p < 0 or p + ln > end:
            return p, -1
        return p, p + ln
    _, q = read_varint(buf, p, end)
    return p, q


@kernel(inline="always")
def _count_varints(buf, a, b):
    """Number of varints in ``buf[a:b]``, -1 if one is cut or longer than 10 bytes (so the
    decoding loops may trust every run they are given)."""
    n = 0
    run = 0
    for i in range(a, b):
        if buf[i] < 0x80:
            n += 1
            run = 0
        else:
            run += 1
            if run >= 10:
                return -1
    if run:
        return -1
    return n


@kernel()
def _read_f64(buf, p, scratch):
    """The little-endian double at ``buf[p]``, through ``scratch`` (float64 (1,)): no
    allocation per value in the decoding loops."""
    scratch.view(np.uint8)[:] = buf[p:p + 8]
    return scratch[0]


@kernel()
def _scan_quantized(buf, p, end, sub, scratch):
    """Validate one ``Quantized`` body ``buf[p:end]``; return ``(samples, status)``."""
    nd = 0
    ni = 0
    nr = 0
    top = -1
    q = np.nan
    while p < end:
        tag, p = read_varint(buf, p, end)
        if p < 0:
            return 0, BAD_WIRE
        fnum = tag >> 3
        wt = tag & 7
        if fnum == sub[0] and wt == 1 and p + 8 <= end:
            q = _read_f64(buf, p, scratch)
            p += 8
        elif (fnum == sub[1] or fnum == sub[2]) and (wt == 0 or wt == 2):
            a, p = _varint_run(buf, p, end, wt)
            if p < 0:
                return 0, BAD_WIRE
            if fnum == sub[1]:
                c = _count_varints(buf, a, p)
                if c < 0:
                    return 0, BAD_WIRE
                nd += c
            else:
                while a < p:
                    v, a = read_varint(buf, a, p)
                    if a < 0:
                        return 0, BAD_WIRE
                    top = max(top, v) if v >= 0 else np.iinfo(np.int64).max
                    ni += 1
        elif fnum == sub[3] and wt == 2:
            ln, p = read_varint(buf, p, end)
            if p < 0 or p + ln > end or ln % 8 != 0:
                return 0, BAD_WIRE
            nr += ln // 8
            p += ln
        elif fnum == sub[3] and wt == 1:
            nr += 1
            p += 8
        else:
            p = _skip(buf, p, end, wt)
        if p < 0 or p > end:
            return 0, BAD_WIRE
    if not (q > 0 and q < np.inf):
        return 0, BAD_QUANTUM
    if ni != nr or ni > nd or top >= nd:
        return 0, BAD_COUNTS
    return nd, OK


@kernel()
def _fill_quantized(buf, p, end, sub, out, vb, pos, scratch, idx):
    """Decode a ``Quantized`` body validated by :func:`_scan_quantized` into
    ``out[pos:pos + n]`` (``vb``: the same row as bytes, for the raw samples; ``idx``: room
    for the raw indices, at least ``n``)."""
    q = 0.0
    a0 = p
    while p < end:  # the quantum first: it may follow the deltas
        tag, p = read_varint(buf, p, end)
        if tag >> 3 == sub[0] and tag & 7 == 1:
            q = _read_f64(buf, p, scratch)
        p = _skip(buf, p, end, tag & 7)
    p = a0
    acc = 0
    i = pos
    r = 0
    while p < end:
        tag, p = read_varint(buf, p, end)
        fnum = tag >> 3
        wt = tag & 7
        if fnum == sub[1] and (wt == 0 or wt == 2):
            a, p = _varint_run(buf, p, end, wt)
            # the hot loop of a replay: one pass over the bytes of validated varints
            z = 0
            shift = 0
            for s in range(a, p):
                byte = np.int64(buf[s])
                z |= (byte & 0x7F) << shift
                if byte < 0x80:
                    acc += unzigzag(z)
                    out[i] = acc * q
                    i += 1
                    z = 0
                    shift = 0
                else:
                    shift += 7
        elif fnum == sub[2] and (wt == 0 or wt == 2):
            a, p = _varint_run(buf, p, end, wt)
            while a < p:
                idx[r], a = read_varint(buf, a, p)
                r += 1
        else:
            p = _skip(buf, p, end, wt)
    p = a0
    w = 0
    while p < end and w < r:  # raw samples last: their indices may come after them
        tag, p = read_varint(buf, p, end)
        if tag >> 3 == sub[3] and (tag & 7 == 1 or tag & 7 == 2):
            ln = 8
            if tag & 7 == 2:
                ln, p = read_varint(buf, p, end)
            for s in range(p, p + ln, 8):
                base = (pos + idx[w]) * 8
                vb[base:base + 8] = buf[s:s + 8]
                w += 1
            p += ln
        else:
            p = _skip(buf, p, end, tag & 7)


@kernel(nogil=True)  # runs in the read-ahead thread
def _decode_kernel(buf, offs, lens, fn_t0, fn_period, fn_off, fn_vals, sub, front):
    m = offs.shape[0]
    nf = fn_vals.shape[0]
    quantized = sub[0] >= 0
    status = np.zeros(m, np.int8)
    nsamp = np.zeros(m, np.int64)
    t0s = np.zeros(m, np.int64)
    periods = np.zeros(m, np.int64)
    cnt = np.zeros(nf, np.int64)
    seen = np.zeros(nf, np.bool_)
    scratch = np.empty(1, np.float64)
    # pass 1: validate and count samples per message
    for k in range(m):
        p = offs[k]
        end = p + lens[k]
        cnt[:] = 0
        seen[:] = False
        noff = 0
        have_t0 = False
        st = 0
        while p < end:
            tag, p = read_varint(buf, p, end)
            if p < 0:
                st = BAD_WIRE
                break
            fnum = tag >> 3
            wt = tag & 7
            j = _value_slot(fn_vals, fnum)
            if fnum == fn_t0 and wt == 1:
                if p + 8 > end:
                    st = BAD_WIRE
                    break
                t0s[k] = _read_i64(buf, p)
                have_t0 = True
                p += 8
            elif fnum == fn_period and wt == 0:
                v, p = read_varint(buf, p, end)
                periods[k] = v
            elif fnum == fn_off and (wt == 0 or wt == 2):
                a, p = _varint_run(buf, p, end, wt)
                c = _count_varints(buf, a, p) if p >= 0 else -1
                if c < 0:
                    st = BAD_WIRE
                    break
                noff += c
            elif j >= 0 and quantized and wt == 2:
                ln, p = read_varint(buf, p, end)
                if p < 0 or p + ln > end:
                    st = BAD_WIRE
                    break
                if seen[j]:
                    st = REPEATED_FIELD
                    break
                seen[j] = True
                c, st = _scan_quantized(buf, p, p + ln, sub, scratch)
                if st != OK:
                    break
                cnt[j] = c
                p += ln
            elif j >= 0 and not quantized and wt == 2:
                ln, p = read_varint(buf, p, end)
                if p < 0 or p + ln > end or ln % 8 != 0:
                    st = BAD_WIRE
                    break
                cnt[j] += ln // 8
                p += ln
            elif j >= 0 and not quantized and wt == 1:
                if p + 8 > end:
                    st = BAD_WIRE
                    break
                cnt[j] += 1
                p += 8
            else:
                p = _skip(buf, p, end, wt)
            if p < 0:
                st = BAD_WIRE
                break
        if st == 0:
            n = cnt[0]
            for q in range(1, nf):
                if cnt[q] != n:
                    st = BAD_COUNTS
            if noff != 0 and noff != n:
                st = BAD_COUNTS
            if st == 0 and not have_t0:
                st = NO_T0
            if st == 0 and n > 1 and noff == 0 and periods[k] <= 0:
                st = NO_TIME_BASE
            if st == 0:
                nsamp[k] = n
                if noff != 0:
                    periods[k] = -1  # marks "offsets present" for pass 2
        status[k] = st
    total = 0
    for k in range(m):
        total += nsamp[k]
    t = np.empty(front + total, np.int64)
    vals = np.empty((nf, front + total), np.float64)
    vb = vals.view(np.uint8)
    fill = np.zeros(nf, np.int64)
    idx = np.empty(nsamp.max() if m else 0, np.int64)
    # pass 2: fill times and values (messages already validated)
    pos = front
    for k in range(m):
        n = nsamp[k]
        if status[k] != 0 or n == 0:
            continue
        p = offs[k]
        end = p + lens[k]
        fill[:] = 0
        noff = 0
        while p < end:
            tag, p = read_varint(buf, p, end)
            fnum = tag >> 3
            wt = tag & 7
            j = _value_slot(fn_vals, fnum)
            if fnum == fn_off and (wt == 2 or wt == 0):
                a, p = _varint_run(buf, p, end, wt)
                while a < p:
                    z, a = read_varint(buf, a, p)
                    t[pos + noff] = unzigzag(z)
                    noff += 1
            elif j >= 0 and quantized and wt == 2:
                ln, p = read_varint(buf, p, end)
                _fill_quantized(buf, p, p + ln, sub, vals[j], vb[j], pos, scratch, idx)
                p += ln
            elif j >= 0 and not quantized and (wt == 2 or wt == 1):
                ln = 8
                if wt == 2:
                    ln, p = read_varint(buf, p, end)
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
    return status, nsamp, t, vals


def decode_many(
    buf: np.ndarray, offs: np.ndarray, lens: np.ndarray,
    numbers: FieldNumbers, front: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Decode many block payloads lying in one byte buffer.

    Args:
        buf: uint8 buffer holding the payloads.
        offs, lens: int64 start and length of each payload in ``buf``.
        numbers: field numbers and value encoding (see :func:`field_numbers_from_schema`).
        front: room for this many samples (left unset) before the decoded ones in ``t_ns``
            and ``values``: a caller that puts samples it holds there gets one array of
            both without a copy of the decoded ones.

    Returns:
        ``(status, n_samples, t_ns, values)``: per-message status (:data:`OK` or an error code
        of :data:`STATUS_TEXT`) and sample count (0 for bad messages), then the samples of all
        good messages concatenated in message order: ``t_ns`` int64 (front + N,) and
        ``values`` float64 (n_fields, front + N), C-contiguous rows.
    """
    fast = decode_regular(buf, offs, lens, numbers, front)  # what buoymon writes
    if fast is not None:
        return fast
    fn_t0, fn_period, fn_off, fn_vals, sub = numbers
    return _decode_kernel(buf, offs, lens, fn_t0, fn_period, fn_off,
                          np.asarray(fn_vals, np.int64), np.asarray(sub, np.int64), front)


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
