"""Cable dynamics: axial waves (seed 002), elastic-drag "jerk" tension (seed 001), resonance.

SI units throughout (N, m, s, kg). Three independent pieces:

* Axial (longitudinal) waves, Zajac 1957 (seed 002, eq 29): a cable whose top moves along its
  own tangent at speed dP/dt carries the dynamic tension T = -sqrt(EA m) dP/dt when the line is
  long enough that no reflection returns (impedance sqrt(EA m)). A mooring line is usually SHORT
  compared with the axial wavelength: with the anchor fixed, a harmonic top displacement U gives
  the tension amplitude EA k U cot(k L), k = omega / c1, c1 = sqrt(EA/m), which tends to the
  spring EA U / L; the first dynamic correction is the inertia of a third of the line mass,
  T ~ EA U / L + (m L / 3) d2U/dt2.
* Elastic-drag jerk, Aleksandrov 1970 (seed 001, section B3, eqs 46-50): when the distance
  between the cord's supports grows at speed V_z, part of it (V) is taken up by a change of
  form, resisted by drag, and the rest by stretch: V + mu d(V^2)/dt = V_z with
  mu = c l^2 / (270 alpha^3 EA) and the drag tension dT = c l V^2 / (270 alpha^3),
  c = 1/2 C_D rho d (drag per unit length per speed squared), l = span, alpha = sag/span.
  The paper's closed forms (53-56) are not used (56 carries a wrong exponent); the ODE is
  integrated in y = V|V| by implicit Euler, which is unconditionally stable and has a
  closed-form step (a quadratic in sqrt|y|).
* Transverse resonance (seed 001, eq 29): string modes with wave speed sqrt(T/m), natural
  periods 2 l / (n c), amplification 1 / |1 - (T_n / T)^2| (damped form optional).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from models._jit import kernel


def _pos(name: str, value: float) -> float:
    if not isinstance(value, (int, float, np.floating)) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return float(value)


def _finite(name: str, value: ArrayLike) -> NDArray[np.float64]:
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return arr


# --------------------------------------------------------------------------- axial waves
def axial_wave_speed(ea: float, mass_per_length: float) -> float:
    """Longitudinal wave speed c1 = sqrt(EA/m) (m/s)."""
    return math.sqrt(_pos("ea", ea) / _pos("mass_per_length", mass_per_length))


def axial_impedance(ea: float, mass_per_length: float) -> float:
    """Axial impedance sqrt(EA m) (N s/m): tension per unit tangential top speed (seed 002)."""
    return math.sqrt(_pos("ea", ea) * _pos("mass_per_length", mass_per_length))


def tangential_speed(
    top_angle_rad: ArrayLike, vertical_speed: ArrayLike = 0.0, horizontal_speed: ArrayLike = 0.0
) -> NDArray[np.float64]:
    """Top speed along the cable, dP/dt = W sin(alpha) + U cos(alpha).

    alpha = cable angle above horizontal at the top; W = vertical speed (up, away from a
    hanging cable), U = horizontal speed away from the anchor / touchdown.
    """
    a = _finite("top_angle_rad", top_angle_rad)
    return _finite("vertical_speed", vertical_speed) * np.sin(a) + _finite(
        "horizontal_speed", horizontal_speed
    ) * np.cos(a)


def longitudinal_tension(
    impedance: float,
    top_angle_rad: ArrayLike,
    vertical_speed: ArrayLike = 0.0,
    horizontal_speed: ArrayLike = 0.0,
) -> NDArray[np.float64]:
    """Dynamic tension of a non-reflecting line, Z dP/dt (seed 002, eq 29), N.

    Positive when the top moves away along the cable (the sign of eq 29 is for P measured
    toward the top, i.e. paying out)."""
    return _pos("impedance", impedance) * tangential_speed(
        top_angle_rad, vertical_speed, horizontal_speed
    )


def finite_line_tension_amplitude(
    omega: ArrayLike,
    displacement_amplitude: ArrayLike,
    ea: float,
    mass_per_length: float,
    length: float,
) -> NDArray[np.float64]:
    """Tension amplitude EA k U cot(k L) at the top of a line with a fixed anchor (N).

    k = omega / sqrt(EA/m). Tends to the spring EA U / L as k L -> 0; infinite at the axial
    resonances k L = n pi. ``omega`` in rad/s, ``displacement_amplitude`` U in m.
    """
    w = _finite("omega", omega)
    if np.any(w < 0):
        raise ValueError("omega must be >= 0")
    u = _finite("displacement_amplitude", displacement_amplitude)
    ea = _pos("ea", ea)
    length = _pos("length", length)
    kl = w / axial_wave_speed(ea, mass_per_length) * length
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(kl > 1e-8, kl / np.tan(kl), 1.0 - kl * kl / 3.0)
    return ea / length * u * factor


def finite_line_added_mass(mass_per_length: float, length: float) -> float:
    """The inertia term of :func:`finite_line_tension_amplitude` for k L << 1: m L / 3 (kg).

    EA k cot(kL) = EA/L - m L omega^2 / 3 + O((kL)^4), so the dynamic tension beyond the static
    spring is (m L / 3) x the top acceleration along the cable.
    """
    return _pos("mass_per_length", mass_per_length) * _pos("length", length) / 3.0


# --------------------------------------------------------------------------- drag
def drag_constant(cd: float, diameter: float, rho: float = 1025.0) -> float:
    """c = 1/2 C_D rho d: normal drag per unit length per speed squared (N s^2/m^3)."""
    return 0.5 * _pos("cd", cd) * _pos("rho", rho) * _pos("diameter", diameter)


def hydrodynamic_constant(
    weight_per_length: float, cd: float, diameter: float, rho: float = 1025.0
) -> float:
    """Zajac's H = sqrt(2 w / (C_D rho d)) (m/s): the towing speed scale of a heavy cable."""
    w = _pos("weight_per_length", weight_per_length)
    return math.sqrt(2.0 * w / (_pos("cd", cd) * _pos("rho", rho) * _pos("diameter", diameter)))


def critical_angle(speed: ArrayLike, hydro_constant: float) -> NDArray[np.float64]:
    """Critical (steady-tow) angle of a cable with normal drag only, radians above horizontal.

    cos(alpha) = sqrt(1 + (H/V)^4 / 4) - (H/V)^2 / 2 (seed 002); alpha -> H/V for fast tows.
    """
    v = _finite("speed", speed)
    if np.any(v <= 0):
        raise ValueError("speed must be > 0")
    x = (_pos("hydro_constant", hydro_constant) / v) ** 2
    # Written as 1 / (sqrt(1 + x^2/4) + x/2) to avoid cancellation for large x.
    return np.arccos(1.0 / (np.sqrt(1.0 + 0.25 * x * x) + 0.5 * x))


# --------------------------------------------------------------------------- jerk (seed 001 B3)
@dataclass(frozen=True)
class ElasticDragCord:
    """Aleksandrov's elastic cord with drag (seed 001, B3).

    Attributes:
        c: drag constant 1/2 C_D rho d (N s^2/m^3), see :func:`drag_constant`.
        span: l, horizontal distance between the supports (m).
        alpha: form parameter, sag / span (the flat-cord theory wants alpha << 1).
        axial_stiffness: EA (N; the seed's "E d^2"). ``math.inf`` = inextensible (eq 45).
        length: stretched length S (m) for the elongation S dT / EA; defaults to ``span``
            (the seed's S ~ l).
    """

    c: float
    span: float
    alpha: float
    axial_stiffness: float
    length: float | None = None

    def __post_init__(self) -> None:
        _pos("c", self.c)
        _pos("span", self.span)
        _pos("alpha", self.alpha)
        if not (isinstance(self.axial_stiffness, (int, float)) and self.axial_stiffness > 0):
            raise ValueError(f"axial_stiffness must be > 0, got {self.axial_stiffness!r}")
        if self.length is not None:
            _pos("length", self.length)

    @property
    def tension_coefficient(self) -> float:
        """k in dT = k V^2: c l / (270 alpha^3) (eq 46), N s^2/m^2."""
        return self.c * self.span / (270.0 * self.alpha**3)

    @property
    def mu(self) -> float:
        """mu = k S / EA (eqs 48-50 with the cube on 1/alpha and S ~ l), s^2/m."""
        s = self.span if self.length is None else self.length
        return self.tension_coefficient * s / self.axial_stiffness

    def tension_increment(self, form_speed: ArrayLike) -> NDArray[np.float64]:
        """dT = k V |V| (N): eq 46, signed so that an approaching support unloads the cord."""
        v = _finite("form_speed", form_speed)
        return self.tension_coefficient * v * np.abs(v)


def form_parameter(x: ArrayLike, z: ArrayLike) -> tuple[float, float]:
    """(alpha, chord) of a cable shape: alpha = the largest distance of the shape from its
    chord, divided by the chord length (seed 001's "form parameter" y_max / l of a flat cord,
    measured perpendicular to the chord so that it also applies to inclined cords).

    ``x``, ``z``: points along the suspended part (m), e.g. a catenary profile from the
    touchdown point to the fairlead.
    """
    xx = _finite("x", x)
    zz = _finite("z", z)
    if xx.shape != zz.shape or xx.ndim != 1 or xx.size < 3:
        raise ValueError("x and z must be 1-D arrays of the same length >= 3")
    dx, dz = xx[-1] - xx[0], zz[-1] - zz[0]
    chord = math.hypot(dx, dz)
    if chord <= 0:
        raise ValueError("the shape's end points coincide")
    dist = np.abs((xx - xx[0]) * dz - (zz - zz[0]) * dx) / chord
    return float(dist.max() / chord), chord


# where jerk_step's halved form rounds exactly as its full form: b, b^2 and (b/2)^2 normal,
# 4 |c| + b^2 finite
_HALF_B_MIN, _HALF_B_MAX, _HALF_C_MAX = 2.0 ** -500, 2.0 ** 500, 2.0 ** 1000


@kernel(inline="always")
def jerk_step(y: float, vz: float, b: float) -> float:
    """One implicit-Euler step of y' = (V_z - sign(y) sqrt|y|) / mu, b = dt / mu (inf: mu = 0).

    Solves y_new + b sign(y_new) sqrt|y_new| = y + b V_z exactly: s = sqrt|y_new| is the
    positive root of s^2 + b s = |c|, c = y + b V_z, in a form that stays exact as b -> inf.
    """
    if math.isinf(b):
        return vz * abs(vz)
    c = y + b * vz
    ac = abs(c)
    if _HALF_B_MIN <= b <= _HALF_B_MAX and ac <= _HALF_C_MAX:
        # the same root with b / 2: s = |c| / (b/2 + sqrt((b/2)^2 + |c|)), one multiplication
        # less in the chain of dependent operations that sets the ODE's pace; every rounding
        # is that of the form below scaled by a power of two (exact where nothing overflows
        # or underflows, as the bounds ensure): the same bits
        h = 0.5 * b
        s = ac / (h + math.sqrt(h * h + ac))
    else:
        s = 2.0 * ac / (b + math.sqrt(b * b + 4.0 * ac))
    return s * s if c >= 0.0 else -s * s


@kernel()
def _jerk_steps(vz: np.ndarray, b: float, y0: float, out: np.ndarray) -> float:
    y = y0
    for i in range(vz.size):
        y = jerk_step(y, vz[i], b)
        out[i] = y
    return y


def jerk_form_speed_squared(
    support_speed: ArrayLike, dt: float, mu: float, y0: float = 0.0
) -> tuple[NDArray[np.float64], float]:
    """Integrate V + mu d(V|V|)/dt = V_z(t) for y = V|V| by implicit Euler (seed 001, eq 49).

    ``support_speed`` V_z at t = dt, 2 dt, ...; ``y0`` the state at t = 0. Returns (y at each
    step, final y) so a stream can be continued block by block. Unconditionally stable (see
    :func:`jerk_step`). mu = 0 (inextensible) gives y = V_z |V_z| (eq 45).
    """
    vz = np.ascontiguousarray(_finite("support_speed", support_speed), dtype=float)
    _pos("dt", dt)
    if not (math.isfinite(mu) and mu >= 0):
        raise ValueError(f"mu must be finite and >= 0, got {mu!r}")
    if not math.isfinite(y0):
        raise ValueError(f"y0 must be finite, got {y0!r}")
    out = np.empty_like(vz)
    last = _jerk_steps(vz, dt / mu if mu > 0 else math.inf, float(y0), out)
    return out, float(last)


def jerk_peak_ratio(phi: float, steps: int = 200_000) -> float:
    """Max V / V_z for the triangular support-speed pulse of eqs 51-52, phi = 8 mu V_z / tau.

    V_z rises linearly to its peak at tau/4 and falls back to 0 at tau/2 (the half cycle in
    which the supports separate). Seed 001 Fig. 8 gives this ratio graphically.
    """
    if not (math.isfinite(phi) and phi >= 0):
        raise ValueError(f"phi must be finite and >= 0, got {phi!r}")
    # Normalised: V_z peak = 1, tau = 1 -> mu = phi / 8.
    t = np.arange(1, steps + 1) / steps * 0.5
    vz = np.where(t <= 0.25, 4.0 * t, 2.0 - 4.0 * t)
    y, _ = jerk_form_speed_squared(vz, 0.5 / steps, phi / 8.0)
    return float(math.sqrt(max(y.max(), 0.0)))


# --------------------------------------------------------------------------- resonance
def transverse_wave_speed(tension: ArrayLike, mass_per_length: float) -> NDArray[np.float64]:
    """Transverse (string) wave speed sqrt(T / m) (m/s); m may include added mass.

    Seed 001 writes sqrt(T g / w) with w the weight per length: the same with m = w / g.
    """
    t = _finite("tension", tension)
    if np.any(t <= 0):
        raise ValueError("tension must be > 0 for transverse waves")
    return np.sqrt(t / _pos("mass_per_length", mass_per_length))


def transverse_natural_periods(
    tension: float, mass_per_length: float, length: float, n_modes: int = 5
) -> NDArray[np.float64]:
    """Natural periods 2 l / (n c) of the first ``n_modes`` string modes (s), seed 001."""
    if not isinstance(n_modes, int) or n_modes < 1:
        raise ValueError(f"n_modes must be a positive integer, got {n_modes!r}")
    c = transverse_wave_speed(tension, mass_per_length)
    return 2.0 * _pos("length", length) / (np.arange(1, n_modes + 1) * c)


def dynamic_amplification(
    forcing_period: ArrayLike, natural_period: ArrayLike, damping_ratio: float = 0.0
) -> NDArray[np.float64]:
    """DAF = 1 / sqrt((1 - r^2)^2 + (2 zeta r)^2), r = T_n / T (forcing over natural frequency).

    With zeta = 0 this is seed 001's resonance factor |1 / (1 - (omega_n tau/2 pi)^2)| pole at
    the same place; infinite exactly at resonance.
    """
    tf = _finite("forcing_period", forcing_period)
    tn = _finite("natural_period", natural_period)
    if np.any(tf <= 0) or np.any(tn <= 0):
        raise ValueError("periods must be > 0")
    if not (math.isfinite(damping_ratio) and damping_ratio >= 0):
        raise ValueError(f"damping_ratio must be >= 0, got {damping_ratio!r}")
    r = tn / tf
    den = np.sqrt((1.0 - r * r) ** 2 + (2.0 * damping_ratio * r) ** 2)
    with np.errstate(divide="ignore"):
        return 1.0 / den


@dataclass(frozen=True)
class ResonanceScreen:
    """Result of :func:`resonance_screen` for an array of wave periods.

    natural_periods: (n_modes,) s; daf: worst amplification over modes per wave period;
    nearest_mode: 1-based mode index closest in period; near: True where a wave period lies
    within the band of a natural period.
    """

    natural_periods: NDArray[np.float64]
    daf: NDArray[np.float64]
    nearest_mode: NDArray[np.int64]
    near: NDArray[np.bool_]


def resonance_screen(
    wave_periods: ArrayLike,
    tension: float,
    mass_per_length: float,
    length: float,
    n_modes: int = 5,
    band: float = 0.15,
    damping_ratio: float = 0.0,
) -> ResonanceScreen:
    """Flag wave periods within ``band`` (relative) of a transverse natural period."""
    tw = _finite("wave_periods", wave_periods)
    if np.any(tw <= 0):
        raise ValueError("wave_periods must be > 0")
    if not (0 < band < 1):
        raise ValueError(f"band must be between 0 and 1, got {band!r}")
    tn = transverse_natural_periods(tension, mass_per_length, length, n_modes)
    daf = dynamic_amplification(tw[..., None], tn, damping_ratio)
    rel = np.abs(tw[..., None] / tn - 1.0)
    return ResonanceScreen(
        natural_periods=tn,
        daf=daf.max(axis=-1),
        nearest_mode=np.argmin(rel, axis=-1) + 1,
        near=np.any(rel <= band, axis=-1),
    )
