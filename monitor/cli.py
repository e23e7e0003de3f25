"""The ``buoymon`` command line: one subcommand per job, each defined in its own module.

Each command module exposes ``register(subparsers)`` which adds its parser and sets
``func=<callable(args) -> int>``; the callable's return value is the exit status.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from typing import Sequence

from monitor.numba_setup import prepare_numba

# command name -> (module that registers it, one-line summary for `buoymon --help`). A
# module is imported only when its command runs: importing all of them (numpy, numba,
# mcap...) made `buoymon --help` take 0.65 s instead of 0.03 s (bench/bench_startup.py).
COMMANDS: dict[str, tuple[str, str]] = {
    "simulate": ("replay.cmd_simulate",
                 "write a synthetic buoy log (sea -> motion -> tension -> sensors)"),
    "import": ("replay.cmd_import", "convert a measurement CSV into an MCAP log"),
    "replay": ("replay.cmd_replay", "replay MCAP logs through the fatigue pipeline"),
    "demo": ("replay.cmd_demo", "simulate and replay the seed 004 storm (1980, VAPS)"),
    "warmup": ("replay.cmd_warmup", "compile the numerical kernels into their on-disk cache "
               "(at install and service start, so that no command has to)"),
    "design": ("replay.cmd_design",
               "annual damage and design life per component from a sea-state record"),
    "lab-test": ("replay.cmd_lab_test",
                 "seed 004's lab fatigue test through the monitor: predicted vs observed"),
    "forecast": ("replay.cmd_forecast", "projected fatigue damage over a sea-state forecast"),
    "publish": ("replay.publish", "play MCAP logs over Zenoh to a daemon as a live buoy "
                "(--retime now: moved to the current time)"),
    "run": ("monitor.cmd_run", "run the live monitoring daemon (Zenoh in, status out)"),
    "bridge": ("monitor.cmd_bridge", "read instruments (serial, TCP, UDP, files, stdin) and "
               "publish their samples to the monitor"),
    "shore": ("monitor.shore", "follow every buoy on the Zenoh network (shore side)"),
    "check-config": ("monitor.cmd_check_config", "validate a configuration file"),
    "record": ("monitor.cmd_record", "record a buoy's Zenoh traffic to MCAP files"),
    "alerts": ("monitor.alerts.cmd_alerts", "list, acknowledge or reset alerts"),
    "status": ("monitor.cmd_status", "show a running daemon's status (or its last checkpoint)"),
    "report": ("monitor.viz.cmd_report",
               "render a replay report (JSON) as self-contained HTML with PNG plots"),
    "view": ("monitor.viz.cmd_view", "open .rrd recordings in a Rerun viewer (analytics off)"),
}

# commands that run the compiled models: the first run after an install says it compiles
COMPUTING = {"simulate", "import", "replay", "demo", "design", "forecast", "run", "publish"}


class _Subcommands(argparse._SubParsersAction):
    """Subparsers whose ``add_parser`` fills in the command's summary from ``COMMANDS``."""

    def add_parser(self, name: str, **kwargs):  # type: ignore[override]
        kwargs.setdefault("help", COMMANDS[name][1])
        return super().add_parser(name, **kwargs)


def build_parser(argv: Sequence[str]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="buoymon", description="Mooring-cable fatigue monitoring for moored buoys."
    )
    parser.add_argument(
        "--log-level", default="info", choices=["debug", "info", "warning", "error"],
        help="logging verbosity (structured JSON logs go to stderr)",
    )
    parser.register("action", "parsers", _Subcommands)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    wanted = next((a for a in argv if a in COMMANDS), None)
    for name, (module, _) in COMMANDS.items():
        if name == wanted:
            importlib.import_module(module).register(sub)
        else:
            sub.add_parser(name)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    prepare_numba()  # before any command module is imported: some import numba
    try:
        args = build_parser(argv).parse_args(argv)
        from monitor.logs import setup_logging

        setup_logging(args.log_level)
        if args.command in COMPUTING:
            from monitor.first_run import announce_compiles

            announce_compiles()
        try:
            return int(args.func(args) or 0)
        except BrokenPipeError:
            # the reader of stdout went away (`| head`, a pager quit): not a failure; stdout
            # to /dev/null so the interpreter's final flush does not raise again
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 0
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
