"""Alert records: what the engine emits on every transition (and periodic re-send).

One :class:`AlertRecord` describes one alert instance (a rule applied to one component or
stream) at one moment. Times are sensor times (int ns since the Unix epoch, UTC), so a replay
and the live daemon produce identical records for the same samples.

The JSON forms:

* :meth:`AlertRecord.to_dict` / :meth:`AlertRecord.from_dict`: lossless (state files, MCAP
  record, Zenoh payload on ``buoy/<id>/monitor/alert/<rule>/<component>``).
* :meth:`AlertRecord.to_alertmanager` and :func:`webhook_payload`: the shape of Prometheus
  Alertmanager's webhook notification (version "4"), so any receiver written for Alertmanager
  (PagerDuty bridges, chat relays) accepts ours.
"""

from __future__ import annotations

import functools
import hashlib
import math
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any, Iterable, Mapping

SEVERITIES = ("info", "warning", "critical")
STATES = ("firing", "resolved")
# fire: became active; resend: still active, periodic reminder; clear: condition went away;
# reset: an operator reset (or cable replacement) released a latched alert.
EVENTS = ("fire", "resend", "clear", "reset")

# Alertmanager's "zero" endsAt for alerts that are still firing.
_ZERO_TIME = "0001-01-01T00:00:00Z"


_NUMBER = {"oneOf": [{"type": "number"}, {"enum": ["inf", "-inf", "nan"]}]}
_STRING = {"type": "string"}
_INT = {"type": "integer"}

# JSON Schema of :meth:`AlertRecord.to_dict`: the MCAP channel schema (encoding "jsonschema")
# of ``buoy/<id>/monitor/alert/...`` messages, and the Zenoh payload.
ALERT_JSON_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "buoymon alert record",
    "type": "object",
    "properties": {
        "fingerprint": _STRING, "rule": _STRING, "kind": _STRING,
        "severity": {"enum": list(SEVERITIES)}, "state": {"enum": list(STATES)},
        "event": {"enum": list(EVENTS)},
        "labels": {"type": "object", "properties": {"buoy": _STRING, "component": _STRING,
                                                    "rule": _STRING},
                   "required": ["buoy", "component", "rule"]},
        "annotations": {"type": "object", "properties": {"value": _STRING,
                                                         "threshold": _STRING,
                                                         "summary": _STRING},
                        "required": ["value", "threshold", "summary"]},
        "starts_at_ns": _INT, "ends_at_ns": _INT, "at_ns": _INT,
        "value": _NUMBER, "threshold": _NUMBER, "unit": _STRING, "summary": _STRING,
        "acked_by": _STRING, "ack_reason": _STRING,
    },
    "required": ["fingerprint", "rule", "kind", "severity", "state", "event", "labels",
                 "annotations", "starts_at_ns", "ends_at_ns", "at_ns", "value", "threshold",
                 "unit", "summary", "acked_by", "ack_reason"],
    "additionalProperties": False,
}


def fingerprint(labels: Mapping[str, str]) -> str:
    """Stable 16-hex-digit fingerprint of a label set (order-independent).

    SHA-256 over ``name=value`` lines sorted by name; unlike Python's ``hash`` it does not
    change between processes, so a fingerprint in a state file or an operator's ``ack``
    still matches after a restart.
    """
    return _digest("\n".join(f"{k}={labels[k]}" for k in sorted(labels)))


@functools.lru_cache(maxsize=4096)
def _digest(text: str) -> str:
    """The fingerprint of a label text; cached (a pure function of it): a long replay makes
    thousands of records (re-sends) of the same few alert instances."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def rfc3339(t_ns: int) -> str:
    """``t_ns`` (ns since the epoch) as RFC 3339 UTC with microseconds, e.g. for Alertmanager."""
    dt = datetime.fromtimestamp(t_ns // 1_000_000_000, tz=timezone.utc)
    micros = (t_ns % 1_000_000_000) // 1000
    return dt.strftime("%Y-%m-%dT%H:%M:%S") + f".{micros:06d}Z"


def encode_float(x: float) -> float | str:
    """JSON-safe float: finite values unchanged (Python's repr round-trips exactly), others
    as the strings "inf", "-inf", "nan" (strict JSON has no literal for them)."""
    x = float(x)
    return x if math.isfinite(x) else repr(x)


def decode_float(x: float | str) -> float:
    """Inverse of :func:`encode_float`."""
    return float(x)


def format_quantity(x: float, unit: str) -> str:
    """Human form of a value with its unit, e.g. ``"31.6 MPa"``, ``"0.1234"``, ``"12.5 d"``."""
    if math.isnan(x):
        return "n/a"
    if math.isinf(x):
        return f"{x} {unit}".strip()
    if unit == "Pa":
        return f"{x / 1e6:.4g} MPa"
    if unit == "N":
        return f"{x / 1e3:.4g} kN"
    return f"{x:.4g} {unit}".strip()


@dataclass(frozen=True)
class AlertRecord:
    """One alert instance at one transition or re-send.

    Attributes:
        rule: the rule's name (unique per component; also a Zenoh key chunk).
        kind: the rule kind, e.g. ``"damage_fraction"`` (see :mod:`monitor.alerts.rules`).
        severity: ``"info"``, ``"warning"`` or ``"critical"``.
        buoy, component: what the alert is about (component = fatigue component, sensor
            stream, or ``"cable"`` for whole-cable load rules).
        state: ``"firing"`` or ``"resolved"``.
        event: why this record was emitted, one of :data:`EVENTS`.
        starts_at_ns: sensor time the alert fired.
        ends_at_ns: sensor time it resolved (0 while firing).
        at_ns: sensor time of the evaluation that emitted this record.
        value, threshold, unit: the observed value and the limit it is compared with (SI, or
            the unit named: ``""`` for a Miner sum or a fraction, ``"1/d"``, ``"d"``).
        summary: one-line human explanation.
        acked_by, ack_reason: the operator acknowledgement, if any ("" otherwise).
    """

    rule: str
    kind: str
    severity: str
    buoy: str
    component: str
    state: str
    event: str
    starts_at_ns: int
    ends_at_ns: int
    at_ns: int
    value: float
    threshold: float
    unit: str
    summary: str
    acked_by: str = ""
    ack_reason: str = ""
    fingerprint: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if self.severity not in SEVERITIES:
            raise ValueError(f"alert severity {self.severity!r} must be one of {SEVERITIES}")
        if self.state not in STATES:
            raise ValueError(f"alert state {self.state!r} must be one of {STATES}")
        if self.event not in EVENTS:
            raise ValueError(f"alert event {self.event!r} must be one of {EVENTS}")
        object.__setattr__(self, "fingerprint", fingerprint(self.labels))

    @property
    def labels(self) -> dict[str, str]:
        """The identifying labels; the fingerprint is computed from exactly these."""
        return {"buoy": self.buoy, "component": self.component, "rule": self.rule}

    @property
    def annotations(self) -> dict[str, str]:
        """Human annotations: value and threshold with units, and the one-line summary."""
        return {
            "value": format_quantity(self.value, self.unit),
            "threshold": format_quantity(self.threshold, self.unit),
            "summary": self.summary,
        }

    @property
    def key(self) -> str:
        """Zenoh key expression of this alert: ``buoy/<id>/monitor/alert/<rule>/<component>``."""
        return f"buoy/{self.buoy}/monitor/alert/{self.rule}/{self.component}"

    def to_dict(self) -> dict[str, Any]:
        """Lossless JSON-serialisable form (includes labels, annotations and fingerprint)."""
        return {
            "fingerprint": self.fingerprint,
            "rule": self.rule,
            "kind": self.kind,
            "severity": self.severity,
            "state": self.state,
            "event": self.event,
            "labels": self.labels,
            "annotations": self.annotations,
            "starts_at_ns": self.starts_at_ns,
            "ends_at_ns": self.ends_at_ns,
            "at_ns": self.at_ns,
            "value": encode_float(self.value),
            "threshold": encode_float(self.threshold),
            "unit": self.unit,
            "summary": self.summary,
            "acked_by": self.acked_by,
            "ack_reason": self.ack_reason,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "AlertRecord":
        """Inverse of :meth:`to_dict`; ValueError if the fingerprint does not match."""
        try:
            labels = d["labels"]
            rec = cls(
                rule=str(d["rule"]), kind=str(d["kind"]), severity=str(d["severity"]),
                buoy=str(labels["buoy"]), component=str(labels["component"]),
                state=str(d["state"]), event=str(d["event"]),
                starts_at_ns=int(d["starts_at_ns"]), ends_at_ns=int(d["ends_at_ns"]),
                at_ns=int(d["at_ns"]), value=decode_float(d["value"]),
                threshold=decode_float(d["threshold"]), unit=str(d["unit"]),
                summary=str(d["summary"]), acked_by=str(d.get("acked_by", "")),
                ack_reason=str(d.get("ack_reason", "")),
            )
        except (KeyError, TypeError) as exc:
            raise ValueError(f"alert record is missing or has a bad field: {exc!r}") from exc
        if "fingerprint" in d and d["fingerprint"] != rec.fingerprint:
            raise ValueError(
                f"alert record fingerprint {d['fingerprint']!r} does not match its labels "
                f"({rec.fingerprint!r})"
            )
        return rec

    def to_alertmanager(self, generator_url: str = "") -> dict[str, Any]:
        """One element of an Alertmanager webhook's ``alerts`` list."""
        return {
            "status": self.state,
            "labels": {"alertname": self.rule, "severity": self.severity, **self.labels},
            "annotations": self.annotations,
            "startsAt": rfc3339(self.starts_at_ns),
            "endsAt": rfc3339(self.ends_at_ns) if self.ends_at_ns else _ZERO_TIME,
            "generatorURL": generator_url,
            "fingerprint": self.fingerprint,
        }


def webhook_payload(
    records: Iterable[AlertRecord], receiver: str = "buoymon", external_url: str = ""
) -> dict[str, Any]:
    """An Alertmanager-compatible webhook body (``"version": "4"``) for ``records``.

    ``status`` is ``"firing"`` if any record fires; common labels/annotations are those all
    records share, as Alertmanager computes them.
    """
    alerts = [r.to_alertmanager(external_url) for r in records]
    if not alerts:
        raise ValueError("webhook_payload needs at least one alert record")
    common_labels = dict(alerts[0]["labels"])
    common_ann = dict(alerts[0]["annotations"])
    for a in alerts[1:]:
        common_labels = {k: v for k, v in common_labels.items() if a["labels"].get(k) == v}
        common_ann = {k: v for k, v in common_ann.items() if a["annotations"].get(k) == v}
    group_labels = {"buoy": alerts[0]["labels"]["buoy"]}
    return {
        "version": "4",
        "groupKey": "{}:" + "{" + ",".join(f'{k}="{v}"' for k, v in group_labels.items()) + "}",
        "truncatedAlerts": 0,
        "status": "firing" if any(a["status"] == "firing" for a in alerts) else "resolved",
        "receiver": receiver,
        "groupLabels": group_labels,
        "commonLabels": common_labels,
        "commonAnnotations": common_ann,
        "externalURL": external_url,
        "alerts": alerts,
    }
