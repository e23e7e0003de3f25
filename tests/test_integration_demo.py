"""``buoymon demo``: WAVFOR loads, three conductor lines, and the visual outputs it points to."""

import json

import pytest

from monitor.cli import main
from replay.cmd_demo import AS_BUILT, FIELD, OPPOSITE
from viz_helpers import read_rrd

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`


def test_demo_writes_and_names_its_outputs(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--hours", "0.5"]) == 0
    out = capsys.readouterr().out
    assert "cable load from the seed's WAVFOR wave-force model, an upper bound" in out
    assert "wavfor load model" in out
    report = json.loads((tmp_path / "report.json").read_text())
    comps = report["components"]
    left, right, field = comps[AS_BUILT], comps[OPPOSITE], comps[FIELD]
    # the seed: left lay about 1.7 times the stress of right lay; derating 2 on a steep curve
    assert 1.6 < left["max_stress_Pa"] / right["max_stress_Pa"] < 1.8
    assert left["damage_committed"] > 5 * right["damage_committed"] > 0
    assert field["damage_committed"] > 10 * left["damage_committed"]
    assert "left lay (as built)" in out and "right lay" in out and "left, field /2" in out
    rrd, html = tmp_path / "vaps.rrd", tmp_path / "report.html"
    assert f"`buoymon view {rrd}`" in out and f"{html}    the fatigue report as a page" in out
    assert "open it in a browser" in out
    assert sorted(p.name for p in tmp_path.glob("report_*.png")) == [
        f"report_{k}.png" for k in ("alerts", "damage", "histogram", "life", "sn", "tension")]
    data = read_rrd(rrd)
    assert {f"damage/{c}/committed" for c in comps} <= set(data)
