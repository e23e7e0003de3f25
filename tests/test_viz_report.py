"""The HTML fatigue report: parsing, plots, PNG files, the CLI, and a headless-Chromium render."""

from __future__ import annotations

import base64
import json
import math
import re
import subprocess
from pathlib import Path

import matplotlib.dates as mdates
import numpy as np
import pytest
from matplotlib.image import imread

from monitor.cli import main as buoymon
from monitor.viz.html_report import write_report
from monitor.viz.report_data import parse_report
from monitor.viz.report_plots import PLOTS, SEVERITY_COLOURS, STYLES

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`

CHROMIUM = Path("/usr/bin/chromium")
T0_S = 1_700_000_000.0
DAY_S = 86400.0


def minimal_report() -> dict:
    """Only the required fields of the contract (issue 2)."""
    return {
        "buoy_id": "VAPS-1",
        "time_start": "2023-11-14T22:13:20Z",
        "time_end": "2023-11-15T08:13:20Z",
        "samples": {"tension": {"accepted": 720000, "rejected": {"spike": 12, "nan": 3}},
                    "imu": {"accepted": 360000, "rejected": {}}},
        "tension_N": {"min": 2100.0, "mean": 5000.0, "max": 9100.0, "p99": 8200.0},
        "components": {
            "conductor_left": {"damage": 0.021, "damage_committed": 0.02, "cycles": 6850.5,
                               "max_stress_Pa": 61e6, "damage_rate_per_day": 0.048,
                               "remaining_life_days": 20.4},
            "conductor_right": {"damage": 0.0011, "damage_committed": 0.001, "cycles": 6850.5,
                                "max_stress_Pa": 30e6, "damage_rate_per_day": 0.0024,
                                "remaining_life_days": "inf"},
        },
        "alerts": [
            {"rule": "damage_warning", "labels": {"buoy": "VAPS-1", "component": "conductor_left",
                                                  "rule": "damage_warning"},
             "severity": "warning", "state": "firing", "event": "fire",
             "starts_at_ns": int((T0_S + 3 * 3600) * 1e9), "ends_at_ns": 0,
             "at_ns": int((T0_S + 3 * 3600) * 1e9), "summary": "damage 0.01 >= 0.01"},
            {"rule": "tension_high", "labels": {"buoy": "VAPS-1", "component": "cable",
                                                "rule": "tension_high"},
             "severity": "critical", "state": "firing", "event": "fire",
             "starts_at_ns": int((T0_S + 5 * 3600) * 1e9), "ends_at_ns": 0,
             "at_ns": int((T0_S + 5 * 3600) * 1e9), "summary": "tension 9.1 kN > 9 kN"},
            {"rule": "tension_high", "labels": {"buoy": "VAPS-1", "component": "cable",
                                                "rule": "tension_high"},
             "severity": "critical", "state": "resolved", "event": "clear",
             "starts_at_ns": int((T0_S + 5 * 3600) * 1e9),
             "ends_at_ns": int((T0_S + 7 * 3600) * 1e9),
             "at_ns": int((T0_S + 7 * 3600) * 1e9), "summary": "tension back below 8.5 kN"},
        ],
    }


def full_report() -> dict:
    r = minimal_report()
    r["design_life_years"] = 2.0
    t = T0_S + np.arange(0, 10 * 3600, 60.0)
    swell = 5000 + 1500 * np.sin(2 * np.pi * (t - T0_S) / (10 * 3600))
    r["tension_history"] = {"t_s": t.tolist(), "min": (swell - 2000).tolist(),
                            "mean": swell.tolist(), "max": (swell + 2500).tolist()}
    edges = np.linspace(0, 80e6, 41)
    ranges = np.logspace(6, 9, 30)
    for name, k in (("conductor_left", 1.0), ("conductor_right", 0.5)):
        c = r["components"][name]
        c["damage_history"] = {"t_s": t.tolist(),
                               "damage_committed": (0.02 * k * (t - T0_S) / 36000).tolist(),
                               "damage": (0.021 * k * (t - T0_S) / 36000).tolist()}
        c["histogram"] = {"edges_Pa": edges.tolist(),
                          "counts": (3000 * np.exp(-edges[:-1] / (10e6 * k))).round(1).tolist()}
        c["sn_curve"] = {"ranges_Pa": ranges.tolist(),
                         "cycles": (2e6 * (50e6 * k / ranges) ** 5).tolist(),
                         "endurance_Pa": 12e6 * k}
    return r


def test_parse_checks_required_fields_and_numbers():
    r = parse_report(minimal_report())
    assert r.time_start_ns == 1_700_000_000 * 10**9
    assert r.components["conductor_right"].remaining_life_days == float("inf")
    assert r.samples["tension"] == (720000, {"spike": 12, "nan": 3})
    assert r.tension_history is None and r.components["conductor_left"].hist_counts is None
    bad = minimal_report()
    del bad["tension_N"]
    with pytest.raises(ValueError, match="'tension_N' is missing"):
        parse_report(bad)
    bad = minimal_report()
    bad["components"]["conductor_left"]["damage"] = "lots"
    with pytest.raises(ValueError, match=r"components.conductor_left.damage = 'lots'"):
        parse_report(bad)
    bad = full_report()
    bad["components"]["conductor_left"]["histogram"]["counts"].pop()
    with pytest.raises(ValueError, match=r"histogram.counts: expected 40 values, got 39"):
        parse_report(bad)
    bad = minimal_report()
    bad["time_end"] = "yesterday"
    with pytest.raises(ValueError, match="time_end"):
        parse_report(bad)


def nonwhite_fraction(png: Path) -> float:
    img = imread(png)[..., :3]
    return float(np.mean(np.any(img < 0.95, axis=-1)))


def has_colour(img: np.ndarray, hex_colour: str, tol: int = 4, min_pixels: int = 30) -> bool:
    rgb = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)])
    px = (img[..., :3] * 255 if img.dtype != np.uint8 else img[..., :3]).astype(int)
    return int(np.all(np.abs(px - rgb) <= tol, axis=-1).sum()) >= min_pixels


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """The full report rendered once for the tests that only read it."""
    return write_report(parse_report(full_report()), tmp_path_factory.mktemp("r") / "report.html")


def test_full_report_writes_all_plots(rendered):
    out = rendered
    assert sorted(out.png_paths) == ["alerts", "damage", "histogram", "life", "sn", "tension"]
    page = out.html_path.read_text()
    assert "<script" not in page and not re.search(r"src=['\"]https?:", page)
    uris = re.findall(r"src='data:image/png;base64,([^']+)'", page)
    assert len(uris) == 6
    for key, png in out.png_paths.items():
        assert png.name == f"report_{key}.png"
        assert base64.b64decode(uris[list(out.png_paths).index(key)]) == png.read_bytes()
        assert 0.03 < nonwhite_fraction(png) < 0.9, key
    # the plots carry the data: the tension band colour, both alert severities, the life bars
    assert has_colour(imread(out.png_paths["tension"]), "#9ecae1")
    alerts = imread(out.png_paths["alerts"])
    assert has_colour(alerts, SEVERITY_COLOURS["warning"])
    assert has_colour(alerts, SEVERITY_COLOURS["critical"])
    assert has_colour(imread(out.png_paths["life"]), "#2b8cbe")
    # remaining life in words: 20.4 d -> "20 days"; "inf" -> unlimited
    assert "20.4" not in page and "<td>20 days</td>" in page
    assert "<td>unlimited (no damage accrues)</td>" in page
    # only the reasons that rejected something; counts with thousands separators
    assert ("<td>tension</td><td>720,000</td><td>15</td><td>nan: 3, spike: 12</td>" in page
            and "<td>imu</td><td>360,000</td><td>0</td><td>-</td>" in page)
    # the alert table: one row per episode (fired 5 h after T0, cleared at 7 h)
    assert ("<td>tension_high</td><td>cable</td><td>2023-11-15 03:13:20 UTC</td><td>-</td>"
            "<td>0</td><td>2023-11-15 05:13:20 UTC</td><td>tension 9.1 kN &gt; 9 kN</td>") in page


def test_minimal_report_degrades_gracefully(tmp_path):
    out = write_report(parse_report(minimal_report()), tmp_path / "r.html")
    assert sorted(out.png_paths) == ["alerts", "damage", "life", "tension"]
    page = out.html_path.read_text()
    assert "Not shown: the report has no components[...].histogram" in page
    assert "Not shown: the report has no components[...].sn_curve" in page
    for png in out.png_paths.values():
        assert nonwhite_fraction(png) > 0.03


def test_cli_report(tmp_path, capsys):
    src = tmp_path / "R.json"
    src.write_text(json.dumps(minimal_report()))
    assert buoymon(["report", str(src), "-o", str(tmp_path / "out" / "report.html")]) == 0
    assert (tmp_path / "out" / "report.html").exists()
    assert (tmp_path / "out" / "report_life.png").exists()
    assert "report.html" in capsys.readouterr().out
    (tmp_path / "bad.json").write_text("{not json")
    assert buoymon(["report", str(tmp_path / "bad.json")]) == 2
    assert "not valid JSON" in capsys.readouterr().err


@pytest.mark.skipif(not CHROMIUM.exists(),
                    reason="/usr/bin/chromium is absent (apt-get install -y chromium)")
def test_report_renders_in_headless_chromium(rendered, tmp_path):
    out = rendered
    shot = tmp_path / "shot.png"
    cmd = [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
           "--no-first-run", "--disable-background-networking", "--disable-component-update",
           "--disable-sync", f"--user-data-dir={tmp_path / 'profile'}", "--hide-scrollbars",
           # Chromium still tries Google hosts (updates, accounts) despite the flags above;
           # resolve no host at all so nothing leaves the machine (the page is a local file)
           "--host-resolver-rules=MAP * ~NOTFOUND",
           "--force-color-profile=srgb", "--window-size=1200,4200", f"--screenshot={shot}",
           out.html_path.as_uri()]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert run.returncode == 0 and shot.exists(), run.stderr[-2000:]
    img = imread(shot)
    assert img.shape[0] == 4200 and img.shape[1] == 1200
    # every plot made it onto the page as pixels: colours only the plots contain
    for colour in ("#9ecae1",  # tension min-max band
                   STYLES[0][0],  # the first component's damage line / histogram
                   SEVERITY_COLOURS["warning"], SEVERITY_COLOURS["critical"],  # alert lanes
                   "#2b8cbe"):  # remaining-life bars
        assert has_colour(img, colour), colour
    # and the page is not blank: a good share of it is drawn
    assert np.mean(np.any(img[..., :3] < 0.95, axis=-1)) > 0.05


def test_empty_and_non_finite_values_render(tmp_path):
    r = minimal_report()
    r["components"] = {"c": {"damage": 0.0, "damage_committed": 0.0, "cycles": 0,
                             "max_stress_Pa": "nan", "damage_rate_per_day": 0.0,
                             "remaining_life_days": "inf"}}
    r["tension_N"] = {"min": "nan", "mean": "nan", "max": "nan", "p99": "nan"}
    r["alerts"] = []
    out = write_report(parse_report(r), tmp_path / "e.html")
    page = out.html_path.read_text()
    assert "No alerts were raised." in page and "n/a" in page
    assert sorted(out.png_paths) == ["alerts", "damage", "life", "tension"]
    r["components"] = {}
    out = write_report(parse_report(r), tmp_path / "e2.html")
    assert sorted(out.png_paths) == ["alerts", "tension"]
    assert "Not shown: no fatigue components in the report" in out.html_path.read_text()


def test_replay_html_with_a_component_that_accrues_nothing(tmp_path, capsys):
    """The report writer leaves remaining_life_days null when nothing accrues (and tension
    figures null without samples): replay --html renders it instead of failing."""
    from monitor.blocks import SampleBlock
    from replay.writer import LogWriter

    log = tmp_path / "still.mcap"
    t0 = 1_700_000_000 * 10**9
    with LogWriter(log) as w:
        for k in range(30):  # a constant tension: no stress cycle at all
            t = t0 + k * 10**9 + np.arange(20, dtype=np.int64) * (10**9 // 20)
            w.write_block(SampleBlock("vaps", "tension", t, {"tension_N": np.full(20, 900.0)}),
                          recv_ns=t0 + (k + 1) * 10**9)
    report, html = tmp_path / "r.json", tmp_path / "r.html"
    assert buoymon(["replay", str(log), "--report", str(report), "--html", str(html),
                    "--no-progress"]) == 0
    data = json.loads(report.read_text())
    assert data["components"]["conductor"]["remaining_life_days"] is None
    parsed = parse_report(data)
    assert parsed.components["conductor"].remaining_life_days == math.inf
    assert "unlimited (no damage accrues)" in html.read_text()
    assert "html report" in capsys.readouterr().out
    data["tension_N"] = {k: None for k in ("min", "mean", "max", "p99")}
    assert all(math.isnan(v) for v in parse_report(data).tension.values())


def storm_report() -> dict:
    """The demo's three conductors (damage 0.64, 0.044, 15 over 10 h): two share the S-N
    curve and two the cycle histogram; histories start with the data, at T0."""
    r = full_report()
    t = np.array(r["tension_history"]["t_s"])
    growth = np.sqrt((t - T0_S + 60) / 36000)  # damage grows like the demo's, fastest first
    comps = {}
    for name, final, peak, lay, derating in (
            ("conductor", 0.6432, 142.35e6, "left", 1.0),
            ("conductor_right_lay", 0.04397, 84.76e6, "right", 1.0),
            ("conductor_field_derated", 15.024, 142.35e6, "left", 2.0)):
        ranges = np.logspace(np.log10(peak / 1000), np.log10(3 * peak), 40)
        comps[name] = {
            "damage": final, "damage_committed": 0.97 * final, "cycles": 113500,
            "max_stress_Pa": peak, "damage_rate_per_day": final * 2.4,
            "remaining_life_days": max(0.0, (1 - final) / (final * 2.4)),
            "kind": "conductor", "lay": lay, "derating": derating,
            "damage_history": {"t_s": t.tolist(), "damage_committed": (0.97 * final * growth).tolist(),
                               "damage": (final * growth).tolist()},
            # a Basquin curve N = 2e6 (50 MPa / (S * derating))^5 sampled over each span
            "sn_curve": {"ranges_Pa": ranges.tolist(),
                         "cycles": (2e6 * (50e6 / (ranges * derating)) ** 5).tolist(),
                         "endurance_Pa": 12e6 / derating},
            "histogram": {"edges_Pa": list(np.arange(0, peak + 2e6, 2e6)),
                          "counts": [1.0] * len(np.arange(0, peak, 2e6)),
                          "max_range_Pa": peak - 1e6},
        }
    r["components"] = comps
    return r


def _axes(fig):
    return fig.axes[0]


def test_plots_are_readable():
    r = parse_report(storm_report())
    start = np.datetime64(r.time_start_ns, "ns")

    ax = _axes(PLOTS["damage"](r))
    assert ax.get_yscale() == "log"
    lines = {ln.get_label(): ln for ln in ax.get_lines() if ln.get_gid()}
    assert set(lines) == set(r.components)
    lo, hi = ax.get_ylim()
    x0, x1 = ax.get_xlim()
    assert x0 == pytest.approx(mdates.date2num(start))  # the axis starts at the first sample
    for name, ln in lines.items():
        x, y = ln.get_xdata(), ln.get_ydata()
        assert mdates.date2num(x[0]) >= x0
        # the whole curve inside the axes: 0.044 and 15 are both visible
        assert lo < y.min() and y.max() < hi, name
    paths = [tuple(ln.get_ydata()) for ln in lines.values()]
    styles = {(ln.get_color(), str(ln.get_linestyle())) for ln in lines.values()}
    assert len(set(paths)) == 3 and len(styles) == 3
    assert ax.get_legend().get_bbox_to_anchor().x0 >= ax.get_window_extent().x1 - 1

    ax = _axes(PLOTS["tension"](r))
    assert ax.get_xlim()[0] == pytest.approx(mdates.date2num(start))

    ax = _axes(PLOTS["histogram"](r))
    assert ax.get_xlim()[1] >= 142.35  # the histogram covers the peak (MPa)
    labels = [t.get_label() for t in ax.patches]
    assert "conductor, conductor_field_derated" in labels  # identical: one curve, both named
    assert "conductor_right_lay" in labels

    ax = _axes(PLOTS["sn"](r))
    curves = [ln.get_label() for ln in ax.get_lines() if ln.get_label().startswith("S-N")]
    # the same curve sampled over two spans is drawn once; the derated one apart
    assert curves == ["S-N curve: conductor, conductor_right_lay",
                      "S-N curve: conductor_field_derated"]
    notes = sorted(t.get_text() for t in ax.texts)
    assert notes == ["endurance 12 MPa (conductor, conductor_right_lay)",
                     "endurance 6 MPa (conductor_field_derated)"]


def test_every_curve_shows_in_the_embedded_pixels(tmp_path):
    """The PNGs (byte-identical to the page's data URIs) hold each curve's own colour."""
    out = write_report(parse_report(storm_report()), tmp_path / "storm.html")
    damage = imread(out.png_paths["damage"])
    for colour, _ in STYLES[:3]:  # 0.044, 0.64 and 15 all drawn on the log axis
        assert has_colour(damage, colour), colour
    hist = imread(out.png_paths["histogram"])
    assert has_colour(hist, STYLES[0][0]) and has_colour(hist, STYLES[1][0])
    sn = imread(out.png_paths["sn"])
    assert has_colour(sn, STYLES[0][0]) and has_colour(sn, STYLES[2][0])


def _dump_dom(page: Path, tmp_path: Path) -> str:
    cmd = [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={tmp_path / 'profile'}", "--host-resolver-rules=MAP * ~NOTFOUND",
           "--dump-dom", page.as_uri()]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr[-2000:]
    return run.stdout


@pytest.mark.skipif(not CHROMIUM.exists(),
                    reason="/usr/bin/chromium is absent (apt-get install -y chromium)")
def test_findings_lead_the_page_in_chromium(tmp_path):
    out = write_report(parse_report(storm_report()), tmp_path / "storm.html")
    dom = _dump_dom(out.html_path, tmp_path)
    text = re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", dom))
    # the findings come first, before the details and the plots
    assert dom.index("id=\"findings\"") < dom.index("<h2>Details</h2>") < dom.index("plot-tension")
    # the plots' axes as the page states them under each plot (read from the figures):
    # time axes from the first sample (T0 = 2023-11-14 22:13:20 UTC) to the last (+10 h)
    span = "2023-11-14 22:13:20 UTC to 2023-11-15 08:13:20 UTC"
    for key in ("tension", "damage", "alerts"):
        assert re.search(rf"id=\"caption-{key}\"[^>]*>x: sensor time \(UTC\), {span}\.",
                         dom), key
    damage = re.search(r'id="caption-damage"[^>]*>([^<]*)<', dom).group(1)
    y0, y1 = map(float, re.search(r"y: Miner damage incl. open cycles, (\S+) to (\S+) \(log "
                                  r"scale\)", damage).groups())
    # damage histories run 15.024 sqrt((t + 60 s) / 36000 s) ... down to the right lay's
    # 0.04397 sqrt(60 / 36000) = 0.00180 at the first point (t = T0): all inside the axis
    assert y0 < 0.04397 * math.sqrt(60 / 36000) and y1 > 15.024
    assert damage.endswith("shown: conductor; conductor_right_lay; conductor_field_derated; "
                           "failure (damage 1).")
    for sentence in (
            "conductor (left-lay conductor) takes 15 times the damage of conductor_right_lay "
            "(right-lay conductor), at 1.7 times its peak stress.",
            # 0.6432 in 10 h: rate 1.54 per day, life (1 - 0.6432) / 1.544 d = 5.5 h
            "conductor (left-lay conductor): damage 0.643 in 10 h (peak stress 142 MPa); at the "
            "latest rate (1.54 per day) it fails in 5.5 h, short of the 2-year design life.",
            # history every 60 s of 15.024 sqrt((t + 60 s) / 36000 s): 0.8675 at 60 s,
            # 1.0624 at 120 s; linear between them 1 at 60 + 60 * 0.1325 / 0.1949 = 100.8 s
            "FAILED: Miner damage 15.0 (1 = predicted failure), reached 1 after 1.7 min"):
        assert sentence in text, sentence
