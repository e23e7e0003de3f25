"""Issue 8 wired into the product: ``buoymon replay --rrd/--html``, the report's plot fields, and
the daemon's ``[rerun]`` output."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from monitor.cli import main
from monitor.viz.report_data import load_report
from replay.simulate import SimConfig, simulate
from viz_helpers import ns, read_rrd

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`

HOURS = 0.25


@pytest.fixture(scope="module")
def replayed(tmp_path_factory):
    d = tmp_path_factory.mktemp("vis")
    log = d / "storm.mcap"
    simulate(SimConfig(hours=HOURS, hs_m=1.5, tp_s=5.25, seed=4, load_model="wavfor"), log)
    rc = main(["replay", str(log), "--no-progress", "--rrd", str(d / "r.rrd"),
               "--html", str(d / "r.html"), "--report", str(d / "r.json")])
    assert rc == 0
    return d


def test_report_carries_the_plot_fields(replayed):
    rep = json.loads((replayed / "r.json").read_text())
    c = rep["components"]["conductor"]
    assert rep["design_life_years"] == 20.0
    th = rep["tension_history"]
    assert 450 <= len(th["t_s"]) <= 1000  # bins of 1 s doubled to fit 900 s in <= 1000 points
    assert max(th["max"]) == pytest.approx(rep["tension_N"]["max"])
    assert c["damage_history"]["damage_committed"][-1] == pytest.approx(c["damage_committed"])
    assert sum(c["histogram"]["counts"]) == pytest.approx(c["cycles"])
    # the copper curve x 0.42 (seed 004): 1e4 cycles at 54.6 MPa, endurance 31.6 MPa at 1e7
    sn = c["sn_curve"]
    assert sn["endurance_Pa"] == pytest.approx(31.584e6)
    assert np.interp(4.0, np.log10(sn["cycles"][::-1]),
                     np.log10(sn["ranges_Pa"][::-1])) == pytest.approx(np.log10(54.6e6), abs=0.01)
    assert max(sn["cycles"]) <= 1e12
    # readable by `buoymon report` (non-finite numbers as strings, per docs/REPORT_FORMAT.md)
    r = load_report(replayed / "r.json")
    assert r.components["conductor"].hist_counts is not None and r.tension_history is not None


def test_html_report_and_plots(replayed):
    page = (replayed / "r.html").read_text()
    assert page.count("data:image/png;base64,") == 6
    for plot in ("tension", "damage", "histogram", "sn", "life", "alerts"):
        assert (replayed / f"r_{plot}.png").stat().st_size > 5000


def test_rrd_holds_the_dashboard(replayed):
    data = read_rrd(replayed / "r.rrd")
    rep = json.loads((replayed / "r.json").read_text())
    envelope = np.array(data["tension/load"]["Scalars:scalars"], dtype=float)
    assert envelope.shape[1] == 2  # [min, max] per second
    assert envelope[:, 1].max() == pytest.approx(rep["tension_N"]["max"] / 1e3)  # kN
    assert 0.95 * HOURS * 3600 <= len(envelope) <= HOURS * 3600 + 1
    committed = data["damage/conductor/committed"]["Scalars:scalars"]
    assert committed[-1][0] == pytest.approx(rep["components"]["conductor"]["damage_committed"],
                                             rel=0.05)
    # GNSS blocks reach the position view; the mooring is drawn from the seed 004 line
    pos = np.array(data["position/buoy"]["Points2D:positions"][-1][0])
    assert 25.0 < np.hypot(*pos) < 37.0  # 31 m mean span, GNSS noise 1.5 m, wave orbit
    circle = np.array(data["position/watch_circle"]["LineStrips2D:strips"][0][0])
    assert np.hypot(circle[:, 0], circle[:, 1]).max() == pytest.approx(
        math.sqrt(40.0**2 - 23.0**2), rel=1e-6)
    line = np.array(data["mooring/line"]["LineStrips3D:strips"][-1][0])
    assert line[-1][2] == pytest.approx(23.0, abs=1e-6) and line[0][2] == pytest.approx(0.0)
    assert ns(data["tension/load"]["sensor_time"][0]) == pytest.approx(946684800e9, abs=1e9)
    # every entity's timeline starts at or after the first sample (it began a reorder window
    # early), and the slow rows reach the last one within a slow interval
    first = min(ns(c["sensor_time"][0]) for c in data.values() if c.get("sensor_time"))
    assert first >= rep["time_start_ns"]
    last = max(ns(c["sensor_time"][-1]) for c in data.values() if c.get("sensor_time"))
    assert last <= rep["time_end_ns"]


def _daemon_config(tmp_path: Path, rerun: str) -> Path:
    src = Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml"
    text = (src.read_text() + f'\n[state]\npath = "{tmp_path / "state"}"\n'
            + '[metrics]\nport = 0\n' + rerun)  # any free port: the test builds two daemons
    tmp_path.mkdir(parents=True, exist_ok=True)
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(text)
    return cfg


def test_daemon_rerun_output_only_when_configured(tmp_path, replayed):
    from monitor.cmd_run import ClosingSinks, build_daemon
    from monitor.viz.pipeline_sinks import ViewerSink
    from replay.reader import LogReader

    plain = build_daemon(str(_daemon_config(tmp_path / "a", "")))
    assert not [s for s in plain.pipeline.sinks if isinstance(s, ViewerSink)]
    rrd = tmp_path / "live.rrd"
    d = build_daemon(str(_daemon_config(tmp_path / "b", f'[rerun]\nrrd = "{rrd}"\n')))
    sinks = [s for s in d.pipeline.sinks if isinstance(s, ViewerSink)]
    assert len(sinks) == 1 and sinks[0].sink.opt.slow_interval_s == 1.0  # the live preset
    for block in LogReader([replayed / "storm.mcap"], coalesce=False):
        d.pipeline.process(block)
        if block.t_first_ns > 946684800e9 + 60e9:
            break
    ClosingSinks(sinks).close()  # what the daemon's extension does at shutdown
    data = read_rrd(rrd)
    assert len(data["tension/load"]["Scalars:scalars"]) >= 55
    assert "damage/conductor/committed" in data
