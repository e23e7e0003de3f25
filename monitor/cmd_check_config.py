"""``buoymon check-config CFG.toml``: validate a configuration file and summarise it."""

from __future__ import annotations

import argparse
import sys
import tomllib

from monitor.config import load_config, run_section_parsers


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("check-config")
    p.add_argument("config", help="TOML configuration file")
    p.set_defaults(func=run)


def _bridge_only(path: str) -> bool:
    """A bridge's own file (``buoymon bridge --config``): sources but no monitored component."""
    try:
        with open(path, "rb") as f:
            raw = tomllib.load(f)
    except (OSError, ValueError):  # unreadable, not UTF-8, not TOML: load_config reports it
        return False  # load_config reports it
    return "source" in raw and "component" not in raw


def _check_bridge(path: str) -> int:
    from monitor.bridge.config import load_bridge_config  # noqa: PLC0415 (bridge files only)

    try:
        cfg = load_bridge_config(path)
    except ValueError as exc:
        print(exc, file=sys.stderr)
        return 2
    print(f"{path}: ok (a bridge configuration: buoymon bridge --config)")
    print(f"  buoy {cfg.buoy_id}: publishing to {', '.join(cfg.connect)}")
    for s in cfg.sources:
        print(f"  [[source]] {s.name}: {s.transport} -> {s.sensor}")
    return 0


def run(args: argparse.Namespace) -> int:
    if _bridge_only(args.config):
        return _check_bridge(args.config)
    try:
        config = load_config(args.config)
        sections = run_section_parsers(config)
        # the model objects the pipeline will build: S-N curves, the cable
        from monitor.components import build_cable, build_sn_curve

        build_cable(config)
        for component in config.components:
            build_sn_curve(component)
    except ValueError as exc:  # ConfigError, or a model rejecting a configured value
        print(exc, file=sys.stderr)
        return 2
    comps = ", ".join(
        f"{c.name} ({c.kind}{', ' + c.lay + ' lay' if c.lay else ''}, {c.sn_curve.preset or 'table'})"
        for c in config.components
    )
    print(f"{args.config}: ok")
    print(f"  buoy {config.buoy.id}: {config.mooring.length_m:g} m line in "
          f"{config.mooring.depth_m:g} m of water; load source {config.load.source}")
    print(f"  components: {comps}")
    rate = config.load.motion_rate_hz
    print("  motion estimator step: " + (
        "auto (the motion stream's own sample spacing)" if rate == "auto" else
        f"{rate:g} Hz (a motion stream spaced otherwise gives no estimate: rate_mismatch)"))
    for name, status in sections.items():
        print(f"  [{name}] {status}")
    return 0
