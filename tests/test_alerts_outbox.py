"""Durable outbox: webhook delivery to a receiver that comes up late, no duplicates, restart,
and the e-mail rendering."""

from __future__ import annotations

import json
import re
import socket
import sqlite3
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pytest

from monitor.alerts.config import AlertsConfig
from monitor.alerts.delivery import EmailSender, OutboxSink, WebhookSender
from monitor.alerts.engine import AlertEngine
from monitor.alerts.outbox import Outbox
from monitor.events import ComponentObs, Observation
from waiting import wait_for

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`

NS = 1_000_000_000
T0 = 1_700_000_000 * NS


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Receiver:
    """A local Alertmanager-like webhook receiver recording every POST."""

    def __init__(self, port: int, fail_first: int = 0) -> None:
        self.bodies: list[dict] = []
        self.keys: list[str] = []
        self.fail_left = fail_first
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self):
                body = self.rfile.read(int(self.headers["Content-Length"]))
                if outer.fail_left > 0:
                    outer.fail_left -= 1
                    self.send_response(500)
                else:
                    outer.bodies.append(json.loads(body))
                    outer.keys.append(self.headers["Idempotency-Key"])
                    self.send_response(200)
                self.end_headers()

            def log_message(self, *args):
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", port), Handler)
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()




def damage_records():
    """fire, resend, clear of one damage-rate alert, as the engine emits them."""
    eng = AlertEngine.from_config(
        {"resend_interval_s": 10, "rule": [{"kind": "damage_rate", "threshold": 1.0}]},
        "b1", {"left": None})
    out = []
    for k, rate in enumerate([2.0, 2.0, 0.5], 1):
        c = ComponentObs(0.0, 0.0, rate, 1.0, float("nan"))
        out += eng.evaluate(Observation("b1", T0 + k * 10 * NS, 10.0, "measured",
                                        np.zeros(0, np.int64), np.zeros(0), 1.0, 1.0,
                                        {"left": c}, {}))
    assert [r.event for r in out] == ["fire", "resend", "clear"]
    return out


def test_webhook_delivers_after_receiver_comes_up_late_without_duplicates(tmp_path):
    port = free_port()
    cfg = AlertsConfig.from_dict({"webhook": {"url": f"http://127.0.0.1:{port}/hook",
                                              "timeout_s": 2},
                                  "outbox": {"retry_base_s": 0.05, "retry_max_s": 0.2}})
    sink = OutboxSink.from_config(cfg, str(tmp_path / "outbox.sqlite"))
    records = damage_records()
    sink.publish(records)
    # nobody listens yet: every attempt fails and is retried with backoff
    assert wait_for(lambda: sink.outbox.messages()[0]["attempts"] >= 3)
    assert sink.outbox.pending() == 3
    assert "Connection refused" in sink.outbox.messages()[0]["last_error"]
    rx = Receiver(port)
    try:
        assert wait_for(lambda: sink.outbox.pending() == 0)
        sink.publish(records)  # the same transitions again (e.g. after a restart): ignored
        # the outbox stores them once (enqueue dedups synchronously): nothing left to send
        assert len(sink.outbox.messages()) == 3 and sink.outbox.pending() == 0
        assert [b["alerts"][0]["status"] for b in rx.bodies] == ["firing", "firing", "resolved"]
        assert rx.keys == [f"{r.fingerprint}:{r.event}:{r.at_ns}" for r in records]
        first = rx.bodies[0]
        assert first["version"] == "4" and first["receiver"] == "buoymon"
        assert first["alerts"][0]["labels"]["alertname"] == "damage_rate"
        assert rx.bodies[2]["alerts"][0]["endsAt"] == "2023-11-14T22:13:50.000000Z"
    finally:
        sink.close()
        rx.close()


def test_http_error_is_retried_in_order(tmp_path):
    port = free_port()
    rx = Receiver(port, fail_first=2)
    box = Outbox(str(tmp_path / "o.sqlite"),
                 {"webhook": WebhookSender(AlertsConfig.from_dict(
                     {"webhook": {"url": f"http://127.0.0.1:{port}/"}}).webhook)},
                 retry_base_s=0.02, retry_max_s=0.05)
    try:
        for i in range(3):
            box.enqueue("webhook", f"k{i}", json.dumps({"i": i}).encode())
        box.start()
        assert wait_for(lambda: box.pending() == 0)
        assert [b["i"] for b in rx.bodies] == [0, 1, 2]
        assert [m["attempts"] for m in box.messages()] == [3, 1, 1]
    finally:
        box.close()
        rx.close()


def test_outbox_survives_restart_and_never_resends_delivered(tmp_path):
    path = str(tmp_path / "o.sqlite")
    sent: list[bytes] = []
    clock = [1000.0]

    def down(payload, key):
        raise ConnectionError("receiver down")

    class Jitter:  # the jitter's draw as a fraction of the capped backoff
        fraction = 1.0

        def uniform(self, a, b):
            assert (a, b) == (0.5, 1.0)
            return self.fraction

    jitter = Jitter()
    box = Outbox(path, {"webhook": down}, retry_base_s=5, retry_max_s=40,
                 clock=lambda: clock[0], rng=jitter)
    assert box.enqueue("webhook", "a", b"A") and box.enqueue("webhook", "b", b"B")
    assert not box.enqueue("webhook", "a", b"A")
    # backoff 5, 10, 20, 40, 40 s after successive failures (wall clock injected), each
    # drawn between half and all of that: here all, then half
    dues = []
    for fraction in (1.0, 1.0, 1.0, 1.0, 0.5):
        jitter.fraction = fraction
        dues.append(box.run_once() - clock[0])
        clock[0] += dues[-1]
    assert dues == [5, 10, 20, 40, 20]
    assert box.stats()["webhook"]["failures_total"] == 5
    box.close()

    box = Outbox(path, {"webhook": lambda p, k: sent.append(p)}, clock=lambda: clock[0])
    assert box.pending() == 2
    assert box.run_once() is None
    assert sent == [b"A", b"B"] and box.pending() == 0
    box.close()

    box = Outbox(path, {"webhook": lambda p, k: sent.append(p)}, clock=lambda: clock[0])
    assert box.run_once() is None and sent == [b"A", b"B"]  # nothing delivered twice
    assert [m["attempts"] for m in box.messages()] == [6, 1]
    clock[0] += 100
    assert box.prune(50) == 2 and box.messages() == []
    box.close()


def test_pending_by_channel_counts_undelivered_messages_of_every_channel(tmp_path):
    """The status's outbox depth (monitor.cmd_run.AlertDelivery.status_fields)."""
    def down(payload, key):
        raise ConnectionError("receiver down")

    box = Outbox(str(tmp_path / "o.sqlite"), {"webhook": down, "email": lambda p, k: None})
    assert box.pending_by_channel() == {"webhook": 0, "email": 0}
    for k in "abc":
        box.enqueue("webhook", k, b"x")
    box.enqueue("email", "a", b"x")
    assert box.pending_by_channel() == {"webhook": 3, "email": 1}
    box.run_once()  # e-mail delivered, the webhook's head failed
    assert box.pending_by_channel() == {"webhook": 3, "email": 0}
    box.close()


def test_pending_age_is_monotonic_within_a_process_across_a_wall_clock_step(tmp_path):
    """alert_delivery_stalled's age (oldest_pending_age_s): a logger's RTC stepped an hour
    forward (GNSS/NTP at boot) does not age the messages of this process; one from before
    it is as old as its wall-clock age now."""
    wall, mono = [1_000.0], [50.0]

    def down(payload, key):
        raise ConnectionError("receiver down")

    def open_box() -> Outbox:
        return Outbox(str(tmp_path / "o.sqlite"), {"webhook": down, "email": lambda p, k: None},
                      clock=lambda: wall[0], monotonic=lambda: mono[0])

    box = open_box()
    box.enqueue("webhook", "a", b"A")
    box.enqueue("email", "a", b"A")
    wall[0] += 3600.0  # the step
    mono[0] += 12.0
    box.enqueue("webhook", "b", b"B")
    mono[0] += 8.0
    ages = {ch: c["oldest_pending_age_s"] for ch, c in box.stats().items()}
    assert ages == {"webhook": 20.0, "email": 20.0}  # with the wall clock: 3620 s
    box.run_once()  # e-mail delivered, the webhook's head retried later
    stats = box.stats()
    assert stats["email"]["oldest_pending_age_s"] is None
    assert stats["webhook"]["oldest_pending_age_s"] == 20.0
    box.close()
    # a new process (its monotonic clock from elsewhere), 100 s of wall clock later: the
    # messages of the last one are as old as the wall clock says (only it spans processes:
    # the step counts now)
    wall[0] += 100.0
    mono[0] = 7.0
    box = open_box()
    mono[0] += 5.0
    wall[0] += 5.0
    assert box.stats()["webhook"]["oldest_pending_age_s"] == 3600.0 + 100.0 + 5.0
    box.close()


def test_pending_age_of_an_earlier_process_counts_after_a_late_rtc_step(tmp_path):
    """A message left pending by the last process, the outbox opened while the wall clock is
    still the logger's RTC (3 h behind), then stepped by GNSS/NTP: the old message's age is
    its wall-clock age at each look (not frozen near 0 from the opening), and this process's
    own stuck message counts too (the channel reports the older of the two)."""
    true_t = 1_790_000_000.0  # when the last process enqueued
    wall, mono = [true_t], [100.0]

    def down(payload, key):
        raise ConnectionError("receiver down")

    def open_box() -> Outbox:
        return Outbox(str(tmp_path / "o.sqlite"), {"webhook": down},
                      clock=lambda: wall[0], monotonic=lambda: mono[0])

    box = open_box()
    box.enqueue("webhook", "old", b"A")
    box.close()
    # power off 1 h; boot: the RTC (fake-hwclock saved 2 h before) is 3 h behind true time
    wall[0], mono[0] = true_t - 7200.0, 5.0
    box = open_box()
    mono[0] += 10.0
    assert box.stats()["webhook"]["oldest_pending_age_s"] == 0.0  # the RTC says the future
    box.enqueue("webhook", "new", b"B")  # this life's message, receiver still down
    mono[0] += 1800.0
    wall[0] += 1810.0
    # still behind: the old one's wall age is negative, this process's own one is 1800 s old
    assert box.stats()["webhook"]["oldest_pending_age_s"] == 1800.0
    wall[0] = true_t + 3600.0 + 1810.0 + 60.0  # NTP/GNSS steps the clock
    mono[0] += 60.0
    assert box.stats()["webhook"]["oldest_pending_age_s"] == 3600.0 + 1810.0 + 60.0
    box.close()


def test_outbox_rejects_unknown_channel(tmp_path):
    box = Outbox(str(tmp_path / "o.sqlite"), {"webhook": lambda p, k: None})
    with pytest.raises(ValueError, match="channel 'email': no sender"):
        box.enqueue("email", "k", b"x")
    box.close()


class SmtpCapture:
    """Minimal SMTP server (enough of RFC 5321 for smtplib) that stores received messages."""

    def __init__(self, refuse: set[str] = frozenset(), connections: int = 1) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(1)
        self.port = self.sock.getsockname()[1]
        self.messages: list[str] = []
        self.refuse = refuse  # recipients answered 550 (mailbox unavailable)
        self.thread = threading.Thread(target=self._serve_many, args=(connections,),
                                       daemon=True)
        self.thread.start()

    def _serve_many(self, n: int) -> None:
        for _ in range(n):
            self._serve()

    def _serve(self) -> None:
        conn, _ = self.sock.accept()
        with conn, conn.makefile("rwb") as f:
            def say(line):
                f.write(line.encode() + b"\r\n")
                f.flush()
            say("220 test")
            while line := f.readline().decode():
                cmd = line[:4].upper()
                if cmd in ("EHLO", "HELO"):
                    say("250 test")
                elif cmd == "RCPT" and any(r in line for r in self.refuse):
                    say("550 mailbox unavailable")
                elif cmd == "DATA":
                    say("354 go")
                    data = []
                    while (row := f.readline().decode()) != ".\r\n":
                        data.append(row)
                    self.messages.append("".join(data))
                    say("250 ok")
                elif cmd == "QUIT":
                    say("221 bye")
                    return
                else:
                    say("250 ok")


def test_email_through_outbox(tmp_path):
    smtp = SmtpCapture()
    cfg = AlertsConfig.from_dict({"email": {"host": "127.0.0.1", "port": smtp.port,
                                            "from": "buoymon@example.org",
                                            "to": "ops@example.org"}})
    sink = OutboxSink.from_config(cfg, str(tmp_path / "o.sqlite"))
    try:
        rec = damage_records()[0]
        sink.publish([rec])
        assert wait_for(lambda: sink.outbox.pending() == 0)
    finally:
        sink.close()
    msg = smtp.messages[0]
    assert "Subject: [buoymon FIRING] warning damage_rate left (buoy b1)" in msg
    assert "value: 2 1/d" in msg and "threshold: 1 1/d" in msg
    assert EmailSender(cfg.email).message(json.dumps(rec.to_dict()).encode(), "f:fire:1")[
        "Message-ID"] == "<f.fire.1@buoymon>"


def test_email_refused_by_the_server_is_a_dead_letter_and_the_next_one_goes(tmp_path):
    smtp = SmtpCapture(refuse={"gone@example.org"}, connections=2)
    cfg = AlertsConfig.from_dict({"email": {"host": "127.0.0.1", "port": smtp.port,
                                            "from": "buoymon@example.org",
                                            "to": "gone@example.org"}})
    box = Outbox(str(tmp_path / "o.sqlite"), {"email": EmailSender(cfg.email)})
    good = EmailSender(AlertsConfig.from_dict({"email": {
        "host": "127.0.0.1", "port": smtp.port, "from": "buoymon@example.org",
        "to": "ops@example.org"}}).email)
    try:
        rec = damage_records()[0]
        box.enqueue("email", "a", json.dumps(rec.to_dict()).encode())
        box.enqueue("email", "b", json.dumps(rec.to_dict()).encode())
        box.senders["email"] = lambda p, k: (EmailSender(cfg.email) if k == "a" else good)(p, k)
        assert box.run_once() is None
        st = box.stats()["email"]
        assert st["dead_letters"] == 1 and st["delivered_total"] == 1
        assert "recipients refused" in box.messages(dead_only=True)[0]["last_error"]
        assert len(smtp.messages) == 1
    finally:
        box.close()


def test_refused_message_becomes_a_dead_letter_and_does_not_block(tmp_path):
    """A 4xx from the receiver: the message is kept aside with the answer's body, counted,
    and the next one goes out at once; an operator can retry or discard dead letters."""
    refused = {"k0"}
    got: list[str] = []

    class Refusing(BaseHTTPRequestHandler):
        def do_POST(self):
            body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
            if body["k"] in refused:
                self.send_response(400)
                self.end_headers()
                self.wfile.write(b'{"message":"cannot unmarshal object"}')
            else:
                got.append(body["k"])
                self.send_response(200)
                self.end_headers()

        def log_message(self, *args):
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Refusing)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{server.server_address[1]}/"
    box = Outbox(str(tmp_path / "o.sqlite"), {"webhook": WebhookSender(AlertsConfig.from_dict(
        {"webhook": {"url": url}}).webhook)}, retry_base_s=30, retry_max_s=60)
    try:
        for i in range(3):
            box.enqueue("webhook", f"k{i}", json.dumps({"k": f"k{i}"}).encode())
        assert box.run_once() is None  # nothing left to retry: k0 is dead, k1 and k2 sent
        assert got == ["k1", "k2"]
        st = box.stats()["webhook"]
        assert st["dead_letters"] == 1 and st["dead_total"] == 1 and st["pending"] == 0
        assert st["delivered_total"] == 2 and st["failures_total"] == 0
        dead = box.messages(dead_only=True)
        assert [d["dedup_key"] for d in dead] == ["k0"]
        assert "HTTP 400" in dead[0]["last_error"] and "cannot unmarshal" in dead[0]["last_error"]
        refused.clear()
        assert box.settle_dead(retry=True) == 1
        assert box.run_once() is None and got == ["k1", "k2", "k0"]
        assert box.stats()["webhook"]["dead_letters"] == 0
    finally:
        box.close()
        server.shutdown()
        server.server_close()


def test_full_outbox_drops_the_oldest_and_counts_them(tmp_path):
    box = Outbox(str(tmp_path / "o.sqlite"), {"webhook": lambda p, k: None}, max_pending=3)
    try:
        for i in range(5):
            box.enqueue("webhook", f"k{i}", b"x")
        assert [m["dedup_key"] for m in box.messages()] == ["k2", "k3", "k4"]
        assert box.stats()["webhook"]["dropped_total"] == 2
        # the dropped ones' enqueue times are forgotten with them (memory stays bounded)
        assert sorted(box._enqueued) == [m["id"] for m in box.messages()]
    finally:
        box.close()


class _Sqlite334:
    """The outbox's connection as SQLite 3.34 (Debian 11) would parse it: ``RETURNING`` (3.35)
    is a syntax error there. A stand-in: the venv's SQLite is newer."""

    def __init__(self, db: sqlite3.Connection) -> None:
        self._db = db

    def execute(self, sql: str, *args):
        if re.search(r"\bRETURNING\b", sql, re.IGNORECASE):
            raise sqlite3.OperationalError('near "RETURNING": syntax error')
        return self._db.execute(sql, *args)

    def __getattr__(self, name: str):
        return getattr(self._db, name)


def test_full_outbox_drops_the_oldest_on_sqlite_3_34(tmp_path):
    box = Outbox(str(tmp_path / "o.sqlite"), {"webhook": lambda p, k: None}, max_pending=2)
    box._db = _Sqlite334(box._db)
    try:
        for i in range(4):
            box.enqueue("webhook", f"k{i}", b"x")
        assert [m["dedup_key"] for m in box.messages()] == ["k2", "k3"]
        assert box.stats()["webhook"]["dropped_total"] == 2
        assert sorted(box._enqueued) == [m["id"] for m in box.messages()]
    finally:
        box.close()


def test_an_outbox_of_an_older_version_is_upgraded(tmp_path):
    import sqlite3
    path = str(tmp_path / "old.sqlite")
    db = sqlite3.connect(path)
    db.executescript("""CREATE TABLE outbox (id INTEGER PRIMARY KEY AUTOINCREMENT,
        channel TEXT NOT NULL, dedup_key TEXT NOT NULL, payload BLOB NOT NULL,
        created_s REAL NOT NULL, attempts INTEGER NOT NULL DEFAULT 0,
        next_attempt_s REAL NOT NULL, delivered_s REAL, last_error TEXT,
        UNIQUE (channel, dedup_key));
        INSERT INTO outbox (channel, dedup_key, payload, created_s, next_attempt_s)
        VALUES ('webhook', 'old', x'41', 1.0, 1.0);""")
    db.commit()
    db.close()
    sent = []
    box = Outbox(path, {"webhook": lambda p, k: sent.append(p)})
    try:
        assert box.run_once() is None and sent == [b"A"]
    finally:
        box.close()


def test_a_damaged_outbox_is_named_by_the_daemon_and_the_outbox_command(tmp_path):
    """An outbox file that is not an outbox database (damaged, or another file at its path):
    `buoymon run` and `buoymon alerts outbox` ended in a traceback (sqlite3.DatabaseError:
    file is not a database); a missing folder of `[alerts.outbox] path` likewise (unable to
    open database file)."""
    import os  # noqa: PLC0415
    import subprocess  # noqa: PLC0415
    import sys  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    repo = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(repo)}
    bad = tmp_path / "outbox.sqlite"
    bad.write_bytes(b"garbage, not SQLite" * 300)
    cfg = tmp_path / "cfg.toml"
    base = (repo / "monitor" / "vaps_seed004.toml").read_text() + (
        f'\n[state]\npath = "{tmp_path / "st.sqlite"}"\n[metrics]\nenabled = false\n'
        '[alerts.webhook]\nurl = "http://127.0.0.1:9/hook"\n[alerts.outbox]\n')
    cfg.write_text(base + f'path = "{bad}"\n')
    for cmd, rc in ((["run"], 2), (["alerts", "outbox"], 1)):
        p = subprocess.run([sys.executable, "-m", "monitor.cli", *cmd, "--config", str(cfg)],
                           capture_output=True, text=True, timeout=120, env=env)
        assert p.returncode == rc and "Traceback" not in p.stderr, p.stderr
        assert f"{bad}: not an alert outbox database (file is not a database)" in p.stderr
    assert bad.read_bytes() == b"garbage, not SQLite" * 300
    # a folder that does not exist yet is made, as for the state
    box = Outbox(str(tmp_path / "new" / "deeper" / "o.sqlite"), {})
    assert box.pending() == 0
    box.close()
