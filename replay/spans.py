"""A replay's blocks: those of its buoy (:func:`of_buoy`), taken in spans (:func:`spans`):
one slab for the blocks of the streams covering one stretch of the log, instead of one slab
per block.

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


def spans(blocks: Iterable[SampleBlock], join: bool = True) -> Iterator[list[SampleBlock]]:
    """``blocks`` in runs of consecutive blocks, in order: a block joins the run before it
    when the run has no block of its stream and the block starts at or before the run's
    latest end (so a run holds at most one block per stream, of overlapping spans: what
    the ordering buffers anyway); each block alone unless ``join``."""
    run: list[SampleBlock] = []
    end = 0
    for block in blocks:
        if run and (not join or block.t_first_ns > end
                    or any(b.sensor == block.sensor for b in run)):
            yield run
            run = []
        end = max(end, block.t_last_ns) if run else block.t_last_ns
        run.append(block)
    if run:
        yield run
