"""The shore-side monitor: one process following every buoy of a fleet over Zenoh.

It subscribes to ``buoy/*/sensor/**`` through a Zenoh client (to a router or a peer) or as a
peer, and keeps, per buoy, the same pipeline core the buoy's own daemon runs (live ordering),
built on the first data with the shared configuration and the buoy's id. Buoys appear and
disappear by their sensors' liveliness tokens (``buoy/<id>/sensor/<name>``, declared by every
publisher, see :mod:`monitor.publisher`) and by the age of their data.

Threads: Zenoh callbacks only admit and enqueue (see :mod:`monitor.zenoh_io`); one consumer
thread decodes, runs the pipelines and publishes the fleet status, so the pipelines need no
locks.

Bounded memory per buoy: at most ``max_pending_blocks`` received-but-unprocessed blocks per
buoy (beyond that, new blocks of that buoy are dropped at intake and counted in ``dropped``);
the pipeline itself holds at most ``[ordering] horizon_s`` of samples per stream; the rest is
fixed-size (damage accumulators, rainflow residue, histograms). ``max_buoys`` bounds the number
of buoys followed (further ones are counted in ``refused_buoys``).

Status per buoy (:meth:`ShoreMonitor.status`, published as one JSON document on
``shore/<name>/status`` every ``status_interval_s``):

``state``  ``online`` (data younger than ``data_age_timeout_s``), ``stale`` (liveliness tokens
           but no recent data: a hung sensor on a live link) or ``offline`` (no token, no
           recent data; the buoy's damage history is kept);
plus the pipeline's figures (sensor time, load source, damage, damage rate and remaining life
per component, per-stream counts), the live liveliness tokens, the data age and counters.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from monitor.blocks import validate_buoy_id
from monitor.config import Config, config_with
from monitor.daemon_config import ZenohConfig

log = logging.getLogger("buoymon.shore")

SENSOR_KEYS = "buoy/*/sensor/**"
_IDLE_WAIT_S = 0.1


def config_for_buoy(config: Config, buoy_id: str) -> Config:
    """The fleet's shared configuration with ``buoy.id`` set to ``buoy_id``."""
    if config.buoy.id == buoy_id:
        return config
    return config_with(config, buoy={**config.section("buoy"), "id": buoy_id})


def buoy_of_key(key: str) -> str | None:
    """``buoy/<id>/sensor/...`` -> ``<id>`` (None for any other key)."""
    parts = key.split("/", 3)
    if len(parts) < 4 or parts[0] != "buoy" or parts[2] != "sensor":
        return None
    return parts[1]


@dataclass(frozen=True)
class ShoreConfig:
    """How the shore monitor connects and what it bounds."""

    name: str = "shore"
    zenoh: ZenohConfig = field(default_factory=lambda: ZenohConfig(
        mode="client", listen=(), connect=("tcp/127.0.0.1:7447",)))
    status_interval_s: float = 1.0
    data_age_timeout_s: float = 10.0
    max_pending_blocks: int = 600
    max_buoys: int = 1000

    def __post_init__(self) -> None:
        validate_buoy_id(self.name)  # one key chunk, like a buoy id
        for key in ("status_interval_s", "data_age_timeout_s"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and v > 0 and v < float("inf")):
                raise ValueError(f"shore.{key} = {v!r}: must be a finite number > 0")
        for key in ("max_pending_blocks", "max_buoys"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"shore.{key} = {v!r}: must be an integer >= 1")


class BuoyTracker:
    """One buoy as the shore sees it: its pipeline (built on first data), tokens, counters."""

    def __init__(self, buoy_id: str, first_seen_mono: float) -> None:
        self.buoy_id = buoy_id
        self.pipeline: Any = None
        self.tokens: set[str] = set()
        self.first_seen_mono = first_seen_mono
        self.last_arrival_mono: float | None = None
        self.counters = {"messages": 0, "undecodable": 0, "dropped": 0}

    def state(self, now_mono: float, timeout_s: float) -> str:
        fresh = (self.last_arrival_mono is not None
                 and now_mono - self.last_arrival_mono <= timeout_s)
        if fresh:
            return "online"
        return "stale" if self.tokens else "offline"

    def status(self, now_mono: float, timeout_s: float) -> dict[str, Any]:
        age = None if self.last_arrival_mono is None else now_mono - self.last_arrival_mono
        doc: dict[str, Any] = {
            "buoy_id": self.buoy_id,
            "state": self.state(now_mono, timeout_s),
            "data_age_s": age,
            "alive_sensors": sorted(k.rsplit("/", 1)[-1] for k in self.tokens),
            "counters": dict(self.counters),
        }
        if self.pipeline is not None:
            p = self.pipeline.status()
            doc.update({k: p[k] for k in ("now_ns", "load_source", "measured_tension_N",
                                           "estimated_tension_N", "components", "streams")})
        return doc


class ShoreMonitor:
    """Follows every buoy on the Zenoh network until :meth:`stop`.

    ``make_pipeline(config_for_buoy)`` builds a buoy's pipeline (default: the live
    ``monitor.pipeline.Pipeline``, as the buoy's daemon runs it).
    """

    def __init__(self, config: Config, shore: ShoreConfig = ShoreConfig(), *,
                 codec: Any = None, make_pipeline: Callable[[Config], Any] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.config = config
        self.shore = shore
        self.codec = codec
        self.make_pipeline = make_pipeline or _live_pipeline
        self.clock = clock
        self.buoys: dict[str, BuoyTracker] = {}
        self.refused_buoys: set[str] = set()
        self._q: "queue.SimpleQueue[tuple]" = queue.SimpleQueue()
        self._pending: dict[str, int] = {}
        self._dropped: dict[str, int] = {}
        self._intake_lock = threading.Lock()
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._snapshot_lock = threading.Lock()
        self._snapshot: dict[str, Any] = {"buoys": {}}

    # ---- intake (Zenoh threads: admit, enqueue, return) -------------------------------------

    def offer_data(self, key: str, payload: bytes, recv_ns: int) -> bool:
        """Enqueue one received sample unless its buoy already has ``max_pending_blocks``
        waiting; return whether it was accepted."""
        buoy = buoy_of_key(key)
        if buoy is None:
            return False
        with self._intake_lock:
            n = self._pending.get(buoy, 0)
            if n >= self.shore.max_pending_blocks:
                self._dropped[buoy] = self._dropped.get(buoy, 0) + 1
                return False
            self._pending[buoy] = n + 1
        self._q.put(("data", key, payload, recv_ns))
        return True

    def offer_alive(self, key: str, alive: bool) -> None:
        self._q.put(("alive", key, alive))

    # ---- consumer thread ------------------------------------------------------------------

    def _tracker(self, buoy: str) -> BuoyTracker | None:
        t = self.buoys.get(buoy)
        if t is None:
            try:
                validate_buoy_id(buoy)
            except ValueError:
                return None
            if len(self.buoys) >= self.shore.max_buoys:
                self.refused_buoys.add(buoy)
                return None
            t = self.buoys[buoy] = BuoyTracker(buoy, self.clock())
            log.info("buoy appeared", extra={"fields": {"buoy_id": buoy}})
        return t

    def handle(self, item: tuple) -> None:
        """Process one queued item (data or a liveliness change)."""
        if item[0] == "data":
            _, key, payload, recv_ns = item
            buoy = buoy_of_key(key)
            with self._intake_lock:
                self._pending[buoy] -= 1
            t = self._tracker(buoy)
            if t is None:
                return
            from monitor.zenoh_io import decode_counted  # noqa: PLC0415 (zenoh: loaded by now)

            block = decode_counted(self.codec, key, payload, recv_ns, t.counters, log)
            if block is None:
                return
            if t.pipeline is None:
                t.pipeline = self.make_pipeline(config_for_buoy(self.config, buoy))
            t.last_arrival_mono = self.clock()
            t.pipeline.process(block)
        elif item[0] == "alive":
            _, key, alive = item
            buoy = buoy_of_key(key)
            t = self._tracker(buoy) if buoy is not None else None
            if t is None:
                return
            was = bool(t.tokens)
            (t.tokens.add if alive else t.tokens.discard)(key)
            if was != bool(t.tokens):
                log.info("buoy liveliness", extra={"fields": {"buoy_id": buoy,
                                                              "alive": bool(t.tokens)}})

    def drain(self, timeout_s: float = 0.0) -> int:
        """Handle queued items (waiting up to ``timeout_s`` for the first); return how many."""
        n = 0
        try:
            item = self._q.get(timeout=timeout_s) if timeout_s > 0 else self._q.get_nowait()
        except queue.Empty:
            return 0
        while True:
            self.handle(item)
            n += 1
            try:
                item = self._q.get_nowait()
            except queue.Empty:
                return n

    def status(self) -> dict[str, Any]:
        """The fleet status document (consumer thread)."""
        now = self.clock()
        with self._intake_lock:
            dropped = dict(self._dropped)
            pending = dict(self._pending)
        buoys = {}
        for b, t in sorted(self.buoys.items()):
            t.counters["dropped"] = dropped.get(b, 0)
            doc = t.status(now, self.shore.data_age_timeout_s)
            doc["counters"]["pending"] = pending.get(b, 0)
            buoys[b] = doc
        return {"shore": self.shore.name, "wall_time_ns": time.time_ns(), "buoys": buoys,
                "refused_buoys": sorted(self.refused_buoys)}

    def snapshot(self) -> dict[str, Any]:
        """The last published status (safe from any thread)."""
        with self._snapshot_lock:
            return self._snapshot

    def pipeline_state(self, buoy_id: str) -> dict[str, Any] | None:
        """A buoy's full pipeline state (consumer thread, or after :meth:`run` returned)."""
        t = self.buoys.get(buoy_id)
        return None if t is None or t.pipeline is None else t.pipeline.state()

    # ---- lifecycle ------------------------------------------------------------------------

    def stop(self) -> None:
        self._stop.set()

    def wait_ready(self, timeout_s: float) -> bool:
        return self._ready.wait(timeout_s)

    def run(self) -> None:
        """Serve until :meth:`stop`: subscribe, process, publish the status; then drain."""
        from monitor import zenoh_io  # noqa: PLC0415 (zenoh only when actually serving)

        if self.codec is None:
            self.codec = zenoh_io.default_codec()
        status_key = f"shore/{self.shore.name}/status"
        with zenoh_io.open_session(self.shore.zenoh) as session:
            declared = []

            def on_sample(sample: Any) -> None:
                self.offer_data(str(sample.key_expr), sample.payload.to_bytes(), time.time_ns())

            def on_alive(sample: Any) -> None:
                self.offer_alive(str(sample.key_expr), sample.kind == zenoh_io.zenoh.SampleKind.PUT)

            try:
                declared.append(session.liveliness().declare_subscriber(
                    SENSOR_KEYS, on_alive, history=True))
                pub = zenoh_io.declare_json_publisher(session, status_key)
                declared.append(pub)
                subscriber = session.declare_subscriber(SENSOR_KEYS, on_sample)
                self._ready.set()
                last_status = 0.0
                while not self._stop.is_set():
                    self.drain(_IDLE_WAIT_S)
                    if self.clock() - last_status >= self.shore.status_interval_s:
                        self._publish(pub)
                        last_status = self.clock()
                subscriber.undeclare()  # stop intake, then finish what already arrived
                self.drain()
                self._publish(pub)
            finally:
                for obj in reversed(declared):
                    try:
                        obj.undeclare()
                    except Exception:  # already gone with the session: nothing to undo
                        pass

    def _publish(self, pub: Any) -> None:
        from monitor import zenoh_io  # noqa: PLC0415

        doc = self.status()
        with self._snapshot_lock:
            self._snapshot = doc
        pub.put(zenoh_io.to_json_bytes(doc))


def _live_pipeline(config: Config) -> Any:
    from monitor.pipeline import Pipeline  # noqa: PLC0415 (heavy: models, numba)

    return Pipeline(config)


# ---- command line: `buoymon shore` -----------------------------------------------------------


def register(sub: Any) -> None:
    p = sub.add_parser("shore",
                       description="Subscribe to buoy/*/sensor/**, run one pipeline per buoy, "
                       "publish shore/<name>/status with a status per buoy.")
    p.add_argument("--config", metavar="CFG.toml",
                   help="configuration shared by the fleet (its [zenoh] section says how to "
                   "connect; default: the seed 004 example, client of tcp/127.0.0.1:7447)")
    p.add_argument("--name", default="shore", help="status key shore/<name>/status")
    p.add_argument("--data-age-timeout-s", type=float, default=10.0,
                   help="a buoy with no data this long is stale or offline")
    p.add_argument("--max-pending-blocks", type=int, default=600,
                   help="per buoy: received blocks waiting to be processed before drops")
    p.add_argument("--max-buoys", type=int, default=1000, help="buoys followed at most")
    p.set_defaults(func=run_command)


def run_command(args: Any) -> int:
    import signal  # noqa: PLC0415

    from monitor.config import default_config, load_config  # noqa: PLC0415

    try:
        config = load_config(args.config) if args.config else default_config()
        zc = config.daemon.zenoh if "zenoh" in config.raw else ShoreConfig().zenoh
        shore = ShoreConfig(args.name, zc, data_age_timeout_s=args.data_age_timeout_s,
                            max_pending_blocks=args.max_pending_blocks, max_buoys=args.max_buoys,
                            status_interval_s=zc.status_interval_s)
    except (ValueError, OSError) as exc:
        log.error(str(exc))
        return 2
    monitor = ShoreMonitor(config, shore)
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda signum, frame: monitor.stop())
    from monitor import zenoh_io  # noqa: PLC0415 (zenoh only when actually serving)

    try:
        monitor.run()
    except zenoh_io.zenoh.ZError as exc:  # the session did not open: no router or daemon there
        log.error(f"cannot join the Zenoh network as a {zc.mode} of {list(zc.connect)}: is a "
                  f"router or `buoymon run` listening there? ({exc})")
        return 1
    return 0
