"""Drive the pipeline core from recorded logs: ``buoymon replay`` and ``buoymon demo``.

The reader (``replay.reader.iter_blocks``) yields coalesced blocks (many 1-s messages of one
channel joined), in log order; the pipeline's ordering uses ``[ordering] replay_horizon_s`` so
that coalescing cannot make one channel look late. ``--state`` continues a previous replay: the
state file is loaded if it exists and saved atomically at the end, so a log replayed in parts
gives the same committed damage as one pass, to the last bit.
"""

from __future__ import annotations

import contextlib
import ctypes
import itertools
import json
import logging
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence, TextIO

from models._jit import uncompiled
from monitor.blocks import SampleBlock
from monitor.config import Config, config_with
from monitor.events import Sink
from monitor.pipeline import Pipeline
from monitor.time_ahead import DEFAULT_MAX_AHEAD_S, pace_ns
from monitor.atomic_file import atomic_write_text
from replay.report import build_report
from replay.spans import of_buoy, spans
from replay.stages import ingest_ahead

log = logging.getLogger(__name__)

# Logs whose chunks inflate to at most this many bytes replay with every kernel run as plain
# Python, never importing numba: loading numba and its CPU target for the cached kernels
# costs about 0.55 s of CPU, more than such a log's loops take uncompiled. A whole replay in
# a fresh process, CPU s plain / compiled, by inflated size (simulated logs of the default
# streams; 2026-11-25, 2-core Xeon, `bench/bench_startup.py --plain-sweep`): 20 kB (36 s of
# log) 0.43 / 1.10, 57 kB (2 min) 0.68 / 1.10, 84 kB (3 min) 0.82 / 1.14, 137 kB (5 min)
# 1.06 / 1.14, 269 kB (10 min) 2.01 / 1.08: even near 130 kB; 100 kB keeps a margin.
PLAIN_PYTHON_BYTES = 100_000


def plain_python_pays(files: Sequence[Path]) -> bool:
    """Whether the kernels should run as plain Python for these logs: they are small (inflate
    to at most :data:`PLAIN_PYTHON_BYTES`, from their summaries) and this process has not
    loaded numba yet (once loaded, compiled is faster at any size). Same bits either way."""
    from replay.log_files import inflated_size

    if "numba" in sys.modules:
        return False
    size = inflated_size(files)
    return size is not None and size <= PLAIN_PYTHON_BYTES


# glibc's mallopt parameters (malloc.h) and the values a replay sets
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_TRIM_BYTES, _MMAP_BYTES = 512 << 20, 32 << 20  # 32 MB: the largest mallopt takes


def keep_freed_memory() -> bool:
    """Have glibc's malloc serve blocks of up to 32 MB from its heap and keep what is freed
    for the next ones, for the rest of this process (and a child it forks). A replay
    allocates and frees chunk- and slab-sized buffers by the thousand: by default each is
    mapped anew and every page faulted in again (30-day log: 100-150k page faults and
    ~0.5 s of system time a process, 15-35k with this; bench/bench_threads.py). The heap
    then stays at the most the replay held at once, flat in log length. Whether it was set
    (False off glibc)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):  # another C library
        return False
    return bool(mallopt(_M_TRIM_THRESHOLD, _TRIM_BYTES)) and bool(
        mallopt(_M_MMAP_THRESHOLD, _MMAP_BYTES))


def collect_logs(paths: Sequence[str | Path]) -> list[Path]:
    """The ``*.mcap`` files under ``paths`` (folders searched with their sub-folders, as fleet
    mode does; a file named twice is read once), in the order of their first message time,
    so that no file's samples arrive after later ones (which validation would reject as
    going back in time); files whose start cannot be read go last, in the order given. A
    missing path is logged and skipped (the others are still replayed); FileNotFoundError
    if nothing is left."""
    from replay.log_files import expand_paths, file_start_ns

    out: list[Path] = []
    seen: set[Path] = set()
    for p in expand_paths(paths, recursive=True, missing="skip"):
        if p.resolve() not in seen:  # a file named twice, or a file and its folder
            seen.add(p.resolve())
            out.append(p)
    if not out:
        raise FileNotFoundError(f"no log files in {[str(p) for p in paths]}")
    starts = [file_start_ns(p) for p in out]
    order = sorted(range(len(out)), key=lambda i: (starts[i] is None, starts[i] or 0, i))
    return [out[i] for i in order]


def load_state(path: str | Path | None) -> dict[str, Any] | None:
    if path is None or not Path(path).exists():
        return None
    try:
        state = json.loads(Path(path).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"state file {path}: not valid JSON ({exc})") from None
    if not isinstance(state, dict):
        raise ValueError(f"state file {path}: expected a JSON object (a saved pipeline state), "
                         f"got {type(state).__name__}")
    return state


def _check_state_components(state: dict[str, Any], config: Config, path: str | Path) -> None:
    """ValueError unless the state holds exactly the config's components: a component the
    config lacks would have its damage dropped from the saved state, a new one would count
    only the later parts."""
    saved = sorted(state.get("components") or {})
    wanted = sorted(c.name for c in config.components)
    if saved != wanted:
        raise ValueError(f"state file {path} holds components {saved}, the config {wanted}: "
                         "continue with the configuration that wrote it")


def save_state(path: str | Path, state: dict[str, Any]) -> None:
    atomic_write_text(path, json.dumps(state, allow_nan=True, separators=(",", ":")))


class Progress:
    """A one-line progress bar on a terminal (stderr); silent otherwise."""

    def __init__(self, stream: TextIO, span_ns: int | None, enabled: bool,
                 t0_ns: int | None = None) -> None:
        self.stream, self.span_ns, self.enabled = stream, span_ns, enabled
        self.start_wall = time.monotonic()
        # the log's first time (else the first update's): a coalesced block's last time is
        # up to half an hour in, and the bar ended short of 100% by that much
        self.t0: int | None = t0_ns
        self._last = 0.0

    def update(self, t_ns: int, samples: int, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self._last < 0.2:
            return
        self._last = now
        self.t0 = t_ns if self.t0 is None else self.t0
        rate = samples / max(now - self.start_wall, 1e-9)
        done_s = (t_ns - self.t0) / 1e9
        if self.span_ns:
            frac = min(max((t_ns - self.t0) / self.span_ns, 0.0), 1.0)
            bar = "#" * int(frac * 30)
            text = f"\r[{bar:30s}] {frac:6.1%} {done_s / 3600:8.1f} h  {rate / 1e6:6.2f} M samples/s"
        else:
            text = f"\r{done_s / 3600:8.1f} h of data  {rate / 1e6:6.2f} M samples/s"
        self.stream.write(text)
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


@dataclass
class ReplayResult:
    report: dict[str, Any]
    blocks: int
    samples: int
    wall_s: float
    ignored_blocks: dict[str, int] = field(default_factory=dict)


def _pace(block: SampleBlock, speed: float, origin: list[float]) -> None:
    """Sleep so sensor time advances ``speed`` times faster than wall-clock time."""
    t_ns = pace_ns(block.t_first_ns, block.recv_ns)
    if not origin:
        origin.extend((t_ns, time.monotonic()))
        return
    due = origin[1] + (t_ns - origin[0]) / 1e9 / speed
    delay = due - time.monotonic()
    if delay > 0:
        time.sleep(delay)


def replay_pipeline(config: Config, sinks: Sequence[Sink] = (), state: dict | None = None,
                    warm: bool = True) -> Pipeline:
    """A pipeline set up for logs: every stream gates, with the replay horizon; ``warm``:
    its kernels loaded now (else on their first call, or as its user chooses)."""
    return Pipeline(config, sinks, state, horizon_s=config.ordering.replay_horizon_s,
                    gate_all=True, warm=warm)


def run_blocks(config: Config, blocks: Iterable[SampleBlock], *, state: dict | None = None,
               sinks: Sequence[Sink] = (), speed: float | None = None,
               progress: Progress | None = None,
               forecasts: Sequence[tuple[str, Any, int]] = (),
               threads: bool = False, child: bool = False) -> tuple[Pipeline, ReplayResult]:
    """Feed blocks into a pipeline and flush it at the end. The pipeline is built at the first
    block, whose buoy id replaces the config's (with a warning); a continued state keeps its
    own buoy id, and a ValueError says so if the first block is of another buoy. Later blocks
    of other buoys are counted and skipped. ``forecasts`` (buoy id, JSON, due time ns), as
    recorded by the daemon (:mod:`replay.forecast_log`), are given to the pipeline before
    the blocks: each is applied at its due tick, as it was live. Unless paced (``speed``):
    ``child``: the blocks are read and the pipeline's stream stage runs in a forked child
    process, its tick stage here (:mod:`replay.stage_process`; the same bits; a reader's
    ``stats`` are brought back; until the end this pipeline's stream-stage objects, which
    only its status, report and state read, are those it started with); ``threads``: the
    stream stage runs on a second thread (:mod:`replay.stages`; the same bits), which does
    not shorten the wall time, the two stages' Python holding the GIL most of the time
    (figures in bench/bench_threads.py)."""
    start = time.perf_counter()
    # a continued state keeps its buoy (it took the log's buoy id when it was first saved)
    state_buoy = state.get("buoy_id") if state is not None else None
    if isinstance(state_buoy, str) and state_buoy != config.buoy.id:
        config = config_with(config, buoy={**config.section("buoy"), "id": state_buoy})
    if child and speed is None:
        return _run_with_child(config, blocks, state, sinks, progress, forecasts, start)
    n_blocks = n_samples = 0
    ignored: dict[str, int] = {}
    source = iter(blocks)
    first = next(source, None)
    if first is not None:
        config = _log_config(config, state, first.buoy_id)
    pipeline = replay_pipeline(config, sinks, state)
    if first is None:  # an empty log
        pipeline.flush()
        return pipeline, ReplayResult({}, 0, 0, time.perf_counter() - start, ignored)
    _add_forecasts(pipeline, forecasts)

    own = of_buoy(itertools.chain([first], source), pipeline.buoy_id, ignored)
    if threads and speed is None:
        for intake in ingest_ahead(pipeline, own):
            pipeline.advance_unread(intake)
            if intake.block is not None:
                n_blocks += 1
                # the block as read: its time_ahead samples (dropped from intake.block) too
                n_samples += len(intake.block) + intake.rejected["time_ahead"]
                if progress is not None:
                    progress.update(intake.block.t_last_ns, n_samples)
    else:
        origin: list[float] = []
        # unpaced and with no sink to see the steps: one slab per stretch, or per run of
        # stretches (replay.spans)
        for run in spans(own, speed is None and not sinks, pipeline.reorder.horizon_ns,
                         after_ns=pipeline.reorder.newest_ns):
            if speed is not None:
                _pace(run[0], speed, origin)
            pipeline.advance_unread(pipeline.ingest(*run))
            n_blocks += len(run)
            n_samples += sum(len(b) for b in run)
            if progress is not None:
                progress.update(run[-1].t_last_ns, n_samples)
        pipeline.flush()
    _close_progress(progress, pipeline, n_samples)
    result = ReplayResult({}, n_blocks, n_samples, time.perf_counter() - start, ignored)
    return pipeline, result


def _log_config(config: Config, state: dict | None, buoy_id: str, warn: bool = True) -> Config:
    """The config for a log whose first block is of ``buoy_id`` (see :func:`run_blocks`)."""
    if buoy_id != config.buoy.id and state is not None:
        raise ValueError(f"the state is for buoy {config.buoy.id!r}, the log for "
                         f"buoy {buoy_id!r}")
    if buoy_id != config.buoy.id:
        if warn:
            log.warning("log is for buoy %r, config for %r: replaying as %r",
                        buoy_id, config.buoy.id, buoy_id)
        config = config_with(config, buoy={**config.section("buoy"), "id": buoy_id})
    return config


def _close_progress(progress: Progress | None, pipeline: Pipeline, n_samples: int) -> None:
    if progress is not None and n_samples:
        end = pipeline.last["now_ns"]
        if progress.span_ns and progress.t0 is not None:  # all read: the log's last time,
            end = max(end, progress.t0 + progress.span_ns)  # a stream's later than the ticks'
        progress.update(end, n_samples, force=True)
        progress.close()


def _run_with_child(config: Config, blocks: Iterable[SampleBlock], state: dict | None,
                    sinks: Sequence[Sink], progress: Progress | None,
                    forecasts: Sequence[tuple[str, Any, int]], start: float
                    ) -> tuple[Pipeline, ReplayResult]:
    """:func:`run_blocks` with the reading and the stream stage in a child process."""
    from replay.stage_process import WantsQc, intake_of, run_in_child, take_stream_state

    wants_qc = any(getattr(s, "wants_qc", False) for s in sinks)

    def child_pipeline(buoy_id: str) -> Pipeline:  # called in the child (no sink is called)
        return replay_pipeline(_log_config(config, state, buoy_id, warn=False),
                               [WantsQc(wants_qc)], state, warm=False)

    # before the fork: numba and the stream stage's kernels, which the child needs first
    # (the stresses this process too); the tick stage's, this process loads after the fork
    # while the child reads and validates (~0.1 s off the replay's wall)
    child_pipeline(config.buoy.id).warm_up_stream()
    n_blocks = n_samples = 0
    messages = run_in_child(blocks, child_pipeline,
                            send_blocks=any(hasattr(s, "on_block") for s in sinks),
                            join_spans=not sinks)
    with contextlib.closing(messages):
        _, buoy_id = next(messages)
        if buoy_id is not None:
            config = _log_config(config, state, buoy_id)
        pipeline = replay_pipeline(config, sinks, state, warm=False)
        pipeline.warm_up_ticks()
        if buoy_id is not None:
            _add_forecasts(pipeline, forecasts)
        for kind, message in messages:
            if kind == "end":
                stream_state, ignored, stats = message
                break
            fields, done = message
            pipeline.advance_unread(intake_of(fields, pipeline))
            # no reference of our own left: the slab's shared memory goes back to the child
            del message, fields
            if done is not None:
                n_blocks += done[0]
                n_samples += done[1]
                if progress is not None:
                    progress.update(done[2], n_samples)
    if stream_state is None:  # an empty log
        pipeline.flush()
    else:
        take_stream_state(pipeline, stream_state)
    if stats is not None:
        blocks.stats[:] = stats  # type: ignore[attr-defined]
    _close_progress(progress, pipeline, n_samples)
    result = ReplayResult({}, n_blocks, n_samples, time.perf_counter() - start, ignored)
    return pipeline, result


def _add_forecasts(pipeline: Pipeline, forecasts: Sequence[tuple[str, Any, int]]) -> None:
    refused = 0
    for buoy, doc, due_ns in forecasts:
        if buoy != pipeline.buoy_id or pipeline.forecasts is None:
            continue
        try:
            pipeline.add_forecast(doc, due_ns)
        except ValueError:  # the daemon refused it too: it was never recorded as accepted
            refused += 1
    if refused:
        log.warning("%d recorded forecast(s) refused", refused)


def read_summary(stats: Sequence[Any]) -> dict[str, Any]:
    """Totals over the reader's per-file statistics, plus the per-file details."""
    files = [st.as_dict() for st in stats]
    lost = [r for st in stats for r in st.lost]
    return {
        "messages": sum(st.messages for st in stats),
        "samples": sum(st.samples for st in stats),
        "late": sum(st.late for st in stats),
        "bad_chunks": sum(st.bad_chunks for st in stats),
        "bad_payloads": sum(st.bad_payloads for st in stats),
        "lost_ranges": len(lost),
        "lost_messages_known": sum(r.messages or 0 for r in lost),
        "incomplete_files": [st.path for st in stats if not st.complete],
        "unreadable_files": [st.path for st in stats if st.error],
        "files": files,
    }


def use_child(files: Sequence[Path], speed: float | None = None,
              two_processes: bool | None = None, meanwhile: Any = None) -> bool:
    """Whether to replay ``files`` with the reading and stream stage in a child process
    (:mod:`replay.stage_process`): by default (``two_processes`` None) when
    :func:`replay.stage_process.one_process_reason` finds nothing against it and the
    replay is not paced; never when False; when True, the same, saying why not (the
    operator asked). ``meanwhile``: work to run while it measures the idle CPUs (if it
    does)."""
    from replay.stage_process import one_process_reason

    if two_processes is False:
        return False
    reason = "a paced replay" if speed is not None else one_process_reason(files, meanwhile)
    if reason is not None and two_processes:
        log.warning("two processes not used, one process replays: %s", reason)
    return reason is None


def replay_reader(files: Sequence[Path], speed: float | None, child: bool,
                  max_ahead_s: float = DEFAULT_MAX_AHEAD_S) -> Any:
    """The reader of a replay: coalesced blocks unless paced (which keeps the recorded 1-s
    blocks); with a child process, reading on its one thread (a read-ahead thread there
    waits for the GIL: bench/bench_threads.py), else ahead by the reader's rule
    (replay.chunks.read_ahead_pays: only with a CPU to spare); a message more than
    ``max_ahead_s`` ahead of its log time ordered by its log time (``[ordering]``)."""
    from replay.reader import LogReader

    return LogReader(files, coalesce=speed is None, read_ahead=False if child else None,
                     max_ahead_s=max_ahead_s)


def replay_logs(config: Config, paths: Sequence[str | Path], *, state_path: str | Path | None = None,
                sinks: Sequence[Sink] = (), speed: float | None = None,
                show_progress: bool | None = None, plot_fields: bool = False,
                plain: bool | None = None, two_processes: bool | None = None) -> ReplayResult:
    """Replay MCAP logs (files or directories) through the pipeline; return the report.

    ``plot_fields`` adds the report's optional plot fields (docs/REPORT_FORMAT.md: tension and
    damage histories, rainflow histograms, S-N curves) for ``buoymon report`` / ``--html``.
    ``plain``: run every kernel as plain Python (True) or compiled (False); by default as
    plain Python when the logs inflate to at most :data:`PLAIN_PYTHON_BYTES` (same bits).
    ``two_processes``: read the logs and run the stream stage in a child process (same
    bits): by default when :func:`use_child` finds it pays (logs of about a day or more,
    two idle CPUs: the 30-day benchmark log in ~5 s against ~7.5 s in one process,
    bench/bench_threads.py); False: one process; True: two when they can, and a warning
    saying why not.
    """
    from monitor.viz.report_history import ReportHistory
    from replay.forecast_log import read_forecasts
    from replay.log_files import time_span
    from replay.report import add_plot_fields

    files = collect_logs(paths)
    keep_freed_memory()
    if plain is None:
        plain = plain_python_pays(files)
    with uncompiled() if plain else contextlib.nullcontext():
        state = load_state(state_path)
        if state is not None:
            _check_state_components(state, config, state_path)
        if show_progress is None:
            show_progress = sys.stderr.isatty()
        span = time_span(files) if show_progress else None
        progress = Progress(sys.stderr, span[1] - span[0] if span else None, show_progress,
                            span[0] if span else None)
        # the stream stage's kernels (which either way are loaded first) while the idle
        # CPUs are measured: 0.05 s less of sleeping before the replay starts
        child = use_child(files, speed, two_processes,
                          meanwhile=lambda: replay_pipeline(config, warm=False).warm_up_stream())
        # paced replay keeps the recorded 1-s blocks; as fast as possible, coalesced blocks
        source = replay_reader(files, speed, child, config.ordering.max_ahead_s)
        history = ReportHistory() if plot_fields else None
        all_sinks = [*sinks, history] if history is not None else list(sinks)
        pipeline, result = run_blocks(config, source, state=state, sinks=all_sinks, speed=speed,
                                      progress=progress, forecasts=read_forecasts(files),
                                      child=child)
        result.report = build_report(pipeline.config, pipeline.report(), [str(f) for f in files],
                                     read_summary(source.stats))
        if history is not None:
            # rerun-sdk comes with it: 0.44 s of a 1.4 s replay of a tiny log that plots nothing
            from monitor.viz.pipeline_sinks import report_plot_fields

            add_plot_fields(result.report, report_plot_fields(history, pipeline.components))
        if result.ignored_blocks:
            result.report["inputs"]["ignored_blocks_of_other_buoys"] = result.ignored_blocks
        if state_path is not None:
            save_state(state_path, pipeline.state())
        pipeline.close()
        return result
