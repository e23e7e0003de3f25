"""The live daemon behind ``buoymon run``: Zenoh in, pipeline core, status out, checkpoints.

One thread does all the work; zenoh callbacks only enqueue (see :mod:`monitor.zenoh_io`).
Each loop turn: take what arrived -> decode -> record -> ``pipeline.process`` -> publish
status (after new data, and at least every ``status_interval_s``) -> checkpoint when due ->
``WATCHDOG=1``. Queries on ``buoy/<id>/monitor/state`` are answered from the same thread, so
they always see a consistent state.

Crash safety: the checkpoint holds the pipeline's state (damage, residue, per-stream last
sample times, alert states) plus the daemon's counters, written atomically. After a crash the
pipeline restarts from it and skips samples at or before each stream's last time, so a
publisher may re-deliver from a bit before the crash without double counting.

Shutdown (``stop()``, e.g. from SIGTERM/SIGINT): ``STOPPING=1``, stop intake, process what is
already queued, publish a last status, checkpoint, close the recorder and the session.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Protocol, Sequence

from monitor.blocks import SampleBlock, parse_sensor_topic
from monitor.checkpoint import CheckpointStore, PeriodicCheckpointer
from monitor.daemon_config import DaemonConfig
from monitor.events import Sink, StepResult
from monitor.memory import release_compiler_pages
from monitor.recorder import JSON_OBJECT, McapRecorder
from monitor.sdnotify import SdNotifier
from monitor import zenoh_io

log = logging.getLogger("buoymon.daemon")

# status is re-published after new data at most this often (bounds the cost of bursts)
_MIN_STATUS_GAP_S = 0.02
_IDLE_WAIT_S = 0.2
_MAX_TURN_S = 0.25  # longest stretch of queued work between periodic duties
_RELEASE_EVERY_S = 600.0  # hand back the JIT compiler's pages (monitor.memory) this often


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


# attach(session, pipeline) -> extensions; may add sinks to ``pipeline.sinks``
Attach = Callable[[Any, PipelineLike], Sequence[Extension]]


class _RecordAlertsSink:
    """Records the alert transitions the pipeline emits, as JSON on their Zenoh keys."""

    def __init__(self, recorder: McapRecorder) -> None:
        self.recorder = recorder

    def on_step(self, step: StepResult) -> None:
        for rec in step.alerts:
            now = time.time_ns()
            self.recorder.write(rec.key, zenoh_io.to_json_bytes(rec.to_dict()), JSON_OBJECT,
                                now, getattr(rec, "at_ns", 0) or now)

    def close(self) -> None:
        pass


@dataclass
class StreamHealth:
    """Wall-clock view of one sensor stream: data age and liveliness (not in the checkpoint)."""

    last_arrival_mono: float | None = None
    alive: bool | None = None  # None: no liveliness token seen either way

    def to_dict(self, now_mono: float, timeout_s: float) -> dict[str, Any]:
        age = None if self.last_arrival_mono is None else now_mono - self.last_arrival_mono
        return {"data_age_s": age, "data_age_timeout_s": timeout_s,
                "data_stale": age is None or age > timeout_s, "alive": self.alive}


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
                 attach: Attach | None = None) -> None:
        self.buoy_id = buoy_id
        self.config = config
        self.codec = codec
        self.notifier = notifier or SdNotifier()
        self._stop = threading.Event()
        self._q: "queue.SimpleQueue[tuple]" = queue.SimpleQueue()
        self._store = CheckpointStore(config.state.path)
        restored = self._store.load()
        saved = restored.state if restored is not None else {}
        self.counters: dict[str, int] = {"messages": 0, "undecodable": 0, "wrong_buoy": 0,
                                         "refused": 0, "status_published": 0, "queries": 0}
        self.counters.update(saved.get("daemon", {}).get("counters", {}))
        self.streams: dict[str, StreamHealth] = {}
        self.restored_seq = restored.seq if restored is not None else 0
        self.recorder = (McapRecorder(config.record.dir, config.record.rotate_s,
                                      config.record.flush_interval_s)
                         if config.record.enabled else None)
        sinks = [_RecordAlertsSink(self.recorder)] if self.recorder is not None else []
        self.pipeline = make_pipeline(saved.get("pipeline"), sinks)
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

    # ---- lifecycle -------------------------------------------------------------------------

    def stop(self) -> None:
        """Ask the loop to drain, checkpoint and close (safe from signal handlers/threads)."""
        self._stop.set()

    def run(self) -> None:
        """Serve until :meth:`stop`; always checkpoints and closes on the way out."""
        zc = self.config.zenoh
        self.session = zenoh_io.open_session(zc)
        declared: list[Any] = []
        try:
            declared.append(zenoh_io.declare_liveliness_watch(
                self.session, zenoh_io.sensor_key(self.buoy_id), self._q))
            declared.append(zenoh_io.declare_deferred_queryable(
                self.session, zenoh_io.state_key(self.buoy_id), self._q))
            self._status_pub = zenoh_io.declare_json_publisher(
                self.session, zenoh_io.status_key(self.buoy_id))
            declared.append(self._status_pub)
            declared.append(self.session.liveliness().declare_token(
                zenoh_io.monitor_token_key(self.buoy_id)))
            if self._attach is not None:
                self._extensions = self._attach(self.session, self.pipeline)
                declared.extend(_Closing(e) for e in self._extensions)
            subscriber = zenoh_io.declare_enqueuing_subscriber(
                self.session, zenoh_io.sensor_key(self.buoy_id), self._q)
            log.info("daemon ready", extra={"fields": {
                "buoy_id": self.buoy_id, "listen": list(zc.listen), "connect": list(zc.connect),
                "restored_checkpoint": self.restored_seq}})
            self.notifier.ready(f"monitoring buoy {self.buoy_id}")
            self._serve()
            self.notifier.stopping()
            subscriber.undeclare()  # stop intake, then finish what already arrived
            self._drain()
            self._publish_status()
            self._checkpointer.save_now()
            log.info("daemon stopped", extra={"fields": {"counters": dict(self.counters)}})
        finally:
            for obj in reversed(declared):
                try:
                    obj.undeclare()
                except Exception:  # already gone with a closing session: nothing to undo
                    pass
            if self.recorder is not None:
                self.recorder.close()
            self._store.close()
            self.session.close()

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
            now = time.monotonic()
            if (now - self._last_status_mono >= zc.status_interval_s
                    or (self._dirty_status and now - self._last_status_mono >= _MIN_STATUS_GAP_S)):
                self._publish_status()
            for ext in self._extensions:
                ext.poll()
            self._checkpointer.maybe_save()
            if self.recorder is not None:
                self.recorder.maybe_flush()
            if now >= self._next_release_mono:  # at once, then now and then: a steady daemon
                release_compiler_pages()        # never runs the compiler (monitor.memory)
                self._next_release_mono = now + _RELEASE_EVERY_S
            self._pet_watchdog(now)

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
            self._on_data(item[1], item[2], item[3])
        elif kind == "alive":
            self._on_alive(item[1], item[2])
        elif kind == "query":
            self._on_query(item[1])

    def _stream(self, sensor: str) -> StreamHealth:
        return self.streams.setdefault(sensor, StreamHealth())

    def _on_data(self, key: str, payload: bytes, recv_ns: int) -> None:
        block = zenoh_io.decode_counted(self.codec, key, payload, recv_ns, self.counters, log)
        if block is None:
            return
        if block.buoy_id != self.buoy_id:
            self.counters["wrong_buoy"] += 1
            return
        if self.recorder is not None:
            self.recorder.write(key, payload, self.codec.channel_spec(block.sensor),
                                recv_ns, block.t_first_ns)
        self._stream(block.sensor).last_arrival_mono = time.monotonic()
        try:
            self.pipeline.process(block)
        except ValueError as exc:  # a block the pipeline refuses: count it, keep serving
            self.counters["refused"] += 1
            log.warning("block refused by the pipeline",
                        extra={"fields": {"key": key, "error": str(exc)}})
        self._dirty_status = True

    def _on_alive(self, key: str, alive: bool) -> None:
        try:
            _, sensor = parse_sensor_topic(key)
        except ValueError:
            return
        self._stream(sensor).alive = alive
        log.info("sensor liveliness", extra={"fields": {"sensor": sensor, "alive": alive}})

    def _on_query(self, query: Any) -> None:
        self.counters["queries"] += 1
        with query:
            query.reply(zenoh_io.state_key(self.buoy_id),
                        zenoh_io.to_json_bytes(self.full_state()), encoding="application/json")

    # ---- output ----------------------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        """The status document published on ``buoy/<id>/monitor/status``.

        The pipeline's figures (sensor time, load source, latest measured and estimated
        tension, per-component damage, damage rate and remaining life, per-stream accepted
        and rejected counts and sensor-time staleness) with, per stream, the daemon's
        wall-clock data age and liveliness, and the daemon's own counters.
        """
        now = time.monotonic()
        doc = dict(self.pipeline.status())
        ages = self.config.health.data_age_timeout_s
        streams = {name: dict(s) for name, s in doc.get("streams", {}).items()}
        for name in sorted(set(streams) | set(self.streams)):
            health = self.streams.get(name, StreamHealth())
            streams.setdefault(name, {}).update(health.to_dict(now, ages[name]))
        doc.update({
            "buoy_id": self.buoy_id,
            "wall_time_ns": time.time_ns(),
            "streams": streams,
            "counters": dict(self.counters),
            "uptime_s": now - self._started_mono,
            "queue_depth": self._q.qsize(),  # received but not yet processed
        })
        return doc

    def full_state(self) -> dict[str, Any]:
        """Answer of the ``monitor/state`` queryable: status plus the checkpointable state."""
        return {"status": self.status(), "state": self.checkpoint_state()}

    def checkpoint_state(self) -> dict[str, Any]:
        return {
            "pipeline": self.pipeline.state(),
            "daemon": {"counters": dict(self.counters)},
        }

    def publish_json(self, key: str, doc: Mapping[str, Any], sensor_time_ns: int) -> None:
        """Publish a JSON document (status, alerts) and record it like a received message."""
        payload = zenoh_io.to_json_bytes(doc)
        now_ns = time.time_ns()
        if key == zenoh_io.status_key(self.buoy_id) and self._status_pub is not None:
            self._status_pub.put(payload)
        else:
            self.session.put(key, payload, encoding="application/json",
                             congestion_control=zenoh_io.zenoh.CongestionControl.BLOCK)
        if self.recorder is not None:
            self.recorder.write(key, payload, JSON_OBJECT, now_ns, sensor_time_ns or now_ns)

    def _publish_status(self) -> None:
        doc = self.status()
        self.publish_json(zenoh_io.status_key(self.buoy_id), doc, int(doc.get("now_ns") or 0))
        self.counters["status_published"] += 1
        self._last_status_mono = time.monotonic()
        self._dirty_status = False
