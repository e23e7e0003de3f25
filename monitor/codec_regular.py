"""Fast decoding of the payloads buoymon itself writes: regular blocks of quantized fields.

:func:`monitor.codec.decode_many` accepts anything a conforming protobuf encoder may produce
and so walks every message several times (validate, count, then fill; each ``Quantized``
body once for its quantum, once for its deltas, once for raw samples). Replaying a log, that
cost about 0.65 us per 1-s tension block and 1.25 us per IMU block: 5 s of a 30-day replay.

Nearly every payload of a log has the one layout :func:`monitor.codec.put_payload` writes for a
regular block of finite samples::

    t0_ns (fixed64) | period_ns (varint > 0) | per value field, in field order:
        Quantized { quantum (double) | delta (packed sint64) }

:func:`decode_regular` decodes a batch of such payloads in ONE pass over their bytes (into
room for as many samples per payload as the first one has: exact for a stream of one block
size, so the values need no copy), and gives up (returns None) at the first payload of any
other shape (offsets, raw samples, one sample, other field order, unknown fields, a malformed
varint ...): the caller then decodes the whole batch with the general kernel. The values are
computed exactly as the general kernel computes them (``float64(sum of deltas) * quantum``,
``t0 + i * period``), so the output is the same to the last bit.
"""

from __future__ import annotations

import numpy as np

from models._jit import bits_float, kernel
from monitor.varint import read_varint, unzigzag


# how _decode_regular ends: decoded; declined (not the regular layout); out of room (more
# samples than the room it was given)
_DONE, _DECLINED, _NO_ROOM = 1, 0, 2


@kernel(nogil=True)
def _first_field_samples(buf, offs, lens, tag_t0, tag_period, tag0, tag_q, tag_delta):
    """The number of samples of a batch of payloads of the regular layout: the varints of
    their first value field's deltas (-1 for a payload of another layout: the decoder then
    declines it). With several fields this sizes the values exactly (no copy of an
    over-sized array afterwards: the count costs less than that copy)."""
    total = 0
    for k in range(offs.shape[0]):
        p = offs[k]
        end = p + lens[k]
        if p + 11 > end or buf[p] != tag_t0 or buf[p + 9] != tag_period:
            return -1
        _, p = read_varint(buf, p + 10, end)
        if p < 0 or p + 2 > end or buf[p] != tag0:
            return -1
        ln, p = read_varint(buf, p + 1, end)
        if p < 0 or p + 11 > min(p + ln, end) or buf[p] != tag_q or buf[p + 9] != tag_delta:
            return -1
        dl, a = read_varint(buf, p + 10, end)
        if a < 0 or a + dl > end or dl == 0 or buf[a + dl - 1] >= 0x80:
            return -1
        # the run ends in a last byte: one varint per last byte
        cont = 0
        s = np.uint64(a)
        while s < np.uint64(a + dl):
            cont += np.int64(buf[s] >> np.uint8(7))
            s += np.uint64(1)
        total += dl - cont
    return total


@kernel(nogil=True)  # runs in the reader's read-ahead thread
def _decode_regular(buf, offs, lens, tag_t0, tag_period, tags, tag_q, tag_delta, front, total):
    m = offs.shape[0]
    nf = tags.shape[0]
    cap = total
    if cap < 0:  # every sample takes at least one byte in each field
        cap = 0
        for k in range(m):
            cap += lens[k]
        cap = cap // nf + 1
    cap += front
    # the times are filled once the count is known, from each payload's t0 and period: no
    # array of ``cap`` (twice the samples) to allocate and copy from
    t = np.empty(0, np.int64)
    t0s = np.empty(m, np.int64)
    periods = np.empty(m, np.int64)
    vals = np.empty((nf, cap), np.float64)
    nsamp = np.zeros(m, np.int64)
    one = np.uint64(1)
    pos = front
    for k in range(m):
        p = offs[k]
        end = p + lens[k]
        if p + 10 > end or buf[p] != tag_t0:
            return _DECLINED, nsamp, t, vals
        t0 = 0
        for i in range(8):
            t0 |= np.int64(buf[p + 1 + i]) << (8 * i)
        p += 9
        # tags and (usually) lengths are one byte: read in place, as an inlined read_varint
        # costs a reference count of ``buf`` each (26 % of the decode with four per field);
        # a tag of two bytes is never the byte compared, so its payloads go the general way
        if buf[p] != tag_period:
            return _DECLINED, nsamp, t, vals
        period, p = read_varint(buf, p + 1, end)
        if p < 0 or period <= 0:
            return _DECLINED, nsamp, t, vals
        n = -1
        for j in range(nf):
            if p + 2 > end or buf[p] != tags[j]:
                return _DECLINED, nsamp, t, vals
            ln = np.int64(buf[p + 1])
            p += 2
            if ln >= 0x80:
                ln, p = read_varint(buf, p - 1, end)
            body_end = p + ln
            if p < 0 or body_end > end or p + 11 > body_end or buf[p] != tag_q:
                return _DECLINED, nsamp, t, vals
            qi = 0  # the quantum's bits, as t0's: a slice copy cost 13 % of the decode
            for r in range(8):
                qi |= np.int64(buf[p + 1 + r]) << (8 * r)
            q = bits_float(qi)
            if not (q > 0 and q < np.inf) or buf[p + 9] != tag_delta:
                return _DECLINED, nsamp, t, vals
            dl = np.int64(buf[p + 10])
            a = p + 11
            if dl >= 0x80:
                dl, a = read_varint(buf, p + 10, body_end)
            if a < 0 or a + dl != body_end or dl == 0 or buf[body_end - 1] >= 0x80:
                return _DECLINED, nsamp, t, vals
            # the hot loop: the deltas of one field, straight to values. Unsigned positions:
            # numba then adds no wrap-around of negative indices to each access (14 % of it)
            out = vals[j]
            i = np.uint64(pos)
            stop = np.uint64(cap)
            acc = 0
            s = np.uint64(a)
            end_u = np.uint64(body_end)
            last = end_u - one
            # while two bytes are left, the second is read unconditionally (used only when
            # the first continues); the run's last byte, when it starts a varint, after
            while s < last:
                if i >= stop:
                    return _NO_ROOM, nsamp, t, vals
                # one- and two-byte varints without a branch on the length (their mix is
                # the data's: a branch on it mispredicts); longer ones in a loop
                b0 = np.int64(buf[s])
                b1 = np.int64(buf[s + one])
                c0 = b0 >> 7
                # b0 | b1 << 7 without b0's continuation bit, when b0 continues
                z = b0 + (((b1 << 7) - 0x80) * c0)
                s += np.uint64(1 + c0)
                if c0 & (b1 >> 7):
                    z &= 0x3FFF  # (b1's continuation bit) the first two bytes' 14 bits
                    shift = 14
                    while True:
                        byte = np.int64(buf[s])
                        s += one
                        z |= (byte & 0x7F) << shift
                        if byte < 0x80:
                            break
                        shift += 7
                        if shift >= 63:  # overlong: let the general kernel say so
                            return _DECLINED, nsamp, t, vals
                acc += unzigzag(z)
                out[i] = acc * q
                i += one
            if s == last:
                if i >= stop:
                    return _NO_ROOM, nsamp, t, vals
                acc += unzigzag(np.int64(buf[s]))
                out[i] = acc * q
                i += one
            got = np.int64(i) - pos
            if n < 0:
                n = got
            elif got != n:
                return _DECLINED, nsamp, t, vals
            p = body_end
        if p != end or n < 2:
            return _DECLINED, nsamp, t, vals
        t0s[k] = t0
        periods[k] = period
        nsamp[k] = n
        pos += n
    t = np.empty(pos, np.int64)
    at = np.uint64(front)  # unsigned: no wrap-around of negative indices, so LLVM vectorizes
    for k in range(m):
        t0, period = t0s[k], periods[k]
        for i in range(nsamp[k]):
            t[at + np.uint64(i)] = t0 + i * period
        at += np.uint64(nsamp[k])
    return _DONE, nsamp, t, vals[:, :pos]


def _tag(field: int, wire_type: int) -> int:
    return (field << 3) | wire_type


def decode_regular(buf: np.ndarray, offs: np.ndarray, lens: np.ndarray, numbers: tuple,
                   front: int = 0
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The payloads ``buf[offs[i]:offs[i] + lens[i]]`` decoded as
    :func:`monitor.codec.decode_many` decodes them (``front`` unset samples first), when every
    one has the regular layout of the module docstring; None otherwise (or for the float64
    format, or no payloads). ``numbers``: :data:`monitor.codec.FieldNumbers`."""
    fn_t0, fn_period, _, fn_vals, sub = numbers
    if offs.shape[0] == 0 or sub[0] < 0 or sub[1] < 0 or fn_period < 0 or not fn_vals:
        return None
    tags = np.array([_tag(f, 2) for f in fn_vals], np.int64)
    tag_t0, tag_period, tag_q, tag_delta = (_tag(fn_t0, 1), _tag(fn_period, 0), _tag(sub[0], 1),
                                            _tag(sub[1], 2))
    args = (buf, offs, lens, tag_t0, tag_period, tags, tag_q, tag_delta, front)
    # room: as many samples per payload as the first one has (a stream's blocks usually have
    # one size). Where a later one has more: one field, room from the payloads' sizes (every
    # varint takes a byte; the values a view of its start); several, the counted samples
    # (counting every payload cost 16 % of the decode in the fleet replay)
    first = _first_field_samples(buf, offs[:1], lens[:1], tag_t0, tag_period, tags[0], tag_q,
                                 tag_delta)
    if first < 0:
        return None
    how, nsamp, t, vals = _decode_regular(*args, first * offs.shape[0])
    if how == _NO_ROOM:
        total = -1
        if len(fn_vals) > 1:
            total = _first_field_samples(buf, offs, lens, tag_t0, tag_period, tags[0], tag_q,
                                         tag_delta)
            if total < 0:
                return None
        how, nsamp, t, vals = _decode_regular(*args, total)
    if how != _DONE:
        return None
    if not vals.flags.c_contiguous:  # several fields, fewer samples than room: (rare) a copy
        vals = np.ascontiguousarray(vals)
    return np.zeros(offs.shape[0], np.int8), nsamp, t, vals
