"""``buoymon forecast --sea-states FILE``: the damage a sea-state forecast will cost.

Each forecast step's (Hs, Tp) is looked up in a damage-rate table over (Hs, Tp) bins
(:class:`models.sea_state_table.DamageRateTable`): the rates learned from the buoy's own data
where a table is given (``--table``, saved by an earlier run with ``--save-table``), the
physics model's elsewhere (:mod:`replay.sea_state_damage`, run once per bin the forecast
visits). The projection starts from the damage a replay report
gives (``--report``; else 0) and says, per component: the damage at the end with its band,
when each damage alert threshold of the configuration would be crossed, and the remaining
life at the end. A forecast never changes the committed damage: it is a separate figure.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from models.fatigue.miner import remaining_life_days
from models.sea_state_table import (HS_EDGES_M, TP_EDGES_S, DamageRateTable, Projection,
                                    project_damage)
from models.waves import breaking_height
from monitor.config import Config, ConfigError, default_config, load_config
from monitor.daemon_target import endpoint_arg
from monitor.strict_json import json_ready
from replay.sea_state_files import SeaStates, read_sea_states

def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "forecast",
        description="Project each component's damage over a sea-state forecast: damage at "
                    "the end with a band, when each damage alert threshold is crossed, and "
                    "the remaining life at the end.")
    p.add_argument("--sea-states", type=Path, required=True,
                   help="forecast (CSV time,hs_m,tp_s[,direction_deg]; or NDBC text)")
    p.add_argument("--config", type=Path, default=None,
                   help="configuration (default: the shipped seed 004 configuration)")
    p.add_argument("--report", type=Path, default=None,
                   help="replay report JSON giving the damage so far (default: none)")
    p.add_argument("--table", type=Path, default=None,
                   help="damage-rate table learned on the buoy (JSON from --save-table)")
    p.add_argument("--save-table", type=Path, default=None,
                   help="write the table used (learned + model rates) as JSON")
    p.add_argument("--load-model", choices=("wavfor", "catenary"), default="wavfor",
                   help="simulator load model for bins without data (default wavfor)")
    p.add_argument("--json", type=Path, default=None, help="write the forecast as JSON here")
    p.add_argument("--publish", metavar="ENDPOINT", action="append", default=None,
                   type=endpoint_arg,
                   help="also send the sea states to the daemon of the configuration's buoy "
                        "(Zenoh key buoy/<id>/forecast/waves; e.g. tcp/127.0.0.1:7447; "
                        "repeatable)")
    p.set_defaults(func=run)


def publish_forecast(buoy_id: str, states: SeaStates, connect: Sequence[str],
                     wait_for_subscriber_s: float = 10.0) -> None:
    """Put the sea states on ``buoy/<id>/forecast/waves`` (the payload of
    :mod:`monitor.forecast`, issued at the first step's time); OSError if no daemon
    subscribes within ``wait_for_subscriber_s`` (a forecast put to nobody is lost)."""
    from monitor import zenoh_io  # noqa: PLC0415 (zenoh only when publishing)
    from monitor.publisher import publisher_config  # noqa: PLC0415

    doc = {"issued_s": float(states.t_s[0]), "time_s": states.t_s.tolist(),
           "hs_m": states.hs_m.tolist(), "tp_s": states.tp_s.tolist()}
    with zenoh_io.open_session(publisher_config(connect)) as session:
        pub = zenoh_io.declare_json_publisher(session, zenoh_io.forecast_key(buoy_id))
        deadline = time.monotonic() + wait_for_subscriber_s
        while not pub.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.01)
        if not pub.matching_status.matching:
            pub.undeclare()
            raise OSError(f"no daemon of buoy {buoy_id!r} subscribed to "
                          f"{zenoh_io.forecast_key(buoy_id)} via {list(connect)} within "
                          f"{wait_for_subscriber_s:g} s: the forecast was not sent")
        pub.put(zenoh_io.to_json_bytes(doc))
        pub.undeclare()


def damage_thresholds(config: Config) -> list[float]:
    """The configuration's damage alert thresholds (``damage_fraction`` rules), ascending."""
    return sorted({float(r.params["threshold"]) for r in config.alerts.rules
                   if r.kind == "damage_fraction"})


def fill_model_rates(table: DamageRateTable, config: Config, states: SeaStates,
                     load_model: str) -> None:
    """Run the physics model in every bin the forecast visits that has no model rate yet."""
    from replay.sea_state_damage import physics_damage  # noqa: PLC0415 (scipy: 0.3 s)

    i, j = table.bin_of(states.hs_m, states.tp_s)
    cells = {(int(a), int(b)) for a, b in zip(i, j)
             if not np.all(np.isfinite(table.model_rate[:, a, b]))}
    if not cells:
        return
    hs_c, tp_c = table.centres()
    order = sorted(cells)
    dmg = physics_damage(config, [hs_c[a] for a, _ in order], [tp_c[b] for _, b in order],
                         load_model)
    names = list(dmg.components)
    rates = table.model_rate.copy()
    for k, (a, b) in enumerate(order):
        for c, name in enumerate(table.components):
            rates[c, a, b] = dmg.rainflow_per_hour[names.index(name), k]
    table.set_model_rate(rates)


def forecast(config: Config, states: SeaStates, damage_now: Sequence[float],
             table: DamageRateTable, load_model: str = "wavfor") -> dict[str, Any]:
    """The forecast as a JSON-ready dict (see the module docstring)."""
    fill_model_rates(table, config, states, load_model)
    rates = table.rates(states.hs_m, states.tp_s)
    hours = states.step_hours()
    thresholds = damage_thresholds(config)
    proj = project_damage(states.t_s, hours, rates, damage_now, thresholds)
    span_days = float(hours.sum()) / 24.0
    out: dict[str, Any] = {
        "buoy_id": config.buoy.id, "steps": len(states), "skipped": dict(states.skipped),
        "time_start": _iso(states.t_s[0]), "time_end": _iso(proj.t_end_s[-1]),
        "steps_outside_table": int(table.outside(states.hs_m, states.tp_s).sum()),
        # Hs above the breaking height of its Tp in the mooring's depth: not a possible sea
        "steps_breaking": int(np.sum(states.hs_m > breaking_height(states.tp_s,
                                                                    config.mooring.depth_m))),
        "components": {}}
    for c, name in enumerate(table.components):
        out["components"][name] = _component(proj, rates.source[c], c, damage_now[c],
                                             span_days, thresholds)
    return out


def _component(proj: Projection, source: np.ndarray, c: int, d0: float, span_days: float,
               thresholds: Sequence[float]) -> dict[str, Any]:
    end, low, high = (float(a[c, -1]) for a in (proj.damage, proj.low, proj.high))
    rate = (end - d0) / span_days if span_days > 0 else 0.0
    # an unrated step makes the end damage NaN: the life is then unknown, not unlimited
    life = remaining_life_days(end, rate) if math.isfinite(rate) else math.nan
    return {
        "damage_now": d0, "damage_end": end, "damage_end_low": low, "damage_end_high": high,
        "damage_rate_per_day": rate,
        "remaining_life_days_at_end": life,
        "steps_learned": int(np.sum(source == "learned")),
        "steps_model": int(np.sum(source == "model")),
        "steps_unrated": int(np.sum(source == "none")),
        "thresholds": {f"{thr:g}": {"at": _iso(t), "earliest": _iso(t_early)}
                       for thr, (t, t_early) in proj.crossings[c].items()},
    }


def _life_text(days: float) -> str:
    if math.isnan(days):
        return "unknown"
    if math.isinf(days):
        return "unlimited (no damage accrues)"
    if days == 0.0:
        return "none (the damage reaches 1 within the forecast)"
    return f"{days:.3g} days at that rate" + (f" ({days * 24:.3g} h)" if days < 2 else "")


def _iso(t_s: float | None) -> str | None:
    if t_s is None or not math.isfinite(t_s):
        return None
    return datetime.fromtimestamp(t_s, timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def _json_file(path: Path, what: str) -> Any:
    try:
        doc = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: not JSON, expected {what} ({e})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: expected {what}, got a JSON {type(doc).__name__}")
    return doc


def _table_file(path: Path) -> DamageRateTable:
    """A damage-rate table written by ``--save-table``; ValueError naming the file if not."""
    what = "a damage-rate table (buoymon forecast --save-table)"
    doc = _json_file(path, what)
    try:
        return DamageRateTable.from_state(doc)
    except KeyError as e:
        raise ValueError(f"{path}: not {what}: no {e}") from None
    except (TypeError, ValueError) as e:  # wrong shapes or values
        raise ValueError(f"{path}: not {what}: {e}") from None


def _damage_from_report(path: Path | None, names: Sequence[str]) -> list[float]:
    if path is None:
        return [0.0] * len(names)
    doc = _json_file(path, "a replay report (buoymon replay --report)")
    comps = doc.get("components")
    if not isinstance(comps, dict):
        raise ValueError(f"{path}: not a replay report (buoymon replay --report): no "
                         "components")
    missing = [n for n in names if n not in comps]
    if missing:
        raise ValueError(f"{path}: no component {missing[0]!r} in the report (the report and "
                         "the configuration must name the same components)")
    out = []
    for n in names:
        d = comps[n].get("damage") if isinstance(comps[n], dict) else None
        if isinstance(d, bool) or not isinstance(d, (int, float)) or not (
                math.isfinite(d) and d >= 0):
            raise ValueError(f"{path}: component {n!r}: damage = {d!r}: must be a finite "
                             "number >= 0")
        out.append(float(d))
    return out


def run(args: argparse.Namespace) -> int:
    try:
        config = load_config(args.config) if args.config else default_config()
        names = [c.name for c in config.components]
        states = read_sea_states(args.sea_states)
        if args.table is not None:
            table = _table_file(args.table)
            if list(table.components) != names:
                raise ValueError(f"{args.table}: table components {list(table.components)} "
                                 f"!= the configuration's {names}")
        else:
            table = DamageRateTable(names, HS_EDGES_M, TP_EDGES_S)
        result = forecast(config, states, _damage_from_report(args.report, names), table,
                          args.load_model)
    except ConfigError as e:
        print(e, file=sys.stderr)
        return 2
    except (ValueError, OSError, KeyError) as e:
        print(f"buoymon forecast: {e}", file=sys.stderr)
        return 2
    skipped = "; ".join(f"{n} {why}" for why, n in sorted(result["skipped"].items()))
    print(f"forecast {result['time_start']} to {result['time_end']} ({result['steps']} steps"
          + (f", {result['steps_outside_table']} beyond the table's sea states"
             if result["steps_outside_table"] else "")
          + (f", {result['steps_breaking']} not a possible sea (Hs above the breaking "
             "height of its Tp)" if result["steps_breaking"] else "")
          + (f"; rows skipped: {skipped}" if skipped else "") + ")")
    for name, c in result["components"].items():
        crossings = "; ".join(
            f"reaches {thr} at {v['at']} (as early as {v['earliest']})" if v["at"] else
            (f"may reach {thr} by {v['earliest']}" if v["earliest"] else f"stays below {thr}")
            for thr, v in c["thresholds"].items())
        print(f"  {name}: damage {c['damage_now']:.3g} now -> {c['damage_end']:.3g} at the end "
              f"(band {c['damage_end_low']:.3g} to {c['damage_end_high']:.3g}); {crossings}")
        print(f"    damage rate {c['damage_rate_per_day']:.3g} per day (the forecast's mean); "
              f"remaining life at the end {_life_text(c['remaining_life_days_at_end'])}"
              + (f"; {c['steps_unrated']} steps unrated" if c["steps_unrated"] else ""))
    if args.save_table is not None:
        args.save_table.write_text(json.dumps(table.to_state()))
    if args.json is not None:
        # strict JSON: an unknown figure (NaN) or an unlimited life (inf) is null
        args.json.write_text(json.dumps(json_ready(result), indent=1, allow_nan=False))
    if args.publish:
        try:
            publish_forecast(config.buoy.id, states, args.publish)
        except OSError as e:
            print(f"buoymon forecast: {e}", file=sys.stderr)
            return 1
        print(f"sent to buoy/{config.buoy.id}/forecast/waves")
    return 0
