"""The replay report: a stable JSON contract, and its human-readable summary.

Stable fields (``report_version`` 1; new fields may be added, these keep their meaning):

``buoy_id``                          the buoy
``time_start`` / ``time_end``        first / last accepted sample, ISO 8601 UTC (null if none),
                                     also as ``time_start_ns`` / ``time_end_ns``
``samples``                          per channel (sensor): ``accepted``, ``rejected`` =
                                     {nan, out_of_range, spike, duplicate, time_backwards,
                                     flat_line}, ``qc`` = QARTOD flags {test: {suspect, fail}}
``motion_sensor`` / ``load_problems`` the motion stream feeding the estimator (null if none);
                                     why no load could be formed, in words ([] if none)
``motion_rate``                      the estimator's step: ``setting`` (``[load]
                                     motion_rate_hz``), ``hz``, ``samples_rate_mismatch``,
                                     ``rate_changes`` (monitor.motion_rate; null if no estimator)
``tension_N``                        the fatigue load series: ``min``, ``mean``, ``max``, ``p99``
                                     (p99 on a fixed histogram, ~3 N bins), and how many samples
                                     were ``samples_measured`` / ``samples_estimated``, and
                                     ``samples_estimate_clamped``: estimates of motion outside
                                     the estimator's table, held at its edge;
                                     ``breaking_load_N`` the configured breaking load
``components``                       {name: ``damage`` (committed + open residue as half cycles),
                                     ``damage_by_source`` (monitor.damage_split),
                                     ``damage_committed`` (Miner sum of closed cycles),
                                     ``cycles``, ``max_stress_Pa``, ``damage_rate_per_day``,
                                     ``remaining_life_days`` (null = nothing accrues),
                                     ``kind``, ``lay``, ``location`` (free_span | termination),
                                     ``samples_beyond_yield``: load samples whose hot-spot
                                     stress exceeded the conductor's yield (the elastic model
                                     and the S-N curve do not hold: damage underestimated),
                                     ``derating``}
``alerts``                           alert transitions (monitor.alerts records as dicts), the
                                     newest 10,000; ``alerts_dropped`` counts older ones
``inputs``                           files read and the reader's statistics (lost data)
``design_life_years``                the configured design life

Optional plot fields (with ``buoymon replay --html``, also in the ``--report`` JSON then, so
``buoymon report`` can draw it again; docs/REPORT_FORMAT.md): ``tension_history``,
``sea_state`` and per component ``damage_history``, ``histogram``, ``sn_curve``. They describe this replay only (a
log replayed in parts with ``--state`` has each part's history), so they are left out of a
plain ``--report``, whose components stay equal between split and one-pass replays.
"""

from __future__ import annotations

import json
import math
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping, Sequence

from monitor.atomic_file import atomic_write_text
from monitor.config import Config
from monitor.strict_json import json_ready
from monitor.viz.alert_view import alert_episodes
from monitor.viz.findings import findings, findings_text
from monitor.viz.human import remaining_life_text, tension_text
from monitor.viz.report_data import parse_report

REPORT_VERSION = 1
MAX_EPISODE_LINES = 20  # alert episodes listed in the terminal summary; the page lists all


def iso_utc(t_ns: int | None) -> str | None:
    if t_ns is None:
        return None
    dt = datetime.fromtimestamp(t_ns // 1_000_000_000, tz=timezone.utc)
    return dt.strftime("%Y-%m-%dT%H:%M:%S") + f".{(t_ns % 1_000_000_000) // 1_000_000:03d}Z"


def build_report(config: Config, pipeline_report: Mapping[str, Any], inputs: Sequence[str],
                 read_stats: Mapping[str, Any] | None) -> dict[str, Any]:
    """Assemble the report from ``Pipeline.report()`` and what the reader saw."""
    comps = {}
    by_name = {c.name: c for c in config.components}
    for name, figures in pipeline_report["components"].items():
        c = by_name[name]
        comps[name] = {
            "damage": figures["damage"],
            "damage_committed": figures["damage_committed"],
            "cycles": figures["cycles"],
            "max_stress_Pa": figures["max_stress_Pa"],
            "damage_rate_per_day": figures["damage_rate_per_day"],
            "remaining_life_days": figures["remaining_life_days"],
            "kind": c.kind,
            "lay": c.lay,
            "location": c.location,
            "samples_beyond_yield": int(figures.get("samples_beyond_yield") or 0),
            "derating": c.derating,
        }
        if "damage_by_source" in figures:
            comps[name]["damage_by_source"] = figures["damage_by_source"]
    return json_ready({
        "report_version": REPORT_VERSION,
        "buoy_id": pipeline_report["buoy_id"],
        "design_life_years": config.buoy.design_life_years,
        "time_start": iso_utc(pipeline_report["time_start_ns"]),
        "time_end": iso_utc(pipeline_report["time_end_ns"]),
        "time_start_ns": pipeline_report["time_start_ns"],
        "time_end_ns": pipeline_report["time_end_ns"],
        "samples": pipeline_report["samples"],
        "tension_N": {**pipeline_report["tension_N"],
                      "breaking_load_N": config.load.breaking_load_N},
        "load_source_at_end": pipeline_report["load_source"],
        "motion_sensor": pipeline_report.get("motion_sensor"),
        "motion_rate": pipeline_report.get("motion_rate"),
        "load_problems": list(pipeline_report.get("load_problems", [])),
        "components": comps,
        "alerts": pipeline_report["alerts"],
        "alerts_dropped": pipeline_report["alerts_dropped"],
        # [forecast]: the learned table's coverage, the last forecast, the per-window
        # spectral cross-check (docs/FORECAST.md)
        **{k: pipeline_report[k] for k in ("sea_state_table", "forecast", "spectral_windows")
           if k in pipeline_report},
        "inputs": {"files": list(inputs), "read": dict(read_stats or {})},
        "config": config.source,
    })


def add_plot_fields(report: dict[str, Any], fields: Mapping[str, Any]) -> None:
    """Merge the optional plot fields (``ReportHistory.fields()`` + S-N curves) into a report,
    in place; components the report does not list are ignored."""
    for key, value in fields.items():
        if key != "components":
            report[key] = json_ready(value, "text")
    for name, extra in fields.get("components", {}).items():
        if name in report["components"]:
            report["components"][name].update(json_ready(extra, "text"))


def write_report(path: str | Path, report: Mapping[str, Any]) -> None:
    atomic_write_text(path, json.dumps(report, indent=2, allow_nan=False) + "\n")


def _num(x: float | str | None, fmt: str) -> str:
    """A report number for people: "-" when absent or not a number, "inf" as is."""
    if x is None or (isinstance(x, str) and x != "inf"):
        return "-"
    return format(float(x), fmt)


def summary_text(report: Mapping[str, Any]) -> str:
    """For a person: the findings (as on the HTML page; monitor.viz.findings), then the
    details: what was read, the load, the damage per component, alerts."""
    lines = []
    parsed = None
    if report["time_start"] is not None:  # without samples there is no finding to state
        parsed = parse_report(report)
        lines += [findings_text(findings(parsed)), "", "Details:"]
    lines.append(f"buoy {report['buoy_id']}: {report['time_start'] or '-'} .. "
                 f"{report['time_end'] or '-'}")
    for sensor, s in report["samples"].items():
        rej = {k: v for k, v in s["rejected"].items() if v}
        rej_text = ", ".join(f"{k} {v}" for k, v in rej.items()) or "none"
        lines.append(f"  {sensor:8s} {s['accepted']:>12,d} samples accepted; rejected: {rej_text}")
        qc = s.get("qc") or {}
        for flag in ("fail", "suspect"):
            flagged = ", ".join(f"{k} {c[flag]:,d}" for k, c in qc.items() if c.get(flag))
            if flagged:
                lines.append(f"  {'':8s} QC {flag}: {flagged}")
    t = report["tension_N"]
    kn = {k: tension_text(math.nan if t[k] is None else float(t[k]))
          for k in ("min", "mean", "max", "p99")}
    lines.append(f"  tension  min {kn['min']}, mean {kn['mean']}, max {kn['max']}, "
                 f"p99 {kn['p99']} "
                 f"({t['samples_measured']:,d} measured, {t['samples_estimated']:,d} estimated"
                 + (f", {t['samples_estimate_clamped']:,d} of them outside the estimator's range"
                    if t.get("samples_estimate_clamped") else "") + ")")
    rate = report.get("motion_rate")
    if rate and rate["hz"] is not None:
        lines.append(f"  motion estimator stepped at {rate['hz']:.4g} Hz ("
                     + ("the stream's own spacing" if rate["setting"] == "auto"
                        else "[load] motion_rate_hz") + ")")
    for problem in report.get("load_problems") or []:
        lines.append(f"  LOAD: {problem}")
    lines.append(f"  {'component':24s} {'damage':>11s} {'committed':>11s} {'cycles':>10s} "
                 f"{'max stress':>11s}  life left")
    for name, c in report["components"].items():
        life = c["remaining_life_days"]
        # null: nothing accrues (the writer's form of an infinite life)
        life = math.inf if life is None else float(life)
        peak = c["max_stress_Pa"]
        lines.append(
            f"  {name:24s} {c['damage']:11.3e} {c['damage_committed']:11.3e} "
            f"{c['cycles']:10.0f} {_num(peak if peak is None or isinstance(peak, str) else peak / 1e6, '8.1f')} MPa "
            f" {remaining_life_text(life)}"
        )
    for name, c in report["components"].items():
        if c.get("samples_beyond_yield"):
            lines.append(f"  {name}: {c['samples_beyond_yield']:,d} samples beyond the conductor's "
                         "yield: elastic model beyond yield, damage underestimated")
    for name, c in report["components"].items():
        split = c.get("damage_by_source")
        if split and split["estimated"]:
            lines.append(
                f"  {name}: committed damage {split['measured']:.3e} from measured load, "
                f"{split['estimated']:.3e} from the motion estimate (band "
                f"{split['estimated_low']:.3e} .. {split['estimated_high']:.3e}, tension error "
                f"+-{split['estimate_relative_error']:.0%} {split['estimate_error_from']})")
    t_flags = [f"{t[k]:,d} {what}" for k, what in (
        ("samples_above_break", "above the breaking load"),
        ("samples_estimate_above_break", "of them estimates above the breaking load"))
        if t.get(k)]
    if t_flags:
        lines.append("  tension: " + ", ".join(t_flags) + " (see the alerts)")
    sea = report.get("sea_state_table")
    if sea:
        lines.append(
            f"  sea states: {sea['windows']} window(s) of {sea['window_s'] / 60:g} min, "
            f"{sea['learned']} learned ({sea['hours_learned']:.3g} h in {sea['bins_learned']} "
            f"(Hs, Tp) bins); spectral cross-check: {sea['flagged']} of {sea['compared']} "
            f"window damages flagged (Dirlik vs rainflow beyond x{sea['flag_factor']:g})")
    dropped = report.get("alerts_dropped") or 0
    episodes = alert_episodes(parsed.alerts) if parsed is not None else []
    lines.append(f"  alerts: {len(report['alerts'])} transition(s)"
                 + (f" in {len(episodes)} episode(s), re-sends collapsed" if episodes else "")
                 + (f" (and {dropped:,d} older ones not kept)" if dropped else ""))
    for ep in episodes[:MAX_EPISODE_LINES]:
        lines.append(f"    {ep.severity:8s} {ep.rule} / {ep.component}: fired {iso_utc(ep.first_fired_ns)}"
                     + (f", re-sent {ep.resends}x" if ep.resends else "")
                     + (f", cleared {iso_utc(ep.cleared_ns)}" if ep.cleared_ns
                        else ", still firing at the end"))
    if len(episodes) > MAX_EPISODE_LINES:
        lines.append(f"    ... and {len(episodes) - MAX_EPISODE_LINES} more (see the report)")
    read = report["inputs"]["read"]
    damage = {k: read.get(k) for k in ("lost_ranges", "lost_messages_known", "bad_chunks",
                                       "bad_payloads", "late")}
    parts = [f"{k.replace('_', ' ')} {v}" for k, v in damage.items() if v]
    unreadable = read.get("unreadable_files") or []
    cut = [f for f in read.get("incomplete_files") or [] if f not in unreadable]
    if cut:
        parts.append(f"{len(cut)} file(s) without footer")
    errors = {f["path"]: f.get("error") for f in read.get("files", [])}
    parts += [f"unreadable {f} ({errors.get(f) or 'no data'})" for f in unreadable]
    parts += [f"{f['trailing_bytes']:,d} bytes after the end of the log in {f['path']} "
              "(not read)"
              for f in read.get("files", []) if f.get("trailing_bytes")]
    if parts:
        lines.append("  damaged input: " + "; ".join(parts))
    return "\n".join(lines)
