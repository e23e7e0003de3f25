"""The ``buoymon`` command line: one subcommand per job, each defined in its own module.

Each command module exposes ``register(subparsers)`` which adds its parser and sets
``func=<callable(args) -> int>``; the callable's return value is the exit status.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import Sequence

# command name -> module that registers it (imported lazily so `buoymon --help` stays fast)
COMMANDS: dict[str, str] = {
    "simulate": "replay.cmd_simulate",
    "import": "replay.cmd_import",
    "replay": "replay.cmd_replay",
    "demo": "replay.cmd_demo",
    "design": "replay.cmd_design",
    "lab-test": "replay.cmd_lab_test",
    "forecast": "replay.cmd_forecast",
    "run": "monitor.cmd_run",
    "bridge": "monitor.cmd_bridge",
    "shore": "monitor.shore",
    "check-config": "monitor.cmd_check_config",
    "record": "monitor.cmd_record",
    "alerts": "monitor.alerts.cmd_alerts",
    "status": "monitor.cmd_status",
    "report": "monitor.viz.cmd_report",
    "view": "monitor.viz.cmd_view",
}


def build_parser(argv: Sequence[str]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="buoymon", description="Mooring-cable fatigue monitoring for moored buoys."
    )
    parser.add_argument(
        "--log-level", default="info", choices=["debug", "info", "warning", "error"],
        help="logging verbosity (structured JSON logs go to stderr)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    wanted = next((a for a in argv if a in COMMANDS), None)
    for name, module in COMMANDS.items():
        if wanted is None or name == wanted:
            importlib.import_module(module).register(sub)
        else:
            sub.add_parser(name, help=f"see `buoymon {name} --help`")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser(argv).parse_args(argv)
        from monitor.logs import setup_logging

        setup_logging(args.log_level)
        try:
            return int(args.func(args) or 0)
        except OSError as exc:
            # a file the command cannot read or write (missing folder, disk full, no access):
            # the operating system's message names the file; a traceback would add nothing
            print(f"buoymon {args.command}: {exc}", file=sys.stderr)
            return 1
    except KeyboardInterrupt:
        # Ctrl-C: a message instead of a traceback, and the shell's status for SIGINT. Reports
        # and state files are written (atomically) only at the end, so none is half-written.
        print("buoymon: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
