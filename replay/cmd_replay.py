"""``buoymon replay LOG.mcap [MORE.mcap | DIR ...]``: run recorded logs through the pipeline core."""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
from pathlib import Path
from typing import Any, Iterator, Sequence

from monitor.cli_paths import check_output
from monitor.config import ConfigError, default_config, load_config
from monitor.events import Sink
from monitor.stop_signals import Stopped, stop_signals_raise
from replay import cmd_fleet


# slowest pace: a millionth of real time already stretches a 1 s block to 12 days; slower
# ones overflow the sleep
MIN_SPEED = 1e-6


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay")
    p.add_argument("logs", nargs="+", help="MCAP files or directories of them (replayed in time order)")
    p.add_argument("--config", help="TOML configuration (default: the seed 004 VAPS mooring)")
    p.add_argument("--report", help="write the JSON report here")
    p.add_argument("--state", help="pipeline state file: loaded if it exists, saved at the end")
    pace = p.add_mutually_exclusive_group()
    pace.add_argument("--realtime", action="store_true", help="pace the replay at sensor time")
    pace.add_argument("--speed", type=float, metavar="X", help="pace at X times real time")
    p.add_argument("--no-progress", action="store_true", help="no progress bar even on a terminal")
    p.add_argument("--rrd", metavar="FILE.rrd",
                   help="also write a Rerun recording (open it with `buoymon view FILE.rrd`); "
                        "written as FILE.partial.rrd and renamed when the replay ends well, so "
                        "an interrupted replay leaves only the .partial.rrd")
    p.add_argument("--html", metavar="FILE.html",
                   help="also write the HTML fatigue report (and its plots as PNG beside it); "
                        "the --report JSON then carries the plot fields too")
    processes = p.add_mutually_exclusive_group()
    processes.add_argument("--one-process", dest="two_processes", action="store_false",
                           default=None,
                           help="replay in this process only (by default the logs are read "
                                "and validated in a second process when that pays: Linux, "
                                "logs of about a day or more, 2+ idle CPUs; same results)")
    processes.add_argument("--two-processes", dest="two_processes", action="store_true",
                           help="a second process as by default, saying why not when it is "
                                "not used")
    cmd_fleet.add_arguments(p)
    p.set_defaults(func=run)


def partial_path(rrd: str | Path) -> Path:
    """Where ``--rrd FILE.rrd`` is written until the replay has ended well: FILE.partial.rrd."""
    p = Path(rrd)
    return p.with_name(f"{p.stem}.partial{p.suffix}" if p.suffix else f"{p.name}.partial")


def build_sinks(args: argparse.Namespace, config: Any) -> list[Sink]:
    """Output sinks for this replay: the Rerun recording of ``--rrd`` (bulk preset), written
    to its :func:`partial_path` (see :func:`recording_kept_whole`)."""
    if not getattr(args, "rrd", None):
        return []
    from monitor.viz.pipeline_sinks import open_rerun

    return [open_rerun(config, rrd=partial_path(args.rrd), replay=True)]


@contextlib.contextmanager
def recording_kept_whole(rrd: str | None, sinks: Sequence[Sink]) -> Iterator[None]:
    """The ``--rrd`` recording takes its name only when the block ends well (the replay closed
    it whole); otherwise (Ctrl-C, SIGTERM, an error) what was recorded is flushed and left as
    its :func:`partial_path`, named on stderr: no partial recording under the full name."""
    try:
        yield
    except BaseException:
        partial = partial_path(rrd) if rrd else None
        if partial is not None and partial.exists():
            for sink in sinks:
                with contextlib.suppress(Exception):  # what it holds is what is kept
                    sink.close()
            print(f"replay: the Rerun recording is partial, kept as {partial} (the replay did "
                  f"not finish; {rrd} not written)", file=sys.stderr)
        raise
    if rrd:
        os.replace(partial_path(rrd), rrd)


def write_html(path: str, report: dict) -> list[str]:
    """Render the report as HTML + PNGs; the paths written."""
    from monitor.viz.html_report import write_report as write_html_report
    from monitor.viz.report_data import parse_report

    rendered = write_html_report(parse_report(report), path)
    return [str(rendered.html_path), *map(str, rendered.png_paths.values())]


def run(args: argparse.Namespace) -> int:
    from replay.log_files import expand_paths

    try:
        config = load_config(args.config) if args.config else default_config()
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        return 2
    if args.speed is not None and not args.speed >= MIN_SPEED:
        print(f"replay: --speed {args.speed}: must be >= {MIN_SPEED:g}", file=sys.stderr)
        return 2
    try:
        inputs = expand_paths(args.logs, recursive=True)  # as the replay reads them
        for option in ("report", "html", "rrd"):
            if getattr(args, option):
                check_output(getattr(args, option), inputs, f"--{option}")
        if args.report_dir and Path(args.report_dir).exists() and not Path(args.report_dir).is_dir():
            raise ValueError(f"--report-dir {args.report_dir}: is a file, expected a folder")
    except ValueError as exc:
        print(f"replay: {exc}", file=sys.stderr)
        return 2
    if not inputs:
        print(f"replay: no log files in {args.logs}", file=sys.stderr)
        return 1
    args.logs = [str(p) for p in inputs]  # folders expanded once: each warning said once
    if cmd_fleet.wanted(args):
        if args.two_processes:  # asked for: say why not, as a single buoy's replay does
            print("replay: --two-processes not used: a fleet replay runs each buoy in one "
                  "process (--workers N of them at once)", file=sys.stderr)
        return cmd_fleet.run(args, config)
    # SIGTERM and SIGHUP end a buoy's replay as Ctrl-C's KeyboardInterrupt does: reports and
    # state are written only at the end (none half-written), a partial recording is named.
    # (Not a fleet's: its pool would finish every buoy before it let the exception out.)
    with stop_signals_raise((signal.SIGTERM, signal.SIGHUP)):
        try:
            return _replay_one(args, config)
        except Stopped as stop:
            print(f"buoymon: stopped ({stop})", file=sys.stderr)
            return stop.exit_status


def _replay_one(args: argparse.Namespace, config: Any) -> int:
    """One buoy's replay of ``args.logs`` (expanded), with ``config``: the exit status."""
    from replay.report import summary_text, write_report
    from replay.runner import replay_logs
    from replay.stage_process import ChildDied

    speed = 1.0 if args.realtime else args.speed
    existed = bool(args.rrd) and partial_path(args.rrd).exists()
    try:
        sinks = build_sinks(args, config)
    except (ValueError, RuntimeError, OSError) as exc:  # the disk's (full, read-only): exit 1
        print(f"replay: --rrd {args.rrd}: cannot write the recording: {exc}", file=sys.stderr)
        if not existed:  # no empty recording left to be taken for one
            partial_path(args.rrd).unlink(missing_ok=True)
        return 1
    try:
        with recording_kept_whole(args.rrd, sinks):
            result = replay_logs(config, args.logs, state_path=args.state, sinks=sinks,
                                 speed=speed, show_progress=False if args.no_progress else None,
                                 plot_fields=bool(args.html), two_processes=args.two_processes)
    except ConfigError as exc:  # found when the pipeline is built (rules, cable, S-N curves)
        print(exc, file=sys.stderr)
        return 2
    except (FileNotFoundError, ValueError) as exc:
        print(f"replay: {exc}", file=sys.stderr)
        return 1
    except ChildDied as exc:  # killed, out of memory: --state unchanged
        print(f"replay: {exc}; no report or state written, run it again", file=sys.stderr)
        return 1
    if args.report:
        write_report(args.report, result.report)
    print(summary_text(result.report))
    if args.report:
        print(f"report: {args.report}")
    if args.rrd:
        print(f"rerun recording: {args.rrd} (open it with `buoymon view {args.rrd}`)")
    if args.html and result.samples:
        print(f"html report: {write_html(args.html, result.report)[0]} (open it in a browser)")
    if result.samples == 0:
        print("replay: nothing could be read", file=sys.stderr)
        return 1
    return 0
