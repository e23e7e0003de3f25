"""The live daemon behind ``buoymon run``: Zenoh in, pipeline core, status out, checkpoints.

One thread does all the work; zenoh callbacks only enqueue (see :mod:`monitor.zenoh_io`).
Each loop turn: take what arrived -> decode -> record -> ``pipeline.process`` -> publish
status (after new data, and at least every ``status_interval_s``) -> checkpoint when due ->
``WATCHDOG=1``. Queries on ``buoy/<id>/monitor/state`` are answered from the same thread, so
they always see a consistent state.

Crash safety: the checkpoint holds the pipeline's state (damage, residue, per-stream last
sample times, alert states) plus the daemon's counters and, per stream, the sequence number of
the last message of each sensor publisher taken in (:mod:`monitor.sequence`), written
atomically. After a crash the daemon restarts from it and asks the publishers' caches for what
they hold (Zenoh's advanced subscriber): messages at or before the checkpoint are recognised
by their numbers and skipped (``redelivered``), the rest are processed once, and a gap in the
numbers (the cache no longer had them) is counted as ``samples_missed`` and alerted on.

Shutdown (``stop()``, e.g. from SIGTERM/SIGINT): ``STOPPING=1``, stop intake, process what is
already queued, publish a last status, checkpoint, close the recorder and the session.
"""

from __future__ import annotations

import heapq
import json
import logging
import math
import queue
import sqlite3
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Protocol, Sequence

from monitor.alerts.live import LiveAlerts, LiveConfig
from monitor.blocks import SampleBlock, parse_sensor_topic
from monitor.checkpoint import CheckpointStore, PeriodicCheckpointer
from monitor.clock_faults import ClockFaults
from monitor.daemon_config import DaemonConfig
from monitor.events import Sink, StepResult
from monitor.forecast import ForecastExpired
from monitor.listening import IntakeQueue, ListeningClock
from monitor.memory import release_compiler_pages
from monitor.recorder import JSON_OBJECT, McapRecorder
from monitor.sdnotify import SdNotifier
from monitor.time_ahead import DEFAULT_MAX_AHEAD_S, is_ahead
from monitor.sequence import SequenceTracker
from monitor import zenoh_io

log = logging.getLogger("buoymon.daemon")

# status is re-published after new data at most this often (bounds the cost of bursts)
_MIN_STATUS_GAP_S = 0.02
_IDLE_WAIT_S = 0.2
_MAX_TURN_S = 0.25  # longest stretch of queued work between periodic duties
_RELEASE_EVERY_S = 600.0  # hand back the JIT compiler's pages (monitor.memory) this often
_RECOVERY_TIMEOUT_S = 5.0  # longest wait for a publisher's cache to give back missed messages
# at start: how long the sensor publishers found must stay the same before their backlogs are
# taken (liveliness tokens of one bridge arrived within 0.42 s of each other, seen)
_SETTLE_S = 0.5
_RECONNECT_WAIT_S = 3.0  # at start: how long the checkpoint's sensor publishers may take to return
_LOG_EVERY_S = 60.0  # a repeating fault (clock, checkpoint) is logged at most this often


class PipelineLike(Protocol):
    """What the daemon needs of ``monitor.pipeline.Pipeline``."""

    def process(self, block: SampleBlock) -> StepResult: ...

    def state(self) -> Any: ...

    def status(self) -> Mapping[str, Any]: ...


# make_pipeline(restored_state_or_None, sinks) -> pipeline
PipelineFactory = Callable[[Any, Sequence[Sink]], PipelineLike]


class Extension(Protocol):
    """Something attached to the daemon's session and pipeline (e.g. alert delivery)."""

    def poll(self) -> None:
        """Called on the daemon's thread every loop turn (between blocks): never blocks."""

    def close(self) -> None: ...

    # optional: ``status_fields(self) -> Mapping[str, Any]``, merged into the top level of the
    # status document (e.g. ``{"delivery": {...}}``); ``finish_input(self)``, called at
    # shutdown before the daemon stops intake (an input inside the daemon sends its last data)


# attach(session, pipeline) -> extensions; an extension delivering alerts lists its channels
# (objects with ``on_step`` and ``publish(records)``) in ``alert_channels``
Attach = Callable[[Any, PipelineLike], Sequence[Extension]]


class _AlertChannels:
    """The pipeline's alert sink, fixed when the pipeline is built: hands the alert
    transitions of each step, and the live rules' (:meth:`publish`), to the delivery channels
    the extensions open once the Zenoh session is up."""

    def __init__(self) -> None:
        self.channels: list[Any] = []

    def on_step(self, step: StepResult) -> None:
        for channel in self.channels:
            channel.on_step(step)

    def publish(self, records: list[Any]) -> None:
        for channel in self.channels:
            try:
                channel.publish(records)
            except Exception as exc:  # noqa: BLE001 (one channel must not stop the others)
                log.error("live alert delivery failed", extra={"fields": {
                    "sink": type(channel).__name__, "error": repr(exc)}})

    def close(self) -> None:
        """The channels are closed by the extensions that opened them."""


class _RecordAlertsSink:
    """Records the alert transitions the pipeline emits, as JSON on their Zenoh keys."""

    def __init__(self, recorder: McapRecorder) -> None:
        self.recorder = recorder

    def on_step(self, step: StepResult) -> None:
        for rec in step.alerts:  # publish time: the record's sensor time, as the status's
            self.recorder.write(rec.key, zenoh_io.to_json_bytes(rec.to_dict()), JSON_OBJECT,
                                time.time_ns(), rec.at_ns)

    def close(self) -> None:
        pass


_RATE_WINDOW_S = 10.0  # the status's per-stream rate: samples received over this window


@dataclass
class StreamHealth:
    """Wall-clock view of one sensor stream: data age, rate and liveliness (not in the
    checkpoint). The age is in listening time (:mod:`monitor.listening`) of delivery; the
    rate in monotonic time (a stall's backlog, delivered after it, is no faster stream)."""

    last_arrival: float | None = None
    alive: bool | None = None  # None: no liveliness token seen either way
    arrivals: "deque[tuple[float, int]]" = field(default_factory=deque)  # (monotonic, samples)

    def arrived(self, at: float, at_mono: float, n_samples: int) -> None:
        self.last_arrival = at if self.last_arrival is None else max(at, self.last_arrival)
        self.arrivals.append((at_mono, n_samples))
        while self.arrivals[0][0] < at_mono - _RATE_WINDOW_S:
            self.arrivals.popleft()

    def to_dict(self, now: float, now_mono: float, timeout_s: float) -> dict[str, Any]:
        age = None if self.last_arrival is None else max(0.0, now - self.last_arrival)
        recent = sum(n for t, n in self.arrivals if t >= now_mono - _RATE_WINDOW_S)
        return {"data_age_s": age, "data_age_timeout_s": timeout_s,
                "data_stale": age is None or age > timeout_s, "alive": self.alive,
                "rate_hz": recent / _RATE_WINDOW_S}


@dataclass
class CheckpointHealth:
    """How checkpointing goes: the last good save (wall clock) and failures in this life,
    and per stream the minutes of late copies the restored checkpoint held but could not give
    back (missing or damaged: :attr:`monitor.late_copies.LateCopies.lost`)."""

    seq: int
    saved_ns: int | None
    failures: int = 0
    failing: bool = False
    last_error: str | None = None
    late_copies_lost: Mapping[str, int] = field(default_factory=dict)

    def to_dict(self, wall_ns: int) -> dict[str, Any]:
        age = None if self.saved_ns is None else (wall_ns - self.saved_ns) / 1e9
        return {"seq": self.seq, "age_s": age, "failures": self.failures,
                "failing": self.failing, "last_error": self.last_error,
                "late_copies_lost_minutes": dict(self.late_copies_lost)}


class _RateLimitedLog:
    """Logs a repeating warning at most every ``_LOG_EVERY_S`` per subject, with the count of
    the ones left out since, so a fault on every block neither floods nor goes quiet."""

    def __init__(self) -> None:
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}

    def warning(self, subject: str, message: str, **fields: Any) -> None:
        now = time.monotonic()
        if now - self._last.get(subject, -_LOG_EVERY_S) < _LOG_EVERY_S:
            self._held[subject] = self._held.get(subject, 0) + 1
            return
        self._last[subject] = now
        log.warning(message, extra={"fields": {**fields, "not_logged_since_last":
                                               self._held.pop(subject, 0)}})


class _Closing:
    """Adapts an extension to the undeclare-on-exit list."""

    def __init__(self, ext: Extension) -> None:
        self.ext = ext

    def undeclare(self) -> None:
        self.ext.close()


class Daemon:
    """Runs one buoy's live monitoring until :meth:`stop` is called."""

    def __init__(self, buoy_id: str, config: DaemonConfig, make_pipeline: PipelineFactory,
                 codec: zenoh_io.BlockCodec, notifier: SdNotifier | None = None,
                 attach: Attach | None = None,
                 max_ahead_s: float = DEFAULT_MAX_AHEAD_S) -> None:
        self.buoy_id = buoy_id
        self.config = config
        self.codec = codec
        self.notifier = notifier or SdNotifier()
        self._stop = threading.Event()
        self._q = IntakeQueue()
        self._store = CheckpointStore(config.state.path)
        restored = self._store.load()
        saved = restored.state if restored is not None else {}
        self.counters: dict[str, int] = {"messages": 0, "undecodable": 0, "wrong_buoy": 0,
                                         "refused": 0, "status_published": 0, "queries": 0,
                                         "forecasts": 0, "forecasts_refused": 0,
                                         "forecasts_expired": 0}
        self.counters.update(saved.get("daemon", {}).get("counters", {}))
        self.streams: dict[str, StreamHealth] = {}
        # wall-clock ages (data, accepted samples, fatigue feed) in listening time: a stall of
        # the whole process (SIGSTOP, a GC pause) is no silence of the sensors
        self.listening = ListeningClock()
        # ages across a restart: the last arrivals and fatigue feed, saved as wall-clock times,
        # in this life's frame (a stream silent since before the crash stays late)
        saved_daemon = saved.get("daemon", {})
        now_listen, now_wall = self.listening.now(), time.time_ns()

        def listen_of(wall_ns: int) -> float:
            return now_listen - max(0, now_wall - int(wall_ns)) / 1e9

        for name, wall_ns in saved_daemon.get("arrivals", {}).items():
            self.streams[name] = StreamHealth(last_arrival=listen_of(wall_ns))
        self.sequences = SequenceTracker(saved.get("daemon", {}).get("sequences"))
        # per (stream, publisher): the last sequence number written to the recording, and the
        # one the recording held at its last flush (kept in the checkpoint): a redelivered
        # message beyond it may have been lost with an unflushed chunk, so it is recorded again
        self._recorded: dict[str, dict[str, int]] = {}
        self._flushed: dict[str, dict[str, int]] = {
            s: dict(d) for s, d in saved.get("daemon", {}).get("recorded", {}).items()}
        self._flushes_seen = 0
        self._first_catch_up = True
        # with publishers in the checkpoint, the live rules wait for the first catch-up (or
        # for as long as it may take to come): judged before it, every stream is as old as
        # the daemon's downtime, and a restart beside a bridge whose cache holds it all sent
        # data_age fire + clear to Alertmanager
        self._live_from_mono = math.inf
        self.restored_seq = restored.seq if restored is not None else 0
        hc = config.health
        # the pipeline's [ordering] max_ahead_s: a block it rejects as time_ahead is no restart
        self.clocks = ClockFaults(hc.clock_skew_max_s, hc.time_restart_min_s, max_ahead_s)
        self.live = LiveAlerts(buoy_id, LiveConfig(
            hc.live_rules, hc.required_streams, hc.fatigue_blind_timeout_s,
            hc.clock_skew_max_s, hc.hold_s, hc.delivery_stall_s),
            saved.get("daemon", {}).get("live"))
        self._faults = _RateLimitedLog()
        # checkpoint health: wall time of the last good save, failures in this life
        self._ckpt = CheckpointHealth(self.restored_seq,
                                      restored.saved_ns if restored is not None else None)
        self._last_doc: dict[str, Any] | None = None  # the last status built (read by /metrics)
        self._last_live_mono = 0.0
        # the pipeline's newest load time, and when it last moved
        fed = saved_daemon.get("fatigue_fed")
        self._load_t_ns: Any = fed[0] if fed else None
        self._load_listen = listen_of(fed[1]) if fed else now_listen
        # stream -> (accepted, rejected, duplicates among them, when accepted last moved)
        self._accepted: dict[str, tuple[int, int, int, float]] = {}
        self.metrics = None
        if config.metrics.enabled:  # bound now: a port in use fails before anything starts
            from monitor.metrics import MetricsServer  # noqa: PLC0415 (only when enabled)

            self.metrics = MetricsServer(config.metrics.listen, config.metrics.port,
                                         lambda: self._last_doc)
        self.recorder = (McapRecorder(config.record.dir, config.record.rotate_s,
                                      config.record.flush_interval_s)
                         if config.record.enabled else None)
        self._alert_channels = _AlertChannels()
        sinks: list[Sink] = [_RecordAlertsSink(self.recorder)] if self.recorder is not None else []
        sinks.append(self._alert_channels)
        self.pipeline = make_pipeline(saved.get("pipeline"), sinks)
        self._ckpt.late_copies_lost = getattr(getattr(self.pipeline, "late_copies", None),
                                              "lost", {})
        self._attach = attach
        self._extensions: Sequence[Extension] = ()
        self._checkpointer = PeriodicCheckpointer(self._store, self.checkpoint_state,
                                                  config.state.checkpoint_interval_s)
        self.session: Any = None
        self._status_pub: Any = None
        self._started_mono = time.monotonic()
        self._last_status_mono = 0.0
        self._next_release_mono = 0.0
        self._dirty_status = False
        self._last_watchdog = 0.0
        # the newest samples' delivery in this life, or its start: a silence from the start
        # releases the horizon a restored ordering holds (_silence) as any other silence
        self._last_data_mono = self._started_mono

    # ---- lifecycle -------------------------------------------------------------------------

    def stop(self) -> None:
        """Ask the loop to drain, checkpoint and close (safe from signal handlers/threads)."""
        self._stop.set()

    def run(self) -> None:
        """Serve until :meth:`stop`; always checkpoints and closes on the way out."""
        zc = self.config.zenoh
        self.session = zenoh_io.open_session(zc)
        self.listening.start()
        declared: list[Any] = []
        try:
            declared.append(zenoh_io.declare_liveliness_watch(
                self.session, zenoh_io.sensor_key(self.buoy_id), self._q))
            declared.append(zenoh_io.declare_deferred_queryable(
                self.session, zenoh_io.state_key(self.buoy_id), self._q))
            declared.append(zenoh_io.declare_deferred_queryable(
                self.session, zenoh_io.status_key(self.buoy_id), self._q))
            self._status_pub = zenoh_io.declare_json_publisher(
                self.session, zenoh_io.status_key(self.buoy_id))
            declared.append(self._status_pub)
            declared.append(self.session.liveliness().declare_token(
                zenoh_io.monitor_token_key(self.buoy_id)))
            if self._attach is not None:
                self._extensions = self._attach(self.session, self.pipeline)
                for ext in self._extensions:
                    self._alert_channels.channels.extend(getattr(ext, "alert_channels", ()))
                declared.extend(_Closing(e) for e in self._extensions)
            declared.append(zenoh_io.declare_forecast_subscriber(
                self.session, self.buoy_id, self._q))
            subscriber = zenoh_io.declare_enqueuing_subscriber(
                self.session, zenoh_io.sensor_key(self.buoy_id), self._q)
            declared.append(zenoh_io.declare_publisher_watch(self.session, self.buoy_id,
                                                             self._q))
            log.info("daemon ready", extra={"fields": {
                "buoy_id": self.buoy_id, "listen": list(zc.listen), "connect": list(zc.connect),
                "restored_checkpoint": self.restored_seq,
                "metrics": None if self.metrics is None
                else f"http://{self.config.metrics.listen}:{self.metrics.port}/metrics"}})
            if self.metrics is not None:
                self.metrics.start()
            self.notifier.ready(f"monitoring buoy {self.buoy_id}")
            self._live_from_mono = time.monotonic() + (
                _RECONNECT_WAIT_S + _RECOVERY_TIMEOUT_S if self.sequences.latest_sources()
                else 0.0)
            self._serve()
            self.notifier.stopping()
            for ext in self._extensions:
                finish = getattr(ext, "finish_input", None)
                if finish is not None:
                    finish()
            self._drain()
            # what the sensor publishers sent but is still on its way (a bridge inside the
            # daemon flushing its last block): take it from their caches, by number (no
            # waiting for publishers that are not there)
            self._first_catch_up = False
            self._catch_up()
            subscriber.undeclare()  # stop intake, then finish what already arrived
            self._drain()
            self._publish_status()
            self._checkpoint(self._checkpointer.save_now)
            log.info("daemon stopped", extra={"fields": {"counters": dict(self.counters)}})
        finally:
            for obj in reversed(declared):
                try:
                    obj.undeclare()
                except Exception:  # already gone with a closing session: nothing to undo
                    pass
            if self.recorder is not None:
                self.recorder.close()
            if self.metrics is not None:
                self.metrics.close()
            self._store.close()
            self.session.close()
            self.listening.close()

    def _serve(self) -> None:
        zc = self.config.zenoh
        while not self._stop.is_set():
            next_status = self._last_status_mono + (
                _MIN_STATUS_GAP_S if self._dirty_status else zc.status_interval_s)
            wait = min(_IDLE_WAIT_S, max(0.0, self._checkpointer.due_in()),
                       max(0.0, next_status - time.monotonic()))
            try:
                item = self._q.get(timeout=wait)
            except queue.Empty:
                item = None
            if item is not None:
                self._handle(item)
                # a backlog is worked off in slices so status, checkpoints and the watchdog
                # keep their pace
                self._drain(time.monotonic() + _MAX_TURN_S)
            self._duties()

    def _duties(self) -> None:
        """Silence, status, extensions, checkpoint, recorder flush, compiler pages, watchdog:
        each when due (called between slices of work, never inside a block)."""
        zc = self.config.zenoh
        self._silence()  # before the status, which then shows what it released
        now = time.monotonic()
        if (now - self._last_status_mono >= zc.status_interval_s
                or (self._dirty_status and now - self._last_status_mono >= _MIN_STATUS_GAP_S)):
            self._publish_status()
        for ext in self._extensions:
            ext.poll()
        self._checkpoint(self._checkpointer.maybe_save)
        if self.recorder is not None:
            self.recorder.maybe_flush()
            self._note_flush()
        if now >= self._next_release_mono:  # at once, then now and then: a steady daemon
            release_compiler_pages()        # never runs the compiler (monitor.memory)
            self._next_release_mono = now + _RELEASE_EVERY_S
        self._pet_watchdog(now)

    def _silence(self) -> None:
        """Tell the pipeline how long no samples have arrived (monotonic time, as of the
        oldest message still waiting): past the ordering horizon it stops waiting for load
        streams never seen or dead (monitor.ordering), so the last horizon of sensor time,
        and its ticks' alerts, go out now, not with the next data. Not in listening time: a
        loaded machine's late beats, left out as stalls, would hold the release back, and a
        real stall taken for silence costs at most the grace of a stream not seen (or dead)."""
        silence = getattr(self.pipeline, "silence", None)
        if silence is None:
            return
        waiting = self._q.oldest_put()
        now = time.monotonic() if waiting is None else waiting
        if silence(now - self._last_data_mono) is not None:
            self._dirty_status = True

    def _checkpoint(self, save: Callable[[], Any]) -> None:
        """Save via ``save``; a failure (disk full, database gone) is counted, logged, shown
        in the status and alerted on (``checkpoint_failed``), and the daemon keeps serving."""
        ck = self._ckpt
        try:
            if not save():
                return
        except (sqlite3.Error, OSError, ValueError) as exc:
            ck.failures += 1
            ck.failing, ck.last_error = True, repr(exc)[:300]
            self._faults.warning("checkpoint", "checkpoint failed; damage since the last good "
                                 "one would be lost in a crash", error=repr(exc),
                                 failures=ck.failures)
            return
        ck.seq += 1
        ck.saved_ns, ck.failing = time.time_ns(), False

    def _pet_watchdog(self, now: float) -> None:
        interval = self.notifier.watchdog_interval_s
        if interval is not None and now - self._last_watchdog >= interval / 2:
            self.notifier.watchdog()
            self._last_watchdog = now

    def _drain(self, until_mono: float = float("inf")) -> None:
        """Handle queued items until the queue is empty or ``until_mono`` has passed."""
        while time.monotonic() < until_mono:
            try:
                item = self._q.get_nowait()
            except queue.Empty:
                return
            self._handle(item)

    # ---- input -----------------------------------------------------------------------------

    def _handle(self, item: tuple) -> None:
        kind = item[0]
        if kind == "data":
            self._on_data(item[1], item[2], item[3], item[4], item[5])
        elif kind == "forecast":
            self._on_forecast(item[1], item[2], item[3])
        elif kind == "publisher":
            self._catch_up()
        elif kind == "alive":
            self._on_alive(item[1], item[2])
        elif kind == "query":
            self._on_query(item[1])

    def _stream(self, sensor: str) -> StreamHealth:
        return self.streams.setdefault(sensor, StreamHealth())

    def _on_data(self, key: str, payload: bytes, recv_ns: int,
                 origin: zenoh_io.Origin | None, recv_mono: float) -> None:
        block = self._decode(key, payload, recv_ns)
        if block is None:
            return
        if origin is not None and self.sequences.gap(block.sensor, origin.source,
                                                     origin.sn) is not None:
            self._catch_up()  # takes this message too, as long as its publisher's cache has it
        # timed at delivery (the Zenoh callback), not now: a backlog worked off late is no
        # older than when it came (status() judges ages as of the oldest still waiting);
        # on the monotonic clock, which a wall-clock step while it waited does not move
        self._take(key, payload, block, recv_ns, origin, recv_mono)

    def _decode(self, key: str, payload: bytes, recv_ns: int) -> SampleBlock | None:
        block = zenoh_io.decode_counted(self.codec, key, payload, recv_ns, self.counters, log,
                                        count_decoded=False)
        if block is not None and block.buoy_id != self.buoy_id:
            self.counters["messages"] += 1
            self.counters["wrong_buoy"] += 1
            return None
        return block

    def _catch_up(self) -> None:
        """Take what the sensor publishers' caches hold beyond the last message taken from
        each (everything, for a publisher not seen before): at start, when a publisher
        appears, and when a message's number shows a gap (live messages overtook what a
        restarting daemon missed). All publishers are asked at once and the messages taken in
        sensor-time order across streams, as a replay would see them (one stream's backlog
        taken alone would push the others' behind the ordering horizon)."""
        try:
            publishers = self._publishers_to_catch_up()
            caches = []
            for key, source in publishers:
                _, sensor = parse_sensor_topic(key)
                first = self.sequences.gap(sensor, source, None)[0]
                if self.recorder is not None:  # what the recording may have lost unflushed
                    first = min(first, self._flushed.get(sensor, {}).get(source, -1) + 1)
                caches.append((key, zenoh_io.fetch_cached(self.session, key, source,
                                                          (first, None), _RECOVERY_TIMEOUT_S)))
        except (zenoh_io.zenoh.ZError, ValueError) as exc:  # what is not fetched is counted
            self._faults.warning("catch-up", "could not ask the sensor publishers' caches; "
                                 "a gap will count as missed", error=repr(exc))
            return
        # taken in sensor-time order across publishers (one stream's backlog alone would
        # push the others' behind the ordering horizon), each publisher's in its own number
        # order: a block taken before one numbered earlier (a clock that went back) made that
        # one a "redelivery", dropped uncounted. A block far ahead of its publication (a
        # wrong clock) goes after its predecessor: by its time it was taken last, leaving
        # clock_skew active until the stream's next live block.
        streams = []
        for key, replies in caches:
            stream, at = [], 0
            for payload, origin in replies:
                block = self._decode(key, payload, time.time_ns())
                if block is not None:
                    if not is_ahead(block.t_last_ns, origin.sent_ns or block.recv_ns,
                                    self.clocks.max_ahead_ns):
                        at = block.t_last_ns
                    stream.append((at, block, key, payload, origin))
            streams.append(stream)
        taken: dict[str, int] = {}
        turn_ends = time.monotonic() + _MAX_TURN_S
        for _, block, key, payload, origin in heapq.merge(*streams, key=lambda f: f[0]):
            if time.monotonic() > turn_ends:  # an hour's backlog: keep status and watchdog going
                self._duties()
                turn_ends = time.monotonic() + _MAX_TURN_S
            if self._take(key, payload, block, block.recv_ns, origin):
                self.sequences.recovered_from_cache(block.sensor, 1)
                taken[block.sensor] = taken.get(block.sensor, 0) + 1
        log.info("caught up from the sensor publishers' caches", extra={"fields": {
            "publishers": [k for k, _ in publishers], "taken": taken}})

    def _publishers_to_catch_up(self) -> list[tuple[str, str]]:
        """The sensor publishers alive now. The first time in a daemon life, wait (up to
        ``_RECONNECT_WAIT_S``) for the publishers the checkpoint knows to reconnect: their
        backlogs must be taken together, in time order."""
        first = self._first_catch_up
        deadline = time.monotonic() + (_RECONNECT_WAIT_S if first else 0.0)
        self._first_catch_up = False
        expected = self.sequences.latest_sources()
        settled: tuple[list[tuple[str, str]], float] | None = None  # found, since when
        while True:
            found = zenoh_io.sensor_publishers(self.session, self.buoy_id, _RECOVERY_TIMEOUT_S)
            streams = {(parse_sensor_topic(k)[1], src) for k, src in found}
            now = time.monotonic()
            if settled is None or settled[0] != found:
                settled = (found, now)
            # a first start (no publisher in the checkpoint) also waits until discovery has
            # settled (the same publishers for _SETTLE_S): beside a running bridge it finds
            # the streams one by one, and a stream's backlog taken after another's had been
            # was all time_backwards (tension 182 of 23,743 samples accepted)
            fresh = first and not expected
            if (expected <= streams and (not fresh or now - settled[1] >= _SETTLE_S)) \
                    or now >= deadline:
                return found
            time.sleep(0.05)

    def _take(self, key: str, payload: bytes, block: SampleBlock, recv_ns: int,
              origin: zenoh_io.Origin | None, delivered_mono: float | None = None) -> bool:
        """Record and process one decoded message; False if it was a redelivery (skipped).
        ``delivered_mono``: when it arrived (None: now, as a catch-up's messages, fetched
        all at once from the caches and taken one by one)."""
        verdict = (self.sequences.observe(block.sensor, origin.source, origin.sn)
                   if origin is not None else None)
        if verdict is not None and verdict.missed:
            self._faults.warning(f"missed {block.sensor}", "sensor messages missed: the "
                                 "publisher's cache no longer held them", sensor=block.sensor,
                                 missed=verdict.missed, sn=origin.sn,
                                 **self.sequences.fields(block.sensor))
        redelivered = verdict is not None and verdict.redelivered
        self._record(key, payload, block, recv_ns, origin, redelivered)
        if redelivered:
            return False  # already in the restored state (taken before the checkpoint)
        self.counters["messages"] += 1
        at_mono = time.monotonic() if delivered_mono is None else delivered_mono
        self._stream(block.sensor).arrived(self.listening.at(at_mono), at_mono, len(block))
        if len(block):
            self._last_data_mono = max(at_mono, self._last_data_mono)
            # ahead of the block's receive time, as the pipeline judges time_ahead; behind its
            # publication (a message from a publisher's cache arrives late by design)
            sent_ns = origin.sent_ns if origin is not None and origin.sent_ns else None
            # the newest sample (a block need not be sorted): a corrupt time inside it shows
            for msg in self.clocks.observe(block.sensor, int(block.t_ns.max()), block.recv_ns,
                                           sent_ns):
                self._faults.warning(f"clock {block.sensor}", "sensor clock fault: " + msg,
                                     sensor=block.sensor, **self.clocks.fields(block.sensor))
        try:
            self.pipeline.process(block)
        except ValueError as exc:  # a block the pipeline refuses: count it, keep serving
            self.counters["refused"] += 1
            log.warning("block refused by the pipeline",
                        extra={"fields": {"key": key, "error": str(exc)}})
        self._dirty_status = True
        return True

    def _record(self, key: str, payload: bytes, block: SampleBlock, recv_ns: int,
                origin: zenoh_io.Origin | None, redelivered: bool) -> None:
        """Record a received sensor message; a redelivered one only if the recording may not
        hold it yet (numbered after what the recording held at its last flush, and not
        written in this life: a live message that a catch-up already took)."""
        rec = self.recorder
        if rec is None:
            return
        if origin is not None:
            if redelivered and origin.sn <= max(
                    self._flushed.get(block.sensor, {}).get(origin.source, -1),
                    self._recorded.get(block.sensor, {}).get(origin.source, -1)):
                return
            self._recorded.setdefault(block.sensor, {})[origin.source] = origin.sn
        rec.write(key, payload, self.codec.channel_spec(block.sensor), recv_ns,
                  block.t_first_ns)
        self._note_flush()

    def _note_flush(self) -> None:
        if self.recorder is not None and self.recorder.flushes != self._flushes_seen:
            self._flushes_seen = self.recorder.flushes
            for stream, d in self._recorded.items():
                self._flushed.setdefault(stream, {}).update(d)

    def _on_forecast(self, key: str, payload: bytes, recv_ns: int) -> None:
        """A sea-state forecast: recorded as received, handed to the pipeline (applied at
        sensor time, :mod:`monitor.forecast`); a malformed one is counted and logged, and one
        with no step left to project also as ``forecasts_expired``."""
        add = getattr(self.pipeline, "add_forecast", None)
        try:
            if add is None:
                raise ValueError("this pipeline takes no forecasts")
            due_ns = add(json.loads(payload))
        except (ValueError, RecursionError) as exc:  # JSON and UTF-8 errors are ValueErrors
            self.counters["forecasts_refused"] += 1
            expired = isinstance(exc, ForecastExpired)
            if expired:  # logged apart: not hidden behind the last malformed one's minute
                self.counters["forecasts_expired"] += 1
            self._faults.warning("forecast expired" if expired else "forecast",
                                 "forecast refused", key=key, error=str(exc)[:300])
            return
        self.counters["forecasts"] += 1
        self._dirty_status = True
        if self.recorder is not None:  # a replay applies it at the same tick (monitor.forecast)
            self.recorder.write(key, payload, JSON_OBJECT, recv_ns, due_ns)

    def _on_alive(self, key: str, alive: bool) -> None:
        try:
            _, sensor = parse_sensor_topic(key)
        except ValueError:
            return
        self._stream(sensor).alive = alive
        log.info("sensor liveliness", extra={"fields": {"sensor": sensor, "alive": alive}})

    def _on_query(self, query: Any) -> None:
        self.counters["queries"] += 1
        status = zenoh_io.status_key(self.buoy_id)
        with query:
            if str(query.key_expr) == status:  # `buoymon status`: the status document only
                query.reply(status, zenoh_io.to_json_bytes(self._last_doc or self.status()),
                            encoding="application/json")
            else:
                query.reply(zenoh_io.state_key(self.buoy_id),
                            zenoh_io.to_json_bytes(self.full_state()),
                            encoding="application/json")

    # ---- output ----------------------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        """The status document published on ``buoy/<id>/monitor/status`` (docs/DAEMON.md).

        The pipeline's figures (sensor time, load source, latest measured and estimated
        tension, per-component damage, damage rate and remaining life, per-stream accepted
        and rejected counts and sensor-time staleness) with, per stream, the daemon's
        wall-clock data age, liveliness and clock faults; the daemon's counters, checkpoint
        health and fatigue-feed age; the extensions' fields (``status_fields``); the active
        alerts (sensor-time and live rules) and the health verdict of the live rules.
        """
        now = time.monotonic()
        # the ages (data, accepted samples, fatigue feed) in listening time, as of the oldest
        # message still waiting: a backlog not yet looked at is no silence
        listen = self.listening.now()
        waiting = self._q.oldest_put()
        if waiting is not None:
            listen = min(listen, self.listening.at(waiting))
        wall_ns = time.time_ns()
        doc = dict(self.pipeline.status())
        ages = self.config.health.data_age_timeout_s
        streams = {name: dict(s) for name, s in doc.get("streams", {}).items()}
        required = self.config.health.required_streams
        for name in sorted(set(streams) | set(self.streams) | set(required)):
            health = self.streams.get(name, StreamHealth())
            s = streams.setdefault(name, {})
            s.update(health.to_dict(listen, now, ages[name]))
            s.update(self.clocks.fields(name))
            s.update(self.sequences.fields(name))
            # wall-clock age of the last accepted sample: blocks that keep arriving but are
            # all rejected (a clock that went back) look alive by data age alone
            # (duplicates, copies of data already received, are among the rejected counts)
            accepted, rejected = s.get("accepted", 0), sum((s.get("rejected") or {}).values())
            duplicates = (s.get("rejected") or {}).get("duplicate", 0)
            seen = self._accepted.get(name)
            if seen is None or seen[0] != accepted:
                seen = self._accepted[name] = (accepted, rejected, duplicates, listen)
            s["accepted_age_s"] = listen - seen[3]
            s["rejected_since_accepted"] = rejected - seen[1]
            s["duplicates_since_accepted"] = duplicates - seen[2]
        load_t = doc.get("load_t_ns")
        if load_t is not None and load_t != self._load_t_ns:
            self._load_t_ns, self._load_listen = load_t, listen
        doc.update({
            "buoy_id": self.buoy_id,
            "wall_time_ns": wall_ns,
            "streams": streams,
            "counters": dict(self.counters),
            "uptime_s": now - self._started_mono,
            "queue_depth": self._q.qsize(),  # received but not yet processed
            "fatigue_feed_age_s": listen - self._load_listen,
            "checkpoint": self._ckpt.to_dict(wall_ns),
        })
        for ext in self._extensions:
            fields = getattr(ext, "status_fields", None)
            if fields is not None:
                doc.update(fields())
        engine_active = getattr(getattr(self.pipeline, "alerts", None), "active", None)
        sensor_time = engine_active() if engine_active is not None else []
        forecasts = getattr(self.pipeline, "forecasts", None)
        doc["alerts"] = {"active": [_alert_summary(r, "sensor_time") for r in sensor_time]
                         + [_alert_summary(r, "forecast") for r in (
                             forecasts.active() if forecasts is not None else [])]
                         + [_alert_summary(r, "live") for r in self.live.active()]}
        doc["health"] = self.live.health()
        return doc

    def full_state(self) -> dict[str, Any]:
        """Answer of the ``monitor/state`` queryable: status plus the checkpointable state."""
        return {"status": self.status(), "state": self.checkpoint_state()}

    def checkpoint_state(self) -> dict[str, Any]:
        """The pipeline's state, the daemon's counters and live-rule state, the wall-clock
        times of the last arrivals and fatigue feed, and the last status (shown by ``buoymon
        status`` while the daemon is stopped)."""
        now_listen, now_wall = self.listening.now(), time.time_ns()

        def wall_of(listen: float) -> int:  # the wall time as old, in listening time
            return now_wall - int((now_listen - listen) * 1e9)

        return {
            "pipeline": self.pipeline.state(),
            "daemon": {"counters": dict(self.counters), "live": self.live.state(),
                       "arrivals": {name: wall_of(h.last_arrival)
                                    for name, h in self.streams.items()
                                    if h.last_arrival is not None},
                       "fatigue_fed": [self._load_t_ns, wall_of(self._load_listen)],
                       "sequences": self.sequences.state(),
                       "recorded": {s: dict(d) for s, d in self._flushed.items()},
                       "last_status": self._last_doc},
        }

    def publish_json(self, key: str, doc: Mapping[str, Any], sensor_time_ns: int) -> None:
        """Publish a JSON document (status, alerts) and record it like a received message,
        stamped with ``sensor_time_ns`` as its publish time: the pipeline's sensor time never
        goes back, so neither does a recorded topic. Before there is any sensor time (0: no
        data yet, ever) documents are published but not recorded; the wall clock would put
        them after the sensor-time ones that follow."""
        payload = zenoh_io.to_json_bytes(doc)
        if key == zenoh_io.status_key(self.buoy_id) and self._status_pub is not None:
            self._status_pub.put(payload)
        else:
            self.session.put(key, payload, encoding="application/json",
                             congestion_control=zenoh_io.zenoh.CongestionControl.BLOCK)
        if self.recorder is not None and sensor_time_ns > 0:
            self.recorder.write(key, payload, JSON_OBJECT, time.time_ns(), sensor_time_ns)

    def _publish_status(self) -> None:
        doc = self.status()
        now = time.monotonic()
        if now - self._last_live_mono >= self.config.zenoh.status_interval_s and (
                not self._first_catch_up or now >= self._live_from_mono):
            self._last_live_mono = now
            records = self.live.evaluate(doc, doc["wall_time_ns"])
            if records:
                doc["alerts"]["active"] = [a for a in doc["alerts"]["active"]
                                           if a["source"] != "live"] + [
                    _alert_summary(r, "live") for r in self.live.active()]
                doc["health"] = self.live.health()
                self._last_doc = doc  # /healthz agrees before anyone hears of the change
                self._deliver_live(records, int(doc.get("now_ns") or 0))
        self._last_doc = doc
        self.publish_json(zenoh_io.status_key(self.buoy_id), doc, int(doc.get("now_ns") or 0))
        self.counters["status_published"] += 1
        self._last_status_mono = time.monotonic()
        self._dirty_status = False

    def _deliver_live(self, records: list[Any], sensor_time_ns: int) -> None:
        """Live-rule transitions take the pipeline's alert path: every alert delivery channel
        (Zenoh alert keys, outbox channels), and the recording, stamped with the sensor time
        like every other message."""
        for rec in records:
            log.warning("live alert", extra={"fields": {
                "rule": rec.rule, "component": rec.component, "event": rec.event,
                "value": rec.value, "summary": rec.summary}})
        self._alert_channels.publish(records)
        if self.recorder is not None and sensor_time_ns > 0:  # as publish_json
            for rec in records:
                self.recorder.write(rec.key, zenoh_io.to_json_bytes(rec.to_dict()), JSON_OBJECT,
                                    time.time_ns(), sensor_time_ns)


def _alert_summary(rec: Any, source: str) -> dict[str, Any]:
    """One active alert as shown in the status (``source``: ``sensor_time`` or ``live``)."""
    return {"rule": rec.rule, "component": rec.component, "severity": rec.severity,
            "source": source, "since_ns": rec.starts_at_ns, "value": rec.value,
            "threshold": rec.threshold, "unit": rec.unit, "summary": rec.summary,
            "fingerprint": rec.fingerprint, "acked_by": rec.acked_by}
