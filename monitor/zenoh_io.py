"""Zenoh plumbing for the daemon, the recorder and the publisher.

Callbacks declared here run on zenoh's own threads: they only copy what arrived into a
thread-safe queue and return (never block, never call zenoh). The single consumer thread
(the daemon loop) does everything else, including answering queries.

Queue items are tuples whose first element says what they are:

* ``("data", key, payload_bytes, recv_ns, origin, recv_mono)``: a sample on ``buoy/<id>/sensor/**`` (or
  any key the subscriber was declared on); ``origin`` is an :class:`Origin` for messages of
  advanced publishers (sensor streams), None for others;
* ``("forecast", key, payload_bytes, recv_ns)``: a sea-state forecast on
  ``buoy/<id>/forecast/waves``;
* ``("alive", key, is_alive, recv_ns)``: a liveliness token appeared or went away;
* ``("query", zenoh.Query)``: a query to answer, then ``drop()``.
"""

from __future__ import annotations

import json
import queue
import time
from typing import Any, Mapping, NamedTuple, Protocol

import msgspec
import zenoh
import zenoh.ext

from monitor.blocks import SENSOR_FIELDS, SampleBlock, parse_sensor_topic, validate_buoy_id
from monitor.daemon_config import ZenohConfig
from monitor.recorder import ChannelSpec
from monitor.strict_json import to_json_bytes  # noqa: F401  (callers use zenoh_io.to_json_bytes)


def session_config_dict(zc: ZenohConfig) -> dict[str, Any]:
    """The zenoh JSON configuration for ``zc`` (loopback-only embedded peer by default)."""
    conf: dict[str, Any] = {
        "mode": zc.mode,
        "listen": {"endpoints": list(zc.listen)},
        # a lost connection (the daemon restarting) is retried within a second, not after
        # zenoh's default back-off of up to 4 s: a sensor reconnects while the daemon's new
        # life catches up from its cache
        "connect": {"endpoints": list(zc.connect),
                    "retry": {"period_init_ms": 250, "period_max_ms": 1000,
                              "period_increase_factor": 2}},
        "scouting": {
            "multicast": {"enabled": zc.multicast_scouting},
            "gossip": {"enabled": False},
        },
        # sensor samples carry an HLC timestamp: tells duplicates and ordering apart
        "timestamping": {"enabled": True},
    }
    transport: dict[str, Any] = {}
    if zc.tls is not None:
        tls = {k: v for k, v in msgspec.structs.asdict(zc.tls).items() if v is not None}
        transport["link"] = {"tls": tls}
    if zc.auth is not None:
        usrpwd = {k: v for k, v in msgspec.structs.asdict(zc.auth).items() if v is not None}
        transport["auth"] = {"usrpwd": usrpwd}
    if transport:
        conf["transport"] = transport
    return conf


def open_session(zc: ZenohConfig) -> zenoh.Session:
    """Open a zenoh session configured by ``zc``; the caller closes it."""
    return zenoh.open(zenoh.Config.from_json5(json.dumps(session_config_dict(zc))))


def sensor_key(buoy_id: str) -> str:
    return f"buoy/{validate_buoy_id(buoy_id)}/sensor/**"


def status_key(buoy_id: str) -> str:
    return f"buoy/{validate_buoy_id(buoy_id)}/monitor/status"


def state_key(buoy_id: str) -> str:
    return f"buoy/{validate_buoy_id(buoy_id)}/monitor/state"


def forecast_key(buoy_id: str) -> str:
    """Sea-state forecasts for the buoy (JSON, :mod:`monitor.forecast`)."""
    return f"buoy/{validate_buoy_id(buoy_id)}/forecast/waves"


def monitor_token_key(buoy_id: str) -> str:
    return f"buoy/{validate_buoy_id(buoy_id)}/monitor/alive"


def declare_enqueuing_subscriber(session: zenoh.Session, key: str,
                                 q: "queue.SimpleQueue[tuple]") -> Any:
    """Subscribe to ``key`` with Zenoh's advanced subscriber; every sample is put on ``q`` as
    ``("data", key, bytes, recv_ns, Origin | None, recv_mono)``: received at wall time
    ``recv_ns`` and at monotonic ``recv_mono`` (ages of waiting messages are judged on the
    monotonic clock, which a clock step while they wait does not move).

    Recovery: a message lost in transit is fetched again from its publisher's cache
    (heartbeat-driven), and delivery stays in order per publisher. No history: what a
    (re)starting process missed is fetched by number (:func:`declare_publisher_watch`,
    :func:`fetch_cached`), since Zenoh's history can be overtaken, and then dropped, by live
    messages of a publisher that reconnects at the same moment.
    """

    def on_sample(sample: zenoh.Sample) -> None:
        info, ts = sample.source_info, sample.timestamp
        origin = None if info is None else Origin(
            f"{info.source_id.zid}/{info.source_id.eid}", info.source_sn,
            None if ts is None else ts.get_time_as_ntp64().as_nanos())
        q.put(("data", str(sample.key_expr), sample.payload.to_bytes(), time.time_ns(), origin,
               time.monotonic()))

    return zenoh.ext.declare_advanced_subscriber(
        session, key, on_sample,
        recovery=zenoh.ext.RecoveryConfig(heartbeat=True))


def declare_forecast_subscriber(session: zenoh.Session, buoy_id: str,
                                q: "queue.SimpleQueue[tuple]") -> zenoh.Subscriber:
    """Subscribe to the buoy's forecasts; each is put on ``q`` as ``("forecast", key, bytes,
    recv_ns)`` (a plain subscriber: a forecast is a single message that its sender repeats)."""

    def on_sample(sample: zenoh.Sample) -> None:
        q.put(("forecast", str(sample.key_expr), sample.payload.to_bytes(), time.time_ns()))

    return session.declare_subscriber(forecast_key(buoy_id), on_sample)


class Origin(NamedTuple):
    """Where a message came from: its advanced publisher (``"<zenoh id>/<entity id>"``), that
    publisher's sequence number of the message, and when it was published (the publisher's
    clock, ns since the epoch; None without timestamps)."""

    source: str
    sn: int
    sent_ns: int | None


def _publisher_of(token_key: str) -> tuple[str, str] | None:
    """(stream key, "<zid>/<eid>") of an advanced publisher's liveliness token
    ``<key>/@adv/pub/<zid>/<eid>/...``; None for any other key."""
    key, _, rest = token_key.partition("/@adv/pub/")
    zid, _, tail = rest.partition("/")
    eid = tail.split("/", 1)[0]
    return (key, f"{zid}/{eid}") if zid and eid else None


def _publishers_key(buoy_id: str) -> str:
    return f"buoy/{validate_buoy_id(buoy_id)}/sensor/*/@adv/pub/**"


def declare_publisher_watch(session: zenoh.Session, buoy_id: str,
                            q: "queue.SimpleQueue[tuple]") -> zenoh.Subscriber:
    """Watch the advanced sensor publishers of ``buoy_id`` (existing ones included): each
    one's appearance is put on ``q`` as ``("publisher", key, source)``."""

    def on_change(sample: zenoh.Sample) -> None:
        pub = _publisher_of(str(sample.key_expr))
        if sample.kind == zenoh.SampleKind.PUT and pub is not None:
            q.put(("publisher", *pub))

    return session.liveliness().declare_subscriber(_publishers_key(buoy_id), on_change,
                                                   history=True)


def sensor_publishers(session: zenoh.Session, buoy_id: str,
                      timeout_s: float) -> list[tuple[str, str]]:
    """The advanced sensor publishers of ``buoy_id`` alive now: (stream key, source), source
    being ``"<zid>/<eid>"`` as in :class:`Origin`."""
    found = set()
    for reply in session.liveliness().get(_publishers_key(buoy_id), timeout=timeout_s):
        pub = None if reply.ok is None else _publisher_of(str(reply.ok.key_expr))
        if pub is not None:
            found.add(pub)
    return sorted(found)


def fetch_cached(session: zenoh.Session, key: str, source: str,
                 sns: tuple[int, int | None], timeout_s: float) -> list[tuple[bytes, Origin]]:
    """Ask the advanced publisher ``source`` of ``key`` for the messages numbered
    ``sns[0]..sns[1]`` (inclusive; ``sns[1]`` None: up to the newest) still in its cache;
    returns (payload, origin) in number order (empty if the publisher is gone or no longer
    holds them).

    The selector is the advanced publisher's cache queryable
    (``<key>/@adv/pub/<zid>/<eid>/*?_sn=a..b``), the one its subscribers' history and
    recovery use; replies carry the original key, hence ``accept_replies=ANY``."""
    lo, hi = sns[0], (sns[1] if sns[1] is not None else 2**63)
    selector = f"{key}/@adv/pub/{source}/*?_sn={lo}..{'' if sns[1] is None else hi}"
    out: dict[int, tuple[bytes, Origin]] = {}
    for reply in session.get(selector, timeout=timeout_s,
                             consolidation=zenoh.ConsolidationMode.NONE,
                             accept_replies=zenoh.ReplyKeyExpr.ANY):
        sample = reply.ok
        info = None if sample is None else sample.source_info
        if info is None or not lo <= info.source_sn <= hi:
            continue
        ts = sample.timestamp
        out[info.source_sn] = (sample.payload.to_bytes(), Origin(
            source, info.source_sn, None if ts is None else ts.get_time_as_ntp64().as_nanos()))
    return [out[sn] for sn in sorted(out)]


def declare_liveliness_watch(session: zenoh.Session, key: str,
                             q: "queue.SimpleQueue[tuple]") -> zenoh.Subscriber:
    """Watch liveliness tokens under ``key`` (existing ones included) into ``q``."""

    def on_change(sample: zenoh.Sample) -> None:
        q.put(("alive", str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT,
               time.time_ns()))

    return session.liveliness().declare_subscriber(key, on_change, history=True)


def declare_deferred_queryable(session: zenoh.Session, key: str,
                               q: "queue.SimpleQueue[tuple]") -> zenoh.Queryable:
    """A queryable whose queries are answered later by the queue's consumer."""
    return session.declare_queryable(key, lambda query: q.put(("query", query)))


def declare_data_publisher(session: zenoh.Session, key: str,
                           encoding: str = "application/protobuf") -> zenoh.Publisher:
    """A publisher that never drops: BLOCK congestion control and RELIABLE reliability."""
    return session.declare_publisher(
        key,
        encoding=zenoh.Encoding(encoding),
        congestion_control=zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
    )


def declare_json_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """A reliable, blocking publisher for JSON documents (status, alerts)."""
    return declare_data_publisher(session, key, "application/json")


class BlockCodec(Protocol):
    """Payload encoding of sensor blocks on Zenoh (the same bytes as the MCAP log messages)."""

    def encode(self, block: SampleBlock) -> bytes: ...

    def decode(self, topic: str, payload: bytes, recv_ns: int) -> SampleBlock: ...

    def channel_spec(self, sensor: str) -> ChannelSpec: ...


class ProtobufCodec:
    """The log format's protobuf block encoding (``monitor.codec``) as a :class:`BlockCodec`.

    ``quanta``: quantum per field name for encoding (``monitor.quanta.DEFAULT_QUANTA``
    otherwise; ValueError for a bad one); decoding takes the quantum carried in each message.
    """

    def __init__(self, quanta: Mapping[str, float] | None = None) -> None:
        from monitor.quanta import quanta as sensor_quanta  # noqa: PLC0415

        self._quanta = dict(quanta or {})
        for sensor in SENSOR_FIELDS:
            sensor_quanta(sensor, self._quanta)

    def encode(self, block: SampleBlock) -> bytes:
        # numpy alone: a process that only publishes (the bridge) never loads numba
        from monitor import codec_np  # noqa: PLC0415

        return codec_np.encode_block(block, self._quanta)

    def decode(self, topic: str, payload: bytes, recv_ns: int) -> SampleBlock:
        from monitor import codec  # noqa: PLC0415 (lazy: numba only where blocks are read)

        buoy_id, sensor = parse_sensor_topic(topic)
        return codec.decode_block(buoy_id, sensor, payload, recv_ns)

    def channel_spec(self, sensor: str) -> ChannelSpec:
        from monitor import codec  # noqa: PLC0415

        return ChannelSpec(codec.schema_name(sensor), "protobuf",
                           codec.file_descriptor_set(sensor), "protobuf")


def default_codec() -> BlockCodec:
    """The codec used on the wire: the same bytes as the MCAP log messages."""
    return ProtobufCodec()


def decode_counted(codec: BlockCodec, key: str, payload: bytes, recv_ns: int,
                   counters: dict[str, int], log: Any,
                   count_decoded: bool = True) -> SampleBlock | None:
    """Decode a received sensor message, counting it in ``counters["messages"]``; a payload
    that does not decode is counted as ``"undecodable"``, logged, and gives None.
    ``count_decoded=False``: a message that decodes is left for the caller to count (the
    daemon counts a redelivered message once)."""
    try:
        block = codec.decode(key, payload, recv_ns)
    except ValueError as exc:
        counters["messages"] += 1
        counters["undecodable"] += 1
        log.warning("undecodable message", extra={"fields": {"key": key, "error": str(exc)}})
        return None
    counters["messages"] += count_decoded
    return block
