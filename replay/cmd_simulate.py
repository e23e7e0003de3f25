"""``buoymon simulate -o LOG.mcap --hours H --hs M --tp S --seed N``: a synthetic buoy log.

``--publish [ENDPOINT] [--speed X]`` also plays the simulated buoy over Zenoh to a daemon
(``replay.publish.publish_logs``: one message per 1 s block, paced by sensor time, through
advanced publishers that keep the last hour per stream for a daemon that starts or restarts
later), as a peer that only connects out. The endpoint must be on the loopback
interface unless ``--allow-remote`` is given.
"""

from __future__ import annotations

import argparse
import ipaddress
import sys
import tempfile
import time
from pathlib import Path

from monitor.cli_paths import check_output
from monitor.config import default_config
from monitor.quanta import add_quantum_option, parse_quanta
from replay.cmd_replay import MIN_SPEED
from replay.simulate import LOAD_MODELS, SimConfig, sea_state_warnings, simulate


def start_time(start: str | None, publish: str | None) -> str:
    """The log's start from ``--start``: ``now`` is the current second; when not given, the
    current second when publishing live, else 2000-01-01 (reproducible files)."""
    if start is None and publish is None:
        return "2000-01-01T00:00:00Z"
    if start is None or start.strip().lower() == "now":
        return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    return start


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "simulate",
        description="Simulate an irregular sea, the buoy's motion and the line tension through "
                    "the physics models, with sensor noise and optional faults; write an MCAP "
                    "log (20 Hz tension, 10 Hz IMU and motion, 1 Hz GNSS, 30 min waves). "
                    "Deterministic for a seed. See docs/LOG_FORMAT.md.")
    p.add_argument("-o", "--output", type=Path,
                   help="output .mcap file (required unless --publish; then kept only if given)")
    p.add_argument("--hours", type=float, required=True, help="length of the log in hours")
    p.add_argument("--hs", type=float, required=True, help="significant wave height Hs (m)")
    p.add_argument("--tp", type=float, required=True, help="peak period Tp (s)")
    p.add_argument("--seed", type=int, required=True, help="random seed (integer >= 0)")
    p.add_argument("--buoy-id", default="vaps", help="buoy id for the topics (default vaps)")
    p.add_argument("--start", default=None,
                   help="sensor time of the first sample, ISO 8601 or 'now' (the current "
                        "second: a log to publish to a daemon later, see `buoymon publish "
                        "--retime`) (default: now with --publish, so a live daemon sees no "
                        "clock skew at real-time speed; 2000-01-01T00:00:00Z otherwise, for "
                        "reproducible files)")
    p.add_argument("--mean-span", type=float, default=31.0,
                   help="mean horizontal anchor -> buoy distance in m, the steady drift "
                        "(default 31; the 40 m line in 23 m of water is straight at 32.7)")
    p.add_argument("--load-model", choices=LOAD_MODELS, default="catenary",
                   help="how line tension follows from the sea: 'catenary' = buoy motion -> "
                        "catenary + axial dynamics (default); 'wavfor' = the seed 004 WAVFOR "
                        "wave force on the held-fixed buoy plus the static pretension, an upper "
                        "bound")
    p.add_argument("--dropouts", type=float, default=0.0,
                   help="probability that a 1 s block of a stream is lost (default 0)")
    p.add_argument("--spikes", type=float, default=0.0,
                   help="probability per sample of a spike (default 0)")
    p.add_argument("--nans", type=float, default=0.0,
                   help="probability per sample of a NaN (default 0)")
    p.add_argument("--publish", nargs="?", const=DEFAULT_ENDPOINT, metavar="ENDPOINT",
                   help="also play the simulated buoy over Zenoh to the daemon listening on "
                        f"ENDPOINT (default {DEFAULT_ENDPOINT})")
    p.add_argument("--speed", type=float, metavar="X",
                   help="with --publish: X times real time (default: as fast as possible)")
    p.add_argument("--allow-remote", action="store_true",
                   help="with --publish: allow an endpoint that is not on the loopback interface")
    add_quantum_option(p)
    p.set_defaults(func=run)


DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


def check_endpoint(endpoint: str, allow_remote: bool) -> str:
    """``proto/host:port`` with a loopback host unless ``allow_remote``; ValueError otherwise."""
    proto, sep, address = endpoint.partition("/")
    host, colon, port = address.rpartition(":")
    if not sep or not colon or not proto or not port.isdigit():
        raise ValueError(f"--publish {endpoint!r}: expected PROTO/HOST:PORT, e.g. "
                         f"{DEFAULT_ENDPOINT}")
    host = host.strip("[]")
    if not allow_remote:
        try:
            loopback = host == "localhost" or ipaddress.ip_address(host).is_loopback
        except ValueError:
            loopback = False
        if not loopback:
            raise ValueError(f"--publish {endpoint!r}: {host} is not a loopback address "
                             "(pass --allow-remote to publish beyond this machine)")
    return endpoint


def run(args: argparse.Namespace) -> int:
    try:
        if args.output is None and args.publish is None:
            raise ValueError("-o/--output is required (or --publish)")
        if args.output is not None:
            check_output(args.output, [], "-o")
        if args.publish is not None:
            check_endpoint(args.publish, args.allow_remote)
        if args.speed is not None and not args.speed >= MIN_SPEED:
            raise ValueError(f"--speed {args.speed}: must be >= {MIN_SPEED:g}")
        cfg = SimConfig(hours=args.hours, hs_m=args.hs, tp_s=args.tp, seed=args.seed,
                        buoy_id=args.buoy_id, start=start_time(args.start, args.publish),
                        dropouts=args.dropouts,
                        spikes=args.spikes, nans=args.nans, mean_span_m=args.mean_span,
                        load_model=args.load_model, quanta=parse_quanta(args.quantum))
    except ValueError as e:
        print(f"buoymon simulate: {e}", file=sys.stderr)
        return 2
    for warning in sea_state_warnings(cfg):
        print(f"buoymon simulate: warning: {warning}", file=sys.stderr)
    with tempfile.TemporaryDirectory(prefix="buoymon-sim-") as tmp:
        path = args.output or Path(tmp) / "simulated.mcap"
        try:
            summary = simulate(cfg, path)
        except ValueError as e:
            print(f"buoymon simulate: {e}", file=sys.stderr)
            return 2
        print(summary.text(), flush=True)
        # the simulated mooring is seed 004's, so its break is the shipped configuration's
        breaking_N = default_config().load.breaking_load_N
        if summary.tension_N[2] > breaking_N:
            print(f"buoymon simulate: warning: the line tension reaches "
                  f"{summary.tension_N[2]:,.0f} N, above the cable's {breaking_N:,.0f} N "
                  "breaking load: the line would have parted", file=sys.stderr)
        if args.publish is not None:
            from monitor.publisher import publisher_config
            from replay.publish import publish_logs

            pace = "as fast as possible" if args.speed is None else f"at {args.speed:g}x real time"
            print(f"publishing to {args.publish} {pace} ...", flush=True)
            from monitor.zenoh_io import ProtobufCodec

            # on the wire with the log's quanta: its samples are on that grid already
            sent = publish_logs([str(path)], publisher_config([args.publish]), args.speed,
                                codec=ProtobufCodec(cfg.quanta),
                                warn=lambda text: print(f"buoymon simulate: warning: {text}",
                                                        file=sys.stderr, flush=True))
            print(f"published {sent:,} blocks on buoy/{cfg.buoy_id}/sensor/*")
    return 0
