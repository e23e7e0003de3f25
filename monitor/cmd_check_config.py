"""``buoymon check-config CFG.toml``: validate a configuration file and summarise it."""

from __future__ import annotations

import argparse
import sys
from typing import Any

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


def _check_forecast(config: Any) -> None:
    """The ``[forecast]`` learner as the pipeline builds it: its window in whole alert ticks,
    its table file readable and of the configuration's components."""
    from monitor.components import build_sn_curve  # noqa: PLC0415 (models: not for --help)
    from monitor.sea_state_learner import SeaStateLearner  # noqa: PLC0415

    forecast = config.forecast
    if not forecast.enabled:
        return
    prior = None
    if forecast.table is not None:
        from monitor.pipeline import load_forecast_table  # noqa: PLC0415 (numba: only then)

        prior = load_forecast_table(config, forecast.table)
    curves = {c.name: build_sn_curve(c) for c in config.components}
    SeaStateLearner(forecast, curves, config.alerts.eval_interval_s, prior)


def _check_alert_rules(config: Any, cable: Any) -> None:
    """The ``[alerts]`` rules against the components and streams, as the pipeline's engine
    takes them (``monitor.pipeline.build_alert_engine``, not called here: it loads numba): a
    rule naming a component the configuration lacks is refused here, not at the first replay."""
    from monitor.alerts.engine import AlertEngine  # noqa: PLC0415
    from monitor.components import (build_sn_curve, endurance_stress_Pa,  # noqa: PLC0415
                                     yield_stress_Pa)

    AlertEngine.from_config(config.alerts, config.buoy.id, {
        c.name: {"endurance_stress_Pa": endurance_stress_Pa(c, build_sn_curve(c)),
                 "yield_stress_Pa": yield_stress_Pa(c, cable)} for c in config.components})


def run(args: argparse.Namespace) -> int:
    try:
        raw = read_toml(args.config)
        if "source" in raw and "component" not in raw:
            return _check_bridge(args.config, raw)
        from monitor.config import SERVICE_SECTIONS, parse_config  # noqa: PLC0415
        config = parse_config(raw, source=args.config)
        # the model objects the pipeline will build: S-N curves, the cable
        from monitor.components import build_cable, build_sn_curve

        cable = build_cable(config)
        for component in config.components:
            build_sn_curve(component)
        _check_forecast(config)
        _check_alert_rules(config, cable)
    except ValueError as exc:  # ConfigError, or a model rejecting a configured value
        from monitor.schema import ConfigError, ConfigErrors  # noqa: PLC0415

        print(exc if isinstance(exc, ConfigError) else f"config error: {exc}", file=sys.stderr)
        if isinstance(exc, ConfigErrors):  # all of them, found in one run
            print(f"{args.config}: {len(exc.errors)} errors", file=sys.stderr)
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
