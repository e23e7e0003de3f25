"""A forecast into the live daemon: `buoymon run`, and `buoymon forecast --publish` as the
publisher of a sea-state forecast on buoy/<id>/forecast/waves (loopback), with a sensor log
played by `python -m replay.publish`. The forecast is twelve measured hours of NDBC 44007
(../shared/realdata, 19 January 1996, Hs 1.3 m to 3.6 m) re-timed to start a minute into the
log; the daemon projects it with the table `buoymon forecast --save-table` prepared (the
simulator's rates in the bins it visits), raises forecast_damage at the shipped 0.5, shows
it in the status, publishes it on the alert key, and keeps it across a restart."""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import time
import urllib.request
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pytest

from monitor import zenoh_io
from monitor.blocks import SampleBlock
from monitor.checkpoint import CheckpointStore
from monitor.daemon_config import ZenohConfig
from replay.sea_state_files import read_sea_states
from replay.writer import LogWriter

from daemon_harness import ENV, DaemonProcess, free_port, wait_until_state

REPO = Path(__file__).resolve().parents[1]
SHARED = next((p / "shared" for p in REPO.parents if (p / "shared/realdata").is_dir()), None)
pytestmark = pytest.mark.skipif(SHARED is None, reason="../shared/realdata absent")
BUOY = "vaps"
T0_S = 1_750_000_000
ISSUED_S = T0_S + 60


def _buoymon(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "monitor.cli", *args], cwd=cwd, env=ENV,
                          capture_output=True, text=True, timeout=300)


def _forecast_csv(tmp: Path) -> Path:
    s = read_sea_states(SHARED / "realdata/ndbc44007_ecbenchmarkA/ec-benchmark_dataset_A.txt")
    rows = [f"{ISSUED_S + 3600 * k},{s.hs_m[436 + k]},{s.tp_s[436 + k]}" for k in range(12)]
    path = tmp / "forecast.csv"
    path.write_text("time_s,hs_m,tp_s\n" + "\n".join(rows) + "\n")
    return path


def _sensor_log(tmp: Path, seconds: int = 120) -> Path:
    path = tmp / "sensors.mcap"
    with LogWriter(path) as w:
        for k in range(seconds):
            t = (T0_S + k) * 10**9 + (np.arange(20, dtype=np.int64) + 1) * 50_000_000
            x = 3000.0 + 800.0 * np.sin(2 * np.pi * 0.19 * (t - T0_S * 10**9) / 1e9)
            w.write_block(SampleBlock(BUOY, "tension", t, {"tension_N": x}, int(t[-1])))
    return path


def _config(tmp: Path, port: int, table: Path, record: bool = False) -> Path:
    text = (REPO / "monitor" / "vaps_seed004.toml").read_text()
    assert '# table = "table.json"' in text
    text = text.replace('# table = "table.json"', f'table = "{table}"')
    text += (f'\n[zenoh]\nlisten = ["tcp/127.0.0.1:{port}"]\nstatus_interval_s = 0.5\n'
             f'[state]\npath = "{tmp / "state.sqlite"}"\ncheckpoint_interval_s = 0.5\n'
             f'[metrics]\nport = {free_port()}\n')
    if record:
        text += f'[record]\ndir = "{tmp / "rec"}"\nflush_interval_s = 0.5\n'
    path = tmp / "buoymon.toml"
    path.write_text(text)
    return path


def _start(cfg: Path, tmp: Path) -> DaemonProcess:
    d = DaemonProcess([sys.executable, "-m", "monitor.cli", "--log-level", "warning", "run",
                       "--config", str(cfg)], tmp)
    d.wait_for("READY=1", timeout=120)
    return d


def _forecast_alert(state: dict) -> list[dict]:
    return [a for a in state["status"]["alerts"]["active"] if a["rule"] == "forecast_damage"]


def test_daemon_raises_forecast_damage_from_a_published_forecast(tmp_path):
    fc = _forecast_csv(tmp_path)
    table = tmp_path / "table.json"
    offline = tmp_path / "offline.json"
    # the operator's preparation: the model's rates in the bins of the forecast, and the
    # same forecast offline (from zero damage) as the reference
    p = _buoymon("forecast", "--sea-states", str(fc), "--save-table", str(table),
                 "--json", str(offline), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    ref = json.loads(offline.read_text())["components"]["conductor"]
    assert ref["thresholds"]["0.5"]["at"] is not None  # the forecast does reach 0.5
    port = free_port()
    cfg = _config(tmp_path, port, table, record=True)
    d = _start(cfg, tmp_path)
    alerts: "queue.SimpleQueue[tuple]" = queue.SimpleQueue()
    zc = ZenohConfig(mode="client", listen=(), connect=(f"tcp/127.0.0.1:{port}",))
    try:
        with zenoh_io.open_session(zc) as session:
            sub = zenoh_io.declare_enqueuing_subscriber(
                session, f"buoy/{BUOY}/monitor/alert/forecast_damage/**", alerts)
            pub = _buoymon("forecast", "--sea-states", str(fc), "--table", str(table),
                           "--publish", f"tcp/127.0.0.1:{port}", cwd=tmp_path)
            assert pub.returncode == 0 and "sent to buoy/vaps/forecast/waves" in pub.stdout, \
                pub.stderr
            play = subprocess.run([sys.executable, "-m", "replay.publish",
                                   str(_sensor_log(tmp_path)), "--connect",
                                   f"tcp/127.0.0.1:{port}"], env=ENV, capture_output=True,
                                  text=True, timeout=120)
            assert play.returncode == 0, play.stderr
            st = wait_until_state(port, lambda s: bool(_forecast_alert(s)), buoy=BUOY)
            time.sleep(0.5)  # the alert went out before the state that showed it
            sub.undeclare()
        status = st["status"]
        assert status["counters"]["forecasts"] == 1
        assert status["counters"]["forecasts_refused"] == 0
        [active] = [a for a in _forecast_alert(st) if a["component"] == "conductor"]
        last = status["forecast"]["last"]["components"]["conductor"]
        # the daemon's projection is the offline one plus the (tiny) damage already committed
        assert last["damage_now"] < 1e-6
        assert last["damage_end"] == pytest.approx(ref["damage_end"], rel=1e-6)
        assert last["steps_model"] == 12
        at = datetime.strptime(ref["thresholds"]["0.5"]["at"], "%Y-%m-%dT%H:%M:%SZ")
        assert active["source"] == "forecast" and active["since_ns"] == ISSUED_S * 10**9
        assert f"reaches damage 0.5 by {at:%Y-%m-%d %H:%M} UTC" in active["summary"]
        published = [r for r in _drain(alerts) if r["labels"]["component"] == "conductor"]
        assert [r["event"] for r in published] == ["fire"]
        assert published[0]["summary"] == active["summary"]
    finally:
        assert d.terminate() == 0
    # the recording replayed gives the same forecast alert: the forecast is recorded with
    # the tick it was due at
    store = CheckpointStore(tmp_path / "state.sqlite")
    live = [a for a in store.load().state["pipeline"]["alert_history"]
            if a["rule"] == "forecast_damage" and a["labels"]["component"] == "conductor"]
    store.close()
    p = _buoymon("replay", str(tmp_path / "rec"), "--config", str(cfg), "--report",
                 str(tmp_path / "replay.json"), "--no-progress", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    replayed = [a for a in json.loads((tmp_path / "replay.json").read_text())["alerts"]
                if a["rule"] == "forecast_damage" and a["labels"]["component"] == "conductor"]
    assert len(live) == 1 and replayed == live
    # the checkpoint holds the table and the firing alert: a restarted daemon shows it
    d = _start(cfg, tmp_path)
    try:
        st = wait_until_state(port, lambda s: s["status"]["counters"]["status_published"] > 0,
                              buoy=BUOY)
        assert active["summary"] in [a["summary"] for a in _forecast_alert(st)]
    finally:
        assert d.terminate() == 0


def test_daemon_counts_and_survives_bad_forecasts(tmp_path):
    port = free_port()
    table = tmp_path / "table.json"
    table.write_text(json.dumps(_empty_table()))
    d = _start(_config(tmp_path, port, table), tmp_path)
    zc = ZenohConfig(mode="peer", listen=(), connect=(f"tcp/127.0.0.1:{port}",))
    try:
        with zenoh_io.open_session(zc) as session:
            pub = zenoh_io.declare_json_publisher(session, zenoh_io.forecast_key(BUOY))
            deadline = time.monotonic() + 10
            while not pub.matching_status and time.monotonic() < deadline:
                time.sleep(0.01)
            for payload in (b"not json", b"\xff\xfe", b"[1, 2]",
                            b'{"time_s": [1, 2], "hs_m": [1], "tp_s": [5, 5]}',
                            b'{"time_s": [1], "hs_m": [1.0], "tp_s": [5.0]}',
                            # two hourly steps ending 7201 s, issued at 7300 s: nothing left
                            # to project (was: applied with 0 steps, unsaid)
                            b'{"issued_s": 7300, "time_s": [1, 3601], "hs_m": [1.0, 1.0], '
                            b'"tp_s": [5.0, 5.0]}'):
                pub.put(payload)
            st = wait_until_state(port, lambda s: s["status"]["counters"]["forecasts"]
                                  + s["status"]["counters"]["forecasts_refused"] == 6,
                                  buoy=BUOY)
        counters = st["status"]["counters"]
        assert (counters["forecasts_refused"], counters["forecasts_expired"]) == (5, 1)
        assert st["status"]["forecast"]["pending"] == 1  # no sensor data: not applied yet
        metrics = int(cfg_text(tmp_path).split("[metrics]\nport = ")[1].split()[0])
        with urllib.request.urlopen(f"http://127.0.0.1:{metrics}/metrics", timeout=10) as r:
            text = r.read().decode()
        assert f'buoymon_forecasts_refused_total{{buoy="{BUOY}"}} 5.0' in text
        assert f'buoymon_forecasts_expired_total{{buoy="{BUOY}"}} 1.0' in text
        assert f'buoymon_forecasts_total{{buoy="{BUOY}"}} 1.0' in text
    finally:
        assert d.terminate() == 0
    logged = [json.loads(line) for line in d.stderr_path.read_text().splitlines()
              if '"forecast refused"' in line]
    assert len(logged) == 2  # the first malformed one, and the expired one on its own subject
    assert logged[1]["error"] == ("forecast: nothing to project: its last step ends "
                                  "1970-01-01 02:00 UTC, not after the first tick it can be "
                                  "applied at (1970-01-01 02:01 UTC; issued 1970-01-01 02:01 UTC)")


def cfg_text(tmp: Path) -> str:
    return (tmp / "buoymon.toml").read_text()


def _drain(q: "queue.SimpleQueue[tuple]") -> list[dict]:
    out = []
    while not q.empty():
        payload = q.get()[2]
        if payload:  # a clearing alert is a DELETE with an empty payload
            out.append(json.loads(payload))
    return out


def _empty_table() -> dict:
    from models.sea_state_table import HS_EDGES_M, TP_EDGES_S, DamageRateTable

    from monitor.config import default_config

    names = [c.name for c in default_config().components]
    return DamageRateTable(names, HS_EDGES_M, TP_EDGES_S).to_state()


@pytest.mark.integration  # a Zenoh session on loopback
def test_a_forecast_nobody_subscribes_to_is_not_reported_as_sent(tmp_path):
    """No daemon on the endpoint: an error (the CLI exits 1), not "sent to ..." with the
    forecast put into the void. (The wait for a subscriber tested the MatchingStatus object,
    always true, not its ``matching``: it never waited, with a daemon either.)"""
    from replay.cmd_forecast import publish_forecast  # noqa: PLC0415

    fc = tmp_path / "f.csv"
    fc.write_text("time_s,hs_m,tp_s\n0,1.5,5.25\n3600,1.5,5.25\n")
    port = free_port()
    t0 = time.monotonic()
    with pytest.raises(OSError, match=f"no daemon of buoy 'vaps' subscribed to "
                                      f"buoy/vaps/forecast/waves via \\['tcp/127.0.0.1:{port}'\\] "
                                      "within 1 s: the forecast was not sent"):
        publish_forecast("vaps", read_sea_states(fc), [f"tcp/127.0.0.1:{port}"],
                         wait_for_subscriber_s=1.0)
    assert time.monotonic() - t0 >= 1.0
