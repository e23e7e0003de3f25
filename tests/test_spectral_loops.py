"""The spectral loops (models.fatigue._spectral_loops) give the bits of the numpy expressions
they replace, compiled and as plain Python (models._jit.uncompiled), on random data spanning
ten decades and on edge cases (sums of 0 to 20,000 values, zero rows, a segment's DC only);
window_segments is a copy then detrend_window's expression; and Periodograms.add of a batch
of windowed segments is compute() of the raw ones followed by one addition per row, for any
batch split."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

from models._jit import numba_module, uncompiled
from models.fatigue import _spectral_loops as loops
from models.fatigue.spectral import (Periodograms, SpectralMoments, _gauss_parts, _quadrature,
                                     dirlik_coefficients, hann, spectral_moments)

MODES = pytest.mark.parametrize("plain", [False, True], ids=["compiled", "plain"])


def bits(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.int64)


def mode(plain: bool):
    return uncompiled() if plain else contextlib.nullcontext()


def wide(rng: np.random.Generator, *shape: int) -> np.ndarray:
    """Normal values times magnitudes from 1e-5 to 1e5: their sums' bits depend on order."""
    return rng.standard_normal(shape) * 10.0 ** rng.uniform(-5, 5, shape)


def test_pairwise_sum_is_numpys_sum_for_every_length_compiled_and_plain():
    compiled = numba_module().njit(lambda a: loops.pairwise_sum(a))
    rng = np.random.default_rng(1)
    lengths = [*range(0, 260), 511, 512, 513, 1023, 1024, 1025, 3976, 8191, 8192, 8193, 20000]
    for n in lengths:
        a = wide(rng, n)
        want = bits(np.sum(a))
        assert bits(compiled(a)) == want, n
        if n <= 1025:  # plain Python is slow: the small lengths cover every branch
            assert bits(loops.pairwise_sum(a)) == want, n
    # not a sequential sum: these lengths are where the two differ
    a = wide(rng, 1024)
    seq = 0.0
    for v in a:
        seq += v
    assert bits(seq) != bits(np.sum(a))


@MODES
@pytest.mark.parametrize("rows", [1, 7])
def test_detrend_window_is_numpys_mean_subtract_and_window(plain, rows):
    rng = np.random.default_rng(2)
    n = 1024 if not plain else 64
    src = wide(rng, 2, rows + 3, n) + 1e3
    src[1, 1] = 0.0  # a zero row: its mean is 0
    window = hann(n)
    out = np.empty((2 * rows, n))
    with mode(plain):
        loops.detrend_window(src, 1, 1 + rows, window, out)
    x = src[:, 1:1 + rows].reshape(-1, n).copy()
    np.subtract(x, x.mean(axis=1, keepdims=True), out=x)
    np.multiply(x, window, out=x)
    assert np.array_equal(bits(out), bits(x))


@MODES
@pytest.mark.parametrize("nc", [0, 1, 300, 1023])
def test_window_segments_is_the_segments_copied_then_detrended_and_windowed(plain, nc):
    """Segments of open samples followed by new ones (the first joined across them or not,
    a gap in the indices) into rows: the bits of the numpy copy then detrend_window's
    numpy expression."""
    rng = np.random.default_rng(5)
    n = 1024 if not plain else 64
    open_x = wide(rng, nc % n) + 1e3
    x = wide(rng, 6 * n) + 1e3
    for js in ([0, 1, 2], [1, 2, 5], [0, 3], [4]):
        js = np.array(js, np.int64)
        joined = np.concatenate([open_x, x])
        want = np.stack([joined[j * n:(j + 1) * n] for j in js])
        np.subtract(want, want.mean(axis=1, keepdims=True), out=want)
        np.multiply(want, hann(n), out=want)
        out = np.full((js.shape[0] + 1, n), np.nan)
        with mode(plain):
            loops.window_segments(out, js, open_x, x, hann(n))
        assert np.array_equal(bits(out[:-1]), bits(want)), js
        assert np.isnan(out[-1]).all()  # nothing written past the segments


@MODES
@pytest.mark.parametrize("n", [1024, 15])
def test_periodograms_add_is_compute_then_a_row_at_a_time(plain, n):
    """Windowed segments of two signals added in batches of 1, 3 and all: the same sums,
    and the same as compute()'s rows (the raw segments) added one by one (numpy's +=) from
    0.0; odd and even lengths."""
    rng = np.random.default_rng(3)
    segs = wide(rng, 2, 9, n)
    fs = 19.987
    with mode(plain):
        ref = np.zeros((2, n // 2 + 1))
        work = Periodograms(n, 18)
        for c in range(2):
            work.rows(9)[:] = segs[c]
            for row in work.compute(9, fs):
                ref[c] += row
        windowed = np.empty_like(segs)
        loops.detrend_window(segs, 0, 9, hann(n), windowed.reshape(18, n))
        for per in (1, 3, 9):
            got = np.zeros_like(ref)
            for a in range(0, 9, per):
                work.add(windowed, a, min(a + per, 9), fs, got)
            assert np.array_equal(bits(got), bits(ref)), per
    assert np.all(ref[:, 1:] > 0)
    with pytest.raises(ValueError, match="max_rows"):
        Periodograms(n, 4).add(windowed, 0, 3, fs, ref)
    with pytest.raises(ValueError, match="fs"):
        Periodograms(n, 4).add(windowed, 0, 1, float("nan"), ref)


def _numpy_moments(f: np.ndarray, g: np.ndarray) -> list[float]:
    """spectral_moments as it was written in numpy (main 7e8ba84)."""
    w = 2.0 * np.pi * f
    y = np.empty((4, f.size))
    for row, i in zip(y, (0, 1, 2, 4)):
        np.multiply(w**i, g, out=row)
    return np.trapezoid(y, f).tolist()


@MODES
def test_spectral_moments_are_numpys_trapezoid(plain):
    rng = np.random.default_rng(4)
    for n in (2, 3, 9, 513, 1000):
        f = np.sort(rng.uniform(0.0, 5.0, n))
        g = np.abs(wide(rng, n))
        g[n // 2] = 0.0
        with mode(plain):
            mom = spectral_moments(f, g)
        assert bits([mom.m0, mom.m1, mom.m2, mom.m4]).tolist() == \
            bits(_numpy_moments(f, g)).tolist(), n
    f = np.linspace(0.0, 1.0, 5)
    with pytest.raises(ValueError, match="finite"):
        spectral_moments(f, [1.0, np.nan, 1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="finite"):
        spectral_moments(f[::-1], np.ones(5))
    with pytest.raises(ValueError, match="f >= 0"):
        spectral_moments(f, [1.0, -1.0, 1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="f >= 0"):
        spectral_moments(f - 0.5, np.ones(5))
    with pytest.raises(ValueError, match="no variance"):
        spectral_moments(f, np.zeros(5))


@MODES
def test_dirlik_density_and_weighted_sum_are_numpys(plain):
    from models.fatigue.spectral import _dirlik_density
    rng = np.random.default_rng(5)
    z, w, parts = _quadrature(60.0)
    for m0, m1, m2, m4 in ((1.0, 0.8, 0.9, 1.5), (3e12, 2e12, 4e12, 9e12)):
        mom = SpectralMoments(m0, m1, m2, m4)
        d1, d2, d3, q, r = dirlik_coefficients(mom)
        neg_z2, rayleigh = parts
        want = (d1 / q * np.exp(-z / q) + d2 * z / r**2 * np.exp(neg_z2 / (2.0 * r**2))
                + d3 * z * rayleigh)
        with mode(plain):
            got = _dirlik_density(z, mom, parts)
            dpc = np.abs(wide(rng, z.size))
            total = loops.weighted_sum(w, got, dpc)
        assert np.array_equal(bits(got), bits(want))
        assert bits(total) == bits(np.sum(w * want * dpc))
        # any shape, as range_density passes it
        zz = z[:12].reshape(3, 4)
        with mode(plain):
            got2 = _dirlik_density(zz, mom, _gauss_parts(zz))
        assert got2.shape == (3, 4)
        assert np.array_equal(bits(got2.ravel()), bits(want[:12]))


@MODES
def test_dirlik_damage_sum_is_density_then_weighted_sum(plain):
    """The fused pass gives the bits of dirlik_combine followed by weighted_sum."""
    rng = np.random.default_rng(8)
    z, w, (neg_z2, rayleigh) = _quadrature(60.0 if not plain else 1e-4)
    mom = SpectralMoments(3e12, 2e12, 4e12, 9e12)
    d1, d2, d3, q, r = dirlik_coefficients(mom)
    e1, e2 = np.exp(-z / q), np.exp(neg_z2 / (2.0 * r**2))
    dpc = np.abs(wide(rng, z.size))
    with mode(plain):
        density = np.empty_like(z)
        loops.dirlik_combine(z, rayleigh, d1 / q, d2, r**2, d3, e1, e2, density)
        want = loops.weighted_sum(w, density, dpc)
        got = loops.dirlik_damage_sum(w, z, rayleigh, d1 / q, d2, r**2, d3, e1, e2, dpc)
    assert bits(got) == bits(want) == bits(np.sum(w * density * dpc))


def _numpy_sea_state(f, s, f_min=0.04, f_max=0.5):
    """models.waves.sea_state_from_psd as it was written in numpy (main 452691c): (m0, m2,
    fp), or the ValueError's message."""
    band = (f >= f_min) & (f <= f_max)
    if band.sum() < 3:
        return "too short"
    fb, sb = f[band], s[band]
    if not (np.all(np.isfinite(fb)) and np.all(np.isfinite(sb))):
        return "finite"
    m = {n: float(np.trapezoid(fb**n * sb, fb)) for n in (0, 2)}
    if not m[0] > 0.0:
        return "no energy"
    i = int(np.argmax(sb))
    fp = fb[i]
    if 0 < i < sb.size - 1:
        den = sb[i - 1] - 2.0 * sb[i] + sb[i + 1]
        if den < 0.0:
            fp = fb[i] + 0.5 * (sb[i - 1] - sb[i + 1]) / den * (fb[1] - fb[0])
    return m[0], m[2], fp


@MODES
def test_sea_state_from_psd_is_its_numpy_steps(plain):
    """Hs, Tp, Tz of wide random spectra, a peak at the band's first bin, a flat top
    (argmax: the first), a peak at 0 Hz (Tp = inf), and each error, compiled and plain."""
    from models.waves import sea_state_from_psd
    rng = np.random.default_rng(9)
    f = np.fft.rfftfreq(1024, 1.0 / 9.97)
    cases = [np.abs(wide(rng, f.size)) for _ in range(6)]
    edge = np.abs(wide(rng, f.size))
    edge[np.argmax(f >= 0.04)] = 1e9
    flat = np.ones(f.size)
    flat[10:13] = 5.0
    dc = np.ones(f.size)
    dc[0] = 4.0
    nan = np.ones(f.size)
    nan[20] = np.nan
    for s in (*cases, edge, flat, dc, nan, np.zeros(f.size), np.ones(f.size)):
        for lo, hi in ((0.04, 0.5), (0.04, float(f[-1])), (0.0, 0.02), (0.3, 0.32)):
            want = _numpy_sea_state(f, s, lo, hi)
            with mode(plain), np.errstate(divide="ignore"):
                try:
                    ss = sea_state_from_psd(f, s, lo, hi)
                    got = ss.m0, ss.m2, 1.0 / ss.tp
                except ValueError as e:
                    got = str(e)
            if isinstance(want, str):
                assert isinstance(got, str) and want in got, (want, got)
                continue
            assert bits(got[:2]).tolist() == bits(want[:2]).tolist()
            with np.errstate(divide="ignore"):
                assert bits(ss.tp) == bits(1.0 / want[2])
            assert ss.hs == 4.0 * np.sqrt(want[0]) and ss.tz == np.sqrt(want[0] / want[1])

