"""replay.chunks.Inflater: zstd chunks decompressed into a reused buffer give exactly what
``ZstdDecompressor.decompress`` gives, errors included (the general path takes every chunk the
buffer cannot vouch for)."""

from __future__ import annotations

import os
import struct

import numpy as np
import zstandard
from isal.isal_zlib import crc32

from replay.chunks import Inflater

RECORDS = np.arange(40_000, dtype=np.int64).tobytes()  # 320 kB of "records"


def content(data: bytes, usize: int, crc: int, comp: str = "zstd") -> bytes:
    """A chunk record's content: log times, sizes, CRC, compression, then the data."""
    return (struct.pack("<QQQI", 5, 9, usize, crc) + struct.pack("<I", len(comp)) + comp.encode()
            + struct.pack("<Q", len(data)) + data)


def test_a_whole_chunk_inflates_into_the_reused_buffer():
    frame = zstandard.ZstdCompressor().compress(RECORDS)
    inflater = Inflater()
    first = inflater.inflate(content(frame, len(RECORDS), crc32(RECORDS)), False)
    assert isinstance(first.raw, memoryview) and bytes(first.raw) == RECORDS
    assert (first.t_lo, first.t_hi, first.cut, first.error) == (5, 9, False, None)
    # the next chunk reuses the buffer (a smaller one fits in it)
    half = RECORDS[:100_000]
    again = inflater.inflate(content(zstandard.ZstdCompressor().compress(half), len(half),
                                     crc32(half)), False)
    assert bytes(again.raw) == half and again.raw.obj is first.raw.obj


def test_chunks_the_buffer_cannot_vouch_for_read_as_before():
    def both(frame: bytes, usize: int, crc: int) -> tuple:
        got = Inflater().inflate(content(frame, usize, crc), False)
        try:
            raw = zstandard.ZstdDecompressor().decompress(frame, max_output_size=usize)
        except zstandard.ZstdError as e:
            raw = None
            assert got.error == f"chunk does not decompress: {e}"
        else:
            assert (got.raw is None) == (len(raw) != usize or crc not in (0, crc32(raw)))
            assert got.raw is None or bytes(got.raw) == raw
        return None if got.raw is None else bytes(got.raw), raw, got.error

    plain = zstandard.ZstdCompressor().compress(RECORDS)
    checked = zstandard.ZstdCompressor(write_checksum=True).compress(RECORDS)
    good = crc32(RECORDS)
    # a frame cut inside its zstd checksum still yields every byte: decompress refuses it
    assert both(checked[:-2], len(RECORDS), good)[0] is None
    # a checked frame whole, a frame then junk or a second frame: the first frame's records
    for frame in (checked, plain + b"junk", plain + plain):
        assert both(frame, len(RECORDS), good)[0] == RECORDS
    # more or fewer records than declared; a wrong CRC; no CRC (0)
    assert both(plain, len(RECORDS) - 8, good)[2] is not None
    assert both(plain, len(RECORDS) + 8, good)[2] == (
        f"chunk size {len(RECORDS)} != {len(RECORDS) + 8} declared")
    assert both(plain, len(RECORDS), good ^ 1)[2] == "bad chunk CRC"
    assert both(plain, len(RECORDS), 0)[0] == RECORDS


def test_a_damaged_declared_size_is_refused_before_any_buffer_is_sized_by_it():
    """A chunk header whose size has a high bit flipped: the old error, not 8 GB claimed (bit
    33) or a MemoryError that ended the salvage (bits 45, 62; review of 2026-11-26)."""
    frame = zstandard.ZstdCompressor().compress(RECORDS)
    inflater = Inflater()
    for bit in (33, 45, 62):
        usize = len(RECORDS) | (1 << bit)
        got = inflater.inflate(content(frame, usize, crc32(RECORDS)), False)
        assert (got.raw, got.error) == (None, f"chunk size {len(RECORDS)} != {usize} declared")
        assert len(inflater._out) < 1 << 20
    # a frame that does not say its size takes the general path, with the same records
    streamed = zstandard.ZstdCompressor(write_content_size=False).compress(RECORDS)
    got = inflater.inflate(content(streamed, len(RECORDS), crc32(RECORDS)), False)
    assert bytes(got.raw) == RECORDS and not isinstance(got.raw, memoryview)


def test_read_puts_a_file_range_in_the_content_buffer(tmp_path):
    path = tmp_path / "f"
    path.write_bytes(RECORDS)
    inflater = Inflater()
    fd = os.open(path, os.O_RDONLY)
    try:
        assert bytes(inflater.read(fd, 100, 8)) == RECORDS[8:108]
        assert bytes(inflater.read(fd, 100, len(RECORDS) - 10)) == RECORDS[-10:]  # file's end
    finally:
        os.close(fd)
