"""The ``[alerts]`` section of the buoymon TOML file, validated.

Layout (every key optional unless marked)::

    [alerts]
    eval_interval_s = 10        # sensor-time tick of alert evaluation (the pipeline uses it)
    resend_interval_s = 3600    # re-send active, unacknowledged alerts this often; 0 = never
    history_limit = 10000       # transitions/operator actions kept in the engine's history

    [[alerts.rule]]
    kind = "damage_fraction"    # required, see KIND_PARAMS
    component = "left"          # component / sensor stream; omitted = every one that applies
    severity = "warning"        # info | warning | critical (default warning)
    name = "damage_warning"     # default: the kind; must be unique per component
    threshold = 0.1             # meaning and unit depend on the kind (see KIND_PARAMS)
    on_delay_s = 0              # condition must hold this long before firing
    off_delay_s = 0             # condition must be gone this long before clearing

    [alerts.webhook]            # optional: POST Alertmanager-compatible JSON
    url = "http://127.0.0.1:9093/api/v2/..."
    timeout_s = 10

    [alerts.email]              # optional: SMTP
    host = "127.0.0.1", port = 25, from = "...", to = ["..."], starttls = false,
    username = "", password_env = ""   # name of the environment variable holding the password

    [alerts.outbox]             # durable queue for webhook/email
    path = "alerts_outbox.sqlite", retry_base_s = 5, retry_max_s = 600

Errors raise ConfigError naming the key and the value, e.g.
``alerts.rule[2].threshold = -1: must be > 0`` (rule indices count from 0, as in the file's
array of tables).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Any, Mapping

import msgspec
from msgspec import Meta

from monitor.alerts.alertmanager import (AUTH_KEYS, AlertmanagerConfig, HttpAuth, check_url,
                                         parse_auth)
from monitor.alerts.records import SEVERITIES
from monitor.schema import (MAX_DURATION_S, ConfigError, Errors, check_keys, convert,
                            did_you_mean, error, parse_struct)

# A whole-cable load rule (tension, slack/snap, residual) is labelled with this component.
CABLE_COMPONENT = "cable"


Positive = Annotated[float, Meta(gt=0)]
Seconds = Annotated[float, Meta(gt=0, le=MAX_DURATION_S)]  # a span becomes int64 ns
Delay = Annotated[float, Meta(ge=0, le=MAX_DURATION_S)]
AtLeastZero = Annotated[float, Meta(ge=0)]
_DELAYS: Mapping[str, tuple[Any, float | None]] = {"on_delay_s": (Delay, 0.0),
                                                   "off_delay_s": (Delay, 0.0)}

# kind -> (what the component names: "component" | "stream" | "cable", numeric parameters as
# name -> (type with bounds, default; None = required)).
# threshold units: damage_fraction Miner sum; damage_rate Miner sum per day; remaining_life
# days; tension_high fraction of breaking strength; conductor_stress multiple of the component's
# (derated) endurance stress; conductor_yield multiple of the stress at which the conductor's
# hot spot (scf x stress) reaches its tensile yield; slack_snap jump in N above floor_N; rejected_rate fraction of
# received samples over window_s; model_residual |measured - estimated| in N (tick means; with
# this rule the pipeline estimates every motion sample, not only where the estimate feeds
# fatigue, which costs replay a tenth to a fifth more CPU).
KIND_PARAMS: Mapping[str, tuple[str, Mapping[str, tuple[Any, float | None]]]] = {
    "damage_fraction": ("component", {"threshold": (Positive, None)}),
    "damage_rate": ("component", {"threshold": (Positive, None), **_DELAYS}),
    "remaining_life": ("component", {"threshold": (Positive, None), **_DELAYS}),
    "tension_high": ("cable", {
        "threshold": (Positive, None), "breaking_strength_N": (Positive, None),
        "deadband": (AtLeastZero, 0.0), **_DELAYS,
    }),
    "conductor_stress": ("component", {"threshold": (Positive, 1.0), **_DELAYS}),
    "conductor_yield": ("component", {"threshold": (Positive, 1.0), **_DELAYS}),
    "slack_snap": ("cable", {
        "threshold": (Positive, None), "floor_N": (AtLeastZero, None),
        "window_s": (Seconds, 2.0), "off_delay_s": (Delay, 60.0),
    }),
    "stale": ("stream", dict(_DELAYS)),
    "rejected_rate": ("stream", {
        "threshold": (Annotated[float, Meta(gt=0, le=1)], None), "window_s": (Seconds, 600.0),
        **_DELAYS,
    }),
    "model_residual": ("cable", {
        "threshold": (Positive, None), "on_delay_s": (Delay, 60.0), "off_delay_s": (Delay, 0.0),
    }),
}


def _err(where: str, value: Any, msg: str) -> ConfigError:
    return error("", where, value, msg)  # ``where`` is the whole key path here


def _get(where: str, d: Mapping[str, Any], key: str, tp: Any, default: Any) -> Any:
    return convert(where, key, d.get(key, default), tp)


def _string(where: str, value: Any, pattern_ok=lambda s: True, what="a non-empty string") -> str:
    if not isinstance(value, str) or not value or not pattern_ok(value):
        raise _err(where, value, f"must be {what}")
    return value


def _chunk_ok(s: str) -> bool:
    # rule names and components become Zenoh key chunks: no separators or wildcards
    return all(c.isalnum() or c in "_.-" for c in s) and len(s) <= 64


@dataclass(frozen=True)
class RuleConfig:
    """One ``[[alerts.rule]]`` entry, validated. ``params`` holds every numeric parameter of
    the kind (defaults filled in); ``component`` None means every component/stream it applies
    to."""

    kind: str
    name: str
    component: str | None
    severity: str
    params: Mapping[str, float]
    where: str = ""

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"kind": self.kind, "name": self.name, "severity": self.severity}
        if self.component is not None:
            d["component"] = self.component
        d.update(self.params)
        return d


@dataclass(frozen=True)
class WebhookConfig:
    """``[alerts.webhook]``: a direct receiver (chat, ticketing) that takes the body
    Alertmanager itself sends to its receivers (webhook v4); not for Alertmanager's API."""

    url: str
    timeout_s: float = 10.0
    receiver: str = "buoymon"
    auth: HttpAuth = HttpAuth()


class EmailConfig(msgspec.Struct, frozen=True):
    """``[alerts.email]``: SMTP."""

    host: Annotated[str, Meta(min_length=1)]
    sender: Annotated[str, Meta(pattern="@", description="an e-mail address")
                      ] = msgspec.field(name="from")
    to: Annotated[str | tuple[str, ...], Meta(
        description="an address or a non-empty list of addresses")] = ()
    port: Annotated[int, Meta(ge=1, le=65535)] = 25
    starttls: bool = False
    username: str = ""
    password_env: str = ""  # the environment variable holding the password
    timeout_s: Positive = 10.0

    def check(self, where: str, raw: Mapping[str, Any]) -> "EmailConfig":
        to = (self.to,) if isinstance(self.to, str) else self.to
        if not to or not all("@" in a for a in to):
            raise _err(f"{where}.to", raw.get("to"),
                       "must be an address or a non-empty list of addresses")
        return msgspec.structs.replace(self, to=to)


class OutboxConfig(msgspec.Struct, frozen=True):
    """``[alerts.outbox]``: the durable queue of webhook, e-mail and Alertmanager messages."""

    path: Annotated[str, Meta(min_length=1)] = "alerts_outbox.sqlite"
    retry_base_s: Positive = 5.0
    retry_max_s: Positive = 600.0  # backoff doubles from retry_base_s up to this
    max_pending: Annotated[int, Meta(ge=1)] = 10000  # per channel

    def check(self, where: str, raw: Mapping[str, Any]) -> "OutboxConfig":
        if self.retry_max_s < self.retry_base_s:
            raise _err(f"{where}.retry_max_s", raw.get("retry_max_s"),
                       f"must be >= retry_base_s ({self.retry_base_s:g})")
        return self


@dataclass(frozen=True)
class AlertsConfig:
    eval_interval_s: float = 10.0
    resend_interval_s: float = 3600.0
    history_limit: int = 10000
    rules: tuple[RuleConfig, ...] = ()
    webhook: WebhookConfig | None = None
    email: EmailConfig | None = None
    alertmanager: AlertmanagerConfig | None = None
    outbox: OutboxConfig = field(default_factory=OutboxConfig)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None, where: str = "alerts") -> "AlertsConfig":
        """Validate the parsed ``[alerts]`` table (None or {} gives the defaults, no rules)."""
        d = {} if d is None else d
        if not isinstance(d, Mapping):
            raise _err(where, d, "must be a table")
        check_keys(where, d, {"eval_interval_s", "resend_interval_s", "history_limit", "rule",
                               "webhook", "email", "alertmanager", "outbox"})
        eval_s = _get(where, d, "eval_interval_s", Seconds, 10.0)
        if eval_s * 1e9 != round(eval_s * 1e9):  # the alert tick grid is in int64 ns
            raise _err(f"{where}.eval_interval_s", eval_s,
                       "must be a whole number of nanoseconds")
        resend = _get(where, d, "resend_interval_s", Delay, 3600.0)  # 0 = never
        hist = _get(where, d, "history_limit", Annotated[int, Meta(ge=1)], 10000)
        raw_rules = d.get("rule", [])
        if not isinstance(raw_rules, list):
            raise _err(f"{where}.rule", raw_rules, "must be an array of tables ([[alerts.rule]])")
        errors = Errors()  # every rule's error at once
        found = [errors.parse(_rule, f"{where}.rule[{i}]", r) for i, r in enumerate(raw_rules)]
        errors.raise_any()
        rules = tuple(r for r in found if r is not None)
        seen: dict[tuple[str, str | None], str] = {}
        for r in rules:
            key = (r.name, r.component)
            if key in seen:
                raise _err(f"{r.where}.name", r.name,
                           f"duplicate of {seen[key]} for component {r.component or '(all)'}; "
                           "give each rule a distinct name")
            seen[key] = r.where
        return cls(
            eval_interval_s=eval_s, resend_interval_s=resend, history_limit=hist, rules=rules,
            webhook=_webhook(f"{where}.webhook", d["webhook"]) if "webhook" in d else None,
            email=parse_struct(EmailConfig, d["email"], f"{where}.email") if "email" in d else None,
            alertmanager=(_alertmanager(f"{where}.alertmanager", d["alertmanager"])
                          if "alertmanager" in d else None),
            outbox=parse_struct(OutboxConfig, d.get("outbox"), f"{where}.outbox"),
        )

    def to_dict(self) -> dict[str, Any]:
        """The ``[alerts]`` table that :meth:`from_dict` turns back into this config."""
        d: dict[str, Any] = {
            "eval_interval_s": self.eval_interval_s, "resend_interval_s": self.resend_interval_s,
            "history_limit": self.history_limit, "rule": [r.to_dict() for r in self.rules],
            "outbox": {"path": self.outbox.path, "retry_base_s": self.outbox.retry_base_s,
                       "retry_max_s": self.outbox.retry_max_s,
                       "max_pending": self.outbox.max_pending},
        }
        if self.webhook is not None:
            d["webhook"] = {"url": self.webhook.url, "timeout_s": self.webhook.timeout_s,
                            "receiver": self.webhook.receiver, **_auth_dict(self.webhook.auth)}
        if self.alertmanager is not None:
            a = self.alertmanager
            d["alertmanager"] = {
                "url": list(a.urls), "resend_interval_s": a.resend_interval_s,
                "ends_at_intervals": a.ends_at_intervals, "timeout_s": a.timeout_s,
                "job": a.job, "instance": a.instance, "runbook_url": a.runbook_url,
                "generator_url": a.generator_url, **_auth_dict(a.auth)}
        if self.email is not None:
            e = self.email
            d["email"] = {"host": e.host, "port": e.port, "from": e.sender, "to": list(e.to),
                          "starttls": e.starttls, "username": e.username,
                          "password_env": e.password_env, "timeout_s": e.timeout_s}
        return d


def _rule(where: str, r: Any) -> RuleConfig:
    if not isinstance(r, Mapping):
        raise _err(where, r, "must be a table")
    if "kind" not in r:
        raise ConfigError(f"config error: {where}.kind: missing; expected one of "
                          f"{sorted(KIND_PARAMS)}")
    kind = r["kind"]
    if not isinstance(kind, str) or kind not in KIND_PARAMS:
        raise _err(f"{where}.kind", kind, f"unknown rule kind{did_you_mean(str(kind), KIND_PARAMS)}; "
                   f"expected one of {sorted(KIND_PARAMS)}")
    _, specs = KIND_PARAMS[kind]
    check_keys(where, r, {"kind", "name", "component", "severity", *specs})
    name = _string(f"{where}.name", r.get("name", kind), _chunk_ok,
                   "1-64 letters, digits, '_', '.', '-'")
    component = r.get("component")
    if component is not None:
        component = _string(f"{where}.component", component, _chunk_ok,
                            "1-64 letters, digits, '_', '.', '-'")
    severity = r.get("severity", "warning")
    if severity not in SEVERITIES:
        raise _err(f"{where}.severity", severity, f"must be one of {list(SEVERITIES)}")
    params: dict[str, float] = {}
    for key, (tp, default) in specs.items():
        if key not in r and default is None:
            raise ConfigError(f"config error: {where}.{key}: missing; rule kind {kind!r} "
                              "requires it")
        params[key] = _get(where, r, key, tp, default)
    if kind == "tension_high" and params["deadband"] >= params["threshold"]:
        raise _err(f"{where}.deadband", r.get("deadband"),
                   f"must be < threshold ({params['threshold']:g})")
    return RuleConfig(kind, name, component, severity, params, where)


def _auth_dict(auth: HttpAuth) -> dict[str, str]:
    return {k: getattr(auth, k) for k in AUTH_KEYS if getattr(auth, k)}


def _webhook(where: str, d: Any) -> WebhookConfig:
    if not isinstance(d, Mapping):
        raise _err(where, d, "must be a table")
    check_keys(where, d, {"url", "timeout_s", "receiver", *AUTH_KEYS})
    url = check_url(f"{where}.url", d.get("url"), _err)
    return WebhookConfig(
        url=url, timeout_s=_get(where, d, "timeout_s", Positive, 10.0),
        receiver=_string(f"{where}.receiver", d.get("receiver", "buoymon")),
        auth=parse_auth(where, d, _err),
    )


def _alertmanager(where: str, d: Any) -> AlertmanagerConfig:
    if not isinstance(d, Mapping):
        raise _err(where, d, "must be a table")
    check_keys(where, d, {"url", "resend_interval_s", "ends_at_intervals", "timeout_s", "job",
                           "instance", "runbook_url", "generator_url", *AUTH_KEYS})
    raw = d.get("url")
    urls = [raw] if isinstance(raw, str) else raw
    if not isinstance(urls, list) or not urls:
        raise _err(f"{where}.url", raw, "must be a URL or a non-empty list of URLs")
    urls = [check_url(f"{where}.url[{i}]", u, _err) for i, u in enumerate(urls)]
    text = {k: d.get(k, "") for k in ("instance", "runbook_url", "generator_url")}
    for k, v in text.items():
        if not isinstance(v, str):
            raise _err(f"{where}.{k}", v, "must be a string")
    return AlertmanagerConfig(
        urls=tuple(urls),
        resend_interval_s=_get(where, d, "resend_interval_s", Positive, 60.0),
        ends_at_intervals=_get(where, d, "ends_at_intervals", Annotated[float, Meta(ge=2)], 4.0),
        timeout_s=_get(where, d, "timeout_s", Positive, 10.0),
        job=_string(f"{where}.job", d.get("job", "buoymon")),
        instance=text["instance"], runbook_url=text["runbook_url"],
        generator_url=text["generator_url"], auth=parse_auth(where, d, _err),
    )
