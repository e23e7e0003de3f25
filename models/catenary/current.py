"""Steady current on a suspended mooring line: discretised (shooting) solver.

The line is integrated from the anchor to the fairlead with RK4 in unstretched arc length s:
    dx/ds = t (1 + T/EA),   d(T t)/ds = (0, w) - D,
with D the drag of a cylinder in the horizontal current u(z): normal
D_n = rho C_n d |U_n| U_n / 2 (seed 002's normal drag) and, if asked, tangential
D_t = rho C_t d |U_t| U_t / 2 (seed 002 neglects it: then dT = w dz, eqs 21/49). Weight and
drag are both taken per unit UNSTRETCHED length (strains are small; the diameter thins as the
line stretches), which keeps seed 002's critical angle independent of the strain.
Joint point loads add to the vertical tension. The unknown anchor tension (H_A, V_A) is found
by Newton iteration on the fairlead position mismatch, started from the no-current catenary.
Without tangential drag a straight line at seed 002's critical angle is an exact solution, and
in a uniform stream the tension follows seed 001 eq 11 (both are checked in the tests).
Suspended lines only: a line that would touch the seabed is a ValueError.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from models.catenary.line import Line, solve


@dataclass(frozen=True)
class Drag:
    """Hydrodynamic properties: one diameter (m) per segment (or one for all), normal and
    tangential drag coefficients, water density (kg/m^3)."""

    diameter: float | tuple[float, ...]
    cd_normal: float = 1.2
    cd_tangential: float = 0.0
    rho: float = 1025.0

    def diameters(self, n: int) -> tuple[float, ...]:
        d = self.diameter if isinstance(self.diameter, tuple) else (float(self.diameter),) * n
        if len(d) != n or not all(math.isfinite(v) and v > 0.0 for v in d):
            raise ValueError(f"need {n} positive finite diameters, got {self.diameter!r}")
        return d


@dataclass(frozen=True)
class CurrentSolution:
    """Shape and tension along the line (anchor first) in the current."""

    s: np.ndarray
    x: np.ndarray
    z: np.ndarray
    tension: np.ndarray
    angle: np.ndarray  # line angle above the +x axis (rad)
    h_anchor: float
    v_anchor: float
    h_top: float
    v_top: float

    @property
    def t_top(self) -> float:
        return math.hypot(self.h_top, self.v_top)


def _integrate(line: Line, drag_d: tuple[float, ...], drag: Drag, current: Callable,
               ha: float, va: float, steps: int) -> np.ndarray:
    """RK4 from the anchor; rows of (s, x, z, Tx, Tz)."""
    seg_l, seg_w, seg_c, joint_p = line._arrays
    rows: list[tuple[float, ...]] = [(0.0, 0.0, 0.0, ha, va)]
    s0 = 0.0
    state = [0.0, 0.0, ha, va]
    total = float(seg_l.sum())
    for k in range(seg_l.size):
        w, c, d = float(seg_w[k]), float(seg_c[k]), drag_d[k]
        kn = 0.5 * drag.rho * drag.cd_normal * d
        kt = 0.5 * drag.rho * drag.cd_tangential * d

        def rhs(st):
            x, z, tx, tz = st
            t = math.hypot(tx, tz)
            if t == 0.0:
                raise ValueError("zero tension inside the line: slack in this current")
            ex, ez = tx / t, tz / t
            stretch = 1.0 + c * t
            u = float(current(z))
            ut = u * ex  # tangential current component
            unx, unz = u - ut * ex, -ut * ez
            un = math.hypot(unx, unz)
            dx_ = kn * un * unx + kt * abs(ut) * ut * ex
            dz_ = kn * un * unz + kt * abs(ut) * ut * ez
            return (ex * stretch, ez * stretch, -dx_, w - dz_)

        n = max(2, int(math.ceil(steps * seg_l[k] / total)))
        h = float(seg_l[k]) / n
        for _ in range(n):
            k1 = rhs(state)
            k2 = rhs([a + 0.5 * h * b for a, b in zip(state, k1)])
            k3 = rhs([a + 0.5 * h * b for a, b in zip(state, k2)])
            k4 = rhs([a + h * b for a, b in zip(state, k3)])
            state = [a + h / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4)
                     for a, b1, b2, b3, b4 in zip(state, k1, k2, k3, k4)]
            s0 += h
            rows.append((s0, *state))
        if k < seg_l.size - 1:
            state[3] += float(joint_p[k])  # the joint's weight, carried from above
            rows.append((s0, *state))
    return np.array(rows)


def solve_in_current(line: Line, span: float, height: float,
                     current: float | Callable[[float], float], drag: Drag,
                     steps: int = 400, tol: float = 1e-9, max_iter: int = 50) -> CurrentSolution:
    """Static shape and tensions of a suspended `line` with fairlead at (span, height) in a
    horizontal current `current` (m/s along +x, i.e. from anchor towards fairlead; a number or
    a function of height above the anchor z)."""
    for name, v in (("span", span), ("height", height)):
        if not math.isfinite(v):
            raise ValueError(f"{name} must be finite, got {v!r}")
    if steps < 10:
        raise ValueError(f"steps must be >= 10, got {steps}")
    flow = (lambda z: current) if not callable(current) else current
    if not callable(current) and not math.isfinite(current):
        raise ValueError(f"current must be finite, got {current!r}")
    dd = drag.diameters(len(line.segments))
    still = solve(line, float(span), float(height))
    if float(still.grounded_length) > 0.0:
        raise ValueError("the line touches the seabed without current; the current solver "
                         "handles suspended lines only")
    ha, va = float(still.h_anchor), float(still.v_anchor)
    scale = line.length
    fscale = max(abs(line.weight), math.hypot(ha, va), 1.0)
    for _ in range(max_iter):
        rows = _integrate(line, dd, drag, flow, ha, va, steps)
        r = np.array([rows[-1, 1] - span, rows[-1, 2] - height])
        if np.abs(r).max() <= tol * scale:
            break
        jac = np.empty((2, 2))
        for j, (dh, dv) in enumerate(((1e-6 * fscale, 0.0), (0.0, 1e-6 * fscale))):
            alt = _integrate(line, dd, drag, flow, ha + dh, va + dv, steps)[-1]
            jac[:, j] = (np.array([alt[1] - span, alt[2] - height]) - r) / (dh + dv)
        step = np.linalg.solve(jac, -r)
        # keep Newton steps a fraction of the force scale: the residual is very nonlinear
        lim = 0.5 * max(math.hypot(ha, va), 1e-3 * fscale)
        norm = float(np.hypot(*step))
        if norm > lim:
            step *= lim / norm
        ha += float(step[0])
        va += float(step[1])
    else:
        raise ValueError(f"current solver did not converge for span={span!r}, "
                         f"height={height!r}")
    s, x, z, tx, tz = rows.T
    if line.seabed and z.min() < -tol * scale:
        raise ValueError("the line dips below the seabed in this current (not modelled)")
    return CurrentSolution(s=s, x=x, z=z, tension=np.hypot(tx, tz), angle=np.arctan2(tz, tx),
                           h_anchor=ha, v_anchor=va, h_top=float(tx[-1]), v_top=float(tz[-1]))
