"""Alerts produced to a real Prometheus Alertmanager (the Debian package, on loopback).

A daemon process (fake physics, tests/daemon_harness.py) raises the live `data_age` alert
when its data stops and clears it when data flows again; it delivers through
`[alerts.alertmanager]`. Checked through Alertmanager's own API (GET /api/v2/alerts) and the
notifications Alertmanager sends to a local webhook receiver: our labels and annotations,
no flapping past Alertmanager's resolve_timeout, one firing and one resolved notification,
delivery after an Alertmanager outage, and a misdirected payload (the receiver body sent to
the API, HTTP 400) kept as a dead letter that is itself alerted, without blocking anything.
"""

from __future__ import annotations

import json
import queue
import re
import shutil
import sqlite3
import subprocess
import sys
import threading
import time
import urllib.request
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Callable

import pytest

from daemon_harness import BUOY, ENV, DaemonProcess, free_port, write_config
from test_daemon_live import HARNESS, Client, _block, http_get
from waiting import wait_until

AM_BIN = shutil.which("prometheus-alertmanager") or shutil.which("alertmanager")
pytestmark = [pytest.mark.integration, pytest.mark.skipif(
    AM_BIN is None, reason="prometheus-alertmanager is not installed (make test installs the "
                           "Debian package prometheus-alertmanager when it can)")]
RESOLVE_TIMEOUT_S = 5


class Notifications:
    """Alertmanager's webhook receiver: every notification it sends, in order."""

    def __init__(self) -> None:
        self.got: "queue.SimpleQueue[dict]" = queue.SimpleQueue()
        got = self.got

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802
                got.put(json.loads(self.rfile.read(int(self.headers["Content-Length"]))))
                self.send_response(200)
                self.end_headers()

            def log_message(self, *args) -> None:
                pass

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}/notify"
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


class Alertmanager:
    """prometheus-alertmanager on 127.0.0.1 with a temporary storage, no clustering, routing
    every alert to ``receiver_url`` at once (group_wait 1 s)."""

    def __init__(self, workdir: Path, receiver_url: str) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.workdir = workdir
        (workdir / "am.yml").write_text(
            f"global:\n  resolve_timeout: {RESOLVE_TIMEOUT_S}s\n"
            "route:\n  receiver: hook\n  group_by: [alertname, buoy]\n  group_wait: 1s\n"
            "  group_interval: 1s\n  repeat_interval: 1h\n"
            f"receivers:\n  - name: hook\n    webhook_configs:\n      - url: {receiver_url}\n"
            "        send_resolved: true\n")
        self.proc: subprocess.Popen | None = None
        self.start()

    def start(self) -> None:
        self.proc = subprocess.Popen(
            [AM_BIN, f"--config.file={self.workdir / 'am.yml'}",
             f"--storage.path={self.workdir / 'am-data'}",
             f"--web.listen-address=127.0.0.1:{self.port}", "--cluster.listen-address=",
             "--log.level=warn"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            try:
                urllib.request.urlopen(f"{self.url}/-/ready", timeout=1).close()
                return
            except OSError:
                time.sleep(0.1)
        raise AssertionError("alertmanager did not become ready: "
                             + self.proc.stderr.read().decode(errors="replace"))

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.terminate()
            self.proc.wait(10)
            self.proc = None

    def alerts(self) -> list[dict]:
        with urllib.request.urlopen(f"{self.url}/api/v2/alerts", timeout=5) as r:
            return json.loads(r.read())

    def active(self, alertname: str) -> list[dict]:
        return [a for a in self.alerts() if a["labels"].get("alertname") == alertname
                and a["status"]["state"] == "active"]


def _attempts(outbox: Path, channel: str) -> int:
    """Delivery attempts of the channel's oldest message, read from the outbox database."""
    db = sqlite3.connect(f"file:{outbox}?mode=ro", uri=True, timeout=10)
    try:
        row = db.execute("SELECT attempts FROM outbox WHERE channel = ? ORDER BY id LIMIT 1",
                         (channel,)).fetchone()
    finally:
        db.close()
    return 0 if row is None else int(row[0])


def _feed(client: Client, stop: threading.Event, first_s: int) -> None:
    """Publish one block a second (sensor time in step with the wall clock) until stopped."""
    k = 0
    while not stop.wait(0.0 if k == 0 else 0.5):
        client.put(_block((first_s + k) * 10**9, k))
        k += 1


def _group_notes(rx: Notifications, last: Callable[[dict], bool], timeout: float = 30.0
                 ) -> list[dict]:
    """The receiver's notifications of the data_age group, in order, up to and including the
    first one for which ``last`` holds (AssertionError after ``timeout`` s without it)."""
    notes: list[dict] = []
    deadline = time.monotonic() + timeout
    while not notes or not last(notes[-1]):
        try:
            n = rx.got.get(timeout=max(0.0, deadline - time.monotonic()))
        except queue.Empty:
            raise AssertionError(f"no closing notification within {timeout:g} s; got {notes}")
        if n["groupLabels"].get("alertname") == "data_age":
            notes.append(n)
    return notes


def _nothing_more_after_resolved(manager: Alertmanager, rx: Notifications) -> None:
    """One firing and one resolved notification of the data_age group, and nothing after them.

    "Nothing after" is shown by an event, not a wait: once the resolved notification is in,
    a sentinel alert is posted into the same Alertmanager group. The group's next
    notification carries it; a repeat or a flap of our alert would come before it or inside
    it, as a notification of its own or as a firing alert next to the sentinel."""
    notes = _group_notes(rx, lambda n: n["status"] == "resolved")
    assert [n["status"] for n in notes] == ["firing", "resolved"]
    assert [a["labels"]["component"] for a in notes[1]["alerts"]] == ["tension"]
    sentinel = {"alertname": "data_age", "buoy": BUOY, "component": "sentinel"}
    urllib.request.urlopen(urllib.request.Request(
        f"{manager.url}/api/v2/alerts", data=json.dumps([{"labels": sentinel}]).encode(),
        headers={"Content-Type": "application/json"}, method="POST"), timeout=5).close()
    later = _group_notes(rx, lambda n: any(a["labels"].get("component") == "sentinel"
                                           for a in n["alerts"]))
    assert len(later) == 1, f"notifications after the resolved one: {later[:-1]}"
    assert [a["labels"]["component"] for a in later[0]["alerts"]
            if a["status"] == "firing"] == ["sentinel"]


@pytest.fixture()
def am(tmp_path):
    rx = Notifications()
    manager = Alertmanager(tmp_path, rx.url)
    yield manager, rx
    manager.stop()
    rx.close()


def test_alerts_reach_alertmanager_stay_active_and_resolve(tmp_path, am):
    manager, rx = am
    port = free_port()
    cfg = write_config(
        tmp_path / "cfg.toml", port, tmp_path / "state.sqlite", tension_age_s=1.0,
        extra=f'[alerts.alertmanager]\nurl = "{manager.url}"\nresend_interval_s = 1.0\n'
              'runbook_url = "https://runbooks.example/buoymon/{alertname}"\n'
              'instance = "logger-1"\n'
              f'[alerts.webhook]\nurl = "{manager.url}/api/v2/alerts"\n'
              f'[alerts.outbox]\npath = "{tmp_path / "outbox.sqlite"}"\nretry_base_s = 0.2\n'
              'retry_max_s = 1.0\n')
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
    d.wait_for("READY=1")
    c = Client(port)
    stop = threading.Event()
    try:
        now_s = time.time_ns() // 10**9
        for k in range(2):
            c.put(_block((now_s + k) * 10**9, k))
        # the data stops: data_age fires and reaches Alertmanager with our labels
        fired = wait_until(lambda: manager.active("data_age"), what="data_age active in AM", interval=0.2)
        a = fired[0]
        assert a["labels"] == {"alertname": "data_age", "severity": "warning", "buoy": BUOY,
                               "component": "tension", "instance": "logger-1",
                               "job": "buoymon"}
        assert a["annotations"]["runbook_url"] == "https://runbooks.example/buoymon/data_age"
        assert "tension" in a["annotations"]["summary"]
        assert a["annotations"]["description"].startswith(a["annotations"]["summary"])
        # it stays active well past Alertmanager's resolve_timeout: no flapping
        t_end = time.monotonic() + 2 * RESOLVE_TIMEOUT_S
        while time.monotonic() < t_end:
            assert manager.active("data_age"), "the alert left Alertmanager while firing"
            time.sleep(0.5)
        # the receiver body sent to Alertmanager's API is refused (HTTP 400): a dead letter,
        # alerted on its own (and that alert reaches Alertmanager), while the rest flows
        refused = wait_until(lambda: manager.active("alert_delivery_refused"),
                        what="alert_delivery_refused active in AM", interval=0.2)
        assert refused[0]["labels"]["component"] == "webhook"
        out = subprocess.run([sys.executable, "-m", "monitor.cli", "alerts", "outbox",
                              "--outbox", str(tmp_path / "outbox.sqlite"), "--json"],
                             env=ENV, capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        box = json.loads(out.stdout)
        assert box["channels"]["webhook"]["dead_letters"] >= 1
        assert "HTTP 400" in box["dead_letters"][0]["last_error"]
        assert "unmarshal" in box["dead_letters"][0]["last_error"]
        assert box["channels"]["alertmanager"]["dead_letters"] == 0
        # data flows again: the alert is resolved in Alertmanager
        feeder = threading.Thread(target=_feed, args=(c, stop, now_s + 2), daemon=True)
        feeder.start()
        wait_until(lambda: not manager.active("data_age"), what="data_age resolved in AM", interval=0.2)
        # one firing and one resolved notification for the data_age group, nothing more
        _nothing_more_after_resolved(manager, rx)
    finally:
        stop.set()
        c.close()
        assert d.terminate() == 0


def test_an_alertmanager_outage_delays_but_loses_nothing(tmp_path, am):
    manager, rx = am
    manager.stop()  # down before the alert fires
    port = free_port()
    cfg = write_config(
        tmp_path / "cfg.toml", port, tmp_path / "state.sqlite", tension_age_s=1.0,
        health="delivery_stall_s = 3.0\n",
        extra=f'[alerts.alertmanager]\nurl = "{manager.url}"\nresend_interval_s = 1.0\n'
              f'[alerts.outbox]\npath = "{tmp_path / "outbox.sqlite"}"\nretry_base_s = 0.2\n'
              'retry_max_s = 1.0\n')
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
    d.wait_for("READY=1")
    c = Client(port)
    stop = threading.Event()
    try:
        now_s = time.time_ns() // 10**9
        c.put(_block(now_s * 10**9, 0))
        c.wait_alert("data_age", "put")
        # several failed attempts against the stopped Alertmanager (the outbox counts them)
        wait_until(lambda: _attempts(tmp_path / "outbox.sqlite", "alertmanager") >= 3,
                   what="3 failed attempts", interval=0.2)
        # `buoymon status` says how long the alert has waited, not only that it waits (it
        # shows the daemon's last status, published every 0.5 s: asked until that status
        # has the attempts counted above)
        def shown() -> re.Match | None:
            out = subprocess.run([sys.executable, "-m", "monitor.cli", "status", "--config",
                                  str(cfg)], env=ENV, capture_output=True, text=True,
                                 timeout=60).stdout
            m = re.search(r"outbox: alertmanager (\d+) pending \(oldest (\d+) s, (\d+) "
                          r"failed attempts\)", out)
            return m if m and int(m[1]) >= 1 and int(m[3]) >= 3 else None

        wait_until(shown, what="status showing 3 failed attempts", interval=0.2)
        # undelivered for over delivery_stall_s: alerted where it can be (Zenoh, /healthz)
        stalled, _ = c.wait_alert("alert_delivery_stalled", "put")
        assert stalled["labels"]["component"] == "alertmanager", stalled
        assert stalled["value"] > 3.0 and "undelivered" in stalled["summary"], stalled
        mport = int(cfg.read_text().split("[metrics]\nport = ")[1].split()[0])
        code, body = http_get(mport, "/healthz")
        assert code == 503 and "alert_delivery_stalled alertmanager" in body, body
        manager.start()
        c.wait_alert("alert_delivery_stalled", "delete")  # delivered: it clears
        wait_until(lambda: manager.active("data_age"), what="data_age active after the outage", interval=0.2)
        feeder = threading.Thread(target=_feed, args=(c, stop, now_s + 1), daemon=True)
        feeder.start()
        wait_until(lambda: not manager.active("data_age"), what="data_age resolved", interval=0.2)
        # one firing and one resolved notification for the data_age group, nothing more
        _nothing_more_after_resolved(manager, rx)
    finally:
        stop.set()
        c.close()
        assert d.terminate() == 0
