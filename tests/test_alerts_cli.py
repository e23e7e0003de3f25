"""``buoymon alerts list|ack|reset`` against a state file and against a daemon over Zenoh,
and the Zenoh put/delete of alert transitions."""

from __future__ import annotations

import json
import socket
import threading
import time

import numpy as np
import pytest
import zenoh

from monitor.alerts.delivery import ZenohAlertSink, peer_config
from monitor.alerts.engine import AlertEngine
from monitor.cli import main
from monitor.events import ComponentObs, Observation
from waiting import wait_for

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`

NS = 1_000_000_000
T0 = 1_700_000_000 * NS
RULES = {"resend_interval_s": 30, "rule": [
    {"kind": "damage_fraction", "threshold": 0.1, "name": "damage_warning"},
    {"kind": "damage_rate", "threshold": 1.0, "severity": "critical"},
]}


def tick(k: int, damage: float, rate: float) -> Observation:
    c = ComponentObs(damage, damage, rate, 10.0, float("nan"))
    return Observation("b1", T0 + k * 10 * NS, 10.0, "measured", np.zeros(0, np.int64),
                       np.zeros(0), 1.0, 1.0, {"left": c, "right": c}, {})


def firing_engine() -> AlertEngine:
    eng = AlertEngine.from_config(RULES, "b1", {"left": None, "right": None})
    eng.evaluate(tick(1, 0.2, 2.0))
    return eng


def test_state_file_list_ack_reset(tmp_path, capsys):
    eng = firing_engine()
    path = tmp_path / "state.json"
    path.write_text(json.dumps({"pipeline": {"x": 1}, "alerts": eng.state()}))

    assert main(["alerts", "list", "--state", str(path), "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)["alerts"]
    assert sorted((a["rule"], a["labels"]["component"]) for a in listed) == [
        ("damage_rate", "left"), ("damage_rate", "right"),
        ("damage_warning", "left"), ("damage_warning", "right")]

    fp = next(a["fingerprint"] for a in listed if a["rule"] == "damage_rate"
              and a["labels"]["component"] == "left")
    assert main(["alerts", "ack", fp, "--who", "ana", "--why", "seen", "--state", str(path)]) == 0
    assert main(["alerts", "reset", "damage_warning", "right", "--who", "bo",
                 "--why", "cable replaced", "--state", str(path)]) == 0
    capsys.readouterr()
    saved = json.loads(path.read_text())
    assert saved["pipeline"] == {"x": 1}
    hist = saved["alerts"]["history"]
    assert [(h["type"], h.get("who"), h.get("why")) for h in hist[-2:]] == [
        ("ack", "ana", "seen"), ("reset", "bo", "cable replaced")]
    assert hist[-1]["at_ns"] > 1_700_000_000 * NS  # wall-clock time of the command

    # the daemon resumes from this state: the reset releases the latched alert at its next
    # tick and the acknowledged alert is not re-sent
    eng = AlertEngine.from_state(saved["alerts"])
    out = eng.evaluate(tick(4, 0.25, 2.0))
    assert sorted((r.rule, r.component, r.event) for r in out) == [
        ("damage_rate", "right", "resend"), ("damage_warning", "left", "resend"),
        ("damage_warning", "right", "reset")]

    assert main(["alerts", "list", "--state", str(path)]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split()[:4] == ["FINGERPRINT", "SEVERITY", "RULE", "COMPONENT"]
    assert any(fp in row and row.rstrip().endswith("ana") for row in table)

    assert main(["alerts", "ack", "0" * 16, "--who", "a", "--why", "b",
                 "--state", str(path)]) == 1
    assert "no such alert" in capsys.readouterr().err


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_daemon_over_zenoh_put_delete_list_ack_reset(capsys):
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    eng = AlertEngine.from_config(RULES, "b1", {"left": None, "right": None})
    with zenoh.open(peer_config(listen=[endpoint])) as daemon, \
            zenoh.open(peer_config(connect=[endpoint])) as watcher:
        seen: list[tuple[str, str]] = []
        sub = watcher.declare_subscriber(
            "buoy/b1/monitor/alert/**", lambda s: seen.append((str(s.kind), str(s.key_expr))))
        sink = ZenohAlertSink(daemon, "b1")
        stop = threading.Event()

        def daemon_loop():  # the daemon applies operator commands between ticks
            while not stop.is_set():
                sink.apply_commands(eng)
                time.sleep(0.02)

        loop = threading.Thread(target=daemon_loop)
        loop.start()
        try:
            # until the subscriber's declaration has reached the daemon session
            probe = daemon.declare_publisher("buoy/b1/monitor/alert/damage_rate/left")
            assert wait_for(lambda: probe.matching_status.matching)
            probe.undeclare()
            sink.publish(eng.evaluate(tick(1, 0.05, 2.0)))       # damage_rate fires x2
            sink.publish(eng.evaluate(tick(2, 0.05, 0.5)))       # ... and clears x2
            sink.publish(eng.evaluate(tick(3, 0.2, 0.5)))        # damage_warning fires x2
            assert wait_for(lambda: len(seen) == 6)
            assert seen == [
                ("SampleKind.PUT", "buoy/b1/monitor/alert/damage_rate/left"),
                ("SampleKind.PUT", "buoy/b1/monitor/alert/damage_rate/right"),
                ("SampleKind.DELETE", "buoy/b1/monitor/alert/damage_rate/left"),
                ("SampleKind.DELETE", "buoy/b1/monitor/alert/damage_rate/right"),
                ("SampleKind.PUT", "buoy/b1/monitor/alert/damage_warning/left"),
                ("SampleKind.PUT", "buoy/b1/monitor/alert/damage_warning/right"),
            ]

            common = ["--buoy", "b1", "--connect", endpoint, "--timeout", "10"]
            assert main(["alerts", "list", *common, "--json"]) == 0
            listed = json.loads(capsys.readouterr().out)["alerts"]
            assert sorted((a["rule"], a["labels"]["component"]) for a in listed) == [
                ("damage_warning", "left"), ("damage_warning", "right")]

            fp = listed[0]["fingerprint"]
            assert main(["alerts", "ack", fp, "--who", "ana", "--why", "on it", *common]) == 0
            assert main(["alerts", "reset", "damage_warning", "left", "--who", "bo",
                         "--why", "inspected", *common]) == 0
            assert main(["alerts", "reset", "nope", "left", "--who", "bo",
                         "--why", "x", *common]) == 1
            out = capsys.readouterr()
            assert "no such rule instance" in out.err
            assert [h["type"] for h in eng.history()][-2:] == ["ack", "reset"]
            assert main(["alerts", "list", *common, "--json"]) == 0
            listed = json.loads(capsys.readouterr().out)["alerts"]
            assert next(a for a in listed if a["fingerprint"] == fp)["acked_by"] == "ana"
        finally:
            stop.set()
            loop.join()
            sink.close()
            sub.undeclare()


def test_daemon_absent_times_out(capsys):
    port = free_port()
    assert main(["alerts", "list", "--buoy", "b1", "--connect", f"tcp/127.0.0.1:{port}",
                 "--timeout", "0.5"]) == 1
    assert "no answer from buoy 'b1'" in capsys.readouterr().err




def test_daemon_checkpoint_list_and_reset(tmp_path, capsys):
    """--state also takes a stopped daemon's SQLite checkpoint (the pipeline state under
    "pipeline"); a reset is saved as a new checkpoint the daemon resumes from."""
    from monitor.checkpoint import CheckpointStore

    path = tmp_path / "checkpoint.sqlite"
    store = CheckpointStore(path)
    store.save({"pipeline": {"x": 1, "alerts": firing_engine().state()}, "counters": {"n": 3}})
    store.close()
    assert main(["alerts", "list", "--state", str(path), "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)["alerts"]) == 4
    assert main(["alerts", "reset", "damage_warning", "right", "--who", "bo",
                 "--why", "cable replaced", "--state", str(path)]) == 0
    store = CheckpointStore(path)
    saved = store.load()
    store.close()
    assert saved.seq == 2 and saved.state["counters"] == {"n": 3}
    assert saved.state["pipeline"]["x"] == 1
    hist = saved.state["pipeline"]["alerts"]["history"]
    assert (hist[-1]["type"], hist[-1]["who"]) == ("reset", "bo")
    capsys.readouterr()
    garbage = tmp_path / "garbage.bin"
    garbage.write_bytes(b"\x81\x00\xff" * 10)
    assert main(["alerts", "list", "--state", str(garbage)]) == 1
    assert "neither a daemon checkpoint nor a JSON state file" in capsys.readouterr().err


def test_checkpoint_of_a_daemon_without_alert_rules_lists_none(tmp_path, capsys):
    """A configuration without [[alerts.rule]] keeps no engine state: `alerts list` says
    there is no active alert (was "state has no "alerts" entry", status 1); ack and reset
    still refuse, naming the file."""
    from monitor.checkpoint import CheckpointStore

    path = tmp_path / "checkpoint.sqlite"
    store = CheckpointStore(path)
    store.save({"pipeline": {"x": 1}, "daemon": {"last_status": {"buoy_id": "b9"},
                                                  "live": {"firing": []}}})
    store.close()
    assert main(["alerts", "list", "--state", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == {"buoy": "b9", "alerts": []}
    assert main(["alerts", "list", "--state", str(path)]) == 0
    assert capsys.readouterr().out.strip() == "no active alerts"
    assert main(["alerts", "ack", "f", "--who", "a", "--why", "b", "--state", str(path)]) == 1
    assert f'{path}: state has no "alerts" entry' in capsys.readouterr().err


def test_alert_table_marks_logger_clock_times():
    from monitor.alerts.cmd_alerts import format_table

    def alert(rule: str, starts_s: int) -> dict:
        return {"fingerprint": "f" + rule, "severity": "warning", "rule": rule,
                "labels": {"component": "tension"}, "starts_at_ns": starts_s * 10**9,
                "annotations": {"value": "1", "threshold": "0"}, "acked_by": ""}

    lines = format_table([alert("data_age", 1_795_000_000), alert("stale", 946_684_800)])
    lines = lines.splitlines()
    assert "SINCE (UTC; sensor time, * logger clock)" in lines[0]
    assert "2026-11-18 11:06:40 *" in lines[1] and "2000-01-01 00:00:00 " in lines[2] + " "
    assert "*" not in lines[2]


def test_ack_of_a_logger_clock_alert_says_why_it_cannot_be(tmp_path, capsys):
    """`alerts list` shows the daemon's logger-clock (health) alerts with a fingerprint, but
    only sensor-time alerts take an ack: acking one said "no such alert"."""
    from monitor.checkpoint import CheckpointStore

    # a data_age record as a stopped `buoymon run` saved it in its checkpoint
    live = {"fingerprint": "166d062c5b05f60a", "rule": "data_age", "kind": "data_age",
            "severity": "warning", "state": "firing", "event": "fire",
            "labels": {"buoy": "b1", "component": "tension", "rule": "data_age"},
            "annotations": {"value": "5.118 s", "threshold": "5 s",
                            "summary": "no data on stream tension for 5 s"},
            "starts_at_ns": 1795626014071910440, "ends_at_ns": 0, "at_ns": 1795626014071910440,
            "value": 5.118, "threshold": 5.0, "unit": "s",
            "summary": "no data on stream tension for 5 s", "acked_by": "", "ack_reason": ""}
    path = tmp_path / "checkpoint.sqlite"
    store = CheckpointStore(path)
    store.save({"pipeline": {"alerts": firing_engine().state()},
                "daemon": {"live": {"firing": [live]}}})
    store.close()
    assert main(["alerts", "list", "--state", str(path)]) == 0
    assert "166d062c5b05f60a" in capsys.readouterr().out
    assert main(["alerts", "ack", "166d062c5b05f60a", "--who", "a", "--why", "b",
                 "--state", str(path)]) == 1
    assert ("fingerprint '166d062c5b05f60a': a logger-clock alert (data_age), raised by the "
            "daemon's own health rules; it cannot be acknowledged") in capsys.readouterr().err
    assert main(["alerts", "ack", "0000", "--who", "a", "--why", "b", "--state", str(path)]) == 1
    assert "fingerprint '0000': no such alert" in capsys.readouterr().err
