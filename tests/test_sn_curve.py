"""S-N curves: seed 004 copper table, DNV-RP-C203 (2016) against qats and fatpack, factors."""

import json

import numpy as np
import pytest

from models.fatigue import SNCurve

MPA = 1e6


def test_vaps_copper_reproduces_marks_times_042():
    curve = SNCurve.vaps_copper()
    cycles = np.array([1e7, 1e6, 1e5, 2.5e4, 1e4])
    expected = 0.42 * np.array([75.2, 78.0, 90.0, 106.0, 130.0])
    np.testing.assert_allclose(curve.stress_range_at(cycles) / MPA, expected, rtol=1e-12)
    np.testing.assert_allclose(curve.cycles_to_failure(expected * MPA), cycles, rtol=1e-10)
    np.testing.assert_allclose(np.round(expected, 1), [31.6, 32.8, 37.8, 44.5, 54.6])
    # log-log interpolation half-way between 1e6 and 1e5 cycles (in log N and log S)
    mid_s = np.sqrt(expected[1] * expected[2]) * MPA
    np.testing.assert_allclose(curve.cycles_to_failure(mid_s), np.sqrt(1e6 * 1e5), rtol=1e-10)
    # above the table: the 1e4-2.5e4 segment continues
    m_top = np.log10(2.5e4 / 1e4) / np.log10(expected[4] / expected[3])
    np.testing.assert_allclose(curve.cycles_to_failure(2 * expected[4] * MPA), 1e4 * 2.0 ** -m_top, rtol=1e-10)


def test_low_stress_treatments():
    s_end = 0.42 * 75.2  # MPa, endurance at 1e7
    m_last = 1.0 / np.log10(78.0 / 75.2)  # slope of the 1e6-1e7 segment
    below = np.array([0.9 * s_end, 0.8 * s_end]) * MPA
    cut = SNCurve.vaps_copper(low_stress="cutoff")
    assert np.all(np.isinf(cut.cycles_to_failure(below)))
    assert np.all(cut.damage_per_cycle(below) == 0.0)
    miner = SNCurve.vaps_copper(low_stress="miner")
    np.testing.assert_allclose(miner.cycles_to_failure(below), 1e7 * np.array([0.9, 0.8]) ** -m_last, rtol=1e-9)
    haibach = SNCurve.vaps_copper(low_stress="haibach")
    np.testing.assert_allclose(haibach.cycles_to_failure(below),
                               1e7 * np.array([0.9, 0.8]) ** -(2 * m_last - 1), rtol=1e-9)
    # all three agree on and above the endurance stress
    at = np.array([s_end, 40.0]) * MPA
    for c in (miner, haibach):
        np.testing.assert_allclose(c.cycles_to_failure(at), cut.cycles_to_failure(at), rtol=1e-12)
    # the inverse stays consistent through the Haibach tail
    np.testing.assert_allclose(haibach.stress_range_at(haibach.cycles_to_failure(below)), below, rtol=1e-10)
    assert cut.stress_range_at(1e9) == pytest.approx(s_end * MPA, rel=1e-12)


def test_dnv_c_air_and_seawater_hand_values():
    air = SNCurve.dnv_rp_c203("C", "air")
    # knee where 12.592 - 3 log S = 16.320 - 5 log S: log S = 1.864, N = 1e7
    assert air.knees_MPa[0] == pytest.approx(10 ** 1.864, rel=1e-12)
    assert air.cycles_to_failure(10 ** 1.864 * MPA) == pytest.approx(1e7, rel=1e-9)
    assert air.cycles_to_failure(100 * MPA) == pytest.approx(10 ** 12.592 / 100 ** 3, rel=1e-12)
    assert air.cycles_to_failure(40 * MPA) == pytest.approx(10 ** 16.320 / 40 ** 5, rel=1e-12)
    sea = SNCurve.dnv_rp_c203("C", "seawater_cp")
    assert sea.cycles_to_failure(10 ** 2.064 * MPA) == pytest.approx(1e6, rel=1e-9)
    assert sea.cycles_to_failure(200 * MPA) == pytest.approx(10 ** 12.192 / 200 ** 3, rel=1e-12)
    assert sea.cycles_to_failure(40 * MPA) == pytest.approx(air.cycles_to_failure(40 * MPA), rel=1e-12)
    b1 = SNCurve.dnv_rp_c203("B1")
    assert b1.cycles_to_failure(200 * MPA) == pytest.approx(10 ** 15.117 / 200 ** 4, rel=1e-12)


def test_hand_computed_miner_sum_across_the_knee():
    # D curve in air: 2000 cycles at 120 MPa (m = 3 side) + 3e6 at 30 MPa (m = 5 side)
    curve = SNCurve.dnv_rp_c203("D")
    n1 = 10 ** 12.164 / 120.0 ** 3  # 8.44221e5 cycles
    n2 = 10 ** 15.606 / 30.0 ** 5  # 1.66109e8 cycles
    assert n1 == pytest.approx(8.44221e5, rel=1e-5) and n2 == pytest.approx(1.66109e8, rel=1e-5)
    d = curve.damage_per_cycle(np.array([120.0, 30.0]) * MPA, counts=np.array([2000.0, 3e6]))
    assert d.sum() == pytest.approx(2000 / n1 + 3e6 / n2, rel=1e-12)
    assert d.sum() == pytest.approx(0.0204295, rel=1e-5)


@pytest.mark.parametrize("detail", ["B1", "C", "D"])
@pytest.mark.parametrize("environment,knee", [("air", 1e7), ("seawater_cp", 1e6)])
def test_miner_sum_matches_qats_and_fatpack(detail, environment, knee):
    qats_sn = pytest.importorskip("qats.fatigue.sn")
    fatpack = pytest.importorskip("fatpack")
    rng = np.random.default_rng(7)
    ranges = rng.uniform(5.0, 300.0, 400)  # MPa, both sides of the knee
    counts = rng.integers(1, 1000, 400).astype(float)
    preset = SNCurve.dnv_rp_c203(detail, environment)
    m1, m2 = preset.m
    log_a1 = preset.log_a[0]
    # the peers define the lower segment by continuity at the knee cycle count
    log_a2 = m2 / m1 * log_a1 + (1 - m2 / m1) * np.log10(knee)
    ours = SNCurve.multi_slope((m1, m2), (log_a1, log_a2)).damage_per_cycle(ranges * MPA, counts=counts).sum()
    q = qats_sn.minersum(ranges, counts, {"m1": m1, "m2": m2, "loga1": log_a1, "nswitch": knee})
    fp = fatpack.BiLinearEnduranceCurve(1.0)
    fp.Nc, fp.m1, fp.m2, fp.Nd = 10 ** log_a1, m1, m2, knee
    f = fp.find_miner_sum(np.column_stack((ranges, counts)))
    assert ours == pytest.approx(q, rel=1e-12)
    assert ours == pytest.approx(f, rel=1e-12)
    # the preset uses the RP's printed log a2; the difference is the table's rounding
    assert preset.damage_per_cycle(ranges * MPA, counts=counts).sum() == pytest.approx(q, rel=5e-3)


def test_chain_curve():
    chain = SNCurve.dnv_chain_studless()
    assert chain.cycles_to_failure(50 * MPA) == pytest.approx(6.0e10 / 50 ** 3, rel=1e-12)


def test_factors():
    base = SNCurve.dnv_chain_studless()
    s = np.array([20.0, 60.0]) * MPA
    d0 = base.damage_per_cycle(s)
    np.testing.assert_allclose(base.with_factors(scf=1.5).damage_per_cycle(s), d0 * 1.5 ** 3, rtol=1e-12)
    np.testing.assert_allclose(base.with_factors(derating=2.0).damage_per_cycle(s), d0 * 8.0, rtol=1e-12)
    np.testing.assert_allclose(base.with_factors(dff=3.0).damage_per_cycle(s), d0 * 3.0, rtol=1e-12)
    np.testing.assert_allclose(base.with_factors(dff=3.0).cycles_to_failure(s), base.cycles_to_failure(s))
    assert base.with_factors(scf=2.0).stress_range_at(1e6) == pytest.approx(base.stress_range_at(1e6) / 2)


def test_mean_stress_corrections():
    su = 220.6 * MPA
    s = np.array([20.0 * MPA])
    none = SNCurve.basquin(3.0, 12.0)
    half = np.array([su / 2])
    goodman = none.with_factors(mean_correction="goodman", ultimate_Pa=su)
    gerber = none.with_factors(mean_correction="gerber", ultimate_Pa=su)
    np.testing.assert_allclose(goodman.effective_range_MPa(s, half), [40.0], rtol=1e-12)
    np.testing.assert_allclose(gerber.effective_range_MPa(s, half), [20.0 / 0.75], rtol=1e-12)
    # no credit for a compressive mean; failure at or above the ultimate strength
    np.testing.assert_allclose(goodman.effective_range_MPa(s, -half), [20.0], rtol=1e-12)
    assert np.isinf(goodman.damage_per_cycle(s, np.array([su])))
    # SWT on a 0-to-max cycle (mean = range/2): S_ar = sqrt(S_max S_a) = S / sqrt(2)
    swt = none.with_factors(mean_correction="swt")
    np.testing.assert_allclose(swt.effective_range_MPa(s, s / 2), [2 * 20.0 / np.sqrt(2)], rtol=1e-12)
    # Walker with gamma = 1 ignores the mean; gamma = 0.5 equals SWT
    walker1 = none.with_factors(mean_correction="walker", walker_gamma=1.0)
    np.testing.assert_allclose(walker1.effective_range_MPa(s, s), [20.0], rtol=1e-12)
    walker = none.with_factors(mean_correction="walker", walker_gamma=0.5)
    np.testing.assert_allclose(walker.effective_range_MPa(s, s / 2), swt.effective_range_MPa(s, s / 2))
    # fully reversed cycles are unchanged by SWT; entirely compressive ones do no damage
    np.testing.assert_allclose(swt.effective_range_MPa(s, np.zeros(1)), [20.0], rtol=1e-12)
    assert swt.damage_per_cycle(s, -s)[0] == 0.0
    with pytest.raises(ValueError, match="mean"):
        swt.damage_per_cycle(s)


def test_json_round_trip():
    for curve in (SNCurve.vaps_copper(), SNCurve.dnv_rp_c203("C2", "seawater_cp", scf=1.2, dff=3.0)):
        again = SNCurve.from_dict(json.loads(json.dumps(curve.to_dict())))
        assert again == curve


def test_bad_input():
    curve = SNCurve.dnv_rp_c203("D")
    with pytest.raises(ValueError, match="finite"):
        curve.damage_per_cycle(np.array([1e6, np.nan]))
    with pytest.raises(ValueError, match=">= 0"):
        curve.damage_per_cycle(np.array([-1e6]))
    with pytest.raises(ValueError, match="detail"):
        SNCurve.dnv_rp_c203("Z")
    with pytest.raises(ValueError, match="ultimate"):
        SNCurve.basquin(3.0, 12.0, mean_correction="goodman")
    with pytest.raises(ValueError, match="low_stress"):
        SNCurve.basquin(3.0, 12.0, low_stress="maybe", endurance_MPa=10.0)
    with pytest.raises(ValueError, match="increase"):
        SNCurve.tabulated([10.0, 20.0], [1e6, 1e7])


def test_damage_per_cycle_one_call_path_is_the_scaled_loop_and_refuses_bad_ranges():
    """Without mean correction damage_per_cycle checks, scales and evaluates in one compiled
    call: the bits of effective_range_MPa then damage_loop (the committed Miner sum's), for
    scalar and per-cycle counts; a NaN, infinite or negative range is a ValueError."""
    from models.fatigue._loops import damage_loop

    curve = SNCurve.vaps_copper().with_factors(scf=1.37)
    rng = np.random.default_rng(7)
    ranges = rng.uniform(0.0, 120.0, 5000) * MPA
    ranges[:3] = [0.0, -0.0, 1e-300]
    counts = rng.uniform(0.5, 2.0, 5000)
    s = curve.effective_range_MPa(ranges)
    for c in (counts, np.ones(5000)):
        want = damage_loop(np.ascontiguousarray(s), np.ascontiguousarray(c), curve._mpa_params)
        got = curve.damage_per_cycle(ranges, counts=c if c is counts else 1.0)
        assert np.array_equal(got.view(np.int64), want.view(np.int64))
    one = curve.damage_per_cycle(ranges[7])  # a scalar in, a scalar out: the same bits
    assert np.shape(one) == () and one == got[7]
    for bad in (np.nan, np.inf, -np.inf, -1.0):
        with pytest.raises(ValueError, match="finite and >= 0"):
            curve.damage_per_cycle(np.array([10e6, bad]))
        with pytest.raises(ValueError, match="finite and >= 0"):
            curve.damage_per_cycle(np.array([10e6, bad]), counts=np.ones(2))
