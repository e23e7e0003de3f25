"""Play MCAP logs over Zenoh as a live buoy: ``buoymon publish LOG.mcap [--connect EP]``
(also ``python -m replay.publish``).

What ``buoymon simulate --publish`` calls; the blocks go out through
:func:`monitor.publisher.play`, message by message as recorded (not coalesced), through
advanced publishers with a cache, as a sensor driver publishes (``monitor.sensors``).

A daemon judges each block's sensor time against its own clock (``clock_skew``, and
``time_ahead`` rejects samples more than ``max_ahead_s`` ahead): a log recorded or simulated
at another time (``buoymon simulate`` dates its logs 2000-01-01 unless ``--start`` says
otherwise) is re-timed with ``--retime now`` (or an ISO time): every sample moves by the same
whole number of seconds, the first to that time. Blocks published more than
:data:`CLOCK_OFF_S` off this machine's clock are said on stderr (the first at once, then how
many), with what to do about it.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from typing import Callable, Iterable, Iterator, Sequence

from monitor import zenoh_io
from monitor.blocks import SampleBlock
from monitor.daemon_config import ZenohConfig
from monitor.daemon_target import DEFAULT_CONNECT, endpoint_arg
from monitor.publisher import play, publisher_config
from monitor.sensors import DEFAULT_CACHE_BLOCKS, PublisherOptions
from monitor.time_ahead import DEFAULT_MAX_AHEAD_S
from replay.csv_import import parse_iso_ns
from replay.reader import iter_blocks
from replay.report import iso_utc

# a block this far off the publishing clock raises the daemon's clock_skew (its [health]
# clock_skew_max_s default); ahead by more, its samples are rejected as time_ahead
CLOCK_OFF_S = DEFAULT_MAX_AHEAD_S
NS = 1_000_000_000


def retime_target(text: str, clock: Callable[[], int] = time.time_ns) -> int:
    """``--retime``'s time in ns: ``now`` (this clock's current second) or an ISO 8601 time;
    ValueError naming the text otherwise."""
    if text.strip().lower() == "now":
        return clock() // NS * NS
    return parse_iso_ns(text)


def retimed(blocks: Iterable[SampleBlock], target_ns: int) -> Iterator[SampleBlock]:
    """``blocks`` with every sample (and receive) time moved by one whole number of seconds:
    the first block's first sample to ``target_ns`` (within half a second; the samples' phase
    within the second, their spacing and their order are kept)."""
    shift = None
    for block in blocks:
        if shift is None:
            shift = round((target_ns - block.t_first_ns) / NS) * NS
        yield dataclasses.replace(block, t_ns=block.t_ns + shift,
                                  recv_ns=block.recv_ns + shift if block.recv_ns else 0)


def _duration(s: float) -> str:
    """``s`` seconds in words a reader takes in at once (3.2 h, 26.9 years)."""
    for unit, size in (("years", 365.25 * 86400), ("days", 86400), ("h", 3600), ("min", 60)):
        if s >= 2 * size:
            return f"{s / size:.3g} {unit}"
    return f"{s:.3g} s"


class ClockCheck:
    """Pass blocks through, comparing each one's newest sample time with ``clock`` right
    after it was sent (when the next is asked for): a daemon on a clock like this one sees
    the same distance. ``warn`` gets a message at the first block more than
    :data:`CLOCK_OFF_S` off; :attr:`off` counts them, :attr:`blocks` all."""

    def __init__(self, blocks: Iterable[SampleBlock], warn: Callable[[str], None],
                 retimed: bool, clock: Callable[[], int] = time.time_ns) -> None:
        self._blocks = blocks
        self._warn = warn
        self._retimed = retimed
        self._clock = clock
        self.off = 0
        self.blocks = 0

    def __iter__(self) -> Iterator[SampleBlock]:
        for block in self._blocks:
            yield block
            self.blocks += 1
            off_s = (block.t_last_ns - self._clock()) / NS
            if abs(off_s) > CLOCK_OFF_S:
                if not self.off:
                    self._warn(self._first_message(block, off_s))
                self.off += 1

    def _first_message(self, block: SampleBlock, off_s: float) -> str:
        way = "ahead of" if off_s > 0 else "behind"
        if off_s < 0 and not self._retimed:
            fix = "re-time it with --retime now"
        elif off_s > 0 and not self._retimed:
            fix = "re-time it with --retime now, and publish at real time (--speed 1)"
        else:  # re-timed: a log played faster than real time runs away from the clock
            fix = "publish at real time (--speed 1) to keep a re-timed log on the clock"
        rejected = (f"; samples more than {CLOCK_OFF_S:g} s ahead are rejected as time_ahead"
                    if off_s > 0 else "")
        return (f"the log's sensor time ({iso_utc(block.t_last_ns)}, {block.sensor}) is "
                f"{_duration(abs(off_s))} {way} this machine's clock: a daemon raises "
                f"clock_skew for blocks more than {CLOCK_OFF_S:g} s off{rejected}; {fix}")

    def summary(self) -> str | None:
        """How many blocks went out off the clock, or None if none did."""
        if not self.off:
            return None
        return (f"{self.off:,} of {self.blocks:,} blocks were published more than "
                f"{CLOCK_OFF_S:g} s off this machine's clock")


def publish_logs(paths: Sequence[str], zc: ZenohConfig, speed: float | None = None,
                 codec: zenoh_io.BlockCodec | None = None,
                 options: PublisherOptions = PublisherOptions(), linger_s: float = 0.0,
                 retime_ns: int | None = None,
                 warn: Callable[[str], None] | None = None) -> int:
    """Play MCAP logs message by message (as recorded: not coalesced) over Zenoh; with
    ``retime_ns`` the first sample at that time (:func:`retimed`); blocks off this machine's
    clock are told to ``warn`` (default: stderr) as they go and in one line at the end."""
    warn = warn or (lambda text: print(f"publish: warning: {text}", file=sys.stderr,
                                       flush=True))
    blocks: Iterable[SampleBlock] = iter_blocks(list(paths), coalesce=False)
    if retime_ns is not None:
        blocks = retimed(blocks, retime_ns)
    check = ClockCheck(blocks, warn, retime_ns is not None)
    sent = play(check, zc, speed, codec, options, linger_s)
    summary = check.summary()
    if summary is not None:
        warn(summary)
    return sent


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``buoymon publish`` and ``python -m replay.publish``."""
    p.add_argument("logs", nargs="+", help="MCAP log files")
    p.add_argument("--connect", action="append", default=[], type=endpoint_arg,
                   metavar="ENDPOINT",
                   help="zenoh endpoint of the daemon (repeatable; default "
                        f"{DEFAULT_CONNECT})")
    p.add_argument("--speed", type=float, default=None, metavar="X",
                   help="times real time (default: as fast as possible)")
    p.add_argument("--retime", metavar="now|TIME",
                   help="move every sample time by one whole number of seconds so that the "
                        "log starts now (or at the ISO 8601 TIME): a daemon judges sensor "
                        "times against its clock (clock_skew, time_ahead); with --speed 1 the "
                        "log then stays on the clock")
    p.add_argument("--cache-blocks", type=int, default=DEFAULT_CACHE_BLOCKS, metavar="N",
                   help="blocks kept per stream for a daemon that (re)starts later "
                        f"(default {DEFAULT_CACHE_BLOCKS})")
    p.add_argument("--linger-s", type=float, default=0.0, metavar="S",
                   help="keep the caches up this long after the last block (default 0)")


def run(args: argparse.Namespace, p: argparse.ArgumentParser) -> int:
    """Publish as ``args`` say; usage errors through ``p.error`` (exit status 2)."""
    # checked here: the player raised a traceback on them once the session was open
    if args.speed is not None and not 0 < args.speed < math.inf:
        p.error(f"--speed {args.speed}: must be a number > 0 (times real time)")
    if not 0 <= args.linger_s < math.inf:
        p.error(f"--linger-s {args.linger_s}: must be a number of seconds >= 0")
    try:
        options = PublisherOptions(cache_blocks=args.cache_blocks)
    except ValueError as exc:
        p.error(f"--cache-blocks: {exc}")
    try:
        retime_ns = None if args.retime is None else retime_target(args.retime)
    except ValueError as exc:
        p.error(f"--retime: {exc} (or 'now')")

    def warn(text: str) -> None:
        print(f"{p.prog}: warning: {text}", file=sys.stderr, flush=True)

    n = publish_logs(args.logs, publisher_config(args.connect or [DEFAULT_CONNECT]),
                     args.speed, None, options, args.linger_s, retime_ns, warn)
    print(n, flush=True)
    if n == 0:  # missing, unreadable or empty logs: nothing went to the daemon
        print(f"{p.prog}: no sensor block could be read from {args.logs}", file=sys.stderr)
        return 1
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "publish",
        description="Play MCAP logs over Zenoh to a daemon as a live buoy (advanced "
                    "publishers with a cache, as a sensor driver); prints the number of "
                    "blocks sent. See docs/DAEMON.md.")
    add_arguments(p)
    p.set_defaults(func=lambda args: run(args, p))


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m replay.publish",
                                description="Play MCAP logs over Zenoh as a live buoy.")
    add_arguments(p)
    return run(p.parse_args(argv), p)


if __name__ == "__main__":
    sys.exit(main())
