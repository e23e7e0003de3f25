"""Fast, damage-tolerant reader of buoymon MCAP logs.

The file is read front to back record by record (https://mcap.dev/spec); the footer and
summary are not needed, so a file that was cut short (crash, power loss) or has damaged
chunks is read as far as it is intact. (An intact summary's copies of the channel definitions
are taken too, so a damaged chunk that held a channel's definition costs only its own
messages.) Each chunk is decompressed once, its records located by a numba scan and all of
its sensor payloads decoded in bulk (:func:`monitor.codec.decode_many`). With ``read_ahead``
a worker thread does all that for the next chunk (:class:`replay.chunks.ReadAhead`; none of
it holds the GIL) while the caller processes the blocks of the current one; the results are
the same either way. By default the reader reads ahead only when the process may use more
than one CPU (:func:`replay.chunks.read_ahead_pays`: on one core the thread costs CPU and
saves no time).
This delivers millions of messages per second where ``mcap``'s per-message reader manages a
few hundred thousand.

The jobs, one module each: which files (:mod:`replay.log_files`), locating records in the
bytes (:mod:`replay.mcap_scan`), reading a file with salvage (:mod:`replay.salvage`), the
cross-file merge and coalescing (:mod:`replay.merge`); this module joins
them.

Salvage (what is recovered, what is reported lost, see :class:`replay.salvage.FileStats`):

* chunk CRC (when not 0) is checked; a chunk with a bad CRC, a wrong size or that does not
  decompress is skipped whole and reported as a :class:`~replay.salvage.LostRange` with its receive-time range
  (the chunk's log times) and its message count (from the Message Index records after it,
  ``None`` when those are missing too);
* a file cut inside a chunk: every complete message record of the decompressible prefix of the
  chunk is recovered, the rest is reported lost (count unknown);
* a missing footer/summary is only noted (``complete = False``): nothing is lost by it;
* a corrupt record header (impossible opcode or length) is reported and reading resumes at
  the next chunk found by its signature (a chunk whose length field alone is corrupt is
  still read whole when its CRC verifies);
* a payload that is not a valid block is dropped and counted in ``bad_payloads``;
* bytes after the log's end (its closing magic) are not read and counted in
  ``trailing_bytes``; a second log appended there (it starts with the magic) is also reported
  lost, count unknown.
Nothing raises on a damaged file; a file where nothing could be read has ``error`` set and
``messages == 0``; :attr:`LogReader.ok` is False when no file delivered any message.

Ordering guarantees (deterministic for the same files in the same order):

1. Messages of all files pass through one reorder buffer, keyed by MCAP ``publish_time``
   (= sensor time of the block's first sample), or by ``log_time`` (the receive time) for
   a message whose publish time is more than ``max_ahead_s`` after it: a corrupt or wrong
   sensor clock (``time_ahead``, :mod:`monitor.time_ahead`) is read where it was received,
   not after everything (a re-published recording ended on a clock skew, and the reorder
   window let everything after it through at once). A message is released once a message with a
   publish time more than ``reorder_window_s`` later has been read (at the end, all are).
2. Released messages are delivered sorted by ``(publish_time, topic, read order)``; so
   messages that are out of order by less than the window are delivered in sensor-time order.
3. A message read after messages more than the window newer than it (``publish_time`` at or
   before an already released one) is *late*: it is counted in ``late`` and delivered with the
   next release, i.e. out of order; the pipeline's validation then rejects its samples.
4. Every copy of a message is delivered (a recording's re-recorded messages, overlapping
   files): the pipeline drops and counts duplicate samples, live and in replay alike
   (:mod:`monitor.ordering`, :mod:`monitor.validate`; ``samples.<stream>.rejected.duplicate``
   in the report). The order of 2 puts each copy right behind the first.
5. With ``coalesce=True`` the messages of one topic in one release are concatenated, in the
   order of 2, into ONE :class:`SampleBlock` (tens of thousands of samples); the blocks of one
   release are ordered by (first publish time, topic). The samples of each topic are exactly
   those of ``coalesce=False`` in the same order; only the interleaving between topics is
   coarser (per release instead of per message). ``recv_ns`` of a coalesced block is the
   latest receive time of its messages. A release is cut into spans of
   :data:`COALESCE_S` of publish time, each giving its own blocks, so no block covers more.
"""

from __future__ import annotations

from os import PathLike
from typing import Iterator, Sequence

from monitor.blocks import SampleBlock
from monitor.time_ahead import DEFAULT_MAX_AHEAD_S
from replay.chunks import read_ahead_pays
from replay.log_files import expand_paths
from replay.merge import StreamMerge
from replay.salvage import FileSalvage, FileStats


class LogReader:
    """Iterate over the sensor blocks of one or more logs, with per-file statistics.

    Args:
        paths: files or directories (see :func:`replay.log_files.expand_paths`), read in the given order.
        coalesce: concatenate messages per topic and release (see module doc) for speed.
        reorder_window_s: sensor-time horizon within which out-of-order messages are sorted.
        max_ahead_s: a message whose publish time is more than this after its log time is
            ordered by its log time (``[ordering] max_ahead_s``: the pipeline rejects its
            samples that far ahead).
        read_ahead: inflate the next chunk in a worker thread while the caller processes the
            blocks of the current one (same results; uses a second core). None (default):
            only when the process may use more than one CPU
            (:func:`replay.chunks.read_ahead_pays`).

    Iterate once; afterwards :attr:`stats` holds one :class:`FileStats` per file.
    """

    def __init__(self, paths: Sequence[str | PathLike] | str | PathLike, *, coalesce: bool = True,
                 reorder_window_s: float = 60.0, read_ahead: bool | None = None,
                 max_ahead_s: float = DEFAULT_MAX_AHEAD_S):
        if isinstance(paths, (str, PathLike)):
            paths = [paths]
        if not reorder_window_s >= 0:
            raise ValueError(f"reorder_window_s = {reorder_window_s}: must be >= 0")
        self.paths = expand_paths(paths)
        self.coalesce = coalesce
        self.read_ahead = read_ahead_pays() if read_ahead is None else read_ahead
        self.window_ns = int(round(reorder_window_s * 1e9))
        self.stats: list[FileStats] = []
        self._merge = StreamMerge(self.window_ns, coalesce, int(round(max_ahead_s * 1e9)))
        self._files = FileSalvage(self._merge, self.read_ahead)

    @property
    def ok(self) -> bool:
        """True when at least one sensor message was read."""
        return any(s.messages > 0 for s in self.stats)

    def __iter__(self) -> Iterator[SampleBlock]:
        for path in self.paths:
            st = FileStats(path=str(path))
            self.stats.append(st)
            for _ in self._files.read_file(path, st):
                yield from self._merge.release(final=False)
        yield from self._merge.release(final=True)


def iter_blocks(paths: Sequence[str | PathLike] | str | PathLike, coalesce: bool = True,
                reorder_window_s: float = 60.0) -> Iterator[SampleBlock]:
    """Shorthand for ``iter(LogReader(paths, ...))`` when the statistics are not needed."""
    return iter(LogReader(paths, coalesce=coalesce, reorder_window_s=reorder_window_s))
