"""Alert delivery: Zenoh (put/delete + queryables) and webhook/e-mail through the outbox.

Zenoh keys for buoy ``<id>``:

* ``buoy/<id>/monitor/alert/<rule>/<component>``: a PUT (JSON :meth:`AlertRecord.to_dict`)
  when an alert fires or is re-sent, a DELETE when it clears; congestion control BLOCK and
  priority INTERACTIVE_HIGH, so alerts are neither dropped nor queued behind sensor data;
* ``buoy/<id>/monitor/alerts`` (queryable): replies ``{"buoy": id, "alerts": [record, ...]}``
  with the active alerts;
* ``buoy/<id>/monitor/alerts/operator`` (queryable): ``buoymon alerts ack|reset`` sends its
  command as the query payload; the daemon applies it between ticks
  (:meth:`ZenohAlertSink.apply_commands`) and the reply carries the result.

Zenoh callbacks only enqueue (they run on zenoh's threads); a worker thread answers list
queries from a snapshot, and operator commands wait for the daemon's thread, which owns the
:class:`~monitor.alerts.engine.AlertEngine`.

Webhook (Alertmanager-compatible JSON) and e-mail go through :class:`OutboxSink`, which stores
each record in the durable :class:`~monitor.alerts.outbox.Outbox` before returning.
"""

from __future__ import annotations

import json
import logging
import os
import queue
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping

import zenoh

from monitor.alerts.config import AlertsConfig, EmailConfig, WebhookConfig
from monitor.alerts.engine import AlertEngine
from monitor.alerts.alertmanager import (AlertmanagerConfig, post_json, records_payload,
                                         senders as alertmanager_senders)
from monitor.alerts.outbox import Outbox, PermanentDeliveryError
from monitor.alerts.records import AlertRecord, webhook_payload
from monitor.blocks import validate_buoy_id
from monitor.events import StepResult

if TYPE_CHECKING:
    from email.message import EmailMessage

log = logging.getLogger(__name__)


def alerts_key(buoy_id: str) -> str:
    """Queryable listing the active alerts of a buoy."""
    return f"buoy/{validate_buoy_id(buoy_id)}/monitor/alerts"


def operator_key(buoy_id: str) -> str:
    """Queryable receiving operator commands (ack/reset) for a buoy."""
    return f"buoy/{validate_buoy_id(buoy_id)}/monitor/alerts/operator"


def _json(obj: Any) -> bytes:
    return json.dumps(obj, allow_nan=False, separators=(",", ":")).encode("utf-8")


@dataclass
class OperatorRequest:
    """An operator command received over Zenoh, waiting to be applied and answered."""

    command: Any  # the decoded JSON payload (validated by AlertEngine.apply_command)
    reply: Callable[[Mapping[str, Any]], None]


class ZenohAlertSink:
    """Publishes alert records on Zenoh and serves the active list and operator commands.

    The daemon opens the session (loopback peer, explicit endpoints) and keeps it; this class
    only declares on it. ``active`` seeds the list after a restart (``engine.active()``).
    """

    def __init__(self, session: zenoh.Session, buoy_id: str,
                 active: Iterable[AlertRecord] = ()) -> None:
        self.session = session
        self.buoy_id = validate_buoy_id(buoy_id)
        self._lock = threading.Lock()
        self._active: dict[str, dict[str, Any]] = {r.fingerprint: r.to_dict() for r in active}
        self._list_queries: queue.Queue[zenoh.Query | None] = queue.Queue()
        self._commands: queue.Queue[zenoh.Query] = queue.Queue()
        self._list_key = alerts_key(buoy_id)
        self._op_key = operator_key(buoy_id)
        self._worker = threading.Thread(target=self._answer_lists, name="alert-queryable",
                                        daemon=True)
        self._worker.start()
        self._queryables = [
            session.declare_queryable(self._list_key, self._list_queries.put),
            session.declare_queryable(self._op_key, self._commands.put),
        ]

    # --- publishing (daemon thread) --------------------------------------------------------
    def publish(self, records: Iterable[AlertRecord]) -> None:
        for rec in records:
            if rec.state == "firing":
                d = rec.to_dict()
                with self._lock:
                    self._active[rec.fingerprint] = d
                self.session.put(rec.key, _json(d), encoding=zenoh.Encoding.APPLICATION_JSON,
                                 congestion_control=zenoh.CongestionControl.BLOCK,
                                 priority=zenoh.Priority.INTERACTIVE_HIGH)
            else:
                with self._lock:
                    self._active.pop(rec.fingerprint, None)
                self.session.delete(rec.key, congestion_control=zenoh.CongestionControl.BLOCK,
                                    priority=zenoh.Priority.INTERACTIVE_HIGH)

    def on_step(self, step: StepResult) -> None:
        if step.alerts:
            self.publish(step.alerts)

    def active(self) -> list[dict[str, Any]]:
        """The active-alert snapshot served to queries (record dicts)."""
        with self._lock:
            return [self._active[k] for k in sorted(self._active)]

    # --- operator commands (daemon thread) -------------------------------------------------
    def take_commands(self) -> list[OperatorRequest]:
        """Operator commands received since the last call (never blocks)."""
        out = []
        while True:
            try:
                q = self._commands.get_nowait()
            except queue.Empty:
                return out
            out.append(self._request(q))

    def _request(self, q: zenoh.Query) -> OperatorRequest:
        try:
            command = json.loads(q.payload.to_bytes()) if q.payload is not None else None
        except ValueError:
            command = None
        key = self._op_key

        def reply(result: Mapping[str, Any]) -> None:
            q.reply(key, _json(dict(result)), encoding=zenoh.Encoding.APPLICATION_JSON)
            q.drop()

        return OperatorRequest(command, reply)

    def apply_commands(self, engine: AlertEngine) -> int:
        """Apply pending operator commands to ``engine`` and answer each; returns how many.

        Call from the thread that owns the engine (e.g. between ticks); errors in a command
        are answered as ``{"ok": false, "error": ...}``.
        """
        requests = self.take_commands()
        for req in requests:
            try:
                result = engine.apply_command(req.command)
            except ValueError as exc:
                result = {"ok": False, "error": str(exc)}
            else:
                if result.get("op") == "ack":
                    with self._lock:
                        self._active[result["alert"]["fingerprint"]] = result["alert"]
            log.info("operator alert command", extra={"fields": {"command": req.command,
                                                                  "result": result}})
            req.reply(result)
        return len(requests)

    # --- list queries (worker thread) ------------------------------------------------------
    def _answer_lists(self) -> None:
        while True:
            q = self._list_queries.get()
            if q is None:
                return
            try:
                q.reply(self._list_key, _json({"buoy": self.buoy_id, "alerts": self.active()}),
                        encoding=zenoh.Encoding.APPLICATION_JSON)
            except zenoh.ZError:
                log.exception("could not answer an alert list query")
            finally:
                q.drop()

    def close(self) -> None:
        for qb in self._queryables:
            qb.undeclare()
        self._list_queries.put(None)
        self._worker.join(5.0)
        for req in self.take_commands():  # answer rather than leave the client waiting
            req.reply({"ok": False, "error": "daemon shutting down"})


class WebhookSender:
    """POSTs the Alertmanager *receiver* body (webhook v4) to a direct receiver; a 4xx answer
    is a permanent refusal, anything else not 2xx is retried (``post_json``)."""

    def __init__(self, cfg: WebhookConfig) -> None:
        self.cfg = cfg

    def __call__(self, payload: bytes, dedup_key: str) -> None:
        post_json(self.cfg.url, payload, self.cfg.timeout_s, self.cfg.auth,
                  {"Idempotency-Key": dedup_key})


class EmailSender:
    """Sends one alert record (JSON payload from :class:`OutboxSink`) as a plain-text e-mail.

    The SMTP password, if any, is read from the environment variable named by
    ``password_env`` at send time (it is never stored in the config or the outbox).
    """

    def __init__(self, cfg: EmailConfig) -> None:
        self.cfg = cfg

    def message(self, payload: bytes, dedup_key: str) -> EmailMessage:
        rec = json.loads(payload)
        ann, labels = rec["annotations"], rec["labels"]
        from email.message import EmailMessage  # noqa: PLC0415 (see WebhookSender.__call__)

        msg = EmailMessage()
        msg["From"] = self.cfg.sender
        msg["To"] = ", ".join(self.cfg.to)
        msg["Subject"] = (f"[buoymon {rec['state'].upper()}] {rec['severity']} {rec['rule']} "
                          f"{labels['component']} (buoy {labels['buoy']})")
        msg["Message-ID"] = f"<{dedup_key.replace(':', '.')}@buoymon>"
        msg.set_content(
            f"{ann['summary']}\n\nvalue: {ann['value']}\nthreshold: {ann['threshold']}\n"
            f"event: {rec['event']}\nfingerprint: {rec['fingerprint']}\n\n"
            + json.dumps(rec, indent=2) + "\n"
        )
        return msg

    def __call__(self, payload: bytes, dedup_key: str) -> None:
        import smtplib  # noqa: PLC0415 (see WebhookSender.__call__)

        msg = self.message(payload, dedup_key)
        try:
            with smtplib.SMTP(self.cfg.host, self.cfg.port, timeout=self.cfg.timeout_s) as smtp:
                if self.cfg.starttls:
                    smtp.starttls()
                if self.cfg.username:
                    smtp.login(self.cfg.username, os.environ.get(self.cfg.password_env, ""))
                smtp.send_message(msg)
        except smtplib.SMTPRecipientsRefused as exc:  # every recipient refused: permanent
            raise PermanentDeliveryError(f"SMTP {self.cfg.host}: recipients refused: "
                                         f"{exc.recipients}") from None
        except smtplib.SMTPResponseException as exc:  # 5xx permanent, 4xx try again
            text = f"SMTP {self.cfg.host} answered {exc.smtp_code} {exc.smtp_error!r}"
            if exc.smtp_code >= 500:
                raise PermanentDeliveryError(text) from None
            raise OSError(text) from None


class OutboxSink:
    """Stores every alert record for delivery (webhook, e-mail, Alertmanager) in a durable
    outbox, and keeps Alertmanager's view of the active alerts fresh.

    One message per record and channel, deduplicated on ``<fingerprint>:<event>:<at_ns>`` so
    re-processing ticks after a restart does not notify twice. For Alertmanager channels,
    :meth:`refresh` (called on the daemon's thread between blocks) re-sends every active
    alert each ``resend_interval_s`` of wall-clock time, as Prometheus does: only while the
    channel has nothing else pending, so an outage queues one refresh, not one per interval.
    """

    def __init__(self, outbox: Outbox, receiver: str = "buoymon",
                 alertmanager: AlertmanagerConfig | None = None,
                 active: Iterable[AlertRecord] = (),
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.outbox = outbox
        self.receiver = receiver
        self.alertmanager = alertmanager
        self.am_channels = [c for c in outbox.senders if c.startswith("alertmanager")]
        self.active: dict[str, AlertRecord] = {r.fingerprint: r for r in active}
        self.clock = clock
        self._next_refresh = clock()  # at once: a restarted daemon re-asserts what is active
        self._refreshes = 0

    @classmethod
    def from_config(cls, cfg: AlertsConfig, path: str | None = None,
                    active: Iterable[AlertRecord] = ()) -> "OutboxSink | None":
        """The sink for ``[alerts.webhook]``, ``[alerts.email]`` and ``[alerts.alertmanager]``
        (None if none is set), with its sender thread started. ``path`` overrides
        ``[alerts.outbox] path``; ``active`` are the alerts active at start."""
        senders: dict[str, Callable[[bytes, str], None]] = {}
        if cfg.webhook is not None:
            senders["webhook"] = WebhookSender(cfg.webhook)
        if cfg.email is not None:
            senders["email"] = EmailSender(cfg.email)
        if cfg.alertmanager is not None:
            senders.update(alertmanager_senders(cfg.alertmanager))
        if not senders:
            return None
        outbox = Outbox(path or cfg.outbox.path, senders, cfg.outbox.retry_base_s,
                        cfg.outbox.retry_max_s, cfg.outbox.max_pending)
        outbox.start()
        return cls(outbox, cfg.webhook.receiver if cfg.webhook else "buoymon",
                   cfg.alertmanager, active)

    def publish(self, records: Iterable[AlertRecord]) -> None:
        for rec in records:
            if rec.state == "firing":
                self.active[rec.fingerprint] = rec
            else:
                self.active.pop(rec.fingerprint, None)
            key = f"{rec.fingerprint}:{rec.event}:{rec.at_ns}"
            for channel in self.outbox.senders:
                if channel == "webhook":
                    payload = _json(webhook_payload([rec], self.receiver))
                elif channel in self.am_channels:
                    payload = records_payload([rec])
                else:
                    payload = _json(rec.to_dict())
                self.outbox.enqueue(channel, key, payload)

    def refresh(self) -> None:
        """Re-send the active alerts to Alertmanager when a re-send interval has passed."""
        if self.alertmanager is None or self.clock() < self._next_refresh:
            return
        self._next_refresh = self.clock() + self.alertmanager.resend_interval_s
        if not self.active:
            return
        pending = self.outbox.pending_by_channel()
        self._refreshes += 1
        payload = records_payload(self.active.values())
        for channel in self.am_channels:
            if pending.get(channel, 0) == 0:
                self.outbox.enqueue(channel, f"refresh:{time.time_ns()}:{self._refreshes}",
                                    payload)

    def on_step(self, step: StepResult) -> None:
        if step.alerts:
            self.publish(step.alerts)

    def close(self) -> None:
        self.outbox.close()


def peer_config(listen: Iterable[str] = ("tcp/127.0.0.1:0",),
                connect: Iterable[str] = ()) -> zenoh.Config:
    """A Zenoh peer config that talks only to explicit endpoints: listen where given, connect
    where given, multicast scouting and gossip off (the library default would listen on all
    interfaces and scout the LAN)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    return conf
