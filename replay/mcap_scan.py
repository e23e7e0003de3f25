"""Locating records in MCAP bytes (https://mcap.dev/spec), for the damage-tolerant reader.

A numba scan finds the records of a decompressed chunk (or of a run of top-level records) and
the sensor payloads of known channels are decoded in bulk (:func:`monitor.codec.decode_many`);
a signature search finds the next compressed chunk after a corrupt record; the summary section
is read when the footer and its CRC are intact.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from typing import BinaryIO, Iterator, Mapping

import numpy as np

from models._jit import kernel
from monitor import codec
from monitor.mcap_file import MAGIC, OP_CHUNK, OP_FOOTER

@kernel(inline="always")
def _u64_at(buf, p):
    """The little-endian uint64 at ``buf[p]`` (``p`` unsigned: numba then adds no wrap-around
    of negative indices to each byte's access, and LLVM joins the eight loads into one)."""
    v = np.uint64(0)
    for i in range(8):
        v |= np.uint64(buf[p + np.uint64(i)]) << np.uint64(8 * i)
    return v


@kernel(nogil=True)  # runs in the read-ahead thread
def scan_records(buf):
    """Locate records in a decompressed chunk (or any record sequence).

    Returns message fields (channel, log, publish, payload offset, payload length), the other
    records (opcode, content offset, length), the end position and a status: 0 all records
    complete, 1 the buffer ends inside a record, 2 an impossible record (opcode 0).
    """
    n = buf.shape[0]
    # room for the most records the bytes can hold, in two allocations (each large one is
    # an mmap and munmap: eight cost 40 us a chunk)
    msg = np.empty((5, n // 31 + 1), np.int64)
    ch, log, pub, doff, dlen = msg[0], msg[1], msg[2], msg[3], msg[4]
    other = np.empty((3, n // 9 + 1), np.int64)
    oop, ooff, olen = other[0], other[1], other[2]
    m = 0
    o = 0
    p = np.uint64(0)
    nu = np.uint64(n)
    status = 0
    while p < nu:
        if p + np.uint64(9) > nu:
            status = 1
            break
        op = buf[p]
        ln = _u64_at(buf, p + np.uint64(1))
        if op == 0:
            status = 2
            break
        if ln > nu - p - np.uint64(9):
            status = 1
            break
        c = p + np.uint64(9)
        if op == 5 and ln >= np.uint64(22):
            ch[m] = np.int64(buf[c]) | (np.int64(buf[c + np.uint64(1)]) << 8)
            log[m] = np.int64(_u64_at(buf, c + np.uint64(6)))
            pub[m] = np.int64(_u64_at(buf, c + np.uint64(14)))
            doff[m] = np.int64(c) + 22
            dlen[m] = np.int64(ln) - 22
            m += 1
        else:
            oop[o] = op
            ooff[o] = np.int64(c)
            olen[o] = np.int64(ln)
            o += 1
        p = c + ln
    return (ch[:m], log[:m], pub[:m], doff[:m], dlen[:m], oop[:o], ooff[:o], olen[:o],
            np.int64(p), status)


def distinct(ids: np.ndarray) -> list[int]:
    """The distinct values of small non-negative integers (channel ids, stream indices),
    ascending: ``np.unique(ids).tolist()`` by a count per value, without the sort or hash
    table np.unique pays for on every run of records."""
    return np.flatnonzero(np.bincount(ids)).tolist()


@dataclass(slots=True)
class Digest:
    """A run of records located by :func:`scan_records`, its messages grouped by channel
    (indices in record order) and the payloads of the channels already known decoded
    (with ``fronts[channel]`` unset samples first, see :func:`digest`)."""

    buf: np.ndarray
    scan: tuple
    groups: dict[int, np.ndarray]
    decoded: dict[int, tuple]
    fronts: dict[int, int]


def digest(raw: bytes | memoryview, channels: Mapping[int, tuple[int, tuple] | str],
           fronts: Mapping[int, int] | None = None) -> Digest:
    """Scan ``raw`` and decode the messages of the sensor channels in ``channels``, leaving
    room for ``fronts[stream]`` samples before those of each stream (for the samples the
    merge still holds of it: :meth:`replay.merge.StreamMerge.fronts`). A pure function of its
    inputs, so the read-ahead thread can run it (channel definitions never change once read,
    so a copy of them taken earlier decodes the same)."""
    buf = np.frombuffer(raw, np.uint8)
    scan = scan_records(buf)
    ch, doff, dlen = scan[0], scan[3], scan[4]
    groups = {c: np.flatnonzero(ch == c) for c in distinct(ch)}
    decoded = {}
    used = {}
    for c, sel in groups.items():
        target = channels.get(c)
        if isinstance(target, tuple):
            used[c] = fronts.get(target[0], 0) if fronts else 0
            decoded[c] = codec.decode_many(buf, doff[sel], dlen[sel], target[1], used[c])
    return Digest(buf, scan, groups, decoded, used)


MAX_CUT_CHUNK = 64 << 20  # bytes read for a chunk whose length runs past the end of file
_CHUNK_SIGNATURES = (b"\x04\x00\x00\x00zstd", b"\x03\x00\x00\x00lz4")
_SIG_AT = 37  # opcode, length, start, end, uncompressed size, CRC: then the compression string


def find_chunk(f: BinaryIO, start: int, size: int) -> int | None:
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


def end_of_log(f: BinaryIO, pos: int, size: int) -> int:
    """Where the log ends: the byte after its closing magic, found by walking the records
    from ``pos`` (the first after the data section's end: the summary, its offsets, then the
    footer), or the first thing there that cannot be a record. What lies beyond (a second
    file appended, bytes of a broken copy) is no part of the log. A file cut inside a record
    or the magic after the data section ends at its size: cut short, nothing follows."""
    while pos + 9 <= size:
        f.seek(pos)
        op, ln = struct.unpack("<BQ", f.read(9))
        if op == 0 or 0x10 <= op < 0x80:
            return pos
        if ln > size - pos - 9:
            return size
        pos += 9 + ln
        if op == OP_FOOTER:
            f.seek(pos)
            tail = f.read(8)
            if tail == MAGIC:
                return pos + 8
            return size if pos + len(tail) == size and MAGIC.startswith(tail) else pos
    return size


def str_at(b: bytes | memoryview, p: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", b, p)
    return bytes(b[p + 4:p + 4 + n]).decode("utf-8", "replace"), p + 4 + n


# ------------------------------------------------------------------------------ streams


def summary_records(f: BinaryIO, size: int) -> Iterator[tuple[int, bytes]]:
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
