"""Alert records as the visual outputs read them (``AlertRecord`` objects or their dict form)."""

from __future__ import annotations

from typing import Any, Mapping


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
