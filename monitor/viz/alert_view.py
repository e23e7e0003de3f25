"""Alert records as the visual outputs read them (``AlertRecord`` objects or their dict form),
and collapsed into episodes (fired, re-sent, cleared) for the report's alert table."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable, Mapping


def alert_fields(record: Any) -> dict[str, Any]:
    """The fields of an alert record the visual outputs use, from an ``AlertRecord`` or its
    ``to_dict()`` form: rule, component, severity, state, event, at_ns, summary."""
    get = record.get if isinstance(record, Mapping) else lambda k, d=None: getattr(record, k, d)
    labels = get("labels") or {}
    out = {
        "rule": str(get("rule") or labels.get("rule", "")),
        "component": str(get("component") or labels.get("component", "")),
        "severity": str(get("severity", "info")),
        "state": str(get("state", "firing")),
        "event": str(get("event", "")),
        "at_ns": int(get("at_ns", 0) or 0),
        "summary": str(get("summary", "")),
    }
    if not out["rule"] or out["at_ns"] <= 0:
        raise ValueError(f"alert record needs a rule and a positive at_ns: {record!r}")
    return out


@dataclass(frozen=True)
class AlertEpisode:
    """One alert from firing to clearing, its re-sends collapsed.

    ``severity`` is the highest seen while firing; ``cleared_ns`` is 0 while still firing at
    the end of the data; ``resends`` counts the re-sent notifications of the episode.
    """

    rule: str
    component: str
    severity: str
    first_fired_ns: int
    last_resent_ns: int
    cleared_ns: int
    resends: int
    summary: str
    cleared_by: str  # "clear", "reset" (an operator) or "" while firing


_RANK = {"info": 0, "warning": 1, "critical": 2}


def alert_episodes(alerts: Iterable[Any]) -> list[AlertEpisode]:
    """Alert transitions as episodes, in the order they fired. ``alerts`` have the attributes
    of ``monitor.viz.report_data.Alert`` (rule, component, severity, state, event, at_ns,
    starts_at_ns, summary).

    A ``fire`` opens an episode of its (rule, component); ``resend`` and further firing
    records add to it; ``clear`` / ``reset`` close it. A re-send whose ``fire`` is older than
    the kept records (the report keeps the newest 10,000) opens the episode at its
    ``starts_at_ns``.
    """
    open_: dict[tuple[str, str], dict[str, Any]] = {}
    done: list[dict[str, Any]] = []
    for a in sorted(alerts, key=lambda a: a.at_ns):
        key = (a.rule, a.component)
        ep = open_.get(key)
        if a.state == "firing":
            if ep is None:
                ep = open_[key] = {
                    "rule": a.rule, "component": a.component, "severity": a.severity,
                    "first_fired_ns": a.at_ns if a.event == "fire" else a.starts_at_ns or a.at_ns,
                    "last_resent_ns": 0, "cleared_ns": 0, "resends": 0, "summary": a.summary,
                    "cleared_by": ""}
            if a.event == "resend":
                ep["resends"] += 1
                ep["last_resent_ns"] = a.at_ns
            if _RANK.get(a.severity, 0) > _RANK.get(ep["severity"], 0):
                ep["severity"] = a.severity
        elif ep is not None:  # resolved: a clear or an operator reset
            ep["cleared_ns"], ep["cleared_by"] = a.at_ns, a.event
            done.append(open_.pop(key))
    done += open_.values()
    return [AlertEpisode(**e) for e in sorted(done, key=lambda e: e["first_fired_ns"])]
