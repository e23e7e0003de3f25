"""``buoymon design --scatter FILE``: annual fatigue damage and design life per component.

The sea-state records (hourly Hs and period, e.g. a decade of NDBC data) are binned into a
scatter table; each occupied (Hs, Tp) bin is simulated once with the simulator's load model
(:mod:`replay.sea_state_damage`) and its damage rate, times the hours the records spent in
it, scaled to a year, gives the annual damage (seed 004 App. 6 asks exactly this: how long
does the cable last in this lake's wave climate). The Dirlik spectral damage of each bin is
shown beside it; bins where the two differ by more than ``--flag-factor`` are counted.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from models.environment import HOURS_PER_YEAR
from models.waves import breaking_height
from monitor.config import ConfigError, default_config, load_config
from replay.sea_state_files import read_sea_states


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "design",
        description="Bin hourly sea states into a scatter table, simulate each occupied bin "
                    "with the simulator's load model, and give each component's annual "
                    "fatigue damage (rainflow, and Dirlik as a cross-check) and design life.")
    p.add_argument("--scatter", type=Path, required=True,
                   help="sea-state records (CSV time,hs_m,tp_s; NDBC text; or the "
                        "'YYYY-MM-DD-HH; Hs; Tz' benchmark format)")
    p.add_argument("--config", type=Path, default=None, help="configuration (default: the "
                   "shipped seed 004 configuration)")
    p.add_argument("--load-model", choices=("wavfor", "catenary"), default="wavfor",
                   help="simulator load model (default wavfor: the seed 004 upper bound)")
    p.add_argument("--hs-bin", type=float, default=0.5, help="Hs bin width, m (default 0.5)")
    p.add_argument("--tp-bin", type=float, default=1.0, help="Tp bin width, s (default 1)")
    p.add_argument("--duration", type=float, default=1200.0,
                   help="simulated seconds per bin (default 1200)")
    p.add_argument("--flag-factor", type=float, default=3.0,
                   help="flag bins where Dirlik and rainflow damage differ by more (default 3)")
    p.add_argument("--json", type=Path, default=None, help="write the result as JSON here")
    p.set_defaults(func=run)


def design(config_path: Path | None, scatter: Path, load_model: str = "wavfor",
           hs_bin: float = 0.5, tp_bin: float = 1.0, duration_s: float = 1200.0,
           flag_factor: float = 3.0) -> dict:
    """The design check as a JSON-ready dict (see the module docstring)."""
    from replay.sea_state_damage import physics_damage  # noqa: PLC0415 (scipy: 0.3 s)

    for name, v in (("hs_bin", hs_bin), ("tp_bin", tp_bin), ("duration", duration_s)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"--{name.replace('_', '-')} {v!r}: must be > 0")
    if not (math.isfinite(flag_factor) and flag_factor > 1):
        raise ValueError(f"--flag-factor {flag_factor!r}: must be > 1")
    config = load_config(config_path) if config_path else default_config()
    ss = read_sea_states(scatter)
    record_h = float(np.median(np.diff(ss.t_s))) / 3600.0 if len(ss) > 1 else 1.0
    i = np.floor(ss.hs_m / hs_bin).astype(np.int64)
    j = np.floor(ss.tp_s / tp_bin).astype(np.int64)
    cells, counts = np.unique(np.stack([i, j], axis=1), axis=0, return_counts=True)
    hs_c = (cells[:, 0] + 0.5) * hs_bin
    tp_c = (cells[:, 1] + 0.5) * tp_bin
    hours = counts * record_h
    dmg = physics_damage(config, hs_c, tp_c, load_model, duration_s)
    per_year = HOURS_PER_YEAR / hours.sum()
    out: dict = {"records": len(ss), "skipped": dict(ss.skipped),
                 # Hs above the breaking height of its Tp in the mooring's depth: a record
                 # that cannot be a sea (a corrupt row), yet simulated like the rest
                 "records_breaking": int(np.sum(ss.hs_m > breaking_height(
                     ss.tp_s, config.mooring.depth_m))),
                 "hours": float(hours.sum()),
                 "record_hours": record_h, "bins": int(cells.shape[0]),
                 "load_model": load_model, "buoy_id": config.buoy.id, "components": {}}
    for c, name in enumerate(dmg.components):
        rf = dmg.rainflow_per_hour[c] * hours
        sp = dmg.dirlik_per_hour[c] * hours
        annual, annual_sp = float(rf.sum() * per_year), float(sp.sum() * per_year)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = dmg.dirlik_per_hour[c] / dmg.rainflow_per_hour[c]
        flagged = int(np.sum((ratio > flag_factor) | (ratio < 1.0 / flag_factor)))
        worst = int(np.argmax(rf))
        out["components"][name] = {
            "annual_damage": annual,
            "design_life_years": (1.0 / annual) if annual > 0 else None,
            "annual_damage_dirlik": annual_sp,
            "bins_flagged_non_gaussian": flagged,
            "worst_bin": {"hs_m": float(hs_c[worst]), "tp_s": float(tp_c[worst]),
                          "hours": float(hours[worst]), "share": float(rf[worst] / rf.sum())
                          if rf.sum() > 0 else 0.0},
        }
    out["max_tension_N"] = float(dmg.max_tension_N.max())
    return out


def run(args: argparse.Namespace) -> int:
    try:
        result = design(args.config, args.scatter, args.load_model, args.hs_bin, args.tp_bin,
                        args.duration, args.flag_factor)
    except ConfigError as e:
        print(e, file=sys.stderr)
        return 2
    except (ValueError, OSError) as e:
        print(f"buoymon design: {e}", file=sys.stderr)
        return 2
    skipped = "; ".join(f"{n} {why}" for why, n in sorted(result["skipped"].items()))
    print(f"{result['records']:,} sea states ({result['hours'] / HOURS_PER_YEAR:.1f} years) in "
          f"{result['bins']} Hs/Tp bins, {result['load_model']} load model"
          + (f"; {result['records_breaking']} not a possible sea (Hs above the breaking "
             "height of its Tp)" if result["records_breaking"] else "")
          + (f"; rows skipped: {skipped}" if skipped else ""))
    for name, c in result["components"].items():
        life = c["design_life_years"]
        life_s = "no damage" if life is None else _years(life)
        w = c["worst_bin"]
        print(f"  {name}: annual damage {c['annual_damage']:.3g} (Dirlik {c['annual_damage_dirlik']:.3g}), "
              f"design life {life_s}; worst bin Hs {w['hs_m']:.2f} m, Tp {w['tp_s']:.1f} s "
              f"({w['share']:.0%} of the damage in {w['hours']:.0f} h)")
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=1))
    return 0


def _years(y: float) -> str:
    if y < 1.0 / 365.25:
        return f"{y * 8766:.1f} h"
    if y < 1.0:
        return f"{y * 365.25:.0f} days"
    if y > 1000:
        return "more than 1,000 years"
    return f"about {y:.3g} years"
