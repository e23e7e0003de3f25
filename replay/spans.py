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
days). A stretch whose samples all start after every sample before it joins the run before
it, exactly, however long the run (the horizon plays no part): the pushes are those of the
stretches one by one, and the slab taken at the run's end holds what their slabs would
have taken, with the same verdicts (no sample of a later stretch is at or before a
watermark taken before it, so none is ``time_backwards``, none is a copy of an earlier
one, and the validators' floors are below all of them); the ordering's release (``W =
min`` of the gating streams' marks) is a function of what was pushed, so the run's last
watermark is theirs. Nothing downstream depends on where the slabs were cut but one rule:
the ticks of a gap without samples are evaluated only up to ``monitor.pipeline.
_EMPTY_SPAN_S`` (or the damage-rate window) after its last sample (``Pipeline._tick_ends``:
after a clock jump, memory and time depend on the data, not on the jump). Until
2026-11-26 that walk counted from a slab's first tick when the gap began before it, so a
longer gap cut by a slab boundary was walked further than whole; it now counts from the
newest sample before the gap (``Pipeline.sample_tick_ns``), and the rule below, written
for the old walk, is kept as a second guard. A boundary is left out only where no
watermark can fall into such a gap, nor start one (a stretch after a gap over
``_EMPTY_SPAN_S`` never joins: with every stream's last sample on a tick end the watermark
is that sample, and the old walk went from the tick after it, one later than a run across
it; tests/test_spans.py): in replay every stream gates, so the watermark after the stretch
before it lies within the horizon of the newest sample (``newest - horizon <= W <=
newest``; a restored ordering's newest may be later: then none is left out), and
:func:`spans` keeps the time since which the samples leave no gap longer than
``_EMPTY_SPAN_S`` (a block that may lose samples ``time_ahead`` of its receive time
restarts it at the next stretch). Every boundary is checked so: the runs of up to an hour
within the horizon that replays took before (main f01117f to 2026-11-26) were joined without
the check, and after a gap of over an hour with a stream silent they gave other alerts than
a slab per block (tests/test_spans.py); so the first horizon of a log, and of the data after
such a gap, goes stretch by stretch.

That leaves memory and the cache as the bounds: a run spans at most :data:`LONGEST_RUN_NS`
of sensor time (a slab's arrays: ~2.2 MB an hour of the default streams in the two-process
replay's hand-over, replay.stage_process.SLOT_BYTES; peak RSS of a one-process replay of
the 1-day bench log 232 / 250 / 259 / 264 MB for runs of at most 1 / 2 / 3 / 4 h). Fleet
buoy002, 5 days, CPU best of 4, load ~3, 2026-11-26 08:42 UTC (with the horizon ignored):
1 h 148 slabs, 0.89-1.00 s; 2 h 67 slabs, 0.76-0.77 s; 3 h 44 slabs, 0.75-0.77 s; 4 h 34
slabs, 0.74-0.77 s; with this rule at 3 h, 39 slabs (2 h against 3 h at 08:49, load 2.6:
0.815-0.826 s against 0.787-0.819 s).
"""

from __future__ import annotations

from typing import Iterable, Iterator

from monitor.blocks import SampleBlock
from monitor.pipeline import _EMPTY_SPAN_S


def of_buoy(blocks: Iterable[SampleBlock], buoy_id: str, ignored: dict[str, int]
            ) -> Iterator[SampleBlock]:
    """The blocks of ``buoy_id``; the others counted per buoy in ``ignored``."""
    for block in blocks:
        if block.buoy_id == buoy_id:
            yield block
        else:
            ignored[block.buoy_id] = ignored.get(block.buoy_id, 0) + 1


# The longest run of stretches (see the module docstring): for memory and the cache, whatever
# the horizon
LONGEST_RUN_NS = 3 * 3600 * 1_000_000_000
# A gap of at most this much sensor time without samples is evaluated tick by tick whatever
# the slabs' cut: Pipeline._tick_ends walks at least _EMPTY_SPAN_S of ticks after a sample.
_DENSE_GAP_NS = int(_EMPTY_SPAN_S * 1e9)


def spans(blocks: Iterable[SampleBlock], join: bool = True, horizon_ns: int | None = None, *,
          after_ns: int | None = None) -> Iterator[list[SampleBlock]]:
    """``blocks`` in runs of consecutive blocks, in order, each block alone unless ``join``:
    a stretch is a run of blocks where a block joins the one before it when the run has no
    block of its stream and the block starts at or before the run's latest end (so it holds
    at most one block per stream, of overlapping spans: what the ordering buffers anyway);
    a stretch whose samples all come after every sample before it joins the run before it
    while the run's samples span at most :data:`LONGEST_RUN_NS`, if no watermark within
    ``horizon_ns`` (the ordering's horizon in replay, where every stream gates) before it
    can fall into a gap of the samples longer than :data:`_DENSE_GAP_NS` (module
    docstring), it does not start after such a gap, and the run before has a sample later
    than ``after_ns`` (the newest time a restored ordering has received,
    ReorderBuffer.newest_ns: the watermark may lie up to it). No horizon given: stretches
    alone."""
    if not join:
        for block in blocks:
            yield [block]
        return
    horizon, longest = (0, 0) if horizon_ns is None else (horizon_ns, LONGEST_RUN_NS)
    run: list[SampleBlock] = []
    first: int | None = None  # the earliest sample of the run
    newest: int | None = None  # the latest sample so far
    dense: int | None = None  # since when the samples leave no gap longer than _DENSE_GAP_NS
    reset = False  # the next stretch's start opens a gap (the last one's end is not sure)
    for stretch in _stretches(blocks):
        lo, hi, gaps, sure = _bounds(stretch)
        if lo is not None and hi is not None:
            if first is not None and newest is not None and (
                    lo <= newest or lo - newest > _DENSE_GAP_NS
                    or dense is None or dense > newest - horizon
                    or max(hi, newest) - first > longest
                    or (after_ns is not None and newest <= after_ns)):
                yield run
                run, first = [], None
            since = (lo if newest is None or dense is None or reset
                     or lo - newest > _DENSE_GAP_NS else dense)
            dense = since if gaps is None else max(since, gaps)
            reset = not sure
            first = lo if first is None else first
            newest = hi if newest is None else max(newest, hi)
        run.extend(stretch)
    if run:
        yield run


def _bounds(blocks: list[SampleBlock]) -> tuple[int | None, int | None, int | None, bool]:
    """The earliest and latest sample time of ``blocks`` (None, None without samples); the
    latest time a gap longer than :data:`_DENSE_GAP_NS` may end within them (None: none);
    whether all their samples reach the ordering (False: some may be ``time_ahead`` of
    their receive time, dropped before it, monitor.time_ahead)."""
    hulls = sorted((int(b.t_ns.min()), int(b.t_ns.max()), b.recv_ns) for b in blocks if len(b))
    if not hulls:
        return None, None, None, True
    gaps: int | None = None
    sure = True
    reach = hulls[0][0]
    for lo, hi, recv in hulls:
        if recv and hi > recv:  # (then its samples' gaps are not sure either)
            sure = False
        if lo - reach > _DENSE_GAP_NS or hi - lo > _DENSE_GAP_NS or not sure:
            gaps = hi if gaps is None else max(gaps, hi)
        reach = max(reach, hi)
    return hulls[0][0], reach, gaps, sure


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
