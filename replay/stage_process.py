"""The replay's reading and stream stage in a child process, its tick stage in this one: the
second core does half the work of one log.

``Pipeline.ingest`` (the stream stage) never reads the tick stage's state and the tick stage
reads the stream stage's only in the slab's hand-over (monitor.pipeline), so a forked child
can read the log and run the stream stage on its own copy of the pipeline while this process
runs ``Pipeline.advance`` on the hand-overs, in order; at the end the child sends its stream
stage's objects back and this pipeline takes them, so its report and state are those of one
process to the last bit. Threads cannot do this (replay.stages): both stages' Python holds
the GIL most of the time. The stream-stage work that needs nothing but the hand-over's load
and accepted values is done here, where the tick stage leaves more of a CPU than reading
and validation leave the child: the tension statistics, the components' stresses and
peaks, and the sea-state learner's feeding (:func:`intake_of`; the same calls on the same
samples in the same order: the same bits).

The hand-over: each slab's :class:`~monitor.pipeline.SlabIntake`, pickled (protocol 5), its
arrays' data (~46 MB a day of the default streams; a stream's slab without the accepted
values the tick stage never reads, but those the learner takes; the block only when a sink
has a block hook) copied by the child into one of :data:`SLOTS` slots of memory shared with
this process (mapped and touched once before the fork, then reused: no page faults, no
copies through the kernel), the header alone through the pipe. The arrays here are views
of the slot until the tick stage lets go of them: a slot goes back to the child only when
nothing refers to its slab any more (:class:`_SlotReader`, by reference count; a sink or
state that keeps arrays holds the slot, and with every slot held the child sends through
the pipe, into fresh buffers here), so a slot is never written while something reads it.
The slots and the pipe's buffer (1 MB) are all the child can be ahead: memory stays flat in
log length. Headers and answers go two at a time, each side writing what it holds before
it waits, so neither waits for the other's batch.

A child that fails sends its exception, raised here; a child that dies (killed, out of
memory) closes the pipe: :class:`ChildDied` here, nothing saved (``--state`` is written only
after a complete replay), nothing left running. An exception here (a sink) closes the pipes,
which stops the child at its next send or wait.

When it is used: by ``buoymon replay`` (``--one-process`` turns it off) when
:func:`one_process_reason` finds nothing against it: on Linux, when this process may run on
at least two CPUs, the logs inflate to at least :data:`CHILD_MIN_BYTES` (a log cut short,
without a summary: its bytes on disk) and at least
:data:`IDLE_CPUS` of the machine's CPUs are idle as the replay starts (on a busy machine the
two processes wait for each other; figures in bench/bench_threads.py).
"""

from __future__ import annotations

import copyreg
import ctypes
import dataclasses
import fcntl
import gc
import importlib
import io
import itertools
import mmap
import multiprocessing
import operator
import os
import pickle
import select
import signal
import sys
import time
import traceback
import types
from pathlib import Path
from typing import Any, Callable, Generator, Iterable, Sequence

import numpy as np

from monitor.blocks import SENSOR_FIELDS, SampleBlock
from monitor.pipeline import _SEA_STATE_FIELDS, Pipeline, SlabIntake, _StreamSlab, _Totals
from replay.spans import of_buoy, spans

# Logs inflating to less than this replay in one process: the fork and the hand-over cost
# what the second core saves at about a day of the default streams (20.8 MB; measured with
# the hand-over through the pipe: 0.89-0.95 s against 0.90-0.97 s in a fresh process,
# bench/bench_threads.py).
CHILD_MIN_BYTES = 20_000_000
CHILD_NAME = "buoymon-stream"  # the child's name in ps -C, top and pgrep (at most 15 bytes)
IDLE_CPUS = 1.5  # one for each process, less half of one another job may take
_PIPE_BYTES = 1 << 20  # Linux's default ceiling for an unprivileged pipe
# The hand-overs' arrays go through slots of memory shared by the two processes (mapped once
# before the fork, reused: no page faults, no copies through the pipe). A slab of the default
# streams needs up to ~6.5 MB (a run of replay.spans.LONGEST_RUN_NS, 3 h, of tension, IMU,
# GNSS and wave samples on the 1-day bench log; more with a sink's block hook); a larger one
# (or one with every slot still in use here) goes through the pipe. Four slots let the child
# work up to three slabs (some 9 h of the log) ahead. After the replay, arrays a sink kept
# stay valid: their slot stays mapped while they refer to it, and nothing writes it.
SLOTS = 4
SLOT_BYTES = 8 << 20
BATCH = 2  # hand-overs and answers written together: each write may wake the other process
_ALIGN = 64  # each array starts on a cache line (the compiled kernels want aligned arrays)
_HELD = 0x80  # a slot's release message: its number, or'ed with this while still in use

# The stream stage's state (monitor.pipeline, "core step"), taken from the child at the end;
# but the tension statistics and the sea-state learner's feeding side, which need nothing
# but the slab's load and accepted values: they are kept here (intake_of), where the tick
# stage leaves a CPU less busy than the child's reading and validation
_STREAM_ATTRS = ("reorder", "validators", "late_copies", "taken_upto", "processed_ns",
                 "motion_sensor", "estimator", "selector", "_full_estimate")


class ChildDied(RuntimeError):
    """The child process reading the log ended without a word (killed, out of memory)."""


def child_pays(files: Sequence[Path]) -> bool:
    """Whether to replay these logs with the reading and stream stage in a child process
    (:func:`one_process_reason` finds none against it)."""
    return one_process_reason(files) is None


def one_process_reason(files: Sequence[Path], meanwhile: Callable[[], Any] | None = None
                       ) -> str | None:
    """Why these logs replay in one process, or None when the child pays: on Linux, with at
    least two CPUs for this process, at least :data:`CHILD_MIN_BYTES` of data, and at least
    :data:`IDLE_CPUS` of the machine's CPUs idle just before (with another job on the second
    CPU the two processes keep waiting for each other: the 30-day log took 15.2 s against
    11.6 s in one process). The reason is for the operator who asked for two processes.
    ``meanwhile``: work run while the idle CPUs are measured (:func:`idle_cpus`)."""
    from replay.log_files import inflated_size

    # fork, CPU affinity and pipe sizes as Linux has them (elsewhere: one process)
    if not sys.platform.startswith("linux"):
        return f"Linux only (this is {sys.platform})"
    if len(os.sched_getaffinity(0)) < 2:
        return "this process may run on one CPU only"
    size = inflated_size(files)
    if size is None:  # no summary (a log cut short by a crash, a damaged end): its bytes on
        # disk, a lower bound of what its chunks inflate to (compression only shrinks them)
        size = sum(_stored_bytes(p) for p in files)
        if size < CHILD_MIN_BYTES:
            return (f"the logs have no summary (cut short or damaged) and their files hold "
                    f"less than {CHILD_MIN_BYTES / 1e6:g} MB")
    if size < CHILD_MIN_BYTES:
        return (f"the logs hold less than {CHILD_MIN_BYTES / 1e6:g} MB of data (about a day "
                "of the default streams), where a child costs what it saves")
    idle = idle_cpus(meanwhile=meanwhile)
    if idle < IDLE_CPUS:
        return f"{idle:.1f} of the machine's CPUs idle, {IDLE_CPUS:g} needed"
    return None


def _stored_bytes(path: Path) -> int:
    try:
        return os.path.getsize(path)
    except OSError:  # gone since it was listed: the reader says so
        return 0


def idle_cpus(interval_s: float = 0.05, meanwhile: Callable[[], Any] | None = None) -> float:
    """The machine's CPUs idle on average over at least ``interval_s`` from now
    (/proc/stat's idle and iowait times), this process's own CPU counted as idle: it runs
    ``meanwhile`` (work it would do anyway: the replay's kernels loaded while it measures,
    not after), then sleeps what is left of the interval."""
    def sample() -> tuple[int, int, float]:
        with open("/proc/stat") as f:
            ticks = [int(x) for x in f.readline().split()[1:]]
        own = os.times()
        return ticks[3] + ticks[4], sum(ticks), own.user + own.system

    end = time.monotonic() + interval_s
    idle0, total0, own0 = sample()
    if meanwhile is not None:
        meanwhile()
    time.sleep(max(end - time.monotonic(), 0.0))
    idle1, total1, own1 = sample()
    cpus = os.cpu_count() or 1
    idle = idle1 - idle0 + (own1 - own0) * os.sysconf("SC_CLK_TCK")
    return min(cpus * idle / max(total1 - total0, 1), cpus)


# ---------------------------------------------------------------------------------- pickling
def _stream_slab(t: np.ndarray, codes: np.ndarray, acc_t: np.ndarray | None,
                 rx_t: np.ndarray | None, rej_t: np.ndarray, before: tuple,
                 acc_values: list[np.ndarray | None] | None = None) -> _StreamSlab:
    """A stream's slab as the tick stage reads it; its accepted values (the stream stage's)
    only those the sea-state learner takes, as rows (None for the others)."""
    slab = _StreamSlab.__new__(_StreamSlab)
    slab.t, slab.codes, slab.rej_t, slab._before = t, codes, rej_t, before
    slab.acc_t = t if acc_t is None else acc_t
    slab.rx_t = t if rx_t is None else rx_t
    slab.acc_values = acc_values  # type: ignore[assignment]  # read otherwise, it fails loudly
    return slab


def _reduce_stream_slab(s: _StreamSlab) -> tuple:
    return _stream_slab, (s.t, s.codes, None if s.acc_t is s.t else s.acc_t,
                          None if s.rx_t is s.t else s.rx_t, s.rej_t, s._before)


@dataclasses.dataclass(frozen=True)
class _LearnerStream:
    """A stream's slab to send with the values the sea-state learner takes of it."""

    name: str
    slab: _StreamSlab

    def __reduce__(self) -> tuple:
        wanted = _SEA_STATE_FIELDS[self.name]
        rows = [row if field in wanted else None
                for field, row in zip(SENSOR_FIELDS[self.name], self.slab.acc_values)]
        return _stream_slab, (*_reduce_stream_slab(self.slab)[1], rows)


def _no_block() -> None:
    return None


# A hand-over travels as the tuple of its fields, without the components' stresses and
# peaks (the child computes none) and the sea-state learner's inputs, which the parent
# computes from the load and the values the learner takes (sent with their stream), in the
# child's place (the same functions of the same samples: the same bits; the learner's
# inputs, Pipeline.feed_learner, each window's segments so far at every slab, were most of
# the bytes to copy).
_INTAKE_FIELDS = tuple(f.name for f in dataclasses.fields(SlabIntake))
_STREAMS, _STRESSES, _PEAKS, _TIME, _LOAD, _SOURCE, _SPECTRA = (
    _INTAKE_FIELDS.index(f)
    for f in ("streams", "stresses", "peaks", "t", "v", "src", "spectra"))


class _StatsHere:
    """The child's tension statistics: kept in the parent (intake_of)."""

    def add(self, v: np.ndarray, src: np.ndarray) -> None:
        pass


_intake_fields = operator.attrgetter(*_INTAKE_FIELDS)


def _reduce_intake(intake: SlabIntake) -> tuple:
    fields = list(_intake_fields(intake))
    fields[_STREAMS] = {name: _LearnerStream(name, slab) if name in _SEA_STATE_FIELDS else slab
                        for name, slab in intake.streams.items()}
    return tuple, (fields,)


def intake_of(sent: tuple, pipeline: Pipeline) -> SlabIntake:
    """The hand-over the child sent as ``sent`` (its fields), its stream stage completed
    with ``pipeline``'s: the components' stresses and peaks, the tension statistics and the
    sea-state learner's feeding (the child's are off)."""
    fields = list(sent)
    t, v, src = fields[_TIME], fields[_LOAD], fields[_SOURCE]
    pipeline.stats.add(v, src)
    stresses = pipeline.stresses(v)
    fields[_STRESSES], fields[_PEAKS] = stresses, pipeline.peaks(stresses)
    fields[_SPECTRA] = pipeline.feed_learner(fields[_STREAMS], t, stresses)
    return SlabIntake(*fields)


# a stream's totals by their fields' values: a slotted dataclass pickles by its generated
# __getstate__ and __setstate__, which call dataclasses.fields() at every one, every slab
_totals_fields = operator.attrgetter(*(f.name for f in dataclasses.fields(_Totals)))


def _reduce_totals(totals: _Totals) -> tuple:
    return _Totals, _totals_fields(totals)


def _array(data: Any, dtype: str, shape: tuple[int, ...]) -> np.ndarray:
    return np.frombuffer(data, dtype).reshape(shape)


def _reduce_array(a: np.ndarray) -> Any:
    """A plain C-ordered array as its data out of band, its dtype's string and its shape:
    what numpy's own reduction sends, at 2 us an array less (numpy looks up the pickle
    module and pickles the dtype object at every one; ~10 arrays a slab)."""
    if a.flags.c_contiguous and a.dtype.fields is None and not a.dtype.hasobject:
        return _array, (pickle.PickleBuffer(a), a.dtype.str, a.shape)
    return a.__reduce_ex__(5)


class _Pickler(pickle.Pickler):
    dispatch_table = copyreg.dispatch_table.copy()
    dispatch_table[np.ndarray] = _reduce_array
    dispatch_table[_StreamSlab] = _reduce_stream_slab
    dispatch_table[_Totals] = _reduce_totals
    dispatch_table[SlabIntake] = _reduce_intake
    # the estimator keeps the model modules it calls
    dispatch_table[types.ModuleType] = lambda m: (importlib.import_module, (m.__name__,))


class _BlocklessPickler(_Pickler):
    """Sends a hand-over's block as None: no sink here reads it (no samples sent twice)."""

    dispatch_table = {**_Pickler.dispatch_table, SampleBlock: lambda b: (_no_block, ())}


def _pickled(obj: Any, pickler: type[pickle.Pickler]) -> tuple[bytes, list[memoryview]]:
    """``obj`` pickled without its arrays' data, and that data (not copied)."""
    buffers: list[pickle.PickleBuffer] = []
    meta = io.BytesIO()
    pickler(meta, protocol=5, buffer_callback=buffers.append).dump(obj)
    return meta.getvalue(), [b.raw() for b in buffers]


def _write(fd: int, parts: list[Any]) -> None:
    """``parts`` written in as few system calls as the pipe allows (it blocks until it
    holds them all; no thread: a writer thread waited for the GIL at every write, and the
    parent for it)."""
    views = [memoryview(p).cast("B") for p in parts]
    while views:
        n = os.writev(fd, views)
        while views and n >= views[0].nbytes:
            n -= views[0].nbytes
            views.pop(0)
        if views:
            views[0] = views[0][n:]


def _header(kind: str, meta: bytes, where: Any) -> list[bytes]:
    header = pickle.dumps((kind, meta, where), protocol=5)
    return [len(header).to_bytes(8, "little"), header]


def _send(fd: int, kind: str, obj: Any, pickler: type[pickle.Pickler] = _Pickler) -> None:
    """``(kind, obj)`` through the pipe: the header (its length, then the pickle without
    its arrays' data, and their sizes), then that data."""
    meta, raws = _pickled(obj, pickler)
    _write(fd, [*_header(kind, meta, [r.nbytes for r in raws]), *raws])


def _read_into(fd: int, buf: Any, wait: Callable[[], None]) -> None:
    """Fill ``buf`` from the non-blocking ``fd``, calling ``wait`` whenever it is empty."""
    view = memoryview(buf).cast("B")
    while view.nbytes:
        try:
            n = os.readv(fd, [view])
        except BlockingIOError:
            wait()
            continue
        if n == 0:
            raise EOFError
        view = view[n:]


def _receive(fd: int, slots: "_SlotReader") -> tuple[str, Any]:
    """The next message; before waiting for one, the slots' answers are sent (the child
    may be waiting for them)."""
    def wait() -> None:
        slots.flush()
        select.select([fd], [], [])

    size = bytearray(8)
    _read_into(fd, size, wait)
    header = bytearray(int.from_bytes(size, "little"))
    _read_into(fd, header, wait)
    kind, meta, where = pickle.loads(header)
    if isinstance(where, tuple):  # the data is in a slot
        return kind, slots.load(meta, *where)
    buffers = [np.empty(n, np.uint8) for n in where]  # writable: the arrays are the tick stage's
    for buf in buffers:
        _read_into(fd, buf, wait)
    return kind, pickle.loads(meta, buffers=buffers)


def _shared_slots(count: int, size: int) -> list[mmap.mmap]:
    """``count`` blocks of ``size`` bytes of memory that a forked child shares, each page
    touched once now (the hand-overs then never fault a page in)."""
    maps = [mmap.mmap(-1, size) for _ in range(count)]  # anonymous, MAP_SHARED
    zeros = bytes(size)
    for m in maps:
        m.write(zeros)
    return maps


class _SlotWriter:
    """The child's side of the slots: which are free, which the parent still holds; the
    hand-overs' headers, written :data:`BATCH` at a time (each write may wake the parent).

    The parent answers every slot it was sent, once the tick stage is done with the slab:
    free, or held (something there still refers to the slab's arrays; free later). The
    child waits for an answer only while a slot is on its way (its headers written first):
    with every slot held, the data goes through the pipe, so the child never waits for
    what may not come."""

    def __init__(self, fd: int, maps: Sequence[mmap.mmap], answers_fd: int) -> None:
        self.fd, self.answers_fd = fd, answers_fd
        self.views = [memoryview(m) for m in maps]
        self.size = len(maps[0]) if maps else 0
        self.free = list(range(len(maps)))
        self.sent: set[int] = set()  # sent, not answered
        self.pending: list[bytes] = []  # headers not written yet
        os.set_blocking(answers_fd, False)

    def send(self, kind: str, obj: Any, pickler: type[pickle.Pickler]) -> None:
        """``(kind, obj)``: its arrays' data copied into a free slot and the header kept to
        write with the next; through the pipe (after the headers kept) if no slot takes
        it. The headers kept are written at the latest by :meth:`flush`."""
        meta, raws = _pickled(obj, pickler)
        offsets, end = [], 0
        for raw in raws:
            offsets.append(end)
            end += -(-raw.nbytes // _ALIGN) * _ALIGN
        slot = self.take(end)
        if slot is None:
            self.pending += _header(kind, meta, [r.nbytes for r in raws])
            self.flush(raws)
            return
        view = self.views[slot]
        for offset, raw in zip(offsets, raws):
            view[offset:offset + raw.nbytes] = raw
        self.pending += _header(kind, meta, (slot, offsets, [r.nbytes for r in raws]))
        if len(self.pending) >= 2 * BATCH:
            self.flush()

    def flush(self, data: Sequence[Any] = ()) -> None:
        _write(self.fd, [*self.pending, *data])
        self.pending = []

    def take(self, nbytes: int) -> int | None:
        """A free slot for ``nbytes`` (waiting for one on its way), or None: the pipe."""
        if nbytes > self.size or not nbytes:
            return None
        if not self.free:
            self._answers(wait=False)
        if not self.free and self.sent:
            self.flush()  # the parent may be waiting for these to answer
            while not self.free and self.sent:
                self._answers(wait=True)
        if not self.free:  # every slot held by the tick stage
            return None
        slot = self.free.pop()  # the one freed last: the warmest
        self.sent.add(slot)
        return slot

    def _answers(self, wait: bool) -> None:
        if wait:
            select.select([self.answers_fd], [], [])
        try:
            answers = os.read(self.answers_fd, 4096)
        except BlockingIOError:
            return
        if not answers:  # the parent is gone
            raise BrokenPipeError
        for answer in answers:
            slot = answer & ~_HELD
            self.sent.discard(slot)
            if not answer & _HELD:
                self.free.append(slot)


class _SlotReader:
    """The parent's side of the slots: the arrays of a slab sent in a slot are views of it
    until the slot is released, which is only once nothing refers to them any more; the
    answers are written :data:`BATCH` at a time (each write may wake the child), and
    before this process waits (:func:`_receive`).

    Each slab's views hang on one fresh object exporting the slot's memory (a ctypes
    array): every array made from them, and every view of those, keeps a reference to it
    through numpy's memoryview, so its reference count tells whether anything (the tick
    stage, a sink) still holds one. A slot still referred to is answered "held" and
    released later, once it is not."""

    def __init__(self, maps: Sequence[mmap.mmap], answers_fd: int) -> None:
        self.maps, self.fd = maps, answers_fd
        self.owners: dict[int, Any] = {}  # slot -> its current slab's exporting object
        self.held: set[int] = set()
        self.lost = 0  # slabs whose slot had to wait for a later slab to be released
        self.answers = bytearray()  # not written yet

    def load(self, meta: bytes, slot: int, offsets: Sequence[int], sizes: Sequence[int]) -> Any:
        if slot in self.owners:  # the child wrote a slot not given back: nothing here is safe
            raise RuntimeError(f"hand-over slot {slot} written while still in use")
        owner = (ctypes.c_char * len(self.maps[slot])).from_buffer(self.maps[slot])
        base = memoryview(owner).cast("B")
        buffers = [base[o:o + n] for o, n in zip(offsets, sizes)]
        obj = pickle.loads(meta, buffers=buffers)
        del buffers
        base.release()
        self.owners[slot] = owner
        return obj

    def release(self) -> None:
        """Answer every slot the tick stage is done with (call with no reference of one's
        own left to a slab's arrays)."""
        for slot in list(self.owners):
            # the dictionary's reference and getrefcount's argument: 2 when nothing else
            # (no array, no view of one) refers to it
            if sys.getrefcount(self.owners[slot]) == 2:
                del self.owners[slot]
                self.held.discard(slot)
                self.answers.append(slot)
            elif slot not in self.held:
                self.held.add(slot)
                self.lost += 1
                self.answers.append(slot | _HELD)
        if len(self.answers) >= BATCH:
            self.flush()

    def flush(self) -> None:
        if self.answers:
            try:
                os.write(self.fd, self.answers)
            except BrokenPipeError:  # the child ended: the pipe says how
                pass
            self.answers = bytearray()


# ---------------------------------------------------------------------------------- the child
class WantsQc:
    """Stands for the parent's sinks in the child's pipeline: whether one reads the slab's QC
    counts (Pipeline computes them only then). The child calls no sink."""

    def __init__(self, wants_qc: bool) -> None:
        self.wants_qc = wants_qc

    def on_step(self, step: Any) -> None:  # the tick stage's: never runs in the child
        pass

    def close(self) -> None:
        pass


def take_stream_state(pipeline: Pipeline, state: dict[str, Any]) -> None:
    """Give ``pipeline`` the stream stage's objects of the child's pipeline (the tension
    statistics and the learner's feeding side are its own: :func:`intake_of` kept them)."""
    for attr, value in state.items():
        setattr(pipeline, attr, value)


def _name_process(name: str) -> None:
    """Give this process ``name`` in ps, top and pgrep (Linux's prctl PR_SET_NAME): a forked
    child's command line is its parent's, so an operator could not tell the two apart."""
    try:
        ctypes.CDLL(None).prctl(15, name.encode()[:15], 0, 0, 0)  # 15: PR_SET_NAME
    except (OSError, AttributeError):  # not Linux: the name stays the parent's
        pass


def _child(fd: int, other_fds: Sequence[int], release_fd: int, maps: Sequence[mmap.mmap],
           blocks: Iterable[SampleBlock], make_pipeline: Any, send_blocks: bool,
           join_spans: bool, reader: Any) -> None:
    """The child: read, send the first block's buoy id, run the stream stage, send the
    hand-overs, then the stream stage's state, the blocks of other buoys and the reader's
    statistics."""
    for other in other_fds:  # the parent's ends: a parent gone then fails the next send
        os.close(other)
    _name_process(CHILD_NAME)
    try:
        slots = _SlotWriter(fd, maps, release_fd)
        source = iter(blocks)
        first = next(source, None)
        _send(fd, "first", None if first is None else first.buoy_id)
        ignored: dict[str, int] = {}
        streams = None
        pickler = _Pickler if send_blocks else _BlocklessPickler
        if first is not None:
            pipeline = make_pipeline(first.buoy_id)
            pipeline.sea_states = None  # fed in the parent, as the statistics (intake_of)
            pipeline.stats = _StatsHere()  # type: ignore[assignment]
            # no stresses, no peaks (the intake's are empty): the parent computes the
            # stresses for the tick stage anyway, and the peaks of them (intake_of)
            pipeline.components = {}
            own = of_buoy(itertools.chain([first], source), pipeline.buoy_id, ignored)
            for run in spans(own, join_spans, pipeline.reorder.horizon_ns,
                             after_ns=pipeline.reorder.newest_ns):
                done = (len(run), sum(len(b) for b in run), run[-1].t_last_ns)
                slots.send("slab", (pipeline.ingest(*run), done), pickler)
            slots.send("slab", (pipeline.ingest_end(), None), pickler)
            slots.flush()
            streams = {a: getattr(pipeline, a) for a in _STREAM_ATTRS}
        _send(fd, "end", (streams, ignored, getattr(reader, "stats", None)))
    except BrokenPipeError:  # the parent stopped reading: it has its own exception
        pass
    except BaseException as exc:  # noqa: BLE001 - handed to the parent
        try:
            pickle.dumps(exc)
        except Exception:  # noqa: BLE001 - an exception that does not pickle: its text
            exc = RuntimeError("".join(traceback.format_exception(exc)))
        try:
            _send(fd, "error", exc)
        except BrokenPipeError:
            pass
    finally:
        os.close(fd)
        os.close(release_fd)


# --------------------------------------------------------------------------------- the parent
def _how_ended(exitcode: int | None) -> str:
    """A child's end in the operator's words: multiprocessing's -9 means killed by SIGKILL
    (the OOM killer's signal, or an operator's kill -9)."""
    if exitcode is None:
        return "still running"
    if exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exit code {exitcode}"


def run_in_child(blocks: Iterable[SampleBlock], make_pipeline: Any, send_blocks: bool,
                 join_spans: bool = False) -> Generator[tuple[str, Any], None, None]:
    """Read ``blocks`` and run the stream stage in a forked child; yields, in order,
    ``("first", buoy id or None)``, then ``("slab", (the intake's fields (:func:`intake_of`),
    (blocks, samples, last time) or None for the flush))`` per slab and ``("end", (stream
    state or None, ignored blocks, reader statistics))``. ``make_pipeline(buoy_id)`` builds
    the child's pipeline (as the caller builds its own); ``send_blocks``: the intakes carry
    their blocks; ``join_spans``: one slab per stretch of the log (replay.spans; for a
    pipeline without sinks). The child's exception is raised here; :class:`ChildDied` if
    it ends without a word. Closing the generator stops the child."""
    read_fd, write_fd = os.pipe()
    try:
        fcntl.fcntl(write_fd, fcntl.F_SETPIPE_SZ, _PIPE_BYTES)
    except OSError:  # pipe-max-size lowered, or the user's pipe pages spent: the default
        pass  # pipe (64 KB) only makes the child wait more often
    answers_read, answers_write = os.pipe()  # the slots' answers, to the child
    maps = _shared_slots(SLOTS, SLOT_BYTES)
    ctx = multiprocessing.get_context("fork")
    child = ctx.Process(target=_child, name=CHILD_NAME,
                        args=(write_fd, (read_fd, answers_write), answers_read, maps, blocks,
                              make_pipeline, send_blocks, join_spans,
                              blocks if hasattr(blocks, "stats") else None), daemon=True)
    # (multiprocessing flushes the standard streams before it forks: nothing this process
    # buffered is written twice.) The child's garbage collections then skip the objects it
    # inherits: they would write to every one of them, copying each page of this heap
    gc.freeze()
    try:
        child.start()
    finally:
        gc.unfreeze()
    os.close(write_fd)
    os.close(answers_read)
    os.set_blocking(read_fd, False)  # _receive sends the answers before it waits
    slots = _SlotReader(maps, answers_write)
    try:
        while True:
            try:
                kind, obj = _receive(read_fd, slots)
            except EOFError:
                child.join(5)
                raise ChildDied(f"the replay's reading process ended without finishing the "
                                f"log ({_how_ended(child.exitcode)})") from None
            if kind == "error":
                raise obj
            yield kind, obj
            if kind == "end":
                return
            del obj  # the caller is done with the slab (it asks for the next): its slot
            slots.release()  # goes back to the child unless something still refers to it
    finally:
        os.close(read_fd)  # the child's next send fails: it stops
        os.close(answers_write)
        child.join(5)
        if child.is_alive():
            child.kill()
            child.join()
