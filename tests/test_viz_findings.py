"""The report's findings in words, human units, and alert episodes (issue 19)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from monitor.viz.alert_view import alert_episodes
from monitor.viz.findings import describe, failure_time_days, findings, findings_text
from monitor.viz.human import (duration_text, number_text, remaining_life_text, stress_text,
                               tension_text)
from monitor.viz.report_data import parse_report
from test_viz_report import T0_S, full_report, minimal_report


@pytest.mark.parametrize("days, text", [
    (40 / 1440, "40 min"),            # 40 minutes
    (7.8 / 24, "7.8 h"),
    (0.2722595920799383, "6.5 h"),    # the demo's as-built conductor: 0.2723 d * 24 = 6.53 h
    (11.233249571881773, "11 days"),
    (40 * 365.25, "about 40 years"),
    (4.1e107, "more than 1,000 years"),
    (math.inf, "unlimited"),
    (math.nan, "n/a"),
])
def test_duration_text(days, text):
    assert duration_text(days) == text


def test_other_human_numbers():
    assert remaining_life_text(0.0) == "none (failed)"
    assert remaining_life_text(math.inf) == "unlimited (no damage accrues)"
    assert number_text(0.6432196707660677) == "0.643"
    assert number_text(15.024363752613503) == "15.0"
    assert number_text(4.4e-5) == "4.40e-05" and number_text(math.inf) == "unlimited"
    assert stress_text(142349218.5452524) == "142 MPa" and stress_text(math.nan) == "n/a"
    assert tension_text(22113.794741813734) == "22.1 kN"


def _report(**components) -> dict:
    r = minimal_report()
    r["design_life_years"] = 20.0
    r["inputs"] = {"files": ["/logs/storm.mcap"], "read": {}}
    r["tension_N"].update(samples_measured=720000, samples_estimated=0,
                          samples_estimate_clamped=0, samples_above_break=0,
                          samples_estimate_above_break=0, breaking_load_N=45000.0)
    r["components"] = components
    return r


def _comp(damage, stress_mpa, life_days, rate, lay="left", derating=1.0):
    return {"damage": damage, "damage_committed": damage * 0.97, "cycles": 1000,
            "max_stress_Pa": stress_mpa * 1e6, "damage_rate_per_day": rate,
            "remaining_life_days": life_days, "kind": "conductor", "lay": lay,
            "derating": derating}


def test_findings_state_the_verdict_and_the_comparison():
    # 10 h replayed (minimal_report's period); hand figures in the comments
    r = parse_report(_report(
        conductor=_comp(0.6432, 142.35, 0.27226, 1.3104),
        conductor_right_lay=_comp(0.04397, 84.76, 11.233, 0.08511, lay="right"),
        conductor_field_derated=_comp(15.024, 142.35, 0.0, 30.94, derating=2.0)))
    f = findings(r)
    assert f.replayed[0] == ("Buoy VAPS-1, log storm.mcap: 2023-11-14 22:13 UTC to "
                             "2023-11-15 08:13 UTC (10 h).")
    assert f.replayed[1] == "Fatigue load from the load cell (720,000 samples)."
    # 9100 N / 45000 N = 20 %
    assert f.replayed[2] == "Tension: mean 5.00 kN, peak 9.10 kN (20% of the 45.0 kN breaking load)."
    assert f.verdicts[0] == (
        "conductor (left-lay conductor): damage 0.643 in 10 h (peak stress 142 MPa); at the "
        "latest rate (1.31 per day) it fails in 6.5 h, short of the 20-year design life.")
    # no damage history: the average rate, 10 h / 15.024 = 0.666 h = 40 min
    assert f.verdicts[2] == (
        "conductor_field_derated (left-lay conductor, S-N strength / 2): FAILED: Miner damage "
        "15.0 (1 = predicted failure), reached 1 after 40 min at the average rate; peak "
        "stress 142 MPa.")
    # 0.6432 / 0.04397 = 14.6 -> "15"; 142.35 / 84.76 = 1.68 -> "1.7"; 15.024 / 0.6432 = 23.4
    assert f.comparisons == [
        "conductor (left-lay conductor) takes 15 times the damage of conductor_right_lay "
        "(right-lay conductor), at 1.7 times its peak stress.",
        "conductor_field_derated (left-lay conductor, S-N strength / 2) takes 23 times the "
        "damage of conductor (left-lay conductor), at the same peak stress."]
    assert f.warnings == []
    assert f.next_steps[0] == ("Treat conductor_field_derated as failed: inspect it "
                               "(continuity, insulation) and plan the replacement.")
    assert "Of the configurations compared, conductor_right_lay (right-lay conductor) takes 15 "\
           "times less damage than conductor (left-lay conductor)." in f.next_steps
    text = findings_text(f)
    assert text.splitlines()[0] == "What was replayed:" and "Comparison:" in text


def test_findings_for_extremes_and_loads_beyond_the_model():
    rep = _report(a=_comp(1e-12, 20.0, 4.1e107, 1e-111),
                  b={**_comp(0.0, 5.0, "inf", 0.0), "lay": None, "kind": "axial"})
    rep["tension_N"].update(max=52000.0, samples_above_break=12, samples_estimated=400,
                            samples_estimate_above_break=3, samples_estimate_clamped=250)
    f = findings(parse_report(rep))
    assert f.verdicts[0].endswith("it fails in more than 1,000 years, beyond the 20-year "
                                  "design life.")
    assert "4.1e+107" not in findings_text(f)
    assert f.verdicts[1] == ("b (axial): no fatigue damage (peak stress 5.00 MPa, no cycle "
                             "that the S-N curve counts).")
    assert f.warnings[0].startswith("12 load samples lie above the 45.0 kN breaking load (3 of "
                                    "them estimates)")
    assert f.warnings[1].startswith("250 estimated load samples came from motion outside")
    assert f.replayed[1] == ("Fatigue load from the load cell (720,000 samples) and the motion "
                             "estimate where it was missing (400 samples).")
    assert f.comparisons == []  # different kinds are not compared


def test_failure_time_from_the_damage_history():
    r = full_report()
    h = r["components"]["conductor_left"]["damage_history"]
    t = np.array(h["t_s"])
    h["damage"] = (2.0 * (t - T0_S) / 36000).tolist()  # reaches 1 at exactly 5 h
    comp = parse_report(r).components["conductor_left"]
    days, from_history = failure_time_days(comp, int(T0_S * 1e9), 10 / 24)
    assert from_history and days * 24 == pytest.approx(5.0, abs=1e-9)
    assert describe(comp) == "conductor_left"  # old reports: no kind / lay


def _alert(rule, comp, event, at_h, severity="warning", starts_h=None):
    at = int((T0_S + at_h * 3600) * 1e9)
    return {"rule": rule, "labels": {"component": comp}, "severity": severity,
            "state": "resolved" if event in ("clear", "reset") else "firing", "event": event,
            "at_ns": at, "starts_at_ns": int((T0_S + (starts_h or at_h) * 3600) * 1e9),
            "ends_at_ns": 0, "summary": f"{rule} {event}"}


def test_alert_episodes_collapse_resends():
    r = minimal_report()
    r["alerts"] = (
        [_alert("stress", "c", "fire", 1.0)]
        + [_alert("stress", "c", "resend", 1.0 + k) for k in (1, 2, 3)]
        + [_alert("stress", "c", "resend", 4.5, severity="critical"),
           _alert("stress", "c", "clear", 5.0),
           _alert("stress", "c", "fire", 6.0),
           # an episode whose fire was dropped from the report (only the newest kept)
           _alert("damage", "c", "resend", 2.0, starts_h=0.5),
           _alert("damage", "c", "reset", 9.0)])
    eps = alert_episodes(parse_report(r).alerts)
    assert [(e.rule, e.resends, e.severity, e.cleared_by) for e in eps] == [
        ("damage", 1, "warning", "reset"), ("stress", 4, "critical", "clear"),
        ("stress", 0, "warning", "")]
    h = 3600 * 10**9
    t0 = int(T0_S * 1e9)
    assert eps[0].first_fired_ns == t0 + h // 2
    assert (eps[1].first_fired_ns, eps[1].last_resent_ns, eps[1].cleared_ns) == (
        t0 + h, t0 + int(4.5 * h), t0 + 5 * h)
    assert eps[2].cleared_ns == 0 and eps[2].last_resent_ns == 0


def test_terminal_summary_leads_with_the_findings_and_collapses_alerts():
    from replay.report import summary_text

    rep = _report(conductor=_comp(0.6432, 142.35, 0.27226, 1.3104),
                  conductor_right_lay=_comp(0.04397, 84.76, 11.233, 0.08511, lay="right"))
    rep["alerts"] = ([_alert("stress", "conductor", "fire", 1.0)]
                     + [_alert("stress", "conductor", "resend", 1.0 + k) for k in (1, 2, 3)]
                     + [_alert("stress", "conductor", "clear", 5.0)])
    rep["alerts_dropped"] = 0
    text = summary_text(rep)
    lines = text.splitlines()
    assert lines[0] == "What was replayed:"
    assert text.index("Comparison:") < text.index("Details:")
    # 9100 N -> 9.10 kN in the details as in the findings; life in words
    assert "tension  min 2.10 kN, mean 5.00 kN, max 9.10 kN, p99 8.20 kN" in text
    assert any(l.split()[:1] == ["conductor"] and l.endswith("  6.5 h") for l in lines)
    assert "  alerts: 5 transition(s) in 1 episode(s), re-sends collapsed" in lines
    assert ("    warning  stress / conductor: fired 2023-11-14T23:13:20.000Z, re-sent 3x, "
            "cleared 2023-11-15T03:13:20.000Z") in lines


def test_damage_that_stopped_accruing_projects_no_end_of_life():
    r = parse_report(_report(c=_comp(0.2, 60.0, "inf", 0.0)))
    assert findings(r).verdicts == [
        "c (left-lay conductor): damage 0.200 in 10 h (peak stress 60.0 MPa); none accrued at "
        "the end of the replay, so no end of life is projected."]


def test_status_screen_shows_remaining_life_in_words():
    from monitor.cmd_status import render

    text = render("daemon", {"buoy_id": "vaps", "components": {
        "conductor": {"damage": 0.6432, "remaining_life_days": 0.2722595920799383},
        "right": {"damage": 1e-12, "remaining_life_days": 4.1e107},
        "spent": {"damage": 15.0, "remaining_life_days": 0.0}}})
    # the last column is BEYOND YIELD ("-": not reported here)
    rows = {line.split()[0]: line.rstrip(" -") for line in text.splitlines()
            if line.startswith("  ")}
    assert rows["conductor"].endswith("  6.5 h")
    assert rows["right"].endswith("  more than 1,000 years") and "e+107" not in text
    assert rows["spent"].endswith("  none (failed)")


def test_status_screen_says_when_fatigue_was_never_fed():
    """A daemon that has had no load sample since its start: not "fatigue fed 9.3 s ago"."""
    from monitor.cmd_status import render

    doc = {"buoy_id": "vaps", "load_t_ns": None, "fatigue_feed_age_s": 9.3}
    assert "fatigue not fed yet (9.3 s since the start)" in render("daemon", doc)
    doc["load_t_ns"] = 946684800 * 10**9
    assert "fatigue fed 9.3 s ago" in render("daemon", doc)
