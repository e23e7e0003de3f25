"""``buoymon import FILE.csv -o LOG.mcap``: turn a measurement CSV into a buoymon log."""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

from monitor.blocks import validate_buoy_id
from monitor.cli_paths import check_output
from replay.csv_import import DEFAULT_START, read_csv
from replay.writer import LogWriter, Series


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "import",
        description="Convert a CSV (time_s or time column, <channel>_<unit> columns) into an "
                    "MCAP log with ~1 s blocks. Bad rows are reported with line numbers and "
                    "skipped. See docs/LOG_FORMAT.md.")
    p.add_argument("csv", type=Path, help="input CSV file")
    p.add_argument("-o", "--output", type=Path, required=True, help="output .mcap file")
    p.add_argument("--buoy-id", help="buoy id for the topics (default: the CSV file name stem)")
    p.add_argument("--start", default=DEFAULT_START,
                   help=f"instant that time_s = 0 stands for (ISO 8601, default {DEFAULT_START}; "
                        "use 1970-01-01T00:00:00Z when time_s is Unix time)")
    p.add_argument("--block-s", type=float, default=1.0, help="block length in seconds (default 1)")
    p.add_argument("--max-errors", type=int, default=100, metavar="N",
                   help="bad rows listed one by one (default 100; 0 lists all); the rest are "
                        "counted by reason")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        buoy_id = validate_buoy_id(args.buoy_id if args.buoy_id is not None else args.csv.stem)
        if not 1e-9 <= args.block_s <= 1e9:
            raise ValueError(f"--block-s {args.block_s}: must be between 1e-9 (1 ns) and 1e9")
        check_output(args.output, [args.csv], "-o")
        data = read_csv(args.csv, start=args.start)
    except (ValueError, OSError) as e:
        hint = "" if args.buoy_id is not None else " (or pass --buoy-id)"
        print(f"buoymon import: {e}{hint if 'buoy id' in str(e) else ''}", file=sys.stderr)
        return 2
    shown = data.bad_rows if args.max_errors <= 0 else data.bad_rows[:args.max_errors]
    for bad in shown:
        print(f"{args.csv}: {bad}", file=sys.stderr)
    rest = data.bad_rows[len(shown):]
    if rest:
        reasons = Counter(b.reason.split(":")[0] for b in rest)
        print(f"{args.csv}: ... and {len(rest)} more bad rows (" + ", ".join(
            f"{n} {r}" for r, n in reasons.most_common()) + "); --max-errors 0 lists them all",
            file=sys.stderr)
    if data.rows_accepted == 0:
        print(f"buoymon import: no valid rows in {args.csv}; nothing written\n{data.summary()}",
              file=sys.stderr)
        return 1
    with LogWriter(args.output) as w:
        messages = w.write_series(
            [Series(buoy_id, sensor, t, v) for sensor, (t, v) in data.sensors.items()],
            block_ns=int(round(args.block_s * 1e9)))
    print(data.summary())
    print(f"wrote {messages} messages for buoy {buoy_id} to {args.output}")
    return 0
