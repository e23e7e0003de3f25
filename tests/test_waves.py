"""Linear waves: dispersion against tables, kinematics, spectra, random series, sea-state stats."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from models import waves

# shared/ sits beside the checkout (CI) or beside a parent of the worktree (development).
SHARED = next(
    (p / "shared" for p in Path(__file__).resolve().parents if (p / "shared/reference").is_dir()),
    None,
)
needs_shared = pytest.mark.skipif(SHARED is None, reason="../shared (seed reference data) absent")


@pytest.mark.parametrize(
    "h_over_l0, h_over_l",
    # Shore Protection Manual (1984) App. C, Table C-1: h/L for a given h/L0, L0 = g T^2/2pi.
    [(0.05, 0.09416), (0.10, 0.1410), (0.20, 0.2251), (0.50, 0.5018)],
)
def test_dispersion_matches_spm_table(h_over_l0, h_over_l):
    t = 9.0
    l0 = waves.G_STANDARD * t * t / (2 * math.pi)
    h = h_over_l0 * l0
    assert h / waves.wavelength(t, h) == pytest.approx(h_over_l, abs=6e-5)


def test_dispersion_limits_and_residual():
    omega = np.logspace(-2, 1.5, 200)
    k = waves.wavenumber(omega, 30.0)
    np.testing.assert_allclose(omega**2, waves.G_STANDARD * k * np.tanh(k * 30.0), rtol=1e-12)
    # Deep water: L0 = g T^2 / (2 pi); shallow: c = sqrt(g h).
    assert waves.wavelength(5.0, math.inf) == pytest.approx(39.01942, rel=1e-6)
    assert 2 * math.pi / waves.wavenumber(0.01, 2.0)[()] * 0.01 / (2 * math.pi) == pytest.approx(
        math.sqrt(waves.G_STANDARD * 2.0), rel=1e-4
    )


@needs_shared
def test_dispersion_reproduces_wavfor_wavelengths():
    """Seed 004 App. 6 tabulated L for h = 22 m, g = 9.806 (rows 2-11; row 1 is as printed)."""
    ref = json.loads((SHARED / "reference/seed004_vaps_cable.json").read_text())
    rows = np.array(ref["wavfor_cases_height_period_wavelength"][1:])
    got = waves.wavelength(rows[:, 1], 22.0, g=9.806)
    np.testing.assert_allclose(got, rows[:, 2], rtol=4.5e-3)
    np.testing.assert_allclose(got[:-1], rows[:-1, 2], atol=0.06)


def test_breaking_height_limits_and_the_seed_design_waves():
    """Miche: L/7 tanh(kh). Deep water, T = 8 s: L0 = g 64/(2 pi) = 99.893 m, / 7 = 14.270 m;
    in 23 m: L = 91.696 m (the SPM-checked dispersion above), tanh(2 pi 23/91.696) = 0.91797,
    H_b = 13.099 x 0.91797 = 12.025 m; shallow water (h = 1 m, T = 30 s): kh -> 0, so
    H_b -> 2 pi h / 7 = 0.8976 h."""
    assert waves.breaking_height(8.0, math.inf) == pytest.approx(14.2704, abs=1e-3)
    assert waves.breaking_height(8.0, 23.0) == pytest.approx(12.025, abs=2e-3)
    assert waves.breaking_height(30.0, 1.0) == pytest.approx(2 * math.pi / 7, rel=2e-3)
    with pytest.raises(ValueError, match="period"):
        waves.breaking_height(0.0, 23.0)


@needs_shared
def test_seed_design_waves_are_below_breaking():
    """Seed 004 App. 6's design waves (site rule T = H + 2.5 s, 22 m) are physical: each
    below its breaking height, the largest (3.96 m, 9.65 s) at 28 % of it."""
    ref = json.loads((SHARED / "reference/seed004_vaps_cable.json").read_text())
    rows = np.array(ref["wavfor_cases_height_period_wavelength"][1:])
    ratio = rows[:, 0] / waves.breaking_height(rows[:, 1], 22.0, g=9.806)
    assert np.all(ratio < 0.3) and ratio[-1] == pytest.approx(3.96 / 13.984, rel=1e-3)


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match="omega"):
        waves.wavenumber([1.0, float("nan")], 10.0)
    with pytest.raises(ValueError, match="depth"):
        waves.wavenumber(1.0, -5.0)
    with pytest.raises(ValueError, match="z must"):
        waves.wave_kinematics(1.0, 8.0, 20.0, 1.0, 0.0)
    with pytest.raises(ValueError, match="hs"):
        waves.jonswap(np.array([0.1]), -1.0, 8.0)
    with pytest.raises(ValueError, match="heave contains NaN"):
        waves.sea_state_from_heave(np.r_[np.zeros(100), np.nan], 0.5)


def test_kinematics_hand_values():
    # Deep-water surface: |u| = |w| = a omega; accelerations a omega^2.
    kin = waves.wave_kinematics(1.0, 10.0, math.inf, 0.0, [0.0, math.pi / 2])
    om = 2 * math.pi / 10
    np.testing.assert_allclose(kin.u, [om, 0.0], atol=1e-12)
    np.testing.assert_allclose(kin.w, [0.0, om], atol=1e-12)
    np.testing.assert_allclose(kin.du_dt, [0.0, om**2], atol=1e-12)
    np.testing.assert_allclose(kin.dw_dt, [-(om**2), 0.0], atol=1e-12)
    # Finite depth, seabed: w = 0; u = a omega / sinh(kh) (hand formula).
    h = 15.0
    k = waves.wavenumber(om, h)[()]
    kin = waves.wave_kinematics(0.5, 10.0, h, -h, 0.0)
    assert kin.w == pytest.approx(0.0, abs=1e-14)
    assert kin.u == pytest.approx(0.5 * om / math.sinh(k * h), rel=1e-12)
    # Seed 004 form: u = A g k / omega cosh(k(z+h))/cosh(kh) at z = -5.
    kin = waves.wave_kinematics(0.5, 10.0, h, -5.0, 0.0)
    assert kin.u == pytest.approx(
        0.5 * waves.G_STANDARD * k / om * math.cosh(k * 10) / math.cosh(k * h), rel=1e-12
    )


def test_spectra_moments_and_peak():
    f = np.linspace(0.0, 3.0, 60001)
    m_pm = waves.spectral_moments(f, waves.pierson_moskowitz(f, 3.0, 9.0))
    assert 4 * math.sqrt(m_pm[0]) == pytest.approx(3.0, rel=1e-4)
    # PM: Tz = Tp / 1.4049 (DNV-RP-C205 3.5.5.4 with gamma = 1); the f^-5 tail's m2 is cut at
    # 3 Hz, hence the looser tolerance.
    assert math.sqrt(m_pm[0] / m_pm[2]) == pytest.approx(9.0 / 1.4049, rel=3e-3)
    s = waves.jonswap(f, 3.0, 9.0, gamma=3.3)
    m_j = waves.spectral_moments(f, s)
    assert 4 * math.sqrt(m_j[0]) == pytest.approx(3.0, rel=5e-3)
    # DNV: Tz/Tp = 0.6673 + 0.05037 g - 0.006230 g^2 + 0.0003341 g^3 = 0.7782 for gamma = 3.3
    assert math.sqrt(m_j[0] / m_j[2]) / 9.0 == pytest.approx(0.7782, rel=4e-3)
    assert f[np.argmax(s)] == pytest.approx(1 / 9.0, abs=1e-4)
    pm = waves.pierson_moskowitz(f, 3.0, 9.0)
    np.testing.assert_allclose(waves.jonswap(f, 3.0, 9.0, gamma=1.0), pm)


def test_random_series_deterministic_and_hs():
    spec = lambda f: waves.jonswap(f, 2.0, 8.0)  # noqa: E731
    t1, e1 = waves.random_phase_series(spec, 3600.0, 0.5, seed=7)
    _, e2 = waves.random_phase_series(spec, 3600.0, 0.5, seed=7)
    _, e3 = waves.random_phase_series(spec, 3600.0, 0.5, seed=8)
    np.testing.assert_array_equal(e1, e2)
    assert not np.allclose(e1, e3)
    assert t1[1] - t1[0] == 0.5 and t1.size == 7200
    # Discrete variance equals sum a_i^2/2 exactly; with df = 1/3600 that is m0 to < 0.1 %.
    f = np.linspace(0, 1, 20001)
    m0 = waves.spectral_moments(f, spec(f))[0]
    assert np.var(e1) == pytest.approx(m0, rel=2e-3)


def test_sea_state_from_heave_recovers_input():
    t, eta = waves.random_phase_series(lambda f: waves.jonswap(f, 2.5, 9.0), 3 * 3600.0, 0.5, 3)
    ss = waves.sea_state_from_heave(eta, 0.5)
    assert ss.hs == pytest.approx(2.5, rel=0.05)
    assert ss.tp == pytest.approx(9.0, rel=0.08)
    assert ss.tz == pytest.approx(0.7782 * 9.0, rel=0.05)


def test_buoy_motion_frame_and_accelerations():
    m = waves.buoy_motion(2.0, 8.0, 1200.0, 0.05, seed=1, depth=23.0, direction_deg=30.0)
    assert m.heave.size == m.t.size == 24000
    # Long-crested sea at 30 deg: sway/surge = tan(30 deg) sample by sample.
    np.testing.assert_allclose(m.sway, m.surge * math.tan(math.radians(30)), atol=1e-12)
    # Horizontal orbit in 23 m is larger than vertical (coth(kh) > 1).
    assert np.std(m.surge) / math.cos(math.radians(30)) > 1.05 * np.std(m.heave)
    # Accelerations are second derivatives of displacements: A(f) = -(2 pi f)^2 X(f).
    om = 2 * np.pi * np.fft.rfftfreq(m.t.size, 0.05)
    for x, a in ((m.heave, m.accel_z), (m.surge, m.accel_x)):
        np.testing.assert_allclose(np.fft.rfft(a), -(om**2) * np.fft.rfft(x), atol=1e-8 * m.t.size)
    # ... and the low-frequency part also matches a finite difference in time.
    lo = om < 2 * np.pi * 0.5
    smooth = lambda x: np.fft.irfft(np.fft.rfft(x) * lo, n=m.t.size)  # noqa: E731
    hz, az = smooth(m.heave), smooth(m.accel_z)
    d2 = (hz[2:] - 2 * hz[1:-1] + hz[:-2]) / 0.05**2
    assert np.max(np.abs(d2 - az[1:-1])) < 0.01 * np.max(np.abs(az))
    # Heave RAO: a long-period component passes unchanged; at resonance the response is 1/(2 zeta).
    assert abs(waves.heave_rao(np.array([1e-4]), 3.0, 0.2)[0]) == pytest.approx(1.0, rel=1e-6)
    assert abs(waves.heave_rao(np.array([2 * math.pi / 3.0]), 3.0, 0.2)[0]) == pytest.approx(2.5)


def test_tz_agrees_with_qats_zero_crossings():
    qsig = pytest.importorskip("qats.signal")
    t, eta = waves.random_phase_series(lambda f: waves.jonswap(f, 2.0, 8.0), 3 * 3600.0, 0.25, 9)
    ss = waves.sea_state_from_heave(eta, 0.25, f_max=1.0)
    assert ss.tz == pytest.approx(1.0 / qsig.average_frequency(t, eta, up=True), rel=0.05)


@pytest.mark.skipif(SHARED is None, reason="../shared absent")
def test_sea_state_of_real_waverider_record():
    raw = np.loadtxt(SHARED / "realdata/cdip_datawell_raw/cdip.raw", delimiter=",")
    ss = waves.sea_state_from_heave(raw[:, 1] / 100.0, 1 / 1.28)
    assert ss.hs == pytest.approx(1.84, abs=0.05)  # the record's documented Hm0
    assert 5.0 < ss.tz < ss.tp < 20.0
