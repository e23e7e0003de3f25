"""models.butterworth against scipy.signal (the reference it replaces on the daemon's path)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from models.butterworth import bilinear_zpk, butter_analog_zpk, zpk2sos
from models.imu import DisplacementIntegrator


def digital_butter_sos(order: int, f_c: float, fs: float, btype: str) -> np.ndarray:
    """The digital design from the module's three steps, cutoff prewarped."""
    wc = 2 * fs * np.tan(np.pi * f_c / fs)
    return zpk2sos(*bilinear_zpk(*butter_analog_zpk(order, wc, btype), fs))


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5, 6, 8])
@pytest.mark.parametrize("btype", ["low", "high"])
@pytest.mark.parametrize("f_c,fs", [(0.03, 10.0), (0.5, 20.0), (3.0, 10.0), (40.0, 100.0)])
def test_digital_design_matches_scipy_butter_sos(order, btype, f_c, fs):
    ref = signal.butter(order, f_c, btype=btype, fs=fs, output="sos")
    got = digital_butter_sos(order, f_c, fs, btype)
    assert got.shape == ref.shape
    # scipy normalises to fs = 2 before prewarping: same design, rounding apart
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("order", [1, 2, 4, 7])
@pytest.mark.parametrize("btype", ["low", "high"])
def test_analog_zpk_and_bilinear_bit_identical_to_scipy(order, btype):
    wc = 2 * np.pi * 0.03
    z, p, k = butter_analog_zpk(order, wc, btype)
    zr, pr, kr = signal.butter(order, wc, btype=btype, analog=True, output="zpk")
    assert np.array_equal(z, zr) and np.array_equal(p, pr) and k == kr
    got = bilinear_zpk(z, p, k, 10.0)
    ref = signal.bilinear_zpk(zr, pr, kr, 10.0)
    for g, r in zip(got, ref):
        assert np.array_equal(g, r)


@pytest.mark.parametrize("dt", [0.05, 0.1, 0.2])
@pytest.mark.parametrize("f_cut", [0.01, 0.03, 0.04])
def test_imu_integrator_coefficients_bit_identical_to_scipy(dt, f_cut):
    """The streaming integrator's HP4 / s^2 sections: the old scipy construction, exactly."""
    z, p, k = signal.butter(4, 2 * np.pi * f_cut, btype="high", analog=True, output="zpk")
    ref = signal.zpk2sos(*signal.bilinear_zpk(z[2:], p, k, 1.0 / dt))
    got = DisplacementIntegrator(dt, f_cut, channels=3)._sos
    assert np.array_equal(got, ref), np.abs(got - ref).max()


def test_zpk2sos_pairs_like_scipy_with_complex_zeros_and_odd_order():
    """Cases Butterworth designs do not reach: complex zeros, a real pole left over."""
    z = np.array([0.5 + 0.5j, 0.5 - 0.5j, -0.9, 0.2 + 0.9j, 0.2 - 0.9j])
    p = np.array([0.7, 0.1 + 0.8j, 0.1 - 0.8j, -0.3, 0.6 + 0.2j, 0.6 - 0.2j])
    np.testing.assert_array_equal(zpk2sos(z, p, 0.7), signal.zpk2sos(z, p, 0.7))


def test_lowpass_response_half_power_at_cutoff():
    """|H| = 1/sqrt(2) at the cutoff and 1 at DC for the digital (prewarped) design."""
    sos = digital_butter_sos(4, 2.0, 20.0, "low")
    for f, want in ((0.0, 1.0), (2.0, 2**-0.5)):
        zz = np.exp(2j * np.pi * f / 20.0)
        h = np.prod([(s[0] * zz**2 + s[1] * zz + s[2]) / (s[3] * zz**2 + s[4] * zz + s[5])
                     for s in sos])
        assert abs(h) == pytest.approx(want, rel=1e-12)


@pytest.mark.parametrize("call,match", [
    (lambda: butter_analog_zpk(0, 1.0), "order"),
    (lambda: butter_analog_zpk(2, float("nan")), "cutoff"),
    (lambda: butter_analog_zpk(2, 1.0, "band"), "btype"),
    (lambda: bilinear_zpk([1.0, 2.0], [-1.0], 1.0, 10.0), "more zeros"),
    (lambda: bilinear_zpk([], [-1.0], 1.0, 0.0), "fs"),
    (lambda: zpk2sos([], [0.5 + 0.1j], 1.0), "conjugate"),
])
def test_bad_input_named(call, match):
    with pytest.raises(ValueError, match=match):
        call()
