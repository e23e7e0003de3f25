"""Issue 20 in the product: twist and termination keys, yield counting and alerts, and the lab
fatigue test fed through the pipeline as a synthetic load-cell log."""

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from models.helix import HelixCable, conductor_stress
from models.termination import TerminationBend, termination_stress
from monitor.cmd_status import render
from monitor.components import Component, build_cable, build_sn_curve
from monitor.config import ConfigError, config_with, default_config
from replay.lab_validation import lab_tension_blocks, lab_validation, predict
from replay.report import build_report, summary_text
from replay.runner import run_blocks

LAB = json.loads((Path(__file__).parent / "reference" / "issue20_lab_validation.json").read_text())


def _with_cable(**cable):
    c = default_config()
    return config_with(c, cable={**c.raw["cable"], **cable})


def _comp(config, name):
    return next(c for c in config.components if c.name == name)


def _bent(radius_m=0.6, angle_deg=30.0):
    """The shipped configuration with a locked termination bend configured."""
    c = default_config()
    return config_with(c, component=[
        {**t, "bend_radius_m": radius_m, "bend_angle_deg": angle_deg}
        if t["name"] == "conductor_termination" else t for t in c.raw["component"]])


def test_twist_keys():
    cable = build_cable(_with_cable(twist="limited", twist_limit_deg=75.0, twist_length_m=40.0))
    assert cable.twist_restraint == "limited"
    assert cable.twist_limit_rad == pytest.approx(math.radians(75.0), rel=1e-15)
    assert cable.twist_length_m == 40.0
    assert build_cable(_with_cable(twist="restrained")).twist_restraint == "restrained"
    assert build_cable(default_config()) == HelixCable.vaps_biw()  # shipped: free, as before
    assert build_cable(_with_cable(core_torsional_stiffness_Nm2=5.0)).core_torsional_stiffness_Nm2 == 5.0
    for bad, msg in (({"twist": "locked"}, "must be one of"),
                     ({"twist": "limited", "twist_length_m": 40.0}, "twist_limit_deg is missing"),
                     ({"twist": "limited", "twist_limit_deg": 75.0}, "twist_length_m is missing"),
                     ({"twist": "limited", "twist_limit_deg": -1.0, "twist_length_m": 40.0}, ">= 0"),
                     ({"twist_limit_deg": 75.0}, 'only with twist = "limited"'),
                     ({"twist": "restrained", "twist_length_m": 40.0}, 'only with twist = "limited"')):
        with pytest.raises(ConfigError, match=msg):
            _with_cable(**bad)


def test_location_keys():
    c = default_config()
    base = c.raw["component"][0]
    for bad, msg in (({"location": "sheave"}, "must be one of"),
                     ({"bend_radius_m": 0.6}, 'only with location = "termination"'),
                     ({"location": "termination", "bend_angle_deg": 10.0}, "bend_radius_m is missing"),
                     ({"location": "termination", "bend_radius_m": 0.6}, "bend_angle_deg is missing"),
                     ({"location": "termination", "bend_radius_m": 0.0, "bend_angle_deg": 10.0}, "> 0"),
                     ({"location": "termination", "bend_radius_m": 0.6, "bend_angle_deg": 200.0}, "<= 180"),
                     ({"location": "termination", "bend_radius_m": 0.6, "bend_angle_deg": 10.0,
                       "bend_gauge_length_m": -1.0}, "> 0"),
                     ({"kind": "axial", "lay": None, "area_m2": 1e-4, "location": "termination"},
                      "must be one of")):
        comp = {k: v for k, v in {**base, **bad}.items() if v is not None}
        with pytest.raises(ConfigError, match=msg):
            config_with(c, component=[comp])


def test_termination_component_stress_and_yield_count():
    t = np.array([0.0, 4450.0, 8900.0, 11000.0])
    shipped = default_config()
    cable = build_cable(shipped)
    # shipped: the bend not configured, so no bend strain: the free span's stress and yield
    plain = Component(_comp(shipped, "conductor_termination"), cable, shipped.fatigue)
    np.testing.assert_array_equal(plain.stress(t), conductor_stress(t, cable, "left"))
    assert plain.samples_beyond_yield == 1  # 11 kN only (70.8 MPa, below)
    config = _bent()
    term = Component(_comp(config, "conductor_termination"), cable, config.fatigue)
    free = Component(_comp(config, "conductor"), cable, config.fatigue)
    bend = TerminationBend(0.6, math.radians(30.0))
    np.testing.assert_array_equal(term.stress(t), termination_stress(t, cable, "left", bend))
    # the locked bend alone: 19.5 GPa x 9.2 mm / 0.6 m = 299 MPa > 68.9 MPa yield: all four
    assert term.samples_beyond_yield == 4
    assert term.figures()["samples_beyond_yield"] == 4.0
    # free span: 57.3 MPa at 8.9 kN is elastic; 11 kN gives 70.8 MPa > 68.9 MPa
    s = free.stress(t)
    np.testing.assert_array_equal(s, conductor_stress(t, cable, "left"))
    assert s[3] / 1e6 == pytest.approx(70.8, abs=0.05) and free.samples_beyond_yield == 1
    free.stress(t, record=False)  # samples seen before are not counted twice
    assert free.samples_beyond_yield == 1
    # the hot spot is scf x stress: scf 1.25 moves the nominal limit to 55.1 MPa (8.9 kN counts)
    hot = Component(dataclasses.replace(_comp(config, "conductor"), scf=1.25), cable, config.fatigue)
    hot.stress(t)
    assert hot.yield_stress_Pa == pytest.approx(68.9e6 / 1.25) and hot.samples_beyond_yield == 2
    # the count survives a save/restore
    again = Component(_comp(config, "conductor"), cable, config.fatigue, state=free.state())
    assert again.samples_beyond_yield == 1


def _storm_blocks(config, peak_N):
    return lab_tension_blocks(config.buoy.id, peak_N, 30)


def test_yield_in_report_status_and_alerts():
    config = _bent()
    pipeline, _ = run_blocks(config, _storm_blocks(config, 11000.0))
    rep = pipeline.report()
    comps = rep["components"]
    # 30 cam cycles at 10 Hz: the free span passes 68.9 MPa above 10.71 kN, the termination always
    n = 30 * 44 + 1
    assert comps["conductor_termination"]["samples_beyond_yield"] == n
    assert 0 < comps["conductor"]["samples_beyond_yield"] < n
    assert pipeline.status()["components"]["conductor"]["samples_beyond_yield"] == comps["conductor"][
        "samples_beyond_yield"]
    fired = [a for a in rep["alerts"] if a["rule"] == "conductor_yield" and a["event"] == "fire"]
    assert {a["labels"]["component"] for a in fired} == {"conductor", "conductor_termination"}
    assert all("elastic model beyond yield: damage underestimated" in a["summary"] for a in fired)
    text = summary_text(build_report(config, rep, [], None))
    assert "conductor: " in text and "beyond the conductor's yield" in text
    screen = render("daemon", pipeline.status())  # `buoymon status`
    assert "BEYOND YIELD" in screen and f"{n}" in screen
    assert "elastic model beyond yield: damage underestimated (conductor, conductor_termination)" in screen
    # below yield on the free span: counted nowhere, no alert for it
    p2, _ = run_blocks(config, _storm_blocks(config, 8900.0))
    rep2 = p2.report()
    assert rep2["components"]["conductor"]["samples_beyond_yield"] == 0
    assert not [a for a in rep2["alerts"] if a["rule"] == "conductor_yield" and a["labels"]["component"] == "conductor"]


@pytest.mark.integration  # processes: simulate, check-config, replay
def test_calm_sea_raises_no_yield_alert_unless_a_tight_bend_is_configured(tmp_path):
    """A flat calm (Hs 0.3 m, Tp 4 s: the line at 0.37 to 0.50 kN, 3 MPa in the free span)
    replayed with the shipped configuration raises no conductor_yield alert and counts no
    sample beyond yield (an assumed locked bend of 0.6 m did, at every sample: 19.5 GPa x
    9.2 mm / 0.6 m = 299 MPa at rest). With a tight bend configured (0.3 m, locked: 598 MPa
    at rest) every sample is beyond the 68.9 MPa yield and the alert fires."""
    def cli(*args):
        p = subprocess.run([sys.executable, "-m", "monitor.cli", *args], capture_output=True,
                           text=True, timeout=300, cwd=tmp_path)
        assert p.returncode == 0, p.stderr
        return p.stdout

    log = tmp_path / "calm.mcap"
    cli("simulate", "-o", str(log), "--hours", "0.05", "--hs", "0.3", "--tp", "4", "--seed", "2")
    shipped = Path(__file__).resolve().parents[1] / "monitor" / "vaps_seed004.toml"
    tight = tmp_path / "tight.toml"
    text = shipped.read_text()
    assert text.count('location = "termination"\n') == 1
    tight.write_text(text.replace('location = "termination"\n', 'location = "termination"\n'
                                  'bend_radius_m = 0.3\nbend_angle_deg = 45.0\n'))
    assert "termination bend not configured" in cli("check-config", str(shipped))
    assert "termination bend not configured" not in cli("check-config", str(tight))
    results = {}
    for name, cfg in (("shipped", shipped), ("tight", tight)):
        report = tmp_path / f"{name}.json"
        cli("replay", str(log), "--config", str(cfg), "--report", str(report), "--no-progress")
        results[name] = json.loads(report.read_text())
    n = results["shipped"]["samples"]["tension"]["accepted"]
    assert n == 3600 and results["shipped"]["tension_N"]["max"] < 600.0
    for name, rep in results.items():
        fired = {a["labels"]["component"] for a in rep["alerts"]
                 if a["rule"] == "conductor_yield" and a["event"] == "fire"}
        term = rep["components"]["conductor_termination"]
        if name == "shipped":
            assert fired == set() and term["samples_beyond_yield"] == 0
            assert term["max_stress_Pa"] < 5e6
            assert not [a for a in rep["alerts"] if a["rule"] == "conductor_stress"]
        else:
            assert fired == {"conductor_termination"} and term["samples_beyond_yield"] == n
            assert term["max_stress_Pa"] > 19.5e9 * 9.2e-3 / 0.3
        assert rep["components"]["conductor"]["samples_beyond_yield"] == 0


def test_lab_test_through_the_pipeline():
    """Predicted against observed cycles to failure (App. 2): the shipped curve predicts 8,070
    cycles at 8.9 kN where the cable lasted 25,000; the lab-calibrated curve 30,150."""
    config = default_config()
    rows = lab_validation(config, n_cycles=100)
    assert [(r.load_N, r.observed_cycles) for r in rows] == [
        (kN * 1e3, n) for kN, n in zip(LAB["load_kN"], LAB["observed_cycles"])]
    shipped = [r.predicted_cycles["conductor"] for r in rows]
    np.testing.assert_allclose(shipped, LAB["shipped_vaps_copper"]["predicted_cycles"], rtol=2e-3)
    # the termination sees the same tension ranges (its bend is static): the same life within 1 %
    np.testing.assert_allclose([r.predicted_cycles["conductor_termination"] for r in rows], shipped, rtol=1e-2)
    calibrated = config_with(config, component=[{**config.raw["component"][0], "sn_curve": "vaps_lab_calibrated"}])
    got = predict(calibrated, 8.9e3, n_cycles=100)["conductor"]
    assert got == pytest.approx(LAB["vaps_lab_calibrated"]["predicted_cycles"][0], rel=2e-3)


def test_dnv_knee_convention_from_the_configuration():
    c = default_config()
    comp = {**c.raw["component"][0], "kind": "axial", "area_m2": 1e-4}
    del comp["lay"]
    for preset, log_a2 in (("dnv_rp_c203:D:air", 15.606), ("dnv_rp_c203:D:air:intersection", 15.606),
                           ("dnv_rp_c203:D:air:cycles", 7 + 5 * (12.164 - 7) / 3)):
        cfg = config_with(c, component=[{**comp, "sn_curve": preset}])
        assert build_sn_curve(cfg.components[0]).log_a[1] == pytest.approx(log_a2, abs=1e-12)
    cfg = config_with(c, component=[{**comp, "sn_curve": "dnv_rp_c203:D:air:continuous"}])
    with pytest.raises(ConfigError, match="knee must be"):
        build_sn_curve(cfg.components[0])


def test_cli_lab_test(tmp_path, capsys):
    from monitor.cli import main

    assert main(["lab-test", "--cycles", "50", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert [r["observed_cycles"] for r in rows] == LAB["observed_cycles"]
    np.testing.assert_allclose([r["predicted_cycles"]["conductor"] for r in rows],
                               LAB["shipped_vaps_copper"]["predicted_cycles"], rtol=2e-3)
    assert main(["lab-test", "--cycles", "50"]) == 0
    text = capsys.readouterr().out
    assert "25,000" in text and "(x0.32)" in text and "(vaps_copper)" in text
    assert main(["lab-test", "--cycles", "1"]) == 2
    bad = tmp_path / "bad.toml"
    bad.write_text("[buoy]\n")
    assert main(["lab-test", "--config", str(bad)]) == 2
    assert "config error" in capsys.readouterr().err
