"""``buoymon check-config CFG.toml``: validate a configuration file and summarise it."""

from __future__ import annotations

import argparse
import sys

from monitor.schema import read_toml


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("check-config")
    p.add_argument("config", help="TOML configuration file")
    p.set_defaults(func=run)


def _check_bridge(path: str, raw: dict) -> int:
    """A bridge's own file (``buoymon bridge --config``): sources but no monitored component."""
    from monitor.bridge.config import parse_bridge_config  # noqa: PLC0415 (bridge files only)

    cfg = parse_bridge_config(raw)
    print(f"{path}: ok (a bridge configuration: buoymon bridge --config)")
    print(f"  buoy {cfg.buoy_id}: publishing to {', '.join(cfg.connect)}")
    for s in cfg.sources:
        print(f"  [[source]] {s.name}: {s.transport} -> {s.sensor}")
    return 0


def run(args: argparse.Namespace) -> int:
    try:
        raw = read_toml(args.config)
        if "source" in raw and "component" not in raw:
            return _check_bridge(args.config, raw)
        from monitor.config import SERVICE_SECTIONS, parse_config  # noqa: PLC0415
        config = parse_config(raw, source=args.config)
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
    for name in ("alerts", *SERVICE_SECTIONS):
        if name in raw:
            print(f"  [{name}] ok")
    for c in config.components:
        if c.location == "termination" and c.bend_radius_m is None:
            print(f"  note: component {c.name}: termination bend not configured "
                  "(bend_radius_m, bend_angle_deg): no bend strain, the free span's stress; "
                  "conductor_yield and conductor_stress see no bend until it is set "
                  "(docs/CONDUCTOR.md)")
    return 0
