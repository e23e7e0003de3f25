"""The bridge inside the daemon (``[[source]]`` in the daemon's configuration), one process:
the Maine load cell on a pseudo-terminal -> daemon -> the committed damage of `buoymon import`
+ `buoymon replay`; the bridge's counters in the status and the Prometheus metrics; an
instrument that goes quiet is alerted on within seconds, and cleared when it talks again."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
import tty
import urllib.request

import pytest

from daemon_harness import ENV, DaemonProcess, free_port, wait_until_state
from monitor.bridge.transports import _IDLE_S
from monitor.config import load_config
from test_bridge import (LBF, REPO, checkpointed_figures, committed, import_and_replay,
                         maine_lines, pytestmark)  # noqa: F401 (pytestmark: skip without data)

STALL_S = 1.0


def metric(text: str, name: str, **labels: str) -> float:
    """The value of one sample of the exposition ``text`` (its labels include ``labels``)."""
    for m in re.finditer(rf"^{name}\{{([^}}]*)\}} (\S+)$", text, re.M):
        got = dict(re.findall(r'(\w+)="([^"]*)"', m.group(1)))
        if all(got.get(k) == v for k, v in labels.items()):
            return float(m.group(2))
    raise AssertionError(f"no {name} {labels} in the metrics")


def scrape_until(port: int, pred, timeout: float = 10.0) -> str:
    """``/metrics`` once ``pred(text)`` holds (they follow the last published status)."""
    deadline = time.monotonic() + timeout
    while True:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=10) as r:
            text = r.read().decode()
        if pred(text) or time.monotonic() > deadline:
            return text
        time.sleep(0.1)


def bridge_source(status: dict) -> dict:
    return status["status"].get("bridge", {}).get("sources", {}).get("loadcell", {})


def alerted(status: dict) -> bool:
    return any(a["rule"] == "bridge_source" and a["component"] == "loadcell"
               for a in status["status"]["alerts"]["active"])


def test_bridge_inside_the_daemon_pty_to_damage_counters_metrics_and_a_stall(tmp_path):
    lines = maine_lines(1200)
    port, mport = free_port(), free_port()
    master, slave = os.openpty()
    tty.setraw(slave)
    cfg = tmp_path / "buoymon.toml"
    cfg.write_text(
        (REPO / "monitor" / "vaps_seed004.toml").read_text().replace('id = "vaps"', 'id = "maine"', 1)
        + f'\n[zenoh]\nlisten = ["tcp/127.0.0.1:{port}"]\nstatus_interval_s = 0.5\n'
        f'[state]\npath = "{tmp_path / "st.sqlite"}"\ncheckpoint_interval_s = 1.0\n'
        f'[metrics]\nport = {mport}\n'
        '[bridge]\nstatus_interval_s = 0.5\n'
        '[[source]]\nname = "loadcell"\nsensor = "tension"\ntransport = "serial"\n'
        f'device = "{os.ttyname(slave)}"\nbaud = 115200\nstall_s = {STALL_S}\n'
        f'columns = {{ tension_N = 2 }}\nscale = {{ tension_N = {LBF} }}\ntime_column = 0\n'
        'time_format = "%Y-%m-%d-%H:%M:%S.%f"\n')
    d = DaemonProcess([sys.executable, "-m", "monitor.cli", "--log-level", "warning", "run",
                       "--config", str(cfg)], tmp_path)
    faults = {200: b"2018-11-30-10:00:00.000, 1.0\n",  # too few columns
              400: b"2018-11-30-10:01:00.000, 1.0,4x0, 0.1\n"}  # non-numeric load

    def write(part: range) -> None:
        for k in part:
            if k in faults:
                os.write(master, faults[k])
            os.write(master, (lines[k] + "\n").encode())
            if k % 100 == 0:
                time.sleep(0.02)

    try:
        d.wait_for("READY=1", timeout=120)
        wait_until_state(port, lambda s: bridge_source(s).get("connected"), buoy="maine")
        # a port quiet for _IDLE_S after its open is between lines: the first line counts
        time.sleep(_IDLE_S + 0.1)
        write(range(600))
        st = wait_until_state(port, lambda s: bridge_source(s).get("samples") == 600,
                              buoy="maine", timeout=60)
        src = bridge_source(st)
        assert src["lines"] == 602 and src["blocks"] >= 1 and src["state"] == "reading"
        assert src["rejected"] == {"columns": 1, "non_numeric": 1}
        assert src["time_source"] == "instrument"
        lab = {"buoy": "maine", "source": "loadcell", "sensor": "tension"}
        text = scrape_until(mport, lambda t: 'buoymon_bridge_lines_total{buoy="maine",'
                            'sensor="tension",source="loadcell"} 602.0' in t)
        assert metric(text, "buoymon_bridge_lines_total", **lab) == 602
        assert metric(text, "buoymon_bridge_samples_total", **lab) == 600
        assert metric(text, "buoymon_bridge_rejected_lines_total", reason="non_numeric",
                      **lab) == 1
        assert metric(text, "buoymon_bridge_source_state", state="reading", **lab) == 1
        # the instrument goes quiet: stalled, alerted, in the metrics within seconds
        t0 = time.monotonic()
        quiet = wait_until_state(port, alerted, buoy="maine", timeout=30)
        assert time.monotonic() - t0 < STALL_S + 3.0
        assert bridge_source(quiet)["state"] == "stalled"
        text = scrape_until(mport, lambda t: 'rule="bridge_source"' in t)
        assert metric(text, "buoymon_bridge_source_state", state="stalled", **lab) == 1
        assert metric(text, "buoymon_alert_firing", rule="bridge_source",
                      component="loadcell") == 1
        screen = subprocess.run([sys.executable, "-m", "monitor.cli", "status", "--config",
                                 str(cfg)], env=ENV, capture_output=True, text=True, timeout=60)
        row = next(ln for ln in screen.stdout.splitlines()
                   if ln.strip().startswith("loadcell (serial -> tension)"))
        cells = row.split()  # name (transport -> stream), state, last line, counts, rejected
        assert cells[4] == "STALLED" and cells[7] == "ago", screen.stdout
        assert cells[8:] == ["602", "600", "columns=1", "non_numeric=1"], screen.stdout
        # it talks again: reading, the alert clears
        write(range(600, 1200))
        wait_until_state(port, lambda s: bridge_source(s).get("samples") == 1200
                         and not alerted(s), buoy="maine", timeout=60)
    finally:
        rc = d.terminate()
        os.close(master)
        os.close(slave)
    assert rc == 0
    # the last partial block went out before the daemon stopped listening: all 1200 samples
    config = load_config(cfg)
    live = checkpointed_figures(config, tmp_path / "st.sqlite")
    replayed = import_and_replay(tmp_path, lines, config)
    assert live["samples"]["tension"]["accepted"] == 1200
    assert live["samples"]["tension"] == replayed["samples"]["tension"]
    assert committed(live) == committed(replayed)


def test_a_bridge_that_dies_without_a_word_turns_silent_and_is_alerted():
    """A bridge killed (no last status): its sources show ``silent`` once three of its status
    intervals (at least MIN_SILENT_S) pass, and the live rule fires on that."""
    from monitor import zenoh_io
    from monitor.alerts.live import LiveAlerts, LiveConfig
    from monitor.bridge.watch import MIN_SILENT_S, BridgeWatch
    from monitor.daemon_config import ZenohConfig

    port = free_port()
    with zenoh_io.open_session(ZenohConfig(listen=(f"tcp/127.0.0.1:{port}",))) as daemon, \
            zenoh_io.open_session(ZenohConfig(listen=(), connect=(f"tcp/127.0.0.1:{port}",))) \
            as bridge:
        watch = BridgeWatch(daemon, "b1")
        pub = zenoh_io.declare_json_publisher(bridge, "buoy/b1/bridge/status")
        entry = {"sensor": "gnss", "transport": "udp", "state": "reading", "stall_s": 5.0,
                 "last_line_age_s": 0.1, "lines": 7}
        deadline = time.monotonic() + 10
        while not watch.status_fields() and time.monotonic() < deadline:
            pub.put(zenoh_io.to_json_bytes({"status_interval_s": 0.2, "sources": {"gps": entry}}))
            time.sleep(0.05)
        fresh = watch.status_fields()["bridge"]["sources"]["gps"]
        assert fresh["state"] == "reading" and fresh["lines"] == 7
        live = LiveAlerts("b1", LiveConfig())
        assert live.evaluate(watch.status_fields(), time.time_ns()) == []
        time.sleep(MIN_SILENT_S + 0.3)  # the bridge says nothing more
        gone = watch.status_fields()
        assert gone["bridge"]["sources"]["gps"]["state"] == "silent"
        assert gone["bridge"]["sources"]["gps"]["status_age_s"] > MIN_SILENT_S
        # its last line keeps ageing: 0.1 s when reported, plus the silence since
        assert gone["bridge"]["sources"]["gps"]["last_line_age_s"] == pytest.approx(
            0.1 + gone["bridge"]["sources"]["gps"]["status_age_s"])
        (rec,) = live.evaluate(gone, time.time_ns())
        assert (rec.rule, rec.component, rec.event) == ("bridge_source", "gps", "fire")
        assert "silent, last line 3 s ago" in rec.summary, rec.summary
        watch.close()


def test_check_config_reads_the_bridge_sections_of_a_daemon_configuration(tmp_path):
    from monitor.config import ConfigError, load_config

    base = (REPO / "monitor" / "vaps_seed004.toml").read_text()
    good = tmp_path / "good.toml"
    good.write_text(base + '\n[bridge]\nstatus_interval_s = 0.5\n[[source]]\nname = "gps"\n'
                    'sensor = "gnss"\ntransport = "udp"\nport = 10110\n')
    bridge = load_config(good).bridge
    assert bridge is not None and bridge.status_interval_s == 0.5
    assert [(s.name, s.sensor, s.transport, s.port) for s in bridge.sources] == [
        ("gps", "gnss", "udp", 10110)]
    bad = tmp_path / "bad.toml"
    bad.write_text(base + '\n[[source]]\nname = "gps"\nsensor = "gnss"\ntransport = "udp"\n'
                   'port = 10110\nstal_s = 3\n')
    with pytest.raises(ConfigError, match=r"source\[0\]\.stal_s = 3: unknown key \(did you mean "
                       r"'stall_s'\?\)"):
        load_config(bad)
