"""``buoymon report R.json -o report.html``: the replay report as a readable HTML page."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        description="Render the JSON report written by `buoymon replay --report` as one "
                    "self-contained HTML page; the plots are also written beside it as PNG files.")
    p.add_argument("report", type=Path, help="report JSON from `buoymon replay --report`")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="HTML file to write (default: the report's name with .html)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monitor.viz.html_report import write_report
    from monitor.viz.report_data import load_report

    from monitor.cli_paths import check_output

    out = args.output or args.report.with_suffix(".html")
    try:
        check_output(out, [args.report], "-o")
        rendered = write_report(load_report(args.report), out)
    except ValueError as exc:
        print(f"buoymon report: {exc}", file=sys.stderr)
        return 2
    pngs = [str(p) for p in rendered.png_paths.values()]
    log.info("report written",
             extra={"fields": {"html": str(rendered.html_path), "png": pngs}})
    print(f"report: {rendered.html_path} (open it in a browser); plots: "
          f"{', '.join(p.name for p in rendered.png_paths.values())}")
    return 0
