"""``buoymon view FILE.rrd``: open a recording in a Rerun viewer with analytics disabled.

By default a web viewer is served on 127.0.0.1 (works on a headless server; open the printed
URL, or tunnel the two ports with ssh -L); ``--native`` starts the desktop viewer instead.
SIGTERM, SIGINT and SIGHUP stop the viewer with the command (the viewer runs in its own
session, so nothing else would); ports held by another process are refused, naming it.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from monitor.stop_signals import Stopped, stop_signals_raise


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view")
    p.add_argument("recordings", type=Path, nargs="+", help=".rrd files")
    p.add_argument("--native", action="store_true", help="desktop viewer instead of web")
    p.add_argument("--web-port", type=int, default=9090)
    p.add_argument("--grpc-port", type=int, default=9876)
    p.set_defaults(func=run)


def _head(path: Path) -> bytes:
    with open(path, "rb") as f:
        return f.read(3)


def run(args: argparse.Namespace) -> int:
    missing = [str(p) for p in args.recordings if not p.is_file()]
    if missing:
        print(f"buoymon view: no such recording: {', '.join(missing)}", file=sys.stderr)
        return 2
    # a Rerun recording starts with "RRF" and a format digit; the viewer itself shows nothing
    # for another file and exits without saying why
    other = [str(p) for p in args.recordings if _head(p) != b"RRF"]
    if other:
        print(f"buoymon view: not a Rerun recording (.rrd): {', '.join(other)}", file=sys.stderr)
        return 2
    with stop_signals_raise():
        try:
            return _serve(args)
        except Stopped as sig:
            print(f"buoymon view: {sig}: viewer stopped", file=sys.stderr)
            return 0


def _serve(args: argparse.Namespace) -> int:
    from monitor.viz.rerun_options import RerunOptions
    from monitor.viz.rerun_outputs import (analytics_disabled_env, check_ports_free,
                                           rerun_command, serve_web_viewer)

    if args.native:
        try:
            check_ports_free({"gRPC": args.grpc_port})
        except RuntimeError as exc:
            print(f"buoymon view: {exc}", file=sys.stderr)
            return 2
        # the desktop viewer also hosts a gRPC server, on all interfaces unless told otherwise;
        # subprocess.call kills it when a stop signal raises here
        cmd = rerun_command() + ["--bind", "127.0.0.1", "--port", str(args.grpc_port),
                                 *[str(p) for p in args.recordings]]
        return subprocess.call(cmd, env=analytics_disabled_env())
    try:
        opts = RerunOptions(web_port=args.web_port, grpc_port=args.grpc_port)
        viewer = serve_web_viewer(opts, recordings=tuple(args.recordings))
    except (ValueError, RuntimeError) as exc:
        print(f"buoymon view: {exc}", file=sys.stderr)
        return 2
    print(f"Rerun web viewer (127.0.0.1 only): {viewer.web_url}\nCtrl-C to stop.", flush=True)
    try:
        viewer.process.wait()
    finally:
        viewer.stop()
    return 0
