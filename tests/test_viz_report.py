"""The HTML fatigue report: parsing, plots, PNG files, the CLI, and a headless-Chromium render."""

from __future__ import annotations

import base64
import json
import math
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from monitor.cli import main as buoymon
from monitor.viz.html_report import write_report
from monitor.viz.report_data import parse_report
from monitor.viz.report_plots import SEVERITY_COLOURS

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
    assert "20.4" not in page  # remaining life is shown in years: 20.4 d = 0.05585 y
    assert "0.05585" in page and "&infin;" in page
    assert "tension back below 8.5 kN" in page


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
                   "#1f77b4",  # damage history line / histogram (matplotlib C0)
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
    assert "&infin;" in html.read_text() and "html report" in capsys.readouterr().out
    data["tension_N"] = {k: None for k in ("min", "mean", "max", "p99")}
    assert all(math.isnan(v) for v in parse_report(data).tension.values())
