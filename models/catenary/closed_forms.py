"""The seeds' closed-form cable formulas as named functions (seeds 000, 001, 002, 003).

Units are whatever consistent set the caller uses (SI in the service); weights are submerged
weights per unit length, `a = H / w` is the catenary parameter. The general solver is
`models.catenary.solve_line`; these are the papers' own relations, kept for checks and quick
estimates.
"""

from __future__ import annotations

import math

import numpy as np

from models.catenary.kernel import _phi_from_excess


# --- seed 001 (Aleksandrov 1970) -----------------------------------------------------------

def touchdown_catenary_y(x, a):
    """Seed 001 eq 1: height above the touchdown (lowest, horizontal) point,
    y = a (cosh(x/a) - 1), a = T0/w."""
    return a * (np.cosh(np.asarray(x, dtype=float) / a) - 1.0)


def touchdown_tension(t0, w, y):
    """Seed 001 eq 2: tension at height y above the touchdown point, T = T0 + w y."""
    return t0 + w * np.asarray(y, dtype=float)


def touchdown_suspended_length(y, a):
    """Seed 001 eq 3 (sign corrected; the print has a minus): cable length from the touchdown
    point up to height y, s = sqrt(y^2 + 2 a y)."""
    y = np.asarray(y, dtype=float)
    return np.sqrt(y * y + 2.0 * a * y)


def chain_suspended_length(depth, h, w):
    """Seed 001 appendix: suspended length of a chain partly on the seabed,
    S = depth sqrt(2 H/(w depth) + 1) (eq 3 with a = H/w and y = depth)."""
    return depth * np.sqrt(2.0 * h / (w * depth) + 1.0)


def chain_top_tension(depth, h, w):
    """Seed 001 appendix: top tension of a chain tangent to the seabed, T = H + w depth."""
    return h + w * depth


def current_cord_tension(beta, lam, p0, beta_top):
    """Seed 001 eqs 10-11: tension of a heavy cord in a uniform stream (tangential drag
    neglected) at local angle `beta` above the horizontal (rad), lam = c/w with
    c = c' rho v^2 d / 2; the constant comes from the top condition T cos(beta_top) = p0.
    T(beta) = C |(2 lam cos b - 1 - s)/(2 lam cos b - 1 + s)|^(1/s), s = sqrt(4 lam^2 + 1).
    The stream flows against the direction in which the cord rises (it pushes the cord back,
    as behind a towing ship); the singular angle of the formula is seed 002's critical angle.
    """
    s = math.sqrt(4.0 * lam * lam + 1.0)

    def shape(b):
        cb = 2.0 * lam * np.cos(b)
        return np.abs((cb - 1.0 - s) / (cb - 1.0 + s)) ** (1.0 / s)

    c = p0 / (math.cos(beta_top) * shape(beta_top))
    return c * shape(np.asarray(beta, dtype=float))


# --- seed 002 (Zajac 1957): hydrodynamic_constant and critical_angle are in models.dynamics

# --- seed 003 (Filipich, Rosales, Almeida) -------------------------------------------------

def filipich_end_forces(length, a, b, w):
    """Seed 003: inextensible cable from A = (0, 0) to B = (a, b), free of any seabed.
    With phi = w a / (2 H): sinh(phi)/phi = sqrt(L^2 - b^2)/a, H = w a / (2 phi),
    V_B = (w/2)(L + b coth phi), V_A = (w/2)(b coth phi - L) (V_A < 0: the cable dips below A).
    Returns (H, V_A, V_B)."""
    if not (a > 0.0 and length > math.hypot(a, b)):
        raise ValueError(f"need a > 0 and length > chord, got length={length!r}, a={a!r}, "
                         f"b={b!r}")
    q = (length * length - b * b - a * a) / (a * (math.sqrt(length * length - b * b) + a))
    phi = _phi_from_excess(q)
    coth = 1.0 / math.tanh(phi)
    return w * a / (2.0 * phi), 0.5 * w * (b * coth - length), 0.5 * w * (length + b * coth)


# --- seed 000 (Texas A&M 1975, tapered cables) ---------------------------------------------

def vertical_cable_tension(s, w, p):
    """Seed 000: tension of a vertically hanging common cable, T = w s + P (s from the load)."""
    return w * np.asarray(s, dtype=float) + p


def self_support_length(sigma, gamma):
    """Seed 000: length of a common cable that just carries its own weight at stress sigma,
    sigma / gamma (gamma = specific weight; psi with lb/ft^3 needs the factor 144 in ft)."""
    return sigma / gamma


def e_taper_area(s, a0, gamma, sigma):
    """Seed 000 eq 8: constant-stress hanging cable, A = A0 exp(gamma s / sigma)."""
    return a0 * np.exp(gamma * np.asarray(s, dtype=float) / sigma)


def e_taper_weight(s, t0, gamma, sigma):
    """Seed 000 eq 10: weight of an E-tapered cable of length s, W = T0 (exp(gamma s/sigma)-1)."""
    return t0 * np.expm1(gamma * np.asarray(s, dtype=float) / sigma)


def constant_stress_catenary_y(x, c):
    """Seed 000 eq 17: y = c ln sec(x/c), c = sigma/gamma, |x/c| < pi/2."""
    u = np.asarray(x, dtype=float) / c
    if np.any(np.abs(u) >= 0.5 * math.pi):
        raise ValueError("constant-stress catenary needs |x/c| < pi/2")
    return -c * np.log(np.cos(u))


def constant_stress_catenary_length(y, c):
    """Seed 000 eq 18 (as intended: cosh(s/c) = exp(y/c)): arc length from the tangency point
    to height y, s = c acosh(exp(y/c)), written to stay finite for y >> c."""
    t = np.asarray(y, dtype=float) / c
    return c * (t + np.log1p(np.sqrt(-np.expm1(-2.0 * t))))


def constant_stress_area(s, t_h, sigma, c):
    """Seed 000 eq 19: A = (T_H / sigma) cosh(s/c)."""
    return t_h / sigma * np.cosh(np.asarray(s, dtype=float) / c)


def constant_stress_parameter(x, y):
    """Parameter c of the constant-stress catenary tangent at the origin through (x, y)."""
    if not (x > 0.0 and y > 0.0):
        raise ValueError(f"need x > 0 and y > 0, got {x!r}, {y!r}")
    # y/x = ln sec(u)/u with u = x/c in (0, pi/2), increasing in u
    ratio = y / x
    # imported here, not at module level: scipy costs the live daemon memory it never uses
    from scipy.optimize import brentq  # noqa: PLC0415

    u = brentq(lambda u: -math.log(math.cos(u)) / u - ratio, 1e-12, 0.5 * math.pi - 1e-15,
               xtol=1e-300, rtol=1e-15, maxiter=500)
    return x / u


def gravity_cable_shape(s, weight, t_h):
    """Seed 000's general gravity-only cable: a cable tangent to the bottom at s = 0 with any
    weight distribution `weight(s)` (N/m, e.g. gamma * A(s)) and horizontal tension t_h.
    V(s) = integral of w, slope V/H, x = int H/T ds, y = int V/T ds (Simpson's rule on the
    given arc-length grid). Returns (x, y, T)."""
    s = np.asarray(s, dtype=float)
    w = np.broadcast_to(np.asarray(weight, dtype=float), s.shape)
    if s.ndim != 1 or s.size < 2 or s[0] != 0.0 or np.any(np.diff(s) <= 0.0):
        raise ValueError("s must be an increasing 1-D grid starting at 0")
    from scipy.integrate import cumulative_simpson  # noqa: PLC0415 (see constant_stress_parameter)

    v = cumulative_simpson(w, x=s, initial=0.0)
    t = np.hypot(t_h, v)
    x = cumulative_simpson(t_h / t, x=s, initial=0.0)
    y = cumulative_simpson(v / t, x=s, initial=0.0)
    return x, y, t
