"""Seed 004 Appendix 6, program WAVFOR: wave force on a buoy held fixed in a linear wave.

An upper bound of the cable force per wave (the 1981 study's design estimate, "pessimistic"):
the buoy is held fixed and the cable supplies the Morison force of the undisturbed Airy wave,

    F_H = rho Ci Vol du/dt + 1/2 rho Cd_h S_h |u| u,
    F_V = rho Ci Vol dw/dt + 1/2 rho Cd_v S_v |w| w,

evaluated at the wave crest (drag horizontal, inertia vertical) and at the node (inertia
horizontal, drag vertical). The formulas follow the program listing, not the report's text:
u and dw/dt are evaluated at z = +A (``cosh/sinh(k(A + h))``), w and du/dt at z = 0, and
Ci = 1.8 for both directions (the text quotes 1.1 for surge). With these the printed table
reproduces to the printed digits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from models.waves import wavelength


@dataclass(frozen=True)
class WavforBuoy:
    """Hull and site data of the WAVFOR run (seed 004: GVAPS buoy, 22 m depth), SI units."""

    rho: float = 1000.0  # kg/m^3 (the listing's Mf = 1 t/m^3, forces in kN)
    ci: float = 1.8  # virtual-mass coefficient, heave and surge (listing)
    volume: float = 3.3  # m^3 displaced
    cd_v: float = 0.6
    cd_h: float = 0.05
    s_v: float = 10.7  # m^2, waterplane area
    s_h: float = 1.26  # m^2, vertical projection
    depth: float = 22.0  # m
    g: float = 9.806

    def __post_init__(self) -> None:
        for name in ("rho", "ci", "volume", "cd_v", "cd_h", "s_v", "s_h", "depth", "g"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"WavforBuoy.{name} must be finite and > 0, got {v!r}")


@dataclass(frozen=True)
class WaveForce:
    """Horizontal and vertical force (N); resultant (N) and its angle above horizontal (deg)."""

    horizontal: NDArray[np.float64]
    vertical: NDArray[np.float64]

    @property
    def total(self) -> NDArray[np.float64]:
        return np.hypot(self.horizontal, self.vertical)

    @property
    def direction_deg(self) -> NDArray[np.float64]:
        return np.degrees(np.arctan2(self.vertical, self.horizontal))


@dataclass(frozen=True)
class WavforResult:
    crest: WaveForce
    node: WaveForce

    @property
    def max_force(self) -> NDArray[np.float64]:
        """The larger of the crest and node resultants: the per-wave cable-force bound (N)."""
        return np.maximum(self.crest.total, self.node.total)


SEED004_TABLE_SLOPE_S_PER_M = 0.55 / 0.3048


def seed004_period(height: ArrayLike, slope_s_per_m: float = 1.0) -> NDArray[np.float64]:
    """Seed 004's site rule (Point Pelee scatter diagram): T = slope H + 2.5 s, H in metres.

    The report's text states T = H + 2.5 (slope 1 s/m, the default). The WAVFOR DATA rows
    2-11 were however generated with 0.55 s per FOOT of height (heights were read in feet):
    pass ``SEED004_TABLE_SLOPE_S_PER_M`` to reproduce them.
    """
    h = np.asarray(height, dtype=float)
    if not np.all(np.isfinite(h)) or np.any(h < 0):
        raise ValueError(f"wave height must be finite and >= 0, got {height!r}")
    if not (math.isfinite(slope_s_per_m) and slope_s_per_m >= 0):
        raise ValueError(f"slope_s_per_m must be finite and >= 0, got {slope_s_per_m!r}")
    return slope_s_per_m * h + 2.5


def wavfor(
    height: ArrayLike,
    period: ArrayLike,
    buoy: WavforBuoy = WavforBuoy(),
    wave_length: ArrayLike | None = None,
) -> WavforResult:
    """WAVFOR crest and node forces for waves of ``height`` (m) and ``period`` (s).

    ``wave_length`` (m) defaults to linear dispersion in ``buoy.depth``; pass the listing's
    DATA values to reproduce the printed table exactly (its first row, 120 m, is not the
    dispersion value). Vectorised over the wave arrays.
    """
    hw = np.asarray(height, dtype=float)
    t = np.asarray(period, dtype=float)
    if not np.all(np.isfinite(hw)) or np.any(hw <= 0):
        raise ValueError(f"wave height must be finite and > 0, got {height!r}")
    if not np.all(np.isfinite(t)) or np.any(t <= 0):
        raise ValueError(f"wave period must be finite and > 0, got {period!r}")
    if wave_length is None:
        lw = wavelength(t, buoy.depth, buoy.g)
    else:
        lw = np.asarray(wave_length, dtype=float)
        if not np.all(np.isfinite(lw)) or np.any(lw <= 0):
            raise ValueError(f"wave_length must be finite and > 0, got {wave_length!r}")
    h, g = buoy.depth, buoy.g
    k = 2.0 * np.pi / lw
    a = hw / 2.0
    k_over_omega = t / lw  # the listing's Z = T/L
    u_max = a * g * k_over_omega * np.cosh(k * (a + h)) / np.cosh(k * h)
    w_max = a * g * k_over_omega * np.tanh(k * h)
    du_max = a * g * k
    dw_max = a * g * k * np.sinh(k * (a + h)) / np.cosh(k * h)
    zero = np.zeros_like(u_max)
    return WavforResult(crest=morison_force(u_max, zero, zero, dw_max, buoy),
                        node=morison_force(zero, w_max, du_max, zero, buoy))


def morison_force(u: ArrayLike, w: ArrayLike, du_dt: ArrayLike, dw_dt: ArrayLike,
                  buoy: WavforBuoy = WavforBuoy()) -> WaveForce:
    """WAVFOR's force on the held-fixed buoy from the water-particle kinematics at the buoy.

    F_H = rho Ci Vol du/dt + 1/2 rho Cd_h S_h |u| u, F_V = rho Ci Vol dw/dt + 1/2 rho Cd_v S_v
    |w| w (seed 004 App. 6). :func:`wavfor` evaluates it at the crest and the node of a regular
    wave; a time series of kinematics (e.g. an irregular sea's) gives the force history.
    Vectorised; velocities in m/s, accelerations in m/s^2, forces in N.
    """
    arrays = [np.asarray(x, dtype=float) for x in (u, w, du_dt, dw_dt)]
    for name, x in zip(("u", "w", "du_dt", "dw_dt"), arrays):
        if not np.all(np.isfinite(x)):
            raise ValueError(f"morison_force: {name} must be finite")
    uu, ww, du, dw = arrays
    inertia = buoy.rho * buoy.ci * buoy.volume
    return WaveForce(
        horizontal=inertia * du + 0.5 * buoy.rho * buoy.cd_h * buoy.s_h * np.abs(uu) * uu,
        vertical=inertia * dw + 0.5 * buoy.rho * buoy.cd_v * buoy.s_v * np.abs(ww) * ww,
    )
