"""The sensor-time ``stale`` rule across an instrument replug, live (horizon 10 s), with the
shipped config (load source and motion sensor "auto") and a load cell but no motion stream:
the operator's `buoymon run` finding (bridge in the daemon, pty load cell unplugged, replugged
for ~10 s, stopped again). The never-seen motion streams gated the ordering for ever at
``newest - 10 s``, so when the data stopped its last 10 s of sensor time waited for the next
data: the ``stale`` clear of the 10 s of data went out together with the next stop's fire, in
one step (a clear and a fire in the same millisecond). Every transition is right in sensor
time (fire at the silence's tick, clear at the data's tick); only WHEN they go out was wrong.

The fix (monitor.ordering, ``ReorderBuffer.silence``; the daemon's idle loop calls
``Pipeline.silence``): after a wall-clock silence of all data longer than the horizon, the
never-seen (or dead) load streams are taken as known up to the newest data, so the held
horizon and its ticks' alerts go out then. From the next data on they gate again at newest -
10 s (never behind what was released): the grace that lets a low-rate stream stamped just
behind the load data (waves at a window's end, tests/test_forecast_pipeline.py) arrive in
time live. Letting them stop gating after the first horizon of SENSOR time (192a884,
reverted), or for good after the first silence, lost that grace."""

from __future__ import annotations

import math
import os
import sys
import time
import tty
from pathlib import Path

import numpy as np

from daemon_harness import DaemonProcess, free_port, wait_until_state
from monitor.blocks import SampleBlock
from monitor.checkpoint import CheckpointStore
from monitor.config import load_config
from monitor.pipeline import Pipeline

SHIPPED = Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml"
T0_NS = 1_750_000_000 * 10**9  # on the 10 s tick grid


def second(s: float) -> SampleBlock:
    """One second of 20 Hz tension from ``s`` s after T0 (a load cell line per 50 ms)."""
    t = T0_NS + int(round(s * 1e9)) + 50_000_000 * np.arange(20, dtype=np.int64)
    x = 20000.0 + 3000.0 * np.sin(np.arange(20.0) / 3.0 + s)
    return SampleBlock("vaps", "tension", t, {"tension_N": x}, int(t[-1]))


# data to 52.95 s, unplugged, replugged 69.0 .. 79.95 s, stopped, back from 146 s
SECONDS = [*range(0, 53), *np.arange(69.0, 79.4, 1.0), *range(146, 160)]


def stale_steps(p: Pipeline, silent_s: float) -> list[tuple[float, list[tuple[str, float]]]]:
    """Per step with stale transitions: the block's start (s), or the second a stop began
    (s) after which the daemon told of ``silent_s`` s of wall-clock silence (one sensor second
    a wall-clock one: a load cell stamped on receipt), and (event, tick end s)."""
    out = []
    for s, following in zip(SECONDS, [*SECONDS[1:], None]):
        steps = [(s, p.process(second(s)))]
        if following is None or following - s > 1.0:
            steps.append((s + 1.0, p.silence(silent_s)))
        for at, step in steps:
            ev = [(a.event, (a.at_ns - T0_NS) / 1e9) for a in step.alerts
                  if a.rule == "stale"] if step is not None else []
            if ev:
                out.append((float(at), ev))
    return out


def test_stale_clear_goes_out_with_the_data_not_with_the_next_stop():
    p = Pipeline(load_config(SHIPPED), horizon_s=10.0)
    # each stop, 10.5 s of wall clock later: the 10 s held are processed; the data resuming,
    # the unseen motion streams gate at newest - 10 s again.
    # tick 60: last sample 52.95 s, 7.05 s > stale_after_s 5 s: fire, once the data passes
    # 70 s (the block at 70 s); tick 70: sample at 70.0 s, clear, at the silence after the
    # replug's data (newest 79.95 s; before the fix: with the next stop's fire, by the block
    # at 146 s); tick 80: age 0.05 s; tick 90: last sample 79.95 s, 10.05 s: fire, with the
    # data at 146 s (past 100 s); tick 150: clear, at the silence after 159.95 s.
    assert stale_steps(p, 10.5) == [(70.0, [("fire", 60.0)]), (80.0, [("clear", 70.0)]),
                                    (146.0, [("fire", 90.0)]), (160.0, [("clear", 150.0)])]
    assert p.reorder.load_streams == ("tension", "imu", "motion")  # still "auto", unseen


def test_a_silence_within_the_horizon_releases_nothing():
    """Stops shorter than the horizon (10 s) by the wall clock: the unseen motion streams
    still gate, the ticks wait for the next data (the clear at 70 s, the fire at 90 s: with
    the data at 146 s, the fire at 60 s with the block at 70 s, newest 70.95 s)."""
    p = Pipeline(load_config(SHIPPED), horizon_s=10.0)
    assert stale_steps(p, 10.0) == [(70.0, [("fire", 60.0)]),
                                    (146.0, [("clear", 70.0), ("fire", 90.0)])]


def test_the_released_horizon_is_processed_at_the_silence():
    """The silence step itself: sensor time reaches the newest sample (52.95 s), tick 50 is
    evaluated, and a second silence changes nothing; a replay's ordering (gate_all) never
    releases."""
    p = Pipeline(load_config(SHIPPED), horizon_s=10.0)
    for s in range(53):
        p.process(second(s))
    assert p.last["now_ns"] == T0_NS + 42_950_000_000  # newest - 10 s
    step = p.silence(10.5)
    assert step is not None and step.now_ns == T0_NS + 52_950_000_000
    assert p.next_tick_ns == T0_NS + 60 * 10**9
    assert p.silence(60.0) is None
    replay = Pipeline(load_config(SHIPPED), horizon_s=10.0, gate_all=True)
    replay.process(second(0))
    assert replay.silence(60.0) is None


def imu_second(s: float) -> SampleBlock:
    """One second of 20 Hz IMU accelerations from ``s`` s after T0."""
    t = T0_NS + int(round(s * 1e9)) + 50_000_000 * np.arange(20, dtype=np.int64)
    a = np.sin(np.arange(20.0) + s)
    return SampleBlock("vaps", "imu", t, {"accel_x_mps2": 0.1 * a, "accel_y_mps2": 0.1 * a,
                                          "accel_z_mps2": 9.81 + a}, int(t[-1]))


def waves_at(s: float) -> SampleBlock:
    """One waves sample (a window's sea state) stamped ``s`` s after T0."""
    t = np.array([T0_NS + int(round(s * 1e9))], np.int64)
    return SampleBlock("vaps", "waves", t, {"hs_m": np.array([2.0]), "tp_s": np.array([8.0])},
                       int(t[0]))


def test_the_grace_returns_when_the_data_resumes_after_a_release():
    """After a release, the never-seen motion streams gate again from the next data, never
    behind what was processed: a waves sample stamped just behind the load data (a window's
    end inside the newest load cell block, tests/test_forecast_pipeline.py) is accepted, as
    before the silence (it was time_backwards: the release lasted until a restart)."""
    p = Pipeline(load_config(SHIPPED), horizon_s=10.0)
    for s in range(53):
        p.process(second(s))
    assert p.silence(10.5) is not None and p.processed_ns == T0_NS + 52_950_000_000
    p.process(second(69))  # newest 69.95 s: the unseen streams gate at 59.95 s
    assert p.last["now_ns"] == T0_NS + 59_950_000_000
    p.process(waves_at(69.5))
    for s in range(70, 80):
        p.process(second(s))
    waves = p.validators["waves"]
    assert (waves.accepted, waves.rejected["time_backwards"]) == (1, 0)
    # the release holds for what it released: data resuming within the horizon of sensor
    # time gates at the release (52.95 s), not at newest - 10 s = 45.95 s; a waves sample
    # behind it was processed time: time_backwards, nothing processed twice
    p = Pipeline(load_config(SHIPPED), horizon_s=10.0)
    for s in range(53):
        p.process(second(s))
    p.silence(10.5)
    p.process(second(55))
    assert p.reorder.watermark() == T0_NS + 52_950_000_000
    p.process(waves_at(54.5))
    p.process(waves_at(52.5))
    for s in range(56, 66):
        p.process(second(s))
    assert (waves := p.validators["waves"]).accepted == 1
    assert waves.rejected["time_backwards"] == 1


def test_a_motion_stream_seen_then_dead_is_released_by_the_silence():
    """An IMU seen for 20 s that then died gates at newest - 10 s like a stream never seen:
    the wall-clock silence releases the last 10 s too. One still talking when the data stops
    (its newest within the horizon) is not released: its delayed samples are still due."""
    p = Pipeline(load_config(SHIPPED), horizon_s=10.0)
    for s in range(53):
        p.process(second(s))
        if s < 20:
            p.process(imu_second(s))
    assert p.reorder.load_streams == ("tension", "imu")
    assert p.last["now_ns"] == T0_NS + 42_950_000_000
    step = p.silence(10.5)
    assert step is not None and step.now_ns == T0_NS + 52_950_000_000
    assert p.silence(60.0) is None
    p.process(second(69))
    p.process(waves_at(69.5))
    for s in range(70, 80):
        p.process(second(s))
    assert p.validators["waves"].accepted == 1
    assert p.validators["waves"].rejected["time_backwards"] == 0
    alive = Pipeline(load_config(SHIPPED), horizon_s=10.0)
    for s in range(53):
        alive.process(second(s))
        if s < 52:
            alive.process(imu_second(s))
    assert alive.last["now_ns"] == T0_NS + 51_950_000_000
    assert alive.silence(10.5) is None
    assert alive.last["now_ns"] == T0_NS + 51_950_000_000


def test_a_motion_stream_arriving_with_the_load_cell_still_gates():
    """The start-up gate kept: an IMU block arriving just after the load cell's first block
    (same sensor time) is not late."""
    p = Pipeline(load_config(SHIPPED), horizon_s=10.0)
    p.process(second(0))
    t = T0_NS + 50_000_000 * np.arange(20, dtype=np.int64)
    a = np.sin(np.arange(20.0))
    p.process(SampleBlock("vaps", "imu", t, {"accel_x_mps2": 0.1 * a, "accel_y_mps2": 0.1 * a,
                                             "accel_z_mps2": 9.81 + a}, int(t[-1])))
    assert p.validators["imu"].accepted == 20
    assert not any(p.validators["imu"].rejected.values())


def test_a_silence_after_a_restart_releases_the_restored_horizon(tmp_path):
    """The daemon restarted (checkpoint restored) within the horizon after a burst of data, and
    no data comes: the horizon the restored ordering holds is released once the daemon has
    heard nothing for the horizon since its start, not with the next data (before: the
    silence counted only from data of this life, so nothing was released)."""
    from monitor.cmd_run import build_daemon  # noqa: PLC0415 (the daemon `buoymon run` builds)

    cfg = tmp_path / "buoymon.toml"
    cfg.write_text(SHIPPED.read_text().replace("\nhorizon_s = 10.0 ", "\nhorizon_s = 0.5 ", 1)
                   + f'\n[state]\npath = "{tmp_path / "st.sqlite"}"\n'
                   '[metrics]\nenabled = false\n')
    first = build_daemon(str(cfg))
    for s in range(53):
        first.pipeline.process(second(s))
    held = first.pipeline.processed_ns
    assert held == T0_NS + 52_450_000_000  # newest 52.95 s - the horizon
    first._store.save(first.checkpoint_state())
    first._store.close()
    again = build_daemon(str(cfg))  # the restart
    try:
        assert again.pipeline.processed_ns == held
        again._silence()  # at once: no silence yet
        assert again.pipeline.processed_ns == held
        time.sleep(0.6)
        again._silence()
        assert again.pipeline.processed_ns == T0_NS + 52_950_000_000
        assert again._dirty_status  # the status tells of it at once
    finally:
        again._store.close()


def _stale_on(status: dict) -> list[int]:
    """``since_ns`` of the active sensor-time ``stale`` alert of tension ([] when none)."""
    return [a["since_ns"] for a in status["status"]["alerts"]["active"]
            if a["rule"] == "stale" and a["component"] == "tension"]


def _until_second(mod: int) -> None:
    """Sleep to the next wall-clock second ``mod`` of the 10 s alert grid (sensor time here is
    the bridge's receive time)."""
    now = time.time()
    time.sleep((mod - now) % 10.0)


def test_replugged_load_cell_stale_clears_while_it_talks_in_the_daemon(tmp_path):
    """Real processes: `buoymon run` with the bridge inside reading a load cell on a pty
    (plain numbers, stamped on receipt), the shipped config. It talks, is silent 14 s across a
    grid second (stale fires there), talks 7 s across the next grid second, stops: the stale
    clear of that tick is out once the daemon has heard nothing for the horizon (10 s), with
    no new fire (before the fix it waited for the next data)."""
    port, mport = free_port(), free_port()
    master, slave = os.openpty()
    tty.setraw(slave)
    cfg = tmp_path / "buoymon.toml"
    cfg.write_text(
        SHIPPED.read_text()
        + f'\n[zenoh]\nlisten = ["tcp/127.0.0.1:{port}"]\nstatus_interval_s = 0.5\n'
        f'[state]\npath = "{tmp_path / "st.sqlite"}"\n[metrics]\nport = {mport}\n'
        '[[source]]\nname = "loadcell"\nsensor = "tension"\ntransport = "serial"\n'
        f'device = "{os.ttyname(slave)}"\nbaud = 115200\ncolumns = {{ tension_N = 0 }}\n')
    d = DaemonProcess([sys.executable, "-m", "monitor.cli", "--log-level", "warning", "run",
                       "--config", str(cfg)], tmp_path)

    def talk(until_mod: int) -> None:
        k = 0
        end = time.time() + (until_mod - time.time()) % 10.0
        while time.time() < end:
            os.write(master, f"{20000 + 3000 * math.sin(k / 20):.1f}\r\n".encode())
            k += 1
            time.sleep(0.05)

    try:
        d.wait_for("READY=1", timeout=120)
        wait_until_state(port, lambda s: s["status"].get("bridge", {}).get("sources", {})
                         .get("loadcell", {}).get("connected"), buoy="vaps")
        _until_second(8)
        talk(3)          # across grid second G (:x0)
        time.sleep(5.0)
        _until_second(7)  # silent 14 s: tick G+10 sees tension 7 s old
        talk(4)          # 7 s across grid second G+20: its tick sees fresh data
        # the G+10 fire is out with the data (past G+20); the G+20 clear, held by the unseen
        # motion streams' 10 s grace, is out after 10 s of silence (not with the next data)
        wait_until_state(port, _stale_on, timeout=5.0, buoy="vaps")
        stopped = time.monotonic()
        after = wait_until_state(port, lambda s: not _stale_on(s), timeout=20.0, buoy="vaps")
        cleared_after_s = time.monotonic() - stopped
    finally:
        rc = d.terminate()
        os.close(master)
        os.close(slave)
    assert rc == 0
    assert not _stale_on(after), after["status"]["alerts"]["active"]
    assert 8.0 < cleared_after_s < 20.0  # the horizon of silence, the status's cadence
    store = CheckpointStore(tmp_path / "st.sqlite")
    history = store.load().state["pipeline"]["alerts"]["history"]
    store.close()
    stale = [(h["event"], h["at_ns"] % (10 * 10**9)) for h in history
             if h.get("rule") == "stale"]  # the shipped config: on tension only
    # each on the grid (G+10 fire, G+20 clear; the start-up tick may add a first fire/clear)
    assert stale[-2:] == [("fire", 0), ("clear", 0)], stale
