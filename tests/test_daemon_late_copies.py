"""A publisher re-sending history the daemon already took (a restart that re-sends its cache):
`buoymon run`, tension from a plain Zenoh publisher, and a separate `replay.publish` process
that re-sends 40 s of it, 50 to 90 s behind the processed time. Was: 800 `time_backwards` and
`rejected_rate` fired on tension (800 of 3,800 samples in its 600-s window). Now: 800
`duplicate`, no alert, and a replay of the daemon's recording counts the same."""

from __future__ import annotations

import json
import queue
import re
import time
from collections.abc import Iterable

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
CODEC = zenoh_io.ProtobufCodec()


def _tension(t0: int, k: int) -> SampleBlock:
    """The ``k``-th second of 20 Hz tension from ``t0``."""
    t = t0 + k * 10**9 + 50_000_000 * np.arange(20, dtype=np.int64)
    return SampleBlock(BUOY, "tension", t, {
        "tension_N": 3000.0 + 100.0 * np.sin(np.arange(20.0) + 0.1 * k)}, int(t[-1]))


def _put_live(pub, t0: int, seconds: Iterable[int]) -> None:
    """Put those seconds of tension through a plain Zenoh publisher (no cache, no numbers)."""
    for k in seconds:
        pub.put(CODEC.encode(_tension(t0, k)))


def test_a_re_sent_history_is_counted_as_duplicates_not_alerted_and_replays_the_same(tmp_path):
    port = free_port()
    cfg = write_config(tmp_path, port, record=True, load_source="measured")
    d = start_daemon(cfg, tmp_path)
    alerts: "queue.SimpleQueue[tuple]" = queue.SimpleQueue()
    t0 = time.time_ns() // 10**9 * 10**9 - 300 * 10**9
    history = write_log(tmp_path / "history.mcap", [_tension(t0, k) for k in range(100, 140)])
    try:
        with client_session(port) as session:
            sub = zenoh_io.declare_enqueuing_subscriber(
                session, f"buoy/{BUOY}/monitor/alert/rejected_rate/**", alerts)
            pub = zenoh_io.declare_data_publisher(session, f"buoy/{BUOY}/sensor/tension")
            _put_live(pub, t0, range(200))
            wait_until_state(port, lambda s: s["status"]["counters"]["messages"] == 200,
                             buoy=BUOY)
            again = publish(history, port)
            out, err = again.communicate(timeout=60)
            assert again.returncode == 0 and out.strip() == "40", err
            _put_live(pub, t0, range(200, 220))  # tension goes on: the ticks that judge it
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
    t0 = time.time_ns() // 10**9 * 10**9 - 400 * 10**9

    def send(ks, messages: int) -> dict:
        with client_session(port) as session:
            pub = zenoh_io.declare_data_publisher(session, f"buoy/{BUOY}/sensor/tension")
            _put_live(pub, t0, ks)
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


def test_data_rejected_on_a_re_send_alone_says_duplicates_not_rejections(tmp_path):
    """A publisher that sends only copies of old data for longer than the data-age timeout:
    no new measurement is accepted, so `data_rejected` fires (kept on purpose); its summary
    counts the copies as duplicates and 0 as rejected (was: "rejected so far: duplicate=N").
    `buoymon run` and a separate `replay.publish` process re-sending 40 s at 8x."""
    port = free_port()
    cfg = write_config(tmp_path, port, load_source="measured")
    cfg.write_text(cfg.read_text() + "[health]\ndata_age_timeout_s = { tension = 2.0 }\n")
    d = start_daemon(cfg, tmp_path)
    alerts: "queue.SimpleQueue[tuple]" = queue.SimpleQueue()
    t0 = time.time_ns() // 10**9 * 10**9 - 300 * 10**9
    history = write_log(tmp_path / "history.mcap", [_tension(t0, k) for k in range(100, 140)])
    try:
        with client_session(port) as session:
            sub = zenoh_io.declare_enqueuing_subscriber(
                session, f"buoy/{BUOY}/monitor/alert/data_rejected/**", alerts)
            pub = zenoh_io.declare_data_publisher(session, f"buoy/{BUOY}/sensor/tension")
            _put_live(pub, t0, range(200))
            wait_until_state(port, lambda s: s["status"]["counters"]["messages"] == 200,
                             buoy=BUOY)
            again = publish(history, port, speed=8.0)
            fired = json.loads(alerts.get(timeout=60)[2])
            out, err = again.communicate(timeout=60)
            assert again.returncode == 0 and out.strip() == "40", err
            sub.undeclare()
            pub.undeclare()
    finally:
        assert d.terminate() == 0
    assert fired["labels"]["component"] == "tension" and fired["state"] == "firing", fired
    found = re.fullmatch(
        r"stream tension: data arrives but none was accepted for \d+ s: since then (\d+) "
        r"duplicate\(s\) \(data already received, sent again\) and 0 rejected \(so far: "
        r"(\d+) duplicate\(s\); rejected none\)", fired["summary"])
    assert found, fired["summary"]
    since, so_far = int(found[1]), int(found[2])
    # whole 1-s blocks of 20 samples, at most the 40 s re-sent
    assert since % 20 == 0 and 0 < since <= so_far <= 800
