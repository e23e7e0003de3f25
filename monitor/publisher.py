"""Play sample blocks over Zenoh as a buoy would: for demos, tests and benchmarks.

:func:`publish_blocks` publishes each block on ``buoy/<id>/sensor/<sensor>`` with the log
format's payload encoding, paced by sensor time (``speed`` times real time, or as fast as
possible), through the same advanced publishers as a sensor driver
(:func:`monitor.sensors.declare_sensor_publisher`: a cache of the last blocks for a daemon
that starts or restarts later, sequence numbers, a liveliness token per stream). It is what
``replay.publish`` (``buoymon simulate --publish``, ``python -m replay.publish``) calls to play
a recorded or simulated log to a daemon.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable, Iterable, Sequence

from monitor.blocks import SampleBlock
from monitor.daemon_config import ZenohConfig
from monitor.sensors import PublisherOptions, declare_sensor_publisher
from monitor.time_ahead import pace_ns
from monitor import zenoh_io

log = logging.getLogger(__name__)


def publisher_config(connect: Sequence[str]) -> ZenohConfig:
    """A peer that only connects out (no listening socket), loopback by the caller's choice."""
    return ZenohConfig(mode="peer", listen=(), connect=tuple(connect))


def publish_blocks(session: Any, blocks: Iterable[SampleBlock], codec: zenoh_io.BlockCodec,
                   speed: float | None = None, options: PublisherOptions = PublisherOptions(),
                   stop: threading.Event | None = None,
                   clock: Callable[[], float] = time.monotonic,
                   sleep: Callable[[float], None] = time.sleep) -> int:
    """Publish ``blocks`` (in sensor-time order) and return how many were sent.

    Nothing waits for a subscriber: a daemon that is not there yet (or restarting) gets the
    blocks from the publishers' caches (``options.cache_blocks`` per stream) when it comes.

    Args:
        speed: sensor seconds per wall second (1 = real time); None = as fast as possible.
            A block is sent when its last sample is due, as a sensor sends a full block.
        options: cache size and heartbeat of the advanced publishers.
        stop: when set, return before the next block.
    """
    if speed is not None and not speed > 0:
        raise ValueError(f"publish: speed = {speed!r} must be > 0 (or None for no pacing)")
    pubs: dict[str, Any] = {}
    tokens: list[Any] = []
    sent = 0
    t0_sensor: int | None = None
    t0_wall = 0.0
    try:
        for block in blocks:
            if stop is not None and stop.is_set():
                break
            if len(block) == 0:
                continue
            pub = pubs.get(block.topic)
            if pub is None:
                pub = pubs[block.topic] = declare_sensor_publisher(session, block.topic, options)
                tokens.append(session.liveliness().declare_token(block.topic))
            if speed is not None:
                t_ns = pace_ns(block.t_last_ns, block.recv_ns)
                if t0_sensor is None:
                    t0_sensor, t0_wall = t_ns, clock()
                delay = t0_wall + (t_ns - t0_sensor) / 1e9 / speed - clock()
                if delay > 0:
                    sleep(delay)
            pub.put(codec.encode(block))
            sent += 1
    finally:
        for obj in [*tokens, *pubs.values()]:
            obj.undeclare()
    return sent


def play(blocks: Iterable[SampleBlock], zc: ZenohConfig, speed: float | None = None,
         codec: zenoh_io.BlockCodec | None = None,
         options: PublisherOptions = PublisherOptions(), linger_s: float = 0.0) -> int:
    """Open a session from ``zc`` and :func:`publish_blocks` (``buoymon simulate --publish``);
    then keep the publishers' caches up for ``linger_s`` (a daemon starting late still gets
    everything)."""
    codec = codec or zenoh_io.default_codec()
    with zenoh_io.open_session(zc) as session:
        sent = publish_blocks(session, _lingering(blocks, linger_s), codec, speed, options)
        if not any(session.info.peers_zid()) and not any(session.info.routers_zid()):
            # nothing waits for a subscriber, and the caches close with this session
            log.warning("published %d blocks but no daemon or router was connected at %s: "
                        "nobody received them", sent, list(zc.connect))
        return sent


def _lingering(blocks: Iterable[SampleBlock], linger_s: float) -> Iterable[SampleBlock]:
    yield from blocks
    if linger_s > 0:
        time.sleep(linger_s)
