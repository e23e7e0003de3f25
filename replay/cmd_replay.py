"""``buoymon replay LOG.mcap [MORE.mcap | DIR ...]``: run recorded logs through the pipeline core."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from monitor.config import ConfigError, default_config, load_config
from monitor.events import Sink


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="replay MCAP logs through the fatigue pipeline")
    p.add_argument("logs", nargs="+", help="MCAP files or directories of them (replayed in time order)")
    p.add_argument("--config", help="TOML configuration (default: the seed 004 VAPS mooring)")
    p.add_argument("--report", help="write the JSON report here")
    p.add_argument("--state", help="pipeline state file: loaded if it exists, saved at the end")
    pace = p.add_mutually_exclusive_group()
    pace.add_argument("--realtime", action="store_true", help="pace the replay at sensor time")
    pace.add_argument("--speed", type=float, metavar="X", help="pace at X times real time")
    p.add_argument("--no-progress", action="store_true", help="no progress bar even on a terminal")
    p.set_defaults(func=run)


def build_sinks(args: argparse.Namespace, config: Any) -> list[Sink]:
    """Output sinks for this replay (the hook where Rerun/HTML outputs plug in)."""
    return []


def run(args: argparse.Namespace) -> int:
    from replay.report import summary_text, write_report
    from replay.runner import replay_logs

    try:
        config = load_config(args.config) if args.config else default_config()
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        return 2
    if args.speed is not None and not args.speed > 0:
        print(f"replay: --speed {args.speed}: must be > 0", file=sys.stderr)
        return 2
    speed = 1.0 if args.realtime else args.speed
    try:
        result = replay_logs(config, args.logs, state_path=args.state,
                             sinks=build_sinks(args, config), speed=speed,
                             show_progress=False if args.no_progress else None)
    except (FileNotFoundError, ValueError) as exc:
        print(f"replay: {exc}", file=sys.stderr)
        return 1
    if args.report:
        write_report(args.report, result.report)
    print(summary_text(result.report))
    if args.report:
        print(f"report: {args.report}")
    if result.samples == 0:
        print("replay: nothing could be read", file=sys.stderr)
        return 1
    return 0
