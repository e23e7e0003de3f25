"""IMU acceleration -> displacement: known-displacement records, drift rejection, state."""

from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from models import imu, waves

SHARED = next(
    (p / "shared" for p in Path(__file__).resolve().parents if (p / "shared/realdata").is_dir()),
    None,
)


def hs(x):
    return 4.0 * np.std(x)


@pytest.fixture(scope="module")
def motion():
    return waves.buoy_motion(1.5, 7.0, 3600.0, 0.05, seed=3, depth=23.0, direction_deg=20.0)


def test_batch_reconstructs_known_displacement(motion):
    for x, a in ((motion.heave, motion.accel_z), (motion.surge, motion.accel_x)):
        got = imu.displacement_from_acceleration(a, 0.05)
        assert hs(got) == pytest.approx(hs(x), rel=0.01)
        # Sample by sample: the only loss is the sub-0.04 Hz tail of the spectrum.
        assert np.std(got - x) < 0.01 * np.std(x)


def test_streaming_blocks_with_bias_and_drift(motion):
    integ = imu.DisplacementIntegrator(0.05, f_cut=0.03)
    # A constant 0.05 m/s^2 bias and a slow bias drift would give kilometres when integrated.
    t = motion.t
    a = motion.accel_z + 0.05 + 1e-5 * t
    got = np.concatenate([integ.update(a[i : i + 20]) for i in range(0, t.size, 20)])
    k = int(integ.settle_time_s / 0.05)
    assert hs(got[k:]) == pytest.approx(hs(motion.heave[k:]), rel=0.05)
    assert abs(np.mean(got[k:])) < 0.01
    # Blocks equal one call; state round-trip continues identically.
    one = imu.DisplacementIntegrator(0.05, f_cut=0.03).update(a)
    np.testing.assert_allclose(got, one, rtol=0, atol=1e-12)
    # The filter kernel is scipy's sosfilt (same sections, same state layout).
    integ = imu.DisplacementIntegrator(0.05, f_cut=0.03)
    np.testing.assert_allclose(one, signal.sosfilt(integ._sos, a), rtol=1e-10, atol=1e-12)
    s1 = imu.DisplacementIntegrator(0.05, 0.03, channels=3)
    s1.update(np.vstack([a[:500]] * 3))
    s2 = imu.DisplacementIntegrator(0.05, 0.03, channels=3)
    s2.load_state(s1.state())
    block = np.vstack([a[500:900]] * 3)
    np.testing.assert_array_equal(s1.update(block), s2.update(block))


def test_bad_input():
    with pytest.raises(ValueError, match="NaN"):
        imu.displacement_from_acceleration(np.r_[np.zeros(20), np.nan], 0.05)
    with pytest.raises(ValueError, match="f_cut"):
        imu.DisplacementIntegrator(0.05, f_cut=6.0)
    with pytest.raises(ValueError, match="shape"):
        imu.DisplacementIntegrator(0.05, channels=2).update(np.zeros(10))


@pytest.mark.skipif(SHARED is None, reason="../shared/realdata absent")
def test_real_waverider_record():
    """CDIP Datawell heave (1.28 Hz, 30 min): acceleration of the measured displacement,
    integrated back, gives the record's Hs within 5 % (batch; at 1.28 Hz the streaming
    trapezoid rule loses the high-frequency part, as documented)."""
    raw = np.loadtxt(SHARED / "realdata/cdip_datawell_raw/cdip.raw", delimiter=",")
    heave = raw[:, 1] / 100.0
    dt = 1 / 1.28
    f = np.fft.rfftfreq(heave.size, dt)
    accel = np.fft.irfft(-((2 * np.pi * f) ** 2) * np.fft.rfft(heave - heave.mean()), n=heave.size)
    got = imu.displacement_from_acceleration(accel, dt)
    assert hs(heave) == pytest.approx(1.84, abs=0.1)  # README: Hm0 about 1.84 m
    assert hs(got) == pytest.approx(hs(heave), rel=0.05)
    assert np.std(got - heave) < 0.05 * np.std(heave)
    # Streaming on the same record, documented trapezoid loss (x/tan x)^2 at 1.28 Hz: < 10 %.
    integ = imu.DisplacementIntegrator(dt, f_cut=0.03)
    integ.update(accel)  # warm-up pass (the record is periodic by construction)
    assert hs(integ.update(accel)) == pytest.approx(hs(heave), rel=0.10)
