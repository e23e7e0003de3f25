"""The fleet side of ``buoymon replay``: several buoys, ``--workers``, ``--cluster``, what-if.

``buoymon replay DIR [DIR ...]`` switches to fleet mode when the logs hold more than one buoy or
any option below is given; one buoy without them stays on the single-log path
(:mod:`replay.cmd_replay`)::

    --workers N             replay N buoys at a time in local processes
    --cluster tcp://H:P     run the buoys on an existing Dask scheduler instead
    --report-dir DIR        DIR/buoys/<id>.json per buoy, DIR/fleet.json (ranked by risk);
                            with a what-if also DIR/whatif/buoys/<id>.json, DIR/whatif/fleet.json
                            and DIR/comparison.json
    --whatif FILE.toml      overrides applied to the archive (see replay.whatif) ...
    --set KEY=VALUE         ... and/or single overrides; a baseline vs what-if table is printed

``--report FILE`` writes the fleet report (or, with a what-if, the comparison) to FILE.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from monitor.config import Config, ConfigError


def add_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("fleet (several buoys)")
    g.add_argument("--workers", type=int, default=1, metavar="N",
                   help="replay N buoys in parallel local processes (default 1)")
    g.add_argument("--cluster", metavar="tcp://HOST:PORT",
                   help="run on this Dask scheduler (workers need the package and the files)")
    g.add_argument("--report-dir", metavar="DIR",
                   help="write one report per buoy and the fleet report into DIR")
    g.add_argument("--whatif", metavar="FILE.toml",
                   help="configuration overrides to compare against the baseline")
    g.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="set_",
                   help="one override, e.g. component.conductor.lay=right (repeatable)")


def wanted(args: argparse.Namespace) -> bool:
    """Fleet mode: a fleet option is given, or the logs hold other than exactly one buoy.
    The buoys found are kept in ``args.archives`` for :func:`run`, which then needs no second
    discovery (a file without a summary is read whole to find its buoys)."""
    if args.workers != 1 or args.cluster or args.report_dir or args.whatif or args.set_:
        return True
    from replay.fleet import discover

    try:
        args.archives = discover(args.logs)
    except FileNotFoundError:
        return False  # the single-log path reports the missing file
    return len(args.archives) > 1


def _check(args: argparse.Namespace) -> str | None:
    if args.workers < 1:
        return f"--workers {args.workers}: must be >= 1"
    if args.cluster and "://" not in args.cluster:
        return f"--cluster {args.cluster!r}: must be a scheduler address like tcp://HOST:PORT"
    for opt, value in (("--state", args.state), ("--realtime", args.realtime),
                       ("--speed", args.speed), ("--rrd", getattr(args, "rrd", None)),
                       ("--html", getattr(args, "html", None))):
        if value:
            return f"{opt} applies to one buoy; not with several buoys or fleet options"
    return None


def _write_json(path: str | Path, obj: Any) -> None:
    from replay.report import atomic_write_text

    atomic_write_text(path, json.dumps(obj, indent=2, allow_nan=False) + "\n")


def run(args: argparse.Namespace, config: Config) -> int:
    from replay.fleet import discover, fleet_report, fleet_summary_text, run_fleet, write_reports
    from replay.whatif import compare, comparison_text, load_whatif, run_whatif

    problem = _check(args)
    if problem:
        print(f"replay: {problem}", file=sys.stderr)
        return 2
    try:
        whatif = load_whatif(args.whatif, args.set_) if (args.whatif or args.set_) else None
        archives = getattr(args, "archives", None)
        if archives is None:
            archives = discover(args.logs)
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        return 2
    except (FileNotFoundError, ValueError) as exc:
        print(f"replay: {exc}", file=sys.stderr)
        return 1
    if not archives:
        print("replay: no buoy sensor data found in the logs", file=sys.stderr)
        return 1
    n_jobs = len(archives) * (2 if whatif else 1)
    finished = []

    def progress(buoy_id: str) -> None:
        finished.append(buoy_id)
        if not args.no_progress and sys.stderr.isatty():
            print(f"\rreplayed {len(finished)}/{n_jobs} buoy runs (last: {buoy_id})",
                  end="" if len(finished) < n_jobs else "\n", file=sys.stderr, flush=True)

    try:
        if whatif is None:
            reports = run_fleet(archives, config, workers=args.workers, cluster=args.cluster,
                                on_done=progress)
            alt_reports: list = []
        else:
            reports, alt_reports = run_whatif(archives, config, whatif, workers=args.workers,
                                              cluster=args.cluster, on_done=progress)
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        return 2
    fleet = fleet_report(reports)
    print(fleet_summary_text(fleet))
    table = None
    if whatif is not None:
        table = compare(reports, alt_reports, whatif.name)
        print(comparison_text(table))
    if args.report_dir:
        write_reports(args.report_dir, reports, fleet)
        if whatif is not None:
            write_reports(Path(args.report_dir) / "whatif", alt_reports, fleet_report(alt_reports))
            _write_json(Path(args.report_dir) / "comparison.json", table)
        print(f"reports: {args.report_dir}")
    if args.report:
        _write_json(args.report, table if table is not None else fleet)
        print(f"report: {args.report}")
    empty = [r["buoy_id"] for r in reports if not any(
        s["accepted"] or any(s["rejected"].values()) for s in r["samples"].values())]
    if empty:
        print(f"replay: nothing could be read for buoy(s) {', '.join(empty)}", file=sys.stderr)
    return 1 if len(empty) == len(reports) else 0
