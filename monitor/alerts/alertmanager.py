"""Alerts to Prometheus Alertmanager as a producer, and the HTTP plumbing of every sender.

Alertmanager takes alerts from producers (Prometheus, and here the daemon) as a JSON array of
*postable alerts* POSTed to ``/api/v2/alerts``: ``labels``, ``annotations``, ``startsAt``,
``endsAt``, ``generatorURL``. It computes the fingerprints itself and considers an alert
resolved once its ``endsAt`` has passed; so, as Prometheus does, a producer re-sends every
active alert well inside Alertmanager's ``resolve_timeout`` with ``endsAt`` a few re-send
intervals ahead, and sends a cleared alert once more with ``endsAt`` = the time it cleared.

Delivery goes through the durable outbox (:mod:`monitor.alerts.outbox`), one channel per
Alertmanager URL. The stored payload is the list of alert records; ``endsAt`` of a firing
alert is computed when the message is *sent*, so a message delayed by an outage never
arrives already expired (which would resolve a firing alert). A 4xx answer is a permanent
refusal (:class:`~monitor.alerts.outbox.PermanentDeliveryError`, a dead letter with the
answer's body); 5xx, timeouts and connection errors are retried.

Credentials: ``user:password@`` in the URL, a bearer token or basic auth with the secret in
a file or an environment variable. They go into the request headers only; every URL logged,
stored or shown is :func:`redact_url`'s.
"""

from __future__ import annotations

import base64
import json
import os
import time
import urllib.parse
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping, Sequence

from monitor.alerts.outbox import PermanentDeliveryError
from monitor.alerts.records import AlertRecord, rfc3339


@dataclass(frozen=True)
class HttpAuth:
    """How a sender authenticates: a bearer token or basic auth, secrets from a file or an
    environment variable (read at send time, never stored)."""

    bearer_token_file: str = ""
    bearer_token_env: str = ""
    username: str = ""
    password_file: str = ""
    password_env: str = ""

    def header(self, url: str) -> str | None:
        """The ``Authorization`` header value for ``url`` (user info in it counts too)."""
        if self.bearer_token_file or self.bearer_token_env:
            return "Bearer " + _secret(self.bearer_token_file, self.bearer_token_env)
        parts = urllib.parse.urlsplit(url)
        user = self.username or urllib.parse.unquote(parts.username or "")
        if not user:
            return None
        password = (_secret(self.password_file, self.password_env)
                    if (self.password_file or self.password_env)
                    else urllib.parse.unquote(parts.password or ""))
        return "Basic " + base64.b64encode(f"{user}:{password}".encode()).decode()


@dataclass(frozen=True)
class AlertmanagerConfig:
    """``[alerts.alertmanager]``: where and how alerts are produced to Alertmanager."""

    urls: tuple[str, ...]
    resend_interval_s: float = 60.0
    ends_at_intervals: float = 4.0
    timeout_s: float = 10.0
    job: str = "buoymon"
    instance: str = ""  # default: the host name
    runbook_url: str = ""  # may contain {alertname}, {component}, {buoy}
    generator_url: str = ""
    auth: HttpAuth = HttpAuth()

    def channel(self, i: int) -> str:
        """Outbox channel name of the i-th URL."""
        return "alertmanager" if len(self.urls) == 1 else f"alertmanager-{i}"


def _secret(path: str, env: str) -> str:
    if path:
        with open(path, encoding="utf-8") as f:
            return f.read().strip()
    value = os.environ.get(env)
    if value is None:
        raise OSError(f"environment variable {env} (a delivery secret) is not set")
    return value


def redact_url(url: str) -> str:
    """``url`` with any user info replaced by ``***`` (for logs, status and errors)."""
    parts = urllib.parse.urlsplit(url)
    if parts.username is None and parts.password is None:
        return url
    host = parts.hostname or ""
    if parts.port is not None:
        host += f":{parts.port}"
    return urllib.parse.urlunsplit(parts._replace(netloc="***@" + host))


def post_json(url: str, body: bytes, timeout_s: float, auth: HttpAuth,
              extra_headers: Mapping[str, str] = {}) -> None:
    """POST ``body``; :class:`PermanentDeliveryError` on a 4xx answer (with its body; 408
    and 429 are transient), OSError on anything else that is not 2xx."""
    # imported by the senders only: with ssl they cost a daemon without them ~4.6 MB
    import urllib.error  # noqa: PLC0415
    import urllib.request  # noqa: PLC0415

    parts = urllib.parse.urlsplit(url)
    clean = urllib.parse.urlunsplit(parts._replace(netloc=parts.netloc.rsplit("@", 1)[-1]))
    headers = {"Content-Type": "application/json", "User-Agent": "buoymon", **extra_headers}
    authorization = auth.header(url)
    if authorization:
        headers["Authorization"] = authorization
    req = urllib.request.Request(clean, data=body, method="POST", headers=headers)
    shown = redact_url(url)
    try:
        with urllib.request.urlopen(req, timeout=timeout_s) as resp:
            if not 200 <= resp.status < 300:
                raise OSError(f"{shown} answered HTTP {resp.status}")
    except urllib.error.HTTPError as exc:
        text = exc.read()[:2000].decode("utf-8", "replace").strip()
        msg = f"{shown} answered HTTP {exc.code} {exc.reason}: {text}"
        if 400 <= exc.code < 500 and exc.code not in (408, 429):
            raise PermanentDeliveryError(msg) from None
        raise OSError(msg) from None
    except urllib.error.URLError as exc:
        raise OSError(f"{shown}: {exc.reason}") from None


def postable(rec: AlertRecord, cfg: AlertmanagerConfig, now_s: float) -> dict[str, Any]:
    """One postable alert of the Alertmanager API v2 for ``rec``, sent at wall time ``now_s``.

    A firing alert ends ``ends_at_intervals`` re-send intervals from now; a resolved one at
    the time it cleared (never later than now: a sensor clock ahead of the logger's must not
    keep it open).
    """
    labels = {"alertname": rec.rule, "severity": rec.severity, "buoy": rec.buoy,
              "instance": cfg.instance or os.uname().nodename, "job": cfg.job}
    if rec.component:
        labels["component"] = rec.component
    ann = rec.annotations
    annotations = {"summary": rec.summary,
                   "description": f"{rec.summary} (value {ann['value']}, threshold "
                                  f"{ann['threshold']}; rule kind {rec.kind})"}
    if cfg.runbook_url:
        annotations["runbook_url"] = cfg.runbook_url.format(
            alertname=rec.rule, component=rec.component, buoy=rec.buoy)
    now_ns = int(now_s * 1e9)
    if rec.state == "firing":
        ends = now_ns + int(cfg.ends_at_intervals * cfg.resend_interval_s * 1e9)
    else:
        ends = min(rec.ends_at_ns or now_ns, now_ns)
    starts = min(rec.starts_at_ns, ends)
    return {"labels": labels, "annotations": annotations, "startsAt": rfc3339(starts),
            "endsAt": rfc3339(ends), "generatorURL": cfg.generator_url}


class AlertmanagerSender:
    """Outbox sender for one Alertmanager URL: the stored payload is a JSON list of alert
    records (``AlertRecord.to_dict``), turned into postable alerts at send time."""

    def __init__(self, cfg: AlertmanagerConfig, url: str,
                 clock: Callable[[], float] = time.time) -> None:
        self.cfg, self.clock = cfg, clock
        self.endpoint = url.rstrip("/") + "/api/v2/alerts"

    def body(self, payload: bytes) -> bytes:
        """The request body; PermanentDeliveryError for a payload that is not alert records
        (it could never be sent)."""
        now = self.clock()
        try:
            records = [AlertRecord.from_dict(d) for d in json.loads(payload)]
        except (ValueError, TypeError) as exc:
            raise PermanentDeliveryError(f"not a list of alert records: {exc}") from None
        return json.dumps([postable(r, self.cfg, now) for r in records]).encode()

    def __call__(self, payload: bytes, dedup_key: str) -> None:
        post_json(self.endpoint, self.body(payload), self.cfg.timeout_s, self.cfg.auth)


def records_payload(records: Iterable[AlertRecord]) -> bytes:
    """The outbox payload of :class:`AlertmanagerSender`."""
    return json.dumps([r.to_dict() for r in records], separators=(",", ":")).encode()


def senders(cfg: AlertmanagerConfig) -> dict[str, AlertmanagerSender]:
    """One outbox channel and sender per URL."""
    return {cfg.channel(i): AlertmanagerSender(cfg, url) for i, url in enumerate(cfg.urls)}


def check_url(where: str, url: Any, err: Callable[[str, Any, str], Exception]) -> str:
    """A http(s) URL with a host, or the config error ``err(where, shown value, why)``."""
    ok = isinstance(url, str) and urllib.parse.urlsplit(url).scheme in ("http", "https") \
        and bool(urllib.parse.urlsplit(url).hostname)
    if not ok:
        raise err(where, redact_url(url) if isinstance(url, str) else url,
                  "must be an http:// or https:// URL with a host")
    return url


def parse_auth(where: str, d: Mapping[str, Any], err: Callable[[str, Any, str], Exception]
               ) -> HttpAuth:
    """The auth keys of a sender's table (``bearer_token_file``/``_env``, ``username`` with
    ``password_file``/``_env``); secrets themselves are never accepted inline."""
    vals = {k: d.get(k, "") for k in ("bearer_token_file", "bearer_token_env", "username",
                                      "password_file", "password_env")}
    for k, v in vals.items():
        if not isinstance(v, str):
            raise err(f"{where}.{k}", v, "must be a string")
    if vals["bearer_token_file"] and vals["bearer_token_env"]:
        raise err(f"{where}.bearer_token_env", vals["bearer_token_env"],
                  "give bearer_token_file or bearer_token_env, not both")
    if (vals["password_file"] or vals["password_env"]) and not vals["username"]:
        raise err(f"{where}.username", "", "is required with password_file/password_env")
    if (vals["bearer_token_file"] or vals["bearer_token_env"]) and vals["username"]:
        raise err(f"{where}.username", vals["username"], "give a bearer token or basic auth, "
                                                          "not both")
    return HttpAuth(**vals)


AUTH_KEYS: Sequence[str] = ("bearer_token_file", "bearer_token_env", "username",
                            "password_file", "password_env")
