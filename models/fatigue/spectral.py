"""Spectral fatigue: Miner damage rate of a stationary Gaussian stress from its spectrum.

A cross-check of rainflow counting and a design tool: from the one-sided power spectral
density ``G(f)`` of a stress (Pa^2/Hz) the methods below give the probability density of the
rainflow stress *ranges* and the rate of cycles, so the damage rate of any S-N curve is

    dD/dt = nu * integral p(S) / N(S) dS                                     (Miner)

Spectral moments use the angular frequency, ``m_i = integral (2 pi f)^i G(f) df`` (the
convention of Dirlik 1985 and of the FLife package), with sigma = sqrt(m0) and

    alpha_1 = m1 / sqrt(m0 m2),   alpha_2 = m2 / sqrt(m0 m4)   (bandwidth parameters)
    nu_0 = sqrt(m2 / m0) / 2 pi   (mean up-crossings per second)
    nu_p = sqrt(m4 / m2) / 2 pi   (peaks per second)

* **Dirlik** (T. Dirlik, PhD thesis, Warwick 1985; Zorman, Slavic & Boltezar, MSSP 2023,
  eq. 23): with ``Z = S / (2 sigma)`` and ``x_m = (m1/m0) sqrt(m2/m4)``,
  ``D1 = 2 (x_m - a2^2) / (1 + a2^2)``, ``R = (a2 - x_m - D1^2) / (1 - a2 - D1 + D1^2)``,
  ``D2 = (1 - a2 - D1 + D1^2) / (1 - R)``, ``D3 = 1 - D1 - D2``,
  ``Q = 1.25 (a2 - D3 - D2 R) / D1``;
  ``p(Z) = D1/Q e^(-Z/Q) + D2 Z/R^2 e^(-Z^2/2R^2) + D3 Z e^(-Z^2/2)``, cycles at ``nu_p``.
* **Tovo-Benasciutti** (Benasciutti & Tovo, IJF 2005, with the 2005 weighting ``b``):
  ``D = [b + (1 - b) alpha_2^(k-1)] D_NB`` for a slope-k curve, i.e. ``b nu_0`` cycles per
  second from the narrow-band Rayleigh law of sigma and ``(1 - b) nu_p`` from the Rayleigh
  law of ``alpha_2 sigma``, with
  ``b = (a1 - a2) [1.112 (1 + a1 a2 - (a1 + a2)) e^(2.11 a2) + (a1 - a2)] / (a2 - 1)^2``.

Both densities are integrated numerically against the curve's own ``damage_per_cycle``, so
any S-N curve (bilinear, tabulated, derated, with an endurance limit) is used exactly as the
rainflow path uses it: one damage formula on every path.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from models.fatigue import _spectral_loops as loops

Method = Literal["dirlik", "tovo_benasciutti"]
METHODS: tuple[Method, ...] = ("dirlik", "tovo_benasciutti")

# Gauss-Legendre quadrature on log-spaced panels of Z = S / (2 sigma): 8 nodes per panel,
# panels from Z = 1e-6 to far beyond where any density of the methods is negligible.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_PANELS_PER_DECADE = 64


class DamageCurve(Protocol):
    """What the damage functions need of an S-N curve (``models.fatigue.SNCurve`` has it)."""

    def damage_per_cycle(self, range_Pa: ArrayLike, mean_Pa: ArrayLike | None = None,
                         counts: ArrayLike = 1.0) -> NDArray[np.float64]: ...


@dataclass(frozen=True)
class SpectralMoments:
    """Spectral moments m0, m1, m2, m4 of a one-sided PSD (angular-frequency convention)."""

    m0: float
    m1: float
    m2: float
    m4: float

    @property
    def sigma(self) -> float:
        return math.sqrt(self.m0)

    @property
    def alpha1(self) -> float:
        return self.m1 / math.sqrt(self.m0 * self.m2)

    @property
    def alpha2(self) -> float:
        return self.m2 / math.sqrt(self.m0 * self.m4)

    @property
    def nu0_hz(self) -> float:
        """Mean rate of up-crossings of the mean (1/s)."""
        return math.sqrt(self.m2 / self.m0) / (2.0 * math.pi)

    @property
    def nup_hz(self) -> float:
        """Mean rate of peaks (1/s)."""
        return math.sqrt(self.m4 / self.m2) / (2.0 * math.pi)


def spectral_moments(f_hz: ArrayLike, psd: ArrayLike) -> SpectralMoments:
    """Moments of a one-sided PSD sampled at frequencies ``f_hz`` (trapezoidal rule).

    Raises ValueError for a spectrum with no variance or no frequency content (every
    method divides by m0, m2 and m4).
    """
    f = np.asarray(f_hz, dtype=float)
    g = np.ascontiguousarray(psd, dtype=float)
    if f.ndim != 1 or f.shape != g.shape or f.size < 2:
        raise ValueError("f_hz and psd must be 1-D arrays of the same length >= 2")
    f_ok, f_negative, powers, steps = _frequency_terms(f.tobytes())
    m_arr = np.empty(4)
    bad_g = loops.psd_moments(powers, g, steps, m_arr) if f_ok else 0
    if not f_ok or bad_g == 1:
        raise ValueError("f_hz must be finite and increasing, psd finite")
    if bad_g == 2 or f_negative:
        raise ValueError("a one-sided PSD has f >= 0 and psd >= 0")
    m = m_arr.tolist()
    if not all(v > 0 for v in m):
        raise ValueError("the spectrum has no variance or no frequency content (m0, m2 or "
                         "m4 is 0)")
    return SpectralMoments(*m)


# a pure function of the frequencies, memoised: a stream of spectra (the learner's windows)
# shares one grid, and its checks and powers were a third of a call
@functools.lru_cache(maxsize=8)
def _frequency_terms(f_bytes: bytes) -> tuple[bool, bool, NDArray[np.float64],
                                               NDArray[np.float64]]:
    """For the frequencies ``f_bytes`` (float64): whether they are finite and increasing,
    whether any is negative, the rows ``(2 pi f)^i`` for i = 0, 1, 2, 4 (numpy's powers)
    and ``np.diff(f)``, the trapezoidal rule's steps (read-only arrays)."""
    f = np.frombuffer(f_bytes, dtype=np.float64)
    ok = bool(np.isfinite(f).all() and not (np.diff(f) <= 0).any())
    w = 2.0 * np.pi * f
    powers = np.empty((4, f.size))
    for row, i in zip(powers, (0, 1, 2, 4)):
        row[:] = w**i
    steps = np.diff(f)
    for a in (powers, steps):
        a.flags.writeable = False
    return ok, bool((f < 0).any()), powers, steps


def dirlik_coefficients(mom: SpectralMoments) -> tuple[float, float, float, float, float]:
    """Dirlik's (D1, D2, D3, Q, R) of the module docstring."""
    a2 = mom.alpha2
    xm = mom.m1 / mom.m0 * math.sqrt(mom.m2 / mom.m4)
    d1 = 2.0 * (xm - a2**2) / (1.0 + a2**2)
    r = (a2 - xm - d1**2) / (1.0 - a2 - d1 + d1**2)
    d2 = (1.0 - a2 - d1 + d1**2) / (1.0 - r)
    d3 = 1.0 - d1 - d2
    q = 1.25 * (a2 - d3 - d2 * r) / d1
    return d1, d2, d3, q, r


def _gauss_parts(z: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(-Z^2, exp(-Z^2 / 2)): the factors of the densities that depend on Z alone."""
    neg_z2 = -z**2
    return neg_z2, np.exp(neg_z2 / 2.0)


def _dirlik_density(z: NDArray[np.float64], mom: SpectralMoments,
                    parts: tuple[NDArray[np.float64], NDArray[np.float64]]
                    ) -> NDArray[np.float64]:
    """Dirlik's density of Z = S / (2 sigma) per cycle (integrates to 1); ``parts``:
    :func:`_gauss_parts` of ``z``."""
    d1, d2, d3, q, r = dirlik_coefficients(mom)
    flat = [np.ascontiguousarray(a, dtype=float).reshape(-1) for a in (z, *parts)]
    # numpy's exp between two loops doing the rest with numpy's bits (_spectral_loops)
    e1, e2, out = (np.empty_like(flat[0]) for _ in range(3))
    loops.dirlik_exponents(flat[0], flat[1], q, 2.0 * r**2, e1, e2)
    np.exp(e1, out=e1)
    np.exp(e2, out=e2)
    loops.dirlik_combine(flat[0], flat[2], d1 / q, d2, r**2, d3, e1, e2, out)
    return out.reshape(np.shape(z))


def tovo_benasciutti_b(mom: SpectralMoments) -> float:
    """The 2005 weighting factor b of Benasciutti & Tovo, clipped to [0, 1]."""
    a1, a2 = mom.alpha1, mom.alpha2
    if a2 >= 1.0:  # a pure tone: the narrow-band law holds exactly
        return 1.0
    b = (a1 - a2) * (1.112 * (1.0 + a1 * a2 - (a1 + a2)) * math.exp(2.11 * a2)
                     + (a1 - a2)) / (a2 - 1.0) ** 2
    return min(max(b, 0.0), 1.0)


def _tb_weights(mom: SpectralMoments) -> tuple[float, float]:
    """Cycle rates (1/s) of TB's two parts: b nu_0 narrow-band cycles and (1 - b) nu_p
    range-counted cycles (so their damages are b D_NB and (1 - b) alpha_2^(k-1) D_NB)."""
    b = tovo_benasciutti_b(mom)
    return b * mom.nu0_hz, (1.0 - b) * mom.nup_hz


def _tb_density(z: NDArray[np.float64], mom: SpectralMoments,
                parts: tuple[NDArray[np.float64], NDArray[np.float64]]) -> NDArray[np.float64]:
    """Tovo-Benasciutti density of Z = S / (2 sigma) (= amplitude / sigma) per cycle;
    ``parts``: :func:`_gauss_parts` of ``z``."""
    nb, rc = _tb_weights(mom)
    a2 = mom.alpha2
    neg_z2, rayleigh = parts
    return (nb * z * rayleigh
            + rc * z / a2**2 * np.exp(neg_z2 / (2.0 * a2**2))) / (nb + rc)


def range_density(range_Pa: ArrayLike, mom: SpectralMoments,
                  method: Method = "dirlik") -> NDArray[np.float64]:
    """Probability density (1/Pa) of the rainflow stress range S per cycle."""
    z = np.asarray(range_Pa, dtype=float) / (2.0 * mom.sigma)
    return _density(method)(z, mom, _gauss_parts(z)) / (2.0 * mom.sigma)


def cycle_rate_hz(mom: SpectralMoments, method: Method = "dirlik") -> float:
    """Cycles per second counted by ``method``: the peaks (Dirlik), or TB's weighted mix of
    up-crossings and peaks, ``b nu_0 + (1 - b) nu_p``."""
    return mom.nup_hz if _check_method(method) == "dirlik" else sum(_tb_weights(mom))


def damage_rate(curve: DamageCurve, mom: SpectralMoments,
                method: Method = "dirlik") -> float:
    """Miner damage per second of the stress whose spectrum has moments ``mom``.

    ``curve.damage_per_cycle`` (Pa ranges, e.g. ``models.fatigue.SNCurve``) is integrated
    against the method's range density; ``nu * integral p(S) / N(S) dS``.
    """
    if _check_method(method) == "dirlik":
        return _dirlik_damage_rate(curve, mom)
    z, w, parts = _quadrature(60.0 * max(1.0, _scale(mom, method)))
    dpc = np.asarray(curve.damage_per_cycle(2.0 * mom.sigma * z), dtype=float)
    density = _density(method)(z, mom, parts)
    return cycle_rate_hz(mom, method) * loops.weighted_sum(w, density, dpc)


def _dirlik_damage_rate(curve: DamageCurve, mom: SpectralMoments) -> float:
    """:func:`damage_rate` of Dirlik's density: its coefficients once, both exponentials in
    one ``np.exp``, the density and the weighted sum in one pass (the same operations on the
    same doubles as :func:`_dirlik_density` then ``weighted_sum``: the same bits)."""
    d1, d2, d3, q, r = dirlik_coefficients(mom)
    z, w, (neg_z2, rayleigh) = _quadrature(60.0 * max(1.0, max(abs(q), abs(r))))
    dpc = np.asarray(curve.damage_per_cycle(2.0 * mom.sigma * z), dtype=float)
    e = np.empty((2, z.shape[0]))
    loops.dirlik_exponents(z, neg_z2, q, 2.0 * r**2, e[0], e[1])
    np.exp(e, out=e)
    total = loops.dirlik_damage_sum(w, z, rayleigh, d1 / q, d2, r**2, d3, e[0], e[1],
                                    np.ascontiguousarray(dpc).reshape(-1))
    return mom.nup_hz * total


# a pure function of z_max, memoised: a stream of spectra (the learner's windows) is
# integrated on a few grids, and building one (and its exponential) was a quarter of a call
@functools.lru_cache(maxsize=16)
def _quadrature(z_max: float) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                       tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Gauss-Legendre nodes Z and weights on the panels from 1e-6 to ``z_max``, and
    :func:`_gauss_parts` of the nodes (read-only arrays)."""
    n = int(_PANELS_PER_DECADE * math.log10(z_max / 1e-6))
    edges = np.geomspace(1e-6, z_max, n + 1)
    half = 0.5 * np.diff(edges)
    z = (edges[:-1, None] + half[:, None] * (1.0 + _GL_X[None, :])).ravel()
    w = (half[:, None] * _GL_W[None, :]).ravel()
    parts = _gauss_parts(z)
    for a in (z, w, *parts):
        a.flags.writeable = False
    return z, w, parts


def damage_rate_from_psd(curve: DamageCurve, f_hz: ArrayLike, psd: ArrayLike,
                         method: Method = "dirlik") -> float:
    """:func:`damage_rate` of a one-sided stress PSD (Pa^2/Hz at ``f_hz``)."""
    return damage_rate(curve, spectral_moments(f_hz, psd), method)


def _scale(mom: SpectralMoments, method: Method) -> float:
    """The widest length scale of the density in Z (Dirlik's Q and R; 1 for TB)."""
    if method != "dirlik":
        return 1.0
    _, _, _, q, r = dirlik_coefficients(mom)
    return max(abs(q), abs(r))


def _check_method(method: str) -> Method:
    if method not in METHODS:
        raise ValueError(f"spectral method {method!r}: must be one of {list(METHODS)}")
    return method  # type: ignore[return-value]


def _density(method: str):
    return _dirlik_density if _check_method(method) == "dirlik" else _tb_density


def hann(n: int) -> NDArray[np.float64]:
    """The periodic Hann window of ``n`` points (scipy's ``get_window("hann", n)``)."""
    return 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)


class Periodograms:
    """The periodograms Welch's estimate averages (Welch 1967): one-sided PSD (units^2/Hz)
    of segments of ``n`` samples, each its mean removed and a Hann window applied, computed
    in buffers kept for up to ``max_rows`` segments at a time.

    A stream of slabs then allocates nothing per call: fresh arrays of a few hundred kB
    (a slab's segments) are new pages for the allocator each time, and the page faults cost
    several times the arithmetic. Each row is computed on its own (numpy's row-wise mean,
    pocketfft's one transform per row, elementwise steps), so a row's bits do not depend on
    the rows beside it or on the buffer: :func:`segment_psds` is this on fresh arrays.
    """

    def __init__(self, n: int, max_rows: int = 128) -> None:
        if n < 2 or max_rows < 1:
            raise ValueError("Periodograms: segments of >= 2 samples, max_rows >= 1")
        self.n, self.max_rows = n, max_rows
        self.window = hann(n)
        self.window_power = float(np.sum(self.window * self.window))
        self._x = np.empty((0, n))
        self._spectrum = np.empty((0, n // 2 + 1), complex)
        self._psd = np.empty((0, n // 2 + 1))

    def rows(self, m: int) -> NDArray[np.float64]:
        """The input buffer's first ``m`` rows (``1 <= m <= max_rows``), for the caller to
        fill with segments before :meth:`compute`."""
        if not 1 <= m <= self.max_rows:
            raise ValueError(f"Periodograms.rows: m = {m}: need 1 <= m <= max_rows = "
                             f"{self.max_rows}")
        if m > self._x.shape[0]:
            size = min(max(m, 2 * self._x.shape[0]), self.max_rows)
            self._x = np.empty((size, self.n))
            self._spectrum = np.empty((size, self.n // 2 + 1), complex)
            self._psd = np.empty((size, self.n // 2 + 1))
        return self._x[:m]

    def compute(self, m: int, fs_hz: float) -> NDArray[np.float64]:
        """The PSD of each of the first ``m`` rows filled (a view of a buffer the next call
        overwrites; the input rows are overwritten too)."""
        _check_fs(fs_hz)
        x = self.rows(m)
        loops.detrend_window(x[None], 0, m, self.window, x)  # row by row: in place
        psd = self._magnitudes(x[None], 0, m)
        np.square(psd, out=psd)
        psd /= fs_hz * self.window_power
        n = self.n
        psd[:, 1:n // 2 + (n % 2)] *= 2.0  # one-sided: every bin but DC (and Nyquist, even n)
        return psd

    def add(self, windowed: NDArray[np.float64], first: int, last: int, fs_hz: float,
            sums: NDArray[np.float64]) -> None:
        """Add the PSD of each segment ``windowed[c, first:last]`` (``c`` a signal; at most
        ``max_rows`` segments in all), its mean already removed and the window applied
        (``models.fatigue._spectral_loops.window_segments`` or ``detrend_window``), to
        ``sums[c]``, one segment after another in order: the bits of :meth:`compute` on those
        segments followed by ``sums[c] += psd`` per row."""
        m = windowed.shape[0] * (last - first)
        if not 1 <= m <= self.max_rows:
            raise ValueError(f"Periodograms.add: {m} segments: need 1 <= m <= max_rows = "
                             f"{self.max_rows}")
        _check_fs(fs_hz)
        self.rows(m)  # buffers for m rows
        mags = self._magnitudes(windowed, first, last)
        # doubled bins 1 .. top - 1: an even segment's last (Nyquist) bin is not doubled
        top = mags.shape[1] - 1 if self.n % 2 == 0 else mags.shape[1]
        loops.add_power(sums, mags, fs_hz * self.window_power, last - first, top)

    def _magnitudes(self, windowed: NDArray[np.float64], first: int, last: int
                    ) -> NDArray[np.float64]:
        """``|rfft|`` of each windowed segment ``windowed[c, first:last]`` (signal by signal,
        rows ``[c (last - first), (c + 1) (last - first))`` of the result): numpy's transform,
        one row at a time whatever the rows' layout, and complex ``abs``, in the buffers."""
        c, r = windowed.shape[0], last - first
        spectrum = self._spectrum[:c * r]
        np.fft.rfft(windowed[:, first:last], axis=2, out=spectrum.reshape(c, r, -1))
        return np.abs(spectrum, out=self._psd[:c * r])


def _check_fs(fs_hz: float) -> None:
    if not (math.isfinite(fs_hz) and fs_hz > 0):
        raise ValueError(f"Periodograms: fs = {fs_hz!r}: must be finite and > 0")


def segment_psds(segments: ArrayLike, fs_hz: float
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One-sided PSD (units^2/Hz) of each equal-length segment (rows), its mean removed and
    a Hann window applied: the periodograms Welch's estimate averages (Welch 1967; their mean
    is ``scipy.signal.welch(x, fs, nperseg=n, noverlap=0)`` over the segments laid end to
    end). Returns (frequencies, PSD per row); :class:`Periodograms` for a stream."""
    x = np.atleast_2d(np.asarray(segments, dtype=float))
    if x.shape[1] < 2 or x.shape[0] == 0 or not (math.isfinite(fs_hz) and fs_hz > 0):
        raise ValueError("segment_psds: at least one segment of >= 2 samples and fs > 0")
    work = Periodograms(x.shape[1], x.shape[0])
    work.rows(x.shape[0])[:] = x
    freqs = np.fft.rfftfreq(x.shape[1], 1.0 / fs_hz).astype(np.float64, copy=False)
    return freqs, work.compute(x.shape[0], fs_hz)
