"""The report-history sink: bounded, exactly aggregated tension/damage/cycle histories."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from monitor.viz.html_report import write_report
from monitor.viz.report_data import parse_report
from monitor.viz.report_history import ReportHistory, sn_curve_field
from tests.viz_helpers import T0_NS, make_steps


def test_bins_double_and_aggregate_exactly(tmp_path):
    steps = make_steps(2500)
    hist = ReportHistory(max_points=1000, bin_s=1.0)
    for s in steps:
        hist.on_step(s)
    f = hist.fields()
    th = f["tension_history"]
    # 2500 one-second bins > 1000 -> 2 s (1250) > 1000 -> 4 s bins: 625 of them
    assert len(th["t_s"]) == 625
    t = np.concatenate([s.t_ns for s in steps])
    v = np.concatenate([s.tension_N for s in steps])
    b = t // 4_000_000_000
    for k in (0, 1, 311, 624):
        sel = v[b == b[0] + k]
        assert th["t_s"][k] == pytest.approx((b[0] + k) * 4.0)
        assert th["min"][k] == sel.min() and th["max"][k] == sel.max()
        assert th["mean"][k] == pytest.approx(sel.mean(), rel=1e-12)
    dh = f["components"]["left"]["damage_history"]
    assert len(dh["t_s"]) == 625
    # the last step inside each 4 s bin
    last = {}
    for s in steps:
        last[s.now_ns // 4_000_000_000] = s
    want = [last[k] for k in sorted(last)]
    np.testing.assert_array_equal(dh["damage_committed"],
                                  [s.components["left"].damage_committed for s in want])
    np.testing.assert_allclose(dh["t_s"], [s.now_ns / 1e9 for s in want], rtol=1e-15)
    h = f["components"]["right"]["histogram"]
    r = np.concatenate([s.components["right"].ranges_Pa for s in steps])
    c = np.concatenate([s.components["right"].counts for s in steps])
    edges = np.array(h["edges_Pa"])
    want_h, _ = np.histogram(np.minimum(r, edges[-1] - 1), bins=edges, weights=c)
    np.testing.assert_array_equal(h["counts"], want_h)


def test_fields_render_in_the_report(tmp_path):
    hist = ReportHistory()
    steps = make_steps(120)
    for s in steps:
        hist.on_step(s)
    f = hist.fields()
    report = {
        "buoy_id": "B1", "time_start": T0_NS, "time_end": steps[-1].now_ns,
        "samples": {"tension": {"accepted": 2400, "rejected": {}}},
        "tension_N": {"min": 3000.0, "mean": 5000.0, "max": 7000.0, "p99": 6500.0},
        "components": {n: {"damage": 1e-4, "damage_committed": 1e-4, "cycles": 180.0,
                           "max_stress_Pa": 1.4e7, "damage_rate_per_day": 0.07,
                           "remaining_life_days": 1e4, **f["components"][n]}
                       for n in ("left", "right")},
        "alerts": [],
        "tension_history": f["tension_history"],
    }
    out = write_report(parse_report(report), tmp_path / "h.html")
    assert sorted(out.png_paths) == ["alerts", "damage", "histogram", "life", "tension"]


def test_bad_arguments():
    with pytest.raises(ValueError, match="max_points"):
        ReportHistory(max_points=1)
    with pytest.raises(ValueError, match="range_edges_Pa"):
        ReportHistory(range_edges_Pa=(1.0,))


def test_sn_curve_field_from_the_fatigue_model():
    from models.fatigue.sn_curve import SNCurve

    curve = SNCurve.vaps_copper()
    f = sn_curve_field(curve, 80e6)
    r = np.array(f["ranges_Pa"])
    n = np.array([float(c) for c in f["cycles"]])
    assert len(r) == 60 and r[0] == pytest.approx(80e3) and r[-1] == pytest.approx(240e6)
    finite = np.isfinite(n)
    assert finite.sum() > 10 and np.all(np.diff(n[finite]) < 0)  # fewer cycles at higher range
    # a Basquin curve by hand: N = 10^log_a / S_MPa^m, S including the derating
    b = SNCurve.basquin(m=4.0, log_a=12.0, derating=0.5)
    g = sn_curve_field(b, 100e6, n=3)
    s_mpa = np.array(g["ranges_Pa"]) * 0.5 / 1e6
    np.testing.assert_allclose(g["cycles"], 1e12 / s_mpa**4, rtol=1e-12)
    assert "endurance_Pa" not in g
    with pytest.raises(ValueError, match="max_range_Pa"):
        sn_curve_field(b, 0.0)


def test_sea_state_histogram_span_and_damage_times():
    from monitor.blocks import SampleBlock

    hist = ReportHistory()
    t = T0_NS + np.arange(4, dtype=np.int64) * 1_800_000_000_000
    # raw wave reports: one NaN and one negative height are not physical and are left out
    hist.on_block(SampleBlock("B1", "waves", t, {"hs_m": np.array([1.4, np.nan, 1.6, -1.0]),
                                                "tp_s": np.array([5.0, 5.2, 5.6, 5.1])}))
    hist.on_block(SampleBlock("B1", "tension", t[:1], {"tension_N": np.array([900.0])}))
    steps = make_steps(3)
    # a step before any load (the replay's horizon lags the data): no damage point for it
    hist.on_step(dataclasses.replace(steps[0], now_ns=T0_NS - 10**12, t_ns=steps[0].t_ns[:0],
                                     tension_N=steps[0].tension_N[:0]))
    for s in steps:
        hist.on_step(dataclasses.replace(s, now_ns=s.now_ns - 3 * 10**9))  # horizon lags
    f = hist.fields()
    assert f["sea_state"] == {"reports": 2, "hs_m": {"min": 1.4, "mean": 1.5, "max": 1.6},
                              "tp_s": {"min": 5.0, "mean": 5.3, "max": 5.6}}
    dh = f["components"]["left"]["damage_history"]
    # timed at each step's newest load sample, not at the lagging horizon
    assert dh["t_s"] == [int(s.t_ns[-1]) / 1e9 for s in steps]
    h = f["components"]["left"]["histogram"]
    r = np.concatenate([s.components["left"].ranges_Pa for s in steps])
    assert h["max_range_Pa"] == r.max()
    # 2 MPa bins up to the one holding the largest range, none beyond
    assert h["edges_Pa"][-2] <= r.max() < h["edges_Pa"][-1]
    assert len(h["counts"]) == int(r.max() // 2e6) + 1 and h["counts"][-1] > 0
    assert sum(h["counts"]) == sum(float(s.components["left"].counts.sum()) for s in steps)
