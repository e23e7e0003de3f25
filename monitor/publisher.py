"""Play sample blocks over Zenoh as a buoy would: for demos, tests and benchmarks.

:func:`publish_blocks` publishes each block on ``buoy/<id>/sensor/<sensor>`` with the log
format's payload encoding, paced by sensor time (``speed`` times real time, or as fast as
possible), holding a liveliness token per sensor like a real sensor node. It is what
what ``replay.publish`` (``buoymon simulate --publish``, ``python -m replay.publish``) calls
to play a recorded or simulated log to a daemon.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable, Iterable, Sequence

from monitor.blocks import SampleBlock
from monitor.daemon_config import ZenohConfig
from monitor import zenoh_io

log = logging.getLogger("buoymon.publisher")


def publisher_config(connect: Sequence[str]) -> ZenohConfig:
    """A peer that only connects out (no listening socket), loopback by the caller's choice."""
    return ZenohConfig(mode="peer", listen=(), connect=tuple(connect))


def publish_blocks(session: Any, blocks: Iterable[SampleBlock], codec: zenoh_io.BlockCodec,
                   speed: float | None = None, start_after_ns: int | None = None,
                   wait_for_subscriber_s: float = 10.0, stop: threading.Event | None = None,
                   clock: Callable[[], float] = time.monotonic,
                   sleep: Callable[[float], None] = time.sleep) -> int:
    """Publish ``blocks`` (in sensor-time order) and return how many were sent.

    Args:
        speed: sensor seconds per wall second (1 = real time); None = as fast as possible.
            A block is sent when its last sample is due, as a sensor sends a full block.
        start_after_ns: skip blocks whose last sample is at or before this sensor time.
        wait_for_subscriber_s: before the first block of each stream, wait up to this long
            for a matching subscriber (nothing is routed before one exists).
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
            if len(block) == 0 or (start_after_ns is not None and block.t_last_ns <= start_after_ns):
                continue
            pub = pubs.get(block.topic)
            if pub is None:
                pub = pubs[block.topic] = zenoh_io.declare_data_publisher(session, block.topic)
                tokens.append(session.liveliness().declare_token(block.topic))
                _wait_matching(pub, wait_for_subscriber_s, clock, sleep)
            if speed is not None:
                if t0_sensor is None:
                    t0_sensor, t0_wall = block.t_last_ns, clock()
                delay = t0_wall + (block.t_last_ns - t0_sensor) / 1e9 / speed - clock()
                if delay > 0:
                    sleep(delay)
            pub.put(codec.encode(block))
            sent += 1
    finally:
        for obj in [*tokens, *pubs.values()]:
            obj.undeclare()
    return sent


def _wait_matching(pub: Any, timeout_s: float, clock: Callable[[], float],
                   sleep: Callable[[float], None]) -> None:
    deadline = clock() + timeout_s
    while not pub.matching_status and clock() < deadline:
        sleep(0.01)
    if not pub.matching_status:
        log.warning("no subscriber yet; publishing anyway",
                    extra={"fields": {"key": str(pub.key_expr)}})


def play(blocks: Iterable[SampleBlock], zc: ZenohConfig, speed: float | None = None,
         start_after_ns: int | None = None, codec: zenoh_io.BlockCodec | None = None,
         wait_for_subscriber_s: float = 10.0) -> int:
    """Open a session from ``zc`` and :func:`publish_blocks` (``buoymon simulate --publish``)."""
    codec = codec or zenoh_io.default_codec()
    with zenoh_io.open_session(zc) as session:
        return publish_blocks(session, blocks, codec, speed, start_after_ns,
                              wait_for_subscriber_s)
