"""MCAP chunk records: decompress and check them, optionally one chunk ahead in a worker thread.

:meth:`Inflater.inflate` turns a chunk record's content into its records (or says why they are lost)
without interpreting any of them. zstd, lz4 and the CRC release the GIL, so
:class:`ReadAhead` inflating the next chunk in a worker thread while the caller processes the
current one puts a second core to work: replaying the 30-day benchmark log, about 2.3 s of
its ~15 s leave the main thread.

The thread pays only on a core of its own: on one core it costs CPU (the 30-day replay took
13.78 CPU-s with it, 11.89 without, one core, 2026-11-25) and gains no wall time. So the rule
(:func:`read_ahead_pays`): read ahead only when the process may run on more CPUs than there
are processes replaying at once (1 for a single replay, the pool's size for a fleet).
"""

from __future__ import annotations

import os
import struct
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Callable

import zstandard
# zlib's CRC-32, computed with carry-less multiplication (ISA-L): 26 GB/s against zlib's
# 1.6-3 GB/s, which cost 0.15 CPU-s of reading the 30-day benchmark log; 1 ms to import
from isal.isal_zlib import crc32

from monitor.mcap_file import OP_CHUNK, OP_MESSAGE_INDEX


@dataclass(slots=True)
class Inflated:
    """A chunk record's records, or why they are lost.

    ``raw`` is None when nothing could be recovered; with ``cut`` it is the decompressible
    prefix of a chunk the file ends inside. ``t_lo``/``t_hi`` are the chunk's log-time range
    (None when its header is unreadable). ``error`` says why the chunk, or the rest of a cut
    one, is lost; ``indexed`` marks a loss whose message count the chunk's Message Index
    records (which follow it in the file) can give.
    """

    raw: bytes | memoryview | None
    t_lo: int | None = None
    t_hi: int | None = None
    cut: bool = False
    error: str | None = None
    indexed: bool = False


_ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"


class Inflater:
    """:meth:`inflate` chunk records with one zstd context and two buffers (the compressed
    content and the decompressed records) reused chunk after chunk: a fresh megabyte for
    each chunk's records cost a page fault per 4 kB, as long as zstd's work on it (0.28 of
    0.76 CPU-s reading 15 days of the fleet benchmark's buoy went to decompress, 0.04 to
    reading). The records (and the content :meth:`read` gives) are views of those buffers,
    valid until the next call: take what they hold before. Not for sharing between threads.
    """

    def __init__(self) -> None:
        self._dctx = zstandard.ZstdDecompressor()
        self._out = bytearray()
        self._in = bytearray()

    def read(self, fd: int, n: int, at: int) -> memoryview:
        """``n`` bytes of file ``fd`` from byte ``at`` (fewer at its end), in the reused
        content buffer."""
        if len(self._in) < n:
            self._in = bytearray(n)  # a new one: views of the old may still be alive
        view = memoryview(self._in)[:n]
        return view[:os.preadv(fd, [view], at)]

    def inflate(self, content: bytes | memoryview, cut: bool) -> Inflated:
        """Decompress and check one chunk record's content (``cut``: the file ends inside it).

        A cut chunk whose decompressed records are all there and pass the CRC (only its length
        field was wrong) counts as whole.
        """
        try:
            t_lo, t_hi, usize, crc = struct.unpack_from("<QQQI", content, 0)
            (slen,) = struct.unpack_from("<I", content, 28)
            comp = bytes(content[32:32 + slen]).decode()
            (clen,) = struct.unpack_from("<Q", content, 32 + slen)
        except (struct.error, UnicodeDecodeError):
            return Inflated(None, error="file cut inside a chunk header")
        data = memoryview(content)[40 + slen:40 + slen + clen]
        if comp == "zstd" and not cut and crc != 0:
            raw = self._into(data, usize, crc)
            if raw is not None:
                return Inflated(raw, t_lo, t_hi)
        try:
            if comp == "zstd":
                raw = (self._dctx.decompressobj().decompress(data) if cut
                       else self._dctx.decompress(data, max_output_size=usize))
            elif comp == "lz4":
                import lz4.frame

                raw = lz4.frame.decompress(bytes(data))
            elif comp == "":
                raw = bytes(data)
            else:
                return Inflated(None, t_lo, t_hi, error=f"chunk compression {comp!r} not supported",
                                indexed=True)
        except Exception as e:  # any decompressor error means a damaged chunk
            if cut:
                return Inflated(None, t_lo, t_hi, cut=True,
                                error="file cut inside a chunk (nothing decompressible)")
            return Inflated(None, t_lo, t_hi, error=f"chunk does not decompress: {e}",
                            indexed=True)
        if cut:
            whole = len(raw) == usize and crc != 0 and crc32(raw) == crc
            return Inflated(raw, t_lo, t_hi, cut=not whole)
        if len(raw) != usize:
            return Inflated(None, t_lo, t_hi, error=f"chunk size {len(raw)} != {usize} declared",
                            indexed=True)
        if crc != 0 and crc32(raw) != crc:
            return Inflated(None, t_lo, t_hi, error="bad chunk CRC", indexed=True)
        return Inflated(raw, t_lo, t_hi)

    def _into(self, data: memoryview, usize: int, crc: int) -> memoryview | None:
        """The records of a whole zstd chunk decompressed into the reused buffer, when that
        gives exactly what ``decompress`` gives: ``usize`` bytes passing the CRC, from a
        frame without a zstd checksum (a frame cut inside its checksum, or inside an empty
        last block, can yield every byte, which ``decompress`` refuses; without the checksum,
        the last block is what ends the output). None otherwise: the chunk then takes the
        general path, errors and all."""
        if len(data) < 5 or data[:4] != _ZSTD_MAGIC or data[4] & 0x04:
            return None
        try:  # the size the frame says (as decompress allocates), not the chunk header's
            if zstandard.frame_content_size(data) != usize:
                return None
        except zstandard.ZstdError:
            return None
        if len(self._out) <= usize:
            self._out = bytearray(usize + 1)  # one more: a longer frame shows
        out = memoryview(self._out)[:usize + 1]
        try:
            got = self._dctx.stream_reader(data).readinto(out)
        except Exception:
            return None
        if got != usize or crc32(out[:usize]) != crc:
            return None
        return out[:usize]


def usable_cpus() -> int:
    """CPUs this process may run on: its affinity mask (``taskset``, cgroup cpusets), else
    ``os.cpu_count()`` where the platform has no affinity call."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def read_ahead_pays(processes: int = 1, cpus: int | None = None) -> bool:
    """Whether each of ``processes`` replays running at once should read ahead: only when
    the ``cpus`` it may use (default :func:`usable_cpus`) leave a core free for the thread,
    i.e. ``cpus > processes``. One replay on one core: no; one on two: yes; a pool of two
    workers on two cores: no (each thread would only take CPU from a worker)."""
    return (usable_cpus() if cpus is None else cpus) > processes


class ReadAhead:
    """Inflate, in one worker thread, the chunk that follows a file position.

    :meth:`schedule` starts looking at a position (skipping Message Index records), inflates
    the chunk found there if it lies wholly inside the file and, if its records are intact,
    applies ``then(records, arg)`` to them in the worker too. :meth:`take` returns
    ``(Inflated, then's result or None)`` if that chunk is the one at the position asked, else
    None (the caller then reads the chunk itself). The worker reads with ``os.pread`` on
    ``fd``, so it shares no file position with the caller. Close before closing the file.
    """

    def __init__(self, fd: int, size: int, then: Callable[[bytes, Any], Any]) -> None:
        self._fd, self._size, self._then = fd, size, then
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="mcap-inflate")
        self._inflater = Inflater()
        self._future: Future | None = None

    def schedule(self, pos: int, arg: Any = None) -> None:
        self._future = self._pool.submit(self._next_chunk, pos, arg)

    def take(self, pos: int) -> tuple[Inflated, Any] | None:
        future, self._future = self._future, None
        if future is None:
            return None
        try:
            got = future.result()
        except Exception:  # e.g. the file shrank under the worker: read it in line instead
            return None
        return got[1:] if got is not None and got[0] == pos else None

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._future = None

    def _next_chunk(self, pos: int, arg: Any) -> tuple[int, Inflated, Any] | None:
        while pos + 9 <= self._size:
            op, ln = struct.unpack("<BQ", os.pread(self._fd, 9, pos))
            if ln > self._size - pos - 9:
                return None  # a cut or corrupt record: the caller's salvage handles it
            if op == OP_MESSAGE_INDEX:
                pos += 9 + ln
                continue
            if op != OP_CHUNK:
                return None
            content = self._inflater.read(self._fd, ln, pos + 9)
            if len(content) != ln:
                return None
            c = self._inflater.inflate(content, False)
            return pos, c, (self._then(c.raw, arg) if c.raw is not None else None)
        return None
