"""Live (wall-clock) alert rules: what only the running daemon can see.

The rules of :mod:`monitor.alerts.engine` run on sensor time, so a replay and the live daemon
give identical alerts; but sensor time stops when the data stops, so they cannot notice that.
These rules run on the daemon's wall clock instead, live only, evaluated every status
interval from the daemon's status document (:meth:`monitor.daemon.Daemon.status`):

=======================  ===========  =========================================================
rule (component)         severity     fires while
=======================  ===========  =========================================================
data_age (stream)        warning      no block arrived for longer than ``[health]
                                      data_age_timeout_s`` (a stream seen before, or listed in
                                      ``required_streams``; age counted from the daemon's start
                                      when none arrived in this life)
data_rejected (stream)   warning      blocks keep arriving but none of their samples was
                                      accepted for longer than ``data_age_timeout_s`` (e.g. a
                                      sensor restarted with an older clock while the daemon
                                      was down: all ``time_backwards``; or a publisher that
                                      sends only copies of old data: all ``duplicate``; the
                                      summary counts duplicates and rejected apart)
fatigue_blind (fatigue)  critical     neither measured tension nor a motion estimate fed the
                                      fatigue components for ``fatigue_blind_timeout_s``
clock_skew (stream)      warning      the last block's sensor time is off the logger clock by
                                      more than ``clock_skew_max_s`` (monitor.clock_faults)
time_restart (stream)    warning      the stream's time went back (monitor.clock_faults)
samples_missed (stream)  warning      ``samples_missed`` rose within the last ``hold_s``
alert_delivery_refused   critical     an alert channel holds dead letters
(channel)
alert_delivery_stalled   critical     an alert channel's oldest undelivered notification has
(channel)                             waited longer than ``delivery_stall_s`` (its receiver
                                      unreachable or failing: retried, not lost, but nobody
                                      is told; also fails ``/healthz``, the way an outside
                                      probe learns of it when every channel is down)
alert_outbox_dropped     critical     an alert channel's ``dropped_total`` rose within the last
(channel)                             ``hold_s``
checkpoint_failed        critical     the last checkpoint attempt failed
(checkpoint)
bridge_source (source)   warning      a bridge source is ``stalled`` (no line for its
                                      ``stall_s``), ``rejecting`` (lines but no sample for
                                      it), ``disconnected``, ``stopped`` (its bridge
                                      exited) or ``silent`` (its bridge stopped reporting):
                                      monitor.bridge.runner, monitor.bridge.watch
=======================  ===========  =========================================================

Records have the shape of every other alert (:class:`AlertRecord`) and take the same delivery
path; their times (``starts_at_ns``, ``at_ns``, ``ends_at_ns``) are wall-clock times, the
moment the daemon saw the condition change. Firing alerts and counter baselines are kept in the
daemon's checkpoint, so a restart clears what no longer holds and does not re-alert on old
counts.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Iterable, Mapping

from monitor.alerts.records import AlertRecord

LIVE_RULES = ("data_age", "data_rejected", "fatigue_blind", "clock_skew", "time_restart", "samples_missed",
              "alert_delivery_refused", "alert_delivery_stalled", "alert_outbox_dropped",
              "checkpoint_failed", "bridge_source")
log = logging.getLogger(__name__)
# rules whose firing makes /healthz fail: the daemon cannot do its job
HEALTH_RULES = ("data_age", "data_rejected", "fatigue_blind", "checkpoint_failed",
                "alert_delivery_stalled")
# counters that start from 0 in every daemon life (monitor.clock_faults): not saved
_LIFE_COUNTERS = ("time_restart",)
NS = 1_000_000_000


@dataclass(frozen=True)
class LiveConfig:
    """The ``[health]`` figures the live rules use (see monitor.daemon_config.HealthConfig)."""

    enabled: bool = True
    required_streams: tuple[str, ...] = ()
    fatigue_blind_timeout_s: float = 60.0
    clock_skew_max_s: float = 600.0
    hold_s: float = 600.0
    delivery_stall_s: float = 30.0


@dataclass(frozen=True)
class Condition:
    """One rule instance evaluated on one status document."""

    rule: str
    component: str
    severity: str
    active: bool
    value: float
    threshold: float
    unit: str
    summary: str


def _num(x: Any) -> float:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else math.nan


def _seen(s: Mapping[str, Any]) -> bool:
    rejected = s.get("rejected") or {}
    return bool(s.get("accepted") or s.get("last_t_ns") or any(rejected.values()))


def _rejected_text(s: Mapping[str, Any]) -> str:
    """What a stream's samples were since its last accepted one, duplicates (copies of data
    already received: a publisher re-sending its cache) apart from the rejected, with the
    counts by reason so far (the status fields of monitor.daemon.Daemon.status)."""
    since = int(s.get("rejected_since_accepted") or 0)
    dup = int(s.get("duplicates_since_accepted") or 0)
    counts = s.get("rejected") or {}
    reasons = " ".join(f"{k}={v}" for k, v in sorted(counts.items()) if v and k != "duplicate")
    return (f": since then {dup} duplicate(s) (data already received, sent again) and "
            f"{since - dup} rejected (so far: {counts.get('duplicate', 0)} duplicate(s); "
            f"rejected {reasons or 'none'})")


class LiveAlerts:
    """Evaluates the live rules on status documents and tracks their firing state."""

    def __init__(self, buoy_id: str, cfg: LiveConfig, saved: Mapping[str, Any] | None = None
                 ) -> None:
        self.buoy_id = buoy_id
        self.cfg = cfg
        self._firing: dict[tuple[str, str], AlertRecord] = {}
        # counter-increase rules: (rule, component) -> [last value, wall ns of last increase]
        self._counters: dict[tuple[str, str], list[int]] = {}
        # restored alerts whose subject has not reported yet in this life (a stream's clock,
        # a bridge source): kept for hold_s after the restart rather than cleared unseen
        self._restored: set[tuple[str, str]] = set()
        try:
            for d in (saved or {}).get("firing", []):
                rec = AlertRecord.from_dict(d)
                self._firing[(rec.rule, rec.component)] = rec
            self._counters = {(r, c): [int(x) for x in v]
                              for r, c, *v in (saved or {}).get("counters", [])}
            self._restored = set(self._firing)
        except (ValueError, TypeError, AttributeError) as exc:
            # a damaged part of the checkpoint costs the live rules' memory, not monitoring
            log.error("live alert state not restored", extra={"fields": {"error": repr(exc)}})
            self._firing, self._counters = {}, {}

    # --- conditions ------------------------------------------------------------------------
    def conditions(self, doc: Mapping[str, Any], wall_ns: int) -> list[Condition]:
        """Every rule instance the document allows evaluating."""
        cfg, out = self.cfg, []
        uptime = _num(doc.get("uptime_s"))
        for name, s in sorted((doc.get("streams") or {}).items()):
            timeout = _num(s.get("data_age_timeout_s"))
            age = s.get("data_age_s")
            if age is None and (name in cfg.required_streams or _seen(s)):
                age = uptime  # nothing arrived in this life
            if age is not None and math.isfinite(timeout):
                out.append(Condition(
                    "data_age", name, "warning", _num(age) > timeout, _num(age), timeout, "s",
                    f"no data on stream {name} for {_num(age):.0f} s (timeout {timeout:g} s, "
                    "logger clock)"))
            acc_age = s.get("accepted_age_s")
            if acc_age is not None and math.isfinite(timeout) and s.get("data_age_s") is not None:
                # flowing, and rejected (not merely held by the ordering layer)
                flowing = (_num(s["data_age_s"]) <= timeout
                           and (s.get("rejected_since_accepted") or 0) > 0)
                out.append(Condition(
                    "data_rejected", name, "warning", flowing and acc_age > timeout,
                    _num(acc_age), timeout, "s",
                    f"stream {name}: data arrives but none was accepted for {acc_age:.0f} s"
                    + _rejected_text(s)))
            skew = s.get("clock_skew_s")
            if skew is not None:
                way = "ahead of" if skew > 0 else "behind"
                out.append(Condition(
                    "clock_skew", name, "warning", abs(skew) > cfg.clock_skew_max_s, _num(skew),
                    cfg.clock_skew_max_s, "s",
                    f"stream {name}: sensor time {abs(skew):.6g} s {way} the logger clock"))
            if "time_restarts" in s:
                # active while behind, and for hold_s after each restart (a re-sent stretch
                # may catch up between two evaluations)
                rose = self._increase("time_restart", name, "warning", int(s["time_restarts"]),
                                      wall_ns, "")
                behind = _num(s.get("time_behind_s"))
                jump = behind if behind > 0 else _num(s.get("time_restart_jump_s"))
                out.append(Condition(
                    "time_restart", name, "warning", rose.active or behind > 0, jump, 0.0, "s",
                    f"stream {name}: time restarted {jump:.6g} s in the past "
                    f"({int(s['time_restarts'])} restarts); its older samples are rejected "
                    "as time_backwards"))
            if "samples_missed" in s:
                out.append(self._increase("samples_missed", name, "warning",
                                          int(s["samples_missed"]), wall_ns,
                                          f"stream {name}: samples were missed (never received)"))
        feed_age = doc.get("fatigue_feed_age_s")
        if feed_age is not None:
            out.append(Condition(
                "fatigue_blind", "fatigue", "critical", feed_age > cfg.fatigue_blind_timeout_s,
                _num(feed_age), cfg.fatigue_blind_timeout_s, "s",
                f"no measured tension or motion estimate fed fatigue for {feed_age:.0f} s"))
        channels = ((doc.get("delivery") or {}).get("channels") or {})
        for ch, c in sorted(channels.items()):
            dead = int(c.get("dead_letters") or 0)
            out.append(Condition("alert_delivery_refused", ch, "critical", dead > 0, dead, 0.0,
                                 "", f"alert channel {ch}: {dead} notifications refused "
                                 "(dead letters)"))
            waited = c.get("oldest_pending_age_s")
            out.append(Condition(
                "alert_delivery_stalled", ch, "critical",
                waited is not None and waited > cfg.delivery_stall_s, _num(waited or 0.0),
                cfg.delivery_stall_s, "s",
                f"alert channel {ch}: {int(c.get('pending') or 0)} notifications undelivered, "
                f"the oldest for {_num(waited or 0.0):.0f} s (receiver unreachable or failing; "
                "retried)"))
            if "dropped_total" in c:
                out.append(self._increase("alert_outbox_dropped", ch, "critical",
                                          int(c["dropped_total"]), wall_ns,
                                          f"alert channel {ch}: outbox dropped notifications"))
        sources = ((doc.get("bridge") or {}).get("sources") or {})
        for name, b in sorted(sources.items()):
            state = str(b.get("state"))
            quiet = b.get("last_line_age_s")
            out.append(Condition(
                "bridge_source", name, "warning",
                state in ("stalled", "rejecting", "disconnected", "stopped", "silent"),
                _num(quiet), _num(b.get("stall_s")), "s",
                f"bridge source {name} ({b.get('transport')} -> {b.get('sensor')}): {state}"
                + (f" every line ({', '.join(sorted(b.get('rejected') or {}))})"
                   if state == "rejecting" else "")
                + f", last line {'never' if quiet is None else f'{_num(quiet):.0f} s ago'}"))
        ckpt = doc.get("checkpoint")
        if ckpt is not None:
            out.append(Condition(
                "checkpoint_failed", "checkpoint", "critical", bool(ckpt.get("failing")),
                _num(ckpt.get("failures")), 0.0, "",
                f"checkpoint failing: {ckpt.get('last_error') or 'ok'}"))
        return out

    def _increase(self, rule: str, comp: str, severity: str, value: int, wall_ns: int,
                  summary: str) -> Condition:
        """Active for ``hold_s`` after the counter rose (the first value seen is the base of
        a cumulative counter; 0 that of a counter of this daemon life)."""
        base = 0 if rule in _LIFE_COUNTERS else value
        entry = self._counters.setdefault((rule, comp), [base, 0])
        if value > entry[0]:
            entry[1] = wall_ns
        entry[0] = value
        active = entry[1] > 0 and wall_ns - entry[1] < self.cfg.hold_s * NS
        return Condition(rule, comp, severity, active, value, 0.0, "", f"{summary} ({value} total)")

    # --- evaluation ------------------------------------------------------------------------
    def evaluate(self, doc: Mapping[str, Any], wall_ns: int) -> list[AlertRecord]:
        """Transitions since the last evaluation (fire and clear), as alert records; none
        with the rules switched off (their state still drives :meth:`health`)."""
        out = []
        seen = set()
        for c in self.conditions(doc, wall_ns):
            key = (c.rule, c.component)
            seen.add(key)
            was = self._firing.get(key)
            if c.active and was is None:
                rec = self._record(c, "fire", wall_ns, wall_ns)
                self._firing[key] = rec
                out.append(rec)
            elif not c.active and was is not None:
                out.append(self._record(c, "clear", was.starts_at_ns, wall_ns))
                del self._firing[key]
        self._restored &= set(self._firing) - seen
        if _num(doc.get("uptime_s")) >= self.cfg.hold_s:
            self._restored.clear()
        for key in [k for k in self._firing if k not in seen | self._restored]:  # subject gone
            was = self._firing.pop(key)
            out.append(AlertRecord(**{**_fields(was), "state": "resolved", "event": "clear",
                                      "ends_at_ns": wall_ns, "at_ns": wall_ns}))
        return out if self.cfg.enabled else []

    def _record(self, c: Condition, event: str, starts_ns: int, at_ns: int) -> AlertRecord:
        firing = event == "fire"
        return AlertRecord(
            rule=c.rule, kind=c.rule, severity=c.severity, buoy=self.buoy_id,
            component=c.component, state="firing" if firing else "resolved", event=event,
            starts_at_ns=starts_ns, ends_at_ns=0 if firing else at_ns, at_ns=at_ns,
            value=c.value, threshold=c.threshold, unit=c.unit, summary=c.summary)

    def active(self) -> list[AlertRecord]:
        """Firing live alerts (none with the rules switched off)."""
        return [self._firing[k] for k in sorted(self._firing)] if self.cfg.enabled else []

    def health(self) -> dict[str, Any]:
        """``/healthz``: failing while data is stale, fatigue is blind, checkpoints fail or
        alerts cannot be delivered."""
        reasons = [f"{r.rule} {r.component}: {r.summary}"
                   for _, r in sorted(self._firing.items()) if r.rule in HEALTH_RULES]
        return {"ok": not reasons, "reasons": reasons}

    def state(self) -> dict[str, Any]:
        return {"firing": [self._firing[k].to_dict() for k in sorted(self._firing)],
                "counters": [[r, c, *v] for (r, c), v in sorted(self._counters.items())
                             if r not in _LIFE_COUNTERS]}


def _fields(rec: AlertRecord) -> dict[str, Any]:
    names: Iterable[str] = (f for f in AlertRecord.__dataclass_fields__ if f != "fingerprint")
    return {f: getattr(rec, f) for f in names}
