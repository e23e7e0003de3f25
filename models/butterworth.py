"""Butterworth filter design in numpy alone: analog prototype, bilinear transform, sections.

The live daemon filters IMU acceleration (:class:`models.imu.DisplacementIntegrator`) and
must not import ``scipy.signal`` for it (~60 MB of resident memory for three small design
functions). The steps follow the classical design (Oppenheim & Schafer, *Discrete-Time Signal
Processing*, 3rd ed., sec. 7.2-7.3) and scipy.signal's conventions and operation order, so the
coefficients are bit-identical to ``scipy.signal`` on the same machine:

1. :func:`butter_analog_zpk`: the order-N Butterworth poles on the unit circle,
   p_m = -exp(i pi m / 2N), m = -N+1, -N+3, ..., N-1, scaled to the cutoff wc (low-pass:
   s -> s / wc) or inverted about it (high-pass: s -> wc / s, which adds N zeros at s = 0).
2. :func:`bilinear_zpk`: s = 2 fs (z - 1) / (z + 1), each root r -> (2 fs + r) / (2 fs - r),
   zeros at infinity -> z = -1. No prewarping: for a digital cutoff f_c at rate fs, pass
   wc = 2 fs tan(pi f_c / fs) to step 1 (the prewarped frequency).
3. :func:`zpk2sos`: second-order sections [b0 b1 b2 1 a1 a2], poles closest to the unit
   circle last, each pole pair with its nearest zeros, the gain in the first section.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

_TOL = 100 * np.finfo(float).eps  # realness / conjugate-pair tolerance, relative to |root|


def butter_analog_zpk(
    order: int, wc: float, btype: str = "low"
) -> tuple[NDArray[np.float64], NDArray[np.complex128], float]:
    """Zeros, poles and gain of the analog Butterworth ``btype`` ("low"/"high") filter of
    ``order`` with -3 dB angular cutoff ``wc`` (rad/s): |H(i w)|^2 = 1 / (1 + (w/wc)^2N)
    for the low-pass, (w/wc)^2N / (1 + (w/wc)^2N) for the high-pass."""
    if not isinstance(order, int) or isinstance(order, bool) or order < 1:
        raise ValueError(f"order must be a positive integer, got {order!r}")
    if not (isinstance(wc, (int, float)) and math.isfinite(wc) and wc > 0):
        raise ValueError(f"cutoff wc must be finite and > 0 rad/s, got {wc!r}")
    m = np.arange(-order + 1, order, 2, dtype=np.float64)
    p = -np.exp(1j * np.pi * m / (2 * order))  # m = 0 (odd order) gives an exactly real pole
    wc = float(wc)
    if btype == "low":
        p = wc * p
        return np.zeros(0), p, float(wc**order)
    if btype == "high":
        # the N prototype zeros at infinity move to s = 0; the inversion's gain change cancels
        return np.zeros(order), wc / p, float(np.real(1.0 / np.prod(-p)))
    raise ValueError(f"btype must be 'low' or 'high', got {btype!r}")


def bilinear_zpk(
    z: ArrayLike, p: ArrayLike, k: float, fs: float
) -> tuple[NDArray, NDArray, float]:
    """Digital zeros, poles and gain of the analog (z, p, k) by the bilinear transform at
    sample rate ``fs`` (Hz), without prewarping; zeros at infinity land on z = -1."""
    z = np.atleast_1d(np.asarray(z))
    p = np.atleast_1d(np.asarray(p))
    if not (isinstance(fs, (int, float)) and math.isfinite(fs) and fs > 0):
        raise ValueError(f"sample rate fs must be finite and > 0, got {fs!r}")
    degree = p.shape[0] - z.shape[0]
    if degree < 0:
        raise ValueError(f"more zeros ({z.shape[0]}) than poles ({p.shape[0]})")
    fs2 = 2.0 * fs
    z_z = np.concatenate(((fs2 + z) / (fs2 - z), -np.ones(degree)))
    p_z = (fs2 + p) / (fs2 - p)
    return z_z, p_z, k * float(np.real(np.prod(fs2 - z) / np.prod(fs2 - p)))


def _split_conjugates(r: NDArray) -> tuple[NDArray, NDArray]:
    """(one of each conjugate pair with imag > 0, averaged with its partner; the real roots),
    both sorted by real part then |imag|: the order the section pairing depends on."""
    if r.size == 0:
        return r, r
    r = r[np.lexsort((abs(r.imag), r.real))]
    is_real = abs(r.imag) <= _TOL * abs(r)
    real = r[is_real].real
    if real.size == r.size:
        return np.array([]), real
    r = r[~is_real]
    pos, neg = r[r.imag > 0], r[r.imag < 0]
    if pos.size != neg.size:
        raise ValueError("roots contain a complex value without its conjugate")
    # pairs with (nearly) the same real part are ordered by |imag| within their run
    same = np.diff(pos.real) <= _TOL * abs(pos[:-1])
    edges = np.diff(np.concatenate(([0], same, [0])))
    for start, stop in zip(np.nonzero(edges > 0)[0], np.nonzero(edges < 0)[0] + 1):
        for run in (pos[start:stop], neg[start:stop]):
            run[...] = run[np.lexsort([abs(run.imag)])]
    if np.any(abs(pos - neg.conj()) > _TOL * abs(neg)):
        raise ValueError("roots contain a complex value without its conjugate")
    return (pos + neg.conj()) / 2, real


def _nearest(roots: NDArray, to: complex, which: str) -> int:
    """Index of the root nearest ``to`` among the real, complex or ("any") all roots."""
    order = np.argsort(np.abs(roots - to))
    if which == "any":
        return int(order[0])
    real = np.isreal(roots[order])
    return int(order[np.nonzero(real if which == "real" else ~real)[0][0]])


def _section(zeros: list, poles: list) -> NDArray[np.float64]:
    """[b0 b1 b2 a0 a1 a2] of the monic section with up to two zeros and two poles."""
    sos = np.zeros(6)
    b, a = np.atleast_1d(np.poly(zeros)), np.atleast_1d(np.poly(poles))
    sos[3 - len(b):3] = b.real
    sos[6 - len(a):6] = a.real
    return sos


def zpk2sos(z: ArrayLike, p: ArrayLike, k: float) -> NDArray[np.float64]:
    """Second-order sections (n, 6) of the digital filter (z, p, k), real-coefficient.

    Pole pairs are taken from the one closest to the unit circle (placed last, where its
    high gain is applied to an already filtered signal) outwards, each with its nearest
    zeros; ``k`` multiplies the first section's numerator.
    """
    z = np.atleast_1d(np.asarray(z))
    p = np.atleast_1d(np.asarray(p))
    if not np.isreal(k):
        raise ValueError(f"gain k must be real, got {k!r}")
    if len(z) == len(p) == 0:
        return np.array([[float(np.real(k)), 0.0, 0.0, 1.0, 0.0, 0.0]])
    # as many poles as zeros (the extra ones at the origin), an even number of each
    p = np.concatenate((p, np.zeros(max(len(z) - len(p), 0))))
    z = np.concatenate((z, np.zeros(max(len(p) - len(z), 0))))
    n_sections = (len(p) + 1) // 2
    if len(p) % 2 == 1:
        p = np.concatenate((p, [0.0]))
        z = np.concatenate((z, [0.0]))
    z = np.concatenate(_split_conjugates(z))
    p = np.concatenate(_split_conjugates(p))

    def worst(r: NDArray) -> int:  # closest to the unit circle
        return int(np.argmin(np.abs(1 - np.abs(r))))

    sos = np.zeros((n_sections, 6))
    for si in range(n_sections - 1, -1, -1):
        i = worst(p)
        p1 = p[i]
        p = np.delete(p, i)
        if np.isreal(p1) and np.isreal(p).sum() == 0:  # the last real pole: a real zero
            j = _nearest(z, p1, "real")
            sos[si] = _section([z[j], 0], [p1, 0])
            z = np.delete(z, j)
            continue
        if (len(p) + 1 == len(z) and not np.isreal(p1)
                and np.isreal(p).sum() == 1 and np.isreal(z).sum() == 1):
            # one real pole and one real zero left for each other: take a complex zero
            j = _nearest(z, p1, "complex")
            sos[si] = _section([z[j], z[j].conj()], [p1, p1.conj()])
            z = np.delete(z, j)
            continue
        if np.isreal(p1):
            reals = np.flatnonzero(np.isreal(p))
            i2 = reals[worst(p[reals])]
            p2 = p[i2]
            p = np.delete(p, i2)
        else:
            p2 = p1.conj()
        j = _nearest(z, p1, "any")
        z1 = z[j]
        z = np.delete(z, j)
        if not np.isreal(z1):
            sos[si] = _section([z1, z1.conj()], [p1, p2])
        elif len(z) > 0:
            j = _nearest(z, p1, "real")
            sos[si] = _section([z1, z[j]], [p1, p2])
            z = np.delete(z, j)
        else:
            sos[si] = _section([z1], [p1, p2])
    sos[0, :3] *= np.real(k)
    return sos
