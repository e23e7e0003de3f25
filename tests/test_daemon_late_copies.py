"""A publisher re-sending history the daemon already took (a restart that re-sends its cache):
`buoymon run`, tension from a plain Zenoh publisher, and a separate `replay.publish` process
that re-sends 40 s of it, 50 to 90 s behind the processed time. Was: 800 `time_backwards` and
`rejected_rate` fired on tension (800 of 3,800 samples in its 600-s window). Now: 800
`duplicate`, no alert, and a replay of the daemon's recording counts the same."""

from __future__ import annotations

import json
import queue
import time

import numpy as np
import pytest

pytest.importorskip("monitor.pipeline")

from monitor import zenoh_io  # noqa: E402
from monitor.blocks import SampleBlock  # noqa: E402
from monitor.config import load_config  # noqa: E402

from daemon_harness import free_port, wait_until_state  # noqa: E402
from test_daemon_e2e import (  # noqa: E402
    BUOY, checkpoint, client_session, flushed_figures, publish, replayed_figures,
    start_daemon, write_config, write_log,
)

pytestmark = pytest.mark.integration  # processes on loopback: not in `make test-fast`


def test_a_re_sent_history_is_counted_as_duplicates_not_alerted_and_replays_the_same(tmp_path):
    port = free_port()
    cfg = write_config(tmp_path, port, record=True, load_source="measured")
    d = start_daemon(cfg, tmp_path)
    codec = zenoh_io.ProtobufCodec()
    alerts: "queue.SimpleQueue[tuple]" = queue.SimpleQueue()
    t0 = time.time_ns() // 10**9 * 10**9 - 300 * 10**9

    def tension(k: int) -> SampleBlock:
        t = t0 + k * 10**9 + 50_000_000 * np.arange(20, dtype=np.int64)
        return SampleBlock(BUOY, "tension", t, {
            "tension_N": 3000.0 + 100.0 * np.sin(np.arange(20.0) + 0.1 * k)}, int(t[-1]))

    history = write_log(tmp_path / "history.mcap", [tension(k) for k in range(100, 140)])
    try:
        with client_session(port) as session:
            sub = zenoh_io.declare_enqueuing_subscriber(
                session, f"buoy/{BUOY}/monitor/alert/rejected_rate/**", alerts)
            pub = zenoh_io.declare_data_publisher(session, f"buoy/{BUOY}/sensor/tension")
            for k in range(200):
                pub.put(codec.encode(tension(k)))
            wait_until_state(port, lambda s: s["status"]["counters"]["messages"] == 200,
                             buoy=BUOY)
            again = publish(history, port)
            out, err = again.communicate(timeout=60)
            assert again.returncode == 0 and out.strip() == "40", err
            for k in range(200, 220):  # tension goes on: the ticks that judge the re-send
                pub.put(codec.encode(tension(k)))
            st = wait_until_state(port, lambda s: s["status"]["counters"]["messages"] == 260
                                  and s["status"]["now_ns"] >= t0 + 209 * 10**9,
                                  buoy=BUOY)["status"]
            live = st["streams"]["tension"]
            assert {r: n for r, n in live["rejected"].items() if n} == {"duplicate": 800}
            time.sleep(1.0)  # two status intervals: an alert would be out by now
            assert alerts.empty(), alerts.get()[1]
            assert not [a for a in st["alerts"]["active"] if a["rule"] == "rejected_rate"]
            sub.undeclare()
            pub.undeclare()
    finally:
        assert d.terminate() == 0
    config = load_config(cfg)
    flushed = flushed_figures(config, checkpoint(tmp_path)["pipeline"])["samples"]["tension"]
    assert flushed["accepted"] == 220 * 20
    assert {r: n for r, n in flushed["rejected"].items() if n} == {"duplicate": 800}
    replayed = replayed_figures(config, sorted((tmp_path / "rec").glob("*.mcap")))
    assert replayed["samples"]["tension"] == flushed


def test_a_restarted_daemon_with_saved_minutes_lost_starts_says_so_and_judges_the_rest(
        tmp_path):
    """The late copies' closed minutes are write-once parts of the checkpoint file
    (monitor/state_part.py): one deleted and another damaged while the daemon is down was a
    KeyError / zlib.error at start-up. Now the daemon starts, logs it, shows it in the status
    (``checkpoint.late_copies_lost_minutes``) and the metrics, and only late copies of those
    two minutes are time_backwards; those of a minute kept are still duplicates."""
    import sqlite3  # noqa: PLC0415
    import urllib.request  # noqa: PLC0415
    import zlib  # noqa: PLC0415

    from prometheus_client.parser import text_string_to_metric_families  # noqa: PLC0415

    port = free_port()
    cfg = write_config(tmp_path, port, load_source="measured")
    codec = zenoh_io.ProtobufCodec()
    t0 = time.time_ns() // 10**9 * 10**9 - 400 * 10**9

    def tension(k: int) -> SampleBlock:
        t = t0 + k * 10**9 + 50_000_000 * np.arange(20, dtype=np.int64)
        return SampleBlock(BUOY, "tension", t, {
            "tension_N": 3000.0 + 100.0 * np.sin(np.arange(20.0) + 0.1 * k)}, int(t[-1]))

    def send(ks, messages: int) -> dict:
        with client_session(port) as session:
            pub = zenoh_io.declare_data_publisher(session, f"buoy/{BUOY}/sensor/tension")
            for k in ks:
                pub.put(codec.encode(tension(k)))
            st = wait_until_state(port, lambda s: s["status"]["counters"]["messages"] == messages,
                                  buoy=BUOY)["status"]
            pub.undeclare()
        return st

    d = start_daemon(cfg, tmp_path)
    try:
        send(range(260), 260)
    finally:
        assert d.terminate() == 0  # the last checkpoint
    minute = sorted({(t0 + k * 10**9) // (60 * 10**9) for k in range(260)})
    closed = minute[:-1]  # the newest is still open: inline in the state row
    db = sqlite3.connect(tmp_path / "state.sqlite")
    late = json.loads(zlib.decompress(db.execute("SELECT state FROM checkpoint").fetchone()[0])
                      )["pipeline"]["late_copies"]["tension"]
    assert [isinstance(x, dict) for x in late["v"]] == [True] * len(closed) + [False]
    db.execute("DELETE FROM parts WHERE key = ?", (late["v"][1]["k"],))
    db.execute("UPDATE parts SET data = 'AAAA' || substr(data, 5) WHERE key = ?",
               (late["t"][2]["k"],))
    db.commit()
    db.close()

    def seconds_of(m: int) -> list[int]:
        return [k for k in range(260) if (t0 + k * 10**9) // (60 * 10**9) == m][:5]

    d = start_daemon(cfg, tmp_path)
    try:
        st = send([*seconds_of(closed[1]), *seconds_of(closed[2]), *seconds_of(closed[3]),
                   *range(260, 280)], 260 + 35)
        assert st["checkpoint"]["late_copies_lost_minutes"] == {"tension": 2}
        assert {r: n for r, n in st["streams"]["tension"]["rejected"].items() if n} == {
            "time_backwards": 200, "duplicate": 100}
        mport = int(cfg.read_text().split("[metrics]\nport = ")[1].split()[0])
        text = urllib.request.urlopen(f"http://127.0.0.1:{mport}/metrics", timeout=10).read()
        got = {s.name: s.value for fam in text_string_to_metric_families(text.decode())
               for s in fam.samples}
        assert got["buoymon_checkpoint_late_copies_lost_minutes"] == 2.0
    finally:
        assert d.terminate() == 0
    log = [json.loads(line) for line in d.stderr_path.read_text().splitlines()
           if "late copies not restored" in line]
    assert [x["minutes_lost"] for x in log] == [{"tension": 2}]
