"""Linear (Airy) waves: dispersion, kinematics, spectra, random-phase series, sea-state statistics.

Everything is SI: metres, seconds, radians, frequencies in Hz where a name says ``f`` and in
rad/s where it says ``omega``. Depth ``h`` is the still-water depth (``math.inf`` = deep water);
``z`` is measured up from the still-water level (``z = 0`` surface, ``z = -h`` seabed).

The seeds use linear wave theory for design loads (seed 004 App. 6, WAVFOR: dispersion
``L = g T^2/(2 pi) tanh(2 pi h / L)``); the monitor also needs irregular seas to simulate buoy
motion and to estimate Hs / Tp / Tz from a measured heave record.

Buoy motion model (:func:`buoy_motion`): a small heave-following buoy (a Waverider-like
particle follower). Each wave component moves the buoy along the water-particle orbit at the
surface: heave = surface elevation times an optional second-order heave response, horizontal
displacement = ``-i coth(kh)`` times the elevation (finite-depth orbit), split into surge and
sway by the wave direction relative to the mooring's mean direction. Mooring restoring forces
and drift are ignored; a mean offset can be added by the caller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

G_STANDARD = 9.80665

Spectrum = Callable[[NDArray[np.float64]], NDArray[np.float64]]


def _positive_array(name: str, value: ArrayLike) -> NDArray[np.float64]:
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0.0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return arr


def _depth(depth: float) -> float:
    if not isinstance(depth, (int, float)) or math.isnan(depth) or depth <= 0.0:
        raise ValueError(f"depth must be > 0 (math.inf for deep water), got {depth!r}")
    return float(depth)


def wavenumber(omega: ArrayLike, depth: float, g: float = G_STANDARD) -> NDArray[np.float64]:
    """Wave number k (rad/m) solving the linear dispersion relation omega^2 = g k tanh(k h).

    Vectorised Newton iteration on x = k h from the deep/shallow blend of Eckart's explicit
    approximation; converges to machine precision in a few steps for every k h.
    """
    w = _positive_array("omega", omega)
    h = _depth(depth)
    k_deep = w * w / g
    if math.isinf(h):
        return k_deep
    x0 = k_deep * h
    # Eckart (1952) start: x tanh-blended between deep (x0) and shallow (sqrt(x0)).
    x = x0 / np.sqrt(np.tanh(x0))
    for _ in range(50):
        t = np.tanh(x)
        f = x * t - x0
        df = t + x * (1.0 - t * t)
        step = f / df
        x = x - step
        if np.all(np.abs(step) <= 1e-14 * x):
            break
    return x / h


def wavelength(period: ArrayLike, depth: float, g: float = G_STANDARD) -> NDArray[np.float64]:
    """Wavelength L (m) of a linear wave of ``period`` (s): L = g T^2/(2 pi) tanh(2 pi h/L)."""
    t = _positive_array("period", period)
    return 2.0 * np.pi / wavenumber(2.0 * np.pi / t, depth, g)


def breaking_height(period: ArrayLike, depth: float, g: float = G_STANDARD) -> NDArray[np.float64]:
    """Height (m) above which a wave of ``period`` (s) breaks in water ``depth`` (m): Miche's
    (1944) limit H_b = L/7 tanh(2 pi h/L), L from the dispersion relation (seed 004 App. 6).
    In deep water it is Michell's steepness limit H/L = 1/7, in shallow water about 0.9 h."""
    length = wavelength(period, depth, g)
    h = _depth(depth)
    depth_factor = 1.0 if math.isinf(h) else np.tanh(2.0 * np.pi * h / length)
    return length / 7.0 * depth_factor


def _depth_ratios(k: NDArray[np.float64], z: NDArray[np.float64], depth: float):
    """cosh(k(z+h))/sinh(kh) and sinh(k(z+h))/sinh(kh), overflow-free for large k h."""
    if math.isinf(depth):
        e = np.exp(k * z)
        return e, e
    # Multiply numerator and denominator by exp(-k h): stays finite for any k h.
    e_top = np.exp(k * z)
    e_bot = np.exp(-k * (z + 2.0 * depth))
    den = 1.0 - np.exp(-2.0 * k * depth)
    return (e_top + e_bot) / den, (e_top - e_bot) / den


@dataclass(frozen=True)
class WaveKinematics:
    """Linear-wave field at a point: elevation (m), velocities (m/s), accelerations (m/s^2)."""

    eta: NDArray[np.float64]
    u: NDArray[np.float64]
    w: NDArray[np.float64]
    du_dt: NDArray[np.float64]
    dw_dt: NDArray[np.float64]


def wave_kinematics(
    amplitude: ArrayLike,
    period: ArrayLike,
    depth: float,
    z: ArrayLike,
    phase: ArrayLike,
    g: float = G_STANDARD,
) -> WaveKinematics:
    """Airy-wave elevation and particle kinematics for eta = a cos(theta), theta = k x - omega t.

    u = a omega cosh(k(z+h))/sinh(kh) cos(theta), w = a omega sinh(k(z+h))/sinh(kh) sin(theta),
    du/dt = a omega^2 cosh(..)/sinh(kh) sin(theta), dw/dt = -a omega^2 sinh(..)/sinh(kh) cos(theta).
    (Seed 004 App. 6 writes the same field with a g k / omega / cosh(kh), equal by dispersion.)
    Broadcasts over all arguments; ``z`` must lie in [-h, 0] (linear theory stops at the mean
    surface; WAVFOR's evaluation at z = +A is done in :mod:`models.wavfor`).
    """
    a = np.asarray(amplitude, dtype=float)
    if not np.all(np.isfinite(a)) or np.any(a < 0.0):
        raise ValueError(f"amplitude must be finite and >= 0, got {amplitude!r}")
    t = _positive_array("period", period)
    zz = np.asarray(z, dtype=float)
    h = _depth(depth)
    if not np.all(np.isfinite(zz)) or np.any(zz > 0.0) or np.any(zz < -h):
        raise ValueError(f"z must lie between -depth and 0, got {z!r}")
    theta = np.asarray(phase, dtype=float)
    if not np.all(np.isfinite(theta)):
        raise ValueError("phase must be finite")
    omega = 2.0 * np.pi / t
    k = wavenumber(omega, h, g)
    ch, sh = _depth_ratios(k, zz, h)
    c, s = np.cos(theta), np.sin(theta)
    return WaveKinematics(
        eta=a * c,
        u=a * omega * ch * c,
        w=a * omega * sh * s,
        du_dt=a * omega**2 * ch * s,
        dw_dt=-a * omega**2 * sh * c,
    )


def pierson_moskowitz(f: ArrayLike, hs: float, tp: float) -> NDArray[np.float64]:
    """Pierson-Moskowitz spectrum S(f) in m^2/Hz with significant height hs and peak period tp.

    S(f) = 5/16 Hs^2 fp^4 f^-5 exp(-5/4 (fp/f)^4) (DNV-RP-C205 eq 3.5.1 in Hz form);
    its zeroth moment is exactly Hs^2/16.
    """
    ff = np.asarray(f, dtype=float)
    if not np.all(np.isfinite(ff)) or np.any(ff < 0.0):
        raise ValueError("frequencies must be finite and >= 0")
    _positive_array("hs", hs)
    _positive_array("tp", tp)
    fp = 1.0 / tp
    out = np.zeros_like(ff)
    pos = ff > 0.0
    r = fp / ff[pos]
    out[pos] = 5.0 / 16.0 * hs**2 * fp**4 / ff[pos] ** 5 * np.exp(-1.25 * r**4)
    return out


def jonswap(
    f: ArrayLike,
    hs: float,
    tp: float,
    gamma: float = 3.3,
    sigma_a: float = 0.07,
    sigma_b: float = 0.09,
) -> NDArray[np.float64]:
    """JONSWAP spectrum S(f) in m^2/Hz (DNV-RP-C205 eq 3.5.5: PM x (1 - 0.287 ln gamma) x gamma^r).

    The normalisation makes the zeroth moment Hs^2/16 to within about 1 % for 1 <= gamma <= 7.
    gamma = 1 gives Pierson-Moskowitz.
    """
    if not (isinstance(gamma, (int, float)) and 1.0 <= gamma <= 10.0):
        raise ValueError(f"gamma must be between 1 and 10, got {gamma!r}")
    ff = np.asarray(f, dtype=float)
    pm = pierson_moskowitz(ff, hs, tp)
    fp = 1.0 / tp
    sigma = np.where(ff <= fp, sigma_a, sigma_b)
    r = np.exp(-((ff - fp) ** 2) / (2.0 * sigma**2 * fp**2))
    return pm * (1.0 - 0.287 * math.log(gamma)) * gamma**r


def spectral_moments(
    f: ArrayLike, s: ArrayLike, orders: tuple[int, ...] = (0, 1, 2, 4)
) -> dict[int, float]:
    """Spectral moments m_n = integral f^n S(f) df (trapezoid), frequency in Hz."""
    ff = np.asarray(f, dtype=float)
    ss = np.asarray(s, dtype=float)
    if ff.shape != ss.shape or ff.ndim != 1 or ff.size < 2:
        raise ValueError("f and s must be 1-D arrays of the same length >= 2")
    if not (np.all(np.isfinite(ff)) and np.all(np.isfinite(ss))):
        raise ValueError("f and s must be finite")
    return {n: float(np.trapezoid(ff**n * ss, ff)) for n in orders}


@dataclass(frozen=True)
class WaveComponents:
    """Discrete wave components eta(t) = sum a_i cos(2 pi f_i t + phase_i) on an FFT grid.

    ``f[i] = i / duration`` for i = 0..n//2; a_0 = 0. ``n`` samples at step ``dt``.
    """

    f: NDArray[np.float64]
    amplitude: NDArray[np.float64]
    phase: NDArray[np.float64]
    dt: float
    n: int

    def synthesize(self, transfer: NDArray[np.complexfloating] | NDArray[np.floating] | None = None
                   ) -> NDArray[np.float64]:
        """The time series sum |H a| cos(2 pi f t + phase + arg H) at t = 0, dt, ..., (n-1) dt.

        ``transfer`` is a complex response per component (e.g. a heave RAO); None = 1.
        Uses one inverse real FFT, so it is O(n log n).
        """
        spec = self.amplitude * np.exp(1j * self.phase)
        if transfer is not None:
            spec = spec * transfer
        coeffs = spec * (self.n / 2.0)
        return np.fft.irfft(coeffs, n=self.n)


def random_phase_components(
    spectrum: Spectrum, duration: float, dt: float, seed: int
) -> WaveComponents:
    """Deterministic random-phase discretisation of a one-sided spectrum S(f) (m^2/Hz).

    Components at f_i = i/duration with amplitude sqrt(2 S(f_i) df) and phases uniform on
    [0, 2 pi) from ``numpy.random.default_rng(seed)``: the same seed gives the same sea.
    The Nyquist component is zeroed (its phase is not representable).
    """
    _positive_array("duration", duration)
    _positive_array("dt", dt)
    if not isinstance(seed, (int, np.integer)):
        raise ValueError(f"seed must be an integer, got {seed!r}")
    n = int(round(duration / dt))
    if n < 4:
        raise ValueError(f"duration/dt must give at least 4 samples, got {n}")
    n += n % 2
    df = 1.0 / (n * dt)
    f = np.arange(n // 2 + 1, dtype=np.float64) * df
    s = np.asarray(spectrum(f), dtype=np.float64)
    if s.shape != f.shape or not np.all(np.isfinite(s)) or np.any(s < 0.0):
        raise ValueError("spectrum must return finite values >= 0, one per frequency")
    amp = np.sqrt(2.0 * s * df)
    amp[0] = 0.0
    amp[-1] = 0.0
    phase = np.random.default_rng(seed).uniform(0.0, 2.0 * np.pi, f.size)
    return WaveComponents(f=f, amplitude=amp, phase=phase, dt=float(dt), n=n)


def random_phase_series(
    spectrum: Spectrum, duration: float, dt: float, seed: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(t, eta): a surface-elevation record from ``spectrum``, deterministic for ``seed``."""
    comp = random_phase_components(spectrum, duration, dt, seed)
    return np.arange(comp.n, dtype=np.float64) * comp.dt, comp.synthesize()


@dataclass(frozen=True)
class SeaState:
    """Sea-state statistics of a record: Hs = 4 sqrt(m0), Tz = sqrt(m0/m2), Tp = 1/f_peak."""

    hs: float
    tp: float
    tz: float
    m0: float
    m2: float


def sea_state_from_heave(
    heave: ArrayLike,
    dt: float,
    f_min: float = 0.04,
    f_max: float = 0.5,
    segment_s: float = 256.0,
) -> SeaState:
    """Hs, Tp, Tz from a heave record (m) sampled at ``dt`` (s), via a Welch spectrum.

    Moments are integrated over [f_min, f_max] Hz to reject drift and high-frequency noise;
    Tp is refined by a parabola through the spectral peak and its neighbours.
    """
    x = np.asarray(heave, dtype=float)
    _positive_array("dt", dt)
    if x.ndim != 1 or x.size < 64:
        raise ValueError("heave must be a 1-D record of at least 64 samples")
    if not np.all(np.isfinite(x)):
        raise ValueError("heave contains NaN or infinite values")
    if not 0.0 <= f_min < f_max:
        raise ValueError(f"need 0 <= f_min < f_max, got {f_min}, {f_max}")
    # scipy.signal costs the live daemon ~60 MB of memory: imported only where it is used
    from scipy import signal  # noqa: PLC0415

    nper = min(x.size, int(round(segment_s / dt)))
    f, s = signal.welch(x, fs=1.0 / dt, nperseg=nper, detrend="linear")
    return sea_state_from_psd(f, s, f_min, min(f_max, 0.5 / dt))


def sea_state_from_psd(f_hz: ArrayLike, psd: ArrayLike, f_min: float = 0.04,
                       f_max: float = 0.5) -> SeaState:
    """Hs, Tp, Tz of a one-sided heave PSD (m^2/Hz at evenly spaced ``f_hz``), its moments
    integrated over [f_min, f_max] Hz (trapezoidal rule, as :func:`spectral_moments`); Tp
    refined by a parabola through the spectral peak and its neighbours. ValueError if the
    band holds fewer than 3 bins or no energy. One compiled pass
    (``models.fatigue._spectral_loops.band_moments``: the bits of the numpy steps)."""
    # imported when used: the loops live in the fatigue package (beside the pairwise sum they
    # share), whose import costs the many users of this module that never call this ~5 ms
    from models.fatigue._spectral_loops import band_moments  # noqa: PLC0415

    f = np.asarray(f_hz, dtype=float)
    s = np.asarray(psd, dtype=float)
    if f.shape != s.shape:
        raise ValueError(f"f_hz {f.shape} and psd {s.shape} must have the same shape")
    out = np.empty(3)
    bad = band_moments(np.ascontiguousarray(f).reshape(-1), np.ascontiguousarray(s).reshape(-1),
                       float(f_min), float(f_max), out)
    if bad == 1:
        raise ValueError("record too short for the requested frequency band")
    if bad == 2:
        raise ValueError("f and s must be finite")
    if bad == 3:
        raise ValueError("heave record has no energy in the wave band")
    m0, m2 = float(out[0]), float(out[1])
    # fp a numpy float, as it was: a peak at 0 Hz gives Tp = inf (and numpy's warning)
    return SeaState(hs=4.0 * math.sqrt(m0), tp=1.0 / out[2], tz=math.sqrt(m0 / m2), m0=m0, m2=m2)


@dataclass(frozen=True)
class BuoyMotion:
    """Displacements (m) and accelerations (m/s^2) of a buoy in the project's motion frame."""

    t: NDArray[np.float64]
    heave: NDArray[np.float64]
    surge: NDArray[np.float64]
    sway: NDArray[np.float64]
    accel_x: NDArray[np.float64]
    accel_y: NDArray[np.float64]
    accel_z: NDArray[np.float64]
    # velocities (m/s); for a perfect follower also the surface water-particle velocity
    vel_x: NDArray[np.float64]
    vel_y: NDArray[np.float64]
    vel_z: NDArray[np.float64]


def heave_rao(
    omega: ArrayLike, natural_period: float | None, damping_ratio: float = 0.3
) -> NDArray[np.complexfloating]:
    """Second-order heave response to surface elevation, 1 at low frequency.

    H = 1 / (1 - r^2 + 2 i zeta r), r = omega T_n / (2 pi). ``natural_period`` None = a perfect
    follower (H = 1).
    """
    w = np.asarray(omega, dtype=float)
    if natural_period is None:
        return np.ones_like(w, dtype=np.complex128)
    _positive_array("natural_period", natural_period)
    if not 0.0 < damping_ratio:
        raise ValueError(f"damping_ratio must be > 0, got {damping_ratio!r}")
    r = w * natural_period / (2.0 * np.pi)
    return cast(NDArray[np.complexfloating], 1.0 / (1.0 - r * r + 2j * damping_ratio * r))


def buoy_motion(
    hs: float,
    tp: float,
    duration: float,
    dt: float,
    seed: int,
    depth: float = math.inf,
    direction_deg: float = 0.0,
    gamma: float = 3.3,
    heave_natural_period: float | None = None,
    heave_damping: float = 0.3,
    g: float = G_STANDARD,
) -> BuoyMotion:
    """Heave/surge/sway of a heave-following buoy in a long-crested JONSWAP sea.

    Waves travel at ``direction_deg`` from the mooring's mean direction (anchor -> buoy),
    counter-clockwise seen from above, so sway = the horizontal orbit times sin(direction).
    Per component: heave = RAO x elevation (:func:`heave_rao`); horizontal displacement
    = -i coth(kh) x elevation (the surface particle orbit). Accelerations are the exact
    second derivatives (-omega^2 x displacement), gravity excluded: the same frame and units
    as the ``imu`` sensor; velocities the first (i omega x displacement). Deterministic for
    ``seed``.
    """
    if not math.isfinite(direction_deg):
        raise ValueError(f"direction_deg must be finite, got {direction_deg!r}")
    comp = random_phase_components(lambda f: jonswap(f, hs, tp, gamma), duration, dt, seed)
    omega = 2.0 * np.pi * comp.f
    safe = np.where(omega > 0.0, omega, 1.0)
    k = wavenumber(safe, depth, g)
    coth = 1.0 if math.isinf(depth) else 1.0 / np.tanh(k * depth)
    rao = heave_rao(omega, heave_natural_period, heave_damping)
    horiz = -1j * coth * np.where(omega > 0.0, 1.0, 0.0)
    b = math.radians(direction_deg)
    acc = -(omega**2)
    vel = 1j * omega
    return BuoyMotion(
        t=np.arange(comp.n, dtype=np.float64) * comp.dt,
        heave=comp.synthesize(rao),
        surge=comp.synthesize(horiz * math.cos(b)),
        sway=comp.synthesize(horiz * math.sin(b)),
        accel_x=comp.synthesize(acc * horiz * math.cos(b)),
        accel_y=comp.synthesize(acc * horiz * math.sin(b)),
        accel_z=comp.synthesize(acc * rao),
        vel_x=comp.synthesize(vel * horiz * math.cos(b)),
        vel_y=comp.synthesize(vel * horiz * math.sin(b)),
        vel_z=comp.synthesize(vel * rao),
    )
