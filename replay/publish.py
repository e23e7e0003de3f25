"""Play MCAP logs over Zenoh as a live buoy: ``python -m replay.publish LOG.mcap --connect EP``.

What ``buoymon simulate --publish`` calls; the blocks go out through
:func:`monitor.publisher.play`, message by message as recorded (not coalesced), through
advanced publishers with a cache, as a sensor driver publishes (``monitor.sensors``).
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Sequence

from monitor import zenoh_io
from monitor.daemon_config import ZenohConfig
from monitor.daemon_target import endpoint_arg
from monitor.publisher import play, publisher_config
from monitor.sensors import DEFAULT_CACHE_BLOCKS, PublisherOptions
from replay.reader import iter_blocks


def publish_logs(paths: Sequence[str], zc: ZenohConfig, speed: float | None = None,
                 codec: zenoh_io.BlockCodec | None = None,
                 options: PublisherOptions = PublisherOptions(), linger_s: float = 0.0) -> int:
    """Play MCAP logs message by message (as recorded: not coalesced) over Zenoh."""
    return play(iter_blocks(list(paths), coalesce=False), zc, speed, codec, options, linger_s)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m replay.publish",
                                description="Play MCAP logs over Zenoh as a live buoy.")
    p.add_argument("logs", nargs="+", help="MCAP log files")
    p.add_argument("--connect", action="append", default=[], type=endpoint_arg,
                   help="zenoh endpoint of the daemon, e.g. tcp/127.0.0.1:7447 (repeatable)")
    p.add_argument("--speed", type=float, default=None,
                   help="times real time (default: as fast as possible)")
    p.add_argument("--cache-blocks", type=int, default=DEFAULT_CACHE_BLOCKS,
                   help="blocks kept per stream for a daemon that (re)starts later "
                        f"(default {DEFAULT_CACHE_BLOCKS})")
    p.add_argument("--linger-s", type=float, default=0.0,
                   help="keep the caches up this long after the last block (default 0)")
    args = p.parse_args(argv)
    if not args.connect:
        p.error("--connect is required (the daemon's listen endpoint)")
    # checked here: the player raised a traceback on them once the session was open
    if args.speed is not None and not 0 < args.speed < math.inf:
        p.error(f"--speed {args.speed}: must be a number > 0 (times real time)")
    if not 0 <= args.linger_s < math.inf:
        p.error(f"--linger-s {args.linger_s}: must be a number of seconds >= 0")
    try:
        options = PublisherOptions(cache_blocks=args.cache_blocks)
    except ValueError as exc:
        p.error(f"--cache-blocks: {exc}")
    n = publish_logs(args.logs, publisher_config(args.connect), args.speed, None, options,
                     args.linger_s)
    print(n, flush=True)
    if n == 0:  # missing, unreadable or empty logs: nothing went to the daemon
        print(f"python -m replay.publish: no sensor block could be read from {args.logs}",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
