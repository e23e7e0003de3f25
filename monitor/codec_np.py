"""The log format's block encoding (``buoymon.v2``, :mod:`monitor.codec`) in numpy alone.

A process that only publishes blocks (the bridge, a custom driver through
:mod:`monitor.sensors`) encodes a few blocks a second and needs neither numba nor LLVM:
loading them cost the bridge ~110 MB of memory and seconds of start-up. These functions
give the same bytes as the numba kernel :func:`monitor.codec.put_payload` (tests/
test_codec_np.py checks it on measured and on hard values: ties, NaN, infinities, values
beyond 2**52 quanta); the numba kernel stays for the bulk writer, which encodes thousands
of blocks into one buffer. The message layout is documented in :mod:`monitor.codec`; its
field numbers live here, so that both encoders read them from one place.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from monitor.blocks import SENSOR_FIELDS, SampleBlock
from monitor.quanta import quanta

FIELD_T0 = 1
FIELD_PERIOD = 2
FIELD_OFFSETS = 3
FIRST_VALUE_FIELD = 4
# fields of Quantized
Q_QUANTUM, Q_DELTA, Q_RAW_INDEX, Q_RAW_VALUE = 1, 2, 3, 4
EXACT = 2.0 ** 52  # beyond this many quanta a float64 no longer holds every integer
# 7-bit group boundaries of a varint: a value >= _GROUPS[j] needs more than j + 1 bytes
_GROUPS = np.uint64(1) << (np.arange(1, 10, dtype=np.uint64) * np.uint64(7))


def varint(z: int) -> bytes:
    """One unsigned varint."""
    out = bytearray()
    while z >= 0x80:
        out.append((z & 0x7F) | 0x80)
        z >>= 7
    out.append(z)
    return bytes(out)


def varints(z: np.ndarray) -> np.ndarray:
    """The concatenated varints of unsigned ``z`` (uint64) as uint8: every value's 7-bit
    groups in a row of a table as wide as the longest varint, the rows' used bytes in order
    (a few whole-array operations, whatever the lengths)."""
    z = np.asarray(z, np.uint64)
    if z.shape[0] == 0:
        return np.empty(0, np.uint8)
    size = 1 + np.searchsorted(_GROUPS, z, side="right")
    j = np.arange(int(size.max()))
    groups = (z[:, None] >> (np.uint64(7) * j.astype(np.uint64))) & np.uint64(0x7F)
    more = (j < (size - 1)[:, None]).astype(np.uint64) << np.uint64(7)
    return (groups | more).astype(np.uint8)[j < size[:, None]]


def zigzag(d: np.ndarray) -> np.ndarray:
    """sint64 zigzag of int64 ``d`` as uint64 (wrapping, as protobuf does)."""
    d = np.asarray(d, np.int64)
    return ((d << np.int64(1)) ^ (d >> np.int64(63))).view(np.uint64)


def quantize(v: np.ndarray, q: float) -> tuple[np.ndarray, np.ndarray]:
    """``(k, ok)``: ``k = rint(v / q)`` (or a neighbour at a tie) where ``float(k) * q`` lies
    within ``q / 2`` of ``v``, computed as the decoder does; ``ok`` False for samples kept
    raw (NaN, inf, beyond ``EXACT`` quanta), whose ``k`` is 0."""
    with np.errstate(invalid="ignore", over="ignore"):
        x = v / q
        ok = np.abs(x) < EXACT  # NaN fails too
        k = np.rint(np.where(ok, x, 0.0))
        half = 0.5 * q
        if np.all(ok & (np.abs(k * q - v) <= half)):  # the usual block: every k is the first
            return k.astype(np.int64), ok
        chosen = np.zeros_like(k)
        found = np.zeros(v.shape, bool)
        for c in (k, k - 1.0, k + 1.0):  # the first candidate within q / 2, in this order
            hit = ok & ~found & (np.abs(c * q - v) <= half)
            chosen[hit] = c[hit]
            found |= hit
    return chosen.astype(np.int64), found


def quantized(v: np.ndarray, q: float) -> bytes:
    """One field's samples as a length-prefixed ``Quantized`` message body."""
    k, ok = quantize(v, q)
    if np.all(ok):
        z = zigzag(np.diff(k, prepend=np.int64(0)))
    else:
        z = np.zeros(v.shape, np.uint64)
        z[ok] = zigzag(np.diff(k[ok], prepend=np.int64(0)))  # a raw sample's delta is 0
    deltas = varints(z).tobytes()
    body = [bytes(((Q_QUANTUM << 3) | 1,)), np.array(q, "<f8").tobytes(),
            bytes(((Q_DELTA << 3) | 2,)), varint(len(deltas)), deltas]
    raw = np.flatnonzero(~ok)
    if raw.shape[0]:
        index = varints(raw.astype(np.uint64)).tobytes()
        body += [bytes(((Q_RAW_INDEX << 3) | 2,)), varint(len(index)), index,
                 bytes(((Q_RAW_VALUE << 3) | 2,)), varint(8 * raw.shape[0]),
                 v[raw].astype("<f8").tobytes()]
    msg = b"".join(body)
    return varint(len(msg)) + msg


def encode_samples(t_ns: np.ndarray, values: np.ndarray, quanta: np.ndarray) -> bytes:
    """Payload bytes of one block (as :func:`monitor.codec.encode_samples`): ``t_ns`` int64
    (n,), ``values`` float64 (n_fields, n) in field order, ``quanta`` (n_fields,); ``n`` at
    least 1."""
    t = np.asarray(t_ns, np.int64)
    vals = np.asarray(values, np.float64)
    out = [bytes(((FIELD_T0 << 3) | 1,)), t[:1].astype("<i8").tobytes()]
    if t.shape[0] > 1:
        step = np.diff(t)
        if step[0] > 0 and np.all(step == step[0]):
            out += [bytes((FIELD_PERIOD << 3,)), varint(int(step[0]))]
        else:
            offsets = varints(zigzag(t - t[0])).tobytes()
            out += [bytes(((FIELD_OFFSETS << 3) | 2,)), varint(len(offsets)), offsets]
    for f in range(vals.shape[0]):
        out += [bytes(((FIRST_VALUE_FIELD + f) << 3 | 2,)), quantized(vals[f], float(quanta[f]))]
    return b"".join(out)


def encode_block(block: SampleBlock, overrides: Mapping[str, float] | None = None) -> bytes:
    """Payload bytes of a :class:`SampleBlock` (ValueError if it is empty), with the default
    quanta or ``overrides`` by field name (as :func:`monitor.codec.encode_block`)."""
    if len(block) == 0:
        raise ValueError(f"{block.topic}: an empty block has no sensor time and cannot be encoded")
    names = SENSOR_FIELDS[block.sensor]
    return encode_samples(block.t_ns, np.array([block.fields[f] for f in names]),
                          quanta(block.sensor, overrides))
