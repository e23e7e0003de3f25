"""Live (wall-clock) alerts, clock faults, `buoymon status`, /metrics and /healthz of a real
daemon process over real Zenoh and HTTP (fake physics, see daemon_harness).

The alerts are read where an operator's tools read them: the Zenoh alert keys; the metrics
are scraped over HTTP and parsed with prometheus_client's parser, then compared with what
`buoymon status --json` (a separate process) reports.
"""

import json
import os
import queue
import re
import socket
import sqlite3
import subprocess
import sys
import time
import urllib.error
import urllib.request
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pytest
import zenoh
from mcap.reader import make_reader
from prometheus_client.parser import text_string_to_metric_families

from monitor import zenoh_io
from monitor.blocks import SampleBlock
from monitor.daemon_config import ZenohConfig

from daemon_harness import (
    BUOY, ENV, RATE_HZ, DaemonProcess, FakeCodec, free_port, wait_until_state, write_config,
)

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`

HARNESS = os.path.join(os.path.dirname(__file__), "daemon_harness.py")
REPO = Path(__file__).resolve().parents[1]
YEAR_NS = 365 * 86400 * 10**9


def _block(t0_ns: int, seed: int = 0) -> SampleBlock:
    t = t0_ns + np.arange(RATE_HZ, dtype=np.int64) * (10**9 // RATE_HZ)
    v = 5000.0 + np.random.default_rng(seed).standard_normal(RATE_HZ)
    return SampleBlock(BUOY, "tension", t, {"tension_N": v})


class Client:
    """A Zenoh client of the daemon: puts blocks, collects alert PUTs and DELETEs."""

    def __init__(self, port: int) -> None:
        zc = ZenohConfig(mode="client", listen=(), connect=(f"tcp/127.0.0.1:{port}",))
        self.session = zenoh_io.open_session(zc)
        self.alerts: "queue.SimpleQueue[tuple[str, str, dict | None, float]]" = queue.SimpleQueue()

        def on_alert(s: zenoh.Sample) -> None:
            put = s.kind == zenoh.SampleKind.PUT
            self.alerts.put((str(s.key_expr), "put" if put else "delete",
                             json.loads(s.payload.to_bytes()) if put else None, time.monotonic()))

        self.seen: list[tuple[str, str, dict | None, float]] = []
        self.sub = self.session.declare_subscriber(f"buoy/{BUOY}/monitor/alert/**", on_alert)
        self.pub = zenoh_io.declare_data_publisher(self.session, f"buoy/{BUOY}/sensor/tension")

    def put(self, block: SampleBlock) -> None:
        self.pub.put(FakeCodec().encode(block))

    def wait_alert(self, rule: str, kind: str, timeout: float = 30.0) -> tuple[dict | None, float]:
        """The first not yet taken PUT or DELETE of ``rule``'s alert (any component)."""
        deadline = time.monotonic() + timeout
        while True:
            for i, (key, k, doc, at) in enumerate(self.seen):
                if key.startswith(f"buoy/{BUOY}/monitor/alert/{rule}/") and k == kind:
                    del self.seen[i]
                    return doc, at
            if time.monotonic() > deadline:
                raise AssertionError(f"no {kind} of alert {rule} within {timeout} s; "
                                     f"seen {[(e[0], e[1]) for e in self.seen]}")
            try:
                self.seen.append(self.alerts.get(timeout=0.2))
            except queue.Empty:
                pass

    def close(self) -> None:
        self.sub.undeclare()
        self.pub.undeclare()
        self.session.close()


def http_get(port: int, path: str, timeout: float = 5.0) -> tuple[int, str]:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=timeout) as r:
            return r.status, r.read().decode()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read().decode()


def scrape(port: int) -> dict[tuple[str, tuple], float]:
    _, text = http_get(port, "/metrics")
    return {(s.name, tuple(sorted(s.labels.items()))): s.value
            for fam in text_string_to_metric_families(text) for s in fam.samples}


def status_cli(cfg: Path) -> dict:
    out = subprocess.run([sys.executable, "-m", "monitor.cli", "status", "--config", str(cfg),
                          "--json"], env=ENV, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def metrics_port(cfg: Path) -> int:
    return int(cfg.read_text().split("[metrics]\nport = ")[1].split()[0])


class Webhook:
    """An HTTP receiver on loopback keeping every POSTed JSON body (an Alertmanager stand-in
    for the delivery path; tests/test_integration_alerts.py covers a real Alertmanager)."""

    def __init__(self) -> None:
        from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
        import threading

        bodies = self.bodies = queue.SimpleQueue()

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802
                bodies.put(json.loads(self.rfile.read(int(self.headers["Content-Length"]))))
                self.send_response(200)
                self.end_headers()

            def log_message(self, *args) -> None:
                pass

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}/hook"
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()

    def wait(self, alertname: str, status: str, timeout: float = 30.0) -> dict:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                body = self.bodies.get(timeout=0.2)
            except queue.Empty:
                continue
            for a in body["alerts"]:
                if a["labels"]["alertname"] == alertname and a["status"] == status:
                    return a
        raise AssertionError(f"webhook got no {status} {alertname} within {timeout} s")

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


def test_data_age_alert_fires_and_clears_and_metrics_equal_the_status(tmp_path):
    port = free_port()
    hook = Webhook()
    cfg = write_config(tmp_path / "cfg.toml", port, tmp_path / "state.sqlite",
                       record=tmp_path / "rec", tension_age_s=1.0,
                       extra=f'[alerts.webhook]\nurl = "{hook.url}"\n'
                       f'[alerts.outbox]\npath = "{tmp_path / "outbox.sqlite"}"\n'
                       'retry_base_s = 0.1\n')
    mport = metrics_port(cfg)
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
    d.wait_for("READY=1")
    c = Client(port)
    try:
        now = time.time_ns() // 10**9 * 10**9
        for k in range(3):
            c.put(_block(now + k * 10**9, k))
        wait_until_state(port, lambda s: s["status"]["streams"]["tension"]["accepted"] == 60)
        stopped = time.monotonic()
        doc, fired_at = c.wait_alert("data_age", "put")
        # fires within the 1-s timeout plus one status interval (0.5 s) of the data stopping
        assert fired_at - stopped < 1.0 + 0.5 + 2.0  # (margin for a loaded machine)
        assert doc["labels"] == {"buoy": BUOY, "component": "tension", "rule": "data_age"}
        assert doc["state"] == "firing" and doc["threshold"] == 1.0 and doc["value"] > 1.0
        # the same alert through the outbox to the webhook (Alertmanager's format)
        am = hook.wait("data_age", "firing")
        assert am["labels"] == {"alertname": "data_age", "severity": "warning", "buoy": BUOY,
                                "component": "tension", "rule": "data_age"}
        code, body = http_get(mport, "/healthz")
        assert code == 503 and "data_age tension" in body
        # the metrics equal the status (`buoymon status --json`, another process)
        status = status_cli(cfg)
        assert status["source"] == "daemon"
        st = status["status"]
        m = scrape(mport)
        b = (("buoy", BUOY),)
        ts = (("buoy", BUOY), ("stream", "tension"))
        assert m[("buoymon_samples_accepted_total", ts)] == st["streams"]["tension"]["accepted"] == 60
        for reason, n in st["streams"]["tension"]["rejected"].items():
            assert m[("buoymon_samples_rejected_total", tuple(sorted(ts + (("reason", reason),))))] == n
        comp = (("buoy", BUOY), ("component", "conductor"))
        assert m[("buoymon_damage_ratio", comp)] == st["components"]["conductor"]["damage"]
        assert m[("buoymon_damage_committed_ratio", comp)] == \
            st["components"]["conductor"]["damage_committed"]
        assert m[("buoymon_messages_total", b)] == st["counters"]["messages"] == 3
        assert m[("buoymon_data_stale", ts)] == 1.0 and st["streams"]["tension"]["data_stale"]
        assert m[("buoymon_data_age_seconds", ts)] > 1.0
        assert m[("buoymon_healthy", b)] == 0.0 and not st["health"]["ok"]
        firing = {k[1] for k, v in m.items() if k[0] == "buoymon_alert_firing" and v == 1.0}
        assert {tuple(sorted({"buoy": BUOY, "rule": a["rule"], "component": a["component"],
                              "severity": a["severity"]}.items()))
                for a in st["alerts"]["active"]} == firing
        assert ("buoymon_checkpoint_age_seconds", b) in m and ("process_cpu_seconds_total", ()) in m
        hook_lab = (("buoy", BUOY), ("channel", "webhook"))
        assert m[("buoymon_outbox_pending_messages", hook_lab)] == \
            st["delivery"]["channels"]["webhook"]["pending"] == 0
        # data flows again: the alert clears (a DELETE on its key), health is back
        c.put(_block(now + 3 * 10**9, 3))
        c.wait_alert("data_age", "delete")
        assert http_get(mport, "/healthz") == (200, "ok\n")
        assert hook.wait("data_age", "resolved")["endsAt"] != "0001-01-01T00:00:00Z"
    finally:
        c.close()
        hook.close()
        assert d.terminate() == 0
    # consistent stamps: recorded statuses and alerts carry sensor time, never going back
    stamps: dict[str, list[tuple[int, dict]]] = {}
    for name in sorted(os.listdir(tmp_path / "rec")):
        with open(tmp_path / "rec" / name, "rb") as f:
            for _, ch, msg in make_reader(f).iter_messages(log_time_order=False):
                if "/monitor/" in ch.topic:
                    stamps.setdefault(ch.topic, []).append((msg.publish_time, json.loads(msg.data)))
    status_rec = stamps[f"buoy/{BUOY}/monitor/status"]
    assert [t for t, _ in status_rec] == [doc["now_ns"] for _, doc in status_rec]
    assert [t for t, _ in status_rec] == sorted(t for t, _ in status_rec)
    alert_rec = stamps[f"buoy/{BUOY}/monitor/alert/data_age/tension"]
    events = [a["event"] for _, a in alert_rec]  # (fires again once the last data ages out)
    assert events[:2] == ["fire", "clear"] and events == ["fire", "clear"] * (len(events) // 2) \
        + ["fire"] * (len(events) % 2)
    assert all(now <= t <= now + 4 * 10**9 for t, _ in alert_rec)  # sensor time, not wall


def test_clock_jumps_of_a_year_and_a_restarted_publisher_are_alerted(tmp_path):
    """A block a year ahead is a clock_skew; the stream going on at the right time after it is
    no time_restart (the real pipeline rejects that block as time_ahead, tests/
    test_time_ahead.py; this fake one takes it); a block a year behind is one."""
    port = free_port()
    cfg = write_config(tmp_path / "cfg.toml", port, tmp_path / "state.sqlite",
                       tension_age_s=60.0)
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
    d.wait_for("READY=1")
    c = Client(port)
    try:
        now = time.time_ns() // 10**9 * 10**9
        c.put(_block(now))
        c.put(_block(now + YEAR_NS, 1))  # the sensor clock jumps a year ahead
        doc, _ = c.wait_alert("clock_skew", "put")
        assert doc["labels"]["component"] == "tension"
        assert abs(doc["value"] - YEAR_NS / 1e9) < 5.0 and "ahead of" in doc["summary"]
        c.put(_block(now + 2 * 10**9, 2))  # back to the right time: no restart
        c.wait_alert("clock_skew", "delete")  # its clock is right again
        st = wait_until_state(port, lambda s: s["status"]["counters"]["messages"] == 3
                              )["status"]["streams"]["tension"]
        assert (st["clock_skewed_blocks"], st["time_restarts"], st["time_behind_s"]) == (1, 0, 0.0)
        # a block a year behind the logger clock: a skew and a restart
        c.put(_block(now - YEAR_NS, 3))
        doc, _ = c.wait_alert("time_restart", "put")
        assert abs(doc["value"] - YEAR_NS / 1e9) < 5.0
        st = wait_until_state(port, lambda s: s["status"]["streams"]["tension"]
                              ["clock_skewed_blocks"] == 2)["status"]["streams"]["tension"]
        assert st["clock_skew_s"] < -YEAR_NS / 1e9 + 5
        assert st["time_restarts"] == 1
    finally:
        c.close()
        assert d.terminate() == 0
    log = d.stderr_path.read_text()
    assert "sensor clock fault: stream tension: sensor time is 3.1536e+07 s ahead" in log
    assert "time restarted" in log


def test_a_publisher_restarting_with_older_times_is_alerted(tmp_path):
    """`simulate --publish` run twice: the second run's samples are all time_backwards."""
    port = free_port()
    cfg = write_config(tmp_path / "cfg.toml", port, tmp_path / "state.sqlite",
                       tension_age_s=60.0)
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
    d.wait_for("READY=1")
    c = Client(port)
    try:
        for run in range(2):
            pub = subprocess.run([sys.executable, HARNESS, "publish", f"tcp/127.0.0.1:{port}",
                                  "10", "0"], env=ENV, capture_output=True, text=True, timeout=60)
            assert pub.stdout.strip() == "10", pub.stderr
        doc, _ = c.wait_alert("time_restart", "put")
        assert doc["labels"]["component"] == "tension" and doc["value"] > 1.0
        st = wait_until_state(port, lambda s: s["status"]["counters"]["messages"] == 20)
        tension = st["status"]["streams"]["tension"]
        assert tension["time_restarts"] == 1 and tension["rejected"]["duplicate"] == 200
        assert any(a["rule"] == "time_restart" for a in st["status"]["alerts"]["active"])
        # `buoymon alerts list` finds the buoy and its endpoints in the configuration
        out = subprocess.run([sys.executable, "-m", "monitor.cli", "alerts", "list", "--config",
                              str(cfg), "--json"], env=ENV, capture_output=True, text=True,
                             timeout=60)
        assert out.returncode == 0, out.stderr
        listed = json.loads(out.stdout)
        assert listed["buoy"] == BUOY
        assert [(a["rule"], a["labels"]["component"]) for a in listed["alerts"]
                if a["rule"] == "time_restart"] == [("time_restart", "tension")]
    finally:
        c.close()
        assert d.terminate() == 0


def test_scrapes_are_answered_during_slow_checkpoints_and_failing_ones_are_alerted(tmp_path):
    port = free_port()
    state = tmp_path / "state.sqlite"
    cfg = write_config(tmp_path / "cfg.toml", port, state, checkpoint_s=0.5, tension_age_s=60.0)
    mport = metrics_port(cfg)
    # every checkpoint takes 2 s of the daemon's thread
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg), "0", "2.0"], tmp_path)
    d.wait_for("READY=1")
    c = Client(port)
    try:
        c.put(_block(time.time_ns() // 10**9 * 10**9))
        answered = 0
        t_end = time.monotonic() + 5.0
        while time.monotonic() < t_end:  # the daemon's thread checkpoints 80 % of this time
            m = scrape(mport)  # 5-s timeout: more than two checkpoints
            answered += ("buoymon_checkpoint_age_seconds", (("buoy", BUOY),)) in m
            time.sleep(0.2)
        assert answered >= 10
        # a checkpoint that cannot be written: counted, alerted, /healthz fails, serving goes on
        lock = sqlite3.connect(state, timeout=30)
        lock.execute("BEGIN EXCLUSIVE")
        try:
            doc, _ = c.wait_alert("checkpoint_failed", "put", timeout=60)
            assert "database is locked" in doc["summary"] and doc["severity"] == "critical"
            code, body = http_get(mport, "/healthz", timeout=10)
            assert code == 503 and "checkpoint_failed" in body
        finally:
            lock.rollback()
            lock.close()
        c.wait_alert("checkpoint_failed", "delete", timeout=60)
        assert scrape(mport)[("buoymon_checkpoint_failures_total", (("buoy", BUOY),))] >= 1
    finally:
        c.close()
        assert d.terminate() == 0


def _start_with_a_port_taken(tmp_path, which):
    """`buoymon run` with its Zenoh listen port or its metrics port (``which``) already bound
    by another socket; returns the finished process and the taken port."""
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        taken = busy.getsockname()[1]
        zenoh, metrics = (taken, free_port()) if which == "zenoh" else (free_port(), taken)
        cfg = tmp_path / "cfg.toml"
        cfg.write_text((REPO / "monitor" / "vaps_seed004.toml").read_text()
                       + f'\n[zenoh]\nlisten = ["tcp/127.0.0.1:{zenoh}"]\n'
                       f'[state]\npath = "{tmp_path / "state.sqlite"}"\n'
                       f'[metrics]\nport = {metrics}\n')
        out = subprocess.run([sys.executable, "-m", "monitor.cli", "run", "--config", str(cfg)],
                             env=ENV, capture_output=True, text=True, timeout=300)
    return out, taken


def test_metrics_port_in_use_is_a_clear_error_at_start(tmp_path):
    out, taken = _start_with_a_port_taken(tmp_path, "metrics")
    assert out.returncode == 2
    assert f"[metrics] cannot listen on 127.0.0.1:{taken}" in out.stderr
    assert "Traceback" not in out.stderr


def test_zenoh_port_in_use_is_a_clear_error_at_start(tmp_path):
    out, taken = _start_with_a_port_taken(tmp_path, "zenoh")
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert f"[zenoh] cannot open the session (listen ['tcp/127.0.0.1:{taken}'], connect [])" \
        in out.stderr and "Address already in use" in out.stderr


def test_status_of_a_stopped_daemon_reads_the_state_file(tmp_path):
    port = free_port()
    cfg = write_config(tmp_path / "cfg.toml", port, tmp_path / "state.sqlite")
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
    d.wait_for("READY=1")
    subprocess.run([sys.executable, HARNESS, "publish", f"tcp/127.0.0.1:{port}", "5", "0"],
                   env=ENV, check=True, capture_output=True, timeout=60)
    wait_until_state(port, lambda s: s["status"]["counters"]["messages"] == 5)
    js = status_cli(cfg)
    assert js["source"] == "daemon" and js["running"] is True
    assert d.terminate() == 0
    stopped = time.time_ns()
    time.sleep(1.0)  # the status's age must count from the daemon's last checkpoint
    out = subprocess.run([sys.executable, "-m", "monitor.cli", "status", "--config", str(cfg)],
                         env=ENV, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "tension" in out.stdout and "100" in out.stdout  # 5 blocks of 20 samples
    # not running, when last seen, and the checkpoint's health only as history: never "ok"
    with sqlite3.connect(tmp_path / "state.sqlite") as db:
        saved_ns = db.execute("SELECT saved_ns FROM checkpoint WHERE id = 1").fetchone()[0]
    assert saved_ns <= stopped
    seen = datetime.fromtimestamp(saved_ns / 1e9, tz=timezone.utc)
    lines = out.stdout.splitlines()
    assert lines[0].startswith(f"buoy {BUOY}: daemon NOT RUNNING (no answer); last seen "
                               f"{seen:%Y-%m-%d %H:%M:%S} UTC (its last checkpoint), ")
    assert re.fullmatch(r"health: NOT RUNNING \(at the last checkpoint: (ok|FAILING)\)", lines[1])
    assert "health: ok" not in out.stdout
    js = status_cli(cfg)
    assert js["source"] == "state file" and js["status"]["streams"]["tension"]["accepted"] == 100
    assert js["running"] is False and js["status"]["health"]["ok"] is False
    assert js["last_seen"] == f"{seen:%Y-%m-%dT%H:%M:%S.%f}Z"
    assert js["last_seen_age_s"] >= 1.0
    assert "daemon not running" in js["status"]["health"]["reasons"][0]
    assert set(js["status"]["health"]["at_last_checkpoint"]) >= {"ok", "reasons"}
    # `alerts list` of the stopped daemon's configuration: its checkpoint's alerts, said so
    # (was "no answer from buoy" and status 1); ack/reset name --state instead of guessing.
    # This daemon has no alert rules (no engine state), and perhaps no live alert: listed
    # as none (was "state has no "alerts" entry", status 1), its buoy id from the status
    out = subprocess.run([sys.executable, "-m", "monitor.cli", "alerts", "list", "--config",
                          str(cfg), "--timeout", "1", "--json"], env=ENV, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert f"the alerts of its last checkpoint ({tmp_path / 'state.sqlite'}) follow" in out.stderr
    listed = json.loads(out.stdout)
    assert listed["buoy"] == BUOY and isinstance(listed["alerts"], list)
    out = subprocess.run([sys.executable, "-m", "monitor.cli", "alerts", "ack", "x", "--who", "a",
                          "--why", "b", "--config", str(cfg), "--timeout", "1"], env=ENV,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 1
    assert f"--state {tmp_path / 'state.sqlite'} acts on its checkpoint" in out.stderr
    # `status --watch | head -1`: the reader goes away; the command ends quietly, status 0
    # (was "buoymon status: [Errno 32] Broken pipe", status 1)
    watch = subprocess.Popen([sys.executable, "-m", "monitor.cli", "status", "--config",
                              str(cfg), "--watch"], env=ENV, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    assert "daemon NOT RUNNING" in watch.stdout.readline()
    watch.stdout.close()
    assert watch.wait(timeout=60) == 0
    err = watch.stderr.read()
    assert "Broken pipe" not in err and "Traceback" not in err and "Exception" not in err
    # no state file either: a clear error naming it
    (tmp_path / "state.sqlite").unlink()
    out = subprocess.run([sys.executable, "-m", "monitor.cli", "status", "--config", str(cfg)],
                         env=ENV, capture_output=True, text=True, timeout=60)
    assert out.returncode == 1 and "no state file at" in out.stderr


def test_a_sensor_that_went_back_in_time_while_the_daemon_was_down_is_alerted(tmp_path):
    """Its blocks keep arriving but all are rejected: not stale by data age, yet alerted."""
    port = free_port()
    cfg = write_config(tmp_path / "cfg.toml", port, tmp_path / "state.sqlite",
                       tension_age_s=1.0)
    for life, (n, speed) in enumerate(((10, "0"), (4, "1"))):
        d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
        d.wait_for("READY=1")
        c = Client(port)
        try:
            pub = subprocess.run([sys.executable, HARNESS, "publish", f"tcp/127.0.0.1:{port}",
                                  str(n), speed], env=ENV, capture_output=True, text=True,
                                 timeout=60)
            assert pub.stdout.strip() == str(n), pub.stderr
            if life == 1:  # the same (older) times again, one block a second
                doc, _ = c.wait_alert("data_rejected", "put")
                assert doc["labels"]["component"] == "tension"
                assert "none was accepted" in doc["summary"], doc["summary"]
                # the fake pipeline's re-sent times are duplicates: counted as such, 0 rejected
                assert re.search(r"since then [1-9]\d* duplicate\(s\) .* and 0 rejected",
                                 doc["summary"]), doc["summary"]
                st = wait_until_state(port, lambda s: s["status"]["counters"]["messages"] == 14)
                tension = st["status"]["streams"]["tension"]
                assert tension["accepted"] == 200 and tension["rejected"]["duplicate"] == 80
                assert tension["time_restarts"] == 0  # a new daemon life: not a restart
        finally:
            c.close()
            assert d.terminate() == 0


def test_a_required_stream_that_never_appears_is_alerted(tmp_path):
    port = free_port()
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(f'[buoy]\nid = "{BUOY}"\n[zenoh]\nlisten = ["tcp/127.0.0.1:{port}"]\n'
                   'status_interval_s = 0.5\n'
                   f'[state]\npath = "{tmp_path / "state.sqlite"}"\n'
                   '[health]\ndata_age_timeout_s = { gnss = 1.0 }\nrequired_streams = ["gnss"]\n'
                   f'[metrics]\nport = {free_port()}\n')
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
    d.wait_for("READY=1")
    c = Client(port)
    try:
        doc, _ = c.wait_alert("data_age", "put")
        assert doc["labels"]["component"] == "gnss" and doc["value"] > 1.0
        st = wait_until_state(port, lambda s: not s["status"]["health"]["ok"])["status"]
        assert st["streams"]["gnss"]["data_age_s"] is None  # never arrived: shown, not invented
        assert st["streams"]["gnss"]["data_stale"] is True
    finally:
        c.close()
        assert d.terminate() == 0


def test_a_restart_keeps_a_stale_stream_alerted_without_clearing_it(tmp_path):
    """The tension stream stops, its data_age alert fires; the daemon is killed and restarted:
    the stream is still as late as it was (ages are saved as wall-clock times), so the alert
    is neither cleared nor fired again, and the status shows the age across the restart."""
    port = free_port()
    cfg = write_config(tmp_path / "cfg.toml", port, tmp_path / "state.sqlite", tension_age_s=1.0)
    d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
    d.wait_for("READY=1")
    c = Client(port)
    try:
        now = time.time_ns() // 10**9 * 10**9
        c.put(_block(now, 0))
        fired, _ = c.wait_alert("data_age", "put")
        wait_until_state(port, lambda s: s["state"]["daemon"].get("arrivals", {}).get("tension")
                         and any(a["rule"] == "data_age" for a in s["status"]["alerts"]["active"]))
        time.sleep(0.6)  # a checkpoint (every 0.5 s) holds the firing alert
        d.kill9()
        killed = time.monotonic()
        d = DaemonProcess([sys.executable, HARNESS, "run", str(cfg)], tmp_path)
        d.wait_for("READY=1")
        st = wait_until_state(port, lambda s: s["status"]["uptime_s"] > 2.0)["status"]
        tension = st["streams"]["tension"]
        assert tension["data_stale"] and tension["data_age_s"] > time.monotonic() - killed
        # still the alert that fired before the kill: a clear and a new fire would start anew
        assert [(a["rule"], a["since_ns"]) for a in st["alerts"]["active"]
                if a["component"] == "tension"] == [("data_age", fired["starts_at_ns"])]
    finally:
        c.close()
        assert d.terminate() == 0
    # the stopped daemon's checkpoint lists it too (`alerts list --state`)
    out = subprocess.run([sys.executable, "-m", "monitor.cli", "alerts", "list", "--state",
                          str(tmp_path / "state.sqlite"), "--json"], env=ENV,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    listed = json.loads(out.stdout)["alerts"]
    assert [(a["rule"], a["starts_at_ns"]) for a in listed if a["rule"] == "data_age"] == \
        [("data_age", fired["starts_at_ns"])]
