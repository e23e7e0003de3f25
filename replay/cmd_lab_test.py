"""``buoymon lab-test``: seed 004's lab fatigue test through the monitor, predicted against observed.

Appendix 2 (c) cycled the cable from 0 to F kN at 13.6 cycles/min until the #22 AWG conductors
opened (8.9 kN: 25.0e3 cycles; 9.8 kN: 17.1e3 and 27.0e3). The command feeds that tension as a
synthetic load-cell log through the pipeline with the configuration's components and prints,
per component, the predicted cycles to failure beside the observed ones (docs/CONDUCTOR.md).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from monitor.config import ConfigError, default_config, load_config


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "lab-test",
        description="Feed the seed 004 lab fatigue test (0 to F kN at 13.6 cycles/min) through "
                    "the pipeline and compare each component's predicted cycles to failure "
                    "with the observed failures.")
    p.add_argument("--config", type=Path, default=None,
                   help="configuration (default: the shipped seed 004 configuration)")
    p.add_argument("--cycles", type=int, default=200,
                   help="cam cycles fed per load (default 200; life = cycles / damage)")
    p.add_argument("--json", action="store_true", help="print the table as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from replay.lab_validation import lab_validation

    if args.cycles < 2:
        print(f"lab-test: --cycles {args.cycles}: must be >= 2", file=sys.stderr)
        return 2
    try:
        config = default_config() if args.config is None else load_config(args.config)
    except ConfigError as exc:
        print(f"lab-test: {exc}", file=sys.stderr)
        return 2
    rows = lab_validation(config, args.cycles)
    table = [{"load_N": r.load_N, "observed_cycles": r.observed_cycles,
              "predicted_cycles": {n: (None if math.isinf(v) else v)
                                   for n, v in r.predicted_cycles.items()}} for r in rows]
    if args.json:
        print(json.dumps({"rows": table}, indent=1))
        return 0
    curves = {c.name: c.sn_curve.preset or "table" for c in config.components}
    print("Seed 004 lab fatigue test (App. 2 c): 0 -> F kN at 13.6 cycles/min through the monitor;")
    print("stress range = the peak of the 0-to-F cycle, no mean-stress correction; "
          "predicted = cycles fed / damage")
    names = list(curves)
    print(f"  {'load':>7s} {'observed':>9s}" + "".join(f" {n[:28]:>28s}" for n in names))
    print(f"  {'':>7s} {'':>9s}" + "".join(f" {'(' + curves[n][:26] + ')':>28s}" for n in names))
    for r in rows:
        cells = []
        for n in names:
            p = r.predicted_cycles[n]
            cells.append("no damage" if math.isinf(p) else f"{p:,.0f} (x{p / r.observed_cycles:.2f})")
        print(f"  {r.load_N / 1e3:5.1f} kN {r.observed_cycles:9,.0f}" + "".join(f" {c:>28s}" for c in cells))
    return 0
