"""Sea-state forecasts in the pipeline: the projected damage and the ``forecast_damage`` alert.

A forecast arrives as JSON (Zenoh key ``buoy/<id>/forecast/waves``, docs/FORECAST.md)::

    {"issued": "2026-11-25T12:00:00Z",            # or "issued_s": Unix seconds; optional
     "time_s": [1764072000, 1764075600, ...],      # step start times (Unix s, increasing);
     "hs_m": [1.2, 1.5, ...], "tp_s": [6.0, 7.1, ...]}   # or "time": ISO 8601 strings

Each step lasts until the next (:func:`models.sea_state_table.step_hours`). A forecast is
applied at the first alert tick whose end is at or after its issue time (the first step's
time if not given) and that was not yet evaluated when the forecast arrived (its *due* time,
``due_ns``): sensor time. The daemon records each forecast with its due time as the publish
time, and a replay of the recording hands it to the pipeline with that time, so the replay
applies it at the same tick and gives the same forecast alerts. From that tick's committed damage, the steps still ahead (the part of each step
after the tick) are projected with the learned table (:func:`project_damage`). Per
component, ``forecast_damage`` fires while the central projection reaches ``[forecast]
alert_damage`` within the forecast ("at this forecast the conductor reaches damage 0.5 by
...", with the earliest time at the band's high end), is re-sent with the new figures by
each later forecast that still reaches it, and clears when one no longer does. The committed
damage is never changed: the projection is a separate figure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any, Mapping

import numpy as np

from models.sea_state_table import DamageRateTable, project_damage, step_hours
from monitor.alerts.records import AlertRecord
from monitor.forecast_config import ForecastConfig

RULE = "forecast_damage"
MAX_STEPS = 100_000  # a year of 5-min steps: a larger payload is refused
MAX_PENDING = 100  # forecasts waiting for sensor time to reach them


@dataclass(frozen=True)
class WaveForecast:
    """A parsed forecast: step start times (s), Hs (m), Tp (s), the issue time (s) and the
    first tick end it may be applied at (``not_before_ns``; None: any)."""

    issued_s: float
    t_s: np.ndarray
    hs_m: np.ndarray
    tp_s: np.ndarray
    not_before_ns: int | None = None

    @property
    def due_ns(self) -> int:
        """The sensor time from which the forecast is applied (at the next tick end)."""
        issued = int(round(self.issued_s * 1e9))
        return issued if self.not_before_ns is None else max(issued, self.not_before_ns)

    def to_dict(self) -> dict[str, Any]:
        return {"issued_s": self.issued_s, "time_s": self.t_s.tolist(),
                "hs_m": self.hs_m.tolist(), "tp_s": self.tp_s.tolist(),
                "not_before_ns": self.not_before_ns}


def _time_s(value: Any) -> float:
    if isinstance(value, str):
        return datetime.fromisoformat(value.replace("Z", "+00:00")).timestamp()
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"time {value!r}: must be Unix seconds or an ISO 8601 string")
    return float(value)


def parse_forecast(doc: Any, not_before_ns: int | None = None) -> WaveForecast:
    """A forecast payload (module docstring) as a :class:`WaveForecast`; ValueError says
    what is wrong with it."""
    if not isinstance(doc, Mapping):
        raise ValueError("forecast: must be a JSON object")
    times = doc.get("time_s", doc.get("time"))
    cols = [times, doc.get("hs_m"), doc.get("tp_s")]
    if any(not isinstance(c, list) for c in cols) or len({len(c) for c in cols}) != 1:
        raise ValueError("forecast: time_s (or time), hs_m and tp_s must be lists of one length")
    if not 1 <= len(times) <= MAX_STEPS:
        raise ValueError(f"forecast: 1 to {MAX_STEPS} steps, got {len(times)}")
    try:
        t = np.array([_time_s(x) for x in times], float)
        hs = np.array(cols[1], float)
        tp = np.array(cols[2], float)
        issued = _time_s(doc["issued_s"] if "issued_s" in doc else doc.get("issued", t[0]))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"forecast: {exc}") from None
    if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0) and math.isfinite(issued)):
        raise ValueError("forecast: times must be finite and strictly increasing")
    if not (np.all(np.isfinite(hs)) and np.all(hs >= 0) and np.all(np.isfinite(tp))
            and np.all(tp > 0)):
        raise ValueError("forecast: every step needs Hs >= 0 and Tp > 0 (finite)")
    return WaveForecast(issued, t, hs, tp, not_before_ns)


class ForecastExpired(ValueError):
    """A forecast with no step left to project when it would be applied (every step ends
    before its issue time, or it arrived after its last step): refused and counted, since
    applying it would project 0 steps and clear a ``forecast_damage`` alert on nothing."""


def refuse_expired(fc: WaveForecast, tick_ns: int) -> None:
    """Raise :class:`ForecastExpired` unless a step of ``fc`` reaches past the first tick end
    it can be applied at (ticks end on multiples of ``tick_ns``): the test of
    :meth:`ForecastAlerts.apply`, at the earliest tick that may apply it."""
    first_end_ns = -(-fc.due_ns // tick_ns) * tick_ns
    t_end = fc.t_s + 3600.0 * step_hours(fc.t_s)
    if not t_end[-1] > first_end_ns / 1e9:
        raise ForecastExpired(
            f"forecast: nothing to project: its last step ends {iso(float(t_end[-1]))}, not "
            f"after the first tick it can be applied at ({iso(first_end_ns / 1e9)}; issued "
            f"{iso(fc.issued_s)})")


def iso(t_s: float | None) -> str | None:
    if t_s is None or not math.isfinite(t_s):
        return None
    return datetime.fromtimestamp(t_s, timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


class ForecastAlerts:
    """Pending forecasts, the last projection and the ``forecast_damage`` alerts."""

    def __init__(self, cfg: ForecastConfig, buoy_id: str, names: tuple[str, ...],
                 state: Mapping[str, Any] | None = None) -> None:
        st = state or {}
        self.cfg, self.buoy_id, self.names = cfg, buoy_id, names
        self.pending: list[WaveForecast] = [parse_forecast(d, d["not_before_ns"])
                                            for d in st.get("pending", [])]
        self.firing: dict[str, AlertRecord] = {
            n: AlertRecord.from_dict(d) for n, d in st.get("firing", {}).items()}
        self.last: dict[str, Any] | None = st.get("last")
        self.counts = {"received": 0, "applied": 0, "superseded": 0, "dropped": 0,
                       **st.get("counts", {})}
        self.new: list[dict[str, Any]] = []  # projections since the last take_new()

    def add(self, fc: WaveForecast) -> None:
        """Queue a forecast; beyond ``MAX_PENDING`` (no sensor data to apply them) the
        oldest is dropped and counted."""
        self.counts["received"] += 1
        self.pending.append(fc)
        if len(self.pending) > MAX_PENDING:
            del self.pending[0]
            self.counts["dropped"] += 1

    def due(self, end_ns: int) -> bool:
        return any(f.due_ns <= end_ns for f in self.pending)

    def next_due_ns(self) -> int | None:
        """When the first pending forecast is due (None without one)."""
        return min((f.due_ns for f in self.pending), default=None)

    def apply(self, end_ns: int, committed: Mapping[str, float],
              table: DamageRateTable) -> list[AlertRecord]:
        """At a tick end: project the newest due forecast (older due ones are superseded)."""
        due = [f for f in self.pending if f.due_ns <= end_ns]
        self.pending = [f for f in self.pending if f.due_ns > end_ns]
        fc = max(due, key=lambda f: f.issued_s)
        self.counts["applied"] += 1
        self.counts["superseded"] += len(due) - 1
        now_s = end_ns / 1e9
        hours = step_hours(fc.t_s)
        t_end = fc.t_s + 3600.0 * hours
        ahead = t_end > now_s
        t0 = np.maximum(fc.t_s[ahead], now_s)
        h = (t_end[ahead] - t0) / 3600.0
        rates = table.rates(fc.hs_m[ahead], fc.tp_s[ahead])
        thr = self.cfg.alert_damage
        d0 = [committed[n] for n in self.names]
        proj = project_damage(t0, h, rates, d0, [thr])
        comps: dict[str, Any] = {}
        out = []
        for c, n in enumerate(self.names):
            end = float(proj.damage[c, -1]) if h.size else d0[c]
            # already reached: the damage_fraction rules speak for the committed damage
            at, early = proj.crossings[c][thr] if h.size and d0[c] < thr else (None, None)
            comps[n] = {"damage_now": d0[c], "damage_end": end,
                        "damage_end_low": float(proj.low[c, -1]) if h.size else d0[c],
                        "damage_end_high": float(proj.high[c, -1]) if h.size else d0[c],
                        "threshold": thr, "at": iso(at), "earliest": iso(early),
                        "steps_learned": int(np.sum(rates.source[c] == "learned")),
                        "steps_model": int(np.sum(rates.source[c] == "model")),
                        "steps_unrated": int(np.sum(rates.source[c] == "none"))}
            out.extend(self._transition(n, end_ns, end, at, early, t_end[-1]))
        self.last = {"applied_ns": end_ns, "issued_s": fc.issued_s, "steps": int(h.size),
                     "time_end": iso(float(t_end[-1])), "components": comps}
        self.new.append(self.last)
        return out

    def take_new(self) -> list[dict[str, Any]]:
        """Projections made since the last call (for the sinks)."""
        out, self.new = self.new, []
        return out

    def _transition(self, name: str, at_ns: int, value: float, at: float | None,
                    early: float | None, t_end: float) -> list[AlertRecord]:
        was = self.firing.get(name)
        if at is None:
            if was is None:
                return []
            del self.firing[name]
            return [AlertRecord(**{**_fields(was), "state": "resolved", "event": "clear",
                                   "ends_at_ns": at_ns, "at_ns": at_ns, "value": value})]
        summary = (f"at this forecast the {name} reaches damage {self.cfg.alert_damage:g} by "
                   f"{iso(at)} (as early as {iso(early)}); {value:.3g} by the forecast's end "
                   f"{iso(t_end)}")
        rec = AlertRecord(
            rule=RULE, kind=RULE, severity=self.cfg.alert_severity, buoy=self.buoy_id,
            component=name, state="firing", event="fire" if was is None else "resend",
            starts_at_ns=at_ns if was is None else was.starts_at_ns, ends_at_ns=0, at_ns=at_ns,
            value=value, threshold=self.cfg.alert_damage, unit="", summary=summary)
        self.firing[name] = rec
        return [rec]

    def active(self) -> list[AlertRecord]:
        return [self.firing[n] for n in sorted(self.firing)]

    def status(self) -> dict[str, Any]:
        return {**self.counts, "pending": len(self.pending), "last": self.last}

    def state(self) -> dict[str, Any]:
        return {"pending": [f.to_dict() for f in self.pending],
                "firing": {n: r.to_dict() for n, r in self.firing.items()},
                "last": self.last, "counts": dict(self.counts)}


def _fields(rec: AlertRecord) -> dict[str, Any]:
    return {k: getattr(rec, k) for k in (
        "rule", "kind", "severity", "buoy", "component", "state", "event", "starts_at_ns",
        "ends_at_ns", "at_ns", "value", "threshold", "unit", "summary")}
