"""Prometheus metrics and ``/healthz`` of the live daemon, derived from its status document.

Every metric is read from the last status document the daemon built (``Daemon.status()``,
the one it published), so the metrics equal the status by construction; a scrape never
touches the pipeline or the checkpoint database, so it is answered at once even while the
daemon thread is busy (a checkpoint, a backlog). Process figures come from
``prometheus_client``'s process collector.

``GET /metrics``: the Prometheus text exposition. ``GET /healthz``: ``200 ok`` or ``503`` with
one reason per line while data is stale, fatigue is blind or checkpoints fail (the live rules
in :data:`monitor.alerts.live.HEALTH_RULES`), or while the status is older than
:data:`STALL_S` (the daemon's thread is stuck).

Units are in the names (base units: seconds, newtons), counters end in ``_total``; Miner sums
are ``_ratio`` (1 = end of fatigue life); the status's per-day damage rate and remaining life
in days become per second and seconds.
"""

from __future__ import annotations

import math
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Callable, Iterator, Mapping

from prometheus_client import CollectorRegistry, ProcessCollector, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.exposition import CONTENT_TYPE_LATEST

DAY_S = 86400.0
StatusSource = Callable[[], Mapping[str, Any] | None]


def _f(x: Any, scale: float = 1.0) -> float:
    """A status number as a sample value: null (non-finite or unknown) becomes NaN."""
    return float(x) * scale if isinstance(x, (int, float)) else math.nan


class StatusCollector:
    """A ``prometheus_client`` collector mapping one status document to metric families."""

    def __init__(self, source: StatusSource) -> None:
        self.source = source

    def collect(self) -> Iterator[Metric]:
        doc = self.source()
        if doc is None:
            return
        buoy = str(doc.get("buoy_id", ""))
        yield from _stream_metrics(buoy, doc.get("streams") or {})
        yield from _component_metrics(buoy, doc.get("components") or {})
        yield from _daemon_metrics(buoy, doc)
        yield from _motion_rate_metrics(buoy, doc.get("motion_rate"))
        yield from _alert_metrics(buoy, doc)
        yield from _bridge_metrics(buoy, (doc.get("bridge") or {}).get("sources") or {})


def _gauge(name: str, doc: str, labels: list[str]) -> GaugeMetricFamily:
    return GaugeMetricFamily(name, doc, labels=labels)


def _stream_metrics(buoy: str, streams: Mapping[str, Any]) -> Iterator[Metric]:
    acc = CounterMetricFamily("buoymon_samples_accepted", "Samples accepted by validation",
                              labels=["buoy", "stream"])
    rej = CounterMetricFamily("buoymon_samples_rejected", "Samples rejected, by reason",
                              labels=["buoy", "stream", "reason"])
    miss = CounterMetricFamily("buoymon_samples_missed", "Sensor messages published but never "
                               "received (beyond the publisher's cache)",
                               labels=["buoy", "stream"])
    redo = CounterMetricFamily("buoymon_messages_redelivered", "Sensor messages received again "
                               "after being taken (skipped)", labels=["buoy", "stream"])
    rec = CounterMetricFamily("buoymon_messages_recovered", "Sensor messages fetched from a "
                              "publisher's cache (restart catch-up, gaps)",
                              labels=["buoy", "stream"])
    age = _gauge("buoymon_data_age_seconds", "Logger-clock seconds since the stream's last "
                 "block arrived (NaN if none in this daemon life)", ["buoy", "stream"])
    timeout = _gauge("buoymon_data_age_timeout_seconds", "Data-age alert timeout",
                     ["buoy", "stream"])
    stale = _gauge("buoymon_data_stale", "1 while the data age is over its timeout",
                   ["buoy", "stream"])
    last = _gauge("buoymon_last_sample_time_seconds", "Sensor time of the newest accepted "
                  "sample (Unix seconds)", ["buoy", "stream"])
    skew = _gauge("buoymon_clock_skew_seconds", "Sensor time of the last block minus the "
                  "logger clock at its arrival", ["buoy", "stream"])
    skewed = CounterMetricFamily("buoymon_clock_skewed_blocks", "Blocks whose sensor time was "
                                 "off the logger clock by more than allowed", labels=["buoy", "stream"])
    restarts = CounterMetricFamily("buoymon_time_restarts", "Times the stream's time went back",
                                   labels=["buoy", "stream"])
    for name, s in sorted(streams.items()):
        lab = [buoy, name]
        acc.add_metric(lab, _f(s.get("accepted", 0)))
        for reason, n in sorted((s.get("rejected") or {}).items()):
            rej.add_metric([buoy, name, reason], _f(n))
        for family, field in ((miss, "samples_missed"), (redo, "redelivered"),
                              (rec, "recovered")):
            if field in s:
                family.add_metric(lab, _f(s[field]))
        age.add_metric(lab, _f(s.get("data_age_s")))
        timeout.add_metric(lab, _f(s.get("data_age_timeout_s")))
        stale.add_metric(lab, 1.0 if s.get("data_stale") else 0.0)
        last.add_metric(lab, _f(s.get("last_t_ns"), 1e-9))
        skew.add_metric(lab, _f(s.get("clock_skew_s")))
        skewed.add_metric(lab, _f(s.get("clock_skewed_blocks", 0)))
        restarts.add_metric(lab, _f(s.get("time_restarts", 0)))
    yield from (acc, rej, miss, redo, rec, age, timeout, stale, last, skew, skewed, restarts)


# status component field -> (metric name, help, scale)
_COMPONENT = {
    "damage": ("buoymon_damage_ratio", "Miner damage sum (1 = end of fatigue life)", 1.0),
    "damage_committed": ("buoymon_damage_committed_ratio", "Miner damage of closed, "
                         "checkpointed cycles", 1.0),
    "damage_rate_per_day": ("buoymon_damage_rate_per_second", "Damage rate (Miner sum per "
                            "second; the status gives it per day)", 1 / DAY_S),
    "remaining_life_days": ("buoymon_remaining_life_seconds", "Remaining fatigue life at the "
                            "current rate (the status gives days)", DAY_S),
}


def _component_metrics(buoy: str, comps: Mapping[str, Any]) -> Iterator[Metric]:
    for key, (name, doc, scale) in _COMPONENT.items():
        g = _gauge(name, doc, ["buoy", "component"])
        for comp, c in sorted(comps.items()):
            g.add_metric([buoy, comp], _f(c.get(key), scale))
        yield g


def _daemon_metrics(buoy: str, doc: Mapping[str, Any]) -> Iterator[Metric]:
    for key, c_name in (("messages", "messages"), ("undecodable", "undecodable_messages"),
                        ("refused", "refused_blocks"), ("wrong_buoy", "wrong_buoy_messages"),
                        ("queries", "queries"), ("forecasts", "forecasts"),
                        ("forecasts_refused", "forecasts_refused"),
                        ("forecasts_expired", "forecasts_expired")):
        c = CounterMetricFamily(f"buoymon_{c_name}", f"Daemon counter {key!r}", labels=["buoy"])
        c.add_metric([buoy], _f((doc.get("counters") or {}).get(key, 0)))
        yield c
    for name, help_, value in (
            ("buoymon_sensor_time_seconds", "Sensor time the pipeline reached (Unix seconds)",
             _f(doc.get("now_ns"), 1e-9)),
            ("buoymon_uptime_seconds", "Seconds since the daemon started", _f(doc.get("uptime_s"))),
            ("buoymon_queue_depth_messages", "Messages received, not yet processed",
             _f(doc.get("queue_depth"))),
            ("buoymon_fatigue_feed_age_seconds", "Logger-clock seconds since a load sample last "
             "fed fatigue", _f(doc.get("fatigue_feed_age_s")))):
        g = _gauge(name, help_, ["buoy"])
        g.add_metric([buoy], value)
        yield g
    src = _gauge("buoymon_load_source", "1 for the current load source", ["buoy", "source"])
    for s in ("measured", "estimated", "none"):
        src.add_metric([buoy, s], 1.0 if doc.get("load_source") == s else 0.0)
    yield src
    ckpt = doc.get("checkpoint") or {}
    g = _gauge("buoymon_checkpoint_age_seconds", "Seconds since the last successful checkpoint",
               ["buoy"])
    g.add_metric([buoy], _f(ckpt.get("age_s")))
    yield g
    c = CounterMetricFamily("buoymon_checkpoint_failures", "Failed checkpoint attempts "
                            "(this daemon life)", labels=["buoy"])
    c.add_metric([buoy], _f(ckpt.get("failures", 0)))
    yield c
    g = _gauge("buoymon_checkpoint_late_copies_lost_minutes", "Minutes of late copies the "
               "restored checkpoint held but could not give back (missing or damaged)", ["buoy"])
    g.add_metric([buoy], float(sum((ckpt.get("late_copies_lost_minutes") or {}).values())))
    yield g
    health = doc.get("health") or {}
    g = _gauge("buoymon_healthy", "1 when /healthz answers 200", ["buoy"])
    g.add_metric([buoy], 1.0 if health.get("ok", True) else 0.0)
    yield g


def _motion_rate_metrics(buoy: str, rate: Mapping[str, Any] | None) -> Iterator[Metric]:
    """The motion estimator's step (monitor.motion_rate); nothing without an estimator."""
    if not rate:
        return
    g = _gauge("buoymon_motion_rate_hz", "Sample rate the motion estimator steps at (NaN "
               "until known)", ["buoy", "setting"])
    g.add_metric([buoy, str(rate["setting"])], _f(rate["hz"]))
    yield g
    for key, name, help_ in (
            ("samples_rate_mismatch", "buoymon_motion_rate_mismatch_samples",
             "Motion samples withheld from the estimator: spaced unlike [load] motion_rate_hz"),
            ("rate_changes", "buoymon_motion_rate_changes",
             "Times the motion stream's rate changed (the estimator restarted on it)")):
        c = CounterMetricFamily(name, help_, labels=["buoy"])
        c.add_metric([buoy], _f(rate[key]))
        yield c


_CHANNEL = {
    "pending": ("buoymon_outbox_pending_messages", "Alert notifications waiting", False),
    "dead_letters": ("buoymon_outbox_dead_letters_messages", "Notifications refused for good",
                     False),
    "oldest_pending_age_s": ("buoymon_outbox_oldest_pending_age_seconds",
                             "Age of the oldest waiting notification", False),
    "delivered_total": ("buoymon_outbox_delivered", "Notifications delivered", True),
    "failures_total": ("buoymon_outbox_failures", "Failed delivery attempts", True),
    "dropped_total": ("buoymon_outbox_dropped", "Notifications dropped", True),
}


def _alert_metrics(buoy: str, doc: Mapping[str, Any]) -> Iterator[Metric]:
    g = _gauge("buoymon_alert_firing", "1 for each firing alert (sensor-time and live rules)",
               ["buoy", "rule", "component", "severity"])
    for a in (doc.get("alerts") or {}).get("active", []):
        g.add_metric([buoy, a["rule"], a["component"], a["severity"]], 1.0)
    yield g
    channels = ((doc.get("delivery") or {}).get("channels") or {})
    for key, (name, help_, counter) in _CHANNEL.items():
        fam = (CounterMetricFamily(name, help_, labels=["buoy", "channel"]) if counter
               else _gauge(name, help_, ["buoy", "channel"]))
        for ch, c in sorted(channels.items()):
            if key in c:
                fam.add_metric([buoy, ch], _f(c[key]))
        yield fam


# bridge source status counter -> (metric name, help)
_BRIDGE_COUNTERS = {
    "lines": ("buoymon_bridge_lines", "Lines read from the instrument"),
    "samples": ("buoymon_bridge_samples", "Lines parsed into samples"),
    "blocks": ("buoymon_bridge_blocks", "Blocks published"),
}
BRIDGE_STATES = ("reading", "rejecting", "connecting", "stalled", "disconnected", "stopped",
                 "silent")


def _bridge_metrics(buoy: str, sources: Mapping[str, Any]) -> Iterator[Metric]:
    """Per bridge source (monitor.bridge.watch): counters, rejections by reason, link events,
    its state (one-hot) and the ages of its last line and its last report."""
    lab = ["buoy", "source", "sensor"]
    for key, (name, help_) in _BRIDGE_COUNTERS.items():
        c = CounterMetricFamily(name, help_, labels=lab)
        for src, b in sorted(sources.items()):
            c.add_metric([buoy, src, str(b.get("sensor"))], _f(b.get(key, 0)))
        yield c
    for key, name, what in (("rejected", "buoymon_bridge_rejected_lines", "reason"),
                            ("events", "buoymon_bridge_link_events", "event")):
        c = CounterMetricFamily(name, f"Bridge {key} by {what}", labels=[*lab, what])
        for src, b in sorted(sources.items()):
            for k, n in sorted((b.get(key) or {}).items()):
                c.add_metric([buoy, src, str(b.get("sensor")), k], _f(n))
        yield c
    state = _gauge("buoymon_bridge_source_state", "1 for the bridge source's current state",
                   [*lab, "state"])
    for src, b in sorted(sources.items()):
        for st in BRIDGE_STATES:
            state.add_metric([buoy, src, str(b.get("sensor")), st],
                             1.0 if b.get("state") == st else 0.0)
    yield state
    for key, name, help_ in (
            ("last_line_age_s", "buoymon_bridge_line_age_seconds", "Seconds since the bridge "
             "source read a line (NaN: none yet)"),
            ("status_age_s", "buoymon_bridge_status_age_seconds", "Seconds since the bridge "
             "last reported this source")):
        g = _gauge(name, help_, lab)
        for src, b in sorted(sources.items()):
            g.add_metric([buoy, src, str(b.get("sensor"))], _f(b.get(key)))
        yield g


def make_registry(source: StatusSource) -> CollectorRegistry:
    """A registry (not the global one) with the status and process collectors."""
    reg = CollectorRegistry()
    reg.register(StatusCollector(source))
    ProcessCollector(registry=reg)
    return reg


class MetricsServer:
    """``/metrics`` and ``/healthz`` on a background thread. The port is bound at
    construction, so a port in use fails at start with an OSError naming it."""

    def __init__(self, listen: str, port: int, source: StatusSource) -> None:
        registry = make_registry(source)

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 (http.server's name)
                if self.path.split("?")[0] == "/metrics":
                    self._send(200, generate_latest(registry), CONTENT_TYPE_LATEST)
                elif self.path.split("?")[0] == "/healthz":
                    code, body = healthz(source())
                    self._send(code, body.encode(), "text/plain; charset=utf-8")
                else:
                    self._send(404, b"not found: try /metrics or /healthz\n", "text/plain")

            def _send(self, code: int, body: bytes, ctype: str) -> None:
                self.send_response(code)
                self.send_header("Content-Type", ctype)
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args: Any) -> None:
                """Scrapes are not worth a log line each."""

        try:
            self.httpd = ThreadingHTTPServer((listen, port), Handler)
        except OSError as exc:
            raise OSError(f"[metrics] cannot listen on {listen}:{port}: {exc.strerror or exc} "
                          "(another process has the port? set [metrics] port, or "
                          "enabled = false)") from None
        self.httpd.daemon_threads = True
        self.port = self.httpd.server_address[1]
        self._thread = threading.Thread(target=self.httpd.serve_forever, name="metrics-http",
                                        daemon=True)

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        if self._thread.is_alive():
            self.httpd.shutdown()
        self.httpd.server_close()


STALL_S = 10.0  # a status older than this means the daemon's loop is stuck


def healthz(doc: Mapping[str, Any] | None, now_ns: int | None = None) -> tuple[int, str]:
    """HTTP status and body of ``/healthz`` for a status document: its health verdict, and
    whether the document itself is fresh (a stuck daemon thread publishes none)."""
    if doc is None:
        return 503, "starting: no status yet\n"
    reasons = list((doc.get("health") or {}).get("reasons", []))
    age_s = ((time.time_ns() if now_ns is None else now_ns) - int(doc.get("wall_time_ns", 0))) / 1e9
    if age_s > STALL_S:
        reasons.append(f"daemon loop stalled: the last status is {age_s:.0f} s old")
    if not reasons:
        return 200, "ok\n"
    return 503, "".join(f"{r}\n" for r in reasons)
