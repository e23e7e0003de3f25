"""A replay's blocks: those of its buoy (:func:`of_buoy`), taken in spans (:func:`spans`):
one slab for the blocks of the streams covering one stretch of the log, or of several
stretches in turn, instead of one slab per block.

The reader gives, for each stretch of a log (a release, replay.reader), one coalesced block
per stream, all covering about the same time. Given to ``Pipeline.ingest`` one by one, each
takes a slab, but every block before the last stream's takes almost nothing: the ordering
waits for the stream that lags (a 30-min tension block, then the IMU's: a slab of one
tension sample, then one of everything). On the 30-day benchmark log that was half the
slabs (1,789 of 3,574), each ~0.3 ms of per-slab work in the stream stage and ~0.1 ms in
the tick stage, and in two processes one hand-over more each. Pushed together
(``Pipeline.ingest(*span)``), a stretch's blocks take one slab: the same samples in the
same order, so the same results (monitor.ordering: nothing downstream depends on how the
samples were cut into blocks or interleaved); only the sinks would see fewer steps, so a
replay with sinks keeps one slab per block.

Stretches in turn: a reader's release of a chunk (~73 min of the default streams) comes as
stretches of at most 30 min (replay.merge.COALESCE_S: 30, 30 and 13 min), and each slab
costs about a millisecond whatever its length (the fleet benchmark's buoy: 297 slabs in 5
days). A stretch starting after every sample before it joins the run before it while the run
spans at most the ordering's horizon (and an hour): the pushes are those of the stretches
one by one, so a slab at the run's end releases what their slabs would have released
together (no sample of the later stretch can be at or before a watermark taken before it),
and the ordering holds no more than its horizon allows anyway (149 slabs in those 5 days).
"""

from __future__ import annotations

from typing import Iterable, Iterator

from monitor.blocks import SampleBlock


def of_buoy(blocks: Iterable[SampleBlock], buoy_id: str, ignored: dict[str, int]
            ) -> Iterator[SampleBlock]:
    """The blocks of ``buoy_id``; the others counted per buoy in ``ignored``."""
    for block in blocks:
        if block.buoy_id == buoy_id:
            yield block
        else:
            ignored[block.buoy_id] = ignored.get(block.buoy_id, 0) + 1


# The longest run of stretches: an hour of the default streams is a hand-over of ~1.9 MB
# to the tick stage's process (replay.stage_process: within its 4 MB slots), and a horizon
# set far longer must not make a slab of the whole log.
LONGEST_RUN_NS = 3600 * 1_000_000_000


def spans(blocks: Iterable[SampleBlock], join: bool = True, within_ns: int = 0
          ) -> Iterator[list[SampleBlock]]:
    """``blocks`` in runs of consecutive blocks, in order, each block alone unless ``join``:
    a stretch is a run of blocks where a block joins the one before it when the run has no
    block of its stream and the block starts at or before the run's latest end (so it holds
    at most one block per stream, of overlapping spans: what the ordering buffers anyway);
    a stretch whose samples all come after every sample before it joins the run before it
    while the run's samples span at most ``within_ns`` (the ordering's horizon; at most
    :data:`LONGEST_RUN_NS`)."""
    within_ns = min(within_ns, LONGEST_RUN_NS)
    if not join:
        for block in blocks:
            yield [block]
        return
    run: list[SampleBlock] = []
    first: int | None = None  # the run's earliest sample
    newest: int | None = None  # the latest sample so far
    for stretch in _stretches(blocks):
        lo, hi = _bounds(stretch)
        if lo is not None and hi is not None:
            if first is not None and newest is not None and (
                    lo <= newest or max(hi, newest) - first > within_ns):
                yield run
                run, first = [], None
            first = lo if first is None else first
            newest = hi if newest is None else max(newest, hi)
        run.extend(stretch)
    if run:
        yield run


def _bounds(blocks: list[SampleBlock]) -> tuple[int | None, int | None]:
    """The earliest and latest sample time of ``blocks`` (None, None without samples)."""
    full = [b.t_ns for b in blocks if len(b)]
    if not full:
        return None, None
    return min(int(t.min()) for t in full), max(int(t.max()) for t in full)


def _stretches(blocks: Iterable[SampleBlock]) -> Iterator[list[SampleBlock]]:
    """The runs of one block per stream of overlapping spans (see :func:`spans`)."""
    run: list[SampleBlock] = []
    end = 0
    for block in blocks:
        if run and (block.t_first_ns > end or any(b.sensor == block.sensor for b in run)):
            yield run
            run = []
        end = max(end, block.t_last_ns) if run else block.t_last_ns
        run.append(block)
    if run:
        yield run
