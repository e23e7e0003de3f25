"""DNV-RP-C203 knee conventions (issue 20): the RP's printed log a2 against continuity at the
knee's cycle count (qats, fatpack)."""

import numpy as np
import pytest

from models.fatigue.sn_curve import SNCurve

MPA = 1e6


def test_default_is_the_printed_table():
    d = SNCurve.dnv_rp_c203("D")
    assert d.log_a == (12.164, 15.606)
    assert d == SNCurve.dnv_rp_c203("D", "air", "intersection")
    # knee where the printed lines cross: 10**((15.606 - 12.164) / 2) = 52.60 MPa
    assert d.knees_MPa[0] == pytest.approx(10 ** 1.721, rel=1e-12)


@pytest.mark.parametrize("detail", ["B1", "C", "D", "W3"])
@pytest.mark.parametrize("environment,knee", [("air", 1e7), ("seawater_cp", 1e6)])
def test_cycles_convention_matches_qats_and_fatpack(detail, environment, knee):
    qats_sn = pytest.importorskip("qats.fatigue.sn")
    fatpack = pytest.importorskip("fatpack")
    curve = SNCurve.dnv_rp_c203(detail, environment, "cycles")
    m1, m2 = curve.m
    # the knee falls on the knee cycle count exactly
    assert curve.cycles_to_failure(curve.knees_MPa[0] * MPA) == pytest.approx(knee, rel=1e-12)
    rng = np.random.default_rng(11)
    ranges = rng.uniform(5.0, 300.0, 300)
    counts = rng.integers(1, 1000, 300).astype(float)
    ours = curve.damage_per_cycle(ranges * MPA, counts=counts).sum()
    q = qats_sn.minersum(ranges, counts, {"m1": m1, "m2": m2, "loga1": curve.log_a[0], "nswitch": knee})
    fp = fatpack.BiLinearEnduranceCurve(1.0)
    fp.Nc, fp.m1, fp.m2, fp.Nd = 10 ** curve.log_a[0], m1, m2, knee
    assert ours == pytest.approx(q, rel=1e-12)
    assert ours == pytest.approx(fp.find_miner_sum(np.column_stack((ranges, counts))), rel=1e-12)


def test_difference_below_the_knee_is_0_15_percent():
    # D in air: log a2 = 7 + 5 (12.164 - 7) / 3 = 15.60667 against the printed 15.606
    printed, continuous = SNCurve.dnv_rp_c203("D"), SNCurve.dnv_rp_c203("D", "air", "cycles")
    assert continuous.log_a[1] == pytest.approx(15.606667, abs=1e-6)
    ratio = continuous.cycles_to_failure(30 * MPA) / printed.cycles_to_failure(30 * MPA)
    assert ratio == pytest.approx(10 ** (15.606667 - 15.606), rel=1e-6)
    assert (ratio - 1) * 100 == pytest.approx(0.15, abs=0.01)
    # above the knee both use the same printed log a1
    assert continuous.cycles_to_failure(100 * MPA) == printed.cycles_to_failure(100 * MPA)


def test_bad_convention():
    with pytest.raises(ValueError, match="knee"):
        SNCurve.dnv_rp_c203("D", "air", "continuous")
