"""The damage-rate table learned inside the pipeline, forecasts applied at sensor time, and the
per-window spectral cross-check, on measured sea states (NDBC 44007, ../shared/realdata):
four hours of the 20 January 1996 storm build-up, each hour's tension from the simulator's
WAVFOR load model of that hour's measured Hs and Tp, the measured Hs and Tp on the waves
stream."""

from __future__ import annotations

import json
import math
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from models import fatigue
from models.fatigue.spectral import damage_rate_from_psd
from monitor.blocks import SampleBlock
from monitor.config import ConfigError, config_with, default_config
from monitor.forecast import ForecastExpired
from monitor.pipeline import Pipeline
from monitor.sea_state_learner import SEGMENT
from replay.sea_state_files import read_sea_states
from replay.simulate import SimConfig, clean_tension

REPO = Path(__file__).resolve().parents[1]
SHARED = next((p / "shared" for p in REPO.parents if (p / "shared/realdata").is_dir()), None)
pytestmark = pytest.mark.skipif(SHARED is None, reason="../shared/realdata absent")

FIRST_HOUR, HOURS = 446, 4  # 1996-01-19 22:00 to 1996-01-20 02:00 UTC: Hs 3.6 m to 5.6 m
W_NS = 1800 * 10**9


@pytest.fixture(scope="module")
def storm():
    """(t0_ns, tension per hour, (hs, tp) per hour)."""
    s = read_sea_states(SHARED / "realdata/ndbc44007_ecbenchmarkA/ec-benchmark_dataset_A.txt")
    sel = slice(FIRST_HOUR, FIRST_HOUR + HOURS)
    hs, tp = s.hs_m[sel], s.tp_s[sel]
    tension = [clean_tension(SimConfig(hours=1.0, hs_m=float(h), tp_s=float(p), seed=k,
                                       load_model="wavfor"))
               for k, (h, p) in enumerate(zip(hs, tp))]
    return int(s.t_s[FIRST_HOUR]) * 10**9, tension, list(zip(hs.tolist(), tp.tolist()))


def blocks(storm, block_s: int) -> list[SampleBlock]:
    """Tension at 20 Hz in ``block_s`` blocks; a waves sample at each half hour's end with
    the hour's measured sea state."""
    t0, tension, sea = storm
    x = np.concatenate(tension)
    t = t0 + (np.arange(x.size, dtype=np.int64) + 1) * 50_000_000
    out = []
    n = block_s * 20
    for a in range(0, x.size, n):
        tt = t[a:a + n]
        out.append(SampleBlock("vaps", "tension", tt, {"tension_N": x[a:a + n]}, int(tt[-1])))
        for end in range(t0 + W_NS, int(tt[-1]) + 1, W_NS):
            if tt[0] <= end <= tt[-1]:
                hs, tp = sea[(end - t0 - 1) // (3600 * 10**9)]
                out.append(SampleBlock("vaps", "waves", np.array([end], np.int64),
                                       {"hs_m": np.array([hs]), "tp_s": np.array([tp])},
                                       end))
    return out


def run(config, bl, state=None, horizon_s: float = 3600.0) -> Pipeline:
    p = Pipeline(config, state=state, horizon_s=horizon_s)
    for b in bl:
        p.process(b)
    return p


def test_table_learned_from_the_stream_matches_the_committed_damage(storm):
    config = default_config()
    p = run(config, blocks(storm, 60))
    p.flush()
    learner = p.sea_states
    windows = learner.history
    # 8 half hours: the first window starts at the first tick (10 s in); the last one
    # closes at the data's end
    assert [w["status"] for w in windows] == ["learned"] * 8
    assert [w["hs_m"] for w in windows] == [h for h, _ in storm[2] for _ in (0, 1)]
    t = learner.table
    hours = t.hours[t.hours > 0]
    assert hours.sum() == pytest.approx(4.0 - 10.0 / 3600.0)
    i, j = t.bin_of([h for h, _ in storm[2]], [p_ for _, p_ in storm[2]])
    assert sorted(zip(i.tolist(), j.tolist())) == sorted(zip(*np.nonzero(t.hours)))
    # each window's damage is the committed damage it added: they sum to the total after
    # the first tick (the flush commits nothing past the last window's end here)
    conductor = p.components["conductor"].figures()["damage_committed"]
    first_tick = conductor - math.fsum(w["rainflow"]["conductor"] for w in windows)
    assert 0 <= first_tick < 1e-3 * conductor
    assert t.damage[0].sum() == pytest.approx(conductor - first_tick, rel=1e-12)
    # and the committed damage (with the residue as half cycles) is rainflow over the four
    # hours' stress in one piece (models.fatigue.damage, the seed 004 S-N curve)
    comp = p.components["conductor"]
    whole = fatigue.damage(comp.stress(np.concatenate(storm[1])), comp.sn_curve)
    assert comp.figures()["damage"] == pytest.approx(whole, rel=1e-5)
    assert p.status()["sea_state_table"]["learned"] == 8


def test_learning_is_split_invariant_and_restores_exactly(storm):
    config = default_config()
    one = run(config, blocks(storm, 3600))
    fine = blocks(storm, 5)
    half = len(fine) // 2 + 7  # mid-window, mid-segment
    # live-sized blocks with the live ordering horizon (the replay one costs here)
    first = run(config, fine[:half], horizon_s=10.0)
    saved = json.loads(json.dumps(first.state()))
    second = run(config, fine[half:], state=saved, horizon_s=10.0)
    for p in (one, second):
        p.flush()
    a, b = one.state()["sea_states"], second.state()["sea_states"]
    assert json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def test_spectral_cross_check_per_window_against_welch(storm):
    """A window's Dirlik damage is the Welch PSD (scipy, Hann, no overlap, 1024 samples) of
    its stress through the Dirlik density, times the hours the window covered; the WAVFOR
    bound is clipped at zero when the line goes slack, far from Gaussian: flagged."""
    config = default_config()
    p = run(config, blocks(storm, 60))
    w = p.sea_states.history[3]  # the second half of the second hour
    comp = p.components["conductor"]
    x = comp.stress(storm[1][1][36000:])  # samples (T0 + 1.5 h, T0 + 2 h]
    n = x.size // SEGMENT * SEGMENT
    f, psd = signal.welch(x[:n], fs=20.0, nperseg=SEGMENT, noverlap=0)
    expect = damage_rate_from_psd(comp.sn_curve, f[1:], psd[1:]) * 1800.0
    assert w["segments"] == 35
    assert w["dirlik"]["conductor"] == pytest.approx(expect, rel=1e-9)
    ratio = w["dirlik"]["conductor"] / w["rainflow"]["conductor"]
    assert (ratio > 3 or ratio < 1 / 3) == ("conductor" in w["flagged"])
    report = p.report()
    assert report["spectral_windows"][3] == w
    assert len(report["spectral_windows"]) == 6
    assert report["sea_state_table"]["compared"] == 6 * len(p.components)


def test_forecast_applied_at_its_issue_tick_fires_and_clears(storm):
    """A forecast of the storm's own sea states, issued an hour in: projected from the
    committed damage at that tick with the table learned so far; a calm forecast clears."""
    # min_hours 0.5: the first hour's bin holds its two windows (the first from 10 s in)
    config = config_with(default_config(), forecast={"alert_damage": 1.0, "min_hours": 0.5})
    bl = blocks(storm, 60)
    t0, _, sea = storm
    issued = t0 / 1e9 + 3600.0
    p = Pipeline(config, horizon_s=3600.0)
    p.add_forecast({"issued_s": issued, "time_s": [issued + 3600.0 * k for k in range(3)],
                    "hs_m": [sea[0][0]] * 3, "tp_s": [sea[0][1]] * 3})
    p.add_forecast({"issued_s": issued + 1800.0, "time_s": [issued + 1800.0],
                    "hs_m": [0.0], "tp_s": [5.0]})
    fired = []
    for b in bl:
        fired += [r for r in p.process(b).alerts
                  if r.rule == "forecast_damage" and r.component == "conductor"]
    assert [(r.event, r.component, r.at_ns) for r in fired] == [
        ("fire", "conductor", int(issued * 1e9)),
        ("clear", "conductor", int(issued * 1e9) + W_NS)]
    # the first hour cost 0.43: at that rate 1.0 is reached 1.3 h after the issue time
    d_now = math.fsum(w["rainflow"]["conductor"] for w in p.sea_states.history[:2])
    rate = d_now / (1.0 - 10.0 / 3600.0)  # the learned bin: its two windows' mean rate
    hours_to_1 = (1.0 - d_now) / rate
    expect = datetime.fromtimestamp(issued + 3600.0 * hours_to_1, timezone.utc)
    assert f"reaches damage 1 by {expect:%Y-%m-%d %H:%M} UTC" in fired[0].summary
    assert fired[0].value == pytest.approx(d_now + 3.0 * rate, rel=1e-9)
    last = p.forecasts.last  # the calm one: Hs 0 in a bin with no data and no model rate
    assert last["components"]["conductor"]["steps_unrated"] == 1


def test_forecast_bad_payloads_and_config_are_refused():
    p = Pipeline(default_config())
    for bad in ([], {"time_s": [1, 2], "hs_m": [1.0], "tp_s": [5.0, 5.0]},
                {"time_s": [2, 1], "hs_m": [1, 1], "tp_s": [5, 5]},
                {"time_s": [1], "hs_m": [-1], "tp_s": [5]},
                {"time": ["yesterday"], "hs_m": [1], "tp_s": [5]}):
        with pytest.raises(ValueError, match="forecast"):
            p.add_forecast(bad)
    with pytest.raises(ConfigError, match="whole number of alert ticks"):
        Pipeline(config_with(default_config(), forecast={"window_s": 15.0}))
    with pytest.raises(ConfigError, match="forecast.alert_damage"):
        Pipeline(config_with(default_config(), forecast={"alert_damage": -1}))


def test_a_forecast_with_no_step_ahead_of_its_tick_is_refused_as_expired(storm):
    """Steps that all end by the first tick the forecast can be applied at (its issue time, a
    whole tick here) were applied with 0 steps, unsaid (and cleared a forecast_damage alert on
    nothing): now refused as expired, counted by the daemon. One ending a second later is
    applied with that one step."""
    t0, _, sea = storm
    issued = t0 / 1e9 + 1800.0  # t0 on the 10-s tick grid: its tick ends at the issue time
    p = Pipeline(default_config(), horizon_s=10.0)

    def doc(end_s: float) -> dict:  # two hourly steps, the last ending at end_s
        return {"issued_s": issued, "time_s": [end_s - 7200.0, end_s - 3600.0],
                "hs_m": [sea[0][0]] * 2, "tp_s": [sea[0][1]] * 2}

    for end in (issued - 3600.0, issued):
        with pytest.raises(ForecastExpired, match="nothing to project: its last step ends"):
            p.add_forecast(doc(end))
    assert p.add_forecast(doc(issued + 1.0)) == int(issued * 1e9)
    for b in blocks(storm, 60):
        p.process(b)
        if p.forecasts.last is not None:
            break
    assert (p.forecasts.last["applied_ns"], p.forecasts.last["steps"]) == (int(issued * 1e9), 1)
    assert p.forecasts.counts["received"] == 1


def test_windows_in_rerun(storm, tmp_path):
    """Each closed window's rainflow and Dirlik damage, flag lane and sea state, read back
    from the .rrd, are the pipeline's figures."""
    from monitor.viz.rerun_options import RerunOptions
    from monitor.viz.rerun_outputs import open_recording
    from monitor.viz.rerun_sink import RerunSink
    from tests.viz_helpers import read_rrd

    path = tmp_path / "w.rrd"
    opts = RerunOptions()
    sink = RerunSink(open_recording("vaps", opts, rrd=path), opts)
    p = Pipeline(default_config(), [sink], horizon_s=3600.0)
    issued = storm[0] / 1e9 + 7200.0
    p.add_forecast({"issued_s": issued, "time_s": [issued, issued + 3600.0],
                    # the second hour's bin: learned (two whole windows) by the issue time
                    "hs_m": [storm[2][1][0]] * 2, "tp_s": [storm[2][1][1]] * 2})
    for b in blocks(storm, 60):
        p.process(b)
    p.flush()
    p.close()
    data = read_rrd(path)
    last = p.forecasts.last["components"]["conductor"]
    for key in ("damage_end", "damage_end_low", "damage_end_high"):
        rows = data[f"forecast/conductor/{key}"]
        assert [t.value for t in rows["sensor_time"]] == [int(issued * 1e9)]
        assert rows["Scalars:scalars"] == [[last[key]]]
    windows = p.sea_states.history
    rows = data["spectral/conductor/rainflow"]
    assert [t.value for t in rows["sensor_time"]] == [w["end_ns"] for w in windows]
    got = [v[0] for v in rows["Scalars:scalars"]]
    assert got == [w["rainflow"]["conductor"] for w in windows]
    got = [v[0] for v in data["spectral/conductor/dirlik"]["Scalars:scalars"]]
    assert got == [w["dirlik"]["conductor"] for w in windows]
    assert [v[0] for v in data["sea_state/hs_m"]["Scalars:scalars"]] == [
        w["hs_m"] for w in windows]
    flags = data["spectral_flags/conductor"]["StateChange:state"]
    assert flags[0] == [("flagged" if "conductor" in windows[0]["flagged"] else "agree")]


def test_replay_report_and_html_carry_the_cross_check(storm, tmp_path):
    """`buoymon replay --report --html` of a log of the storm: the JSON report lists each
    window's rainflow and Dirlik damage, the summary counts them, the HTML page plots them
    with the per-component table."""
    import subprocess
    import sys

    from replay.reader import iter_blocks
    from replay.runner import run_blocks
    from replay.writer import LogWriter

    log = tmp_path / "storm.mcap"
    with LogWriter(log) as w:
        for b in blocks(storm, 1):
            w.write_block(b)
    report, page = tmp_path / "r.json", tmp_path / "r.html"
    p = subprocess.run([sys.executable, "-m", "monitor.cli", "replay", str(log), "--report",
                        str(report), "--html", str(page), "--no-progress"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300,
                       env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"})
    assert p.returncode == 0, p.stderr
    r = json.loads(report.read_text())
    # the command's figures are those of the pipeline over the same log; the reader cuts its
    # joined blocks at 1800 s of sensor time, so the first waves sample arrives in time and
    # every window has a sea state
    ref, _ = run_blocks(default_config(), iter_blocks([log]))
    assert r["spectral_windows"] == json.loads(json.dumps(ref.sea_states.history))
    sea = r["sea_state_table"]
    n_comp = len(ref.components)
    assert (sea["windows"], sea["learned"], sea["compared"]) == (8, 8, 8 * n_comp)
    assert r["samples"]["waves"]["rejected"]["time_backwards"] + r["samples"]["waves"][
        "accepted"] == 8
    assert (f"spectral cross-check: {sea['flagged']} of {8 * n_comp} window damages flagged "
            "(Dirlik vs rainflow beyond x3)") in p.stdout
    html_text = page.read_text()
    assert "Spectral cross-check: Dirlik vs rainflow damage per window" in html_text
    assert "id='plot-spectral'" in html_text
    ratios = [w["dirlik"]["conductor"] / w["rainflow"]["conductor"] for w in r["spectral_windows"]]
    assert f"<td>{np.median(ratios):.4g}</td>" in html_text


def test_a_late_forecast_is_applied_at_the_next_tick_and_replays_identically(storm):
    """A forecast arriving after sensor time passed its issue time is due at the first tick
    not yet evaluated; handed to a fresh pipeline with that due time before all the data
    (as a replay of the daemon's recording does), it fires at the same tick, the same way."""
    config = config_with(default_config(), forecast={"alert_damage": 1.0, "min_hours": 0.5})
    t0, _, sea = storm
    doc = {"issued_s": t0 / 1e9 + 1800.0, "time_s": [t0 / 1e9 + 1800.0 + 3600.0 * k
                                                      for k in range(4)],
           "hs_m": [sea[0][0]] * 4, "tp_s": [sea[0][1]] * 4}
    bl = blocks(storm, 60)
    live = Pipeline(config, horizon_s=10.0)
    fired = []
    for k, b in enumerate(bl):
        if k == 70:  # 70 min of data in: well past the issue time
            due = live.add_forecast(doc)
            assert due == live.next_tick_ns > doc["issued_s"] * 1e9
        fired += [r.to_dict() for r in live.process(b).alerts if r.rule == "forecast_damage"]
    replay = Pipeline(config, horizon_s=3600.0)
    assert replay.add_forecast(doc, due) == due
    again = []
    for b in bl:
        again += [r.to_dict() for r in replay.process(b).alerts if r.rule == "forecast_damage"]
    assert fired and {r["at_ns"] for r in fired} == {due} and again == fired
    # forecasting never changes the committed damage (nor anything of the fatigue chain)
    plain = Pipeline(config, horizon_s=3600.0)
    for b in bl:
        plain.process(b)
    assert replay.state()["components"] == plain.state()["components"]


def test_hindcast_through_the_pipeline_within_20_percent():
    """Ten days of measured NDBC 44007 sea states (January 1996), five simulated minutes
    each, through the pipeline: the table it learned on the first five days forecasts the
    damage it then commits over the next five within 20 % (-6.5 %; the weather of the two
    halves differs, so only a quarter of the second half's steps fall in bins learned in the
    first: the model fills the rest)."""
    from replay.hindcast import pipeline_hindcast
    from replay.sea_state_files import SeaStates

    s = read_sea_states(SHARED / "realdata/ndbc44007_ecbenchmarkA/ec-benchmark_dataset_A.txt")
    n = 240
    states = SeaStates(s.t_s[:n], s.hs_m[:n], s.tp_s[:n], s.direction_deg[:n])
    h = pipeline_hindcast(default_config(), states, half=n // 2, seed=1000)
    assert h.windows == n and h.actual[0] > 0
    assert h.forecast[0] == pytest.approx(h.actual[0], rel=0.20)
    assert h.low[0] <= h.forecast[0] <= h.high[0]
    assert h.learned_share[0] >= 0.25


@pytest.mark.parametrize("drop, source", [((), "waves"), (("waves",), "motion"),
                                          (("waves", "motion"), "imu")])
def test_sea_state_from_waves_else_motion_else_imu(drop, source, tmp_path):
    """`buoymon simulate` of a measured NDBC 44007 sea state (1996-01-19 22:00, Hs 3.59 m,
    Tp 8.29 s) replayed without some streams: a window takes its sea state from the waves
    samples, else the heave spectrum of the motion stream, else the vertical acceleration
    spectrum of the IMU divided by (2 pi f)^4; each within 10 % of the simulated sea."""
    from replay.reader import iter_blocks
    from replay.runner import replay_pipeline
    from replay.simulate import simulate

    s = read_sea_states(SHARED / "realdata/ndbc44007_ecbenchmarkA/ec-benchmark_dataset_A.txt")
    hs, tp = float(s.hs_m[FIRST_HOUR]), float(s.tp_s[FIRST_HOUR])
    log = tmp_path / "sim.mcap"
    simulate(SimConfig(hours=1.0, hs_m=hs, tp_s=tp, seed=3, load_model="wavfor"), log)
    p = replay_pipeline(default_config())
    for b in iter_blocks([log]):
        if b.sensor not in drop:
            p.process(b)
    p.flush()
    [w] = p.sea_states.history  # the window ending at 30 min (the log ends just before 1 h)
    assert w["sea_state_from"] == source and w["status"] == "learned"
    assert w["hs_m"] == pytest.approx(hs, rel=0.10)
    assert w["tp_s"] == pytest.approx(tp, rel=0.10)


def test_motion_sea_state_restores_exactly(tmp_path):
    """The heave and acceleration spectra of the open window are in the state: a replay
    stopped mid-window and continued from its JSON state ends byte-identical."""
    from replay.reader import iter_blocks
    from replay.runner import replay_pipeline
    from replay.simulate import simulate

    log = tmp_path / "sim.mcap"
    simulate(SimConfig(hours=2.0, hs_m=2.0, tp_s=7.0, seed=5, load_model="wavfor"), log)
    bl = [b for b in iter_blocks([log]) if b.sensor != "waves"]  # blocks of about 20 min
    t0 = bl[0].t_first_ns
    # stop once the data reaches 1 h 25 min: the replay horizon (1 h) has released 25 min
    cut = next(i for i, b in enumerate(bl) if b.t_last_ns - t0 > 5100 * 10**9)
    one = replay_pipeline(default_config())
    for b in bl:
        one.process(b)
    one.flush()
    first = replay_pipeline(default_config())
    for b in bl[:cut]:
        first.process(b)
    assert first.sea_states.heave.current.segments > 0  # the first window is open
    second = replay_pipeline(default_config(), state=json.loads(json.dumps(first.state())))
    for b in bl[cut:]:
        second.process(b)
    second.flush()
    assert [w["sea_state_from"] for w in one.sea_states.history] == ["motion"] * 3
    assert json.dumps(one.state()["sea_states"], sort_keys=True) == json.dumps(
        second.state()["sea_states"], sort_keys=True)
