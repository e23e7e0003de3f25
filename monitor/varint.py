"""Protobuf varint primitives shared by the general decoder (monitor.codec) and the one-pass
decoder of buoymon's own layout (monitor.codec_regular), so both read the same bits."""

from __future__ import annotations

import numpy as np

from models._jit import kernel


@kernel(inline="always")
def read_varint(buf, p, end):
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


@kernel(inline="always")
def unzigzag(z):
    """The signed value of a zigzag-encoded varint (protobuf sint64)."""
    return ((z >> 1) & 0x7FFFFFFFFFFFFFFF) ^ -(z & 1)
