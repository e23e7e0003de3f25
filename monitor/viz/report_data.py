"""Reading and checking the replay report JSON (format: docs/REPORT_FORMAT.md).

Required fields are checked and a bad one is a ValueError naming it; optional plot fields that
are absent become None so the renderer can leave their plots out.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from monitor.viz.alert_view import alert_fields


def _num(value: Any, where: str) -> float:
    """A JSON number, one of the strings "inf", "-inf", "nan", or null (NaN: the replay writes
    null for a figure it does not have, e.g. the remaining life when nothing accrues);
    ValueError otherwise."""
    if value is None:
        return math.nan
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ValueError(f"report: {where} = {value!r}: expected a number")
    if isinstance(value, str) and value.strip().lower() not in ("inf", "-inf", "+inf", "nan"):
        raise ValueError(f"report: {where} = {value!r}: expected a number")
    return float(value)


def _count(value: Any, where: str) -> int:
    """A finite JSON number as int (sample counts); ValueError otherwise."""
    x = _num(value, where)
    if not math.isfinite(x):
        raise ValueError(f"report: {where} = {value!r}: expected a count")
    return int(x)


def _array(value: Any, where: str, n: int | None = None) -> np.ndarray:
    if not isinstance(value, (list, tuple)):
        raise ValueError(f"report: {where}: expected a list of numbers, got {type(value).__name__}")
    a = np.array([_num(v, f"{where}[{i}]") for i, v in enumerate(value)], dtype=float)
    if n is not None and len(a) != n:
        raise ValueError(f"report: {where}: expected {n} values, got {len(a)}")
    return a


def _mapping(value: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise ValueError(f"report: {where}: expected an object, got {type(value).__name__}")
    return value


def parse_time_ns(value: Any, where: str) -> int:
    """ISO 8601 string (naive = UTC), int ns or float s since the epoch -> int ns."""
    if isinstance(value, str):
        try:
            dt = datetime.fromisoformat(value.replace("Z", "+00:00"))
        except ValueError as exc:
            raise ValueError(f"report: {where} = {value!r}: not an ISO 8601 time") from exc
        if dt.tzinfo is None:
            dt = dt.replace(tzinfo=timezone.utc)
        whole = int(dt.replace(microsecond=0).timestamp())
        return whole * 1_000_000_000 + dt.microsecond * 1000
    if isinstance(value, int) and not isinstance(value, bool):
        return value
    if isinstance(value, float) and math.isfinite(value):
        return int(round(value * 1e9))
    raise ValueError(f"report: {where} = {value!r}: expected an ISO 8601 time or a number")


@dataclass(frozen=True, eq=False)
class Series:
    """Time series with named columns, ``t_s`` in seconds since the epoch."""

    t_s: np.ndarray
    columns: Mapping[str, np.ndarray]


@dataclass(frozen=True, eq=False)
class Component:
    name: str
    damage: float
    damage_committed: float
    cycles: float
    max_stress_Pa: float
    damage_rate_per_day: float
    remaining_life_days: float
    damage_history: Series | None = None
    hist_edges_Pa: np.ndarray | None = None
    hist_counts: np.ndarray | None = None
    hist_max_range_Pa: float | None = None
    sn_ranges_Pa: np.ndarray | None = None
    sn_cycles: np.ndarray | None = None
    sn_endurance_Pa: float | None = None
    kind: str = ""
    lay: str | None = None
    derating: float = 1.0


@dataclass(frozen=True, eq=False)
class Alert:
    rule: str
    component: str
    severity: str
    state: str
    event: str
    at_ns: int
    starts_at_ns: int
    ends_at_ns: int
    summary: str


@dataclass(frozen=True)
class SeaState:
    """The buoy's own wave reports over the replay: how many, and min / mean / max of the
    significant wave height (m) and the peak period (s)."""

    reports: int
    hs_m: Mapping[str, float]
    tp_s: Mapping[str, float]


@dataclass(frozen=True, eq=False)
class SpectralCheck:
    """The per-window spectral cross-check of one component: window end times (s), rainflow
    and Dirlik damage per window (NaN where Dirlik had no whole segment), flagged windows."""

    end_s: np.ndarray
    rainflow: np.ndarray
    dirlik: np.ndarray
    flagged: np.ndarray


@dataclass(frozen=True, eq=False)
class Report:
    buoy_id: str
    time_start_ns: int
    time_end_ns: int
    samples: Mapping[str, tuple[int, Mapping[str, int]]]
    tension: Mapping[str, float]
    components: Mapping[str, Component]
    alerts: list[Alert]
    design_life_years: float | None = None
    tension_history: Series | None = None
    spectral: Mapping[str, SpectralCheck] | None = None
    spectral_flag_factor: float = math.nan
    # optional context for the findings (absent from older reports: empty / None)
    tension_counts: Mapping[str, int] = dataclasses.field(default_factory=dict)
    breaking_load_N: float | None = None
    load_source_at_end: str = ""
    motion_sensor: str | None = None
    load_problems: tuple[str, ...] = ()
    sea_state: SeaState | None = None
    input_files: tuple[str, ...] = ()
    alerts_dropped: int = 0


def _spectral(value: Any) -> dict[str, SpectralCheck]:
    """``spectral_windows`` (a list of closed windows) per component."""
    if not isinstance(value, list):
        raise ValueError("report: spectral_windows: expected a list")
    rows: dict[str, list[tuple[float, float, float, bool]]] = {}
    for i, w in enumerate(value):
        where = f"spectral_windows[{i}]"
        w = _mapping(w, where)
        end = _count(w.get("end_ns"), f"{where}.end_ns") / 1e9
        rainflow = _mapping(w.get("rainflow"), f"{where}.rainflow")
        dirlik = _mapping(w.get("dirlik"), f"{where}.dirlik")
        flagged = w.get("flagged", [])
        if not isinstance(flagged, list):
            raise ValueError(f"report: {where}.flagged: expected a list")
        for name, d in rainflow.items():
            rows.setdefault(str(name), []).append((
                end, _num(d, f"{where}.rainflow.{name}"),
                _num(dirlik.get(name), f"{where}.dirlik.{name}"), name in flagged))
    return {name: SpectralCheck(*(np.array(col) for col in zip(*r))) for name, r in rows.items()}


def _series(value: Any, where: str, names: tuple[str, ...], required: tuple[str, ...]) -> Series:
    m = _mapping(value, where)
    if "t_s" not in m:
        raise ValueError(f"report: {where}.t_s is missing")
    t = _array(m["t_s"], f"{where}.t_s")
    cols = {}
    for name in names:
        if name in m:
            cols[name] = _array(m[name], f"{where}.{name}", len(t))
        elif name in required:
            raise ValueError(f"report: {where}.{name} is missing")
    return Series(t, cols)


def _component(name: str, c: Any) -> Component:
    where = f"components.{name}"
    c = _mapping(c, where)
    try:
        base: dict[str, Any] = {k: _num(c[k], f"{where}.{k}") for k in (
            "damage", "damage_committed", "cycles", "max_stress_Pa", "damage_rate_per_day",
            "remaining_life_days")}
    except KeyError as exc:
        raise ValueError(f"report: {where}.{exc.args[0]} is missing") from exc
    if c["remaining_life_days"] is None and base["damage_rate_per_day"] == 0.0:
        base["remaining_life_days"] = math.inf  # the writer's null: nothing accrues
    opt: dict[str, Any] = {}
    if "damage_history" in c:
        opt["damage_history"] = _series(c["damage_history"], f"{where}.damage_history",
                                        ("damage_committed", "damage"), ("damage_committed",))
    if "histogram" in c:
        h = _mapping(c["histogram"], f"{where}.histogram")
        edges = _array(h.get("edges_Pa"), f"{where}.histogram.edges_Pa")
        if len(edges) < 2 or np.any(np.diff(edges) <= 0):
            raise ValueError(f"report: {where}.histogram.edges_Pa: need >= 2 increasing edges")
        opt["hist_edges_Pa"] = edges
        opt["hist_counts"] = _array(h.get("counts"), f"{where}.histogram.counts", len(edges) - 1)
        if h.get("max_range_Pa") is not None:
            opt["hist_max_range_Pa"] = _num(h["max_range_Pa"], f"{where}.histogram.max_range_Pa")
    if "sn_curve" in c:
        s = _mapping(c["sn_curve"], f"{where}.sn_curve")
        ranges = _array(s.get("ranges_Pa"), f"{where}.sn_curve.ranges_Pa")
        opt["sn_ranges_Pa"] = ranges
        opt["sn_cycles"] = _array(s.get("cycles"), f"{where}.sn_curve.cycles", len(ranges))
        if s.get("endurance_Pa") is not None:
            opt["sn_endurance_Pa"] = _num(s["endurance_Pa"], f"{where}.sn_curve.endurance_Pa")
    if c.get("kind") is not None:
        opt["kind"] = str(c["kind"])
    if c.get("lay") is not None:
        opt["lay"] = str(c["lay"])
    if c.get("derating") is not None:
        opt["derating"] = _num(c["derating"], f"{where}.derating")
    return Component(name=name, **base, **opt)


def _sea_state(value: Any) -> SeaState:
    m = _mapping(value, "sea_state")
    stats = {}
    for key in ("hs_m", "tp_s"):
        s = _mapping(m.get(key), f"sea_state.{key}")
        stats[key] = {k: _num(s.get(k), f"sea_state.{key}.{k}") for k in ("min", "mean", "max")}
    return SeaState(reports=_count(m.get("reports"), "sea_state.reports"), **stats)


def _context(d: Mapping[str, Any], t: Mapping[str, Any]) -> dict[str, Any]:
    """The optional fields the findings read (docs/REPORT_FORMAT.md)."""
    out: dict[str, Any] = {
        "tension_counts": {k: _count(t[k], f"tension_N.{k}") for k in (
            "samples_measured", "samples_estimated", "samples_estimate_clamped",
            "samples_above_break", "samples_estimate_above_break") if t.get(k) is not None},
        "load_source_at_end": str(d.get("load_source_at_end") or ""),
        "motion_sensor": None if d.get("motion_sensor") is None else str(d["motion_sensor"]),
        "load_problems": tuple(str(p) for p in d.get("load_problems") or ()),
        "alerts_dropped": _count(d.get("alerts_dropped") or 0, "alerts_dropped"),
    }
    if t.get("breaking_load_N") is not None:
        out["breaking_load_N"] = _num(t["breaking_load_N"], "tension_N.breaking_load_N")
    if d.get("sea_state") is not None:
        out["sea_state"] = _sea_state(d["sea_state"])
    inputs = d.get("inputs")
    if isinstance(inputs, Mapping) and isinstance(inputs.get("files"), list):
        out["input_files"] = tuple(str(f) for f in inputs["files"])
    return out


def _alert(i: int, a: Any) -> Alert:
    where = f"alerts[{i}]"
    a = _mapping(a, where)
    try:
        f = alert_fields(a)
        starts, ends = int(a.get("starts_at_ns") or f["at_ns"]), int(a.get("ends_at_ns") or 0)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"report: {where}: {exc}") from exc
    return Alert(**f, starts_at_ns=starts, ends_at_ns=ends)


def parse_report(data: Any) -> Report:
    """Check a decoded report and convert it; ValueError names the first bad field."""
    d = _mapping(data, "top level")
    if "fleet_report_version" in d:  # the fleet's ranking: its buoys' own reports render
        raise ValueError("report: a fleet report (fleet.json); render one of its buoys' "
                         "replay reports instead: REPORT_DIR/buoys/<buoy>.json")
    for key in ("buoy_id", "time_start", "time_end", "samples", "tension_N", "components",
                "alerts"):
        if key not in d:
            raise ValueError(f"report: required field {key!r} is missing")
    samples = {}
    for ch, s in _mapping(d["samples"], "samples").items():
        s = _mapping(s, f"samples.{ch}")
        rejected = _mapping(s.get("rejected", {}), f"samples.{ch}.rejected")
        samples[str(ch)] = (_count(s.get("accepted"), f"samples.{ch}.accepted"),
                            {str(r): _count(n, f"samples.{ch}.rejected.{r}")
                             for r, n in rejected.items()})
    t = _mapping(d["tension_N"], "tension_N")
    tension = {k: _num(t.get(k), f"tension_N.{k}") for k in ("min", "mean", "max", "p99")}
    comps = {str(n): _component(str(n), c)
             for n, c in _mapping(d["components"], "components").items()}
    if not isinstance(d["alerts"], list):
        raise ValueError("report: alerts: expected a list")
    life = d.get("design_life_years")
    return Report(
        buoy_id=str(d["buoy_id"]),
        time_start_ns=parse_time_ns(d["time_start"], "time_start"),
        time_end_ns=parse_time_ns(d["time_end"], "time_end"),
        samples=samples, tension=tension, components=comps,
        alerts=[_alert(i, a) for i, a in enumerate(d["alerts"])],
        design_life_years=None if life is None else _num(life, "design_life_years"),
        tension_history=(_series(d["tension_history"], "tension_history",
                                 ("min", "mean", "max"), ("min", "mean", "max"))
                         if "tension_history" in d else None),
        spectral=_spectral(d["spectral_windows"]) if d.get("spectral_windows") else None,
        spectral_flag_factor=_num((d.get("sea_state_table") or {}).get("flag_factor"),
                                  "sea_state_table.flag_factor"),
        **_context(d, t),
    )


def load_report(path: str | Path) -> Report:
    """Read and check a report file."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ValueError(f"report: cannot read {path}: {exc.strerror}") from exc
    except UnicodeDecodeError:
        raise ValueError(f"report: {path} is not a JSON report (not UTF-8 text)") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"report: {path} is not valid JSON: {exc}") from exc
    return parse_report(data)
