"""The findings on measured data (../shared/realdata, read in place): the Maine endline load
cell replayed with an as-built (left-lay) and a right-lay conductor and a breaking load below
its peak; every figure in the sentences is checked against a hand computation."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.dates as mdates
import numpy as np
import pytest
import rainflow

from models import fatigue, helix
from monitor.cli import main
from monitor.viz.human import ratio_text, stress_text, tension_text
from monitor.viz.report_data import load_report
from monitor.viz.report_plots import PLOTS
from replay.reader import iter_blocks

SHARED = next(
    (p / "shared" for p in Path(__file__).resolve().parents if (p / "shared/realdata").is_dir()),
    None,
)
pytestmark = pytest.mark.skipif(SHARED is None, reason="../shared/realdata absent")
LBF = 4.4482216152605  # N
BREAK_N = 5000.0


def _hand_damage(tension: np.ndarray, lay: str) -> tuple[float, float]:
    """Miner damage incl. half cycles and the peak stress of a conductor, by hand."""
    stress = helix.conductor_stress(tension, helix.HelixCable.vaps_biw(), lay=lay)
    cyc = np.array([(r, m, c) for r, m, c, _, _ in rainflow.extract_cycles(stress)])
    per_cycle = fatigue.SNCurve.vaps_copper().damage_per_cycle(cyc[:, 0], cyc[:, 1], cyc[:, 2])
    return float(per_cycle.sum()), float(stress.max())


@pytest.fixture(scope="module")
def replayed(tmp_path_factory):
    d = tmp_path_factory.mktemp("maine")
    raw = np.genfromtxt(SHARED / "realdata/maine_endline_loadcell/"
                        "17348481-2018.11.30-09.58.27-15.csv", delimiter=",", usecols=(1, 2))
    seconds, tension = raw[:, 0], raw[:, 1] * LBF
    (d / "in.csv").write_text("time_s,tension_N\n" + "\n".join(
        f"{s!r},{v!r}" for s, v in zip(seconds.tolist(), tension.tolist())) + "\n")
    text = (Path(__file__).resolve().parents[1] / "monitor/vaps_seed004.toml").read_text()
    assert "breaking_load_N = 45000.0" in text
    # the QC fail limits default to fractions of the breaking load: keep the shipped ones
    # (45 kN), so lowering the breaking load rejects nothing
    for old, new in (("breaking_load_N = 45000.0", f"breaking_load_N = {BREAK_N}"),
                     ("# max_rate_per_s = 45000.0", "max_rate_per_s = 45000.0"),
                     ("# spike_fail = 11250.0", "spike_fail = 11250.0")):
        assert old in text
        text = text.replace(old, new)
    text += ('\n[[component]]\nname = "right"\nkind = "conductor"\nlay = "right"\n'
             'sn_curve = "vaps_copper"\n')
    (d / "c.toml").write_text(text)
    assert main(["import", str(d / "in.csv"), "-o", str(d / "in.mcap"), "--buoy-id", "vaps"]) == 0
    assert main(["replay", str(d / "in.mcap"), "--config", str(d / "c.toml"), "--no-progress",
                 "--report", str(d / "r.json"), "--html", str(d / "r.html")]) == 0
    # the hand computation takes the samples as logged: `buoymon import` stores each within
    # half its quantum (0.1 N for tension, docs/LOG_FORMAT.md)
    logged = np.concatenate([b.fields["tension_N"] for b in iter_blocks([str(d / "in.mcap")])])
    assert np.max(np.abs(logged - tension)) <= 0.05 + 1e-9
    return d, logged


def test_findings_on_the_measured_load_cell(replayed, capsys):
    d, tension = replayed
    rep = json.loads((d / "r.json").read_text())
    assert rep["samples"]["tension"]["accepted"] == len(tension)  # nothing rejected
    left, left_peak = _hand_damage(tension, "left")
    right, right_peak = _hand_damage(tension, "right")
    assert rep["components"]["conductor"]["damage"] == pytest.approx(left, rel=1e-12)
    assert rep["components"]["right"]["damage"] == pytest.approx(right, rel=1e-12)
    above = int(np.count_nonzero(tension > BREAK_N))
    assert rep["tension_N"]["samples_above_break"] == above > 0
    assert main(["report", str(d / "r.json"), "-o", str(d / "again.html")]) == 0
    capsys.readouterr()
    page = (d / "again.html").read_text()
    for sentence in (
            "Fatigue load from the load cell (17,228 samples).",
            f"Tension: mean {tension_text(tension.mean())}, peak {tension_text(tension.max())} "
            f"({tension.max() / BREAK_N:.0%} of the 5.00 kN breaking load).",
            f"conductor (left-lay conductor) takes {ratio_text(left / right)} times the damage of "
            f"right (right-lay conductor), at {ratio_text(left_peak / right_peak)} times its "
            "peak stress.",
            f"{above:,d} load samples lie above the 5.00 kN breaking load",
            f"(peak stress {stress_text(left_peak)})"):
        assert sentence in page, sentence
    assert "Sea state" not in page  # the log has no wave reports


def test_plots_of_the_measured_replay_start_at_the_data(replayed):
    d, _ = replayed
    r = load_report(d / "r.json")
    start = mdates.date2num(np.datetime64(r.time_start_ns, "ns"))
    for key in ("tension", "damage"):
        ax = PLOTS[key](r).axes[0]
        assert ax.get_xlim()[0] == pytest.approx(start), key
        for line in ax.get_lines():
            x = line.get_xdata()
            if len(x) > 2:  # the data curves (not the horizontal reference lines)
                assert mdates.date2num(x[0]) >= start, (key, line.get_label())
    # the damage history never precedes the first sample (it did by the reorder window)
    for c in r.components.values():
        assert c.damage_history.t_s[0] * 1e9 >= r.time_start_ns
        assert c.hist_max_range_Pa <= c.hist_edges_Pa[-1]
