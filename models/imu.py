"""IMU acceleration -> displacement, without drift.

Double integration of a measured acceleration diverges: a bias b grows as b t^2 / 2 and noise
as a random walk. Two remedies, both cutting the band below ``f_cut`` (swell and wind sea sit
well above ~0.04 Hz; drift sits below):

* :func:`displacement_from_acceleration` (batch): divide the spectrum by -omega^2 and taper it
  to zero below ``f_cut`` with a raised cosine. Zero phase; exact on periodic records.
* :class:`DisplacementIntegrator` (streaming): the causal filter H(s) = HP4(s) / s^2, a
  4th-order Butterworth high-pass at ``f_cut`` times the double integrator, discretised with
  the bilinear (trapezoid) transform. HP4 has four zeros at s = 0, so H has two left: a
  constant bias or a linear drift of the input gives zero output in steady state. Its state
  (the filter memory) is a small list of floats for checkpoints. It needs ~4 / f_cut seconds
  to settle after a cold start; the amplitude is within 0.1 % above 2.5 f_cut but the phase
  leads (about 50 deg at 3 f_cut, 15 deg at 10 f_cut). The trapezoid rule scales a
  component at frequency f by (x / tan x)^2, x = pi f dt: 2 % low at f = fs/18, so sample
  at 10-20 Hz (the project's IMU rate is 20 Hz) or use the batch function for slow records.

Inputs are the project's ``accel_x/y/z`` (m/s^2, gravity removed, mooring frame).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from models._jit import kernel
from models.butterworth import bilinear_zpk, butter_analog_zpk, zpk2sos


def _check_rate(dt: float, f_cut: float) -> None:
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0, got {dt!r}")
    if not (isinstance(f_cut, (int, float)) and math.isfinite(f_cut) and 0 < f_cut < 0.25 / dt):
        raise ValueError(f"f_cut must be > 0 and below a quarter of the sample rate, got {f_cut!r}")


def displacement_from_acceleration(
    accel: ArrayLike, dt: float, f_cut: float = 0.04
) -> NDArray[np.float64]:
    """Zero-phase displacement (m) from acceleration (m/s^2) along the last axis.

    X(f) = -A(f) / (2 pi f)^2 x W(f) with W a raised-cosine ramp from 0 at f_cut/2 to 1 at
    f_cut. The record's mean and linear trend are removed first (they are below any wave
    band and would leak through the window otherwise).
    """
    a = np.asarray(accel, dtype=float)
    _check_rate(dt, f_cut)
    if a.shape[-1] < 8:
        raise ValueError("need at least 8 acceleration samples")
    if not np.all(np.isfinite(a)):
        raise ValueError("acceleration contains NaN or infinite values")
    from scipy import signal  # noqa: PLC0415 (batch tool only: keeps scipy out of the daemon)

    a = signal.detrend(a, axis=-1, type="linear")
    n = a.shape[-1]
    f = np.fft.rfftfreq(n, dt)
    ramp = np.clip((f - 0.5 * f_cut) / (0.5 * f_cut), 0.0, 1.0)
    w = 0.5 - 0.5 * np.cos(np.pi * ramp)
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.where(f > 0, -w / (2 * np.pi * f) ** 2, 0.0)
    return np.fft.irfft(np.fft.rfft(a, axis=-1) * gain, n=n, axis=-1)


@kernel(inline="always")
def sos_step(sos: np.ndarray, zi: np.ndarray, c: int, v: float) -> float:
    """One sample ``v`` of channel ``c`` through the second-order sections ``sos``
    (transposed direct form II, scipy.signal.sosfilt's layout), updating the memory ``zi``
    (channels, sections, 2) in place; returns the output. Compiled into the loops that call
    it (here and models.estimator: change it together with them, or clear their caches)."""
    for s in range(sos.shape[0]):
        y = sos[s, 0] * v + zi[c, s, 0]
        zi[c, s, 0] = sos[s, 1] * v - sos[s, 4] * y + zi[c, s, 1]
        zi[c, s, 1] = sos[s, 2] * v - sos[s, 5] * y
        v = y
    return v


@kernel()
def _sosfilt(sos: np.ndarray, x: np.ndarray, zi: np.ndarray, out: np.ndarray) -> bool:
    """:func:`sos_step` over every sample of every channel, updating ``zi`` in place: scipy's
    per-call overhead dominated 1 s blocks. The channels are interleaved sample by sample:
    each channel's recursion is one chain of dependent operations (its latency, not the
    arithmetic, sets the pace), and the channels' independent chains overlap (11 instead of
    17 ns per 3-channel sample; each channel's operations and their order are unchanged, so
    are its bits). Returns False, changing nothing, if a value of ``x`` is NaN or infinite."""
    bad = False
    for c in range(x.shape[0]):
        for i in range(x.shape[1]):  # x - x is 0 for finite x, NaN otherwise; the OR vectorises
            bad |= (x[c, i] - x[c, i]) != 0.0
    if bad:
        return False
    for i in range(x.shape[1]):
        for c in range(x.shape[0]):
            out[c, i] = sos_step(sos, zi, c, x[c, i])
    return True


@dataclass
class DisplacementIntegrator:
    """Streaming, drift-free double integrator for ``channels`` acceleration channels.

    ``update(accel)`` takes an array (channels, n) or (n,) for one channel and returns the
    displacement with the same shape; the filter memory carries over between calls, so
    feeding blocks gives exactly the result of one long call.
    """

    dt: float
    f_cut: float = 0.03
    channels: int = 1

    def __post_init__(self) -> None:
        _check_rate(self.dt, self.f_cut)
        if not isinstance(self.channels, int) or self.channels < 1:
            raise ValueError(f"channels must be a positive integer, got {self.channels!r}")
        z, p, k = butter_analog_zpk(4, 2 * np.pi * self.f_cut, "high")
        # HP4 / s^2: drop two of the four zeros at s = 0.
        self._sos = zpk2sos(*bilinear_zpk(z[2:], p, k, 1.0 / self.dt))
        self._zi = np.zeros((self.channels, self._sos.shape[0], 2))
        self.samples_seen = 0

    @property
    def settle_time_s(self) -> float:
        """Time after a cold start before the output is trusted: 4 / f_cut."""
        return 4.0 / self.f_cut

    def update(self, accel: ArrayLike) -> NDArray[np.float64]:
        a = np.asarray(accel, dtype=float)
        one = a.ndim == 1
        a2 = a[None, :] if one else a
        if a2.ndim != 2 or a2.shape[0] != self.channels:
            raise ValueError(f"accel must have shape ({self.channels}, n), got {a.shape}")
        a2 = np.ascontiguousarray(a2)
        out = np.empty_like(a2)
        if not _sosfilt(self._sos, a2, self._zi, out):
            raise ValueError("acceleration contains NaN or infinite values")
        self.samples_seen += a2.shape[1]
        return out[0] if one else out

    def loop_state(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(sections, a copy of the memory) for a compiled loop that integrates sample by
        sample with :func:`sos_step` (models.estimator); it hands the memory back with
        :meth:`advance`."""
        return self._sos, self._zi.copy()

    def advance(self, zi: NDArray[np.float64], n: int) -> None:
        """Take the memory ``zi`` of :meth:`loop_state` after ``n`` more samples."""
        self._zi = zi
        self.samples_seen += n

    def state(self) -> dict:
        """JSON-ready filter memory."""
        return {"zi": self._zi.tolist(), "samples_seen": self.samples_seen}

    def load_state(self, state: dict) -> None:
        zi = np.asarray(state["zi"], dtype=float)
        if zi.shape != self._zi.shape or not np.all(np.isfinite(zi)):
            raise ValueError(f"integrator state zi must be finite with shape {self._zi.shape}")
        self._zi = zi
        self.samples_seen = int(state["samples_seen"])
