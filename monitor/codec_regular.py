"""Fast decoding of the payloads buoymon itself writes: regular blocks of quantized fields.

:func:`monitor.codec.decode_many` accepts anything a conforming protobuf encoder may produce
and so walks every message several times (validate, count, then fill; each ``Quantized``
body once for its quantum, once for its deltas, once for raw samples). Replaying a log, that
cost about 0.65 us per 1-s tension block and 1.25 us per IMU block: 5 s of a 30-day replay.

Nearly every payload of a log has the one layout :func:`monitor.codec.put_payload` writes for a
regular block of finite samples::

    t0_ns (fixed64) | period_ns (varint > 0) | per value field, in field order:
        Quantized { quantum (double) | delta (packed sint64) }

:func:`decode_regular` decodes a batch of such payloads in two passes: their layout (headers,
and with several fields the exact sample count), then their deltas straight to values, two
messages at a time (:func:`_two_runs`); it gives up (returns None) at the first payload of any
other shape (offsets, raw samples, one sample, other field order, unknown fields, a malformed
varint ...): the caller then decodes the whole batch with the general kernel. The values are
computed exactly as the general kernel computes them (``float64(sum of deltas) * quantum``,
``t0 + i * period``), so the output is the same to the last bit.
"""

from __future__ import annotations

import numpy as np

from models._jit import bits_float, kernel
from monitor.varint import read_varint, unzigzag


@kernel(inline="always")
def _varint_at(buf, s, last):
    """The varint at ``buf[s]`` (``last``: the last byte of its run, which ends a varint):
    ``(z, next position)``, next position 0 if longer than 9 bytes (left to the general
    kernel). One- and two-byte varints without a branch on the length (their mix is the
    data's: a branch on it mispredicts); longer ones in a loop. Unsigned positions: numba
    then adds no wrap-around of negative indices to each access (14 % of the loop)."""
    one = np.uint64(1)
    b0 = np.int64(buf[s])
    b1 = np.int64(buf[min(s + one, last)])
    c0 = b0 >> 7
    z = (b0 & 0x7F) | (((b1 & 0x7F) << 7) * c0)
    s += np.uint64(1 + c0)
    if c0 & (b1 >> 7):
        shift = 14
        while True:
            byte = np.int64(buf[s])
            s += one
            z |= (byte & 0x7F) << shift
            if byte < 0x80:
                break
            shift += 7
            if shift >= 63:
                return z, np.uint64(0)
    return z, s


@kernel()
def _rest(buf, s, z):
    """The rest of a varint of more than two bytes (``z`` holds its first two), from its third
    byte at ``buf[s]``: ``(z, next position)``, next position 0 if longer than 9 bytes."""
    shift = 14
    while True:
        byte = np.int64(buf[s])
        s += np.uint64(1)
        z |= (byte & 0x7F) << shift
        if byte < 0x80:
            return z, s
        shift += 7
        if shift >= 63:
            return z, np.uint64(0)


@kernel(inline="always")
def _two_runs(buf, out, q1, s1, e1, i1, stop1, q2, s2, e2, i2, stop2):
    """Decode two runs of deltas (one field of two messages) into ``out[i1:]`` and
    ``out[i2:]``, varint by varint in turn: the varints of one run form a chain (each
    position follows from the bytes before it) that keeps the CPU waiting on each load;
    two independent chains run in its gaps. Returns the ends of the two outputs, or
    ``(0, 0)`` when a run does not fit its room or holds an overlong varint."""
    one = np.uint64(1)
    last1 = e1 - one
    last2 = e2 - one
    acc1 = 0
    acc2 = 0
    while s1 < e1 and s2 < e2:
        if i1 >= stop1 or i2 >= stop2:
            return np.uint64(0), np.uint64(0)
        b0 = np.int64(buf[s1])
        b1 = np.int64(buf[min(s1 + one, last1)])
        c0 = b0 >> 7
        z1 = (b0 & 0x7F) | (((b1 & 0x7F) << 7) * c0)
        s1 += np.uint64(1 + c0)
        d0 = np.int64(buf[s2])
        d1 = np.int64(buf[min(s2 + one, last2)])
        c1 = d0 >> 7
        z2 = (d0 & 0x7F) | (((d1 & 0x7F) << 7) * c1)
        s2 += np.uint64(1 + c1)
        if c0 & (b1 >> 7):
            z1, s1 = _rest(buf, s1, z1)
        if c1 & (d1 >> 7):
            z2, s2 = _rest(buf, s2, z2)
        if s1 == 0 or s2 == 0:
            return np.uint64(0), np.uint64(0)
        acc1 += unzigzag(z1)
        acc2 += unzigzag(z2)
        out[i1] = acc1 * q1
        out[i2] = acc2 * q2
        i1 += one
        i2 += one
    while s1 < e1:
        if i1 >= stop1:
            return np.uint64(0), np.uint64(0)
        z1, s1 = _varint_at(buf, s1, last1)
        if s1 == 0:
            return np.uint64(0), np.uint64(0)
        acc1 += unzigzag(z1)
        out[i1] = acc1 * q1
        i1 += one
    while s2 < e2:
        if i2 >= stop2:
            return np.uint64(0), np.uint64(0)
        z2, s2 = _varint_at(buf, s2, last2)
        if s2 == 0:
            return np.uint64(0), np.uint64(0)
        acc2 += unzigzag(z2)
        out[i2] = acc2 * q2
        i2 += one
    return i1, i2


@kernel(nogil=True)  # runs in the reader's read-ahead thread
def _decode_regular(buf, offs, lens, tag_t0, tag_period, tags, tag_q, tag_delta, front):
    m = offs.shape[0]
    nf = tags.shape[0]
    # pass 1: the layout of every payload: its delta runs and quanta, and room for its
    # samples: with several fields their exact count (the varints of the first field's run,
    # counted), so the values need no copy to an exact array afterwards (the count costs
    # less than that copy); with one field the run's length in bytes, an upper bound
    # (every varint takes at least one byte): the values are then a contiguous prefix
    t0s = np.empty(m, np.int64)
    periods = np.empty(m, np.int64)
    nsamp = np.zeros(m, np.int64)
    room = np.empty(m, np.int64)
    run_a = np.empty((m, nf), np.int64)
    run_b = np.empty((m, nf), np.int64)
    quanta = np.empty((m, nf), np.float64)
    no = (False, nsamp, np.empty(0, np.int64), np.empty((nf, 0), np.float64))
    cap = front
    for k in range(m):
        p = offs[k]
        end = p + lens[k]
        if p + 10 > end or buf[p] != tag_t0:
            return no
        t0 = 0
        for i in range(8):
            t0 |= np.int64(buf[p + 1 + i]) << (8 * i)
        p += 9
        # tags and (usually) lengths are one byte: read in place, as an inlined read_varint
        # costs a reference count of ``buf`` each (26 % of the decode with four per field);
        # a tag of two bytes is never the byte compared, so its payloads go the general way
        if buf[p] != tag_period:
            return no
        period, p = read_varint(buf, p + 1, end)
        if p < 0 or period <= 0:
            return no
        for j in range(nf):
            if p + 2 > end or buf[p] != tags[j]:
                return no
            ln = np.int64(buf[p + 1])
            p += 2
            if ln >= 0x80:
                ln, p = read_varint(buf, p - 1, end)
            body_end = p + ln
            if p < 0 or body_end > end or p + 11 > body_end or buf[p] != tag_q:
                return no
            qi = 0  # the quantum's bits, as t0's: a slice copy cost 13 % of the decode
            for r in range(8):
                qi |= np.int64(buf[p + 1 + r]) << (8 * r)
            q = bits_float(qi)
            if not (q > 0 and q < np.inf) or buf[p + 9] != tag_delta:
                return no
            dl = np.int64(buf[p + 10])
            a = p + 11
            if dl >= 0x80:
                dl, a = read_varint(buf, p + 10, body_end)
            if a < 0 or a + dl != body_end or dl == 0 or buf[body_end - 1] >= 0x80:
                return no
            if j == 0:
                room[k] = dl
                if nf > 1:  # the run ends in a last byte: one varint per last byte
                    cont = 0
                    s = np.uint64(a)
                    while s < np.uint64(body_end):
                        cont += np.int64(buf[s] >> np.uint8(7))
                        s += np.uint64(1)
                    room[k] = dl - cont
                cap += room[k]
            run_a[k, j] = a
            run_b[k, j] = body_end
            quanta[k, j] = q
            p = body_end
        if p != end:
            return no
        t0s[k] = t0
        periods[k] = period
    vals = np.empty((nf, cap), np.float64)
    # pass 2: the deltas straight to values, two messages at a time (see _two_runs): the
    # first half of the batch from the front, the second half from the room the first
    # half may take, closed up afterwards
    h = (m + 1) // 2
    base2 = front
    for k in range(h):
        base2 += room[k]
    pos1 = front
    pos2 = base2
    for k in range(h):
        k2 = h + k
        pair = k2 < m
        n1 = -1
        n2 = -1
        for j in range(nf):
            e2 = np.uint64(run_b[k2, j] if pair else 0)
            i1, i2 = _two_runs(buf, vals[j], quanta[k, j], np.uint64(run_a[k, j]),
                               np.uint64(run_b[k, j]), np.uint64(pos1),
                               np.uint64(pos1 + room[k]),
                               quanta[k2, j] if pair else 0.0,
                               np.uint64(run_a[k2, j]) if pair else e2, e2,
                               np.uint64(pos2), np.uint64(pos2 + (room[k2] if pair else 0)))
            if i1 == 0:
                return no
            g1 = np.int64(i1) - pos1
            g2 = np.int64(i2) - pos2
            if n1 < 0:
                n1 = g1
                n2 = g2
            elif g1 != n1 or g2 != n2:
                return no
        if n1 < 2 or (nf > 1 and n1 != room[k]):
            return no
        nsamp[k] = n1
        pos1 += n1
        if pair:
            if n2 < 2 or (nf > 1 and n2 != room[k2]):
                return no
            nsamp[k2] = n2
            pos2 += n2
    if pos1 != base2:
        for j in range(nf):
            out = vals[j]
            for i in range(pos2 - base2):
                out[pos1 + i] = out[base2 + i]
    pos = pos1 + pos2 - base2
    # the times are filled once the counts are known, from each payload's t0 and period
    t = np.empty(pos, np.int64)
    at = front
    for k in range(m):
        t0, period = t0s[k], periods[k]
        for i in range(nsamp[k]):
            t[at + i] = t0 + i * period
        at += nsamp[k]
    # one field: a contiguous prefix, as a view (its unused end is never written: the pages
    # of a large array are then never mapped)
    return True, nsamp, t, vals[:, :pos]


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
    ok, nsamp, t, vals = _decode_regular(
        buf, offs, lens, _tag(fn_t0, 1), _tag(fn_period, 0),
        np.array([_tag(f, 2) for f in fn_vals], np.int64), _tag(sub[0], 1), _tag(sub[1], 2),
        front)
    return (np.zeros(offs.shape[0], np.int8), nsamp, t, vals) if ok else None
