"""Spectral fatigue (Dirlik, Tovo-Benasciutti) against the FLife package and hand results."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from models.fatigue.sn_curve import SNCurve
from models.fatigue.spectral import (Periodograms, cycle_rate_hz, damage_rate,
                                     damage_rate_from_psd, range_density, segment_psds,
                                     spectral_moments, tovo_benasciutti_b)
from models.waves import jonswap

FLife = pytest.importorskip("FLife")

F = np.linspace(0.01, 1.0, 2000)


def _spectra():
    """A wave-frequency stress spectrum, the same with a second, higher mode, and a narrow
    one (Pa^2/Hz)."""
    wave = 4e12 * jonswap(F, 1.5, 5.25)
    bimodal = wave + 2e11 * np.exp(-((F - 0.6) / 0.05) ** 2)
    narrow = 1e12 * np.exp(-((F - 0.2) / 0.01) ** 2)
    return {"wave": wave, "bimodal": bimodal, "narrow": narrow}


@pytest.mark.parametrize("name", ["wave", "bimodal", "narrow"])
@pytest.mark.parametrize("k, log_a", [(3.0, 12.164), (4.0, 12.0), (5.0, 15.606)])
def test_damage_rate_equals_flife_closed_forms(name, k, log_a):
    psd = _spectra()[name]
    curve = SNCurve.basquin(k, log_a)           # N = 10**log_a * S_MPa**-k, S a range
    sd = FLife.SpectralData(input={"PSD": psd / 1e12, "f": F})  # MPa^2/Hz
    c_amp = 10**log_a / 2**k                    # FLife's S-N curve is on amplitudes
    for method, cls in (("dirlik", FLife.Dirlik), ("tovo_benasciutti", FLife.TovoBenasciutti)):
        ours = damage_rate_from_psd(curve, F, psd, method)
        theirs = 1.0 / cls(sd).get_life(c_amp, k)
        assert ours == pytest.approx(theirs, rel=1e-6), method


def test_narrow_band_limit_is_the_rayleigh_closed_form():
    """A near pure tone (alpha_2 -> 1): both of TB's parts tend to the narrow-band result
    nu0 (2 sqrt(2 m0))^k Gamma(1 + k/2) / C on ranges (Bendat), whatever b is."""
    psd = _spectra()["narrow"]
    mom = spectral_moments(F, psd)
    assert mom.alpha2 > 0.997 and 0.0 <= tovo_benasciutti_b(mom) <= 1.0
    k, log_a = 3.0, 12.0
    by_hand = mom.nu0_hz * (2 * math.sqrt(2 * mom.m0) / 1e6) ** k * math.gamma(1 + k / 2) / 10**log_a
    tb = damage_rate(SNCurve.basquin(k, log_a), mom, "tovo_benasciutti")
    assert tb == pytest.approx(by_hand, rel=2e-3)


@pytest.mark.parametrize("method", ["dirlik", "tovo_benasciutti"])
def test_range_density_integrates_to_one(method):
    mom = spectral_moments(F, _spectra()["bimodal"])
    s = np.linspace(0, 40 * mom.sigma, 200_001)
    assert np.trapezoid(range_density(s, mom, method), s) == pytest.approx(1.0, abs=1e-6)
    assert cycle_rate_hz(mom, "dirlik") == pytest.approx(mom.nup_hz)


def test_a_knee_curve_is_integrated_through_its_own_damage_per_cycle():
    """The DNV two-slope curve: the spectral damage equals a brute-force sum over a fine
    grid of ranges with the curve's damage_per_cycle (the same formula as rainflow)."""
    curve = SNCurve.dnv_rp_c203("D", "air")
    mom = spectral_moments(F, _spectra()["wave"])
    s = np.linspace(1.0, 30 * mom.sigma, 2_000_001)
    brute = mom.nup_hz * np.trapezoid(range_density(s, mom) * curve.damage_per_cycle(s), s)
    assert damage_rate(curve, mom) == pytest.approx(brute, rel=1e-4)


def test_bad_spectra_are_refused():
    with pytest.raises(ValueError, match="no variance"):
        spectral_moments(F, np.zeros_like(F))
    with pytest.raises(ValueError, match="increasing"):
        spectral_moments(F[::-1], np.ones_like(F))
    with pytest.raises(ValueError, match="psd >= 0"):
        spectral_moments(F, -np.ones_like(F))
    with pytest.raises(ValueError, match="spectral method"):
        damage_rate(SNCurve.basquin(3, 12), spectral_moments(F, _spectra()["wave"]), "rice")


def test_segment_psds_average_to_scipy_welch():
    # Welch's estimate without overlap over the segments laid end to end: scipy as the oracle
    rng = np.random.default_rng(7)
    for n in (64, 63):  # even n has a Nyquist bin, odd n none
        x = rng.normal(3.0, 2.0, 5 * n)
        f, rows = segment_psds(x.reshape(5, n), 20.0)
        f_ref, psd_ref = signal.welch(x, fs=20.0, nperseg=n, noverlap=0)
        np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rows.mean(axis=0), psd_ref, rtol=1e-12, atol=1e-15)
    with pytest.raises(ValueError, match="segment_psds"):
        segment_psds(np.zeros((2, 1)), 20.0)


def _fresh_periodograms(x: np.ndarray, fs: float) -> np.ndarray:
    """The periodograms written as one numpy expression on fresh arrays (the formula
    segment_psds had before it reused buffers): the bit-level reference."""
    n = x.shape[1]
    w = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)
    spec = np.abs(np.fft.rfft((x - x.mean(axis=1, keepdims=True)) * w, axis=1)) ** 2
    spec /= fs * float(np.sum(w * w))
    spec[:, 1:n // 2 + (n % 2)] *= 2.0
    return spec


def test_periodograms_give_each_row_the_same_bits_alone_batched_or_in_a_reused_buffer():
    rng = np.random.default_rng(11)
    work = Periodograms(1024, max_rows=40)
    for m, scale, fs in ((37, 1e6, 20.0), (3, 1e-2, 10.0), (40, 5e8, 19.98), (1, 1.0, 20.0)):
        x = rng.normal(2.0, 1.0, (m, 1024)) * scale  # a mean to remove, stress-like scales
        ref = _fresh_periodograms(x, fs)
        work.rows(m)[:] = x
        batched = work.compute(m, fs)
        alone = np.vstack([segment_psds(x[i], fs)[1] for i in range(m)])
        for got in (batched, alone, segment_psds(x, fs)[1]):
            assert np.array_equal(got.view(np.int64), ref.view(np.int64))
    with pytest.raises(ValueError, match="max_rows"):
        work.rows(41)
    with pytest.raises(ValueError, match="fs"):
        work.compute(1, 0.0)


def _damage_rate_written_out(curve, f, g, method, ranges):
    """damage_rate_from_psd as one expression per step, its grid built afresh (the code before
    the grid was memoised), and the range density at ``ranges``: the bit-level reference."""
    w = 2.0 * np.pi * f
    mom = spectral_moments(f, g)
    m = [float(np.trapezoid(w**i * g, f)) for i in (0, 1, 2, 4)]
    assert m == [mom.m0, mom.m1, mom.m2, mom.m4]
    if method == "dirlik":
        a2 = mom.alpha2
        xm = mom.m1 / mom.m0 * math.sqrt(mom.m2 / mom.m4)
        d1 = 2.0 * (xm - a2**2) / (1.0 + a2**2)
        r = (a2 - xm - d1**2) / (1.0 - a2 - d1 + d1**2)
        d2 = (1.0 - a2 - d1 + d1**2) / (1.0 - r)
        d3 = 1.0 - d1 - d2
        q = 1.25 * (a2 - d3 - d2 * r) / d1
        z_max = 60.0 * max(1.0, abs(q), abs(r))
    else:
        z_max = 60.0
    n = int(64 * math.log10(z_max / 1e-6))
    edges = np.geomspace(1e-6, z_max, n + 1)
    half = 0.5 * np.diff(edges)
    x, wt = np.polynomial.legendre.leggauss(8)
    z = (edges[:-1, None] + half[:, None] * (1.0 + x[None, :])).ravel()
    wz = (half[:, None] * wt[None, :]).ravel()

    def density(z):
        if method == "dirlik":
            return (d1 / q * np.exp(-z / q) + d2 * z / r**2 * np.exp(-z**2 / (2.0 * r**2))
                    + d3 * z * np.exp(-z**2 / 2.0))
        b = tovo_benasciutti_b(mom)
        nb, rc = b * mom.nu0_hz, (1.0 - b) * mom.nup_hz
        return (nb * z * np.exp(-z**2 / 2.0)
                + rc * z / mom.alpha2**2 * np.exp(-z**2 / (2.0 * mom.alpha2**2))) / (nb + rc)

    dpc = curve.damage_per_cycle(2.0 * mom.sigma * z)
    rate = cycle_rate_hz(mom, method) * float(np.sum(wz * density(z) * dpc))
    return rate, density(ranges / (2.0 * mom.sigma)) / (2.0 * mom.sigma)


@pytest.mark.parametrize("method", ["dirlik", "tovo_benasciutti"])
def test_damage_rate_on_the_memoised_grid_has_the_bits_of_a_fresh_one(method):
    curves = (SNCurve.basquin(3, 12.164), SNCurve.basquin(5, 15.606))
    for g in _spectra().values():
        ranges = np.linspace(0.0, 10.0 * math.sqrt(spectral_moments(F, g).m0), 1001)
        for curve in curves:
            rate, dens = _damage_rate_written_out(curve, F, g, method, ranges)
            for _ in range(2):  # the grid built, then reused
                assert damage_rate_from_psd(curve, F, g, method) == rate
        got = range_density(ranges, spectral_moments(F, g), method)
        assert np.array_equal(got.view(np.int64), dens.view(np.int64))
