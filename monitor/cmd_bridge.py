"""``buoymon bridge --config CFG.toml``: instruments in, sensor blocks out over Zenoh
(:mod:`monitor.bridge`; docs/SENSORS.md)."""

from __future__ import annotations

import argparse
import logging
import signal

log = logging.getLogger("buoymon.bridge")


def register(sub: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    p = sub.add_parser("bridge",
                       description="Read the [[source]] instruments of the configuration and "
                                   "publish their samples as blocks on buoy/<id>/sensor/<stream> "
                                   "(docs/SENSORS.md).")
    p.add_argument("--config", required=True, metavar="CFG.toml", help="configuration file")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monitor.bridge.config import load_bridge_config  # noqa: PLC0415
    from monitor.bridge.runner import open_bridge  # noqa: PLC0415

    try:
        cfg = load_bridge_config(args.config)
    except (ValueError, OSError) as exc:
        log.error(str(exc))
        return 2
    bridge = open_bridge(cfg)
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda signum, frame: bridge.stop())
    log.info("bridge ready", extra={"fields": {"buoy_id": cfg.buoy_id,
                                               "sources": [s.name for s in cfg.sources]}})
    try:
        bridge.run()
    finally:
        bridge.publisher.close()
    return 0
