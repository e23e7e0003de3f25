"""``buoymon simulate -o LOG.mcap --hours H --hs M --tp S --seed N``: a synthetic buoy log."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from replay.simulate import LOAD_MODELS, SimConfig, simulate


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "simulate", help="write a synthetic buoy log (sea -> motion -> tension -> sensors)",
        description="Simulate an irregular sea, the buoy's motion and the line tension through "
                    "the physics models, with sensor noise and optional faults; write an MCAP "
                    "log (20 Hz tension, 10 Hz IMU and motion, 1 Hz GNSS, 30 min waves). "
                    "Deterministic for a seed. See docs/LOG_FORMAT.md.")
    p.add_argument("-o", "--output", type=Path, required=True, help="output .mcap file")
    p.add_argument("--hours", type=float, required=True, help="length of the log in hours")
    p.add_argument("--hs", type=float, required=True, help="significant wave height Hs (m)")
    p.add_argument("--tp", type=float, required=True, help="peak period Tp (s)")
    p.add_argument("--seed", type=int, required=True, help="random seed (integer >= 0)")
    p.add_argument("--buoy-id", default="vaps", help="buoy id for the topics (default vaps)")
    p.add_argument("--start", default="2000-01-01T00:00:00Z",
                   help="sensor time of the first sample, ISO 8601 (default 2000-01-01T00:00:00Z)")
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
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        cfg = SimConfig(hours=args.hours, hs_m=args.hs, tp_s=args.tp, seed=args.seed,
                        buoy_id=args.buoy_id, start=args.start, dropouts=args.dropouts,
                        spikes=args.spikes, nans=args.nans, mean_span_m=args.mean_span,
                        load_model=args.load_model)
    except ValueError as e:
        print(f"buoymon simulate: {e}", file=sys.stderr)
        return 2
    try:
        summary = simulate(cfg, args.output)
    except ValueError as e:
        print(f"buoymon simulate: {e}", file=sys.stderr)
        return 2
    print(summary.text())
    return 0
