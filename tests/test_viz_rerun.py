"""The Rerun sink: write an .rrd, read it back with rerun's chunk reader, check entities and
values."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from monitor.blocks import SampleBlock
from monitor.schema import ConfigError, parse_struct
from monitor.viz.rerun_options import RerunOptions
from monitor.viz.rerun_outputs import analytics_disabled, analytics_disabled_env, open_recording
from monitor.viz.rerun_sink import RerunSink, entity_part, local_east_north
from tests.viz_helpers import RATE_HZ, T0_NS, make_steps, ns, read_rrd

N_STEPS = 30


def shape(tension: float) -> tuple[np.ndarray, np.ndarray]:
    """A stand-in line profile: straight from anchor to a fairlead 30 m away, 10 m up."""
    x = np.linspace(0.0, 30.0, 7)
    return x, x / 3.0 + tension * 0.0


def record(tmp_path, options: RerunOptions, steps=None, extra=None):
    path = tmp_path / "run.rrd"
    sink = RerunSink(open_recording("B1", options, rrd=path), options, shape_provider=shape)
    steps = steps if steps is not None else make_steps(N_STEPS)
    for k, step in enumerate(steps):
        if extra is not None:
            extra(sink, k, step)
        sink.on_step(step)
    sink.close()
    return read_rrd(path), steps


def scalars(cols) -> np.ndarray:
    """Scalar rows as (n,) for one series per entity or (n, k) for k series (an envelope)."""
    a = np.array([v for v in cols["Scalars:scalars"] if v is not None], dtype=float)
    return a[:, 0] if a.ndim == 2 and a.shape[1] == 1 else a


def test_envelope_matches_per_second_min_max(tmp_path):
    # small flush threshold: bins must survive being split across flushes
    opts = RerunOptions(flush_samples=70)
    data, steps = record(tmp_path, opts)
    t = np.concatenate([s.t_ns for s in steps])
    tension = np.concatenate([s.tension_N for s in steps])
    sec = (t - T0_NS) // 1_000_000_000
    want = np.array([[tension[sec == k].min(), tension[sec == k].max()] for k in range(N_STEPS)])
    got = scalars(data["tension/load"])
    np.testing.assert_array_equal(got, want / 1e3)  # kN, as the report shows it
    times = [ns(x) for x in data["tension/load"]["sensor_time"]]
    assert times == [T0_NS + k * 1_000_000_000 for k in range(N_STEPS)]
    assert data["tension/load"]["sample"] == [k * RATE_HZ for k in range(N_STEPS)]
    stress = scalars(data["stress/left"])
    np.testing.assert_allclose(stress, want * 2000.0 / 1e6, rtol=1e-14)  # MPa
    assert data["tension/load"]["SeriesLines:names"][0] == ["load min [kN]", "load max [kN]"]
    assert data["stress/left"]["SeriesLines:names"][0] == ["left min [MPa]", "left max [MPa]"]


def test_full_rate_logs_every_sample(tmp_path):
    data, steps = record(tmp_path, RerunOptions(envelope_s=0.0))
    t = np.concatenate([s.t_ns for s in steps])
    tension = np.concatenate([s.tension_N for s in steps])
    got = scalars(data["tension/load"])
    np.testing.assert_array_equal(got, tension / 1e3)
    assert [ns(x) for x in data["tension/load"]["sensor_time"]] == t.tolist()
    assert data["tension/load"]["sample"] == list(range(len(t)))


def test_nan_samples_are_left_out(tmp_path):
    steps = make_steps(4)
    steps[1].tension_N[:] = np.nan  # a whole bin of bad load samples
    steps[2].tension_N[3] = np.nan  # one bad sample
    data, _ = record(tmp_path, RerunOptions(), steps=steps)
    env = scalars(data["tension/load"])
    assert [ns(x) for x in data["tension/load"]["sensor_time"]] == [
        T0_NS + k * 1_000_000_000 for k in (0, 2, 3)]
    good = np.delete(steps[2].tension_N, 3)
    np.testing.assert_array_equal(env[1], [good.min() / 1e3, good.max() / 1e3])
    assert len(scalars(data["stress/left"])) == 4  # the stress series has all four bins
    data, _ = record(tmp_path, RerunOptions(envelope_s=0.0), steps=steps)
    assert len(scalars(data["tension/load"])) == 4 * RATE_HZ - RATE_HZ - 1


def test_damage_life_health_and_slow_sampling(tmp_path):
    data, steps = record(tmp_path, RerunOptions(slow_interval_s=5.0))
    # a point at the first step, then whenever sensor time crosses a 5 s grid line
    picked = [0] + [k for k in range(1, N_STEPS)
                    if steps[k].now_ns // 5_000_000_000 > steps[k - 1].now_ns // 5_000_000_000]
    assert [ns(x) for x in data["damage/left/committed"]["sensor_time"]] == [
        steps[k].now_ns for k in picked]
    for entity, comp, attr in (("damage/left/committed", "left", "damage_committed"),
                               ("damage/left/provisional", "left", "damage"),
                               ("damage_rate/right", "right", "damage_rate_per_day"),
                               ("remaining_life/right", "right", "remaining_life_days")):
        want = [getattr(steps[k].components[comp], attr) for k in picked]
        np.testing.assert_array_equal(scalars(data[entity]), want)
    # measured tension sampled likewise; estimated is all-NaN and so has no rows at all
    np.testing.assert_array_equal(scalars(data["tension/measured"]),
                                  [steps[k].measured_tension_N / 1e3 for k in picked])
    assert "tension/estimated" not in data
    accepted = scalars(data["health/tension/accepted"])
    rejected = scalars(data["health/tension/rejected"])
    np.testing.assert_array_equal(accepted, [(k + 1) * RATE_HZ for k in picked])
    np.testing.assert_array_equal(rejected, [sum(j % 2 for j in range(k + 1)) for k in picked])
    assert data["tension/source"]["StateChange:state"] == [["measured"]]


def test_rainflow_histogram_and_range_mean_matrix(tmp_path):
    opts = RerunOptions(snapshot_interval_s=10.0)
    data, steps = record(tmp_path, opts)
    r = np.concatenate([s.components["left"].ranges_Pa for s in steps])
    m = np.concatenate([s.components["left"].means_Pa for s in steps])
    c = np.concatenate([s.components["left"].counts for s in steps])
    edges = np.asarray(opts.range_edges_Pa)
    r_clipped = np.minimum(r, edges[-1] - 1.0)  # beyond the last edge goes in the last bin
    want_hist, _ = np.histogram(r_clipped, bins=edges, weights=c)
    bars = data["rainflow/left/histogram"]["BarChart:values"]
    # snapshots at 0 s, 10 s, 20 s grid crossings and one at close
    assert len(bars) == 4
    final = np.array(bars[-1][0]["buffer"])
    np.testing.assert_array_equal(final, want_hist)
    assert final.sum() == pytest.approx(c.sum())
    tensor = data["rainflow/left/range_mean"]["Tensor:data"][-1][0]
    assert tensor["shape"] == [len(edges) - 1, len(opts.mean_edges_Pa) - 1]
    assert tensor["names"] == ["stress_range", "stress_mean"]
    want2d, _, _ = np.histogram2d(r_clipped, m, bins=[edges, np.asarray(opts.mean_edges_Pa)],
                                  weights=c)
    np.testing.assert_array_equal(np.array(tensor["buffer"]).reshape(tensor["shape"]), want2d)
    # cumulative: every snapshot's total is at least the previous one's
    totals = [sum(b[0]["buffer"]) for b in bars]
    assert totals == sorted(totals) and totals[0] > 0


def test_alert_lanes_and_text_log_levels(tmp_path):
    def alerts(sink, k, step):
        if k == 4:
            sink.on_alert({"rule": "damage_warn", "labels": {"component": "left"},
                           "severity": "warning", "state": "firing", "event": "fire",
                           "at_ns": step.now_ns, "summary": "damage 0.1 >= 0.1"})
        if k == 9:
            sink.on_alert({"rule": "damage_warn", "labels": {"component": "left"},
                           "severity": "critical", "state": "firing", "event": "fire",
                           "at_ns": step.now_ns, "summary": "damage 0.5 >= 0.5"})
        if k == 12:
            sink.on_alert({"rule": "damage_warn", "labels": {"component": "left"},
                           "severity": "critical", "state": "resolved", "event": "reset",
                           "at_ns": step.now_ns, "summary": "cable replaced"})

    data, steps = record(tmp_path, RerunOptions(), extra=alerts)
    lane = data["alerts/state/damage_warn/left"]
    assert lane["StateChange:state"] == [["warning"], ["critical"], ["ok"]]
    assert [ns(x) for x in lane["sensor_time"]] == [steps[k].now_ns for k in (4, 9, 12)]
    logs = data["alerts/log"]
    assert logs["TextLog:level"] == [["WARN"], ["CRITICAL"], ["INFO"]]
    assert logs["TextLog:text"][2] == ["[reset] damage_warn/left: cable replaced"]
    with pytest.raises(ValueError, match="rule"):
        RerunSink(open_recording("B1", RerunOptions(), rrd=tmp_path / "x.rrd")).on_alert({})


def test_alert_record_objects_and_stale_lanes(tmp_path):
    from monitor.alerts.records import AlertRecord
    from monitor.events import Observation, StreamObs

    def events(sink, k, step):
        if k in (2, 6, 7):
            stale = k >= 6  # ok at 2, stale at 6, still stale at 7 (no new lane entry)
            sink.on_observation(Observation(
                buoy_id="B1", t_ns=step.now_ns, tick_s=1.0, load_source="measured",
                load_t_ns=step.t_ns, tension_N=step.tension_N, measured_tension_N=5e3,
                estimated_tension_N=float("nan"), components={},
                streams={"imu": StreamObs(last_t_ns=step.now_ns, stale=stale, accepted=1,
                                          rejected={}, rejected_in_tick=0,
                                          received_in_tick=1)}))
        if k == 8:
            rec = AlertRecord(rule="stale_imu", kind="sensor_stale", severity="warning",
                              buoy="B1", component="imu", state="firing", event="fire",
                              starts_at_ns=step.now_ns, ends_at_ns=0, at_ns=step.now_ns,
                              value=12.0, threshold=10.0, unit="s", summary="imu silent 12 s")
            step.alerts.append(rec)  # transitions carried by the step are logged by on_step

    data, steps = record(tmp_path, RerunOptions(), extra=events)
    assert data["health/imu/state"]["StateChange:state"] == [["ok"], ["stale"]]
    assert [ns(x) for x in data["health/imu/state"]["sensor_time"]] == [
        steps[2].now_ns, steps[6].now_ns]
    assert data["alerts/state/stale_imu/imu"]["StateChange:state"] == [["warning"]]
    assert data["alerts/log"]["TextLog:text"] == [["[fire] stale_imu/imu: imu silent 12 s"]]


def test_position_watch_circle_and_cable_shape(tmp_path):
    opts = RerunOptions(anchor_lat_deg=45.0, anchor_lon_deg=-70.0, watch_circle_m=50.0,
                        bearing_deg=90.0)

    def gnss(sink, k, step):
        if k == 3:
            fix = {"lat_deg": np.array([45.0]), "lon_deg": np.array([-69.9995])}
            sink.on_block(SampleBlock("B1", "gnss", np.array([step.now_ns - 10], dtype=np.int64),
                                      fix))

    data, steps = record(tmp_path, opts, extra=gnss)
    (east, north), = data["position/buoy"]["Points2D:positions"][0]
    # 0.0005 deg of longitude at 45 N on the 6371.0088 km sphere
    assert east == pytest.approx(6_371_008.8 * math.radians(0.0005) * math.cos(math.radians(45)),
                                 rel=1e-6)
    # 111.195 km per degree x 0.0005 deg x cos 45 deg = 39.313 m
    assert east == pytest.approx(39.313, abs=0.001) and north == pytest.approx(0.0, abs=1e-6)
    assert ns(data["position/buoy"]["sensor_time"][0]) == steps[3].now_ns - 10
    circle = np.array(data["position/watch_circle"]["LineStrips2D:strips"][0][0])
    np.testing.assert_allclose(np.hypot(circle[:, 0], circle[:, 1]), 50.0, rtol=1e-6)
    strips = data["mooring/line"]["LineStrips3D:strips"]
    assert len(strips) == N_STEPS  # one shape per second of sensor time
    pts = np.array(strips[-1][0])
    # bearing 90 deg: the line runs east (x), z up, ending at the fairlead 30 m east, 10 m up
    np.testing.assert_allclose(pts[-1], [30.0, 0.0, 10.0], atol=1e-5)
    np.testing.assert_allclose(pts[:, 1], 0.0, atol=1e-5)


def test_local_east_north_against_haversine():
    e, n = local_east_north(np.array([-33.9]), np.array([18.41]), -33.9, 18.4)
    lat = math.radians(-33.9)
    dlon = math.radians(0.01)
    hav = 2 * 6_371_008.8 * math.asin(abs(math.cos(lat) * math.sin(dlon / 2)))
    assert float(e[0]) == pytest.approx(hav, rel=1e-6) and float(n[0]) == 0.0


def test_options_errors_name_the_key():
    def parse(table):
        return parse_struct(RerunOptions, table, "rerun")

    with pytest.raises(ConfigError, match=r"rerun.envelope_s = -1: must be a finite number >= 0"):
        parse({"envelope_s": -1})
    with pytest.raises(ConfigError, match=r"rerun.range_edges_Pa = \[1.0, 1.0\]: must be at least"):
        parse({"range_edges_Pa": [1.0, 1.0]})
    with pytest.raises(ConfigError, match=r"rerun.mean_edges_Pa = \['a', 'b'\]"):
        parse({"mean_edges_Pa": ["a", "b"]})
    with pytest.raises(ConfigError, match=r"rerun.colour = 'red': unknown key"):
        parse({"colour": "red"})
    with pytest.raises(ConfigError, match=r"rerun.anchor_lat_deg = 91.0: must be a finite number "
                       ">= -90 and <= 90"):
        parse({"anchor_lat_deg": 91.0})
    with pytest.raises(ConfigError, match=r"rerun.rrd = 5: must be a string"):
        parse({"rrd": 5})
    with pytest.raises(ConfigError, match=r"rerun.web_port = 70000: must be a port 0-65535"):
        parse({"web_port": 70000})
    with pytest.raises(ConfigError, match=r"rerun.connect"):
        parse({"connect": "http://0.0.0.0:9876"})
    with pytest.raises(ValueError, match="rerun output"):
        open_recording("B1", RerunOptions())
    assert parse({"slow_interval_s": 2}).for_replay().slow_interval_s == 10.0
    assert parse({"range_edges_Pa": [0, 1e6]}).range_edges_Pa == (0.0, 1e6)


def test_rrd_verifies_with_rerun_cli_and_has_blueprint(tmp_path):
    record(tmp_path, RerunOptions())
    out = subprocess.run([sys.executable, "-m", "rerun_cli", "rrd", "stats",
                          str(tmp_path / "run.rrd")],
                         capture_output=True, text=True, timeout=120,
                         env=analytics_disabled_env(tmp_path / "cfg"))
    assert out.returncode == 0, out.stderr
    assert analytics_disabled(tmp_path / "cfg")
    from rerun.chunk import RrdReader

    assert len(RrdReader(tmp_path / "run.rrd").blueprints()) == 1


def test_memory_stays_bounded_in_a_long_live_run(tmp_path):
    # 30 min of 1-s live steps: the sink's buffers are emptied by the flush thresholds
    opts = RerunOptions(flush_samples=300, flush_interval_s=3600.0, snapshot_interval_s=60.0)
    sink = RerunSink(open_recording("B1", opts, rrd=tmp_path / "live.rrd"), opts)
    peaks = []
    for k, step in enumerate(make_steps(1800)):
        sink.on_step(step)
        buffered = sum(len(a) for parts in sink._high.v.values() for a in parts) + sum(
            len(r.t) for r in sink._rows.values())
        if k % 300 == 0:
            peaks.append(0)
        peaks[-1] = max(peaks[-1], buffered)
    sink.close()
    # what is buffered never exceeds what one flush interval brings (3 high-rate series of
    # 300 samples plus ~15 slow rows per step) and does not grow with the run's length
    assert max(peaks) < 4 * 300
    assert max(peaks) <= 1.1 * peaks[0]


def test_entity_parts_are_sanitised():
    assert entity_part("left lay/conductor") == "left_lay_conductor"
    assert entity_part("") == "_" and entity_part("c-1.a_b") == "c-1.a_b"


def test_qartod_flag_totals_are_logged_per_stream_and_test(tmp_path):
    import dataclasses

    steps = [dataclasses.replace(s, qc={"tension": {"spike": {"suspect": k, "fail": 2 * k}}})
             for k, s in enumerate(make_steps(N_STEPS))]
    data, _ = record(tmp_path, RerunOptions(slow_interval_s=5.0), steps)
    picked = [0] + [k for k in range(1, N_STEPS)
                    if steps[k].now_ns // 5_000_000_000 > steps[k - 1].now_ns // 5_000_000_000]
    np.testing.assert_array_equal(scalars(data["health/tension/qc/spike/suspect"]), picked)
    np.testing.assert_array_equal(scalars(data["health/tension/qc/spike/fail"]),
                                  [2 * k for k in picked])


def test_histogram_bars_carry_their_stress_axis_in_mpa(tmp_path):
    data, _ = record(tmp_path, RerunOptions())
    bars = data["rainflow/left/histogram"]
    # static: the default bins, 2 MPa wide to 100 MPa (centres 1, 3, ..., 99), then 10 MPa
    # wide to 300 MPa (centres 105, 115, ..., 295)
    centres = np.array(bars["BarChart:abscissa"][0][0]["buffer"])
    widths = np.array(bars["BarChart:widths"][0])
    np.testing.assert_allclose(centres, np.concatenate((np.arange(1.0, 100.0, 2.0),
                                                        np.arange(105.0, 300.0, 10.0))),
                               rtol=1e-12)
    np.testing.assert_allclose(widths, [2.0] * 50 + [10.0] * 20, rtol=1e-6)


def test_extreme_remaining_lives_are_drawn_at_the_1000_year_cap(tmp_path):
    import dataclasses

    steps = make_steps(3)
    for step, life in zip(steps, (4.1e107, math.inf, 20.0)):
        c = step.components["left"]
        step.components["left"] = dataclasses.replace(c, remaining_life_days=life)
    data, _ = record(tmp_path, RerunOptions(slow_interval_s=0.5), steps=steps)
    # 1000 years = 365,250 days; a finite life below the cap is kept as is
    np.testing.assert_array_equal(scalars(data["remaining_life/left"]), [365250.0, 365250.0, 20.0])
    assert data["remaining_life/left"]["SeriesLines:names"][0] == [
        "left [d] (more than 1,000 years at the cap)"]
