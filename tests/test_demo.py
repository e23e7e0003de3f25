"""``buoymon demo``: the seed 004 storm shows the as-built left lay taking more damage."""

import json

import pytest

from monitor.cli import main
from replay.cmd_demo import AS_BUILT, OPPOSITE, TERMINATION, comparison, demo_config

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`


def test_demo_config_has_both_lays_of_the_same_cable():
    c = demo_config()
    comps = {x.name: x for x in c.components}
    assert (comps[AS_BUILT].lay, comps[OPPOSITE].lay) == ("left", "right")
    assert comps[AS_BUILT].sn_curve == comps[OPPOSITE].sn_curve
    assert c.cable.preset == "vaps_biw" and c.mooring.depth_m == 23.0


def test_comparison_text():
    def comp(d, peak):
        return {"damage": d, "damage_committed": d * 0.9, "max_stress_Pa": peak}

    report = {"time_start_ns": 0, "time_end_ns": int(10 * 3.6e12),
              "components": {AS_BUILT: comp(0.5, 60e6), OPPOSITE: comp(0.01, 36e6)}}
    text = comparison(report)
    assert "after 10.0 h" in text and "50 times the damage" in text
    assert "after about 20 h of such a storm" in text
    report["components"][OPPOSITE] = comp(0.0, 30e6)
    assert "no damage at all" in comparison(report)


def test_demo_end_to_end(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--hours", "1"]) == 0
    out = capsys.readouterr().out
    report = json.loads((tmp_path / "report.json").read_text())
    left, right = report["components"][AS_BUILT], report["components"][OPPOSITE]
    assert left["damage"] > right["damage"]
    assert left["max_stress_Pa"] > 1.5 * right["max_stress_Pa"]
    assert report["samples"]["tension"]["accepted"] >= 3600 * 20 * 0.99
    assert "left lay (as built)" in out and f"Outputs in {tmp_path}/" in out
    # the termination (issue 20): the same tension ranges, the locked bend beyond yield throughout
    term = report["components"][TERMINATION]
    assert term["location"] == "termination" and left["location"] == "free_span"
    assert term["samples_beyond_yield"] == report["samples"]["tension"]["accepted"]
    assert term["max_stress_Pa"] > 299e6 and "left, termination" in out
    assert "elastic model beyond yield, damage underestimated" in out
    assert "report.json" in out and "storm_1980.mcap" in out
