"""The replay's reading and stream stage in a child process, its tick stage in this one: the
second core does half the work of one log.

``Pipeline.ingest`` (the stream stage) never reads the tick stage's state and the tick stage
reads the stream stage's only in the slab's hand-over (monitor.pipeline), so a forked child
can read the log and run the stream stage on its own copy of the pipeline while this process
runs ``Pipeline.advance`` on the hand-overs, in order; at the end the child sends its stream
stage's objects back and this pipeline takes them, so its report and state are those of one
process to the last bit. Threads cannot do this (replay.stages): both stages' Python holds
the GIL most of the time.

The hand-over: each slab's :class:`~monitor.pipeline.SlabIntake`, pickled (protocol 5) with
its arrays sent out of band through a pipe and read straight into fresh buffers (46 MB a day
of the default streams, copied twice: the block itself only when a sink has a block hook, a
stream's slab without the accepted values the tick stage never reads, the components'
stresses computed again here). The pipe's buffer (1 MB) and the slab the child is working
on are all the child can be ahead, so memory stays flat in log length.

A child that fails sends its exception, raised here; a child that dies (killed, out of
memory) closes the pipe: :class:`ChildDied` here, nothing saved (``--state`` is written only
after a complete replay), nothing left running. An exception here (a sink) closes the pipe,
which stops the child at its next send.

When it is used: when asked (``buoymon replay --two-processes``; with the default
configuration one process was faster on the 2-core machine: the hand-over costs about 40 %
more CPU in all) and :func:`child_pays` allows it: on Linux, when this process may run on at least two
CPUs, the logs inflate to at least :data:`CHILD_MIN_BYTES` and at least :data:`IDLE_CPUS`
of the machine's CPUs are idle as the replay starts (figures in bench/bench_threads.py).
"""

from __future__ import annotations

import copyreg
import dataclasses
import fcntl
import gc
import importlib
import io
import itertools
import multiprocessing
import os
import pickle
import signal
import sys
import time
import traceback
import types
from pathlib import Path
from typing import Any, Generator, Iterable, Mapping, Sequence

import numpy as np

from monitor.blocks import SampleBlock
from monitor.components import Component
from monitor.pipeline import Pipeline, SlabIntake, _StreamSlab

# Logs inflating to less than this replay in one process: the fork and the hand-over cost
# what the second core saves at about a day of the default streams (20.8 MB: 0.89-0.95 s
# against 0.90-0.97 s in a fresh process; 30 days 7.7 s against 11.0 s, bench/bench_threads.py).
CHILD_MIN_BYTES = 20_000_000
IDLE_CPUS = 1.5  # one for each process, less half of one another job may take
_PIPE_BYTES = 1 << 20  # Linux's default ceiling for an unprivileged pipe

# The stream stage's state (monitor.pipeline, "core step"), taken from the child at the end.
_STREAM_ATTRS = ("reorder", "validators", "late_copies", "taken_upto", "processed_ns",
                 "motion_sensor", "estimator", "selector", "stats", "_full_estimate")
_LEARNER_FEEDS = ("stress", "heave", "accel")  # the sea-state learner's feeding side


class ChildDied(RuntimeError):
    """The child process reading the log ended without a word (killed, out of memory)."""


def child_pays(files: Sequence[Path]) -> bool:
    """Whether to replay these logs with the reading and stream stage in a child process
    (:func:`one_process_reason` finds none against it)."""
    return one_process_reason(files) is None


def one_process_reason(files: Sequence[Path]) -> str | None:
    """Why these logs replay in one process, or None when the child pays: on Linux, with at
    least two CPUs for this process, at least :data:`CHILD_MIN_BYTES` of data, and at least
    :data:`IDLE_CPUS` of the machine's CPUs idle just before (with another job on the second
    CPU the two processes keep waiting for each other: the 30-day log took 15.2 s against
    11.6 s in one process). The reason is for the operator who asked for two processes."""
    from replay.log_files import inflated_size

    # fork, CPU affinity and pipe sizes as Linux has them (elsewhere: one process)
    if not sys.platform.startswith("linux"):
        return f"Linux only (this is {sys.platform})"
    if len(os.sched_getaffinity(0)) < 2:
        return "this process may run on one CPU only"
    size = inflated_size(files)
    if size is None or size < CHILD_MIN_BYTES:
        return (f"the logs hold less than {CHILD_MIN_BYTES / 1e6:g} MB of data (about a day "
                "of the default streams), where a child costs what it saves")
    idle = idle_cpus()
    if idle < IDLE_CPUS:
        return f"{idle:.1f} of the machine's CPUs idle, {IDLE_CPUS:g} needed"
    return None


def idle_cpus(interval_s: float = 0.05) -> float:
    """The machine's CPUs idle on average over ``interval_s`` from now (/proc/stat's idle
    and iowait times; this process sleeps meanwhile, so its own CPU counts as idle)."""
    def idle_total() -> tuple[int, int]:
        with open("/proc/stat") as f:
            ticks = [int(x) for x in f.readline().split()[1:]]
        return ticks[3] + ticks[4], sum(ticks)

    idle0, total0 = idle_total()
    time.sleep(interval_s)
    idle1, total1 = idle_total()
    return (os.cpu_count() or 1) * (idle1 - idle0) / max(total1 - total0, 1)


# ---------------------------------------------------------------------------------- pickling
def _stream_slab(t: np.ndarray, codes: np.ndarray, acc_t: np.ndarray | None,
                 rx_t: np.ndarray | None, rej_t: np.ndarray, before: tuple) -> _StreamSlab:
    """A stream's slab as the tick stage reads it (its accepted values are the stream
    stage's: left out)."""
    slab = _StreamSlab.__new__(_StreamSlab)
    slab.t, slab.codes, slab.rej_t, slab._before = t, codes, rej_t, before
    slab.acc_t = t if acc_t is None else acc_t
    slab.rx_t = t if rx_t is None else rx_t
    slab.acc_values = None  # type: ignore[assignment]  # read here, it fails loudly
    return slab


def _reduce_stream_slab(s: _StreamSlab) -> tuple:
    return _stream_slab, (s.t, s.codes, None if s.acc_t is s.t else s.acc_t,
                          None if s.rx_t is s.t else s.rx_t, s.rej_t, s._before)


def _no_block() -> None:
    return None


# A hand-over travels as the tuple of its fields, without the components' stresses: the
# parent computes them again from the load (3 ms of CPU a day of data, against 28 MB a day
# to copy twice; the same function of the same samples: the same bits).
_INTAKE_FIELDS = tuple(f.name for f in dataclasses.fields(SlabIntake))
_STRESSES, _LOAD = _INTAKE_FIELDS.index("stresses"), _INTAKE_FIELDS.index("v")


def _reduce_intake(intake: SlabIntake) -> tuple:
    fields = [getattr(intake, name) for name in _INTAKE_FIELDS]
    fields[_STRESSES] = None
    return tuple, (fields,)


def intake_of(fields: tuple, components: Mapping[str, Component]) -> SlabIntake:
    """The hand-over the child sent as ``fields``, with the stresses of ``components``."""
    stresses = {name: c.stress(fields[_LOAD], record=False) for name, c in components.items()}
    head, tail = fields[:_STRESSES], fields[_STRESSES + 1:]
    return SlabIntake(*head, stresses, *tail)  # type: ignore[call-arg]


class _Pickler(pickle.Pickler):
    dispatch_table = copyreg.dispatch_table.copy()
    dispatch_table[_StreamSlab] = _reduce_stream_slab
    dispatch_table[SlabIntake] = _reduce_intake
    # the estimator keeps the model modules it calls
    dispatch_table[types.ModuleType] = lambda m: (importlib.import_module, (m.__name__,))


class _BlocklessPickler(_Pickler):
    """Sends a hand-over's block as None: no sink here reads it (no samples sent twice)."""

    dispatch_table = {**_Pickler.dispatch_table, SampleBlock: lambda b: (_no_block, ())}


def _pack(kind: str, obj: Any, pickler: type[pickle.Pickler]) -> list[Any]:
    """``(kind, obj)`` as the byte strings to send: the header's length, the header (the
    pickle without its arrays' data, their sizes), each array's bytes (not copied)."""
    buffers: list[pickle.PickleBuffer] = []
    meta = io.BytesIO()
    pickler(meta, protocol=5, buffer_callback=buffers.append).dump(obj)
    raws = [b.raw() for b in buffers]
    header = pickle.dumps((kind, meta.getvalue(), [r.nbytes for r in raws]), protocol=5)
    return [len(header).to_bytes(8, "little"), header, *raws]


def _send(fd: int, kind: str, obj: Any, pickler: type[pickle.Pickler] = _Pickler) -> None:
    """``(kind, obj)`` written in one system call (the pipe blocks until it holds it all;
    no thread: a writer thread waited for the GIL at every write, and the parent for it)."""
    parts = [memoryview(p).cast("B") for p in _pack(kind, obj, pickler)]
    while parts:
        n = os.writev(fd, parts)
        while parts and n >= parts[0].nbytes:
            n -= parts[0].nbytes
            parts.pop(0)
        if parts:
            parts[0] = parts[0][n:]


def _read_into(fd: int, buf: Any) -> None:
    view = memoryview(buf).cast("B")
    while view.nbytes:
        n = os.readv(fd, [view])
        if n == 0:
            raise EOFError
        view = view[n:]


def _receive(fd: int) -> tuple[str, Any]:
    size = bytearray(8)
    _read_into(fd, size)
    header = bytearray(int.from_bytes(size, "little"))
    _read_into(fd, header)
    kind, meta, sizes = pickle.loads(header)
    buffers = [np.empty(n, np.uint8) for n in sizes]  # writable: the arrays are the tick stage's
    for buf in buffers:
        _read_into(fd, buf)
    return kind, pickle.loads(meta, buffers=buffers)


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


def _stream_state(pipeline: Pipeline) -> dict[str, Any]:
    learner = pipeline.sea_states
    return {"pipeline": {a: getattr(pipeline, a) for a in _STREAM_ATTRS},
            "learner": None if learner is None else {
                "_new_waves": learner._new_waves,
                **{f: (getattr(learner, f).current, getattr(learner, f)._finished)
                   for f in _LEARNER_FEEDS}}}


def take_stream_state(pipeline: Pipeline, state: dict[str, Any]) -> None:
    """Give ``pipeline`` the stream stage's objects of the child's pipeline."""
    for attr, value in state["pipeline"].items():
        setattr(pipeline, attr, value)
    learner = pipeline.sea_states
    if state["learner"] is not None and learner is not None:
        learner._new_waves = state["learner"]["_new_waves"]
        for f in _LEARNER_FEEDS:
            feed = getattr(learner, f)
            feed.current, feed._finished = state["learner"][f]


def _child(fd: int, other_fd: int, blocks: Iterable[SampleBlock], make_pipeline: Any,
           send_blocks: bool, reader: Any) -> None:
    """The child: read, send the first block's buoy id, run the stream stage, send the
    hand-overs, then the stream stage's state, the blocks of other buoys and the reader's
    statistics."""
    os.close(other_fd)  # the parent's end: a parent gone then fails the next send
    try:
        source = iter(blocks)
        first = next(source, None)
        _send(fd, "first", None if first is None else first.buoy_id)
        ignored: dict[str, int] = {}
        streams = None
        pickler = _Pickler if send_blocks else _BlocklessPickler
        if first is not None:
            pipeline = make_pipeline(first.buoy_id)
            for block in itertools.chain([first], source):
                if block.buoy_id != pipeline.buoy_id:
                    ignored[block.buoy_id] = ignored.get(block.buoy_id, 0) + 1
                    continue
                _send(fd, "slab", (pipeline.ingest(block), (len(block), block.t_last_ns)),
                      pickler)
            _send(fd, "slab", (pipeline.ingest_end(), None))
            streams = _stream_state(pipeline)
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


def run_in_child(blocks: Iterable[SampleBlock], make_pipeline: Any, send_blocks: bool
                 ) -> Generator[tuple[str, Any], None, None]:
    """Read ``blocks`` and run the stream stage in a forked child; yields, in order,
    ``("first", buoy id or None)``, then ``("slab", (the intake's fields (:func:`intake_of`),
    (samples, last time) or None for the flush))`` per slab and ``("end", (stream state or
    None, ignored blocks, reader statistics))``. ``make_pipeline(buoy_id)`` builds the
    child's pipeline (as the caller builds its own); ``send_blocks``: the intakes carry
    their blocks. The child's exception is raised here; :class:`ChildDied` if it ends
    without a word. Closing the generator stops the child."""
    read_fd, write_fd = os.pipe()
    try:
        fcntl.fcntl(write_fd, fcntl.F_SETPIPE_SZ, _PIPE_BYTES)
    except OSError:  # pipe-max-size lowered, or the user's pipe pages spent: the default
        pass  # pipe (64 KB) only makes the child wait more often
    ctx = multiprocessing.get_context("fork")
    child = ctx.Process(target=_child, name="buoymon-stream",
                        args=(write_fd, read_fd, blocks, make_pipeline, send_blocks,
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
    try:
        while True:
            try:
                kind, obj = _receive(read_fd)
            except EOFError:
                child.join(5)
                raise ChildDied(f"the replay's reading process ended without finishing the "
                                f"log ({_how_ended(child.exitcode)})") from None
            if kind == "error":
                raise obj
            yield kind, obj
            if kind == "end":
                return
    finally:
        os.close(read_fd)  # the child's next send fails: it stops
        child.join(5)
        if child.is_alive():
            child.kill()
            child.join()
