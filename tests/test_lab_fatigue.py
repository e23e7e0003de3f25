"""Seed 004's lab fatigue test (App. 2) as validation; the lab-calibrated S-N curve (issue 20)."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from models.helix import HelixCable, conductor_stress
from models.fatigue.lab_calibration import LAB_FAILURES, LAB_RATE_HZ, calibrate, cam_tension, vaps_lab_calibration
from models.fatigue.sn_curve import SNCurve

REF = json.loads((Path(__file__).parent / "reference" / "issue20_lab_validation.json").read_text())


def _shared() -> Path:
    for parent in Path(__file__).resolve().parents[1:4]:
        if (parent / "shared" / "reference").is_dir():
            return parent / "shared"
    pytest.skip("shared/ reference data not found beside the repository")


def test_lab_failures_are_the_seed_table():
    rows = json.loads((_shared() / "reference" / "seed004_vaps_cable.json").read_text())["lab_fatigue_test_0_to_F"]
    assert LAB_RATE_HZ * 60 == rows["rate_cycles_per_min"]
    assert list(LAB_FAILURES) == [(r["load_kN"] * 1e3, r["cycles"]) for r in rows["rows"] if r["failed"]]


def test_cam_tension_is_simple_harmonic_0_to_F():
    t, x = cam_tension(8900.0, 3, 8)
    assert t.shape == (25,) and x[0] == 0.0 and x[-1] == pytest.approx(0.0, abs=1e-9)
    assert x[4] == pytest.approx(8900.0) and x.max() == pytest.approx(8900.0)
    assert t[8] == pytest.approx(60 / 13.6)  # one cycle: 4.41 s
    with pytest.raises(ValueError):
        cam_tension(-1.0, 3, 8)
    with pytest.raises(ValueError):
        cam_tension(1.0, 3, 2)


def test_shipped_curve_prediction_by_hand():
    # the 0 -> 8.9 kN cycle's range is the left-lay stress at 8.9 kN (57.28 MPa, free twist); above
    # the table's top point (54.6 MPa at 1e4) the first segment extends with
    # m = log(25000/10000) / log(54.6/44.5) = 4.470 (Marks x 0.42 at 2.5e4 and 1e4 cycles)
    s = conductor_stress(8900.0, HelixCable.vaps_biw(), "left") / 1e6
    m = math.log10(2.5) / math.log10(0.42 * 130 / (0.42 * 106))
    n = 1e4 * (0.42 * 130 / s) ** m
    assert n == pytest.approx(REF["shipped_vaps_copper"]["predicted_cycles"][0], rel=5e-3)
    cal = vaps_lab_calibration()
    assert cal.predicted_cycles[0] == pytest.approx(n, rel=1e-9)


def test_calibration_fit_by_hand():
    cal = vaps_lab_calibration()
    res = np.log10(cal.observed_cycles) - np.log10(cal.predicted_cycles)
    assert cal.delta == pytest.approx(res.mean(), rel=1e-12)
    assert cal.residual_std == pytest.approx(math.sqrt(((res - res.mean()) ** 2).sum() / 2), rel=1e-12)
    assert cal.std_error == pytest.approx(cal.residual_std / math.sqrt(3), rel=1e-12)
    want = REF["vaps_lab_calibrated"]
    assert cal.life_factor == pytest.approx(want["life_factor"], abs=0.005)
    assert cal.delta == pytest.approx(want["log10_life_shift"], abs=0.0005)
    assert cal.std_error == pytest.approx(want["log10_life_shift_std_error"], abs=0.0005)
    assert cal.residual_std == pytest.approx(want["log10_residual_std"], abs=0.0005)
    curve = SNCurve.vaps_lab_calibrated()
    assert curve.cycles_to_failure(cal.stress_ranges_Pa) == pytest.approx(
        np.array(want["predicted_cycles"]), rel=5e-3)
    # same shape: the calibrated life is the reference life x 10**delta at every stress
    s = np.array([20.0, 31.6, 40.0, 57.0, 80.0]) * 1e6
    np.testing.assert_allclose(curve.cycles_to_failure(s) / SNCurve.vaps_copper().cycles_to_failure(s),
                               cal.life_factor, rtol=1e-12)
    # the log-mean of the calibrated predictions equals the log-mean of the observations
    assert np.log10(curve.cycles_to_failure(cal.stress_ranges_Pa)).mean() == pytest.approx(
        np.log10(cal.observed_cycles).mean(), rel=1e-12)
    design = cal.design_curve()
    np.testing.assert_allclose(design.cycles_to_failure(s) / curve.cycles_to_failure(s),
                               10 ** (-2 * cal.residual_std), rtol=1e-12)


def test_calibrate_bad_input():
    ref = SNCurve.vaps_copper()
    with pytest.raises(ValueError):
        calibrate(ref, [50e6], [1e4])
    with pytest.raises(ValueError):
        calibrate(ref, [50e6, -1.0], [1e4, 2e4])
    with pytest.raises(ValueError, match="cut-off"):
        calibrate(SNCurve.vaps_copper(low_stress="cutoff"), [10e6, 50e6], [1e4, 2e4])
