"""Publish a buoy's sensor samples over Zenoh: the public API for sensor drivers.

A few lines publish samples of any stream of :data:`monitor.blocks.SENSOR_FIELDS` with the log
format's encoding, as the daemon (``buoymon run``) expects them::

    from monitor.sensors import SensorPublisher

    with SensorPublisher.connect("vaps", ["tcp/127.0.0.1:7447"]) as pub:
        pub.publish("tension", t_ns, tension_N=newtons)      # arrays of equal length

Each stream is published through Zenoh's *advanced publisher* on ``buoy/<id>/sensor/<name>``:

* a **cache** of the last ``cache_blocks`` blocks per stream, which a daemon that (re)starts
  queries for the history it missed (late-joiner detection), so samples published while the
  daemon was down are delivered when it comes back, as long as they are still in the cache;
* **sample-miss detection** (sequence numbers and a heartbeat every ``heartbeat_s``), so a
  subscriber knows when samples it can no longer recover were lost;
* BLOCK congestion control and RELIABLE reliability (DROP loses data under load);
* a liveliness token per stream, as a sensor node holds while it is up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
import zenoh
import zenoh.ext

from monitor.blocks import SampleBlock, sensor_topic
from monitor.daemon_config import ZenohConfig
from monitor import zenoh_io

# at the default rates a block carries 1 s of samples: 3600 blocks are an hour of data, four
# times the 15 minutes a restarting daemon is promised (docs/DAEMON.md)
DEFAULT_CACHE_BLOCKS = 3600


@dataclass(frozen=True)
class PublisherOptions:
    """How much a :class:`SensorPublisher` keeps for late subscribers, and its heartbeat.

    Args:
        cache_blocks: blocks kept per stream for history queries (memory: one block each).
        heartbeat_s: period of the sequence-number heartbeat that lets a subscriber detect
            a lost last sample.
    """

    cache_blocks: int = DEFAULT_CACHE_BLOCKS
    heartbeat_s: float = 1.0

    def __post_init__(self) -> None:
        if not (isinstance(self.cache_blocks, int) and self.cache_blocks >= 1):
            raise ValueError(f"cache_blocks = {self.cache_blocks!r}: must be an integer >= 1")
        if not (isinstance(self.heartbeat_s, (int, float)) and math.isfinite(self.heartbeat_s)
                and self.heartbeat_s > 0):
            raise ValueError(f"heartbeat_s = {self.heartbeat_s!r}: must be a number > 0")


def declare_sensor_publisher(session: zenoh.Session, key: str,
                             options: PublisherOptions) -> zenoh.ext.AdvancedPublisher:
    """An advanced publisher with a history cache, miss detection and publisher detection."""
    block = zenoh.CongestionControl.BLOCK
    return zenoh.ext.declare_advanced_publisher(
        session, key,
        encoding=zenoh.Encoding("application/protobuf"),
        congestion_control=block,
        reliability=zenoh.Reliability.RELIABLE,
        cache=zenoh.ext.CacheConfig(
            options.cache_blocks,
            replies_config=zenoh.ext.RepliesConfig(congestion_control=block)),
        sample_miss_detection=zenoh.ext.MissDetectionConfig(
            heartbeat=options.heartbeat_s, sporadic_heartbeat=None),
        publisher_detection=True,
    )


class SensorPublisher:
    """Publishes blocks of samples of one buoy's streams; one advanced publisher per stream.

    Args:
        session: an open Zenoh session (the caller closes it), or use :meth:`connect`.
        buoy_id: the buoy's id (one Zenoh key chunk).
        options: cache and heartbeat (:class:`PublisherOptions`).
        codec: payload encoding (default: the log format's protobuf blocks).
    """

    def __init__(self, session: zenoh.Session, buoy_id: str,
                 options: PublisherOptions = PublisherOptions(),
                 codec: zenoh_io.BlockCodec | None = None) -> None:
        self.session = session
        self.buoy_id = buoy_id
        self.options = options
        self.codec = codec or zenoh_io.default_codec()
        self._pubs: dict[str, Any] = {}
        self._tokens: list[Any] = []
        self._own_session = False
        self.blocks_sent = 0

    @classmethod
    def connect(cls, buoy_id: str, connect: Sequence[str],
                options: PublisherOptions = PublisherOptions(),
                codec: zenoh_io.BlockCodec | None = None) -> "SensorPublisher":
        """Open a session of its own (a peer that only connects out) to ``connect``."""
        session = zenoh_io.open_session(ZenohConfig(mode="peer", listen=(),
                                                    connect=tuple(connect)))
        pub = cls(session, buoy_id, options, codec)
        pub._own_session = True
        return pub

    def publish_block(self, block: SampleBlock) -> None:
        """Publish one block (its ``buoy_id`` must be this publisher's)."""
        if block.buoy_id != self.buoy_id:
            raise ValueError(f"block of buoy {block.buoy_id!r} given to the publisher of "
                             f"{self.buoy_id!r}")
        if len(block) == 0:
            return
        pub = self._pubs.get(block.sensor)
        if pub is None:
            pub = self._pubs[block.sensor] = declare_sensor_publisher(
                self.session, block.topic, self.options)
            self._tokens.append(self.session.liveliness().declare_token(block.topic))
        pub.put(self.codec.encode(block))
        self.blocks_sent += 1

    def publish(self, sensor: str, t_ns: Any, **fields: Any) -> SampleBlock:
        """Publish samples of ``sensor`` at sensor times ``t_ns`` (int ns since the epoch,
        increasing) with one array per field of the stream (SI units, see
        :data:`monitor.blocks.SENSOR_FIELDS`); returns the block sent."""
        block = SampleBlock(self.buoy_id, sensor, np.asarray(t_ns, dtype=np.int64),
                            {k: np.asarray(v, dtype=np.float64) for k, v in fields.items()})
        self.publish_block(block)
        return block

    def topics(self) -> Mapping[str, str]:
        """Stream name -> Zenoh key of the streams published so far."""
        return {s: sensor_topic(self.buoy_id, s) for s in self._pubs}

    def close(self) -> None:
        """Withdraw the liveliness tokens and publishers (the cache goes with them)."""
        for obj in [*self._tokens, *self._pubs.values()]:
            obj.undeclare()
        self._tokens.clear()
        self._pubs.clear()
        if self._own_session:
            self.session.close()

    def __enter__(self) -> "SensorPublisher":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
