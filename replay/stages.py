"""The pipeline's two stages on two threads: the stream stage of the next slabs while the tick
stage of this one runs.

``Pipeline.process`` is its stream stage (``ingest``: ordering, validation, QC, the motion
estimator, the load, stresses, the learner's spectra) then its tick stage (``advance``:
rainflow and Miner per tick, the alert rules, the sinks). Each stage owns its state and the
tick stage reads the stream stage's only in the slab's hand-over (monitor.pipeline), so the
stream stage may run ahead: the tick stage still gets every hand-over in order, and the
results are the same to the bit as ``process`` block by block. Only the ``nogil`` compiled
kernels (validation, QC, the estimator) and some numpy operations release the GIL, so the
two overlap little: ``run_blocks`` uses this only when asked (``threads=True``; figures in
bench/bench_threads.py). The same split across two processes (replay.stage_process) does
overlap; ``buoymon replay`` uses it when it pays (``--one-process`` to turn it off).
"""

from __future__ import annotations

import queue
import threading
from typing import Iterable, Iterator

from monitor.blocks import SampleBlock
from monitor.pipeline import Pipeline, SlabIntake

AHEAD = 2  # slabs the stream stage may be ahead (memory: this many slabs' hand-overs)


def ingest_ahead(pipeline: Pipeline, blocks: Iterable[SampleBlock],
                 ahead: int = AHEAD) -> Iterator[SlabIntake]:
    """The stream stage of every block and then of the flush, run on a worker thread up to
    ``ahead`` slabs ahead; yields their hand-overs in order (the flush's last). The blocks
    are iterated on the worker. An exception there is raised here; closing the generator
    early (an exception in the caller) stops the worker after its current slab."""
    handed: queue.Queue = queue.Queue(maxsize=ahead)
    stop = threading.Event()

    def put(item: tuple[SlabIntake | None, BaseException | None]) -> bool:
        while not stop.is_set():
            try:
                handed.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def work() -> None:
        try:
            for block in blocks:
                if not put((pipeline.ingest(block), None)):
                    return
            put((pipeline.ingest_end(), None))
        except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread
            put((None, exc))

    worker = threading.Thread(target=work, name="buoymon-ingest", daemon=True)
    worker.start()
    try:
        while True:
            intake, exc = handed.get()
            if exc is not None:
                raise exc
            assert intake is not None
            yield intake
            if intake.block is None:  # the flush: the worker is done
                return
    finally:
        stop.set()
        worker.join()
