"""Zenoh plumbing for the daemon, the recorder and the publisher.

Callbacks declared here run on zenoh's own threads: they only copy what arrived into a
thread-safe queue and return (never block, never call zenoh). The single consumer thread
(the daemon loop) does everything else, including answering queries.

Queue items are tuples whose first element says what they are:

* ``("data", key, payload_bytes, recv_ns)``: a sample on ``buoy/<id>/sensor/**`` (or any
  key the subscriber was declared on);
* ``("forecast", key, payload_bytes, recv_ns)``: a sea-state forecast on
  ``buoy/<id>/forecast/waves``;
* ``("alive", key, is_alive, recv_ns)``: a liveliness token appeared or went away;
* ``("query", zenoh.Query)``: a query to answer, then ``drop()``.
"""

from __future__ import annotations

import json
import queue
import time
from typing import Any, Protocol

import numpy as np
import zenoh

from monitor.blocks import SampleBlock, parse_sensor_topic, validate_buoy_id
from monitor.daemon_config import ZenohConfig
from monitor.recorder import ChannelSpec


def session_config_dict(zc: ZenohConfig) -> dict[str, Any]:
    """The zenoh JSON configuration for ``zc`` (loopback-only embedded peer by default)."""
    conf: dict[str, Any] = {
        "mode": zc.mode,
        "listen": {"endpoints": list(zc.listen)},
        "connect": {"endpoints": list(zc.connect)},
        "scouting": {
            "multicast": {"enabled": zc.multicast_scouting},
            "gossip": {"enabled": False},
        },
        # sensor samples carry an HLC timestamp: tells duplicates and ordering apart
        "timestamping": {"enabled": True},
    }
    transport: dict[str, Any] = {}
    if zc.tls is not None:
        tls = {k: v for k, v in vars(zc.tls).items() if v is not None and k != "enable_mtls"}
        tls["enable_mtls"] = zc.tls.enable_mtls
        transport["link"] = {"tls": tls}
    if zc.auth is not None:
        usrpwd = {k: v for k, v in vars(zc.auth).items() if v is not None}
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
                                 q: "queue.SimpleQueue[tuple]", kind: str = "data"
                                 ) -> zenoh.Subscriber:
    """Subscribe to ``key``; every sample is put on ``q`` as ``(kind, key, bytes, recv_ns)``."""

    def on_sample(sample: zenoh.Sample) -> None:
        q.put((kind, str(sample.key_expr), sample.payload.to_bytes(), time.time_ns()))

    return session.declare_subscriber(key, on_sample)


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


def to_json_bytes(doc: Any) -> bytes:
    """Strict JSON (non-finite floats become null) encoded as UTF-8."""
    return json.dumps(_finite(doc), separators=(",", ":"), allow_nan=False).encode()


def _finite(x: Any) -> Any:
    if isinstance(x, (np.generic, np.ndarray)):
        return _finite(x.tolist())
    if isinstance(x, float):
        return x if x == x and x not in (float("inf"), float("-inf")) else None
    if isinstance(x, dict):
        return {str(k): _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    return x


class BlockCodec(Protocol):
    """Payload encoding of sensor blocks on Zenoh (the same bytes as the MCAP log messages)."""

    def encode(self, block: SampleBlock) -> bytes: ...

    def decode(self, topic: str, payload: bytes, recv_ns: int) -> SampleBlock: ...

    def channel_spec(self, sensor: str) -> ChannelSpec: ...


class ProtobufCodec:
    """The log format's protobuf block encoding (``monitor.codec``) as a :class:`BlockCodec`."""

    def __init__(self) -> None:
        from monitor import codec  # noqa: PLC0415 (lazy: numba compile only when used)

        self._codec = codec

    def encode(self, block: SampleBlock) -> bytes:
        return self._codec.encode_block(block)

    def decode(self, topic: str, payload: bytes, recv_ns: int) -> SampleBlock:
        buoy_id, sensor = parse_sensor_topic(topic)
        return self._codec.decode_block(buoy_id, sensor, payload, recv_ns)

    def channel_spec(self, sensor: str) -> ChannelSpec:
        return ChannelSpec(self._codec.schema_name(sensor), "protobuf",
                           self._codec.file_descriptor_set(sensor), "protobuf")


def default_codec() -> BlockCodec:
    """The codec used on the wire: the same bytes as the MCAP log messages."""
    return ProtobufCodec()


def decode_counted(codec: BlockCodec, key: str, payload: bytes, recv_ns: int,
                   counters: dict[str, int], log: Any) -> SampleBlock | None:
    """Decode a received sensor message, counting it in ``counters["messages"]``; a payload
    that does not decode is counted as ``"undecodable"``, logged, and gives None."""
    counters["messages"] += 1
    try:
        return codec.decode(key, payload, recv_ns)
    except ValueError as exc:
        counters["undecodable"] += 1
        log.warning("undecodable message", extra={"fields": {"key": key, "error": str(exc)}})
        return None
